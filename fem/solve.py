"""Command line: solve one joint load case.

    python -m fem.solve --p 0.2 --f1 1 --f2 -1 --m 20 --json
    mpirun -n 2 python -m fem.solve --p -0.1 --m 50

Inputs: P (MPa), F1, F2 (N), M (N·mm); outside |P|<=0.3, |F1|,|F2|<=3, |M|<=100 the load
is refused unless --allow-extrapolation (then recorded as "extrapolated": true).
Prints the anchors r_1..r_10 (mm), phi_end and the cap rotation (deg), Newton iterations
and wall time; with --jacobian also d(anchors)/d(P, F1, F2, M), shape (20, 4), rows
(x_1, y_1, x_2, ...), columns mm/MPa, mm/N, mm/N, mm/(N·mm). Exit status 0 on
convergence, 1 if the solve failed, 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import asdict, replace

from mpi4py import MPI

from fem.geometry import JointGeometry
from fem.solver import JointSolver, Load, LoadOutOfRange


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m fem.solve",
                                 description="Solve one bellow-joint load case with DOLFINx.")
    ap.add_argument("--p", type=float, default=0.0, help="chamber pressure P, MPa (signed)")
    ap.add_argument("--f1", type=float, default=0.0, help="axial end force F1, N")
    ap.add_argument("--f2", type=float, default=0.0, help="transverse end force F2, N")
    ap.add_argument("--m", type=float, default=0.0, help="end couple M about +z, N*mm")
    ap.add_argument("--mesh-size", type=float, default=JointGeometry().mesh_size,
                    help="tetrahedron size, mm (default: production mesh)")
    ap.add_argument("--allow-extrapolation", action="store_true",
                    help="accept loads outside the training box")
    ap.add_argument("--json", action="store_true", help="print JSON only")
    ap.add_argument("--jacobian", action="store_true",
                    help="also print d(anchors)/d(P, F1, F2, M) from the converged tangent")
    ap.add_argument("--xdmf", help="also write the displacement field to this XDMF file")
    ap.add_argument("-v", "--verbose", action="store_true", help="log load steps")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    comm = MPI.COMM_WORLD
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(message)s", force=True)
    load = Load(args.p, args.f1, args.f2, args.m)
    try:
        load.check_box(args.allow_extrapolation)
        if args.mesh_size <= 0:
            raise ValueError(f"--mesh-size must be > 0, got {args.mesh_size}")
    except ValueError as exc:
        if comm.rank == 0:
            print(f"error: {exc}", file=sys.stderr)
        return 2
    geo = replace(JointGeometry(), mesh_size=args.mesh_size)
    solver = JointSolver(geo, comm)
    result = solver.solve(load, allow_extrapolation=args.allow_extrapolation)
    jac = solver.sensitivities() if args.jacobian and result.converged else None
    if args.xdmf and result.converged:
        from dolfinx.io import XDMFFile
        with XDMFFile(comm, args.xdmf, "w") as f:
            f.write_mesh(solver.mesh_data.mesh)
            f.write_function(solver.u)
    if comm.rank == 0:
        out = {**result.summary(), "mesh": solver.mesh_info(), "geometry": asdict(geo),
               "ranks": comm.size}
        if jac is not None:
            out["jacobian"] = jac.tolist()
        if args.json:
            print(json.dumps(out))
        else:
            print(f"load P={load.P} MPa F1={load.F1} N F2={load.F2} N M={load.M} N*mm: "
                  f"converged={result.converged} {result.reason}")
            for i, (x, y) in enumerate(result.anchors, 1):
                print(f"  r_{i:<2d} = ({x:9.4f}, {y:9.4f}) mm")
            print(f"  phi_end = {out['phi_end_deg']:.3f} deg, cap rotation = "
                  f"{out['cap_rotation_deg']:.3f} deg")
            print(f"  Newton iterations {result.newton_iterations}, {result.wall_time:.1f} s, "
                  f"{out['mesh']['nodes']} nodes, {out['mesh']['dofs']} dofs, {comm.size} rank(s)")
            if jac is not None:
                print("  d(anchors)/d(P, F1, F2, M), rows x_1, y_1, x_2, ...:")
                for row in jac:
                    print("   " + " ".join(f"{v:12.5g}" for v in row))
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
