"""Where a campaign walk spends its time: per-sample Newton, LU and GMRES counts + cProfile.

    python -m workflow.profile_walk [--seed 1] [--unit 39] [--samples 8] [--json]
        [--mesh-size H | --divisions N [--hex-size S]] [--formulation F]

Data flow: the walk of campaign unit ``--unit`` (workflow.campaign.unit_walk, the
campaign's default step), solved on one rank as the campaign does, on the campaign's
discretisation for the same options (the paper joint file's [mesh] by default: the
production hex2:3 mixed; the committed datasets' units need ``--mesh-size 1.8
--formulation displacement``): its first sample from zero, then continuation; each sample followed by its sensitivities. For every sample after
the first it reports the wall time (s), the Newton iterations, and the LU factorisations
and GMRES iterations of the solve and of its sensitivities; then the top functions of a
cProfile over the continuation samples (by own time, s). Nothing is written.
"""

from __future__ import annotations

import cProfile
import pstats
import time

from contract import cli
from contract.joint import load_joint
from fem.options import add_divisions, add_formulation, add_mesh_size, add_wall_mesh_size, joint_geometry


def parse_args(argv=None):
    ap = cli.Parser(prog="python -m workflow.profile_walk", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=cli.number(0, None, integer=True), default=1,
                    help="campaign seed (default 1)")
    ap.add_argument("--unit", type=cli.number(0, None, integer=True), default=39,
                    help="campaign unit whose walk is solved (default 39)")
    ap.add_argument("--samples", type=cli.number(2, None, integer=True), default=8,
                    help="walk samples, the first from zero (default 8)")
    add_mesh_size(ap, None, "tetrahedron size", shown="the joint file's [mesh], the production one")
    add_wall_mesh_size(ap)
    add_divisions(ap)
    add_formulation(ap, "the joint file's [mesh] formulation (the production one)")
    ap.add_argument("--top", type=cli.number(1, None, integer=True), default=12,
                    help="cProfile lines to report (default 12)")
    args = ap.parse_args(argv)
    with ap.errors():
        args.geometry = joint_geometry(args, load_joint())
    return args


def profile_walk(seed: int, unit: int, samples: int, geometry, top: int, formulation: str | None = None) -> dict:
    """Solve the walk as the campaign does, on the paper joint of ``geometry`` (a
    fem.mesh.geometry.JointGeometry) and ``formulation`` (None: the joint file's); return its
    figures (times s, counts)."""
    from mpi4py import MPI

    from fem.solvers.joint import JointSolver, Load
    from workflow.campaign import DEFAULT_STEP, unit_walk

    solver = JointSolver.for_joint(load_joint(), MPI.COMM_SELF, geometry, formulation=formulation)
    walk = unit_walk(seed, unit, samples, DEFAULT_STEP)
    first = solver.solve(Load.from_array(walk[0]))
    solver.sensitivities()
    rows = []
    profile = cProfile.Profile()
    profile.enable()
    t0 = time.perf_counter()
    for x in walk[1:]:
        res = solver.solve(Load.from_array(x), continuation=True)
        t1, lu1, kr1 = time.perf_counter(), solver.factorisations, solver.krylov_iterations
        solver.sensitivities()
        t2 = time.perf_counter()
        rows.append({"wall_s": res.wall_time + t2 - t1, "converged": res.converged,
                     "newton_iterations": res.iterations, "factorisations": res.factorisations,
                     "krylov_iterations": res.krylov_iterations, "sensitivities_s": t2 - t1,
                     "sensitivities_factorisations": solver.factorisations - lu1,
                     "sensitivities_krylov_iterations": solver.krylov_iterations - kr1})
    profile.disable()
    total = time.perf_counter() - t0
    stats = pstats.Stats(profile).stats             # {(file, line, name): (cc, calls, own, cum, callers)}
    hot = [{"function": f"{path}:{line}({name})", "calls": calls, "tottime_s": own, "cumtime_s": cum}
           for (path, line, name), (_, calls, own, cum, _) in
           sorted(stats.items(), key=lambda kv: -kv[1][2])[:top]]
    return {"seed": seed, "unit": unit, "mesh": solver.mesh_info(), "formulation": solver.formulation,
            "from_zero": {"wall_s": first.wall_time, "converged": first.converged,
                          "newton_iterations": first.newton_iterations,
                          "factorisations": first.factorisations},
            "samples": rows, "continuation_s": total, "profile_top": hot}


def main(argv=None) -> int:
    args = parse_args(argv)
    d = profile_walk(args.seed, args.unit, args.samples, args.geometry, args.top, args.formulation)
    if args.json:
        cli.print_json(d)
        return 0
    z = d["from_zero"]
    print(f"from zero: {z['wall_s']:.1f} s, Newton {z['newton_iterations']}, "
          f"{z['factorisations']} LU; mesh {d['mesh']['dofs']} dofs")
    for r in d["samples"]:
        print(f"sample {r['wall_s']:6.2f} s: Newton {r['newton_iterations']} its, "
              f"{r['factorisations']} LU, {r['krylov_iterations']} GMRES its | sensitivities "
              f"{r['sensitivities_s']:5.2f} s, {r['sensitivities_factorisations']} LU, "
              f"{r['sensitivities_krylov_iterations']} GMRES its")
    print(f"continuation samples: {d['continuation_s']:.1f} s in all; top functions by own time:")
    for h in d["profile_top"]:
        print(f"  {h['tottime_s']:8.3f} s own, {h['cumtime_s']:8.3f} s cumulative, "
              f"{h['calls']:>7} calls  {h['function']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
