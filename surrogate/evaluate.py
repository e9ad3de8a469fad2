"""Accuracy, Jacobian and speed of surrogates on a dataset; the paper/improved/KNN report.

Metrics on n samples with true anchors R (n, k, 2) mm (k the joint's anchor count) and
predictions R̂:

    e_ij = |R̂_ij - R_ij|                                 anchor error, mm
    mean_anchor_error_mm = mean_ij e_ij;  p95_anchor_error_mm = 95th percentile of all e_ij
    tip_error_mm         = mean_i e_i,k
    phi_end_error_deg    = mean_i |wrap(phî_i - phi_i)|,  phi = atan2(y_k - y_k-1, x_k - x_k-1)
    jacobian_rel_error   = mean_i ||(Ĵ_i - J_i) D||_F / ||J_i D||_F,  D = diag(box), the
                           model's joint's input box (ModelConfig.input_box; the paper's
                           contract.spec.INPUT_BOX for a module without one)
                           (the columns in mm per half-range of each input, so P, F1, F2
                           and M weigh alike; samples without an FEM Jacobian are skipped,
                           null when none has one)
    cap_rotation_error_deg     = mean_i |wrap(θ̂_i - θ_i)|, θ the distal cap's own rotation
                                 (the model's cap head; null for a model without one)
    tangent_error_deg          = mean_i |wrap(phî_i - θ_i)|: the model's phi_end taken for
                                 the cap rotation (the paper's tangent connection), any model
with p95_ versions of the angle errors (95th percentile over samples).

Inference time: the median wall time of one no-grad call on a single sample on one
thread, and the throughput of no-grad calls on batches of 4,096 samples drawn in the
model's input box (over 1 s) on one
thread and on every core, in float64 (the dtype of load_surrogate) and in float32.

One checkpoint on any dataset directory:
    python -m surrogate.evaluate --model PATH --data DIR [--split all|train|val|test] [--out F] --json
The report (metrics.json, metrics.md, comparison figure, each written atomically):
    python -m surrogate.evaluate --report --train-data DIR --heldout DIR --dir results/surrogate
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from contract import cli
from contract.files import atomic_path, write_text
from surrogate.artefacts import EVALUATION, METRICS
from contract.spec import INPUT_BOX, N_INPUTS, check_box, phi_end
from surrogate.data import Samples, load_samples, load_splits
from surrogate.knn import choose_knn
from surrogate.model import load_checkpoint, load_surrogate, wrap

def input_box(model) -> tuple[float, ...]:
    """The input box half-widths (P MPa, F1 N, F2 N, M N·mm) of a module's joint: its
    ``input_box`` (JointSurrogate, KNN, the multi-fidelity models), else the paper's."""
    return tuple(getattr(model, "input_box", INPUT_BOX))


def jacobian(model, x: torch.Tensor) -> torch.Tensor:
    """d model(x).reshape(2k) / dx for independent rows: x (n, 4) -> (n, 2k, 4)."""
    x = x.detach().clone()
    jac = torch.autograd.functional.jacobian(lambda a: model(a).reshape(len(a), -1).sum(0), x,
                                             vectorize=True)
    return jac.permute(1, 0, 2)


def _angle_errors(name: str, pred: torch.Tensor | None, true: torch.Tensor | None) -> dict:
    """{name_error_deg, p95_name_error_deg} of |wrap(pred - true)| over (n,) rad angles;
    None for both when either is missing."""
    if pred is None or true is None:
        return {f"{name}_error_deg": None, f"p95_{name}_error_deg": None}
    d = wrap(pred - true).abs()
    return {f"{name}_error_deg": math.degrees(d.mean().item()),
            f"p95_{name}_error_deg": math.degrees(torch.quantile(d, 0.95).item())}


def metrics(pred: torch.Tensor, true: torch.Tensor, pred_jac: torch.Tensor | None = None,
            true_jac: torch.Tensor | None = None, pred_cap: torch.Tensor | None = None,
            true_cap: torch.Tensor | None = None, box=INPUT_BOX) -> dict:
    """The metric dict (module docstring) from anchors (n, k, 2) mm, Jacobians (n, 2k, 4)
    weighted by the input box ``box`` (4,) (P MPa, F1 N, F2 N, M N·mm) and cap rotations
    (n,) rad."""
    e = (pred - true).norm(dim=-1)
    dphi = wrap(phi_end(pred) - phi_end(true)).abs()
    out = {
        "mean_anchor_error_mm": e.mean().item(),
        "p95_anchor_error_mm": torch.quantile(e.flatten(), 0.95).item(),
        "tip_error_mm": e[:, -1].mean().item(),
        "phi_end_error_deg": math.degrees(dphi.mean().item()),
        "jacobian_rel_error": None,
        "n": len(true),
        "max_anchor_error_mm": e.max().item(),
        "p95_phi_end_error_deg": math.degrees(torch.quantile(dphi, 0.95).item()),
        **_angle_errors("cap_rotation", pred_cap, true_cap),
        **_angle_errors("tangent", phi_end(pred), true_cap),
    }
    if pred_jac is not None and true_jac is not None:
        ok = torch.isfinite(true_jac).all(dim=(1, 2))
        if ok.any():
            d = torch.as_tensor(box, dtype=true_jac.dtype)
            num = ((pred_jac[ok] - true_jac[ok]) * d).flatten(1).norm(dim=1)
            out["jacobian_rel_error"] = (num / (true_jac[ok] * d).flatten(1).norm(dim=1)).mean().item()
    return out


def evaluate(model, samples: Samples) -> dict:
    """Metrics of a module (inputs (n, 4) -> anchors (n, k, 2)) on samples; the cap
    rotation's from ``model.with_cap`` where the model has the head; the Jacobian's weighted
    by the model's input box (input_box)."""
    x = samples.inputs.to(torch.float64)
    with torch.no_grad():
        if getattr(model, "has_cap_rotation", False):
            pred, cap = model.with_cap(x)
        else:
            pred, cap = model(x), None
    return metrics(pred, samples.anchors, jacobian(model, x), samples.jacobian, cap,
                   samples.cap_rotation, input_box(model))


def timing(model, repeats: int = 2000, batch: int = 4096, seconds: float = 1.0,
           threads: tuple[int, ...] | None = None) -> dict:
    """Inference speed (module docstring): single-sample ms on one thread, and batched
    samples/s on each of ``threads`` (default: 1 and every core), per dtype. The batched
    keys without a suffix are for 1 thread; ``..._Nthreads`` for N > 1, and
    ``..._all_cores`` repeats the one for max(threads)."""
    threads = threads or tuple(sorted({1, os.cpu_count() or 1}))
    saved = torch.get_num_threads()
    out = {"threads": list(threads), "batch": batch}
    box = input_box(model)
    for dtype, tag in ((torch.float64, "float64"), (torch.float32, "float32")):
        m = model.to(dtype)
        x1 = torch.tensor([box], dtype=dtype) * torch.tensor([1 / 3, 1 / 3, 1 / 6, 1 / 10], dtype=dtype)
        xb = (torch.rand(batch, N_INPUTS, generator=torch.Generator().manual_seed(0), dtype=dtype)
              * 2 - 1) * torch.as_tensor(box, dtype=dtype)
        with torch.no_grad():
            torch.set_num_threads(1)
            for _ in range(50):
                m(x1)
            single = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                m(x1)
                single.append(time.perf_counter() - t0)
            out[f"single_ms_{tag}"] = 1e3 * float(np.median(single))
            for n in threads:
                torch.set_num_threads(n)
                m(xb)
                calls, t0 = 0, time.perf_counter()
                while time.perf_counter() - t0 < seconds:
                    m(xb)
                    calls += 1
                key = f"batched_samples_per_s_{tag}" + (f"_{n}threads" if n > 1 else "")
                out[key] = calls * batch / (time.perf_counter() - t0)
            out[f"batched_samples_per_s_{tag}_all_cores"] = out[key]
    torch.set_num_threads(saved)
    model.to(torch.float64)
    return out


def comparison_figure(path: Path, samples: Samples, models: dict, source: str,
                      n_cases: int = 8, seed: int = 0) -> None:
    """Left: data against surrogate centre lines for random cases (like the paper's Fig. 2C).
    Right: mean error of each anchor r_1..r_k over all samples, per model."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    idx = torch.randperm(len(samples), generator=torch.Generator().manual_seed(seed))[:n_cases]
    cases = samples.subset(idx)
    styles = {"paper": ("tab:orange", "--"), "improved": ("tab:blue", "-"), "knn": ("tab:green", ":")}
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1.4, 1]})
    origin = torch.zeros(len(cases), 1, 2, dtype=torch.float64)
    true = torch.cat([origin, cases.anchors], dim=1)
    for i, line in enumerate(true):
        a.plot(line[:, 0], line[:, 1], "ko", ms=4, label="data" if i == 0 else None)
    for name, model in models.items():
        color, ls = styles.get(name, ("gray", "-"))
        with torch.no_grad():
            pred = torch.cat([origin, model(cases.inputs)], dim=1)
            err = (model(samples.inputs) - samples.anchors).norm(dim=-1).mean(0)
        for i, line in enumerate(pred):
            a.plot(line[:, 0], line[:, 1], color=color, ls=ls, lw=1.2,
                   label=name if i == 0 else None)
        b.semilogy(range(1, samples.n_anchors + 1), err, color=color, ls=ls, marker="o", label=name)
    a.set_aspect("equal")
    a.set_xlabel("x (mm)")
    a.set_ylabel("y (mm)")
    a.set_title(f"{n_cases} random held-out cases: centre lines (anchors r_0..r_{samples.n_anchors})")
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    b.set_xlabel("anchor i")
    b.set_ylabel("mean error |r̂_i - r_i| (mm)")
    b.set_title(f"held-out set, n = {len(samples)}")
    b.grid(alpha=0.3, which="both")
    b.legend(fontsize=8)
    fig.suptitle(f"Joint surrogates against the dataset ({source})")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _fmt(v, digits=3):
    return "n/a" if v is None else f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def markdown_table(report: dict) -> str:
    """The metrics table for results/REPORT.md (held-out and test rows per model)."""
    rows = ["| model | set | n | mean anchor (mm) | p95 anchor (mm) | tip (mm) | phi_end (deg) "
            "| cap rotation (deg) | tangent vs cap (deg) "
            "| Jacobian rel. | train time (s) | single (ms, f64) | batched (samples/s, f64, 1 thread) "
            "| batched (samples/s, f32, all cores) |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in ("paper", "improved", "knn"):
        entry = report[name]
        t = entry.get("timing", {})
        all_cores = t.get("batched_samples_per_s_float32_all_cores")
        for part in ("heldout", "test"):
            m = entry[part]
            rows.append(
                f"| {name} | {part} | {m['n']} | {_fmt(m['mean_anchor_error_mm'])} "
                f"| {_fmt(m['p95_anchor_error_mm'])} | {_fmt(m['tip_error_mm'])} "
                f"| {_fmt(m['phi_end_error_deg'])} | {_fmt(m.get('cap_rotation_error_deg'))} "
                f"| {_fmt(m.get('tangent_error_deg'))} | {_fmt(m['jacobian_rel_error'])} "
                f"| {_fmt(entry.get('train_time_s'), 4)} | {_fmt(t.get('single_ms_float64'))} "
                f"| {_fmt(t.get('batched_samples_per_s_float64'))} | {_fmt(all_cores)} |")
    return "\n".join(rows) + "\n"


def report(train_root: Path, heldout_root: Path, out_dir: Path) -> dict:
    """Evaluate paper.pt, improved.pt and a KNN (k on validation) on test and held-out sets.

    Writes out_dir/metrics.json, metrics.md and comparison.png; returns the report dict.
    """
    splits, manifest = load_splits(train_root)
    heldout, heldout_manifest = load_samples(heldout_root)
    result, models = {}, {}
    for name in ("paper", "improved"):
        path = out_dir / f"{name}.pt"
        ckpt = load_checkpoint(path)
        models[name] = load_surrogate(path)
        result[name] = {"test": evaluate(models[name], splits["test"]),
                        "heldout": evaluate(models[name], heldout),
                        "train_time_s": ckpt["metrics"].get("train_time_s"),
                        "timing": timing(models[name])}
    knn, choice = choose_knn(splits["train"], splits["val"], box=input_box(models["improved"]))
    models["knn"] = knn
    result["knn"] = {"test": evaluate(knn, splits["test"]), "heldout": evaluate(knn, heldout),
                     "train_time_s": choice["fit_time_s"], "choice": choice,
                     "timing": timing(knn, repeats=200)}
    result["datasets"] = {"train": {"root": str(train_root), "seed": manifest.seed,
                                    "config": manifest.config,
                                    "n": {k: len(v) for k, v in splits.items()}},
                          "heldout": {"root": str(heldout_root), "seed": heldout_manifest.seed,
                                      "config": heldout_manifest.config, "n": len(heldout)}}
    METRICS.write(out_dir / "metrics.json", result)
    write_text(out_dir / "metrics.md", markdown_table(result))
    source = heldout_manifest.config.get("source", "FEM campaign")
    comparison_figure(out_dir / "comparison.png", heldout, models, source)
    return result


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.evaluate",
                    description="Evaluate a surrogate checkpoint on a dataset, "
                                "or write the paper/improved/KNN report.")
    ap.add_argument("--model", help="checkpoint (.pt) to evaluate")
    ap.add_argument("--data", help="dataset directory (manifest.json + shards)")
    ap.add_argument("--split", choices=("all", "train", "val", "test"), default="all",
                    help="samples of --data to use (split 7:2:1 by the dataset seed)")
    ap.add_argument("--allow-extrapolation", action="store_true",
                    help="evaluate samples outside the training box too (recorded in the output)")
    ap.add_argument("--report", action="store_true",
                    help="evaluate DIR/paper.pt, DIR/improved.pt and KNN; write the report")
    ap.add_argument("--train-data", default="results/data/train", help="--report: training dataset")
    ap.add_argument("--heldout", default="results/data/heldout", help="--report: held-out dataset")
    ap.add_output("--dir", folder=True,
                  help="--report: checkpoints and outputs (default results/surrogate)")
    ap.add_output("--out", suffix=".json", help="also write the one-checkpoint figures as JSON "
                                                "(atomically), with the model and data paths")
    ap.add_argument("--threads", type=cli.number(1, os.cpu_count() or 1, integer=True), default=1,
                    help="torch CPU threads")
    args = ap.parse_args(argv)
    if not args.report and None in (args.model, args.data):
        ap.error("--model and --data are required (or use --report)")
    torch.set_num_threads(args.threads)
    with ap.errors():
        if args.report:
            result = report(Path(args.train_data), Path(args.heldout),
                            Path(args.dir or "results/surrogate"))
            if args.json:
                cli.print_json(result)
            else:
                print(markdown_table(result), end="")
            return 0
        model = load_surrogate(args.model)
        if args.split == "all":
            samples, _ = load_samples(args.data)
        else:
            samples = load_splits(args.data)[0][args.split]
        outside = check_box(samples.inputs, args.allow_extrapolation, box=model.joint.input_box)
        result = evaluate(model, samples) | {"split": args.split, "extrapolated_samples": outside}
        if args.out:
            EVALUATION.write(args.out, result | {"model": args.model, "data": args.data})
    cli.print_fields(result, args.json, 24, lambda v: _fmt(v, 4), sep="  ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
