"""A multi-fidelity joint surrogate, measured against fine-only training at equal FEM cost.

    python -m surrogate.multifidelity --coarse DIR --fine DIR [--heldout DIR]
        [--coarse-model PATH] [--sizes 50,100,200,400,all] [--seed 0] [--min-steps 22400]
        [--set KEY=VALUE ...] [--reference-curve JSON] [--max-hours H]
        [--out results/surrogate/h1.8/multifidelity.json] [--plot PNG] [--json]

Model. A coarse surrogate C, trained on the coarse set (the improved config; or
--coarse-model), is frozen. On n fine samples a correction in two stages is fitted: least-
squares scales of the coarse displacement u_C = R_C(x) - R_C(0) (the coarse mesh is
stiffer: its error grows with the deflection), then a small network D on what is left:

    R(x)     = R_C(x) + rho u_C(x) + R_D(x)          anchors (k, 2) mm, x = [P MPa, F1 N, F2 N, M N·mm]
    theta(x) = theta_C(x) (1 + rho_theta) + theta_D(x)          distal cap rotation, rad
    J(x)     = (1 + rho) J_C(x) + J_D(x)             d R.reshape(2k) / d x, (2k, 4)

    rho (2k,), one per anchor coordinate, and rho_theta: least squares over the n samples
    (fit_scale); the targets of D at a fine sample (x, R_f, theta_f, J_f), with
    B = R_C + rho u_C:  R_f - B(x),  wrap(theta_f - theta_B(x)),  J_f - J_B(x)

with J_C the coarse surrogate's exact (forward-mode) Jacobian. D is a JointSurrogate of
the improved config with CORRECTION overrides (two hidden layers of 32; w_phi = 0, since
phi_end of a difference of anchors is no angle of the joint), for the fine set's joint (its
anchor count k and input box, ModelConfig.for_joint), fitted by
surrogate.train.train. Its anchor loss |R_D - (R_f - B)| is |R - R_f|, the
multi-fidelity model's own error. u_C,y and theta_C are odd under the mirror y -> -y and
D is mirror-equivariant like C, so R keeps the joint's mirror symmetry exactly. Each
point also records the scaled coarse surrogate B alone (``scale_only``).

Cost at equal FEM effort. c = 3600 cpu_hours / samples from each manifest (CPU s per
sample). A multi-fidelity point with n fine samples spends n c_f + N_c c_c (the whole
coarse campaign); the fine-only surrogate of the same cost has

    m = round(n + N_c c_c / c_f)   fine samples,

trained by surrogate.learning_curve's rule (the improved config, at least min_steps Adam
steps, the same learning-rate path). Where m exceeds the fine training pool, the
baseline is the whole pool (``m_exceeds_data``) and the committed fine-only learning curve
(--reference-curve, log-log interpolated at m; measured on its own data, a proxy of how a
fine-only surrogate improves with m) is quoted beside it. Validation samples are counted
in neither cost: both methods choose their epochs on the same ones. Every size is also
trained fine-only on the same n samples, so the figure shows both curves against CPU hours.

Data flow. --fine is split 7:2:1 by its seed (surrogate.data.load_splits): nested
training subsets (surrogate.learning_curve.nested_subsets) of its train split, its val
split choosing every run's kept epoch, and --heldout measured only. Without --heldout (or
with --heldout the same directory as --fine) the fine set is split instead by walk blocks
of 16 (workflow.shards.split_of, seed SELF_SPLIT_SEED) 4:1:3 into training pool,
validation and held-out (256 samples: 128 / 32 / 96).

Checked before any training (one line, exit 2, nothing written): every set loads with
its checksums; coarse and fine agree on source, input box, material and the geometry
apart from the mesh sizes; the held-out set has the fine set's discretisation (geometry,
material, solver, formulation) and a walk of its own (a seed neither training set has);
--coarse-model was trained on the coarse set's campaign (seed and config); the coarse
and fine manifests record cpu_hours; the sizes fit the pool; each --set key comes once.

OUT (JSON, surrogate.artefacts.MULTIFIDELITY) and the figure (held-out errors against
CPU hours, both curves) are rewritten atomically after every point; a re-run keeps the
points whose configs and data digests match. A coarse surrogate trained here is saved as
OUT's stem + ``_coarse.pt`` and reused while the coarse data is the same. Exit 0 when
every point is done, 3 when --max-hours stopped it (re-run the same command to resume).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch import nn

from contract import cli
from contract.files import atomic_path, json_safe, sha256_file
from contract.spec import N_INPUTS
from surrogate.artefacts import LEARNING_CURVE, MULTIFIDELITY
from surrogate.data import Samples, load_samples, load_splits
from surrogate.evaluate import evaluate
from surrogate.learning_curve import (EXIT_STOPPED, MIN_STEPS, exit_code, load_points, nested_subsets,
                                      point_configs, progress, run_point, say, sizes_arg)
from surrogate.model import (JointSurrogate, ModelError, build_model, config_record, load_checkpoint,
                             save_checkpoint, wrap)
from surrogate.train import CONFIGS, parse_override, train
from workflow.shards import Manifest, ShardError, dataset_digest, split_of
from workflow.store import recorded_joint

SIZES = (50, 100, 200, 400, "all")
KINDS = ("multifidelity", "fine_only")
#: The correction network: the improved config with these overrides (module docstring).
CORRECTION = ("hidden=32,32", "w_phi=0")
#: Without a separate held-out set: blocks of 16 walk samples dealt 4:1:3 (pool, val, held-out).
SELF_SPLIT = (4, 1, 3)
SELF_SPLIT_SEED = 0
#: The committed stand-in's fine-only reference: the 1.8 mm learning curve (make multifidelity).
REFERENCE_CURVE = Path("results/surrogate/h1.8/learning_curve.json")
ERRORS = ("heldout_mean_anchor_error_mm", "heldout_tip_error_mm", "heldout_cap_rotation_error_deg",
          "heldout_phi_end_error_deg", "heldout_jacobian_rel_error")
POINT_KEYS = ("kind", "samples", "seed", "min_steps", "model_config", "train_config", "correction_form",
              "coarse_model_sha256", "fine_sha256", "heldout_sha256", "split", *ERRORS, "scale_only", "rho",
              "rho_theta", "val_mean_anchor_error_mm", "train_anchor_error_mm", "best_epoch", "steps",
              "train_time_s", "cpu_hours")
#: What a multi-fidelity point fits on top of the frozen coarse surrogate (module docstring).
FORM = "rho (R_C - R_C(0)) + network"
#: Config keys coarse and fine must share (the same joint, loads and material), and the
#: held-out set must share with the fine set (the same discretisation).
SAME_JOINT = ("source", "input_box", "material", "joint_sha256")
SAME_DISCRETISATION = ("source", "input_box", "material", "geometry", "solver", "formulation")
MESH_KEYS = ("mesh_size", "wall_mesh_size")


class ScaledCoarse(nn.Module):
    """The coarse surrogate with its displacement scaled (module docstring):
    R_C + rho (R_C - R_C(0)), theta_C (1 + rho_theta), J_C (1 + rho). Inputs (..., 4)
    [MPa, N, N, N·mm] -> anchors (..., k, 2) mm; ``with_cap`` adds the cap rotation rad.
    Frozen; rho = 0 gives the coarse surrogate itself."""

    def __init__(self, coarse: JointSurrogate, rho: torch.Tensor, rho_theta: float):
        super().__init__()
        self.coarse = coarse.requires_grad_(False)
        with torch.no_grad():
            origin = coarse.outputs(torch.zeros(1, N_INPUTS, dtype=torch.float64))[0].reshape(-1)
        self.register_buffer("origin", origin, persistent=False)
        self.register_buffer("rho", torch.as_tensor(rho, dtype=torch.float64).reshape(len(origin)),
                             persistent=False)
        self.rho_theta = float(rho_theta)

    @property
    def has_cap_rotation(self) -> bool:
        return self.coarse.has_cap_rotation

    @property
    def n_anchors(self) -> int:
        return self.coarse.n_anchors

    @property
    def input_box(self) -> tuple[float, ...]:
        return self.coarse.input_box

    def outputs(self, x: torch.Tensor, jacobian: bool = False, cap: bool = False):
        """(anchors (n, k, 2) mm, Jacobian (n, 2k, 4) or None, cap (n,) rad or None)."""
        r, j, c = self.coarse.outputs(x, jacobian, cap)
        u = r.reshape(len(x), -1) - self.origin
        r = r + (self.rho * u).reshape(r.shape)
        return (r, None if j is None else j * (1 + self.rho)[:, None],
                None if c is None else c * (1 + self.rho_theta))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return _anchors(self, x)

    def with_cap(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return _anchors_and_cap(self, x)


class MultiFidelitySurrogate(nn.Module):
    """R = base + correction (module docstring), base a ScaledCoarse: inputs (..., 4)
    [MPa, N, N, N·mm] -> anchors (..., k, 2) mm; ``with_cap`` adds the cap rotation (...)
    rad where both parts have the head."""

    def __init__(self, base: ScaledCoarse, correction: JointSurrogate):
        super().__init__()
        self.base = base
        self.correction = correction

    @property
    def has_cap_rotation(self) -> bool:
        return self.base.has_cap_rotation and self.correction.has_cap_rotation

    @property
    def n_anchors(self) -> int:
        return self.base.n_anchors

    @property
    def input_box(self) -> tuple[float, ...]:
        return self.base.input_box

    def outputs(self, x: torch.Tensor, jacobian: bool = False, cap: bool = False):
        """(anchors (n, k, 2) mm, Jacobian (n, 2k, 4) or None, cap (n,) rad or None)."""
        a, ja, ca = self.base.outputs(x, jacobian, cap)
        b, jb, cb = self.correction.outputs(x, jacobian, cap)
        return a + b, None if ja is None else ja + jb, None if ca is None else ca + cb

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return _anchors(self, x)

    def with_cap(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return _anchors_and_cap(self, x)


def _anchors(model, x: torch.Tensor) -> torch.Tensor:
    batch = x.shape[:-1]
    return model.outputs(x.reshape(-1, N_INPUTS))[0].reshape(*batch, model.n_anchors, 2)


def _anchors_and_cap(model, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    batch = x.shape[:-1]
    y, _, c = model.outputs(x.reshape(-1, N_INPUTS), cap=True)
    return y.reshape(*batch, model.n_anchors, 2), c.reshape(batch)


def fit_scale(coarse: JointSurrogate, fine: Samples) -> ScaledCoarse:
    """The least-squares scales of the coarse displacement u = R_C(x) - R_C(0) against
    the fine data, per anchor coordinate c and for the cap rotation:

        rho_c = sum_i u_ic d_ic / sum_i u_ic^2,       d = R_f - R_C(x)          (2k,)
        rho_theta = sum_i theta_C,i e_i / sum_i theta_C,i^2,  e = wrap(theta_f - theta_C)

    (0 where the coarse displacement vanishes). Both are mirror-consistent: u_y and
    theta_C are odd, so R_C + rho u keeps the symmetry."""
    base = ScaledCoarse(coarse, torch.zeros(2 * coarse.n_anchors), 0.0)
    with torch.no_grad():
        r, _, c = coarse.outputs(fine.inputs, cap=coarse.has_cap_rotation)
    u = r.reshape(len(fine), -1) - base.origin
    d = (fine.anchors - r).reshape(len(fine), -1)
    rho = (u * d).sum(0) / (u * u).sum(0).clamp_min(1e-300)
    rho_theta = 0.0
    if c is not None and (c * c).sum() > 0:
        rho_theta = ((c * wrap(fine.cap_rotation - c)).sum() / (c * c).sum()).item()
    return ScaledCoarse(coarse, rho, rho_theta)


def residual_samples(base, fine: Samples) -> Samples:
    """The correction's targets at the fine samples (module docstring), from a frozen
    ``base`` (a ScaledCoarse or a JointSurrogate): anchors mm, cap rotation rad (0 for a
    base without the head) and Jacobian (NaN rows stay NaN)."""
    with torch.no_grad():
        r, j, c = base.outputs(fine.inputs, jacobian=True, cap=base.has_cap_rotation)
    cap = torch.zeros_like(fine.cap_rotation) if c is None else wrap(fine.cap_rotation - c)
    return Samples(fine.inputs, fine.anchors - r, fine.jacobian - j, fine.sample_id, cap)


def equal_cost_samples(n: int, coarse_cpu_hours: float, fine_cpu_s: float) -> int:
    """m = round(n + N_c c_c / c_f): the fine samples costing what n fine samples and the
    whole coarse campaign (coarse_cpu_hours, h) cost, with c_f CPU s per fine sample."""
    return round(n + 3600.0 * coarse_cpu_hours / fine_cpu_s)


def cpu_s_per_sample(manifest: Manifest, root) -> float:
    """c = 3600 cpu_hours / samples (CPU s); ValueError if the manifest records no CPU time."""
    if not manifest.cpu_hours or manifest.n == 0:
        raise ValueError(f"{root}: its manifest records no cpu_hours (not a campaign dataset): "
                         "no FEM cost to compare at")
    return 3600.0 * manifest.cpu_hours / manifest.n


def correction_configs(samples: int, seed: int, min_steps: int, overrides: list[str], cap: bool, joint=None):
    """(ModelConfig, TrainConfig) of a correction trained on ``samples``: the improved
    config with CORRECTION and then ``overrides`` (a key given in both: the override), the
    learning-curve epoch budget, and no cap head when the coarse model has none; for
    ``joint`` (a contract.joint.JointSpec; None: the paper's)."""
    pairs = {parse_override(p)[0]: p for p in (*CORRECTION, *(() if cap else ("cap_rotation=false", "w_cap=0")),
                                                *overrides)}
    return point_configs("improved", list(pairs.values()), samples, True, seed, min_steps, joint)


def fine_only_configs(samples: int, seed: int, min_steps: int, joint=None):
    """(ModelConfig, TrainConfig) of the fine-only baseline: surrogate.learning_curve's rule."""
    return point_configs("improved", [], samples, True, seed, min_steps, joint)


# ---------------------------------------------------------------------------- data
def _config_part(config: dict, keys) -> dict:
    return {k: config.get(k) for k in keys}


def _joint(config: dict) -> dict:
    """What coarse and fine must share: SAME_JOINT and the geometry without mesh sizes."""
    geometry = {k: v for k, v in (config.get("geometry") or {}).items() if k not in MESH_KEYS}
    return _config_part(config, SAME_JOINT) | {"geometry": geometry}


def check_sets(coarse: Manifest, fine: Manifest, heldout: Manifest | None, roots: dict) -> None:
    """Raise ValueError (one line) for sets that do not belong together (module docstring)."""
    if _joint(coarse.config) != _joint(fine.config):
        diff = [k for k, v in _joint(coarse.config).items() if _joint(fine.config)[k] != v]
        raise ValueError(f"{roots['fine']}: another joint or input box than {roots['coarse']} "
                         f"(config {', '.join(diff)} differ)")
    held, held_root = (fine, roots["fine"]) if heldout is None else (heldout, roots["heldout"])
    if heldout is not None:
        diff = [k for k in SAME_DISCRETISATION if heldout.config.get(k) != fine.config.get(k)]
        if diff:
            raise ValueError(f"{held_root}: not on the discretisation of {roots['fine']} "
                             f"(config {', '.join(diff)} differ)")
        if heldout.seed == fine.seed:
            raise ValueError(f"{held_root}: the same walk (seed {fine.seed}) as {roots['fine']}: "
                             "a held-out set needs a seed of its own")
    if held.seed == coarse.seed:
        raise ValueError(f"{held_root}: the held-out loads are the walk of {roots['coarse']} "
                         f"(seed {coarse.seed}), which trained the coarse surrogate")


def self_split(samples: Samples, seed: int = SELF_SPLIT_SEED) -> dict[str, Samples]:
    """{train, val, heldout} of one set: walk blocks of 16 dealt SELF_SPLIT (4:1:3)."""
    label = torch.as_tensor(split_of(samples.sample_id.numpy(), seed, counts=SELF_SPLIT))
    return {name: samples.subset(label == i) for i, name in enumerate(("train", "val", "heldout"))}


def load_sets(coarse: str, fine: str, heldout: str | None):
    """(fine parts {train, val, heldout}, manifests {coarse, fine, heldout}, split name).
    Raises ValueError (ShardError) for a set that cannot be used."""
    roots = {"coarse": coarse, "fine": fine, "heldout": heldout}
    separate = heldout is not None and Path(heldout).resolve() != Path(fine).resolve()
    manifests = {"coarse": Manifest.load(coarse), "fine": Manifest.load(fine),
                 "heldout": Manifest.load(heldout) if separate else None}
    check_sets(manifests["coarse"], manifests["fine"], manifests["heldout"], roots)
    for name in ("coarse", "fine"):
        cpu_s_per_sample(manifests[name], roots[name])
    if separate:
        splits, _ = load_splits(fine)
        parts = {"train": splits["train"], "val": splits["val"], "heldout": load_samples(heldout)[0]}
    else:
        parts = self_split(load_samples(fine)[0])
        empty = [k for k, v in parts.items() if len(v) == 0]
        if empty:
            raise ValueError(f"{fine}: too few walk blocks to split into pool, validation and "
                             f"held-out ({', '.join(empty)} empty)")
    load_samples(coarse)  # verifies every coarse shard before any work
    split = "separate" if separate else f"self {':'.join(map(str, SELF_SPLIT))} seed {SELF_SPLIT_SEED}"
    return parts, manifests, split


# ---------------------------------------------------------------------------- coarse surrogate
def check_coarse_model(ckpt: dict, manifest: Manifest, path, root) -> None:
    """Raise ValueError unless checkpoint ``ckpt`` was trained on the campaign of ``root``."""
    ds = ckpt.get("dataset") or {}
    if ds.get("seed") != manifest.seed or ds.get("config") != manifest.config:
        raise ValueError(f"{path}: trained on another dataset ({ds.get('root')}, seed {ds.get('seed')}) "
                         f"than --coarse {root} (seed {manifest.seed})")


def coarse_configs(manifest: Manifest):
    """(ModelConfig, TrainConfig) of the coarse surrogate: the improved config for the coarse
    set's joint; ShardError (one line) for a manifest whose joint record is not valid."""
    model_cfg, cfg = CONFIGS["improved"]
    return model_cfg.for_joint(recorded_joint(manifest.config)), cfg


def cached_coarse(path: Path, data_sha: str, manifest: Manifest):
    """The coarse surrogate trained here before on the same coarse data, or None."""
    try:
        ckpt = load_checkpoint(path)
        if ckpt["dataset"].get("data_sha256") != data_sha:
            return None
        cfg = {k: v for k, v in ckpt["train_config"].items() if k != "name"}
        model_cfg, train_cfg = coarse_configs(manifest)
        if ckpt["model_config"] != config_record(model_cfg) or cfg != asdict(train_cfg):
            return None
        return build_model(ckpt, str(path)).eval().requires_grad_(False)
    except (ModelError, KeyError, AttributeError):
        return None


def train_coarse(root: str, manifest: Manifest, path: Path, data_sha: str, log) -> JointSurrogate:
    """Train the improved config on the coarse set (its train split; val chooses the
    epoch), save it at ``path`` and return it frozen."""
    splits, _ = load_splits(root)
    model_cfg, cfg = coarse_configs(manifest)
    model, history = train(model_cfg, cfg, splits, log)
    dataset = {"root": str(root), "seed": manifest.seed, "config": manifest.config, "data_sha256": data_sha,
               "n": {k: len(v) for k, v in splits.items()}}
    metrics = {"train_time_s": history["train_time_s"], "best_epoch": history["best_epoch"], "threads": 1}
    save_checkpoint(path, model, {"name": "improved", **asdict(cfg)}, metrics, dataset,
                    recorded_joint(manifest.config))
    return model.requires_grad_(False)


# ---------------------------------------------------------------------------- points
def run_correction(coarse: JointSurrogate, parts: dict, index: torch.Tensor, model_cfg, cfg, log) -> dict:
    """Fit the scales and train the correction on parts['train'][index] (parts['val']
    chooses the epoch); measure the model, and the scaled coarse surrogate alone, on
    parts['heldout']. The figures of one point."""
    base = fit_scale(coarse, parts["train"].subset(index))
    splits = {"train": residual_samples(base, parts["train"].subset(index)),
              "val": residual_samples(base, parts["val"])}
    correction, history = train(model_cfg, cfg, splits, log)
    held = evaluate(MultiFidelitySurrogate(base, correction.requires_grad_(False)), parts["heldout"])
    scaled = evaluate(base, parts["heldout"])
    best = history["best_epoch"]
    return {**{k: held[k[8:]] for k in ERRORS}, "scale_only": {k: scaled[k[8:]] for k in ERRORS},
            "rho": base.rho.tolist(), "rho_theta": base.rho_theta,
            "val_mean_anchor_error_mm": history["val_anchor_mm"][best - 1],
            "train_anchor_error_mm": history["train_anchor_mm"][best - 1],
            "best_epoch": best, "steps": cfg.epochs * math.ceil(len(index) / cfg.batch_size),
            "train_time_s": history["train_time_s"]}


def plan(pool: int, sizes, m_of) -> list[tuple[str, int]]:
    """(kind, samples) of every point: per size ascending, the multi-fidelity point, the
    fine-only point on the same samples and the fine-only point of equal cost (capped at
    the pool); "all" is the pool."""
    jobs = []
    for n in sorted({pool if s == "all" else s for s in sizes}):
        jobs += [("multifidelity", n), ("fine_only", n), ("fine_only", min(m_of(n), pool))]
    return list(dict.fromkeys(jobs))


def point_cost(kind: str, samples: int, cost: dict) -> float:
    """CPU hours of a point: n c_f (+ the coarse campaign for a multi-fidelity point)."""
    return samples * cost["fine_s"] / 3600.0 + (cost["coarse_h"] if kind == "multifidelity" else 0.0)


def identity(kind: str, samples: int, seed: int, min_steps: int, configs, ids: dict) -> dict:
    """The keys that decide whether a stored point is still valid (as stored in JSON)."""
    model_cfg, cfg = configs
    multi = kind == "multifidelity"
    return json_safe({"kind": kind, "samples": samples, "seed": seed, "min_steps": min_steps,
                      "model_config": config_record(model_cfg), "train_config": asdict(cfg),
                      "correction_form": FORM if multi else None,
                      "coarse_model_sha256": ids["coarse_model_sha256"] if multi else None, "fine_sha256": ids["fine_sha256"],
                      "heldout_sha256": ids["heldout_sha256"], "split": ids["split"]})


def is_current(point: dict, configs: dict, seed: int, min_steps: int, ids: dict) -> bool:
    """A stored point is kept if it is a planned (kind, samples) with the configs, seed,
    budget and data digests this run would give it."""
    try:
        want = identity(point["kind"], point["samples"], seed, min_steps, configs[(point["kind"], point["samples"])],
                        ids)
    except (KeyError, TypeError):
        return False
    return set(point) == set(POINT_KEYS) and all(point[k] == v for k, v in want.items())


def interpolate_curve(doc: dict, m: float) -> dict | None:
    """The committed learning curve's held-out errors at m samples, log-log between its
    points with the Jacobian loss and its first seed; None outside its range."""
    points = [p for p in doc["points"] if p["jacobian_loss"]]
    if not points:
        return None
    seed = min(p["seed"] for p in points)
    points = sorted((p for p in points if p["seed"] == seed), key=lambda p: p["samples"])
    sizes = np.log([p["samples"] for p in points])
    if not sizes[0] <= math.log(m) <= sizes[-1]:
        return None
    out = {}
    for key in ERRORS[:3]:
        vals = [p[key] for p in points]
        out[key] = None if None in vals else float(np.exp(np.interp(math.log(m), sizes, np.log(vals))))
    return out


def comparison(points: list[dict], pool: int, cost: dict, curve: dict | None) -> list[dict]:
    """One row per multi-fidelity point: its errors and cost, the equal-cost m, and the
    fine-only errors at min(m, pool) (and the reference curve at m)."""
    fine = {p["samples"]: p for p in points if p["kind"] == "fine_only"}
    rows = []
    for p in sorted((p for p in points if p["kind"] == "multifidelity"), key=lambda p: p["samples"]):
        m = equal_cost_samples(p["samples"], cost["coarse_h"], cost["fine_s"])
        used = min(m, pool)
        base = fine.get(used)
        rows.append({"samples": p["samples"], "multifidelity_cpu_hours": p["cpu_hours"],
                     "equal_cost_fine_samples": m, "fine_only_samples": used, "m_exceeds_data": m > pool,
                     "fine_only_cpu_hours": point_cost("fine_only", used, cost),
                     "multifidelity": {k: p[k] for k in ERRORS}, "scale_only": p["scale_only"],
                     "fine_only": None if base is None else {k: base[k] for k in ERRORS},
                     "reference_curve_at_m": None if curve is None else interpolate_curve(curve, m)})
    return rows


def figure(path: Path, doc: dict, curve: dict | None) -> None:
    """PNG: held-out mean anchor, tip and cap-rotation errors against CPU hours (log-log):
    multi-fidelity and fine-only curves, the coarse surrogate alone, the committed curve."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("heldout_mean_anchor_error_mm", "mean anchor error (mm)"),
              ("heldout_tip_error_mm", "mean tip error (mm)"),
              ("heldout_cap_rotation_error_deg", "mean cap-rotation error (deg)"))
    fine_s, pool = doc["fine"]["cpu_s_per_sample"], doc["fine"]["pool"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    for ax, (key, label) in zip(axes, panels):
        for kind, color, name in (("multifidelity", "tab:blue", "multi-fidelity (coarse set + n fine)"),
                                  ("fine_only", "tab:orange", "fine only (n fine)")):
            pts = sorted((p for p in doc["points"] if p["kind"] == kind and p[key] is not None),
                         key=lambda p: p["samples"])
            if pts:
                ax.loglog([p["cpu_hours"] for p in pts], [p[key] for p in pts], "o-", color=color, label=name)
                # the multi-fidelity points sit close together (the coarse cost dominates): label the ends
                for p in pts if kind == "fine_only" else pts[::max(1, len(pts) - 1)]:
                    ax.annotate(str(p["samples"]), (p["cpu_hours"], p[key]), fontsize=7,
                                textcoords="offset points", xytext=(3, 3), color=color)
        pts = sorted((p for p in doc["points"] if p["kind"] == "multifidelity" and p["scale_only"]),
                     key=lambda p: p["samples"])
        if pts:
            ax.loglog([p["cpu_hours"] for p in pts], [p["scale_only"][key] for p in pts], "^--", color="tab:blue",
                      alpha=0.5, mfc="none", label="multi-fidelity, scales alone (no network)")
        coarse = doc["coarse_only"]
        if coarse[key] is not None:
            ax.loglog([doc["coarse"]["cpu_hours"]], [coarse[key]], "s", color="tab:gray",
                      label="coarse surrogate alone")
        if curve is not None:
            pts = sorted((p for p in curve["points"] if p["jacobian_loss"] and p[key] is not None),
                         key=lambda p: (p["seed"], p["samples"]))
            seed = pts[0]["seed"] if pts else None
            pts = [p for p in pts if p["seed"] == seed]
            ax.loglog([p["samples"] * fine_s / 3600 for p in pts], [p[key] for p in pts], "--",
                      color="tab:green", alpha=0.8, label="committed fine-only curve (its own data), at c_f")
        ax.axvline(pool * fine_s / 3600, color="gray", ls=":", lw=1, label="fine pool exhausted")
        ax.set_xlabel("FEM CPU hours")
        ax.set_ylabel(f"held-out {label}")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Multi-fidelity against fine-only at equal FEM cost (held-out n = {doc['heldout']['n']}, "
                 f"c_f {fine_s:.1f} s, coarse set {doc['coarse']['cpu_hours']:.2f} CPU h)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def write(out: Path, plot: Path, header: dict, points: list[dict], jobs, curve) -> None:
    """OUT and its figure, atomically; ``complete`` when every planned point is in."""
    have = {(p["kind"], p["samples"]) for p in points}
    rows = comparison(points, header["fine"]["pool"], header["cost"], curve)
    doc = header | {"complete": all(job in have for job in jobs), "points": points, "comparison": rows}
    MULTIFIDELITY.write(out, doc)
    figure(plot, json_safe(doc), curve)


def row(r: dict) -> str:
    mf, fo, ref = r["multifidelity"], r["fine_only"], r["reference_curve_at_m"]
    text = (f"n {r['samples']:5d}: multi-fidelity {r['multifidelity_cpu_hours']:.2f} CPU h, mean anchor "
            f"{mf['heldout_mean_anchor_error_mm']:.4f} mm, tip {mf['heldout_tip_error_mm']:.4f} mm, cap "
            f"{_deg(mf['heldout_cap_rotation_error_deg'])}; equal cost m = {r['equal_cost_fine_samples']}")
    if fo is not None:
        text += (f"; fine-only {r['fine_only_samples']}{' (all there is)' if r['m_exceeds_data'] else ''}: "
                 f"{fo['heldout_mean_anchor_error_mm']:.4f} mm, tip {fo['heldout_tip_error_mm']:.4f} mm, "
                 f"cap {_deg(fo['heldout_cap_rotation_error_deg'])}")
    if ref is not None:
        text += f"; committed curve at m: {ref['heldout_mean_anchor_error_mm']:.4f} mm"
    return text


def _deg(v) -> str:
    return "n/a" if v is None else f"{v:.3f} deg"


def _override(text: str) -> str:
    try:
        parse_override(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m surrogate.multifidelity", description=__doc__.split("\n\n")[0])
    ap.add_argument("--coarse", required=True, help="coarse campaign dataset (the coarse surrogate's)")
    ap.add_argument("--fine", required=True, help="fine campaign dataset (training subsets, validation)")
    ap.add_argument("--heldout", help="fine held-out dataset (default: split off --fine, 4:1:3 by walk blocks)")
    ap.add_argument("--coarse-model", help="coarse surrogate checkpoint trained on --coarse "
                                           "(default: train the improved config, saved as OUT_coarse.pt)")
    ap.add_argument("--sizes", type=sizes_arg, default=SIZES, help="comma-separated fine subset sizes and/or all")
    ap.add_argument("--seed", type=cli.number(0, None, integer=True), default=0,
                    help="the subset draw and training seed")
    ap.add_argument("--min-steps", type=cli.number(1, None, integer=True), default=MIN_STEPS,
                    help="fewest Adam steps per run (surrogate.learning_curve's budget)")
    ap.add_argument("--set", type=_override, action="append", default=[], metavar="KEY=VALUE",
                    help="override a field of the correction network's config (default "
                         + " ".join(CORRECTION) + " on improved)")
    ap.add_argument("--reference-curve", help=f"committed fine-only learning curve (default {REFERENCE_CURVE}, "
                                              "skipped if absent)")
    ap.add_argument("--max-hours", type=cli.number(0, None, "h", open_lo=True), default=None,
                    help="start no run expected to end past it (exit 3 if unfinished)")
    ap.add_output("--out", suffix=".json", default="results/surrogate/h1.8/multifidelity.json")
    ap.add_output("--plot", suffix=".png", help="figure (default: OUT with .png)")
    return ap


def prepare(args) -> dict:
    """Everything checked and loaded before any training (ValueError / OSError on bad input)."""
    keys = [parse_override(p)[0] for p in args.set]
    if len(set(keys)) != len(keys):
        raise ValueError(f"--set {', '.join(args.set)}: give each key once")
    parts, manifests, split = load_sets(args.coarse, args.fine, args.heldout)
    pool = len(parts["train"])
    for s in args.sizes:
        if s != "all" and not 1 <= s <= pool:
            raise ValueError(f"subset size {s} is outside [1, {pool}] (the fine training pool has {pool} samples)")
    cost = {"coarse_h": manifests["coarse"].cpu_hours,
            "coarse_s": cpu_s_per_sample(manifests["coarse"], args.coarse),
            "fine_s": cpu_s_per_sample(manifests["fine"], args.fine)}
    jobs = plan(pool, args.sizes, lambda n: equal_cost_samples(n, cost["coarse_h"], cost["fine_s"]))
    cap = True
    if args.coarse_model:
        ckpt = load_checkpoint(args.coarse_model)
        check_coarse_model(ckpt, manifests["coarse"], args.coarse_model, args.coarse)
        cap = bool(ckpt["model_config"].get("cap_rotation"))
    joint = recorded_joint(manifests["fine"].config)
    configs = {(k, n): (correction_configs(n, args.seed, args.min_steps, args.set, cap, joint) if k == "multifidelity"
                        else fine_only_configs(n, args.seed, args.min_steps, joint)) for k, n in jobs}
    explicit = args.reference_curve is not None
    path = Path(args.reference_curve) if explicit else REFERENCE_CURVE
    curve = LEARNING_CURVE.load(path) if explicit or path.is_file() else None
    return {"parts": parts, "manifests": manifests, "split": split, "pool": pool, "cost": cost, "jobs": jobs,
            "configs": configs, "curve": curve, "curve_path": str(path) if curve else None,
            "coarse_sha": dataset_digest(args.coarse), "fine_sha": dataset_digest(args.fine),
            "heldout_sha": dataset_digest(args.heldout if split == "separate" else args.fine)}


def header(args, s: dict, model_path: Path, model_sha: str, trained_here: bool, coarse_only: dict) -> dict:
    m, cost, parts = s["manifests"], s["cost"], s["parts"]
    return {
        "description": "Multi-fidelity surrogate (frozen coarse surrogate + a correction trained on n fine samples) "
                       "against fine-only training at equal FEM cost (surrogate.multifidelity).",
        "coarse": {"root": args.coarse, "sha256": s["coarse_sha"], "samples": m["coarse"].n,
                   "cpu_hours": cost["coarse_h"], "cpu_s_per_sample": cost["coarse_s"],
                   "model": str(model_path), "model_sha256": model_sha, "model_trained_here": trained_here},
        "fine": {"root": args.fine, "sha256": s["fine_sha"], "samples": m["fine"].n,
                 "cpu_hours": m["fine"].cpu_hours, "cpu_s_per_sample": cost["fine_s"],
                 "pool": s["pool"], "val": len(parts["val"])},
        "heldout": {"root": args.heldout if s["split"] == "separate" else args.fine, "sha256": s["heldout_sha"],
                    "n": len(parts["heldout"]), "split": s["split"]},
        "cost": cost,
        "equal_cost": "m = round(n + N_c c_c / c_f); c = 3600 cpu_hours / samples of each manifest; "
                      "validation samples counted in neither",
        "correction_overrides": list(CORRECTION) + args.set, "min_steps": args.min_steps, "seed": args.seed,
        "coarse_only": {k: coarse_only[k[8:]] for k in ERRORS} | {"cpu_hours": cost["coarse_h"]},
        "reference_curve": s["curve_path"],
        "reference_note": "the committed learning curve is measured on its own train/held-out data; at m "
                          "samples it is a proxy of a fine-only surrogate's error, not a fine-data figure",
    }


def coarse_model(args, s: dict, out: Path) -> tuple[JointSurrogate | None, Path]:
    """(frozen coarse surrogate, its checkpoint): --coarse-model, or the one this tool
    trained before on the same coarse data; (None, path to train it to) otherwise."""
    if args.coarse_model:
        ckpt = load_checkpoint(args.coarse_model)
        return build_model(ckpt, args.coarse_model).eval().requires_grad_(False), Path(args.coarse_model)
    path = out.with_name(out.stem + "_coarse.pt")
    return cached_coarse(path, s["coarse_sha"], s["manifests"]["coarse"]), path


def main(argv=None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    out = Path(args.out)
    plot = Path(args.plot) if args.plot else out.with_suffix(".png")
    torch.set_num_threads(1)  # one core: it runs beside the FEM
    with ap.errors():
        try:
            s = prepare(args)
        except ShardError as exc:
            raise ValueError(str(exc)) from None
    budget = args.max_hours * 3600 if args.max_hours else math.inf
    with ap.errors():
        coarse, model_path = coarse_model(args, s, out)
    trained_here = coarse is None
    if trained_here:
        if time.perf_counter() - t_start > budget:
            say(f"stopped by --max-hours {args.max_hours:g} before the coarse surrogate: re-run to resume")
            return EXIT_STOPPED
        say(f"coarse surrogate: training the improved config on {args.coarse} -> {model_path}")
        with ap.errors():
            coarse = train_coarse(args.coarse, s["manifests"]["coarse"], model_path, s["coarse_sha"], progress)
    elif not args.coarse_model:
        say(f"coarse surrogate: reusing {model_path}")
    model_sha = sha256_file(model_path)
    ids = {"coarse_model_sha256": model_sha, "fine_sha256": s["fine_sha"], "heldout_sha256": s["heldout_sha"],
           "split": s["split"]}
    head = header(args, s, model_path, model_sha, trained_here, evaluate(coarse, s["parts"]["heldout"]))
    points = [p for p in load_points(out) if is_current(p, s["configs"], args.seed, args.min_steps, ids)]
    for p in points:  # costs follow the manifests
        p["cpu_hours"] = point_cost(p["kind"], p["samples"], s["cost"])
    done = {(p["kind"], p["samples"]) for p in points}
    todo = [job for job in s["jobs"] if job not in done]
    subsets = nested_subsets(s["pool"], sorted({n for _, n in s["jobs"]}), args.seed)
    say(f"multi-fidelity: {len(s['jobs']) - len(todo)} of {len(s['jobs'])} points done, {len(todo)} to train "
        f"(fine pool {s['pool']}, val {len(s['parts']['val'])}, held-out {len(s['parts']['heldout'])}, "
        f"{s['split']}; c_f {s['cost']['fine_s']:.1f} s, coarse set {s['cost']['coarse_h']:.2f} CPU h)")
    rate, stopped = {}, False
    for kind, n in todo:
        model_cfg, cfg = s["configs"][(kind, n)]
        steps = cfg.epochs * math.ceil(n / cfg.batch_size)
        per_step = rate.get(kind, max(rate.values(), default=0.0))
        if time.perf_counter() - t_start + steps * per_step > budget:
            stopped = True
            break
        say(f"  {kind} {n} fine samples: {cfg.epochs} epochs, {steps} steps")
        if kind == "multifidelity":
            figures = run_correction(coarse, s["parts"], subsets[n], model_cfg, cfg, progress)
        else:
            figures = run_point({k: s["parts"][k] for k in ("train", "val")}, s["parts"]["heldout"], subsets[n],
                                model_cfg, cfg, progress) | {"scale_only": None, "rho": None, "rho_theta": None}
        rate[kind] = figures["train_time_s"] / steps
        point = identity(kind, n, args.seed, args.min_steps, (model_cfg, cfg), ids) | figures \
            | {"cpu_hours": point_cost(kind, n, s["cost"])}
        points = sorted([p for p in points if (p["kind"], p["samples"]) != (kind, n)] + [point],
                        key=lambda p: (KINDS.index(p["kind"]), p["samples"]))
        with ap.errors():
            write(out, plot, head, points, s["jobs"], s["curve"])
        say(f"    held-out mean anchor {figures['heldout_mean_anchor_error_mm']:.4f} mm, tip "
            f"{figures['heldout_tip_error_mm']:.4f} mm, cap {_deg(figures['heldout_cap_rotation_error_deg'])}; "
            f"{figures['train_time_s']:.0f} s")
    if points and not rate:  # nothing trained: still refresh the file (stale points dropped)
        with ap.errors():
            write(out, plot, head, points, s["jobs"], s["curve"])
    rows = comparison(points, s["pool"], s["cost"], s["curve"])
    if args.json:
        cli.print_json({"out": str(out), "plot": str(plot), "stopped": stopped, "coarse_only": head["coarse_only"],
                        "comparison": rows, "points": points})
    else:
        c = head["coarse_only"]
        print(f"coarse surrogate alone: mean anchor {c['heldout_mean_anchor_error_mm']:.4f} mm, tip "
              f"{c['heldout_tip_error_mm']:.4f} mm, cap {_deg(c['heldout_cap_rotation_error_deg'])}")
        for r in rows:
            print(row(r))
    return exit_code(stopped, args.max_hours)


if __name__ == "__main__":
    sys.exit(main())
