"""The gesture predictor against the whole-finger FEM grasps: ``make validate-grasps`` (issue 36 §3).

    python -m predictor.validation.grasps --fem results/validation/grasps_fem \\
        --model results/surrogate/improved.pt --out results/validation/grasps.json \\
        --figures results/validation/grasps [--mesh hex2:3 --formulation mixed] [--finger FILE]

Data flow: the FEM grasp records of fem.studies.grasp_cases in ``--fem`` (one JSON, format
fem.artefacts.GRASP_CASE, and one render per converged case) -> those on one
discretisation (``--mesh``, ``--formulation``; default the paper joint file's ``[mesh]``,
the production hex2:3 mixed; selected as predictor.validation.finger does, by
predictor.validation.cases) -> for each, the
predictor (predictor.solvers.problem.load_problem, predictor.solvers.solve, Newton; the default finger
model) with the record's finger file, object, approach, mu, W and gravity, and the plane
X = 0 only where the record had it; timed as the median of REPEATS single-query solves in
this run -> differences, targets judged -> ``grasps.json`` (format
predictor.artefacts.GRASP_VALIDATION) and one overlay figure per converged FEM case.

Per case (the issue's keys, then more): ``object`` (the spec), ``p1``, ``p2`` (MPa),
``fem_state`` and ``predictor_state`` (holds, slips, no_contact, not_converged),
``fem_friction_use`` |lambda|/mu, and

    tip_error_mm              = |tip_pred - tip_FEM|                      (mm, global plane)
    tip_angle_error_deg       = angle_pred - angle_FEM                     (deg, signed)
    normal_force_{fem,predictor}_N: the whole finger's normal force N from the object (N)
    contact_location_error_mm = |c_pred - c_FEM|,  c = sum_k N_k p_k / sum_k N_k  (mm)

c is the normal-force-weighted mean contact point over everything that touches: the FEM's
``contact_point_mm`` (its surface nodes), the predictor's over every part face that carries
force (GestureResult.where_it_touches' contacts); null where nothing touches. Beside them
both sides' tip, tip angle, contact point, friction use, ``object_force_*_N`` (the object's
resultant on the finger, [X, Y] N: Y = -W/2 wherever it holds) and ``plane_force_*_N``
(the plane X = 0's push, N). ``fem_s``:
the FEM's whole history (its record), ``predictor_s``: the predictor's (approach, object
brought in, ramp), ``speedup`` = fem_s / predictor_s.

Targets (issue 36, ``TARGETS``), judged per case in ``met``: tip <= 1 mm, |tip angle| <=
0.5 deg, |N_pred - N_FEM| <= max(10 % of N_FEM, 0.02 N), contact location <= 2 mm (met
without a figure when neither touches), the same state wherever the FEM's friction use is
not within 0.05 of 1 (``None``: not judged, the FEM at the slip limit), fem_s <= 900 s,
speed-up >= 1e4. A case the FEM did not solve (its record not converged) is listed with
its state not_converged and meets nothing; one the predictor did not solve meets nothing
but the FEM's time. ``summary``: the worst of each figure over the cases both solved, and
per target how many cases met it of how many were judged.

The problem (issue 56 §1, as predictor.validation.finger): each record is the gripper's (the
plane X = 0, fem.studies.grasp_cases' default) or one finger alone's, and the predictor solves the
record's problem; ``--plane`` or ``--no-plane`` validates the records of that problem only,
and asking for a problem no record was solved for is refused (one line, exit 2). The JSON
records ``plane`` (the records' problem; null if they mix both) and ``discretisation``,
each case its ``plane`` and ``mesh``.

Bad input (no such folder, a JSON file that is not a grasp record or was solved for
another finger file, no record on the chosen discretisation, an unwritable ``--out`` or
``--figures``) is refused in one line, exit 2, before the model is loaded.
"""
from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import torch

from contract import cli
from contract.files import atomic_path
from contract.finger import load_finger, same_finger
from contract.joint import FORMULATIONS, load_joint as load_joint_file, mesh_text
from fem.artefacts import GRASP_CASE, finger_case_formulation, finger_case_mesh
from predictor.artefacts import GRASP_VALIDATION
from predictor.model.gripper import GripperParams
from predictor.model.joint import load_joint
from predictor.solvers.problem import load_problem
from predictor.solvers.progress import set_quiet
from predictor.solvers.solve import SolverOptions, solve
from predictor.model.statics import GripperProblem, apart
from predictor.validation.cases import mesh_arg, one_problem, split_cases

REPEATS = 5
#: issue 36's targets: fingertip (mm), tip angle (deg), normal force (fraction of the FEM's,
#: or N), contact location (mm), the FEM's friction-use band about 1 where the state is not
#: judged, the FEM's time per case (s, one core) and the predictor's speed-up over it.
TARGETS = {"tip_error_mm": 1.0, "tip_angle_error_deg": 0.5, "normal_force_rel": 0.10, "normal_force_N": 0.02,
           "contact_location_error_mm": 2.0, "friction_use_band": 0.05, "fem_s": 900.0, "speedup": 1e4}
#: the per-case verdicts, in the report's order
JUDGED = ("tip", "tip_angle", "normal_force", "contact_location", "state", "fem_time", "speedup")
FORCE_SCALE = 60.0          # mm of arrow per N in the overlays
OUTLINE_COLOURS = {"rigid": "tab:red", "joint": "magenta"}


def production_discretisation() -> tuple[str, str]:
    """(mesh text, formulation) of the paper joint file's ``[mesh]``: what fem.studies.grasp_cases
    solves by default (hex2:3, mixed)."""
    joint = load_joint_file()
    return (mesh_text(joint.mesh_size, joint.wall_mesh_size, joint.divisions, joint.hex_size),
            joint.formulation)


def read_records(folder: str | Path, finger) -> list[tuple[Path, dict]]:
    """[(path, record)] of every ``*.json`` in ``folder`` (sorted), each checked against
    GRASP_CASE and solved for ``finger``; ValueError (one line) otherwise."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"--fem {folder}: no such folder (the FEM grasps: run `make grasp-fem`, "
                         "python -m fem.studies.grasp_cases)")
    out = []
    for path in sorted(folder.glob("*.json")):
        record = GRASP_CASE.load(path)
        if not same_finger(record.get("settings", {}).get("geometry", {}).get("finger", {}), finger):
            raise ValueError(f"{path} was solved for another finger file than {finger.name!r}")
        out.append((path, record))
    return out


def grasp_problem(joint, finger, record: dict) -> GripperProblem:
    """The predictor's problem of a grasp record: its finger, object, approach (MPa), mu,
    W (N) and gravity, the default finger model; the plane X = 0 only if the record had
    it. ValueError (one line) if the record's object spec and geometry disagree."""
    problem = load_problem(None, record["object"], gravity=record["gravity"], params=GripperParams(finger=finger),
                           mu=record["mu"], object_weight=record["object_weight_N"],
                           approach=tuple(record["approach_MPa"]), joint=joint)
    ob, geo = problem.obstacle, record["object_geometry"]
    mine = (ob.kind, ob.a, ob.b, ob.x, ob.y, ob.angle)
    theirs = (geo["kind"], geo["a_mm"], geo["b_mm"], geo["x_mm"], geo["y_mm"], geo["angle_rad"])
    if mine[0] != theirs[0] or any(abs(a - b) > 1e-9 for a, b in zip(mine[1:], theirs[1:])) or (
            ob.kind == "rectangle" and abs(ob.corner - geo.get("corner_mm", ob.corner)) > 1e-9):
        raise ValueError(f"{record['case']}: the object spec {record['object']!r} is not the recorded geometry {geo}")
    return problem if record["plane"] else apart(problem)


def timed_solve(problem: GripperProblem, pressures: tuple[float, ...], repeats: int):
    """(GestureResult, median wall time s) of ``repeats`` single-query Newton solves."""
    p = torch.tensor([pressures], dtype=torch.float64)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = solve(problem, p, SolverOptions(method="newton"))
        times.append(time.perf_counter() - t0)
    return res, statistics.median(times)


def contact_centre(contacts: list[dict] | None) -> list[float] | None:
    """The normal-force-weighted mean point [X, Y] mm of contacts [{normal_force_N,
    point_mm}], None if nothing carries force."""
    total = sum(c["normal_force_N"] for c in contacts or [])
    if total <= 0:
        return None
    return [sum(c["normal_force_N"] * c["point_mm"][i] for c in contacts) / total for i in (0, 1)]


def predictor_figures(problem: GripperProblem, res) -> dict:
    """The predictor's answer in the FEM record's terms: converged, state, tip (mm),
    tip_angle_deg, friction_use, contact_force_N, contact_point_mm (weighted over every
    face that touches), object_force_N (the object's resultant on the finger, N, global),
    plane_force_N; figures null unless converged."""
    s = res.summary(0)
    out = {k: s[k] for k in ("converged", "state", "tip", "tip_angle_deg", "friction_use", "contact_force_N",
                             "plane_force_N")}
    out["contact_point_mm"] = contact_centre(s["contacts"])
    out["object_force_N"] = None
    if s["converged"]:
        with torch.no_grad():
            forces = problem.residual(res.pressures, res.tau).contact.forces[0]
        out["object_force_N"] = forces.sum(0).tolist()
    return out


def differences(record: dict, pred: dict) -> dict:
    """The error figures of one case (module docstring), null where either side has none."""
    both = record["converged"] and pred["converged"]
    out = dict(tip_error_mm=None, tip_angle_error_deg=None, normal_force_error_N=None, contact_location_error_mm=None)
    if not both:
        return out
    out["tip_error_mm"] = math.dist(pred["tip"], record["tip"])
    out["tip_angle_error_deg"] = pred["tip_angle_deg"] - record["tip_angle_deg"]
    out["normal_force_error_N"] = pred["contact_force_N"] - (record["contact_force_N"] or 0.0)
    c_fem, c_pred = record["contact_point_mm"], pred["contact_point_mm"]
    if c_fem is not None and c_pred is not None and (record["contact_force_N"] or 0.0) > 0:
        out["contact_location_error_mm"] = math.dist(c_pred, c_fem)
    return out


def state_judged(fem_use: float | None) -> bool:
    """Whether the state is judged: unless the FEM's friction use is within the band of 1."""
    return fem_use is None or abs(fem_use - 1.0) > TARGETS["friction_use_band"]


def verdicts(entry: dict) -> dict:
    """Each target (JUDGED) met (True), missed (False) or not judged (None) for one case."""
    fem_time = entry["fem_s"] <= TARGETS["fem_s"]
    if not entry["fem_converged"]:
        return {k: False for k in JUDGED}
    if not entry["predictor_converged"]:
        return {**{k: False for k in JUDGED}, "fem_time": fem_time}
    n_fem, touching = entry["normal_force_fem_N"] or 0.0, entry["contact_location_error_mm"] is not None
    neither = n_fem <= 0 and not entry["normal_force_predictor_N"]
    return {
        "tip": entry["tip_error_mm"] <= TARGETS["tip_error_mm"],
        "tip_angle": abs(entry["tip_angle_error_deg"]) <= TARGETS["tip_angle_error_deg"],
        "normal_force": abs(entry["normal_force_error_N"]) <= max(TARGETS["normal_force_rel"] * n_fem,
                                                                  TARGETS["normal_force_N"]),
        "contact_location": (entry["contact_location_error_mm"] <= TARGETS["contact_location_error_mm"]
                             if touching else neither),
        "state": entry["fem_state"] == entry["predictor_state"] if state_judged(entry["fem_friction_use"]) else None,
        "fem_time": fem_time,
        "speedup": entry["speedup"] >= TARGETS["speedup"],
    }


def case_entry(record: dict, pred: dict, predictor_s: float) -> dict:
    """One case of grasps.json: the issue's keys, both sides' figures, the errors, the
    speed-up and the verdicts."""
    fem_ok, n_fem = record["converged"], record["contact_force_N"]
    entry = {
        "case": record["case"], "region": record["region"], "object": record["object"],
        "p1": record["p1"], "p2": record["p2"], "plane": record["plane"], "mesh": finger_case_mesh(record),
        "formulation": finger_case_formulation(record), "nodes": record["mesh"]["nodes"],
        "fem_converged": fem_ok, "predictor_converged": pred["converged"],
        "fem_state": record["state"] if fem_ok else "not_converged", "predictor_state": pred["state"],
        "fem_friction_use": record["friction_use"] if fem_ok else None, "predictor_friction_use": pred["friction_use"],
        "normal_force_fem_N": n_fem if fem_ok else None, "normal_force_predictor_N": pred["contact_force_N"],
        "tip_fem_mm": record["tip"], "tip_predictor_mm": pred["tip"],
        "tip_angle_fem_deg": record["tip_angle_deg"], "tip_angle_predictor_deg": pred["tip_angle_deg"],
        "contact_point_fem_mm": record["contact_point_mm"] if fem_ok else None,
        "contact_point_predictor_mm": pred["contact_point_mm"],
        "object_force_fem_N": record["object_force_N"], "object_force_predictor_N": pred["object_force_N"],
        "plane_force_fem_N": record["plane_force_N"], "plane_force_predictor_N": pred["plane_force_N"],
        **differences(record, pred),
        "fem_s": record["fem_s"], "predictor_s": predictor_s, "speedup": record["fem_s"] / predictor_s,
    }
    err = entry["normal_force_error_N"]
    entry["normal_force_error_rel"] = abs(err) / n_fem if err is not None and n_fem else None
    entry["met"] = verdicts(entry)
    return entry


def _worst(rows: list[dict], key: str, pick=max):
    values = [abs(r[key]) for r in rows if r[key] is not None]
    return pick(values) if values else None


def summarise(entries: list[dict]) -> dict:
    """The worst of each figure over the cases both sides solved, and per target how many
    cases met it of how many were judged (every case counts, a failed FEM as a miss)."""
    both = [e for e in entries if e["fem_converged"] and e["predictor_converged"]]
    judged = {k: [e["met"][k] for e in entries if e["met"][k] is not None] for k in JUDGED}
    return {
        "cases": len(entries), "fem_converged": sum(e["fem_converged"] for e in entries),
        "predictor_converged": sum(e["predictor_converged"] for e in entries), "compared": len(both),
        "tip_error_mm_max": _worst(both, "tip_error_mm"),
        "tip_angle_error_deg_max": _worst(both, "tip_angle_error_deg"),
        "normal_force_error_N_max": _worst(both, "normal_force_error_N"),
        "normal_force_error_rel_max": _worst(both, "normal_force_error_rel"),
        "contact_location_error_mm_max": _worst(both, "contact_location_error_mm"),
        "state_agreement": sum(e["fem_state"] == e["predictor_state"] for e in both),
        "fem_s_max": _worst(entries, "fem_s"), "speedup_min": _worst(entries, "speedup", min),
        "predictor_s_median": statistics.median(e["predictor_s"] for e in entries) if entries else None,
        "met": {k: {"met": sum(v), "judged": len(v)} for k, v in judged.items()},
        "all_met": bool(entries) and all(all(v is not False for v in e["met"].values()) for e in entries),
    }


def overlay(path: Path, record: dict, fem_png: Path, pose, pred: dict, fem_label: str, joint: str) -> None:
    """The FEM render (|u|, the object's outline in black) with the predictor's part
    outlines, its contact point and the object's force on the finger, and the FEM's
    contact point and force (matplotlib, atomic)."""
    from predictor.model.plot import draw_fem_render, part_outlines     # first: it puts matplotlib on Agg
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 7.2), dpi=110)
    draw_fem_render(fig, ax, record["render"], fem_png, f"FEM |u| (mm), {fem_label}")
    if pose is not None:
        for kind, ring in part_outlines(pose, 0):
            ax.plot(ring[:, 0], ring[:, 1], "-", color=OUTLINE_COLOURS[kind], lw=1.3)
        for kind, words in (("rigid", "rigid parts' outlines"), ("joint", "joints' outer bands")):
            ax.plot([], [], "-", color=OUTLINE_COLOURS[kind], lw=1.3, label=f"predictor: {words}")
    fem_ok = record["converged"]
    _contact(ax, record["contact_point_mm"] if fem_ok else None, record["object_force_N"], "tab:orange", "o", "FEM")
    _contact(ax, pred["contact_point_mm"], pred["object_force_N"], "tab:red", "x", "predictor")
    ax.set_title(f"grasp {record['case']}: FEM {record['state']} ({fem_label}) vs predictor {pred['state']}\n"
                 f"joint model {joint}; arrows: the object's force on the finger, {FORCE_SCALE:g} mm per N",
                 fontsize=8)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2, fontsize=7)   # below: never over the finger
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def _contact(ax, point, force, colour: str, marker: str, who: str) -> None:
    """One side's contact point and force arrow (FORCE_SCALE mm per N), if it touches."""
    if point is None:
        return
    ls = "-" if marker == "x" else "--"
    ax.plot(*point, marker, color=colour, mfc="none", mec=colour, mew=2, ms=9,
            label=f"{who}: contact point (force-weighted)")
    if force is not None:
        ax.annotate("", xy=(point[0] + FORCE_SCALE * force[0], point[1] + FORCE_SCALE * force[1]), xytext=point,
                    arrowprops=dict(arrowstyle="->", color=colour, lw=1.8, ls=ls))
        ax.plot([], [], ls, color=colour, lw=1.8, label=f"{who}: the object's force on the finger")


def build_parser() -> cli.Parser:
    mesh, formulation = production_discretisation()
    ap = cli.Parser(prog="python -m predictor.validation.grasps", description=__doc__.split("\n\n")[0])
    ap.add_argument("--fem", default="results/validation/grasps_fem", help="folder of fem.studies.grasp_cases records "
                    "(default results/validation/grasps_fem)")
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: the committed surrogate, "
                    "predictor.defaults)")
    ap.add_argument("--finger", default=None, help="finger file the FEM grasps used (default: the paper's)")
    ap.add_output("--out", suffix=".json", default="results/validation/grasps.json", help="output JSON")
    ap.add_output("--figures", folder=True, default="results/validation/grasps", help="folder for the overlay PNGs")
    ap.add_argument("--mesh", type=mesh_arg, default=mesh, metavar="MESH",
                    help=f"validate the records solved on this joint mesh: H or H:W (mm) or hexN or hexN:S "
                         f"(default {mesh}, the joint file's)")
    ap.add_argument("--formulation", choices=FORMULATIONS, default=formulation,
                    help=f"validate the records solved in this formulation (default {formulation})")
    problem = ap.add_mutually_exclusive_group()
    problem.add_argument("--plane", dest="plane", action="store_true", default=None,
                         help="validate the grasps of the gripper (the mirror finger's contact at X = 0)")
    problem.add_argument("--no-plane", dest="plane", action="store_false",
                         help="validate the grasps of one finger alone")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return ap


def chosen_records(folder: str, finger, validated: tuple[str, str]) -> list[tuple[Path, dict]]:
    """The records of ``folder`` on the discretisation ``validated`` (mesh text,
    formulation); ValueError naming the ones it holds when there is none."""
    pairs = read_records(folder, finger)
    on, _ = split_cases([r for _, r in pairs], validated)
    chosen = [(p, r) for p, r in pairs if any(r is o for o in on)]
    if not chosen:
        held = sorted({f"{finger_case_mesh(r)} {finger_case_formulation(r)}" for _, r in pairs})
        raise ValueError(f"no FEM grasp records on mesh {validated[0]} ({validated[1]}) in {folder}"
                         + (f" (it holds {', '.join(held)}: pass --mesh, --formulation)" if held else
                            ": run `make grasp-fem` (python -m fem.studies.grasp_cases)"))
    return chosen


def case_line(e: dict) -> str:
    """One line of a validated case for the terminal."""
    if not e["fem_converged"]:
        return f"{e['case']}: the FEM did not converge; predictor {e['predictor_state']}"
    if not e["predictor_converged"]:
        return f"{e['case']}: FEM {e['fem_state']}, the predictor did not converge"
    loc = e["contact_location_error_mm"]
    return (f"{e['case']}: FEM {e['fem_state']} / predictor {e['predictor_state']}, tip {e['tip_error_mm']:.2f} mm, "
            f"angle {e['tip_angle_error_deg']:+.2f} deg, N {e['normal_force_fem_N']:.4f} / "
            f"{e['normal_force_predictor_N']:.4f} N, contact {'-' if loc is None else f'{loc:.2f}'} mm, "
            f"speed-up {e['speedup']:.0f}x")


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    set_quiet(args.quiet)
    torch.set_num_threads(1)
    validated = (args.mesh, args.formulation)
    with ap.errors():
        finger = load_finger(args.finger)
        chosen = chosen_records(args.fem, finger, validated)
        kept, plane = one_problem([r for _, r in chosen], args.plane,
                                  f"the FEM grasp records on mesh {validated[0]} ({validated[1]}) in {args.fem}",
                                  lambda r: bool(r["plane"]))
        chosen = [(p, r) for p, r in chosen if any(r is k for k in kept)]
        joint = load_joint(args.model, finger)
        entries, figures = [], []
        for path, record in chosen:
            problem = grasp_problem(joint, finger, record)
            res, predictor_s = timed_solve(problem, (record["p1"], record["p2"]), REPEATS)
            pred = predictor_figures(problem, res)
            entry = case_entry(record, pred, predictor_s)
            png = path.with_suffix(".png")
            entry["figure"] = None
            if record["converged"] and png.is_file():
                figure = Path(cli.make_output_folder(args.figures)) / f"{path.stem}.png"
                overlay(figure, record, png, res.pose if pred["converged"] else None, pred,
                        f"mesh {entry['mesh']} {entry['formulation']}, {entry['nodes']:,} nodes", joint.name)
                entry["figure"] = figure.name
                figures.append(str(figure))
            entries.append(entry)
            if not args.json:
                print(case_line(entry), flush=True)
        report = {"finger": finger.summary(), "joint": joint.name, "fem_folder": args.fem,
                  "discretisation": {"mesh": validated[0], "formulation": validated[1]}, "plane": plane,
                  "targets": TARGETS, "judged": list(JUDGED), "repeats": REPEATS, "cases": entries,
                  "summary": summarise(entries), "figures": figures}
        GRASP_VALIDATION.write(args.out, report)
    s = report["summary"]
    if args.json:
        cli.print_json(s)
    else:
        print(f"{s['compared']} of {s['cases']} cases compared: "
              + ", ".join(f"{k} {v['met']}/{v['judged']}" for k, v in s["met"].items())
              + f"; all targets met: {s['all_met']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
