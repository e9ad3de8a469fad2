"""Command line: solve one joint load case.

    python -m fem.cli.solve --p 0.2 --f1 1 --f2 -1 --m 20 --json
    python -m fem.cli.solve --p 0.2 --formulation mixed --mesh-size 2.4 --wall-mesh-size 1.2
    python -m fem.cli.solve --p 0.2 --formulation mixed --divisions 2
    python -m fem.cli.solve --joint my_joint.toml --p 0.1 --json
    mpirun -n 2 python -m fem.cli.solve --p -0.1 --m 50

The joint is a joint description file (``--joint``, contract.joint, docs/joints.md;
default the paper's, contract/joints/paper.toml): its shape, material law, anchors, input
box and default mesh (``--mesh-size`` and ``--wall-mesh-size`` for tetrahedra, or
``--divisions`` for swept Q2 hexahedra, and ``--formulation`` override the file's [mesh]).
A bad file exits 2 with one line naming its key. Inputs: P (MPa), F1, F2 (N), M (N·mm);
outside the joint's box (the paper's: |P|<=0.3, |F1|,|F2|<=3, |M|<=100) the load
is refused before meshing unless --allow-extrapolation (then recorded as
"extrapolated": true). Prints the anchors r_1..r_n (mm), phi_end and the cap rotation
(deg), Newton iterations and wall time; with --jacobian also d(anchors)/d(P, F1, F2, M),
shape (2n, 4), rows (x_1, y_1, x_2, ...), columns mm/MPa, mm/N, mm/N, mm/(N·mm); with
--xdmf the displacement field (NAME.xdmf + NAME.h5, written by all ranks into a hidden
folder beside them, then renamed into place; for the mixed formulation u alone). The
formulation is in the output and the JSON ("formulation"), and so is the joint
("joint": its name and sha256, contract.joint.joint_digest). Exit status 0 on convergence, 1 if the
solve failed, 2 on bad input. Progress (mesh, load steps) goes to stderr unless --quiet;
stdout holds the result alone.
"""

from __future__ import annotations

import logging
import sys
from dataclasses import asdict

from mpi4py import MPI

from contract import cli
from contract.joint import joint_digest
from fem.options import (add_divisions, add_formulation, add_joint, add_load, add_mesh_size, add_wall_mesh_size, formulation_of,
                         joint_geometry, joint_of, parsed_load)
from fem.solvers.joint import JointSolver, Load
from fem.cli.xdmf import write_xdmf

log = logging.getLogger("softjoint.fem")


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.cli.solve",
                    description="Solve one bellow-joint load case with DOLFINx.")
    add_joint(ap)
    add_load(ap)
    add_mesh_size(ap, None, shown="the joint file's [mesh] size")
    add_wall_mesh_size(ap)
    add_divisions(ap)
    add_formulation(ap, "the joint file's [mesh] formulation (the paper's: the production one)")
    ap.add_argument("--jacobian", action="store_true",
                    help="also print d(anchors)/d(P, F1, F2, M) from the converged tangent")
    ap.add_output("--xdmf", suffix=".xdmf",
                  help="also write the displacement field to this XDMF file (+ its .h5)")
    cli.add_quiet(ap)
    ap.add_argument("-v", "--verbose", action="store_true", help="also log every Newton iteration")
    return ap


def _print_text(out: dict, result, jac) -> None:
    load = result.load
    print(f"load P={load.P} MPa F1={load.F1} N F2={load.F2} N M={load.M} N*mm: "
          f"converged={result.converged} {result.reason}")
    for i, (x, y) in enumerate(result.anchors, 1):
        print(f"  r_{i:<2d} = ({x:9.4f}, {y:9.4f}) mm")
    print(f"  phi_end = {out['phi_end_deg']:.3f} deg, cap rotation = "
          f"{out['cap_rotation_deg']:.3f} deg")
    print(f"  Newton iterations {result.newton_iterations}, {result.wall_time:.1f} s, "
          f"{out['mesh']['nodes']} nodes, {out['mesh']['dofs']} dofs ({out['formulation']}), "
          f"{out['ranks']} rank(s)")
    if jac is not None:
        print("  d(anchors)/d(P, F1, F2, M), rows x_1, y_1, x_2, ...:")
        for row in jac:
            print("   " + " ".join(f"{v:12.5g}" for v in row))


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    joint = joint_of(args)
    load = Load.from_array(parsed_load(ap, args, joint.input_box))
    comm = MPI.COMM_WORLD
    cli.setup_logging(args.quiet, args.verbose)
    with ap.errors():
        geo = joint_geometry(args, joint)
    formulation = formulation_of(args, joint)
    with ap.errors(), cli.heartbeat("joint", enabled=comm.rank == 0):
        if comm.rank == 0:
            log.info("joint %r: meshing and compiling the forms (the first run compiles for tens of seconds)",
                     joint.name)
        solver = JointSolver.for_joint(joint, comm, geo, formulation=formulation)
        if comm.rank == 0:
            log.info("mesh ready (%d nodes); solving %s", solver.mesh_info()["nodes"], load)
        result = solver.solve(load, allow_extrapolation=args.allow_extrapolation)
        jac = solver.sensitivities() if args.jacobian and result.converged else None
        if args.xdmf and result.converged:
            write_xdmf(args.xdmf, solver)
    if comm.rank == 0:
        out = {**result.summary(), "mesh": solver.mesh_info(), "geometry": asdict(geo),
               "formulation": formulation, "joint": {"name": joint.name, "sha256": joint_digest(joint)},
               "ranks": comm.size}
        if jac is not None:
            out["jacobian"] = jac.tolist()
        if args.json:
            cli.print_json(out)
        else:
            _print_text(out, result, jac)
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
