"""Dataset preparation for the surrogate: load, split 7:2:1, mirror-augment, normalise.

Data flow::

    DIR/manifest.json + shards  --workflow.shards.load_dataset-->  arrays (sha256 and
    checksums verified, shard configs checked against the manifest)
        --split_of(sample_id, manifest seed)-->  train / val / test    (7:2:1)
        --mirror (train only, paper config)-->  train ∪ mirror(train)
        --normalisation(train)-->  input_scale, output_mean, output_scale

A sample's split is dealt by its walk block (id // 16: consecutive ids are neighbours on
one continuation walk, and must not straddle train and validation), 7:2:1 exactly in each
group of 10 blocks, from the dataset seed, so it never changes when the campaign adds
shards.

Units: inputs [P MPa, F1 N, F2 N, M N·mm], anchors (n, k, 2) mm (k the joint's anchor
count, workflow.shards.anchor_count), Jacobian d anchors.reshape(2k) / d inputs (NaN rows
where the campaign stored none), cap_rotation rad (the distal cap's own rotation, measured
on the cap by the FEM; docs/physics.md).

Mirror (docs/physics.md, y -> -y): (x, R, J, cap) -> (B x, R S, S J B, -cap); the cap
rotation is odd, like phi_end.

Normalisation (stored inside the model): z = x / box, the joint's input box (the paper's:
contract.spec.INPUT_BOX), so the training box is [-1, 1]^4; anchors = output_mean +
output_scale * network(z), with the per-coordinate
mean and standard deviation of the (mirror-augmented) training anchors. A model with a
cap-rotation head also stores cap_scale (rad): the root mean square of its target, the
cap rotation itself or its offset wrap(cap_rotation - phi_end(R)) (surrogate.model); the
mean of an odd quantity over mirror-augmented data is 0, so the RMS is its std.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from contract.spec import INPUT_BOX, mirror, phi_end
from surrogate.model import wrap
from workflow.shards import Manifest, ShardError, load_dataset, split_of

SPLITS = ("train", "val", "test")


@dataclass
class Samples:
    """A set of samples as float64 tensors.

    inputs (n, 4) [MPa, N, N, N·mm]; anchors (n, k, 2) mm (k the joint's anchor count);
    jacobian (n, 2k, 4), NaN where absent; sample_id (n,) int64; cap_rotation (n,) rad.
    """

    inputs: torch.Tensor
    anchors: torch.Tensor
    jacobian: torch.Tensor
    sample_id: torch.Tensor
    cap_rotation: torch.Tensor

    def __len__(self) -> int:
        return len(self.inputs)

    @property
    def n_anchors(self) -> int:
        """The anchor count k of the samples (their joint's)."""
        return self.anchors.shape[1]

    def subset(self, index) -> "Samples":
        return Samples(self.inputs[index], self.anchors[index], self.jacobian[index],
                       self.sample_id[index], self.cap_rotation[index])

    @property
    def has_jacobian(self) -> torch.Tensor:
        """(n,) bool: the sample carries a finite FEM Jacobian."""
        return torch.isfinite(self.jacobian).all(dim=(1, 2))


def load_samples(root: str | Path) -> tuple[Samples, Manifest]:
    """All samples of dataset ``root`` and its manifest (validated on load). Raises
    ShardError if unusable."""
    arrays, manifest = load_dataset(root)
    if len(arrays["sample_id"]) == 0:
        raise ShardError(f"{root}: the dataset holds no samples")
    if not all(np.isfinite(arrays[k]).all() for k in ("inputs", "anchors", "cap_rotation")):
        raise ShardError(f"{root}: non-finite inputs, anchors or cap rotations in the dataset")
    samples = Samples(*(torch.as_tensor(arrays[k]) for k in
                        ("inputs", "anchors", "jacobian", "sample_id", "cap_rotation")))
    return samples, manifest


def split(samples: Samples, seed: int) -> dict[str, Samples]:
    """Split 7:2:1 into train / val / test by the dataset seed, in blocks of 16 consecutive
    walk samples (workflow.shards.split_of)."""
    label = torch.as_tensor(split_of(samples.sample_id.numpy(), seed))
    return {name: samples.subset(label == i) for i, name in enumerate(SPLITS)}


def load_splits(root: str | Path) -> tuple[dict[str, Samples], Manifest]:
    """Load dataset ``root`` and split it; returns ({train, val, test}, manifest)."""
    samples, manifest = load_samples(root)
    parts = split(samples, manifest.seed)
    for name, part in parts.items():
        if len(part) == 0:
            raise ShardError(f"{root}: the {name} split is empty ({len(samples)} samples)")
    return parts, manifest


def augment_mirror(samples: Samples) -> Samples:
    """samples ∪ their y-mirror images (docs/physics.md, cap_rotation -> -cap_rotation); the
    mirror copies keep their ids."""
    x, r, j = mirror(samples.inputs, samples.anchors, samples.jacobian)
    return Samples(torch.cat([samples.inputs, x]), torch.cat([samples.anchors, r]),
                   torch.cat([samples.jacobian, j]), torch.cat([samples.sample_id, samples.sample_id]),
                   torch.cat([samples.cap_rotation, -samples.cap_rotation]))


def cap_offset(samples: Samples) -> torch.Tensor:
    """(n,) rad: wrap(cap_rotation - phi_end(anchors)), the error of the tangent connection."""
    return wrap(samples.cap_rotation - phi_end(samples.anchors))


def normalisation(train: Samples, cap_target: str | None = None, box=INPUT_BOX) -> dict[str, list[float]]:
    """Normalisation constants from the training samples (mirror-augmented inside).

    Returns input_scale (4,) = ``box`` (the joint's input box half-widths, P MPa, F1 N,
    F2 N, M N·mm; default the paper's), output_mean (2k,) mm, output_scale (2k,) mm; the
    y means are zero because the statistics include the mirror images. With cap_target
    "absolute" or "offset" (a model with a cap-rotation head) also cap_scale (1,) rad, the
    RMS of cap_rotation or of cap_offset (module docstring).
    """
    augmented = augment_mirror(train)
    anchors = augmented.anchors.reshape(len(augmented), -1)
    out = {"input_scale": [float(b) for b in box],
           "output_mean": anchors.mean(0).tolist(),
           "output_scale": anchors.std(0).clamp_min(1e-6).tolist()}
    if cap_target is not None:
        target = {"absolute": augmented.cap_rotation, "offset": cap_offset(augmented)}[cap_target]
        out["cap_scale"] = [target.square().mean().sqrt().clamp_min(1e-6).item()]
    return out

