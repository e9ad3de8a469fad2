"""The report's planning section (issue 16): the grasp atlases against their ramp
references and a finer ramp, and the inverse pressures."""

from __future__ import annotations

from pathlib import Path

from apps.report.common import Check, Target, cells, figure, joint_model, judge, load, missing, num

PLANNING_TITLE = "Grasp planning (issue 16)"


def _range_mid(text) -> float | None:
    """The middle of a paper figure recorded as a range ('10-15' -> 12.5), or None."""
    try:
        parts = [float(v) for v in str(text).split("-")]
    except ValueError:
        return None
    return sum(parts) / len(parts)

def planning_section(root: Path) -> tuple[list[str], list[Check]]:
    title = PLANNING_TITLE
    out, checks = [f"## {title}", ""], []
    kinds = ("circle", "ellipse", "rectangle")
    atlases = [(kind, a) for kind in kinds if (a := load(root, f"predictor/atlas_{kind}.json"))]
    # the paper's contact gesture time, as the predictor benchmark records it
    paper = (load(root, "bench/predictor.json") or {}).get("paper", {})
    per_gesture = _range_mid(paper.get("contact_lbfgs_s"))
    out += ["### Grasp atlas (`make atlas`)", ""]
    if atlases:
        first = atlases[0][1]
        out += [f"Every (P1, P2) of a {first['grid']} x {first['grid']} grid over the "
                "pressure box, each solved along the straight pressure path from the approach gesture "
                f"({', '.join(f'{v:g}' for v in first['approach_MPa'])} MPa): by continuation outward from "
                "it (`--path sweep`, each point from its ray's previous grid point; a point without one, or "
                "whose continuation fails, is ramped on its own), checked against the reference that ramps "
                "every point on its own (`--path ramp`, `make atlas-reference`): the 'same state' column. "
                f"Friction use = |f|/(mu N), mu = {first['mu']}. Joint model: "
                f"{joint_model(root, first.get('joint'), 'make atlas')}. The time is predictor.planning.atlas's own wall time "
                "for the whole grid (atlas_<object>.json, not a benchmark); the paper's column is its contact "
                f"gesture time ({paper.get('contact_lbfgs_s', 'n/a')} s, bench/predictor.json) times the grid.", "",
                "| object | no contact | holds | slips | not converged | best hold (P1, P2) MPa "
                "| its friction use | swept / ramped / retried | same state as the ramp reference "
                "| time (atlas_<object>.json) | paper | target | met |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for kind, a in atlases:
            c, best = a["counts"], a.get("best_hold") or {}
            checks.append(judge(title, f"atlas {kind}", [(Target("<=", a["targets"]["atlas_s_per_object"], "s"),
                                                          a["measured"]["atlas_s_per_object"])]))
            hold_p = ", ".join(f"{v:.3f}" for v in best.get("pressures_MPa", [])) or "none"
            paper_h = f"~{per_gesture * a['measured']['grid_points'] / 3600:.0f} h" if per_gesture else "n/a"
            by = a.get("solved_by") or {}
            how = " / ".join(str(by.get(k, "?")) for k in ("swept", "ramped", "retried")) if by else "all ramped"
            ref = load(root, f"predictor/ramp/atlas_{kind}.json")
            same = "n/a (make atlas-reference)"
            if ref and ref.get("grid") == a["grid"]:
                differ = _differ(ref, a)
                same = f"{1 - differ / a['grid'] ** 2:.2%} ({differ} differ)"
            out.append(f"| {kind} | {c['no_contact']} | {c['holds']} | {c['slips']} | {c['not_converged']} | "
                       f"{hold_p} | {num(best.get('friction_use'))} | {how} | {same} | "
                       f"{a['measured']['atlas_s_per_object']:.1f} s "
                       f"| {paper_h} |" + cells(checks[-1]))
        out.append("")
        slow = [kind for kind, a in atlases if a["measured"]["atlas_s_per_object"] > a["targets"]["atlas_s_per_object"]]
        if slow:
            out += [f"Over the target ({', '.join(slow)}): these atlases were solved on the production surrogate "
                    "beside its contact NN's training, both cores busy (docs/decisions.md §9, `make predictor-new` "
                    "before the switch); the 1.8 mm reference's atlases below, timed on a quieter machine, met it. "
                    "The model's own cost per query against the reference's is `make bench-surrogate`'s (the "
                    "production surrogate's section); an atlas re-timed on an idle machine judges it.", ""]
        for kind, a in atlases:
            out += _finer_ramp(root, kind, a)
        out += _reference_atlases(root, atlases)
    else:
        out += missing("grasp atlas", "make atlas")
    for kind in kinds:
        a = next((a for k, a in atlases if k == kind), {})
        out += figure(root, f"predictor/atlas_{kind}.png", f"grasp atlas, {kind}",
                       f"`make atlas` (`python -m predictor.cli.atlas --object {kind} --grid {a.get('grid', '?')}`, joint "
                       f"model {joint_model(root, a.get('joint'))}): the state and the friction use over "
                       "(P1, P2), normal-force contours; right, the best hold, a slip and a no-contact gesture.",
                       "make atlas")
    inv = load(root, "predictor/inverse.json")
    out += ["### Inverse pressures (`make inverse`)", ""]
    if inv:
        t, m = inv["targets"], inv["measured"]
        out += ["Gradients by the implicit function theorem on the converged equilibrium; every answer "
                "verified by a forward solve along the ramp, and its robustness checked at the "
                f"regulators' +/-{inv['tolerances']['regulator_MPa']} MPa. Joint model: "
                f"{joint_model(root, inv.get('joint'), 'make inverse')}. Times are predictor.cli.inverse's own wall times "
                "(inverse.json, not a benchmark), taken on the machine the track's load averages below describe "
                "(make inverse's run records the track too; make track replaces that part). A tip goal's error "
                "is its position error, and its angle error (wrapped) apart.", "",
                "| goal | object | status | pressures (MPa) | friction use / tip error | verified | robust "
                "| time (inverse.json) |",
                "|---|---|---|---|---|---|---|---|"]
        for c in inv["cases"]:
            angle = c.get("angle_error_deg")
            shown = (f"{num(c['friction_use'])}" if c["friction_use"] is not None
                      else f"{num(c['tip_error_mm'])} mm" + ("" if angle is None else f", {angle:+.2f}°"))
            out.append(f"| {c['goal']} | {c['object'] or '-'} | {c['status']} | "
                       f"{', '.join(f'{v:.4f}' for v in c['pressures'])} | {shown} | {c['verified']} | "
                       f"{c['robust']} | {c['time_ms_median']:.0f} ms |")
        rows = [("fingertip target (median)", "inverse_tip_ms"), ("hold goal, from the atlas (median)",
                                                                  "inverse_hold_ms")]
        out += ["", "| figure (inverse.json) | measured | target | met |", "|---|---|---|---|"]
        for label, key in rows:
            checks.append(judge(title, f"inverse {label}", [(Target("<=", t[key], "ms"), m[key])]))
            out.append(f"| {label} | {m[key]:.0f} ms |" + cells(checks[-1]))
        out += [f"| hold goal, without an atlas (median) | {m['inverse_hold_cold_ms']:.0f} ms |" + cells(None)]
        if m.get("inverse_tip_warm_ms") is not None:
            out += [f"| fingertip target, warm (median) | {m['inverse_tip_warm_ms']:.0f} ms |" + cells(None)]
        out += [""]
        out += _track(inv.get("track"), title, checks)
    else:
        out += missing("inverse pressures", "make inverse")
    out += figure(root, "predictor/inverse.png", "inverse answers",
                   f"`make inverse` (`python -m predictor.cli.inverse --cases`, joint model "
                   f"{joint_model(root, (inv or {}).get('joint'))}): each case's answer drawn, its goal "
                   "and status in the title (x: a fingertip target).", "make inverse")
    out += figure(root, "predictor/track.png", "closed-loop tracking",
                  "`make inverse` (`python -m predictor.cli.inverse --cases --track-plot`; alone: `make track`), "
                  f"joint model {joint_model(root, ((inv or {}).get('track') or {}).get('joint'))}, no object, the "
                  "fingers meeting at X = 0: the 100 goals across the reachable region and out of it, the verified "
                  "forward fingertip at each answer, the time per goal, the tip error and the pressures against "
                  "time.", "make inverse")
    return out, checks


def _differ(a: dict, b: dict) -> int:
    """How many grid points two atlases of one grid give different states."""
    return sum(u != v for ru, rv in zip(a["state"], b["state"]) for u, v in zip(ru, rv))


#: The paper-fidelity reference's predictor artefacts (the 1.8 mm surrogate's, the defaults
#: before the switch, issue 55 §3), under results/.
REFERENCE_DIR = "predictor/h1.8"


def _reference_atlases(root: Path, atlases: list) -> list[str]:
    """The atlases on the 1.8 mm reference surrogate (results/predictor/h1.8/): each one's
    counts, how many grid points' state the production atlas changes from it, and how many
    differ from its own ramp reference; its inverse cases and track. Shown, not judged."""
    rows, joint = [], None
    for kind, a in atlases:
        new = load(root, f"{REFERENCE_DIR}/atlas_{kind}.json")
        if not new or new.get("grid") != a["grid"]:
            continue
        joint = joint or joint_model(root, new.get("joint"))
        c, ref = new["counts"], load(root, f"{REFERENCE_DIR}/ramp/atlas_{kind}.json")
        best = ", ".join(f"{v:.3f}" for v in (new.get("best_hold") or {}).get("pressures_MPa", [])) or "none"
        own = f"{_differ(new, ref)}" if ref and ref.get("grid") == new["grid"] else "n/a"
        rows.append(f"| {kind} | {c['no_contact']} / {c['holds']} / {c['slips']} / {c['not_converged']} | {best} "
                    f"| {_differ(new, a)} of {a['grid'] ** 2} | {own} | {new['time_s']:.1f} s |")
    if not rows:
        return []
    inv = load(root, f"{REFERENCE_DIR}/inverse.json")
    if inv:
        rows += ["", f"The inverse cases on it (results/{REFERENCE_DIR}/inverse.json):", "",
                 "| goal | object | status | pressures (MPa) | friction use / tip error | robust |", "|---|---|---|---|---|---|"]
        rows += [f"| {c['goal']} | {c['object'] or '-'} | {c['status']} | "
                 f"{', '.join(f'{v:.4f}' for v in c['pressures'])} | "
                 f"{num(c['friction_use']) if c['friction_use'] is not None else num(c['tip_error_mm']) + ' mm'} "
                 f"| {c['robust']} |" for c in inv["cases"]]
        tr = inv.get("track") or {}
        if tr:
            rows += ["", f"Its track: {tr['reached']} goals reached, {tr['unreachable']} unreachable, {tr['robust']} "
                         f"robust, largest tip error {tr['max_tip_error_mm']:.3f} mm, CPU median "
                         f"{tr['cpu_median_ms']:.0f} ms a goal ({tr['reached_warm_cpu_median_ms']:.1f} ms reached, warm)."]
    return ["#### The paper-fidelity reference: planning on the 1.8 mm surrogate", "",
            "The atlases on results/surrogate/h1.8/improved.pt (joint model "
            f"{joint}, the 1.8 mm displacement data), the defaults before the switch (issue 55 §3), kept in "
            f"results/{REFERENCE_DIR}/ (docs/decisions.md §9 rebuilds them). Shown, not judged.", "",
            "| object | no contact / holds / slips / not converged | best hold (P1, P2) MPa | points whose state "
            "the production atlas changes | points differing from its own ramp reference | time |",
            "|---|---|---|---|---|---|", *rows, ""]


def _track(tr: dict | None, title: str, checks: list) -> list[str]:
    """Issue 60's track (inverse.json ``track``): its figures against the targets."""
    if not tr:
        return missing("the closed-loop track (inverse.json track)", "make inverse")
    load = ", ".join(f"{v:.1f}" for v in tr.get("load_average_before", []))
    out = ["#### Fingertip goals along a trajectory (issue 60)", "",
           f"{tr['goals']} goals across the reachable region and out of it (`predictor.planning.track`), each warm-started "
           f"from the previous answer and verified through the forward equilibrium (with the ±0.01 MPa stencil): "
           f"{tr['reached']} reached, {tr['unreachable']} unreachable (answered with the closest reachable tip, "
           f"flagged), {tr['restarts'] if 'restarts' in tr else '?'} restarts from the kept grid. A benchmark: "
           f"wall times at one thread, load averages {load} before the run, beside: {tr.get('beside', '?')}. "
           f"The kept grids (solved before the first goal): {tr['setup_ms']:.0f} ms.", "",
           "| figure (inverse.json track) | measured | target | met |", "|---|---|---|---|"]
    t = tr.get("targets", {})
    rows = [("reachable goal, warm (median)", tr.get("reached_warm_median_ms"),
             Target("<=", t.get("reachable_warm_ms", 5.0), "ms")),
            ("any goal (median)", tr["median_ms"], Target("<=", t.get("any_warm_ms", 20.0), "ms")),
            ("rate, end to end", tr["rate_hz"], Target(">=", t.get("rate_hz", 50.0), "Hz")),
            ("tip error where reachable (max)", tr["max_tip_error_mm"], Target("<=", t.get("tip_error_mm", 0.1), "mm"))]
    for label, value, target in rows:
        checks.append(judge(title, f"track {label}", [(target, value)]))
        shown = "-" if value is None else f"{value:.3g}"
        out.append(f"| {label} | {shown} {target.unit} |" + cells(checks[-1]))
    if tr.get("cpu_median_ms") is not None:   # the answers' own CPU time: the cost without the machine's load
        out += [f"| CPU time per goal: reachable warm / any / unreachable (median) | "
                f"{num(tr['reached_warm_cpu_median_ms'])} / {num(tr['cpu_median_ms'])} / "
                f"{num(tr['unreachable_cpu_median_ms'])} ms |" + cells(None),
                f"| track rate by CPU time | {tr['cpu_rate_hz']:.3g} Hz |" + cells(None)]
    out += [f"| unreachable goal (median) | {num(tr.get('unreachable_median_ms'))} ms |" + cells(None),
            f"| p95 per goal | {tr['p95_ms']:.0f} ms |" + cells(None),
            f"| first goal | {tr['first_ms']:.0f} ms |" + cells(None),
            f"| every answer verified | {tr['verified']} |" + cells(None), ""]
    return out

def _finer_ramp(root: Path, kind: str, a: dict) -> list[str]:
    """The reference's own path resolution: the sweep ``a`` and the ramp reference against
    a ramp with more sub-steps (results/predictor/ramp_fine/, make atlas-reference-fine),
    on the points that converge on all three."""
    fine, ref = (load(root, f"predictor/{d}/atlas_{kind}.json") for d in ("ramp_fine", "ramp"))
    if not (fine and ref and fine.get("grid") == ref.get("grid") == a["grid"]):
        return []
    fine_s, ref_s, sweep_s = (sum(x["state"], []) for x in (fine, ref, a))
    failed = fine["states"].index("not_converged")
    common = [i for i in range(len(fine_s)) if failed not in (fine_s[i], ref_s[i], sweep_s[i])]
    sweep = sum(sweep_s[i] != fine_s[i] for i in common)
    coarse = sum(ref_s[i] != fine_s[i] for i in common)
    steps, ref_steps = fine.get("ramp_steps"), ref.get("ramp_steps", 12)  # older files: the solver's default, 12
    return [f"Path resolution, {kind}: the ramp with {steps} sub-steps instead of {ref_steps} "
            f"(`make atlas-reference-fine`) converges at {len(fine_s) - fine['counts']['not_converged']} of "
            f"{len(fine_s)} points. On the {len(common)} points that converge on all three paths, the sweep's "
            f"state differs from the {steps}-step ramp's at {sweep} and the {ref_steps}-step reference's at "
            f"{coarse}" + (": the sweep is closer to the finer ramp than the reference is, so most of their "
                           "disagreement is the reference's coarse path." if sweep < coarse else "."), ""]
