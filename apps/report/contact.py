"""The report's contact section (issue 36 §0, §4): how far the right finger crosses the
symmetry plane X = 0 in every committed gesture, atlas point and inverse answer (judged),
and what the contact on the finger's outline changed against the model before
(results/predictor/h1.8/contact_change.json: atlas states, the reference ramps' failures, the
paper's gestures)."""

from __future__ import annotations

import math
from pathlib import Path

from apps.report.common import Check, Target, cells, judge, load, missing, num

CONTACT_TITLE = "Contact on the finger's outline, fingers that meet (issue 36)"

#: Issue 36 §0: no gesture, atlas point or inverse answer has the right finger more than
#: this far across X = 0 (mm).
PLANE_OVERLAP_MM = 0.1

#: Why targets of other sections moved with this model (met by the model before it, the
#: centre-line contact without the plane; docs/gripper.md §9-11 give the measurements).
COSTS = (
    "Gravity gestures without an object (the Newton solve from tau = 0; the gravity NN's single query and "
    "delivered path, whose residual check evaluates the plane): where the fingers meet, the finger presses on the "
    "plane X = 0, whose penalty is a hundred times the object's (docs/gripper.md §7), so the gesture is a contact "
    "problem; rows whose load-free pose lies across the plane, or whose Newton answer ends across it, are ramped "
    "from zero pressure (docs/gripper.md §9) instead of a few Newton steps. Where they stay apart the plane's broad "
    "phase (docs/gripper.md §10: the penalty's graph runs only for the rows whose outline crosses X = 0) leaves the "
    "solve at about the model before's cost, so a median over pressures of which most stay apart meets its target "
    "while a gesture where the fingers meet takes a ramp (tenths of a second).",
    "The gravity networks learn one finger alone, whose gestures may cross X = 0, and their raw residual is "
    "judged there (Gesture predictor section, docs/gripper.md §11); the gripper's answers add the plane: the raw "
    "answer stands only where the fingers stay apart (there the two residuals are the same), and where they meet "
    "`predictor.cli.gesture --method nn` and the fastest path answer with the network's tau polished on the gripper's "
    "equilibrium, reported as polished: the Newton step from it misses its check, so the LM finishes it{lm}.",
    "Contact gestures, the atlases and the inverse: every solve with an object integrates the penalty over the "
    "outline's edges instead of summing it at fixed centre-line points; the inverse's tip goals start from a "
    "coarse grid of object-free gestures (plane solves), and every answer is verified and checked at the "
    "regulators' stencil by ramp solves (Grasp planning).",
)

#: COSTS[1] for a bench whose gravity network learned the gripper (details.gravity_nn_problem).
GRIPPER_NN_COST = (
    "The gravity networks learn the gripper, the plane X = 0 included, and their raw residual is judged there "
    "(Gesture predictor section, docs/gripper.md §11): where the finger presses on the plane its stiff penalty "
    "puts the raw residual outside the NN bound for any network, so the delivered answer there is the network's "
    "tau polished by the Newton step, reported as polished, and the LM finishes the rows whose one-step check "
    "fails{lm}.")


def _load_note(root: Path) -> str:
    """What the bench's machine was doing (bench/predictor.json): its load average at the
    start and whether its runs on every core were slower than on one (the gravity NN's
    float64 throughput), which makes its times and batched rates the machine's too."""
    b = load(root, "bench/predictor.json")
    if not b or "load_average_at_start" not in b:
        return ""
    thr = b["details"].get("gravity_nn_throughput") or {}
    one, every = (thr.get(k, {}).get("nn_and_kinematics_per_s") for k in ("one_thread", "every_core_float64"))
    text = (f"The bench's timings (bench/predictor.json) were measured at a load average of "
            f"{b['load_average_at_start'][0]:.1f} on this machine's {b.get('batched_threads', '?')} cores")
    if one and every and every < one:
        text += (f", where its runs on every core were slower than on one (the gravity NN's network and "
                 f"kinematics, float64: {every:.3g} against {one:.3g} gestures per second): its times and batched "
                 "rates there are the machine's as much as the model's, until `make bench-predictor` runs on an "
                 "idle machine")
    return text + "."


def _costs(root: Path) -> list[str]:
    """The targets of other sections this model moves, and why (COSTS), with the bench's
    own figures where it has them."""
    b = load(root, "bench/predictor.json")
    fast = (b or {}).get("details", {}).get("gravity_fast")
    lm = f" ({fast['fallbacks']} of {fast['n']} bench cases)" if fast else ""
    out = ["Targets of other sections that this model moves, and why:", ""]
    gripper = (b or {}).get("details", {}).get("gravity_nn_problem") == "gripper"
    out += ["- " + COSTS[0], "- " + (GRIPPER_NN_COST if gripper else COSTS[1]).format(lm=lm), "- " + COSTS[2]]
    note = _load_note(root)
    return out + ([f"- {note}"] if note else []) + [""]


OBJECTS = ("circle", "ellipse", "rectangle")
ATLASES = (("atlas_{}.json", "atlas, sweep", "make atlas"), ("ramp/atlas_{}.json", "atlas, 12-step reference ramp",
                                                              "make atlas-reference"),
           ("ramp_fine/atlas_{}.json", "atlas, 48-step reference ramp", "make atlas-reference-fine"))


def _worst(values) -> tuple[int, float | None]:
    """(how many finite values, their largest or None)."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return len(vals), (max(vals) if vals else None)


def _gesture_overlaps(g: dict) -> list:
    items = [*g["gravity"], *g["free"], *(x for group in g["grasps"].values() for x in group)]
    return [x.get("plane_overlap_mm") for x in items]


def overlap_rows(root: Path) -> list[tuple[str, int, float | None, str]]:
    """(what, results that carry the figure, worst overlap mm or None, make target) per
    committed artefact of the predictor."""
    rows = []
    g = load(root, "predictor/gestures.json")
    if g:
        rows.append(("gestures.json (gravity, free, grasps)", *_worst(_gesture_overlaps(g)), "make gestures"))
    for pattern, what, make in ATLASES:
        for kind in OBJECTS:
            a = load(root, "predictor/" + pattern.format(kind))
            if a:
                n, worst = _worst(v for row in a.get("plane_overlap_mm") or [] for v in row)
                rows.append((f"{what}, {kind} ({pattern.format(kind)})", n, worst, make))
    inv = load(root, "predictor/inverse.json")
    if inv:
        rows.append(("inverse.json answers", *_worst(c.get("plane_overlap_mm") for c in inv["cases"]), "make inverse"))
    return rows


def _overlap(root: Path, checks: list[Check]) -> list[str]:
    rows = overlap_rows(root)
    if not rows:
        return missing("gestures, atlases and inverse answers", "make gestures atlas inverse")
    out = ["The right finger's outline against the symmetry plane X = 0 where it meets the left finger "
           "(a frictionless penalty, docs/gripper.md §7): how far it crosses, over every converged result "
           "of each artefact that records it (`plane_overlap_mm`).", "",
           "| artefact | results | worst overlap across X = 0 | target | met |", "|---|---|---|---|---|"]
    for what, n, worst, make in rows:
        shown = f"{worst:.3f} mm" if worst is not None else f"not recorded (`{make}`)"
        out.append(f"| {what} | {n} | {shown} |" + cells(None))
    n, worst = sum(r[1] for r in rows), _worst(r[2] for r in rows)[1]
    if any(r[2] is None for r in rows):   # an artefact from before the plane: not judged until regenerated
        return out + [f"| **all of the above** | {n} | not recorded in every artefact |" + cells(None), ""]
    checks.append(judge(CONTACT_TITLE, "overlap across X = 0, every result",
                        [(Target("<=", PLANE_OVERLAP_MM, "mm"), worst)]))
    return out + [f"| **all of the above** | {n} | {worst:.3f} mm |" + cells(checks[-1]), ""]


def _changes(root: Path) -> list[str]:
    c = load(root, "predictor/h1.8/contact_change.json")
    if not c:
        return missing("what the outline contact changed", "python -m predictor.validation.contact_change")
    out = [f"Against the model before ({c['before']}), from results/predictor/h1.8/contact_change.json "
           "(`python -m predictor.validation.contact_change`, the two models' committed artefacts compared, both on the 1.8 mm "
           "reference surrogate: the change was measured before the switch).", "",
           "| object | atlas points whose state changed | how | 12-step reference: not converged before -> after "
           "| 48-step reference: not converged before -> after |", "|---|---|---|---|---|"]
    for kind in OBJECTS:
        a = c["atlas"].get(kind)
        if a is None:
            continue
        how = ", ".join(f"{k} {v}" for k, v in sorted(a["transitions"].items(), key=lambda kv: -kv[1]))
        refs = [c[key].get(kind) for key in ("reference", "reference_fine")]
        ref = [f"{r['not_converged_before']} -> {r['not_converged_after']} of {r['points']}" if r else "n/a"
               for r in refs]
        out.append(f"| {kind} | {a['changed']} of {a['points']} | {how} | {ref[0]} | {ref[1]} |")
    out.append("")
    grasps = [g for g in c["gestures"] if g["group"] == "grasps"]
    if grasps:
        out += ["The paper's grasps (gestures.json), the fingertip's shift:", "",
                "| object | (P1, P2) MPa | state before -> after | tip shift | overlap across X = 0 |",
                "|---|---|---|---|---|"]
        out += [f"| {g['object']} | {', '.join(f'{p:g}' for p in g['pressures_MPa'])} | {g['state_before']} -> "
                f"{g['state_after']} | {num(g['tip_shift_mm'], '.2f')} mm | {num(g['plane_overlap_mm'], '.3f')} mm |"
                for g in grasps]
        out.append("")
    others = [g for g in c["gestures"] if g["group"] != "grasps"]
    if others:
        out += ["Without an object (gravity and free gestures), the fingertip's shift and the overlap across "
                "X = 0 now: " + "; ".join(
                    f"{g['group']} ({', '.join(f'{p:g}' for p in g['pressures_MPa'])}) MPa "
                    f"{num(g['tip_shift_mm'], '.2f')} mm ({num(g['plane_overlap_mm'], '.3f')} mm)" for g in others)
                + ".", ""]
    return out


def contact_section(root: Path) -> tuple[list[str], list[Check]]:
    checks: list[Check] = []
    out = [f"## {CONTACT_TITLE}", "",
           "The object touches the finger's outline (the rigid parts' faces, the joints' outer bands and the "
           "tip's end face), not the parts' centre lines, and the two mirror fingers meet at X = 0; "
           "rectangle corners are rounded (`rc`, default 1 mm). docs/gripper.md §7 gives the model.", "",
           "### Where the fingers meet", ""]
    out += _overlap(root, checks)
    out += ["### What it changed", ""]
    out += _changes(root)
    out += ["### What it costs", ""]
    out += _costs(root)
    return out, checks
