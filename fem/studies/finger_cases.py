"""The finger validation cases on the whole-finger FEM: JSON figures and a render per case.

    python -m fem.studies.finger_cases --out results/validation/finger_fem [--mesh-size 1.8 | --divisions N]
                               [--part 1/2] [--formulation displacement] [--no-plane]
    python -m fem.studies.finger_cases --finger FILE --pressures "0.2,0.2;-0.1,0.05" --out DIR

Cases (issue 14 §4; pressures MPa, the paper's finger unless --finger):
* free pressurisation without gravity (the paper's Figure 3): (0.05, 0.05), (0.1, 0.1),
  (0.05, -0.05), (0.1, -0.1);
* gravity (Figure 5A): (-0.1, 0.1), (0.1, -0.1);
* 12 more pairs with gravity spread over the box, among them the grasp region
  (0.2, 0.2) and (0.3, 0.3), none the mirror image (-P1, -P2) of another: with gravity
  along the finger at rest the mirror case is the mirror finger (tests/test_finger.py),
  so it would add no information.

``--pressures "P1,P2;P1,P2;..."`` solves other gravity cases instead (each pair within the
joints' boxes, named ``gravity_P1_P2`` as above; ``pressure_cases``): the calibration's
FEM observations of a deliberately different finger (``make calibration-fem``).

Each case is one ``FingerSolver.solve`` (every joint of its own joint file, fem.solvers.finger;
``--formulation`` and the mesh default to the first joint file's [mesh], for the paper's
joint the production discretisation, hex2:3 mixed; ``--divisions`` N: the finger on swept
Q2 hexahedra, fem.mesh.hexahedra, its records' ``mesh.mesh`` "hexN" or "hexN:S") on one mesh
built once. The committed cases (results/validation/finger_fem) are on the
paper-fidelity 1.8 mm displacement, one finger alone: ``make finger-fem`` passes
``--mesh-size 1.8 --formulation displacement --no-plane`` to resume them. It writes
``<case><suffix>.json`` and ``<case><suffix>.png`` into ``--out`` (suffix ``--suffix``,
by default fem.studies.finger_records.default_suffix's) and skips a case whose record stands
(the same finger, mesh and formulation; a failed one with the same solver controls), so a
killed run resumes: the records, the render and the skip rule are
fem.studies.finger_records', which fem.studies.finger_grid and grasp_cases share.

The problem (fem.solvers.finger, issue 56 §1): by default every case is the gripper's, the right
finger against the mirror finger's contact at X = 0 (fem.physics.plane_contact; the fingers meet
instead of passing through each other); ``--no-plane`` solves one finger alone (``--plane``,
the default now, is accepted for one release). A plane case's record carries
``plane_force_N``, ``plane_overlap_mm`` and ``base_force_N``, its settings ``"plane":
true`` (absent without it, so the cases solved before the plane stand) and its default
suffix ends in ``_plane``: a plane case never resumes from, nor replaces, a case without
it. The committed lone-finger cases (results/validation/finger_fem/<case>.json on 1.8 mm,
and the calibration's truth cases, results/calibration/fem on the production mesh and
fem_h1.8 on 1.8 mm) are resumed with ``--no-plane`` (``make finger-fem``, ``make
calibration-fem``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from contract import cli
from contract.finger import finger_arg, load_finger
from fem.mesh.geometry import pressure_limits
from fem.options import add_finger_mesh, add_plane_flags, finger_discretisation
from fem.studies.finger_records import (CASES, case_name, case_settings, default_suffix, parse_on_one_rank, part_slice,
                                        pending, solve_cases, solver_settings)


def pressure_cases(text: str) -> list[tuple[str, float, float, bool]]:
    """argparse type of --pressures: "P1,P2;P1,P2;..." (MPa) -> gravity cases as CASES
    holds them; a pair given twice, or not two finite numbers, is refused (one line; the
    joints' boxes are checked once the finger is read)."""
    pair = cli.numbers(2, unit="MPa")
    cases = []
    for item in text.split(";"):
        p1, p2 = pair(item.strip())
        cases.append((case_name(p1, p2), p1, p2, True))
    names = [c[0] for c in cases]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise argparse.ArgumentTypeError(f"{text!r}: {', '.join(twice)} given twice")
    return cases


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.finger_cases", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", folder=True, default="results/validation/finger_fem",
                  help="folder for <case>.json and <case>.png (default results/validation/finger_fem)")
    ap.add_argument("--finger", type=finger_arg, default=None, help="finger file (default: the paper's)")
    add_finger_mesh(ap)
    ap.add_argument("--cases", help="comma-separated case names (default: all): " + ", ".join(c[0] for c in CASES))
    ap.add_argument("--pressures", type=pressure_cases, metavar="P1,P2;...",
                    help="solve these gravity pressure pairs (MPa, ';' between pairs) instead of the validation cases")
    add_plane_flags(ap, "; file names end in _plane with the plane")
    ap.add_argument("--part", default="1/1", help="K/N: run every N-th case starting at the K-th (two processes: 1/2 and 2/2)")
    ap.add_argument("--suffix", default=None, help="appended to each file name (e.g. _h1.2 for a finer mesh; "
                    "default: _hexN or _hexNsS on hexahedra, _mixed on mixed tetrahedra, so that they never replace "
                    "the displacement tetrahedral cases, else none)")
    cli.add_quiet(ap)
    args, comm = parse_on_one_rank(ap, argv)
    table = args.pressures or CASES
    names = [c[0] for c in table]
    chosen = args.cases.split(",") if args.cases else names
    for name in chosen:
        if name not in names:
            ap.error(f"unknown case {name!r}: use {', '.join(names)}")
    cases = [c for c in table if c[0] in chosen][part_slice(ap, args.part)]
    finger = args.finger or load_finger()
    if finger.n_joints != 2:
        ap.error(f"--finger: finger {finger.name!r} has {finger.n_joints} joint(s); the validation cases "
                 "are pressure pairs for a two-joint finger (use python -m fem.cli.finger --pressures for others)")
    limits = pressure_limits(finger)
    for name, *pressures, _ in cases:
        for j, (p, limit) in enumerate(zip(pressures, limits), 1):
            if abs(p) > limit:
                ap.error(f"case {name}: P{j} = {p:g} is outside [{-limit:g}, {limit:g}] MPa (its joint's input box)")
    cli.setup_logging(args.quiet)
    geometry, formulation = finger_discretisation(ap, args, finger)
    settings = case_settings(finger, geometry, formulation, args.plane)
    solver = solver_settings(geometry)
    suffix = default_suffix(geometry.joint, formulation, args.plane) if args.suffix is None else args.suffix
    out = Path(args.out)
    todo = pending(cases, out, suffix, settings, solver, finger)
    if not todo:
        print(f"{ap.prog}: all {len(cases)} cases are up to date in {out}")
        return 0
    with ap.errors(), cli.heartbeat("finger cases"):
        solve_cases(todo, geometry, formulation, args.plane, settings, solver, comm)
    return 0


if __name__ == "__main__":
    sys.exit(main())
