"""The grasp validation cases on the whole-finger FEM: one JSON record and one render per grasp.

    python -m fem.studies.grasp_cases --out results/validation/grasps_fem [--cases a,b] [--part K/N]
                              [--mesh-size H | --divisions N] [--formulation F] [--no-plane]
                              [--suffix S]
    python -m fem.studies.grasp_cases --grasps "circle:r=25@0.2,0.3;rectangle@0.25,0.2" --out DIR

Cases (issue 36 §3; pressures MPa, contract.grasp.GRASP_CASES): the paper's six grasps, each
default object of contract.grasp (circle r 30, ellipse 35 x 25, rectangle 60 x 50 with 1 mm
corners, centred at (0, -195) mm) at (0.2, 0.3) and (0.3, 0.2), and ten from the predictor's
atlases (61 x 61, outline contact and the plane X = 0) in the hold and slip regions and near their
boundary, each frozen with the atlas' state and friction use |lambda|/mu that chose it.
``--grasps "SPEC@P1,P2;..."`` solves other grasps instead (SPEC: ``--object``'s spec), named
like the table's: ``<spec>_<P1>_<P2>``, the spec without '=' and every run of other
characters than letters, digits, '.', '+' and '-' turned into '-' (``circle_0.2_0.3``,
``circle-r25_0.2_0.3``).

Each case is one ``fem.solvers.grasp.GraspSolver.solve`` along the predictor's history (that of
``predictor.cli.gesture --object``): the approach gesture ``contract.grasp.approach_for`` (joint 1
at -0.15 MPa) with gravity and without the object, the object brought in, the straight
pressure ramp to (P1, P2); contact law of contract.grasp (normal penalty k_c per area / width,
one friction ratio lambda = (W/2 + Σ N n_y) / Σ N t_y carrying the object's half weight W/2,
slip when |lambda| > mu), mu = 0.3 and W = 0.2 N, and the mirror finger's plane X = 0
(frictionless penalty k_p) unless ``--no-plane``. At equilibrium the clamp's reaction
balances the finger's weight, the object's force and the plane's push:

    base_force_N + object_force_N + (plane_force_N, 0) = (0, finger weight)     (N, global)

One solver (mesh and forms) per object; the discretisation defaults to the joint file's
[mesh] (the paper's joint: hex2:3 mixed u-p), as fem.studies.finger_cases.

Records (``<case><suffix>.json``, format fem.artefacts.GRASP_CASE): the case (``case``,
``region``, ``object`` spec, ``object_geometry`` as the predictor's atlas spells it, ``p1``,
``p2``), GraspResult.summary (``state``, ``tip``, ``tip_angle_deg``, ``contact_force_N``,
``friction_use``, ``contact_point_mm``, ``contact_patch``, ``object_force_N``,
``base_force_N``, ``plane_force_N``, ...; null figures unless converged), ``mu``,
``object_weight_N``, ``plane``, ``fem_s`` and ``fem_cpu_s`` (the whole history, s; CPU of
this process), ``load_average``, ``setup_s`` (the object's mesh and forms), ``mesh``,
``formulation``, ``settings``, ``solver`` (the controls) and ``ranks``. A converged case also
gets ``<case><suffix>.png``: fem.studies.finger_records.render's deformed finger (global plane, seen
along -z, parallel projection, coloured by |u|) with the object's outline in black, and
``render`` (``extent_mm`` [X0, X1, Y0, Y1] of the image, ``u_max_mm``, ``cmap``) to overlay it.

Resume and suffix as fem.studies.finger_cases (fem.studies.finger_records.record_stands, its code): a record of the same settings
(finger, mesh, formulation, plane, and the grasp's object, approach, mu and W) that converged
is skipped, a failed one is solved again once the solver controls change, a damaged or
foreign file is solved again and replaced. Default suffix: fem.studies.finger_records.default_suffix of
the discretisation (``_hex2s3`` on the production mesh, ``_mixed`` on mixed tetrahedra), then
``_noplane`` with ``--no-plane``. Files are written atomically.

Bad input (an unknown case, a pressure outside its joint's box, a bad object spec, an
unwritable ``--out`` or one that is a file) is refused in one line, exit 2, before any
meshing. An object that cuts the finger at the approach gesture (fem.solvers.grasp.ObjectCutsFinger;
a ``--grasps`` object placed too high) stops the run there the same way, the cases written
before it kept. ``--json``: instead of a line per case, one JSON object at the end: ``out``,
``suffix``, ``solved`` (each case solved in this run: case, state, converged, tip,
tip_angle_deg, contact_force_N, friction_use, fem_s) and ``up_to_date`` (the chosen cases
whose records stood).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fem.studies.finger_records as finger_records     # pyvista before dolfinx (its import order)
from contract import cli
from contract.finger import load_finger
from contract.grasp import (FRICTION, GRASP_CASES, OBJECT_WEIGHT, GraspCase, ObjectSpec, approach_for,
                            parse_object)
from fem.artefacts import GRASP_CASE
from fem.mesh.geometry import pressure_limits
from fem.options import add_finger_mesh, finger_discretisation
from fem.solvers.grasp import GraspSolver

OUTLINE_POINTS = 720        # the render's object outline


def grasp_list(text: str) -> list[GraspCase]:
    """argparse type of --grasps: "SPEC@P1,P2;..." (MPa) -> cases; a bad object spec, not two
    finite pressures or a name given twice is refused in one line (the joints' boxes are
    checked once the finger is read)."""
    pair = cli.numbers(2, unit="MPa")
    cases = []
    for item in filter(None, (s.strip() for s in text.split(";"))):
        spec, at, pressures = item.rpartition("@")
        if not at:
            raise argparse.ArgumentTypeError(f"{item!r}: use SPEC@P1,P2 (e.g. circle:r=25@0.2,0.3)")
        try:
            parse_object(spec)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        cases.append(GraspCase(spec.strip(), *pair(pressures.strip())))
    names = [c.name for c in cases]
    twice = sorted({n for n in names if names.count(n) > 1})
    if not cases or twice:
        raise argparse.ArgumentTypeError(f"{text!r}: " + (f"{', '.join(twice)} given twice" if twice else "no grasp"))
    return cases


def object_geometry(ob: ObjectSpec) -> dict:
    """The object as the predictor's atlas records it (mm, rad): kind, a_mm, b_mm, x_mm,
    y_mm, angle_rad, and for a rectangle corner_mm."""
    out = {"kind": ob.kind, "a_mm": ob.a, "b_mm": ob.b, "x_mm": ob.x, "y_mm": ob.y, "angle_rad": ob.angle}
    if ob.kind == "rectangle":
        out["corner_mm"] = ob.corner
    return out


def grasp_settings(base: dict, ob: ObjectSpec, approach, mu: float, weight: float) -> dict:
    """A case's settings (the resume key): fem.studies.finger_records.case_settings ``base`` and the
    grasp's object, approach (MPa), mu and W (N)."""
    return {**base, "grasp": {"object": object_geometry(ob), "approach_MPa": [float(p) for p in approach],
                              "mu": mu, "object_weight_N": weight}}


def default_suffix(joint, formulation: str, plane: bool) -> str:
    """fem.studies.finger_records.default_suffix of the discretisation, then ``_noplane`` without the
    plane X = 0 (the grasps' default has it)."""
    return finger_records.default_suffix(joint, formulation) + ("" if plane else "_noplane")


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.studies.grasp_cases", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", folder=True, default="results/validation/grasps_fem",
                  help="folder for <case>.json and <case>.png (default results/validation/grasps_fem)")
    add_finger_mesh(ap)
    ap.add_argument("--cases", help="comma-separated case names (default: all): "
                    + ", ".join(c.name for c in GRASP_CASES))
    ap.add_argument("--grasps", type=grasp_list, metavar="SPEC@P1,P2;...",
                    help="solve these grasps instead of the table (object spec as --object, MPa; ';' between)")
    ap.add_argument("--no-plane", action="store_true",
                    help="without the mirror finger's contact at X = 0 (file names end in _noplane)")
    ap.add_argument("--part", default="1/1", help="K/N: run every N-th case starting at the K-th")
    ap.add_argument("--suffix", default=None, help="appended to each file name (default: fem.studies.finger_records' "
                    "for the discretisation, _hex2s3 on the production mesh, then _noplane without the plane)")
    cli.add_quiet(ap)
    return ap


def chosen_cases(ap: cli.Parser, args: argparse.Namespace, limits: np.ndarray) -> list[GraspCase]:
    """The cases of --grasps or the table, those --cases names, this --part's share; an
    unknown name or a pressure beyond its joint's box is a usage error."""
    table = args.grasps or GRASP_CASES
    names = [c.name for c in table]
    chosen = args.cases.split(",") if args.cases else names
    for name in chosen:
        if name not in names:
            ap.error(f"unknown case {name!r}: use {', '.join(names)}")
    cases = [c for c in table if c.name in chosen][finger_records.part_slice(ap, args.part)]
    for case in cases:
        for j, (p, limit) in enumerate(zip((case.p1, case.p2), limits), 1):
            if abs(p) > limit:
                ap.error(f"case {case.name}: P{j} = {p:g} is outside [{-limit:g}, {limit:g}] MPa "
                         "(its joint's input box)")
    return cases


def case_record(case: GraspCase, ob: ObjectSpec, result, cpu_s: float, common: dict) -> dict:
    """One case's record (module docstring) from its GraspResult; ``common``: the run's
    keys (mesh, formulation, settings, solver, ranks, ...)."""
    return {"case": case.name, "region": case.region, "object": case.spec, "object_geometry": object_geometry(ob),
            "p1": case.p1, "p2": case.p2, **result.summary(), "fem_s": result.wall_time, "fem_cpu_s": cpu_s,
            "load_average": os.getloadavg()[0], **common}


def case_line(record: dict) -> str:
    """One line of a solved case for the terminal."""
    if not record["converged"]:
        return f"{record['case']}: did not converge ({' '.join(record['reason'].split())}), no figures"
    use = record["friction_use"]
    return (f"{record['case']}: {record['state']}, tip ({record['tip'][0]:.3f}, {record['tip'][1]:.3f}) mm, "
            f"N {record['contact_force_N']:.4f} N, friction use {'-' if use is None else f'{use:.3f}'}, "
            f"{record['fem_s']:.0f} s")


def solve_object(ob: ObjectSpec, todo: list, geometry, formulation: str, plane: bool, approach, run: dict,
                 say) -> list[dict]:
    """Solve ``todo`` [(case, path, settings)], all holding ``ob``, on one GraspSolver,
    write each record (and render) atomically and ``say`` it; returns the records."""
    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    solver = GraspSolver(geometry, ob, comm, formulation, mu=FRICTION, weight=OBJECT_WEIGHT, plane=plane)
    setup_s = time.perf_counter() - t0
    records = []
    for case, path, settings in todo:
        c0 = time.process_time()
        result = solver.solve((case.p1, case.p2), approach)
        record = case_record(case, ob, result, time.process_time() - c0,
                             {"mu": FRICTION, "object_weight_N": OBJECT_WEIGHT, "plane": plane, "setup_s": setup_s,
                              "mesh": solver.fem.mesh_info(), "formulation": formulation, "settings": settings,
                              **run})
        finger_records.write_case(path, record, GRASP_CASE, solver.fem, result.finger.converged,
                                ob.outline(OUTLINE_POINTS))
        say(case_line(record))
        records.append(record)
    return records


def main(argv=None) -> int:
    ap = build_parser()
    args, comm = finger_records.parse_on_one_rank(ap, argv)
    finger = load_finger()
    cases = chosen_cases(ap, args, pressure_limits(finger))
    approach = approach_for(finger.n_joints)
    cli.setup_logging(args.quiet)
    geometry, formulation = finger_discretisation(ap, args, finger)
    plane = not args.no_plane
    base = finger_records.case_settings(finger, geometry, formulation, plane)
    solver = finger_records.solver_settings(geometry)
    suffix = default_suffix(geometry.joint, formulation, plane) if args.suffix is None else args.suffix
    out = Path(args.out)
    todo: dict[ObjectSpec, list] = {}       # per object, in the table's order
    for case in cases:
        ob = parse_object(case.spec)
        path = out / f"{case.name}{suffix}.json"
        settings = grasp_settings(base, ob, approach, FRICTION, OBJECT_WEIGHT)
        if not finger_records.record_stands(path, settings, solver, finger):
            todo.setdefault(ob, []).append((case, path, settings))
    say = (lambda line: None) if args.json else (lambda line: print(line, flush=True))
    records = []
    if not todo:
        say(f"{ap.prog}: all {len(cases)} cases are up to date in {out}")
    with ap.errors(), cli.heartbeat("grasp cases"):
        for ob, items in todo.items():
            records += solve_object(ob, items, geometry, formulation, plane, approach,
                                    {"solver": solver, "ranks": comm.size}, say)
    if args.json:
        keys = ("case", "state", "converged", "tip", "tip_angle_deg", "contact_force_N", "friction_use", "fem_s")
        solved = {r["case"] for r in records}
        cli.print_json({"out": str(out), "suffix": suffix, "solved": [{k: r[k] for k in keys} for r in records],
                        "up_to_date": [c.name for c in cases if c.name not in solved]})
    return 0


if __name__ == "__main__":
    sys.exit(main())
