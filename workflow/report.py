"""Assemble results/REPORT.md from the committed JSON artefacts (no numbers typed by hand).

    python -m workflow.report [--results results] [--out results/REPORT.md] [--json]

Every table row names the make target / command that produced its JSON file. Sections
whose artefact does not exist yet say so instead of showing a number. Every table that
states a target has a "target" and a "met" column: "yes", or "no, over by X" (an upper
bound missed) / "no, short by X" (a lower bound missed), X in the figure's unit. The
targets are read from the artefacts where their producers record them (fem validation,
mesh study, predictor bench), else from this module (SURROGATE_TARGETS, CAMPAIGN_TARGETS);
the paper's figures count as targets to beat (DESIGN.md §6). ``--json`` prints what was
written: the sections and every target row with its verdict.

Reads JSON only, so it imports nothing from the packages above workflow. REPORT.md is
written atomically (fem.files).
"""

from __future__ import annotations

import json
import math
import operator
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from fem import cli
from fem.files import write_text


def _load(path: Path):
    return json.loads(path.read_text()) if path.is_file() else None


def _missing(what: str, target: str) -> list[str]:
    return [f"_Not produced yet: run `{target}` ({what})._", ""]


_OPS = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt}


@dataclass(frozen=True)
class Target:
    """A figure's target ``value OP bound``, in the artefact's units. ``scale`` turns them
    into shown units (0.94 -> 94 %); ``shown`` is the bound as the report prints it
    (default ``bound * scale`` with :g); ``key`` names the figure in its artefact where a
    producer looks it up (bench_campaign)."""

    op: str
    bound: float
    unit: str = ""
    scale: float = 1.0
    shown: str | None = None
    key: str = ""

    def met(self, value) -> bool:
        return value is not None and math.isfinite(value) and _OPS[self.op](value, self.bound)

    def text(self) -> str:
        return f"{self.op} {self.shown or format(self.bound * self.scale, 'g')} {self.unit}".strip()

    def miss(self, value) -> str | None:
        """None if met, else by how much it is missed: 'over by 237 ms' / 'short by 5 %'."""
        if self.met(value):
            return None
        if value is None or not math.isfinite(value):
            return "not measured"
        gap = abs(value - self.bound) * self.scale
        amount = f"{gap:,.0f}" if gap >= 100 else f"{gap:.3g}"
        return f"{'over' if self.op.startswith('<') else 'short'} by {amount} {self.unit}".strip()


@dataclass(frozen=True)
class Check:
    """One target row of the report: the figure, its target(s) and the verdict."""

    section: str
    figure: str
    target: str
    values: tuple
    met: bool
    verdict: str


def judge(section: str, figure: str, pairs) -> Check:
    """The Check of a row whose ``pairs`` [(Target, value), ...] must all be met."""
    misses = [m for t, v in pairs if (m := t.miss(v))]
    return Check(section, figure, ", ".join(t.text() for t, _ in pairs),
                 tuple(v for _, v in pairs), not misses, "yes" if not misses else "no, " + "; ".join(misses))


def _cells(check: Check | None) -> str:
    """The target and met cells of a table row (empty for a row without a target)."""
    return f" {check.target} | {check.verdict} |" if check else " | |"


#: Issue 2's speed targets for one joint sample on one core (the paper: ~420 s in ANSYS).
FEM_TARGETS = (Target("<", 60, "s"), Target("<", 10, "s"))


def fem_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "FEM bellow joint (issue 2)"
    out, checks = [f"## {title}", ""], []
    val = _load(root / "fem/validation.json")
    out += ["### Validation against the exact elastica (`make validation`)", ""]
    if val:
        required = val["required"]
        tip = {kind: Target("<=", required[kind], "% L", 100) for kind in required}
        out += ["Slender 3D cantilever (L/h = 50, nu = 0), same loading code as the joint.", "",
                "| case | load | FEM | exact | tip error (% L) | target | met |",
                "|---|---|---|---|---|---|---|"]
        for c in val["cantilever"]:
            checks.append(judge(title, f"cantilever alpha = {c['alpha']:g} tip error",
                                [(tip["cantilever"], c["error_over_L"])]))
            out.append(f"| cantilever | alpha = {c['alpha']:g} | u/L {c['u_over_L']:.5f}, w/L "
                       f"{c['w_over_L']:.5f}, theta {c['theta']:.4f} | {c['exact']['u_over_L']:.5f}, "
                       f"{c['exact']['w_over_L']:.5f}, {c['exact']['theta']:.4f} | "
                       f"{100 * c['error_over_L']:.3f} |" + _cells(checks[-1]))
        for r in val["rollup"]:
            checks.append(judge(title, f"roll-up T = {r['theta_load']:.4f} tip error",
                                [(tip["rollup"], r["error_over_L"])]))
            out.append(f"| roll-up | T = {r['theta_load']:.4f} | x/L {r['x_over_L']:.5f}, y/L "
                       f"{r['y_over_L']:.5f}, theta {r['theta']:.4f} | {r['exact']['x_over_L']:.5f}, "
                       f"{r['exact']['y_over_L']:.5f}, {r['exact']['theta']:.4f} | "
                       f"{100 * r['error_over_L']:.3f} |" + _cells(checks[-1]))
        out += ["", f"Worst: cantilever {100 * val['max_cantilever_error_over_L']:.3f} % L "
                f"(required {100 * required['cantilever']:g} %), roll-up "
                f"{100 * val['max_rollup_error_over_L']:.3f} % L (required {100 * required['rollup']:g} %).", ""]
    else:
        out += _missing("elastica sweeps", "make validation")

    ms = _load(root / "fem/mesh_study.json")
    out += ["### Mesh convergence (`make mesh-study`)", ""]
    if ms:
        error = Target("<=", ms["tolerance_percent"], "%")
        nodes = Target(">=", ms.get("min_nodes", 0), "nodes", shown=f"{ms.get('min_nodes', 0):,}")
        out += ["Four corners of the input box, solved from zero on each mesh; error = largest "
                "anchor distance to the finest mesh over the largest anchor displacement.", "",
                "| h (mm) | P2 nodes | dofs | error per corner (%) | max (%) | target | met |",
                "|---|---|---|---|---|---|---|"]
        for m in ms["meshes"]:  # the rule picks the production mesh: only it is judged
            errs = ", ".join(f"{e:.2f}" for e in m["error_vs_finest_percent"])
            check = None
            if m["mesh_size"] == ms["production_mesh_size"]:
                check = judge(title, f"production mesh h = {m['mesh_size']} mm",
                              [(error, m["max_error_percent"]), (nodes, m["nodes"])])
                checks.append(check)
            out.append(f"| {m['mesh_size']} | {m['nodes']} | {m['dofs']} | {errs} | "
                       f"{m['max_error_percent']:.2f} |" + _cells(check))
        out += ["", f"Production mesh: h = {ms['production_mesh_size']} mm "
                f"(the coarsest within {ms['tolerance_percent']} % of the finest, the paper "
                f"accepted 3 %, with at least {ms.get('min_nodes', 0):,} nodes, the paper's "
                f"resolution).", ""]
    else:
        out += _missing("mesh convergence", "make mesh-study")

    sc = _load(root / "fem/self_contact.json")
    out += ["### Self-contact of the bellows (`make self-contact`)", ""]
    if sc:
        out += [f"Penalty self-contact ({sc['contact_penalty_MPa_per_mm']} MPa/mm, `fem.contact`). "
                f"Minimum signed gap between facing outer cell walls over the box corners and "
                f"their mirrors: **{sc['min_gap_mm']:.3f} mm** (undeformed "
                f"{sc['undeformed_gap_mm']} mm; negative is overlap); unsolved cases: "
                f"{sc['unsolved_cases']}.", "",
                "| load (P, F1, F2, M) | phi_end (deg) | min gap (mm) |", "|---|---|---|"]
        for c in sc["cases"]:
            gap = f"{c['min_gap_mm']:.3f}" if c.get("converged") else "not converged"
            out.append(f"| {tuple(c['load'])} | {c['phi_end_deg']:.1f} | {gap} |")
        out.append("")
    else:
        out += _missing("valley gaps", "make self-contact")

    b = _load(root / "bench/fem.json")
    out += ["### Timing (`make bench-fem`, one core)", ""]
    if b:
        paper_nodes = Target(">=", b["paper_nodes"], "nodes", shown=f"{b['paper_nodes']:,}")
        zero_s, cont_s = FEM_TARGETS
        mesh, zero, cont = (judge(title, f, pairs) for f, pairs in (
            ("FEM mesh nodes", [(paper_nodes, b["nodes"])]),
            ("FEM solve from zero", [(zero_s, b["solve_from_zero_s"])]),
            ("FEM sample by continuation", [(cont_s, b["continuation_sample_s"])])))
        checks += [mesh, zero, cont]
        out += ["| figure | ours | paper (ANSYS) | target | met |", "|---|---|---|---|---|",
                f"| mesh | {b['nodes']} P2 nodes, {b['dofs']} dofs, h = {b['mesh_size']} mm | "
                f"16,000 nodes, 1.2 mm |" + _cells(mesh),
                f"| solve from zero (median of {len(b['solve_from_zero_cases'])}) | "
                f"{b['solve_from_zero_s']:.1f} s, {b['newton_iterations']:.0f} Newton iterations | ~420 s |"
                + _cells(zero),
                f"| next sample by continuation (median, step {b['continuation_step_fraction_of_box']} "
                f"of the box, with sensitivities) | {b['continuation_sample_s']:.1f} s | ~420 s |" + _cells(cont),
                f"| speed-up vs paper | {b['speedup_vs_paper_from_zero']:.1f}x from zero, "
                f"{b['speedup_vs_paper_continuation']:.1f}x continuation | |" + _cells(None), ""]
    else:
        out += _missing("timings", "make bench-fem")
    return out, checks


#: Issue 3's throughput targets (bench_campaign records whether they are met).
CAMPAIGN_TARGETS = (Target(">=", 400, key="samples_per_hour_2ranks"),
                    Target(">=", 0.85, "%", 100, key="parallel_efficiency"))


def campaign_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "FEM dataset campaign (issue 3)"
    out, checks = [f"## {title}", ""], []
    rows = []
    for name in ("train", "heldout"):
        m = _load(root / "data" / name / "manifest.json")
        if m:
            done = m["samples"] + m["failures"]
            rows.append(f"| {name} | {m['seed']} | {m['samples']} of {m['samples_requested']} | "
                        f"{m['units_done']} of {m['units_total']} | {m['failures']} "
                        f"({100 * m['failures'] / max(done, 1):.2f} %) | {m['cpu_hours']:.2f} | "
                        f"{'yes' if m['complete'] else 'no (resumes)'} |")
    if rows:
        out += ["From the committed manifests (`make dataset`; `python -m workflow.dataset info DIR`).",
                "", "| set | seed | converged samples | units | failures | CPU hours | complete |",
                "|---|---|---|---|---|---|---|", *rows, ""]
    else:
        out += _missing("FEM datasets", "make dataset")
    b = _load(root / "bench/campaign.json")
    out += ["### Campaign throughput (`make bench-campaign`)", ""]
    if b:
        rate, eff = (judge(title, f, [(t, b[t.key])]) for f, t in
                     zip(("campaign samples per hour, 2 ranks", "campaign parallel efficiency"),
                         CAMPAIGN_TARGETS))
        harvested = judge(title, "campaign harvested sample", [(Target("<", 420, "s"), b["harvested_sample_s"])])
        cpu = judge(title, "campaign CPU hours of the committed data",
                    [(Target("<", b["paper_cpu_hours"], "CPU h"), b["dataset_cpu_hours"])])
        checks += [rate, eff, harvested, cpu]
        out += ["| figure | ours | target / paper | met |", "|---|---|---|---|",
                f"| samples per hour, 1 rank | {b['samples_per_hour_1rank']:.0f} | | |",
                f"| samples per hour, 2 ranks | {b['samples_per_hour_2ranks']:.0f} | {rate.target} | {rate.verdict} |",
                f"| parallel efficiency | {100 * b['parallel_efficiency']:.0f} % | {eff.target} | {eff.verdict} |",
                f"| per-unit efficiency (same units, 1 rank vs 2 concurrent) | "
                f"{100 * b['per_unit_efficiency']:.0f} % | | |",
                f"| harvested sample vs fresh solve | {b['harvested_sample_s']:.1f} s vs "
                f"{b['fresh_sample_s']:.1f} s | ~420 s (ANSYS) | {harvested.verdict} |",
                f"| CPU hours of the committed data | {b['dataset_cpu_hours']:.2f} | ~300 for 2,560 | "
                f"{cpu.verdict} |", ""]
    else:
        out += _missing("campaign throughput", "make bench-campaign")
    return out, checks


# Issue 4's accuracy targets for the improved surrogate on the held-out set.
SURROGATE_TARGETS = (("mean anchor error", "mean_anchor_error_mm", 0.10, "mm"),
                     ("95th-percentile anchor error", "p95_anchor_error_mm", 0.30, "mm"),
                     ("phi_end error", "phi_end_error_deg", 0.3, "deg"),
                     ("Jacobian relative error", "jacobian_rel_error", 0.05, ""))


def _num(v, spec: str = ".4g") -> str:
    return "n/a" if v is None else format(v, spec)


def surrogate_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "Joint surrogate (issue 4)"
    out = [f"## {title}", ""]
    m = _load(root / "surrogate/metrics.json")
    if not m:
        return out + _missing("needs the FEM dataset of `make dataset`", "make train"), []
    keys = ("mean_anchor_error_mm", "p95_anchor_error_mm", "tip_error_mm", "phi_end_error_deg",
            "jacobian_rel_error")
    n = m.get("datasets", {}).get("train", {}).get("n", {})
    out += [f"`make train` (results/surrogate/metrics.json): trained on the train split "
            f"{n.get('train', '?')} samples, chosen on validation ({n.get('val', '?')}); test split "
            f"and the separate held-out set. Paper's mean anchor error: NN 0.19 mm, KNN 1.04 mm.", "",
            "| model | set | n | " + " | ".join(keys) + " | train time (s) |",
            "|---" * (len(keys) + 4) + "|"]
    for name in ("paper", "improved", "knn"):
        for split in ("test", "heldout"):
            r = m[name][split]
            out.append(f"| {name} | {split} | {r['n']} | " + " | ".join(_num(r[k]) for k in keys)
                       + f" | {_num(m[name].get('train_time_s'), '.0f')} |")
    improved = m["improved"]
    held, t = improved["heldout"], improved.get("timing", {})
    cores = max(t.get("threads", [1]))
    batched = t.get("batched_samples_per_s_float32_all_cores")
    rows = [(label, f"{_num(held[key])} {unit}".strip(), Target("<=", target, unit), held[key])
            for label, key, target, unit in SURROGATE_TARGETS]
    rows += [("single-sample inference (1 thread, f64)", f"{_num(t.get('single_ms_float64'), '.3f')} ms",
              Target("<=", 0.2, "ms"), t.get("single_ms_float64")),
             (f"batched inference (f32, {cores} thread(s))", f"{_num(batched, '.3g')} /s",
              Target(">=", 1e6, "/s", shown="1e6"), batched),
             ("training time", f"{_num(improved.get('train_time_s'), '.0f')} s",
              Target("<", 900, "s"), improved.get("train_time_s"))]
    checks = [judge(title, f"surrogate {label}", [(target, value)]) for label, _, target, value in rows]
    out += ["", "Improved model against issue 4's targets (held-out set):", "",
            "| figure | measured | target | met |", "|---|---|---|---|"]
    out += [f"| {label} | {shown} |" + _cells(c) for (label, shown, _, _), c in zip(rows, checks)]
    return out + [""], checks


def predictor_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "Gripper gesture predictor (issue 5)"
    out = [f"## {title}", ""]
    b = _load(root / "bench/predictor.json")
    if not b:
        return out + _missing("predictor timings", "make bench-predictor"), []
    t = b.get("targets", {})

    def target(key, op, unit, shown=None):
        return [] if key not in t else [Target(op, t[key], unit, shown=shown, key=key)]

    nn = [*target("nn_mN", "<=", "mN"), *target("nn_Nmm", "<=", "N·mm")]
    raw = b["details"]  # the raw-network figures of the contact NN
    rows = [("gravity gesture, Newton (median)", f"{b['gravity_newton_median_ms']:.1f} ms", "2-3 s",
             target("gravity_newton_ms", "<=", "ms"), [b["gravity_newton_median_ms"]]),
            ("gravity gesture, L-BFGS (median)", f"{b['gravity_lbfgs_median_ms']:.1f} ms", "2-3 s", [], []),
            ("contact gesture (median)", f"{b['contact_median_ms']:.1f} ms", "10-15 s",
             target("contact_ms", "<=", "ms"), [b["contact_median_ms"]]),
            ("gravity NN residual", f"{b['gravity_nn_residual_force_mN']:.3g} mN, "
             f"{b['gravity_nn_residual_moment_Nmm']:.3g} N·mm", "< 2 mN, 1.2 N·mm",
             nn, [b["gravity_nn_residual_force_mN"], b["gravity_nn_residual_moment_Nmm"]]),
            ("contact NN residual, raw network (no solver)", f"{raw['contact_nn_raw_residual_force_mN']:.4g} mN, "
             f"{raw['contact_nn_raw_residual_moment_Nmm']:.4g} N·mm", "> 10 mN, 7 N·mm (failed)",
             nn, [raw["contact_nn_raw_residual_force_mN"], raw["contact_nn_raw_residual_moment_Nmm"]]),
            # The polished figure is the solver's, not the network's: shown, not judged.
            ("contact NN + capped LM polish (solver result)", f"{b['contact_nn_residual_force_mN']:.3g} mN, "
             f"{b['contact_nn_residual_moment_Nmm']:.3g} N·mm", "", [], []),
            ("NN throughput (batched)", f"{b['nn_batched_per_s']:.3g} gestures/s", "< 0.1 s per query",
             target("nn_batched_per_s", ">=", "gestures/s", shown=f"{t.get('nn_batched_per_s', 0):.3g}"),
             [b["nn_batched_per_s"]])]
    checks = [judge(title, f"predictor {a}", list(zip(targets, values))) if targets else None
              for a, _, _, targets, values in rows]
    joint = b.get("joint", "unrecorded")
    out += [f"Joint model: {joint}.", "", "| figure | ours | paper | target | met |", "|---|---|---|---|---|"]
    out += [f"| {a} | {c} | {d} |" + _cells(check) for (a, c, d, _, _), check in zip(rows, checks)]
    return out + [""], [c for c in checks if c]


def planning_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "Grasp planning (issue 16)"
    out, checks = [f"## {title}", ""], []
    atlases = [(kind, a) for kind in ("circle", "ellipse", "rectangle")
               if (a := _load(root / f"predictor/atlas_{kind}.json"))]
    out += ["### Grasp atlas (`make atlas`)", ""]
    if atlases:
        out += [f"Every (P1, P2) of a {atlases[0][1]['grid']} x {atlases[0][1]['grid']} grid over the "
                "pressure box, each solved along the pressure ramp from the approach gesture "
                f"({', '.join(f'{v:g}' for v in atlases[0][1]['approach_MPa'])} MPa), in one batched "
                f"solve; friction use = |f|/(mu N), mu = {atlases[0][1]['mu']}.", "",
                "| object | no contact | holds | slips | not converged | best hold (P1, P2) MPa "
                "| its friction use | time | paper (10-15 s a gesture) | target | met |",
                "|---|---|---|---|---|---|---|---|---|---|---|"]
        for kind, a in atlases:
            c, best = a["counts"], a.get("best_hold") or {}
            checks.append(judge(title, f"atlas {kind}", [(Target("<=", a["targets"]["atlas_s_per_object"], "s"),
                                                          a["measured"]["atlas_s_per_object"])]))
            hold_p = ", ".join(f"{v:.3f}" for v in best.get("pressures_MPa", [])) or "none"
            paper_h = 12.5 * a["measured"]["grid_points"] / 3600
            out.append(f"| {kind} | {c['no_contact']} | {c['holds']} | {c['slips']} | {c['not_converged']} | "
                       f"{hold_p} | {_num(best.get('friction_use'))} | {a['measured']['atlas_s_per_object']:.1f} s "
                       f"| ~{paper_h:.0f} h |" + _cells(checks[-1]))
        out += ["", "".join(f"![atlas {k}](predictor/atlas_{k}.png)\n" for k, _ in atlases)]
    else:
        out += _missing("grasp atlas", "make atlas")
    inv = _load(root / "predictor/inverse.json")
    out += ["### Inverse pressures (`make inverse`)", ""]
    if inv:
        t, m = inv["targets"], inv["measured"]
        out += ["Gradients by the implicit function theorem on the converged equilibrium; every answer "
                "verified by a forward solve along the ramp, and its robustness checked at the "
                f"regulators' +/-{inv['tolerances']['regulator_MPa']} MPa.", "",
                "| goal | object | status | pressures (MPa) | friction use / tip error | verified | robust | time |",
                "|---|---|---|---|---|---|---|---|"]
        for c in inv["cases"]:
            figure = (f"{_num(c['friction_use'])}" if c["friction_use"] is not None
                      else f"{_num(c['tip_error_mm'])} mm")
            out.append(f"| {c['goal']} | {c['object'] or '-'} | {c['status']} | "
                       f"{', '.join(f'{v:.4f}' for v in c['pressures'])} | {figure} | {c['verified']} | "
                       f"{c['robust']} | {c['time_ms_median']:.0f} ms |")
        rows = [("fingertip target (median)", "inverse_tip_ms"), ("hold goal, from the atlas (median)",
                                                                  "inverse_hold_ms")]
        out += ["", "| figure | measured | target | met |", "|---|---|---|---|"]
        for label, key in rows:
            checks.append(judge(title, f"inverse {label}", [(Target("<=", t[key], "ms"), m[key])]))
            out.append(f"| {label} | {m[key]:.0f} ms |" + _cells(checks[-1]))
        out.append(f"| hold goal, without an atlas (median) | {m['inverse_hold_cold_ms']:.0f} ms | | |")
        out += ["", "![inverse answers](predictor/inverse.png)", ""]
    else:
        out += _missing("inverse pressures", "make inverse")
    return out, checks


def _finger_budget(root: Path, v: dict, judged: dict) -> list[str]:
    """The fingertip error budget: discretisation (the finger FEM on a finer mesh, and
    the joint mesh study), surrogate (held-out set) and finger model (the validation)."""
    out = ["", "Fingertip error budget (how far each stage can move the fingertip):", "",
           "| term | figure | source |", "|---|---|---|"]
    for m in v.get("mesh_check", []):
        out.append(f"| discretisation: finger FEM, joint mesh {m['production_mesh_size']} -> {m['mesh_size']} mm "
                   f"({m['production_nodes']:,} -> {m['nodes']:,} nodes), {m['case']} | {m['tip_change_mm']:.2f} mm, "
                   f"{m['tip_angle_change_deg']:+.2f}° | `python -m fem.finger_cases --mesh-size {m['mesh_size']}` |")
    study = _load(root / "fem/mesh_study.json")
    if study:
        sizes = sorted(m["mesh_size"] for m in study["meshes"])
        fine, prod = (next(m for m in study["meshes"] if m["mesh_size"] == h) for h in (sizes[0], 1.8))
        dr = max(math.dist(a, b) for p, f in zip(prod["cases"], fine["cases"])
                 for a, b in zip(p["anchors"], f["anchors"]))
        dphi = max(abs(p["phi_end_deg"] - f["phi_end_deg"]) for p, f in zip(prod["cases"], fine["cases"]))
        out.append(f"| discretisation: one joint at the box corners, mesh 1.8 -> {sizes[0]} mm | anchors {dr:.2f} mm, "
                   f"phi_end {dphi:.2f}° (at the corners, far beyond the finger's joint loads) | `make mesh-study` |")
    cap = _load(root / "surrogate/cap/metrics.json")
    if cap:
        h = cap["heldout"]
        out.append(f"| surrogate (held-out, n = {h['n']}) | tip {h['tip_error_mm']:.3f} mm, cap rotation "
                   f"{h['cap_rotation_error_deg']:.3f}° mean ({h['p95_cap_rotation_error_deg']:.2f}° p95) | "
                   "results/surrogate/cap/metrics.json |")
    out.append(f"| finger model + surrogate against the finger FEM ({v['judged_variant']}) | "
               f"{judged['tip_error_mm_max']:.2f} mm max, {judged['tip_angle_error_deg_max']:.2f}° | this validation |")
    return out


def finger_section(root: Path) -> tuple[list[str], list[Check]]:
    title = "Whole-finger validation (issue 14)"
    out, checks = [f"## {title}", ""], []
    v = _load(root / "validation/finger.json")
    if not v:
        return out + _missing("needs the finger FEM of `make finger-fem`", "make validate-finger"), []
    t, s = v["targets"], v["summary"]
    judged = v["judged_variant"]
    fem = v["fem"]
    mesh = fem[0]["mesh"]
    out += [f"`make validate-finger` (results/validation/finger.json): the finger FEM (`python -m fem.finger`, "
            f"finger file {v['finger']['name']!r}, {mesh['nodes']:,} P2 nodes, joint mesh {mesh['mesh_size']} mm, "
            "one rank) against the predictor on the same finger file and the joint model "
            f"{v['joint']}; every predictor figure is a single-query Newton solve (median of "
            f"{v['repeats']}). Angle errors are predictor minus FEM. The judged variant is "
            f"**{judged}**; the paper's tangent connection is shown beside it.", "",
            "| case | FEM tip (X, Y) mm | FEM tip angle | tangent: tip / angle error | cap: tip / angle error "
            "| cap + split weight | surrogate chain (tau = 0, cap) | FEM | predictor |",
            "|---|---|---|---|---|---|---|---|---|"]
    by = {}
    for e in v["cases"]:
        by.setdefault(e["case"], {})[e["variant"]] = e
    failed = [c for c in fem if not c["converged"]]
    for c in fem:
        if not c["converged"]:
            out.append(f"| {c['case']} | FEM did not converge ({c.get('reason') or 'no reason recorded'}; "
                       f"{c['fem_s']:.0f} s): no answer, not compared | | | | | | | |")
            continue
        rows = by.get(c["case"], {})
        cell = lambda k: (f"{rows[k]['tip_error_mm']:.2f} mm / {rows[k]['tip_angle_error_deg']:+.2f}°"
                          if k in rows else "n/a")
        pred = rows.get(judged, {})
        out.append(f"| {c['case']} | ({c['tip'][0]:.2f}, {c['tip'][1]:.2f}) | {c['tip_angle_deg']:.2f}° | "
                   f"{cell('predictor_tangent_lumped')} | {cell('predictor_cap_lumped')} | "
                   f"{cell('predictor_cap_split')} | {cell('chain_cap')} | {c['fem_s']:.0f} s | "
                   f"{1000 * pred.get('predictor_s', math.nan):.1f} ms |")
    j, tang = s[judged], s.get("predictor_tangent_lumped")
    solved = [c for c in fem if c["converged"]]
    fem_max = max(c["fem_s"] for c in solved)
    rows = [(f"fingertip error, {judged} (max over {j['cases']} cases)", f"{j['tip_error_mm_max']:.2f} mm",
             Target("<=", t["tip_error_mm"], "mm"), j["tip_error_mm_max"]),
            (f"fingertip angle error, {judged} (max)", f"{j['tip_angle_error_deg_max']:.2f}°",
             Target("<=", t["tip_angle_error_deg"], "deg"), j["tip_angle_error_deg_max"]),
            ("speed-up of the predictor over the finger FEM (min)", f"{j['speedup_min']:,.0f}x",
             Target(">=", t["speedup"], "x"), j["speedup_min"]),
            ("finger FEM per gesture, production mesh, one core (max, wall time)", f"{fem_max:.0f} s",
             Target("<=", t["fem_s"], "s"), fem_max),
            ("validation cases the FEM solved (issue 14: 4 free, 2 gravity, >= 8 more)",
             f"{len(solved)} of {len(fem)} run", Target(">=", t["fem_cases"], "cases"), len(solved))]
    out += ["", "| figure | measured | paper | target | met |", "|---|---|---|---|---|"]
    papers = ["", "", "~100x", "20-30 min (ANSYS)", ""]
    for (label, shown, target, value), paper in zip(rows, papers):
        checks.append(judge(title, f"finger {label}", [(target, value)]))
        out.append(f"| {label} | {shown} | {paper} |" + _cells(checks[-1]))
    if tang:
        out.append(f"| fingertip error, tangent kinematics (the paper's; max) | {tang['tip_error_mm_max']:.2f} mm, "
                   f"{tang['tip_angle_error_deg_max']:.2f}° | | | |")
    cap = _load(root / "surrogate/cap/metrics.json")
    if cap:
        h = cap["heldout"]
        out += ["", f"The cap kinematics' joint model ({cap['model']}) predicts the distal cap's rotation with "
                f"{h['cap_rotation_error_deg']:.3f}° mean and {h['p95_cap_rotation_error_deg']:.3f}° p95 error on the "
                f"held-out set (n = {h['n']}); taking the chord angle phi_end for it, as the tangent connection "
                f"does, is off by {h['tangent_error_deg']:.2f}° mean, {h['p95_tangent_error_deg']:.2f}° p95. Its "
                f"anchors: {h['mean_anchor_error_mm']:.4f} mm mean (the committed improved.pt: "
                f"{cap['committed_improved_for_comparison']['mean_anchor_error_mm']:.4f} mm)."]
    out += _finger_budget(root, v, j)
    loads = [c["load_average"] for c in solved if c.get("load_average") is not None]
    out += ["", "The FEM wall times were measured with two cases solving at once, one per core"
            + (f" (load average {min(loads):.1f} to {max(loads):.1f})" if loads else ", and other jobs on the machine")
            + "; an idle core is faster. A case the FEM did not solve is a shortfall of the FEM, not of the predictor."]
    out += ["", "Overlays: the FEM coloured by |u| (pyvista), the predictor's centre lines over it "
            "(black: cap kinematics, red dashed: tangent).", ""]
    out += ["".join(f"![{Path(f).stem}](validation/{Path(f).name})\n" for f in v["figures"]), ""]
    return out, checks


SECTIONS = (fem_section, campaign_section, surrogate_section, predictor_section, finger_section, planning_section)


def build(root: Path) -> tuple[str, list[str], list[Check]]:
    """(REPORT.md text, section titles, target checks) from the artefacts under ``root``."""
    lines = ["# softjoint report", "",
             "Generated by `python -m workflow.report` from the JSON artefacts in results/; "
             "each section names the make target that produced its numbers.", ""]
    checks = []
    for section in SECTIONS:
        part, found = section(root)
        lines += part
        checks += found
    return "\n".join(lines), [ln[3:] for ln in lines if ln.startswith("## ")], checks


def report(root: Path) -> str:
    """The text of REPORT.md from the artefacts under ``root``."""
    return build(root)[0]


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m workflow.report", description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default="results", help="artefact folder (default results)")
    ap.add_output("--out", suffix=".md", default="results/REPORT.md",
                  help="report file (default results/REPORT.md)")
    args = ap.parse_args(argv)
    if not Path(args.results).is_dir():
        ap.error(f"--results {args.results}: not a folder")
    with ap.errors():
        text, sections, checks = build(Path(args.results))
        write_text(args.out, text)
    if args.json:
        cli.print_json({"out": args.out, "sections": sections,
                        "targets": [asdict(c) for c in checks],
                        "met": sum(c.met for c in checks), "missed": sum(not c.met for c in checks)})
    else:
        missed = [c for c in checks if not c.met]
        print(f"wrote {args.out}: {len(sections)} sections, {len(checks) - len(missed)} of "
              f"{len(checks)} targets met" + "".join(f"; {c.figure}: {c.verdict}" for c in missed))
    return 0


if __name__ == "__main__":
    sys.exit(main())
