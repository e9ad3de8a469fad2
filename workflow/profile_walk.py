"""Where a campaign walk spends its time: per-sample Newton, LU and GMRES counts + cProfile.

    python -m workflow.profile_walk [--seed 1] [--unit 39] [--samples 8] [--mesh-size H]

Data flow: the walk of campaign unit ``--unit`` (workflow.campaign.unit_walk, the
campaign's default step), solved on one rank as the campaign does: its first sample from
zero, then continuation; each sample followed by its sensitivities. For every sample after
the first it prints the wall time (s), the Newton iterations, and the LU factorisations
and GMRES iterations of the solve and of its sensitivities; then the top functions of a
cProfile over the continuation samples. Nothing is written.
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
    first = solver.solve(Load.from_array(walk[0]))
    solver.sensitivities()
    print(f"from zero: {first.wall_time:.1f} s, Newton {first.newton_iterations}, "
          f"{first.factorisations} LU; mesh {solver.mesh_info()['dofs']} dofs")
    profile = cProfile.Profile()
    profile.enable()
    t0 = time.perf_counter()
    for x in walk[1:]:
        res = solver.solve(Load.from_array(x), continuation=True)
        t1, lu1, kr1 = time.perf_counter(), solver.factorisations, solver.krylov_iterations
        solver.sensitivities()
        t2 = time.perf_counter()
        print(f"sample {res.wall_time + t2 - t1:6.2f} s: Newton {res.iterations} its, "
              f"{res.factorisations} LU, {res.krylov_iterations} GMRES its | sensitivities "
              f"{t2 - t1:5.2f} s, {solver.factorisations - lu1} LU, "
              f"{solver.krylov_iterations - kr1} GMRES its")
    profile.disable()
    print(f"continuation samples: {time.perf_counter() - t0:.1f} s in all")
    pstats.Stats(profile).sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
