"""Architecture and loss sweep of the improved surrogate on a campaign dataset.

    python -m surrogate.sweep [--data results/data/train] [--heldout results/data/heldout]
                              [--epochs N] [--jobs 2] [--only NAME ...]
                              [--dir results/surrogate/sweep] [--json]

Data flow: for each variant in VARIANTS, the improved config with that variant's
``--set`` overrides (surrogate.train), trained ``--epochs`` epochs on the train split ->
metrics on the validation split (which chooses the configuration), on the held-out set
(reported, never used to choose) and inference speed (surrogate.evaluate.timing) ->
DIR/NAME.json, one file per variant written atomically, so a killed sweep resumes (a
file made with another config, epoch count or dataset is redone) and ``--jobs`` workers
never share a file -> DIR/README.md (also atomic), the table of every finished
variant. Units: mm, degrees, seconds, samples per second.
"""

from __future__ import annotations

import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

import torch

from fem import cli
from fem.files import write_json, write_text
from surrogate.data import load_samples, load_splits
from surrogate.evaluate import evaluate, timing
from surrogate.train import CONFIGS, apply_overrides, train
from workflow.shards import dataset_digest

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


def variant_configs(name: str, epochs: int | None) -> tuple:
    """(ModelConfig, TrainConfig) of a variant: the improved config with its overrides
    (and ``epochs`` unless None)."""
    extra = [] if epochs is None else [f"epochs={epochs}"]
    return apply_overrides(*CONFIGS["improved"], [*VARIANTS[name], *extra])


def run_variant(name: str, data: str, data_sha256: str, heldout: str, epochs: int | None,
                out: str) -> str:
    """Train and evaluate one variant on one thread; write out (JSON). Returns name."""
    torch.set_num_threads(1)
    model_cfg, cfg = variant_configs(name, epochs)
    splits, _ = load_splits(data)
    model, history = train(model_cfg, cfg, splits, log=lambda s: None)
    result = {"name": name, "overrides": VARIANTS[name], "epochs": cfg.epochs,
              "data_sha256": data_sha256,
              "model_config": asdict(model_cfg),
              "train_config": asdict(cfg), "n": {k: len(v) for k, v in splits.items()},
              "best_epoch": history["best_epoch"], "train_time_s": history["train_time_s"],
              "val": evaluate(model, splits["val"]),
              "heldout": evaluate(model, load_samples(heldout)[0]),
              "timing": timing(model, repeats=500, seconds=0.5, threads=(1,))}
    write_json(out, result)
    return name


def table(results: list[dict]) -> str:
    """Markdown table, one row per finished variant, in VARIANTS order."""
    head = ["run", "overrides"] + [f"{part} {key.replace('_error', '').replace('_', ' ')}"
                                   for part, key, _ in COLUMNS]
    head += ["train s", "batched f32 /s (1 thread)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        cells = [r["name"], " ".join(r["overrides"]) or "(none)"]
        for part, key, digits in COLUMNS:
            v = r[part][key]
            cells.append("n/a" if v is None else f"{v:.{digits}f}")
        cells += [f"{r['train_time_s']:.0f}", f"{r['timing']['batched_samples_per_s_float32']:.2g}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.sweep", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="results/data/train")
    ap.add_argument("--heldout", default="results/data/heldout")
    ap.add_argument("--epochs", type=cli.number(1, None, integer=True),
                    help="default: the improved config's")
    ap.add_argument("--jobs", type=cli.number(1, os.cpu_count() or 1, integer=True), default=1,
                    help="variants trained at once, 1 thread each")
    ap.add_argument("--only", nargs="*", choices=sorted(VARIANTS), help="these variants only")
    ap.add_output("--dir", folder=True, default="results/surrogate/sweep",
                  help="one NAME.json per variant and README.md")
    args = ap.parse_args(argv)
    out = Path(args.dir)
    names = args.only or list(VARIANTS)
    say = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else \
        (lambda s: print(s, flush=True))
    with ap.errors():
        data_sha256 = dataset_digest(args.data)
        load_samples(args.heldout)  # a bad held-out set fails now, not after the training

    def done(name):
        path = out / f"{name}.json"
        if not path.exists():
            return None
        r = json.loads(path.read_text())
        model_cfg, cfg = variant_configs(name, args.epochs)
        same = [r["model_config"], r["train_config"]] == json.loads(json.dumps([asdict(model_cfg), asdict(cfg)]))
        return r if same and r["data_sha256"] == data_sha256 else None

    todo = [n for n in names if done(n) is None]
    say(f"surrogate.sweep: {len(names) - len(todo)} of {len(names)} variants done, "
        f"{len(todo)} to train ({args.epochs or 'configured'} epochs, {args.jobs} job(s))")
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(run_variant, n, args.data, data_sha256, args.heldout, args.epochs,
                               str(out / f"{n}.json")) for n in todo]
        for f in futures:
            say(f"  {f.result()} done")
    results = [r for r in map(done, VARIANTS) if r is not None]
    text = (f"# Improved-surrogate sweep\n\nMade by `python -m surrogate.sweep` "
            f"({results[0]['epochs']} epochs) on `{args.data}` (split {results[0]['n']}); held-out: "
            f"`{args.heldout}`. Each run is the improved config with the overrides listed. "
            f"Validation chooses; held-out is for reference only.\n\n"
            + table(results))
    write_text(out / "README.md", text)
    if args.json:
        cli.print_json({"dir": str(out), "trained": todo, "results": results})
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
