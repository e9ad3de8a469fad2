"""The whole-finger FEM's command line (fem.solvers.finger's solver, fem.solvers.grasp's with --object).

    python -m fem.cli.finger --p1 0.1 --p2 -0.1 [--no-gravity] [--mesh-size H | --divisions N]
                             [--finger FILE] [--formulation mixed] [--xdmf OUT.xdmf] --json
    python -m fem.cli.finger --finger FILE --pressures 0.1,-0.05,0.2     # any number of joints
    python -m fem.cli.finger --p1 0.2 --p2 0.2 --no-plane  # one finger alone: it may cross X = 0
    python -m fem.cli.finger --p1 0.2 --p2 0.25 --object circle [--approach -0.15,0] [--mu 0.3]
    mpirun -n 2 python -m fem.cli.finger --p1 0.1 --p2 0.1

``python -m fem.finger``, its old path, runs it too (fem/finger.py). The model, its outputs and units are
fem.solvers.finger's (a gesture) and fem.solvers.grasp's (a grasp); this module reads the options, checks
them against the finger (each joint's pressure box, the approach), solves on every rank of
MPI.COMM_WORLD and prints on rank 0: the figures as JSON (--json) or as text. Exit 0
converged, 1 not converged (no figures), 2 bad input (one line).
"""
from __future__ import annotations

import argparse
import logging
import math
import sys

from mpi4py import MPI

from contract import cli
from contract.finger import FingerSpec, finger_arg, load_finger
from contract.grasp import APPROACH_P1, FRICTION, OBJECT_WEIGHT, ObjectSpec, approach_for, parse_object
from contract.joint import joint_digest
from fem.solvers.finger import FingerLoad, FingerResult, FingerSolver
from fem.mesh.geometry import FingerGeometry, finger_joints, pressure_limits
from fem.solvers.grasp import GraspSolver, ObjectCutsFinger
from fem.options import add_finger_mesh, add_plane_flags, finger_discretisation
from fem.cli.xdmf import write_xdmf

log = logging.getLogger("softjoint.fem")

MAX_JOINTS = 4        # --p1 .. --p4


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.cli.finger", description="Solve one whole-finger gesture with DOLFINx.")
    pressure = cli.number(unit="MPa")     # each joint's box is checked once the finger is read
    for j in range(1, MAX_JOINTS + 1):
        ap.add_argument(f"--p{j}", type=pressure, default=None,
                        help=f"joint-{j} pressure, MPa (|P| <= its joint's input box, the paper's 0.3; default 0)")
    ap.add_argument("--pressures", type=cli.number_list(unit="MPa"), metavar="P1,P2,...",
                    help="every joint's pressure, MPa, base to tip (any number of joints; instead of --p1..--p4)")
    ap.add_argument("--no-gravity", action="store_true", help="no weights (free pressurisation)")
    add_plane_flags(ap)
    ap.add_argument("--finger", type=finger_arg, default=None,
                    help="finger description file (default: contract/fingers/paper.toml); its joint parts "
                         "name their joint files (default: the paper's joint)")
    add_finger_mesh(ap)
    ap.add_output("--xdmf", suffix=".xdmf", help="also write the displacement field (+ its .h5)")
    add_grasp_arguments(ap)
    cli.add_quiet(ap)
    ap.add_argument("-v", "--verbose", action="store_true", help="also log every Newton iteration")
    return ap


def parsed_pressures(ap: cli.Parser, args: argparse.Namespace, finger: FingerSpec) -> tuple[float, ...]:
    """One pressure per joint of ``finger`` (MPa) from --pressures or --p1..--p4 (missing
    ones 0), each within its joint's box; a count that does not fit the finger, or a
    pressure beyond its box, is a usage error."""
    n = finger.n_joints
    given = [j for j in range(1, MAX_JOINTS + 1) if getattr(args, f"p{j}") is not None]
    if args.pressures is not None:
        if given:
            ap.error(f"give either --p1..--p{MAX_JOINTS} or --pressures, not both")
        if len(args.pressures) != n:
            ap.error(f"--pressures: {len(args.pressures)} values for finger {finger.name!r} of {n} joint(s)")
        flags, pressures = ["--pressures"] * n, tuple(args.pressures)
    else:
        if given and max(given) > n:
            ap.error(f"--p{max(given)} given, but finger {finger.name!r} has {n} joint(s)")
        flags = [f"--p{j}" for j in range(1, n + 1)]
        pressures = tuple(getattr(args, f"p{j}", None) or 0.0 for j in range(1, n + 1))
    for flag, p, limit in zip(flags, pressures, pressure_limits(finger)):
        if abs(p) > limit:
            ap.error(f"argument {flag}: {p:g} is outside [{-limit:g}, {limit:g}] MPa (its joint's input box)")
    return pressures


def _print_text(out: dict, result: FingerResult, finger: FingerSpec, ranks: int) -> None:
    load = result.load
    print(f"finger {finger.name!r}, P = {list(load.pressures)} MPa, gravity {load.gravity}: "
          f"converged={result.converged} {result.reason}")
    if result.converged:
        print(f"  tip = ({result.tip[0]:.4f}, {result.tip[1]:.4f}) mm, "
              f"tip angle {math.degrees(result.tip_angle):.3f} deg")
        for j, s in enumerate(out["joints"]):
            print(f"  joint {j + 1}: end angle {s['end_angle_deg']:.3f} deg, chord {s['chord_angle_deg']:.3f} deg, "
                  f"cap rotation {s['cap_rotation_deg']:.3f} deg")
        if out["plane_force_N"] is not None:
            bx, by = out["base_force_N"]
            print(f"  plane X = 0: force {out['plane_force_N']:.4f} N, overlap {out['plane_overlap_mm']:.4f} mm, "
                  f"base force ({bx:.4f}, {by:.4f}) N")
    else:
        print("  tip = none (did not converge)")
    print(f"  {result.load_steps} load steps, Newton {result.newton_iterations}, "
          f"{result.wall_time:.1f} s, mesh {out['mesh']['mesh']}: {out['mesh']['nodes']} nodes ({out['formulation']}), "
          f"{ranks} rank(s)")


def add_grasp_arguments(ap: cli.Parser) -> None:
    """--object, --approach, --mu, --object-weight: a grasp (fem.solvers.grasp)."""
    ap.add_argument("--object", type=object_arg, default=None,
                    help="hold a rigid object, kind[:key=value,...] as predictor.cli.gesture --object "
                         "(circle, ellipse, rectangle; mm, deg): the approach, the object, the pressure ramp")
    ap.add_argument("--approach", type=cli.number_list(unit="MPa"), metavar="P1,P2", default=None,
                    help="with --object: the approach pressures, one per joint (default joint 1 at "
                         f"{APPROACH_P1:g} MPa, the others 0)")
    ap.add_argument("--mu", type=cli.number(0.0, 10.0), default=FRICTION,
                    help=f"with --object: friction coefficient (default {FRICTION:g})")
    ap.add_argument("--object-weight", type=cli.number(0.0, 100.0, unit="N"), default=OBJECT_WEIGHT,
                    help=f"with --object: its weight, N (default {OBJECT_WEIGHT:g})")


def object_arg(text: str) -> ObjectSpec:
    """argparse type of --object (contract.grasp.parse_object)."""
    try:
        return parse_object(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def parsed_approach(ap: cli.Parser, args: argparse.Namespace, finger: FingerSpec) -> tuple[float, ...]:
    """The approach pressures (MPa) of a grasp: one per joint, each within its box."""
    if args.object is None:
        if args.approach is not None:
            ap.error("--approach needs --object")
        return ()
    if args.no_gravity:
        ap.error("--object: a grasp lifts the object's weight; drop --no-gravity")
    approach = approach_for(finger.n_joints) if args.approach is None else tuple(args.approach)
    if len(approach) != finger.n_joints:
        ap.error(f"--approach: {len(approach)} values for finger {finger.name!r} of {finger.n_joints} joint(s)")
    for j, (p, limit) in enumerate(zip(approach, pressure_limits(finger))):
        if abs(p) > limit:
            ap.error(f"argument --approach: P{j + 1} = {p:g} is outside [{-limit:g}, {limit:g}] MPa")
    return approach


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    finger = args.finger or load_finger()
    load = FingerLoad(parsed_pressures(ap, args, finger), not args.no_gravity)
    approach = parsed_approach(ap, args, finger)
    cli.setup_logging(args.quiet, args.verbose)
    geometry, formulation = finger_discretisation(ap, args, finger)
    if args.object is not None:
        return grasp(ap, args, geometry, formulation, load, approach)
    comm = MPI.COMM_WORLD
    with ap.errors(), cli.heartbeat(f"finger {finger.name!r}", enabled=comm.rank == 0):
        if comm.rank == 0:
            log.info("finger %r: meshing and compiling the forms (the first run compiles for tens of seconds)",
                     finger.name)
        solver = FingerSolver(geometry, comm, formulation=formulation, plane=args.plane)
        if comm.rank == 0:
            log.info("mesh ready (%d nodes); solving P = %s MPa, gravity %s", solver.mesh_info()["nodes"],
                     list(load.pressures), load.gravity)
        result = solver.solve(load)
        if args.xdmf and result.converged:
            write_xdmf(args.xdmf, solver)
    if comm.rank == 0:
        out = {**result.summary(), "finger": finger.summary(), "mesh": solver.mesh_info(),
               "geometry": geometry.as_dict(), "formulation": formulation, "plane": args.plane,
               "joint_files": [{"name": j.name, "sha256": joint_digest(j)} for j in finger_joints(finger)],
               "ranks": comm.size}
        if args.json:
            cli.print_json(out)
        else:
            _print_text(out, result, finger, comm.size)
        if not result.converged:
            print(f"{ap.prog}: did not converge: {' '.join(result.reason.split()) or 'no reason given'}; no figures reported",
                  file=sys.stderr, flush=True)
    return 0 if result.converged else 1


def _print_grasp(out: dict) -> None:
    print(f"grasp: P = {out['pressures_MPa']} MPa from the approach {out['approach_MPa']} MPa: "
          f"state {out['state']} {out['reason']}")
    if out["tip"] is not None:
        print(f"  tip = ({out['tip'][0]:.4f}, {out['tip'][1]:.4f}) mm, tip angle {out['tip_angle_deg']:.3f} deg")
        print(f"  contact force {out['contact_force_N']:.4f} N, friction use {out['friction_use']}, "
              f"base force {out['base_force_N']} N")
    print(f"  {out['load_steps']} load steps, Newton {out['iterations']}, {out['grasp_wall_time_s']:.1f} s")


def grasp(ap: cli.Parser, args: argparse.Namespace, geometry: FingerGeometry, formulation: str,
          load: FingerLoad, approach: tuple[float, ...]) -> int:
    """The command with --object (fem.solvers.grasp): exit 0 converged, 1 not converged (figures
    null), 2 an object that cuts the approach gesture."""
    comm = MPI.COMM_WORLD
    with ap.errors(), cli.heartbeat("grasp", enabled=comm.rank == 0):
        solver = GraspSolver(geometry, args.object, comm, formulation, mu=args.mu, weight=args.object_weight,
                             plane=args.plane)
        try:
            result = solver.solve(load.pressures, approach)
        except ObjectCutsFinger as exc:
            ap.error(str(exc))
        if args.xdmf and result.finger.converged:
            write_xdmf(args.xdmf, solver.fem)
    if comm.rank == 0:
        out = {**result.summary(), "object": args.object.__dict__, "mu": args.mu,
               "object_weight_N": args.object_weight, "finger": geometry.finger.summary(),
               "mesh": solver.fem.mesh_info(), "formulation": formulation, "plane": args.plane,
               "ranks": comm.size}
        if args.json:
            cli.print_json(out)
        else:
            _print_grasp(out)
        if not result.finger.converged:
            print(f"{ap.prog}: did not converge: {' '.join(result.finger.reason.split())}; no figures reported",
                  file=sys.stderr, flush=True)
    return 0 if result.finger.converged else 1


if __name__ == "__main__":
    sys.exit(main())
