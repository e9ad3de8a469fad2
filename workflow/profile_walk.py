"""Where a campaign walk spends its time: per-sample Newton, LU and GMRES counts + cProfile.

    python -m workflow.profile_walk [--seed 1] [--unit 39] [--samples 8] [--mesh-size H]

Data flow: the walk of campaign unit ``--unit`` (workflow.campaign.unit_walk, the
campaign's default step), solved on one rank as the campaign does: its first sample from
zero, then continuation; each sample followed by its sensitivities. For every sample after
the first it prints the wall time (s), the Newton iterations, the LU factorisations, and
per tangent solve the GMRES iterations and whether it factorised first (an asterisk);
then the top functions of a cProfile over the continuation samples. Nothing is written.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time


def main(argv=None) -> int:
    from mpi4py import MPI

    from fem.geometry import JointGeometry
    from fem.solver import JointSolver, Load
    from workflow.campaign import DEFAULT_STEP, unit_walk

    ap = argparse.ArgumentParser(prog="python -m workflow.profile_walk",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--unit", type=int, default=39)
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--mesh-size", type=float, default=JointGeometry().mesh_size)
    ap.add_argument("--top", type=int, default=12, help="cProfile lines to print")
    args = ap.parse_args(argv)

    solver = JointSolver(JointGeometry(mesh_size=args.mesh_size), MPI.COMM_SELF)
    walk = unit_walk(args.seed, args.unit, args.samples, DEFAULT_STEP)
    gmres = []
    plain = solver._solve_tangent

    def counted(*a, **kw):
        lu0 = solver.factorisations
        plain(*a, **kw)
        gmres.append(f"{solver.ksp.getIterationNumber()}{'*' * (solver.factorisations - lu0)}")

    solver._solve_tangent = counted
    first = solver.solve(Load.from_array(walk[0]))
    solver.sensitivities()
    print(f"from zero: {first.wall_time:.1f} s, Newton {first.newton_iterations}, "
          f"{first.factorisations} LU; mesh {solver.mesh_info()['dofs']} dofs")
    profile = cProfile.Profile()
    profile.enable()
    t0 = time.perf_counter()
    for x in walk[1:]:
        gmres.clear()
        res = solver.solve(Load.from_array(x), continuation=True)
        newton = list(gmres)
        t1 = time.perf_counter()
        solver.sensitivities()
        print(f"sample {res.wall_time + time.perf_counter() - t1:6.2f} s: Newton "
              f"{res.iterations} its, {res.factorisations} LU, GMRES {' '.join(newton)} | "
              f"sensitivities {time.perf_counter() - t1:5.2f} s, GMRES {' '.join(gmres[len(newton):])}")
    profile.disable()
    print(f"continuation samples: {time.perf_counter() - t0:.1f} s in all "
          f"(* = factorised before that solve)")
    pstats.Stats(profile).sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
