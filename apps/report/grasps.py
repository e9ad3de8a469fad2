"""The report's grasp-validation section (issue 36 §3): the predictor against the FEM grasps
(results/validation/grasps.json, predictor.validation.grasps): one row per case with both
states and the differences, the targets judged over every case compared and every case of
the planned table (contract.grasp.GRASP_CASES, ``make grasp-fem``) not compared yet (a case
the FEM did not solve or has not run counts as a miss), and the overlays. Before
`make validate-grasps` has run, the target rows say "not run"."""

from __future__ import annotations

from pathlib import Path

from apps.report.common import Check, Target, cells, figure_grid, joint_model, judge, load, num
from contract.grasp import GRASP_CASES

GRASPS_TITLE = "Grasps: the predictor against the FEM (issue 36)"
MAKE = "make validate-grasps"

#: (key in grasps.json's ``met``, the row's words, the worst figure in ``summary``, its format)
ROWS = (("tip", "fingertip error <= {tip_error_mm:g} mm", "tip_error_mm_max", "{:.3f} mm"),
        ("tip_angle", "tip angle error <= {tip_angle_error_deg:g}°", "tip_angle_error_deg_max", "{:.3f}°"),
        ("normal_force", "normal force within {normal_force_rel:.0%} (or {normal_force_N:g} N)",
         "normal_force_error_rel_max", "{:.1%} of the FEM's"),
        ("contact_location", "contact location within {contact_location_error_mm:g} mm",
         "contact_location_error_mm_max", "{:.2f} mm"),
        ("state", "same state (holds/slips) where the FEM's friction use is not within {friction_use_band:g} of 1",
         None, None),
        ("fem_time", "FEM grasp <= {fem_s:g} s per case (one core)", "fem_s_max", "{:.0f} s"),
        ("speedup", "predictor speed-up over the FEM >= {speedup:,.0f}x", "speedup_min", "{:,.0f}x"))
#: the issue's bounds, for the rows shown before the validation has run
ISSUE_BOUNDS = {"tip_error_mm": 1.0, "tip_angle_error_deg": 0.5, "normal_force_rel": 0.1, "normal_force_N": 0.02,
                "contact_location_error_mm": 2.0, "friction_use_band": 0.05, "fem_s": 900.0, "speedup": 1e4}
CONVERGED = "FEM grasps converged"
HEAD = ["| target | worst case | cases met | target | met |", "|---|---|---|---|---|"]


def _not_run(root: Path) -> list[str]:
    """The section before grasps.json exists: what is missing, and every target "not run"."""
    records = sorted((root / "validation/grasps_fem").glob("*.json"))
    where = (f"results/validation/grasps_fem holds {len(records)} FEM grasp record(s); run `{MAKE}`" if records else
             "results/validation/grasps_fem holds no FEM grasp record yet: run `make grasp-fem` (the FEM grasps on "
             f"the production mesh, hours on one core), then `{MAKE}`")
    out = [f"_Not run: {where} (the predictor against each FEM grasp, results/validation/grasps.json)._", ""]
    words = [CONVERGED] + [w.format(**ISSUE_BOUNDS) for _, w, _, _ in ROWS]
    out += HEAD + [f"| {w} | not run | not run | all cases | not run |" for w in words]
    return out + [""]


def _state(state: str, use) -> str:
    return state.replace("_", " ") + (f" ({use:.2f})" if use is not None else "")


def case_table(cases: list[dict]) -> list[str]:
    """One row per case: both states (friction use), the differences, the times."""
    out = ["| case | region | FEM state (friction use) | predictor state (friction use) | tip error (mm) | "
           "tip angle error (°) | normal force FEM / predictor (N) | contact location error (mm) | FEM (s) | "
           "predictor (ms) | speed-up |", "|---" * 11 + "|"]
    for e in cases:
        fem = _state(e["fem_state"], e["fem_friction_use"]) if e["fem_converged"] else "**not converged**"
        forces = f"{num(e['normal_force_fem_N'], '.4f')} / {num(e['normal_force_predictor_N'], '.4f')}"
        pred = _state(e["predictor_state"], e["predictor_friction_use"])
        out.append(f"| {e['case']} | {e['region']} | {fem} | {pred} | {num(e['tip_error_mm'], '.3f')} | "
                   f"{num(e['tip_angle_error_deg'], '+.3f')} | {forces} | "
                   f"{num(e['contact_location_error_mm'], '.2f')} | {e['fem_s']:.0f} | {1e3 * e['predictor_s']:.0f} | "
                   f"{e['speedup']:,.0f}x |")
    return out


def not_compared(v: dict) -> list[str]:
    """The planned cases (contract.grasp.GRASP_CASES) that grasps.json does not compare."""
    compared = {e["case"] for e in v["cases"]}
    return [c.name for c in GRASP_CASES if c.name not in compared]


def _checks(v: dict) -> list[tuple[str, str, str, Check]]:
    """(words, worst, cases met, Check) per target: met by every case it judges and by
    every planned case not compared yet (each a miss)."""
    s, title, missing = v["summary"], GRASPS_TITLE, len(not_compared(v))
    failed = s["cases"] - s["fem_converged"]
    rows = [(CONVERGED, f"{failed} not converged" if failed else "all converged",
             f"{s['fem_converged']} of {s['cases'] + missing}",
             judge(title, CONVERGED, [(Target(">=", s["cases"] + missing, "cases"), s["fem_converged"])]))]
    for key, words, worst, spec in ROWS:
        m = s["met"][key]
        shown = words.format(**v["targets"])
        if key == "state":
            low = s["cases"] - m["judged"]
            value = f"{s['state_agreement']} of {s['compared']} agree" + (f", {low} at the slip limit" if low else "")
        else:
            value = "n/a" if s[worst] is None else spec.format(s[worst])
        if key == "normal_force" and s["normal_force_error_N_max"] is not None:
            value += f", {s['normal_force_error_N_max']:.4f} N"
        rows.append((shown, value, f"{m['met']} of {m['judged'] + missing}",
                     judge(title, shown, [(Target(">=", m["judged"] + missing, "cases"), m["met"])])))
    return rows


def _missing_words(v: dict) -> str:
    """The planned cases not compared yet, in words (each a miss of every target)."""
    missing = not_compared(v)
    if not missing:
        return ""
    return (f" {len(missing)} of the {len(GRASP_CASES)} planned cases (`make grasp-fem`'s table, "
            f"contract.grasp.GRASP_CASES) have no FEM grasp yet and count as misses: {', '.join(missing)}.")


def _figures(root: Path, v: dict) -> list[str]:
    """The overlays, one row of pictures per object."""
    out, d = [], v["discretisation"]
    for obj in dict.fromkeys(e["object"] for e in v["cases"]):
        pictures = [(f"validation/grasps/{e['figure']}", e["case"]) for e in v["cases"]
                    if e["object"] == obj and e["figure"]]
        if pictures:
            out += figure_grid(root, pictures, f"{obj}: the FEM render (|u|, the object's outline in black) with the "
                               "predictor's part outlines, its contact point and the object's force on the finger, "
                               f"and the FEM's (`{MAKE}`: FEM on joint mesh {d['mesh']} {d['formulation']}, "
                               f"predictor with joint model {v['joint']})", MAKE)
    return out


def grasps_section(root: Path) -> tuple[list[str], list[Check]]:
    out = [f"## {GRASPS_TITLE}", ""]
    v = load(root, "validation/grasps.json")
    if not v:
        return out + _not_run(root), []
    d, s = v["discretisation"], v["summary"]
    nodes = sorted({e["nodes"] for e in v["cases"]})
    out += [f"`{MAKE}` (results/validation/grasps.json, `python -m predictor.validation.grasps`): each FEM grasp of "
            f"`make grasp-fem` on joint mesh {d['mesh']} {d['formulation']} "
            f"({', '.join(f'{n:,}' for n in nodes)} P2 nodes) against the predictor with the same finger file, object, "
            "approach, mu, W, gravity and plane X = 0, joint model "
            f"{joint_model(root, v['joint'], MAKE)}; the predictor's time is the median of {v['repeats']} "
            "single-query solves of the whole history in the same run, the FEM's its record's. The contact location "
            "is the normal-force-weighted mean contact point on both sides. "
            f"{s['compared']} of {s['cases']} cases compared." + _missing_words(v), ""]
    out += case_table(v["cases"]) + [""]
    rows = _checks(v)
    out += HEAD + [f"| {words} | {worst} | {met} |" + cells(check) for words, worst, met, check in rows]
    return out + [""] + _figures(root, v), [check for *_, check in rows]
