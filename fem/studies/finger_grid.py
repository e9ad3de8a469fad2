"""The whole-finger FEM over the pressure box: an N x N grid of gravity gestures (issue 36 §1, issue 56 §2).

    python -m fem.studies.finger_grid [--cases results/validation/finger_fem] [--out results/fem/finger_grid.json]
                              [--points 7] [--mesh-size H | --divisions N] [--formulation mixed]
                              [--no-plane] [--suffix S] [--summary-only]

Every pair (P1, P2) of the grid p_i = -P_max + 2 P_max i / (N - 1), i = 0 .. N-1, over each
joint's box [-P_max, P_max] MPa (the paper's finger: [-0.3, 0.3]^2, 7 x 7 = 49 pairs), with
gravity, is one case of fem.studies.finger_cases: the same solve (FingerSolver.solve from the
unloaded state on one mesh built once: load path, cut-back, Newton), the same record,
render and file, ``<cases>/gravity_P1_P2<suffix>.json`` and ``.png`` (fem.studies.finger_records.
case_name, default_suffix: on the production mesh with the plane ``_hex2s3_plane``), the
same resume rule (record_stands: a record of the same settings that converged, or failed
under the same solver controls, stands and is skipped, whoever wrote it, e.g.
``python -m fem.studies.finger_cases --plane --pressures ...``). The problem is fem.solvers.finger's
default, the gripper (the mirror finger's contact at X = 0); ``--no-plane`` solves one
finger alone (suffix without ``_plane``).

``--out`` (format fem.artefacts.FINGER_GRID) is the summary of those records, rewritten
(atomically) after every case and rebuilt from the committed records without solving
when every pair stands or with ``--summary-only`` (pairs without a standing record are
pending): the run's ``settings`` (finger digest and geometry, formulation, points, gravity,
plane), ``solver`` controls, ``cases_folder`` and ``suffix``, ``mesh`` (of the records),
and a list ``cases`` in grid order (P1 fastest), one per standing record: ``p1``, ``p2``
(MPa), ``converged``, ``plane``, ``wall_s`` and ``cpu_s`` (the record's fem_s and fem_cpu_s,
s, one process; one core's share under load), the Newton figures (``newton_iterations`` in
total and ``newton_per_step``, ``load_steps``, ``cutbacks``, ``factorisations``), the
fingertip (``tip`` mm, ``tip_angle_deg``), ``plane_force_N`` and ``plane_overlap_mm`` (null
unless converged, or without the plane), ``reason``, ``load_average`` and ``file``; then the
headline figures (``summary``): ``pairs``, ``solved``, ``converged``, ``complete`` (every
pair stands), ``max_wall_s``, ``median_wall_s``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from contract import cli
from contract.files import json_safe
from contract.finger import FingerSpec, finger_arg, load_finger
from fem.artefacts import FINGER_CASE, FINGER_GRID
from fem.mesh.geometry import pressure_limits
from fem.options import add_finger_mesh, add_plane_flags, finger_discretisation
from fem.studies.finger_records import (case_name, case_settings, default_suffix, parse_on_one_rank, pending, solve_cases,
                                        solver_settings)


def grid_pairs(limits: np.ndarray, points: int) -> list[tuple[float, float]]:
    """The (P1, P2) pairs (MPa) of the points x points grid over [-l1, l1] x [-l2, l2],
    P1 varying fastest; values rounded to 1e-12 so that 0 is 0 (and 0.1 is 0.1: the case
    names of fem.studies.finger_records.case_name)."""
    axes = [np.round(np.linspace(-limit, limit, points), 12) + 0.0 for limit in limits]
    return [(float(p1), float(p2)) for p2 in axes[1] for p1 in axes[0]]


def grid_cases(pairs: list[tuple[float, float]]) -> list[tuple[str, float, float, bool]]:
    """The pairs as fem.studies.finger_cases cases: (gravity_P1_P2, P1, P2, gravity on)."""
    return [(case_name(p1, p2), p1, p2, True) for p1, p2 in pairs]


def case_record(p1: float, p2: float, record: dict, file: str = "") -> dict:
    """One grid case of the summary from a fem.studies.finger_cases record (FINGER_CASE)."""
    return {"p1": p1, "p2": p2, "converged": bool(record["converged"]),
            "plane": bool(record.get("settings", {}).get("plane", False)),
            "wall_s": record["fem_s"], "cpu_s": record.get("fem_cpu_s"),
            "newton_iterations": int(sum(record.get("newton_iterations", []))),
            "newton_per_step": list(record.get("newton_iterations", [])),
            "load_steps": record.get("load_steps", 0), "cutbacks": record.get("cutbacks", 0),
            "factorisations": record.get("factorisations", 0), "tip": record["tip"],
            "tip_angle_deg": record["tip_angle_deg"], "plane_force_N": record.get("plane_force_N"),
            "plane_overlap_mm": record.get("plane_overlap_mm"), "reason": record.get("reason", ""),
            "load_average": record.get("load_average"), "file": file}


def summary(cases: list[dict], n_pairs: int) -> dict:
    """The grid's headline figures: converged count, slowest and median solve (s)."""
    walls = [c["wall_s"] for c in cases]
    return {"pairs": n_pairs, "solved": len(cases), "converged": sum(c["converged"] for c in cases),
            "complete": len(cases) == n_pairs,
            "max_wall_s": max(walls) if walls else None,
            "median_wall_s": float(np.median(walls)) if walls else None}


def grid_summary(cases: list, folder: Path, suffix: str, settings: dict, solver: dict,
                 finger: FingerSpec) -> dict | None:
    """The summary document (module docstring) of the standing records of ``cases``
    [(name, P1, P2, gravity)] in ``folder`` (fem.studies.finger_records.pending's rule), None when
    none stands. ``settings``: fem.studies.finger_records.case_settings of the run, completed with
    the grid's own (points, gravity, plane, formulation)."""
    waiting = {c[0] for c in pending(cases, folder, suffix, settings["case"], solver, finger)}
    rows, mesh = [], None
    for name, p1, p2, _ in cases:
        if name in waiting:
            continue
        path = Path(folder) / f"{name}{suffix}.json"
        record = FINGER_CASE.load(path)
        mesh = mesh or record["mesh"]
        rows.append(case_record(p1, p2, record, path.name))
    if not rows:
        return None
    grid = {k: v for k, v in settings.items() if k != "case"}
    return {"finger": finger.summary(), "settings": json_safe({**settings["case"], **grid}), "solver": solver,
            "cases_folder": str(folder), "suffix": suffix, "mesh": mesh, "cases": rows,
            **summary(rows, len(cases))}


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.studies.finger_grid", description=__doc__.split("\n\n")[0])
    ap.add_output("--cases", folder=True, default="results/validation/finger_fem",
                  help="folder of the grid's fem.studies.finger_cases records (default results/validation/finger_fem)")
    ap.add_output("--out", suffix=".json", default="results/fem/finger_grid.json",
                  help="the grid's summary JSON (default results/fem/finger_grid.json)")
    ap.add_argument("--points", type=cli.number(2, 21, integer=True), default=7,
                    help="grid points per pressure axis (default 7: 49 pairs)")
    ap.add_argument("--finger", type=finger_arg, default=None, help="finger file (default: the paper's)")
    add_finger_mesh(ap)
    add_plane_flags(ap, "; file names end in _plane with the plane")
    ap.add_argument("--suffix", default=None, help="appended to each case's file name (default fem.studies.finger_records': "
                    "_hex2s3_plane on the production mesh with the plane)")
    ap.add_argument("--summary-only", action="store_true",
                    help="solve nothing: rebuild --out from the records that stand (the others pending)")
    cli.add_quiet(ap)
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    args, comm = parse_on_one_rank(ap, argv)
    finger = args.finger or load_finger()
    if finger.n_joints != 2:
        ap.error(f"--finger: finger {finger.name!r} has {finger.n_joints} joint(s); the grid is over "
                 "pressure pairs of a two-joint finger")
    cli.setup_logging(args.quiet)
    geometry, formulation = finger_discretisation(ap, args, finger)
    settings = {"case": case_settings(finger, geometry, formulation, args.plane), "formulation": formulation,
                "points": args.points, "gravity": True, "plane": args.plane}
    solver = solver_settings(geometry)
    suffix = default_suffix(geometry.joint, formulation, args.plane) if args.suffix is None else args.suffix
    cases = grid_cases(grid_pairs(pressure_limits(finger), args.points))
    folder, out = Path(args.cases), Path(args.out)

    def write_summary(*_) -> dict | None:
        doc = grid_summary(cases, folder, suffix, settings, solver, finger)
        if doc is not None:
            cli.make_output_folder(out.parent)
            FINGER_GRID.write(out, doc)
        return doc

    todo = [] if args.summary_only else pending(cases, folder, suffix, settings["case"], solver, finger)
    if todo:
        with ap.errors(), cli.heartbeat("finger grid"):
            solve_cases(todo, geometry, formulation, args.plane, settings["case"], solver, comm, after=write_summary)
    with ap.errors():
        doc = write_summary()
    if doc is None:
        print(f"{ap.prog}: no case of the grid stands in {folder} (suffix {suffix!r}); {out} not written")
        return 0
    print(f"{ap.prog}: {doc['converged']} of {doc['solved']} standing pairs converged ({doc['pairs']} in the grid"
          + ("" if doc["complete"] else f", {doc['pairs'] - doc['solved']} pending") + f") -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
