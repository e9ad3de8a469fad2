"""The report's section on the finger FEM over the pressure box (issue 36 §1): the gravity
grid of results/fem/finger_grid.json (fem.studies.finger_grid) drawn as a table, one cell per
pressure pair with its solve time or its failure and the predictor's fingertip error
against it (the judged variant of results/validation/finger.json, make validate-finger,
when that validation is of the same mesh and problem), and the targets (every pair
converged, <= 10 min per gesture on one core)."""

from __future__ import annotations

from pathlib import Path

from apps.report.common import Check, Target, cells, judge, load

FINGER_GRID_TITLE = "Finger FEM over the pressure box (issue 36)"
GESTURE_TARGET_S = 600.0     # issue 36: <= 10 min per gesture on one core


def grid_axes(cases: list[dict], points: int) -> tuple[list[float], list[float]]:
    """The grid's P1 and P2 values (MPa), ascending: ``points`` values over [-l, l] per
    axis, l the largest |P| solved on it (fem.studies.finger_grid.grid_pairs; its first case is
    the corner (-l1, -l2), so a grid with any case knows its box)."""
    def axis(values):
        limit = max(abs(v) for v in values)
        return [round(-limit + 2 * limit * k / (points - 1), 12) + 0.0 for k in range(points)]
    return axis([c["p1"] for c in cases]), axis([c["p2"] for c in cases])


def grid_table(cases: list[dict], points: int, tip_errors: dict | None = None) -> list[str]:
    """Markdown table: columns P1, rows P2 (largest on top), each cell the solve time (s) of
    a converged pair and, where ``tip_errors`` {(p1, p2): mm} has it, the predictor's
    fingertip error against it; "**failed**" for a pair that did not converge, "pending"
    if unsolved."""
    p1s, p2s = grid_axes(cases, points)
    by = {(round(c["p1"], 12), round(c["p2"], 12)): c for c in cases}
    tip_errors = {(round(a, 12), round(b, 12)): e for (a, b), e in (tip_errors or {}).items()}

    def cell(p1, p2):
        c = by.get((p1, p2))
        if c is None:
            return "pending"
        if not c["converged"]:
            return "**failed**"
        e = tip_errors.get((p1, p2))
        return f"{c['wall_s']:.0f} s" + ("" if e is None else f", {e:.2f} mm")

    out = ["| P2 \\ P1 (MPa) | " + " | ".join(f"{p:g}" for p in p1s) + " |",
           "|---" * (len(p1s) + 1) + "|"]
    out += [f"| **{p2:g}** | " + " | ".join(cell(p1, p2) for p1 in p1s) + " |" for p2 in reversed(p2s)]
    return out


def validation_tip_errors(v: dict | None) -> dict:
    """{(P1, P2): fingertip error mm} of the judged variant in a finger validation
    (results/validation/finger.json) over its cases with gravity; {} without one."""
    if not v:
        return {}
    pressures = {c["case"]: c["pressures_MPa"] for c in v["fem"] if c["gravity"]}
    return {tuple(pressures[e["case"]]): e["tip_error_mm"] for e in v["cases"]
            if e["variant"] == v["judged_variant"] and e["case"] in pressures}


def _checks(grid: dict) -> list[Check]:
    """Every pair converged, and the slowest solve within the gesture target (judged only
    on a complete grid)."""
    if not grid["complete"]:
        return []
    title = FINGER_GRID_TITLE
    return [judge(title, "finger FEM grid: pairs converged", [(Target(">=", grid["pairs"], "pairs"),
                                                                grid["converged"])]),
            judge(title, "finger FEM grid: slowest gesture", [(Target("<=", GESTURE_TARGET_S, "s"),
                                                               grid["max_wall_s"])])]


def _judged(v: dict | None) -> str:
    return f"the {v['judged_variant']} variant" if v else "not compared yet"


def finger_grid_section(root: Path) -> tuple[list[str], list[Check]]:
    title = FINGER_GRID_TITLE
    out = [f"## {title}", ""]
    grid = load(root, "fem/finger_grid.json")
    if not grid:
        return out + ["_Pending: `make finger-grid` has not run (the finger FEM with gravity at every pressure "
                      "pair of a 7 x 7 grid over the box)._", ""], []
    mesh, s = grid["mesh"], grid["settings"]
    v = load(root, "validation/finger.json")
    if v and (v.get("discretisation", {}).get("mesh") != mesh.get("mesh") or v.get("plane") != s.get("plane")):
        v = None   # a validation on another mesh or problem is not this grid's
    n = s["points"]
    failed = [c for c in grid["cases"] if not c["converged"]]
    problem = ("the gripper: the right finger against the mirror finger's contact at X = 0" if s.get("plane")
               else "one finger alone, without the plane X = 0")
    out += [f"`make finger-grid` (results/fem/finger_grid.json, `python -m fem.studies.finger_grid`): the whole-finger FEM "
            f"of {problem}, with gravity at every pressure pair of a {n} x {n} grid over the joints' box, each "
            f"a fem.studies.finger_cases record solved from the "
            f"unloaded state on one rank ({mesh['nodes']:,} P2 nodes, joint mesh {mesh.get('mesh', 'unrecorded')}, "
            f"{s['formulation']} formulation). {grid['converged']} of {grid['solved']} solved pairs converged"
            + ("" if grid["complete"] else f" ({grid['pairs'] - grid['solved']} of {grid['pairs']} still to solve)")
            + "; each cell is the pair's wall time (timed while the machine ran other jobs) and, once "
            "`make validate-finger` has compared it, the predictor's fingertip error against it "
            f"(results/validation/finger.json, {_judged(v)}).", ""]
    out += grid_table(grid["cases"], n, validation_tip_errors(v)) + [""]
    if failed:
        out += ["Failed pairs: " + "; ".join(f"({c['p1']:g}, {c['p2']:g}) MPa: {c['reason'] or 'no reason'}"
                                             for c in failed) + ".", ""]
    checks = _checks(grid)
    if checks:
        out += ["| figure | value | target | met |", "|---|---|---|---|",
                f"| pairs converged | {grid['converged']} of {grid['pairs']} |" + cells(checks[0]),
                f"| slowest gesture (one rank) | {grid['max_wall_s']:.0f} s |" + cells(checks[1]), ""]
    return out, checks
