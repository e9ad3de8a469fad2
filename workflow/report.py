"""Assemble results/REPORT.md from the committed JSON artefacts (no numbers typed by hand).

    python -m workflow.report [--results results] [--out results/REPORT.md]

Every table row names the make target / command that produced its JSON file. Sections
whose artefact does not exist yet say so instead of showing a number. Reads JSON only, so
it imports nothing from the packages above workflow.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _load(path: Path):
    return json.loads(path.read_text()) if path.is_file() else None


def _missing(what: str, target: str) -> list[str]:
    return [f"_Not produced yet: run `{target}` ({what})._", ""]


def fem_section(root: Path) -> list[str]:
    out = ["## FEM bellow joint (issue 2)", ""]
    val = _load(root / "fem/validation.json")
    out += ["### Validation against the exact elastica (`make validation`)", ""]
    if val:
        out += ["Slender 3D cantilever (L/h = 50, nu = 0), same loading code as the joint.", "",
                "| case | load | FEM | exact | tip error (% L) |", "|---|---|---|---|---|"]
        for c in val["cantilever"]:
            out.append(f"| cantilever | alpha = {c['alpha']:g} | u/L {c['u_over_L']:.5f}, w/L "
                       f"{c['w_over_L']:.5f}, theta {c['theta']:.4f} | {c['exact']['u_over_L']:.5f}, "
                       f"{c['exact']['w_over_L']:.5f}, {c['exact']['theta']:.4f} | "
                       f"{100 * c['error_over_L']:.3f} |")
        for r in val["rollup"]:
            out.append(f"| roll-up | T = {r['theta_load']:.4f} | x/L {r['x_over_L']:.5f}, y/L "
                       f"{r['y_over_L']:.5f}, theta {r['theta']:.4f} | {r['exact']['x_over_L']:.5f}, "
                       f"{r['exact']['y_over_L']:.5f}, {r['exact']['theta']:.4f} | "
                       f"{100 * r['error_over_L']:.3f} |")
        out += ["", f"Worst: cantilever {100 * val['max_cantilever_error_over_L']:.3f} % L "
                f"(required 1.5 %), roll-up {100 * val['max_rollup_error_over_L']:.3f} % L (required 2 %).", ""]
    else:
        out += _missing("elastica sweeps", "make validation")

    ms = _load(root / "fem/mesh_study.json")
    out += ["### Mesh convergence (`make mesh-study`)", ""]
    if ms:
        out += ["Four corners of the input box, solved from zero on each mesh; error = largest "
                "anchor distance to the finest mesh over the largest anchor displacement.", "",
                "| h (mm) | P2 nodes | dofs | error per corner (%) | max (%) |", "|---|---|---|---|---|"]
        for m in ms["meshes"]:
            errs = ", ".join(f"{e:.2f}" for e in m["error_vs_finest_percent"])
            out.append(f"| {m['mesh_size']} | {m['nodes']} | {m['dofs']} | {errs} | "
                       f"{m['max_error_percent']:.2f} |")
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
        out += ["| figure | ours | paper (ANSYS) |", "|---|---|---|",
                f"| mesh | {b['nodes']} P2 nodes, {b['dofs']} dofs, h = {b['mesh_size']} mm | "
                f"16,000 nodes, 1.2 mm |",
                f"| solve from zero (median of {len(b['solve_from_zero_cases'])}) | "
                f"{b['solve_from_zero_s']:.1f} s, {b['newton_iterations']:.0f} Newton iterations | ~420 s |",
                f"| next sample by continuation (median, step {b['continuation_step_fraction_of_box']} "
                f"of the box, with sensitivities) | {b['continuation_sample_s']:.1f} s | ~420 s |",
                f"| speed-up vs paper | {b['speedup_vs_paper_from_zero']:.1f}x from zero, "
                f"{b['speedup_vs_paper_continuation']:.1f}x continuation | |", ""]
    else:
        out += _missing("timings", "make bench-fem")
    return out


def campaign_section(root: Path) -> list[str]:
    out = ["## FEM dataset campaign (issue 3)", ""]
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
        out += ["| figure | ours | target / paper |", "|---|---|---|",
                f"| samples per hour, 1 rank | {b['samples_per_hour_1rank']:.0f} | |",
                f"| samples per hour, 2 ranks | {b['samples_per_hour_2ranks']:.0f} | >= 400 |",
                f"| parallel efficiency | {100 * b['parallel_efficiency']:.0f} % | >= 85 % |",
                f"| per-unit efficiency (same units, 1 rank vs 2 concurrent) | "
                f"{100 * b['per_unit_efficiency']:.0f} % | |",
                f"| harvested sample vs fresh solve | {b['harvested_sample_s']:.1f} s vs "
                f"{b['fresh_sample_s']:.1f} s | ~420 s (ANSYS) |",
                f"| CPU hours of the committed data | {b['dataset_cpu_hours']:.2f} | ~300 for 2,560 |", ""]
    else:
        out += _missing("campaign throughput", "make bench-campaign")
    return out


# Issue 4's accuracy targets for the improved surrogate on the held-out set.
SURROGATE_TARGETS = (("mean anchor error", "mean_anchor_error_mm", 0.10, "mm"),
                     ("95th-percentile anchor error", "p95_anchor_error_mm", 0.30, "mm"),
                     ("phi_end error", "phi_end_error_deg", 0.3, "deg"),
                     ("Jacobian relative error", "jacobian_rel_error", 0.05, ""))


def _num(v, spec: str = ".4g") -> str:
    return "n/a" if v is None else format(v, spec)


def surrogate_section(root: Path) -> list[str]:
    out = ["## Joint surrogate (issue 4)", ""]
    m = _load(root / "surrogate/metrics.json")
    if not m:
        return out + _missing("needs the FEM dataset of `make dataset`", "make train")
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
    rows = [(label, f"{_num(held[key])} {unit}".strip(), f"<= {target:g} {unit}".strip(),
             held[key] is not None and held[key] <= target)
            for label, key, target, unit in SURROGATE_TARGETS]
    rows += [("single-sample inference (1 thread, f64)", f"{_num(t.get('single_ms_float64'), '.3f')} ms",
              "<= 0.2 ms", (t.get("single_ms_float64") or 1e9) <= 0.2),
             (f"batched inference (f32, {cores} thread(s))", f"{_num(batched, '.3g')} /s",
              ">= 1e6 /s", (batched or 0) >= 1e6),
             ("training time", f"{_num(improved.get('train_time_s'), '.0f')} s", "< 900 s",
              (improved.get("train_time_s") or 1e9) < 900)]
    out += ["", "Improved model against issue 4's targets (held-out set):", "",
            "| figure | measured | target | met |", "|---|---|---|---|"]
    out += [f"| {a} | {b} | {c} | {'yes' if ok else 'no'} |" for a, b, c, ok in rows]
    return out + [""]


def predictor_section(root: Path) -> list[str]:
    out = ["## Gripper gesture predictor (issue 5)", ""]
    b = _load(root / "bench/predictor.json")
    if not b:
        return out + _missing("predictor timings", "make bench-predictor")
    rows = [("gravity gesture, Newton (median)", f"{b['gravity_newton_median_ms']:.1f} ms", "2-3 s"),
            ("gravity gesture, L-BFGS (median)", f"{b['gravity_lbfgs_median_ms']:.1f} ms", "2-3 s"),
            ("contact gesture (median)", f"{b['contact_median_ms']:.1f} ms", "10-15 s"),
            ("gravity NN residual", f"{b['gravity_nn_residual_force_mN']:.3g} mN, "
             f"{b['gravity_nn_residual_moment_Nmm']:.3g} N·mm", "< 2 mN, 1.2 N·mm"),
            ("contact NN residual (NN + capped LM polish)", f"{b['contact_nn_residual_force_mN']:.3g} mN, "
             f"{b['contact_nn_residual_moment_Nmm']:.3g} N·mm", "> 10 mN, 7 N·mm (failed)"),
            ("NN throughput (batched)", f"{b['nn_batched_per_s']:.3g} gestures/s", "< 0.1 s per query")]
    joint = b.get("joint", "unrecorded")
    out += [f"Joint model: {joint}.", "", "| figure | ours | paper |", "|---|---|---|"]
    out += [f"| {a} | {c} | {d} |" for a, c, d in rows]
    return out + [""]


def report(root: Path) -> str:
    lines = ["# softjoint report", "",
             "Generated by `python -m workflow.report` from the JSON artefacts in results/; "
             "each section names the make target that produced its numbers.", ""]
    lines += fem_section(root) + campaign_section(root) + surrogate_section(root) + predictor_section(root)
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m workflow.report", description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default="results")
    ap.add_argument("--out", default="results/REPORT.md")
    args = ap.parse_args(argv)
    Path(args.out).write_text(report(Path(args.results)))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
