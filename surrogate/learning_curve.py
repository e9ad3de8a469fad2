"""The surrogate's learning curve: held-out errors against the number of training samples.

    python -m surrogate.learning_curve [--data results/data/train] [--heldout results/data/heldout]
        [--config improved] [--set KEY=VALUE ...] [--sizes 100,200,400,800,1600,all]
        [--modes with,without] [--seed 0] [--repeat SAMPLES:SEED ...] [--min-steps 22400]
        [--max-hours H] [--out results/surrogate/learning_curve.json] [--plot PNG]
        [--reference OTHER.json] [--json]

Data flow: DIR (verified, split 7:2:1 by the dataset seed, surrogate.data.load_splits; its
joint, the manifest's, sets the model's anchor count and input box, ModelConfig.for_joint) ->
the train split's nested subsets (below) -> for each (samples, Jacobian loss on/off, seed)
point: surrogate.train.train on that subset, with the whole validation split choosing the
kept epoch -> surrogate.evaluate.evaluate on the separate held-out set -> one record in
OUT's ``points``. OUT (JSON) and the figure (PNG, default beside OUT) are rewritten
atomically after every point, so a killed run loses at most the point in progress; a
re-run keeps every finished point whose configs and data digests still match and trains
only the others. Exit 0 when every planned point is done, 3 when ``--max-hours`` stopped
it first (re-run the same command to resume).

Subsets: the train split's n samples in one random order drawn from the seed,
perm = randperm(n, seed); the subset of size s is perm[:s]. So every smaller subset is
inside every larger one of the same seed, and "all" is the whole split.

With and without the Jacobian loss: the config (default ``improved``, its w_jac = 0.2) is
"with"; "without" is the same config with w_jac = 0 (surrogate.train's loss, in mm).

Epoch budget: 800 epochs of 64-sample batches are 28 x 800 = 22,400 Adam steps on the
full split (1,792 samples) but only 2 x 800 = 1,600 on 100 samples, which would measure
under-training rather than data. Every point therefore gets at least ``min_steps`` steps
(default 22,400, the full split's count) with the same learning-rate path over its steps:

    batches(s) = ceil(s / B)                        B the config's batch size (64)
    epochs(s)  = max(E0, ceil(min_steps / batches(s)))       E0 the config's epochs (800)
    decay(s)   = d0 ** (E0 / epochs(s))             d0 the config's decay per epoch (0.995)

so the rate falls from lr0 to lr0 · d0^E0 over every run whatever its size. The epoch
count and decay are applied with surrogate.train.apply_overrides and recorded in each
point's ``train_config``.

A point: samples, jacobian_loss, seed (the subset draw and the training seed),
heldout_mean_anchor_error_mm, heldout_tip_error_mm (the last anchor), heldout_cap_rotation_error_deg,
heldout_phi_end_error_deg, heldout_jacobian_rel_error, val_mean_anchor_error_mm,
train_anchor_error_mm (the mean training anchor error at the kept epoch, mm), best_epoch,
steps, train_time_s (one thread), min_steps, model_config (surrogate.model.config_record),
train_config and the sha256
digests of the train and held-out datasets (workflow.shards.dataset_digest).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

import torch

from contract import cli
from contract.files import atomic_path, json_safe
from surrogate.artefacts import LEARNING_CURVE
from surrogate.data import load_samples, load_splits
from surrogate.evaluate import evaluate
from surrogate.model import config_record
from surrogate.train import CONFIGS, apply_overrides, check_configs, train
from workflow.shards import ShardError, dataset_digest
from workflow.store import recorded_joint

SIZES = (100, 200, 400, 800, 1600, "all")
MODES = {"with": True, "without": False}
#: The full committed split's step count: 28 batches of 64 x 800 epochs.
MIN_STEPS = 22_400
#: Keys of one point (module docstring).
POINT_KEYS = ("samples", "jacobian_loss", "seed", "heldout_mean_anchor_error_mm", "heldout_tip_error_mm",
              "heldout_cap_rotation_error_deg", "heldout_phi_end_error_deg", "heldout_jacobian_rel_error",
              "val_mean_anchor_error_mm", "train_anchor_error_mm", "best_epoch", "steps", "train_time_s",
              "min_steps", "model_config", "train_config", "data_sha256", "heldout_sha256")
EXIT_STOPPED = 3


def nested_subsets(n: int, sizes, seed: int) -> dict[int, torch.Tensor]:
    """{size: sorted indices into the n-sample train split}: the first ``size`` of one
    random order drawn from ``seed``, so smaller subsets lie inside larger ones. Raises
    ValueError for a size outside [1, n]."""
    for s in sizes:
        if not 1 <= s <= n:
            raise ValueError(f"subset size {s} is outside [1, {n}] (the train split has {n} samples)")
    perm = torch.randperm(n, generator=torch.Generator().manual_seed(seed))
    return {s: perm[:s].sort().values for s in sizes}


def point_configs(config: str, overrides: list[str], samples: int, jacobian_loss: bool, seed: int,
                  min_steps: int, joint=None):
    """(ModelConfig, TrainConfig) of one point: ``config`` with ``overrides``, w_jac = 0
    without the Jacobian loss, the seed, and the epoch budget of the module docstring, for
    ``joint`` (a contract.joint.JointSpec: its anchor count and input box; None: the paper's)."""
    model_cfg, base = apply_overrides(*CONFIGS[config], overrides)
    batches = math.ceil(samples / base.batch_size)
    epochs = max(base.epochs, math.ceil(min_steps / batches))
    decay = base.lr_decay ** (base.epochs / epochs)
    extra = [f"seed={seed}", f"epochs={epochs}", f"lr_decay={decay!r}"]
    if not jacobian_loss:
        extra.append("w_jac=0")
    # the overrides again after ours would be refused as repeats: apply ours to the result
    model_cfg, cfg = apply_overrides(model_cfg, base, extra)
    model_cfg = model_cfg if joint is None else model_cfg.for_joint(joint)
    check_configs(model_cfg, cfg)
    if jacobian_loss and cfg.w_jac <= 0:
        raise ValueError(f"config {config} with {overrides} has w_jac = 0: no 'with' Jacobian-loss point")
    return model_cfg, cfg


def run_point(splits: dict, heldout, index: torch.Tensor, model_cfg, cfg, log=lambda s: None) -> dict:
    """Train on splits['train'][index] (validation whole) and measure on ``heldout``; the
    figures of one point (without its identity keys)."""
    subset = dict(splits, train=splits["train"].subset(index))
    model, history = train(model_cfg, cfg, subset, log)
    held = evaluate(model, heldout)
    best = history["best_epoch"]
    return {"heldout_mean_anchor_error_mm": held["mean_anchor_error_mm"],
            "heldout_tip_error_mm": held["tip_error_mm"],
            "heldout_cap_rotation_error_deg": held["cap_rotation_error_deg"],
            "heldout_phi_end_error_deg": held["phi_end_error_deg"],
            "heldout_jacobian_rel_error": held["jacobian_rel_error"],
            "val_mean_anchor_error_mm": history["val_anchor_mm"][best - 1],
            "train_anchor_error_mm": history["train_anchor_mm"][best - 1],
            "best_epoch": best, "steps": cfg.epochs * math.ceil(len(index) / cfg.batch_size),
            "train_time_s": history["train_time_s"]}


def plan(n_train: int, sizes, modes, seed: int, repeats) -> list[tuple[int, bool, int]]:
    """(samples, jacobian_loss, seed) of every point, the curve first (ascending size,
    each size with and without), then the repeats; "all" is n_train."""
    jobs = [(n_train if s == "all" else s, MODES[m], seed) for s in sizes for m in modes]
    jobs += [(n_train if s == "all" else s, MODES[m], r) for s, r in repeats for m in modes]
    return list(dict.fromkeys(jobs))


def identity(samples: int, jacobian_loss: bool, seed: int, min_steps: int, model_cfg, cfg,
             data_sha: str, heldout_sha: str) -> dict:
    """The keys that decide whether a stored point is still valid (as stored in JSON)."""
    return json_safe({"samples": samples, "jacobian_loss": jacobian_loss, "seed": seed, "min_steps": min_steps,
                      "model_config": config_record(model_cfg), "train_config": asdict(cfg),
                      "data_sha256": data_sha, "heldout_sha256": heldout_sha})


def is_current(point: dict, config: str, overrides: list[str], data_sha: str, heldout_sha: str,
               joint=None) -> bool:
    """A stored point is kept if its configs are what this code and ``config`` with
    ``overrides`` give for its samples, mode, seed and min_steps, on the same data (of ``joint``)."""
    try:
        model_cfg, cfg = point_configs(config, overrides, point["samples"], point["jacobian_loss"],
                                       point["seed"], point["min_steps"], joint)
    except (KeyError, TypeError, ValueError):
        return False
    want = identity(point["samples"], point["jacobian_loss"], point["seed"], point["min_steps"],
                    model_cfg, cfg, data_sha, heldout_sha)
    return all(point.get(k) == v for k, v in want.items()) and set(point) == set(POINT_KEYS)


def order(points: list[dict]) -> list[dict]:
    return sorted(points, key=lambda p: (p["seed"], not p["jacobian_loss"], p["samples"]))


def figure(path: Path, points: list[dict], title: str, reference: tuple[str, list[dict]] | None = None) -> None:
    """PNG: held-out mean anchor, tip and cap-rotation errors against training samples
    (log-log), with and without the Jacobian loss; repeat seeds as open markers;
    ``reference`` (label, points): another curve's first seed dashed beside it (the same
    figure of another dataset)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("heldout_mean_anchor_error_mm", "mean anchor error (mm)"),
              ("heldout_tip_error_mm", "mean tip error (mm)"),
              ("heldout_cap_rotation_error_deg", "mean cap-rotation error (deg)"))
    seeds = sorted({p["seed"] for p in points})
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for ax, (key, label) in zip(axes, panels):
        for jac, color in ((True, "tab:blue"), (False, "tab:orange")):
            name = "with Jacobian loss" if jac else "without"
            for i, seed in enumerate(seeds):
                pts = [p for p in points if p["jacobian_loss"] == jac and p["seed"] == seed and p[key] is not None]
                if not pts:
                    continue
                x = [p["samples"] for p in pts]
                y = [p[key] for p in pts]
                if i == 0:
                    ax.loglog(x, y, "o-", color=color, label=f"{name} (seed {seed})")
                else:
                    ax.loglog(x, y, "o", mfc="none", color=color, ms=9, label=f"{name} (seed {seed})")
            if reference:
                pts = [p for p in reference[1] if p["jacobian_loss"] == jac and p["seed"] == min(
                    q["seed"] for q in reference[1]) and p[key] is not None]
                if pts:
                    ax.loglog([p["samples"] for p in pts], [p[key] for p in pts], "s--", color=color, alpha=0.45,
                              ms=4, label=f"{name}, {reference[0]}")
        sizes = sorted({p["samples"] for p in points})
        # a size within 15 % of the next one (1,600 beside all 1,792) would overprint its label
        ax.set_xticks([a for a, b in zip(sizes, sizes[1:] + [math.inf]) if b > 1.15 * a])
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("training samples")
        ax.set_ylabel(f"held-out {label}")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def sizes_arg(text: str):
    """argparse type: comma-separated subset sizes and/or "all", each once, in order."""
    out = []
    for part in text.split(","):
        part = part.strip()
        out.append("all" if part == "all" else cli.number(1, None, integer=True)(part))
    return tuple(dict.fromkeys(out))


def _modes(text: str):
    parts = tuple(dict.fromkeys(p.strip() for p in text.split(",")))
    bad = [p for p in parts if p not in MODES]
    if bad:
        raise argparse.ArgumentTypeError(f"{text!r}: expected with and/or without, comma-separated")
    return parts


def _repeat(text: str):
    size, sep, seed = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r}: expected SAMPLES:SEED, e.g. 400:1")
    return (sizes_arg(size)[0] if size.strip() == "all" else cli.number(1, None, integer=True)(size),
            cli.number(0, None, integer=True)(seed))


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.learning_curve", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="results/data/train", help="campaign dataset (split 7:2:1)")
    ap.add_argument("--heldout", default="results/data/heldout", help="held-out dataset (measured, never chosen on)")
    ap.add_argument("--config", choices=sorted(CONFIGS), default="improved", help="the 'with' config")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a field of the config (surrogate.train --set), for every point")
    ap.add_argument("--sizes", type=sizes_arg, default=SIZES, help="comma-separated subset sizes and/or all")
    ap.add_argument("--modes", type=_modes, default=tuple(MODES), help="with and/or without the Jacobian loss")
    ap.add_argument("--seed", type=cli.number(0, None, integer=True), default=0,
                    help="the curve's subset draw and training seed")
    ap.add_argument("--repeat", type=_repeat, action="append", default=[], metavar="SAMPLES:SEED",
                    help="also this size with another seed (the curve's noise), after the curve")
    ap.add_argument("--min-steps", type=cli.number(1, None, integer=True), default=MIN_STEPS,
                    help="fewest Adam steps per point (module docstring)")
    ap.add_argument("--max-hours", type=cli.number(0, None, "h", open_lo=True), default=None,
                    help="start no point expected to end past it (exit 3 if unfinished)")
    ap.add_output("--out", suffix=".json", default="results/surrogate/learning_curve.json")
    ap.add_output("--plot", suffix=".png", help="figure (default: OUT with .png)")
    ap.add_argument("--reference", help="another learning curve's JSON, drawn dashed in the figure "
                    "(e.g. the 1.8 mm data's beside the production data's)")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    out = Path(args.out)
    plot = Path(args.plot) if args.plot else out.with_suffix(".png")
    torch.set_num_threads(1)  # one core: the curve runs beside other work
    with ap.errors():
        apply_overrides(*CONFIGS[args.config], args.set)
        data_sha, heldout_sha = dataset_digest(args.data), dataset_digest(args.heldout)
        try:
            splits, manifest = load_splits(args.data)
            heldout, _ = load_samples(args.heldout)
            joint = recorded_joint(manifest.config)
        except ShardError as exc:
            raise ValueError(str(exc)) from None
        n_train = len(splits["train"])
        jobs = plan(n_train, args.sizes, args.modes, args.seed, args.repeat)
        subsets = {seed: nested_subsets(n_train, sorted({s for s, _, r in jobs if r == seed}), seed)
                   for seed in {r for _, _, r in jobs}}
        configs = {job: point_configs(args.config, args.set, *job, args.min_steps, joint) for job in jobs}
        old = load_points(out)
    # one file is one curve: points of another config, min_steps or data are redone
    points = [p for p in old if p.get("min_steps") == args.min_steps
              and is_current(p, args.config, args.set, data_sha, heldout_sha, joint)]
    done = {(p["samples"], p["jacobian_loss"], p["seed"]) for p in points}
    todo = [job for job in jobs if job not in done]
    say(f"learning curve: {len(jobs) - len(todo)} of {len(jobs)} points done, {len(todo)} to train "
        f"(train split {n_train}, val {len(splits['val'])}, held-out {len(heldout)}; >= {args.min_steps} steps)")
    header = {"description": "Held-out errors of the surrogate against training samples (surrogate.learning_curve).",
              "config": args.config, "overrides": args.set, "min_steps": args.min_steps,
              "data": {"train": args.data, "train_sha256": data_sha, "n": {k: len(v) for k, v in splits.items()},
                       "heldout": args.heldout, "heldout_sha256": heldout_sha, "heldout_n": len(heldout)},
              "subsets": "nested: the first s of randperm(train split, seed)",
              **({"reference": args.reference} if args.reference else {}),
              "epoch_budget": "epochs = max(E0, ceil(min_steps / ceil(s / batch))), "
                              "lr_decay = d0 ** (E0 / epochs)"}
    budget = args.max_hours * 3600 if args.max_hours else math.inf
    rate, stopped = [], False
    for samples, jac, seed in todo:
        model_cfg, cfg = configs[(samples, jac, seed)]
        steps = cfg.epochs * math.ceil(samples / cfg.batch_size)
        expected = steps * (sum(rate) / len(rate)) if rate else 0.0
        if time.perf_counter() - t_start + expected > budget:
            stopped = True
            break
        say(f"  {samples} samples, {'with' if jac else 'without'} Jacobian loss, seed {seed}: "
            f"{cfg.epochs} epochs, {steps} steps")
        figures = run_point(splits, heldout, subsets[seed][samples], model_cfg, cfg, progress)
        rate.append(figures["train_time_s"] / steps)
        point = identity(samples, jac, seed, args.min_steps, model_cfg, cfg, data_sha, heldout_sha) | figures
        points = order([p for p in points if (p["samples"], p["jacobian_loss"], p["seed"]) != (samples, jac, seed)]
                       + [point])
        with ap.errors():
            write(out, plot, header, points, jobs)
        say(f"    held-out mean anchor {figures['heldout_mean_anchor_error_mm']:.4f} mm, "
            f"tip {figures['heldout_tip_error_mm']:.4f} mm, "
            f"cap {figures['heldout_cap_rotation_error_deg'] or float('nan'):.3f} deg; "
            f"{figures['train_time_s']:.0f} s")
    if points and not rate:  # nothing trained: still drop stale points from the file
        with ap.errors():
            write(out, plot, header, points, jobs)
    if args.json:
        cli.print_json({"out": str(out), "plot": str(plot), "stopped": stopped, "points": points})
    else:
        for p in points:
            print(row(p))
    return exit_code(stopped, args.max_hours)


def say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def exit_code(stopped: bool, max_hours: float) -> int:
    """A resumable run's exit code (here and surrogate.multifidelity): EXIT_STOPPED, with the
    line that says how to resume on stderr, when --max-hours stopped it, else 0."""
    if stopped:
        say(f"stopped by --max-hours {max_hours:g}: re-run the same command to resume")
        return EXIT_STOPPED
    return 0


def progress(text: str) -> None:
    """surrogate.train's epoch lines (every 5 % of the epochs), indented under the point."""
    say("      " + text)


def load_points(path: Path) -> list[dict]:
    """The points of an existing OUT, or [] (absent or unreadable: then it is rewritten)."""
    try:
        points = json.loads(path.read_text()).get("points", [])
    except (OSError, ValueError, AttributeError):
        return []
    return [p for p in points if isinstance(p, dict)] if isinstance(points, list) else []


def write(out: Path, plot: Path, header: dict, points: list[dict], jobs) -> None:
    """OUT and its figure, atomically; ``complete`` when every planned point is in. The
    header's ``reference`` (another curve's JSON) is drawn dashed beside it."""
    have = {(p["samples"], p["jacobian_loss"], p["seed"]) for p in points}
    LEARNING_CURVE.write(out, header | {"complete": all(job in have for job in jobs), "points": points})
    ref = header.get("reference")
    figure(plot, points, f"Surrogate learning curve ({header['config']}; held-out n = "
                         f"{header['data']['heldout_n']}, >= {header['min_steps']} Adam steps per point)",
           (f"reference {ref}", load_points(Path(ref))) if ref else None)


def row(p: dict) -> str:
    cap = p["heldout_cap_rotation_error_deg"]
    return (f"{p['samples']:5d} {'with   ' if p['jacobian_loss'] else 'without'} seed {p['seed']}: "
            f"mean anchor {p['heldout_mean_anchor_error_mm']:.4f} mm, tip {p['heldout_tip_error_mm']:.4f} mm, "
            f"cap {'n/a' if cap is None else f'{cap:.3f}'} deg, {p['train_time_s']:.0f} s")


if __name__ == "__main__":
    sys.exit(main())
