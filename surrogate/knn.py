"""The paper's k-nearest-neighbour baseline (docs/decisions.md §0: k = 4 gave 1.04 mm).

Distances are Euclidean in the normalised inputs z = x / box, the joint's input box (the
paper's: contract.spec.INPUT_BOX), so the box is [-1, 1]^4.
The reference set is the training split plus its y-mirror images (the same augmentation
as the paper's network). The prediction for a query is the mean of the k neighbours'
anchors, uniform or weighted by 1 / distance; k in 1..16 and the weighting are chosen on
the validation split by mean anchor error.
"""

from __future__ import annotations

import time

import torch
from torch import nn

from contract.spec import INPUT_BOX
from surrogate.data import Samples, augment_mirror


class KNN(nn.Module):
    """Inputs (..., 4) [MPa, N, N, N·mm] -> anchors (..., n, 2) mm (the reference's anchor
    count n), from the k nearest samples in inputs scaled by ``box`` (P MPa, F1 N, F2 N,
    M N·mm half-widths)."""

    def __init__(self, reference: Samples, k: int, weighting: str = "uniform", box=INPUT_BOX):
        super().__init__()
        if weighting not in ("uniform", "distance"):
            raise ValueError(f"weighting {weighting!r} is not 'uniform' or 'distance'")
        self.k, self.weighting = k, weighting
        self.n_anchors = reference.n_anchors
        self.input_box = tuple(float(b) for b in box)
        self.register_buffer("scale", torch.as_tensor(self.input_box, dtype=torch.float64))
        self.register_buffer("z_ref", reference.inputs / self.scale)
        self.register_buffer("r_ref", reference.anchors.reshape(len(reference), -1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        batch = x.shape[:-1]
        z = x.reshape(-1, 4) / self.scale.to(x.dtype)
        z_ref, r_ref = self.z_ref.to(x.dtype), self.r_ref.to(x.dtype)
        d, idx = torch.cdist(z, z_ref).topk(self.k, dim=1, largest=False)
        if self.weighting == "uniform":
            w = torch.full_like(d, 1.0 / self.k)
        else:
            w = 1.0 / d.clamp_min(1e-12)
            w = w / w.sum(dim=1, keepdim=True)
        return (w[..., None] * r_ref[idx]).sum(dim=1).reshape(*batch, self.n_anchors, 2)


def choose_knn(train: Samples, val: Samples, ks=range(1, 17), box=INPUT_BOX) -> tuple[KNN, dict]:
    """The KNN (reference: mirror-augmented train; inputs scaled by the joint's ``box``) with
    the lowest validation mean anchor error.

    Returns (model, {"k", "weighting", "val_mean_anchor_error_mm", "paper_k4_val_mm",
    "fit_time_s"}).
    """
    t0 = time.perf_counter()
    reference = augment_mirror(train)
    scores = {}
    for weighting in ("uniform", "distance"):
        for k in ks:
            with torch.no_grad():
                pred = KNN(reference, k, weighting, box)(val.inputs)
            scores[(k, weighting)] = (pred - val.anchors).norm(dim=-1).mean().item()
    k, weighting = min(scores, key=scores.get)
    return KNN(reference, k, weighting, box), {
        "k": k, "weighting": weighting, "val_mean_anchor_error_mm": scores[(k, weighting)],
        "paper_k4_val_mm": scores.get((4, "uniform")), "fit_time_s": time.perf_counter() - t0}
