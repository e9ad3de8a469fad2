"""Architecture and loss sweep of the improved surrogate on a campaign dataset.

    python -m surrogate.sweep [--data results/data/train] [--heldout results/data/heldout]
                              [--epochs N] [--jobs 2] [--only NAME ...] [--max-hours H]
                              [--dir results/surrogate/sweep] [--json]

Data flow: for each variant in VARIANTS, the improved config with that variant's
``--set`` overrides (surrogate.train) for the dataset's joint (its anchor count and input
box, ModelConfig.for_joint), trained ``--epochs`` epochs on the train split ->
metrics on the validation split (which chooses the configuration), on the held-out set
(reported, never used to choose) and inference speed (surrogate.evaluate.timing) ->
DIR/NAME.json, one file per variant written atomically, so a killed sweep resumes and
``--jobs`` workers never share a file -> DIR/README.md (also atomic), the table of every
variant that has a result. Units: mm, degrees, seconds, samples per second.

A result made with another config (an older format of the code, another epoch count) or
on another dataset is *stale*: it is kept, listed as such in the table and on the
console, and retrained only with ``--replace-stale``; a rerun never drops a variant's row
nor replaces a committed result silently.

``--max-hours H`` bounds the sweep: once H hours have passed no further variant starts
(those running finish and are written), the table is written with what is done, and the
exit code is 3; the same command again resumes with the variants still to train.
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

import torch

from contract import cli
from contract.files import write_text
from surrogate.artefacts import SWEEP
from surrogate.data import load_samples, load_splits
from surrogate.evaluate import evaluate, timing
from surrogate.model import config_record
from surrogate.train import CONFIGS, apply_overrides, train
from workflow.shards import Manifest, dataset_digest
from workflow.store import recorded_joint

# name -> overrides of the improved config (surrogate.train --set syntax)
VARIANTS = {
    "improved": [],
    "nojac": ["w_jac=0"],
    "jac0.05": ["w_jac=0.05"],
    "nophi": ["w_phi=0"],
    "nocap": ["cap_rotation=false", "w_cap=0"],
    "capoffset": ["cap_target=offset"],
    "noabsp": ["abs_pressure=false"],
    "nosym": ["equivariant=false", "mirror_augment=true"],
    "symmetric": ["equivariant=false", "symmetric=true"],
    "relu": ["activation=relu"],
    "tanh": ["activation=tanh"],
    "noresidual": ["residual=false"],
    "paperarch": ["hidden=96,192,96", "residual=false"],
    "w64x3": ["hidden=64,64,64"],
    "w64x4": ["hidden=64,64,64,64"],
    "w128x4": ["hidden=128,128,128,128"],
    "symmetric-w64x4": ["equivariant=false", "symmetric=true", "hidden=64,64,64,64"],
    "symmetric-w128x4": ["equivariant=false", "symmetric=true", "hidden=128,128,128,128"],
}

COLUMNS = [("val", "mean_anchor_error_mm", 4), ("val", "p95_anchor_error_mm", 4),
           ("val", "phi_end_error_deg", 3), ("val", "jacobian_rel_error", 4),
           ("val", "cap_rotation_error_deg", 3),
           ("heldout", "mean_anchor_error_mm", 4), ("heldout", "phi_end_error_deg", 3),
           ("heldout", "cap_rotation_error_deg", 3)]


def variant_configs(name: str, epochs: int | None, joint=None) -> tuple:
    """(ModelConfig, TrainConfig) of a variant: the improved config with its overrides
    (and ``epochs`` unless None), for ``joint`` (a contract.joint.JointSpec; None: the paper's)."""
    extra = [] if epochs is None else [f"epochs={epochs}"]
    model_cfg, cfg = apply_overrides(*CONFIGS["improved"], [*VARIANTS[name], *extra])
    return (model_cfg if joint is None else model_cfg.for_joint(joint)), cfg


def run_variant(name: str, data: str, data_sha256: str, heldout: str, epochs: int | None,
                out: str) -> str:
    """Train and evaluate one variant on one thread; write out (JSON). Returns name."""
    torch.set_num_threads(1)
    splits, manifest = load_splits(data)
    model_cfg, cfg = variant_configs(name, epochs, recorded_joint(manifest.config))
    model, history = train(model_cfg, cfg, splits, log=lambda s: None)
    result = {"name": name, "overrides": VARIANTS[name], "epochs": cfg.epochs,
              "data_sha256": data_sha256,
              "model_config": config_record(model_cfg),
              "train_config": asdict(cfg), "n": {k: len(v) for k, v in splits.items()},
              "best_epoch": history["best_epoch"], "train_time_s": history["train_time_s"],
              "val": evaluate(model, splits["val"]),
              "heldout": evaluate(model, load_samples(heldout)[0]),
              "timing": timing(model, repeats=500, seconds=0.5, threads=(1,))}
    SWEEP.write(out, result)
    return name


def table(results: list[dict], stale: dict[str, str]) -> str:
    """Markdown table, one row per variant with a result, in VARIANTS order; ``stale``:
    name -> why its result is not of this config and dataset (shown in the last column)."""
    head = ["run", "overrides"] + [f"{part} {key.replace('_error', '').replace('_', ' ')}"
                                   for part, key, _ in COLUMNS]
    head += ["epochs", "train s", "batched f32 /s (1 thread)", "result"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        cells = [r["name"], " ".join(r["overrides"]) or "(none)"]
        for part, key, digits in COLUMNS:
            v = r[part].get(key)
            cells.append("n/a" if v is None else f"{v:.{digits}f}")
        cells += [str(r["epochs"]), f"{r['train_time_s']:.0f}",
                  f"{r['timing']['batched_samples_per_s_float32']:.2g}",
                  f"stale: {stale[r['name']]}" if r["name"] in stale else "current"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def stored(path: Path) -> dict | None:
    """A variant's result file, or None if there is none (a damaged one is an error:
    it is not replaced behind the user's back)."""
    if not path.exists():
        return None
    try:
        r = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError):
        raise ValueError(f"{path}: not a surrogate.sweep result (remove it to retrain)") from None
    if not isinstance(r, dict) or not {"name", "model_config", "train_config", "data_sha256"} <= set(r):
        raise ValueError(f"{path}: not a surrogate.sweep result (remove it to retrain)")
    return r


def staleness(r: dict, name: str, epochs: int | None, data_sha256: str, joint=None) -> str | None:
    """Why result ``r`` is not this run's variant ``name`` for ``joint`` (None: it is): which
    config fields differ (an older format of the code lacks the new ones), or the dataset."""
    model_cfg, cfg = variant_configs(name, epochs, joint)
    want = json.loads(json.dumps({"model_config": config_record(model_cfg), "train_config": asdict(cfg)}))
    fields = sorted(k for part in want for k in set(want[part]) | set(r[part])
                    if want[part].get(k, "missing") != r[part].get(k, "missing"))
    if fields:
        return f"made with other {', '.join(fields[:4])}{' ...' if len(fields) > 4 else ''}"
    if r["data_sha256"] != data_sha256:
        return "made on another dataset"
    return None


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.sweep", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="results/data/train")
    ap.add_argument("--heldout", default="results/data/heldout")
    ap.add_argument("--epochs", type=cli.number(1, None, integer=True),
                    help="default: the improved config's")
    ap.add_argument("--jobs", type=cli.number(1, os.cpu_count() or 1, integer=True), default=1,
                    help="variants trained at once, 1 thread each")
    ap.add_argument("--only", nargs="*", choices=sorted(VARIANTS), help="these variants only (trained in this order)")
    ap.add_argument("--max-hours", type=cli.number(0, None, "h", open_lo=True), default=None,
                    help="start no variant after this many hours; exit 3 if some are left (re-run to resume)")
    ap.add_argument("--replace-stale", action="store_true",
                    help="retrain (and replace) results made with another config or dataset; "
                         "default: keep them, marked stale")
    ap.add_output("--dir", folder=True, default="results/surrogate/sweep",
                  help="one NAME.json per variant and README.md")
    cli.add_quiet(ap)
    args = ap.parse_args(argv)
    cli.setup_logging(args.quiet)
    out = Path(args.dir)
    names = args.only or list(VARIANTS)
    say = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else \
        (lambda s: print(s, flush=True))
    with ap.errors():
        data_sha256 = dataset_digest(args.data)
        joint = recorded_joint(Manifest.load(args.data).config)
        load_samples(args.heldout)  # a bad held-out set fails now, not after the training
        have = {n: stored(out / f"{n}.json") for n in VARIANTS}
    stale = {n: why for n, r in have.items() if r is not None
             and (why := staleness(r, n, args.epochs, data_sha256, joint)) is not None}
    todo = [n for n in names if have[n] is None or (n in stale and args.replace_stale)]
    kept = [n for n in names if n in stale and not args.replace_stale]
    say(f"surrogate.sweep: {len(names) - len(todo) - len(kept)} of {len(names)} variants current, "
        f"{len(todo)} to train ({args.epochs or 'configured'} epochs, {args.jobs} job(s))"
        + (f"; {len(kept)} stale result(s) kept ({', '.join(f'{n}: {stale[n]}' for n in kept)}); "
           "--replace-stale retrains them" if kept else ""))
    cli.make_output_folder(out)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool, \
            cli.heartbeat(f"surrogate.sweep: training {len(todo)} variant(s)", every=30.0, enabled=bool(todo)):
        futures = [pool.submit(run_variant, n, args.data, data_sha256, args.heldout, args.epochs,
                               str(out / f"{n}.json")) for n in todo]
        t0 = time.monotonic()
        for f in futures:
            if f.cancelled():
                continue
            name = f.result()
            have[name] = stored(out / f"{name}.json")
            stale.pop(name, None)
            say(f"  {name} done")
            if args.max_hours is not None and time.monotonic() - t0 > 3600 * args.max_hours:
                left = sum(g.cancel() for g in futures)   # those not yet started
                if left:
                    say(f"  --max-hours {args.max_hours:g} reached: {left} variant(s) left for the next run")
    results = [r for r in have.values() if r is not None]
    text = (f"# Improved-surrogate sweep\n\nMade by `python -m surrogate.sweep` on `{args.data}`; held-out: "
            f"`{args.heldout}`. Each run is the improved config with the overrides listed. "
            f"Validation chooses; held-out is for reference only. A stale result was made with "
            f"another config or dataset than the current code's (`--replace-stale` retrains it).\n\n"
            + table(results, stale))
    write_text(out / "README.md", text)
    trained = [n for n in todo if have[n] is not None and n not in stale]
    if args.json:
        cli.print_json({"dir": str(out), "trained": trained, "stale": stale, "results": results})
    else:
        print(text, end="")
    return 3 if len(trained) < len(todo) else 0


if __name__ == "__main__":
    sys.exit(main())
