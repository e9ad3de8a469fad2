"""Train a joint surrogate on a campaign dataset; write its checkpoint and learning curve.

    python -m surrogate.train --config paper|improved [--data DIR] [--out PATH.pt]
                              [--set key=value ...] [--threads N] [--quiet] [--json]

Data flow: DIR (shards, verified) -> its joint (the manifest's, workflow.store.recorded_joint:
anchor count k and input box, ModelConfig.for_joint) -> split 7:2:1 by the dataset seed ->
[mirror-augment the train split] -> normalisation from train -> Adam on mini-batches -> the epoch with the
lowest validation loss -> checkpoint (config, normalisation, training config, metrics on
the validation and test splits, learning history) + learning-curve PNG, both written
atomically. Every argument, ``--set`` override and the output path are checked before the
data are read (bad ones exit 2 with one line).

Loss per batch, every term in mm (R anchors (n, k, 2) mm, phi_end rad, J (n, 2k, 4),
theta the distal cap's rotation (n,) rad):

    L = mean_ik |R̂_ik - R_ik|                          mean Euclidean anchor error (paper)
      + w_phi · mean_i |wrap(phî_i - phi_i)|            end orientation; w_phi in mm/rad
      + w_cap · mean_i |wrap(θ̂_i - θ_i)|               cap rotation (models with the cap
                                                        head, and only those); w_cap in mm/rad
      + w_jac · mean_i ||(Ĵ_i - J_i) D||_F              Sobolev; D = diag(box), the joint's input
                                                        box (ModelConfig.input_box), so each
                                                        column is mm per input half-range

The paper config (docs/decisions.md §0): MLP 4-96-192-96-20, Adam lr 0.0016 decayed ×0.99 per
epoch, 500 epochs, mirror augmentation, anchor term only. The paper states neither the
activation nor the batch size; we take ReLU and 32.

The improved config is exactly mirror-symmetric (model.py), so mirror augmentation would
only duplicate every loss term and is off. Its form: the one-pass equivariant network
(invariants in, odd outputs as odd inputs times invariant coefficients), 3 x 96 SiLU,
residual, |P| feature (P > 0 and P < 0 inflate different chambers: the response has a
kink at P = 0), 800 epochs with lr decayed x0.995: the most accurate form that reaches the
1e6 samples/s inference target (the variants compared, and their errors:
docs/decisions.md; ``make sweep`` records them in results/surrogate/sweep/).
w_phi = 10 mm/rad counts the end slope like an extra anchor on a 100 mm lever (one
finger link). The improved config also has the cap-rotation head (surrogate.model), weighted
alike, w_cap = 10 mm/rad: the rigid part is bonded to the cap, so the cap's rotation swings
the same lever as phi_end does under the tangent connection. Its target is the cap rotation
itself, not its offset from phi_end, whose theta = phi_end(R̂) + c would carry the anchors'
chord error.

Seeded: the same seed, data and thread count reproduce the same weights.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import torch

from contract import cli
from contract.files import atomic_path
from contract.spec import phi_end
from surrogate.data import Samples, augment_mirror, load_splits, normalisation
from surrogate.evaluate import evaluate
from surrogate.model import (ACTIVATIONS, CAP_TARGETS, JOINT_FIELDS, JointSurrogate, ModelConfig,
                             save_checkpoint, wrap)
from workflow.shards import ShardError
from workflow.store import recorded_joint


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 500
    batch_size: int = 32
    lr: float = 1.6e-3
    lr_decay: float = 0.99          # per epoch
    mirror_augment: bool = True
    w_phi: float = 0.0              # mm/rad
    w_cap: float = 0.0              # mm/rad; > 0 exactly when the model has a cap head
    w_jac: float = 0.0              # dimensionless (the Jacobian term is in mm already)
    seed: int = 0


CONFIGS = {
    "paper": (ModelConfig(hidden=(96, 192, 96), activation="relu"),
              TrainConfig()),
    "improved": (ModelConfig(hidden=(96, 96, 96), activation="silu", residual=True,
                             equivariant=True, abs_pressure=True, cap_rotation=True,
                             cap_target="absolute"),
                 TrainConfig(epochs=800, batch_size=64, lr=3e-3, lr_decay=0.995,
                             mirror_augment=False, w_phi=10.0, w_cap=10.0, w_jac=0.2)),
}


def check_configs(model_cfg: ModelConfig, cfg: TrainConfig) -> None:
    """Raise ValueError (one line) unless the cap head and its loss term come together: a
    head with w_cap = 0 would stay untrained, and w_cap > 0 has nothing to weigh without one."""
    if model_cfg.cap_rotation and cfg.w_cap <= 0:
        raise ValueError("cap_rotation=true needs w_cap > 0 (mm/rad), or its head stays untrained")
    if cfg.w_cap > 0 and not model_cfg.cap_rotation:
        raise ValueError(f"w_cap={cfg.w_cap:g} needs cap_rotation=true (the model has no cap head)")


def check_data(model_cfg: ModelConfig, splits: dict[str, Samples]) -> None:
    """Raise ValueError (one line) unless every split has the model's anchor count (its joint's)."""
    for name, part in splits.items():
        if part.n_anchors != model_cfg.n_anchors:
            raise ValueError(f"the {name} split has {part.n_anchors} anchors per sample, the model "
                             f"{model_cfg.n_anchors}: configure it for the dataset's joint (ModelConfig.for_joint)")


def loss_terms(model: JointSurrogate, batch: Samples, cfg: TrainConfig) -> dict[str, torch.Tensor]:
    """Loss terms in mm (module docstring) of one batch; 'total' is their weighted sum.
    Terms of zero weight are not computed (and the cap term needs check_configs)."""
    pred, jac, cap = model.outputs(batch.inputs, jacobian=cfg.w_jac > 0, cap=cfg.w_cap > 0)
    terms = {"anchor": (pred - batch.anchors).norm(dim=-1).mean()}
    total = terms["anchor"]
    if cfg.w_phi > 0:
        terms["phi"] = wrap(phi_end(pred) - phi_end(batch.anchors)).abs().mean()
        total = total + cfg.w_phi * terms["phi"]
    if cap is not None:
        terms["cap"] = wrap(cap - batch.cap_rotation).abs().mean()
        total = total + cfg.w_cap * terms["cap"]
    if jac is not None:
        ok = batch.has_jacobian
        d = torch.as_tensor(model.config.input_box, dtype=jac.dtype)
        diff = ((jac[ok] - batch.jacobian[ok]) * d).flatten(1).norm(dim=1)
        terms["jac"] = diff.mean() if ok.any() else jac.sum() * 0
        total = total + cfg.w_jac * terms["jac"]
    terms["total"] = total
    return terms


def train(model_cfg: ModelConfig, cfg: TrainConfig, splits: dict[str, Samples],
          log=print) -> tuple[JointSurrogate, dict]:
    """Train from scratch; returns (model at the best validation epoch, history).

    history: lists per epoch of train_loss, train_anchor_mm, val_loss, val_anchor_mm,
    val_phi_deg, lr (and val_cap_deg for a model with the cap head); plus best_epoch and
    train_time_s. Raises ValueError if the configs disagree (check_configs) or the data are
    of another anchor count than model_cfg (check_data); the inputs are scaled by
    model_cfg.input_box.
    """
    check_configs(model_cfg, cfg)
    check_data(model_cfg, splits)
    torch.manual_seed(cfg.seed)
    data = augment_mirror(splits["train"]) if cfg.mirror_augment else splits["train"]
    val = splits["val"]
    cap_target = model_cfg.cap_target if model_cfg.cap_rotation else None
    model = JointSurrogate(model_cfg, normalisation(splits["train"], cap_target, model_cfg.input_box)).to(torch.float64)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=cfg.lr_decay)
    gen = torch.Generator().manual_seed(cfg.seed)
    history = {k: [] for k in ("train_loss", "train_anchor_mm", "val_loss", "val_anchor_mm",
                               "val_phi_deg", "lr") + ("val_cap_deg",) * model_cfg.cap_rotation}
    best, best_state = math.inf, None
    log_every = max(1, cfg.epochs // 20)
    t0 = time.perf_counter()
    for epoch in range(1, cfg.epochs + 1):
        model.train()
        order = torch.randperm(len(data), generator=gen)
        sums, count = {"total": 0.0, "anchor": 0.0}, 0
        for start in range(0, len(data), cfg.batch_size):
            batch = data.subset(order[start:start + cfg.batch_size])
            terms = loss_terms(model, batch, cfg)
            opt.zero_grad(set_to_none=True)
            terms["total"].backward()
            opt.step()
            for k in sums:
                sums[k] += terms[k].item() * len(batch)
            count += len(batch)
        history["lr"].append(sched.get_last_lr()[0])
        sched.step()
        model.eval()
        with torch.no_grad():
            val_terms = loss_terms(model, val, cfg)
            val_phi = wrap(phi_end(model(val.inputs)) - phi_end(val.anchors)).abs().mean()
        history["train_loss"].append(sums["total"] / count)
        history["train_anchor_mm"].append(sums["anchor"] / count)
        history["val_loss"].append(val_terms["total"].item())
        history["val_anchor_mm"].append(val_terms["anchor"].item())
        history["val_phi_deg"].append(math.degrees(val_phi.item()))
        if "cap" in val_terms:
            history["val_cap_deg"].append(math.degrees(val_terms["cap"].item()))
        if history["val_loss"][-1] < best:
            best, best_state = history["val_loss"][-1], copy.deepcopy(model.state_dict())
            history["best_epoch"] = epoch
        if epoch % log_every == 0 or epoch == cfg.epochs:
            log(f"epoch {epoch:4d}/{cfg.epochs}  loss {history['train_loss'][-1]:.4f} mm  "
                f"val anchor {history['val_anchor_mm'][-1]:.4f} mm  "
                f"val phi {history['val_phi_deg'][-1]:.3f} deg  "
                + (f"val cap {history['val_cap_deg'][-1]:.3f} deg  " if "cap" in val_terms else "")
                + f"lr {history['lr'][-1]:.2e}  "
                f"{time.perf_counter() - t0:.0f} s")
    history["train_time_s"] = time.perf_counter() - t0
    model.load_state_dict(best_state)
    model.eval()
    return model, history


def learning_curve(history: dict, path: Path, title: str) -> None:
    """PNG of training and validation anchor error (and val phi_end and cap rotation
    errors) per epoch."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = range(1, len(history["train_loss"]) + 1)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.semilogy(epochs, history["train_anchor_mm"], label="train (mean anchor error)")
    a.semilogy(epochs, history["val_anchor_mm"], label="validation (mean anchor error)")
    if history["train_loss"] != history["train_anchor_mm"]:
        a.semilogy(epochs, history["train_loss"], lw=0.8, alpha=0.6, label="train loss (total)")
    a.axvline(history["best_epoch"], color="gray", ls=":", label="kept epoch")
    a.set_xlabel("epoch")
    a.set_ylabel("mm")
    a.legend()
    a.grid(alpha=0.3, which="both")
    b.semilogy(epochs, history["val_phi_deg"], color="tab:red", label="phi_end")
    if "val_cap_deg" in history:
        b.semilogy(epochs, history["val_cap_deg"], color="tab:purple", label="cap rotation")
        b.legend()
    b.set_xlabel("epoch")
    b.set_ylabel("validation angle error (deg)")
    b.grid(alpha=0.3, which="both")
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


#: --set fields that take numbers -> cli.number(lo, hi, unit, integer, open_lo) arguments;
#: hidden takes comma-separated layer widths of at least 1.
NUMERIC_FIELDS = {"epochs": (1, None, "", True, False), "batch_size": (1, None, "", True, False),
                  "lr": (0, None, "", False, True), "lr_decay": (0, 1, "", False, True),
                  "w_phi": (0, None, "mm/rad", False, False), "w_cap": (0, None, "mm/rad", False, False),
                  "w_jac": (0, None, "", False, False),
                  "seed": (0, None, "", True, False)}
WIDTH = cli.number(1, None, integer=True)
#: --set fields that take one of a few words
CHOICE_FIELDS = {"activation": sorted(ACTIVATIONS), "cap_target": CAP_TARGETS}


def parse_override(pair: str) -> tuple[str, object]:
    """``key=value`` of a ModelConfig or TrainConfig field -> (key, parsed value).

    Raises ValueError (one line) for a missing ``=``, an unknown key or a value that is not
    of the field's kind or range (numbers must be finite)."""
    key, sep, value = pair.partition("=")
    if not sep:
        raise ValueError(f"--set {pair}: expected key=value")
    names = {f.name: f for cfg in (ModelConfig, TrainConfig) for f in fields(cfg) if f.name not in JOINT_FIELDS}
    if key in JOINT_FIELDS:
        raise ValueError(f"--set {pair}: {key} is the dataset's joint's (its [anchors] count and "
                         f"[input_box]), not a training option")
    if key not in names:
        raise ValueError(f"--set {pair}: unknown field {key!r} (known: {', '.join(names)})")
    default = names[key].default
    try:
        if isinstance(default, bool):
            if value.lower() not in ("true", "false", "1", "0"):
                raise ValueError("expected true or false")
            return key, value.lower() in ("true", "1")
        if key == "hidden":
            return key, tuple(WIDTH(w) for w in value.split(","))
        if key in CHOICE_FIELDS:
            if value not in CHOICE_FIELDS[key]:
                raise ValueError(f"expected one of {', '.join(CHOICE_FIELDS[key])}")
            return key, value
        lo, hi, unit, integer, open_lo = NUMERIC_FIELDS[key]
        return key, cli.number(lo, hi, unit, integer, open_lo)(value)
    except (ValueError, argparse.ArgumentTypeError) as exc:
        raise ValueError(f"--set {pair}: {exc}") from None


def apply_overrides(model_cfg: ModelConfig, cfg: TrainConfig, pairs: list[str]):
    """Apply ``key=value`` overrides to whichever config has the field; returns both
    configs. Raises ValueError for a bad pair (parse_override) or a key given twice."""
    seen = {}
    for pair in pairs:
        key, value = parse_override(pair)
        if key in seen:
            raise ValueError(f"--set {key} given twice ({seen[key]}, {pair}): give each key once")
        seen[key] = pair
        if key in {f.name for f in fields(ModelConfig)}:
            model_cfg = dataclasses.replace(model_cfg, **{key: value})
        else:
            cfg = dataclasses.replace(cfg, **{key: value})
    return model_cfg, cfg


class _Overrides(argparse._AppendAction):
    """--set KEY=VALUE, repeatable; a bad pair or a key given twice is a usage error."""

    def __call__(self, parser, namespace, value, option_string=None):
        try:
            apply_overrides(ModelConfig(), TrainConfig(), [*(getattr(namespace, self.dest) or []), value])
        except ValueError as exc:
            parser.error(str(exc))
        super().__call__(parser, namespace, value, option_string)


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.train",
                    description="Train the joint surrogate (paper or improved config).")
    ap.add_argument("--config", choices=sorted(CONFIGS), required=True)
    ap.add_argument("--data", default="results/data/train", help="campaign dataset directory")
    ap.add_output("--out", suffix=".pt", help="checkpoint path (default results/surrogate/CONFIG.pt); "
                                             "the learning curve goes beside it as *_curve.png")
    ap.add_argument("--set", action=_Overrides, default=[], metavar="KEY=VALUE",
                    help="override a ModelConfig/TrainConfig field, e.g. hidden=64,64 or epochs=50")
    ap.add_argument("--threads", type=cli.number(1, os.cpu_count() or 1, integer=True), default=1,
                    help="torch CPU threads")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    if args.out is None:  # the default depends on --config: check it as add_output would
        args.out = f"results/surrogate/{args.config}.pt"
        if why := cli.check_output(args.out):
            ap.error(why)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    out = Path(args.out)
    torch.set_num_threads(args.threads)
    with ap.errors():
        model_cfg, cfg = apply_overrides(*CONFIGS[args.config], args.set)
        check_configs(model_cfg, cfg)
        try:
            splits, manifest = load_splits(args.data)
        except ShardError as exc:
            raise ShardError(f"{exc}; the campaign writes datasets: make dataset") from None
        joint = recorded_joint(manifest.config)      # the checkpoint carries it (surrogate.model)
        model_cfg = model_cfg.for_joint(joint)
        check_data(model_cfg, splits)
    log = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    log(f"{args.config}: {model_cfg}\n{cfg}\n"
        f"data {args.data}: " + ", ".join(f"{k} {len(v)}" for k, v in splits.items()))
    model, history = train(model_cfg, cfg, splits, log)
    metrics = {"train_time_s": history["train_time_s"], "best_epoch": history["best_epoch"],
               "threads": args.threads, "val": evaluate(model, splits["val"]),
               "test": evaluate(model, splits["test"]), "history": history}
    dataset = {"root": str(args.data), "seed": manifest.seed, "config": manifest.config,
               "n": {k: len(v) for k, v in splits.items()}}
    curve = out.with_name(out.stem + "_curve.png")
    with ap.errors():
        save_checkpoint(out, model, {"name": args.config, **asdict(cfg)}, metrics, dataset, joint)
        source = manifest.config.get("source", "FEM campaign")
        learning_curve(history, curve,
                       f"{args.config} surrogate: {len(splits['train'])} training samples ({source})")
    if args.json:
        cli.print_json({"config": args.config, "checkpoint": str(out), "curve": str(curve),
                        "train_time_s": history["train_time_s"], "best_epoch": history["best_epoch"],
                        "val": metrics["val"], "test": metrics["test"]})
        return 0
    for part in ("val", "test"):
        m = metrics[part]
        jac = "n/a" if m["jacobian_rel_error"] is None else f"{m['jacobian_rel_error']:.4f}"
        cap = "n/a" if m["cap_rotation_error_deg"] is None else f"{m['cap_rotation_error_deg']:.3f} deg"
        print(f"{args.config}: {out} {part}: mean anchor {m['mean_anchor_error_mm']:.4f} mm, "
              f"p95 {m['p95_anchor_error_mm']:.4f} mm, phi_end {m['phi_end_error_deg']:.3f} deg, "
              f"cap rotation {cap}, Jacobian rel {jac}; trained in {history['train_time_s']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
