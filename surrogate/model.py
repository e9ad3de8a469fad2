"""The joint surrogate R = sur(P, F1, F2, M): a configurable MLP and its checkpoint.

    x = [P MPa, F1 N, F2 N, M N·mm]            (..., 4)
    z = x / INPUT_BOX   (+ |z_P| if abs_pressure) the training box is [-1, 1]^4
    h = act(W_0 z + b_0);  h <- act(W_l h + b_l)  or, with residual and equal widths,
        h <- h + act(W_l h + b_l)
    g(x) = output_mean + output_scale * (W_out h + b_out)         (20,) mm
    R = g(x)                                                        (paper)
    R = (g(x) + S g(B x)) / 2                                       (symmetric)

    equivariant (one pass, exactly symmetric):
    o = (z_P, z_F2, z_M) (odd under B), q = (z_F1, o_i o_j for i <= j [, |z_P|]) (invariant)
    h = MLP(q);  [a, c] = W_out h + b_out,  a (10,), c (3, 10)
    x_k = mean_k + scale_k a_k          (even anchor coordinates)
    y_k = scale_k sum_j o_j c_jk        (odd: every odd function is sum_j o_j c_j(invariants))

with the y-mirror of DESIGN.md §3: B = diag(-1, 1, -1, -1) on the inputs and S = diag(1, -1)
on each anchor. The symmetric form satisfies R(Bx) = S R(x) by construction, for any
weights: g(BBx) = g(x), and a sign flip, a sum and a halving are exact in floating point,
so the identity holds to the last bit when x and Bx are evaluated in the same layout.
The equivariant form needs one pass instead of two (half the cost): q is bitwise invariant
(o_i o_j = (-o_i)(-o_j)) and negating o negates each y_k exactly.

|P| as a feature: P > 0 inflates one chamber and P < 0 the other, so the FEM response has a
kink at P = 0 (the axial elongation grows like |P|). |P| is mirror-invariant, so the
symmetry is kept.

A checkpoint is an integrity-checked file of kind ``softjoint-surrogate/2``
(surrogate.checkpoint: a header line with the archive's length and sha256, then a
weights_only torch archive), whose payload holds model_config, normalisation,
model_state (float64), train_config, metrics and dataset. Loading needs only the file;
a file with any flipped, missing or added byte, a foreign file or another kind of
checkpoint is refused with one line (ModelError).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import nn

from fem.spec import ANCHOR_MIRROR, INPUT_MIRROR, N_ANCHORS, N_INPUTS
from surrogate import checkpoint
from surrogate.checkpoint import CheckpointError

FORMAT = "softjoint-surrogate/2"
WHAT = "surrogate checkpoint"


def _relu(a, slope: bool):
    return torch.relu(a), (a > 0).to(a.dtype) if slope else None


def _tanh(a, slope: bool):
    t = torch.tanh(a)
    return t, 1 - t * t if slope else None


def _silu(a, slope: bool):
    if not slope:
        return nn.functional.silu(a), None
    s = torch.sigmoid(a)
    return a * s, s * (1 + a * (1 - s))


def _softplus(a, slope: bool):
    return nn.functional.softplus(a), torch.sigmoid(a) if slope else None


#: activation name -> (a, slope) -> (act(a), act'(a) if slope else None); the derivative
#: feeds the forward-mode Jacobian.
ACTIVATIONS = {"relu": _relu, "tanh": _tanh, "silu": _silu, "softplus": _softplus}


def wrap(angle: torch.Tensor) -> torch.Tensor:
    """Angles (rad) wrapped to [-pi, pi)."""
    return torch.remainder(angle + math.pi, 2 * math.pi) - math.pi


class ModelError(CheckpointError):
    """A surrogate checkpoint is missing, damaged, foreign, of another kind or
    inconsistent (one-line message)."""


@dataclass(frozen=True)
class ModelConfig:
    hidden: tuple[int, ...] = (96, 192, 96)
    activation: str = "relu"
    residual: bool = False       # h + act(W h + b) between hidden layers of equal width
    symmetric: bool = False      # R = (g(x) + S g(Bx)) / 2
    abs_pressure: bool = False   # feed |P| / 0.3 as an extra input
    equivariant: bool = False    # one-pass symmetric form on mirror invariants (docstring)

    def __post_init__(self):
        object.__setattr__(self, "hidden", tuple(int(w) for w in self.hidden))
        if self.symmetric and self.equivariant:
            raise ValueError("symmetric and equivariant are two ways to the same symmetry: "
                             "choose one")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation {self.activation!r} not in {sorted(ACTIVATIONS)}")
        if not self.hidden:
            raise ValueError("the MLP needs at least one hidden layer")


class JointSurrogate(nn.Module):
    """Inputs (..., 4) [P MPa, F1 N, F2 N, M N·mm] -> anchors (..., 10, 2) mm, joint frame."""

    def __init__(self, config: ModelConfig, normalisation: dict):
        super().__init__()
        self.config = config
        self.normalisation = {k: [float(v) for v in normalisation[k]]
                              for k in ("input_scale", "output_mean", "output_scale")}
        for name, value in self.normalisation.items():
            self.register_buffer(name, torch.tensor(value), persistent=False)
        self.register_buffer("input_mirror", torch.tensor(INPUT_MIRROR), persistent=False)
        self.register_buffer("output_mirror", torch.tensor(ANCHOR_MIRROR).repeat(N_ANCHORS),
                             persistent=False)
        odd = [i for i, b in enumerate(INPUT_MIRROR) if b < 0]
        self.register_buffer("odd_inputs", torch.tensor(odd), persistent=False)
        self.register_buffer("even_inputs", torch.tensor([i for i, b in enumerate(INPUT_MIRROR)
                                                          if b > 0]), persistent=False)
        pairs = torch.triu_indices(len(odd), len(odd))
        self.register_buffer("pairs", pairs, persistent=False)
        n_in = N_INPUTS - len(odd) + pairs.shape[1] if config.equivariant else N_INPUTS
        widths = (n_in + config.abs_pressure,) + config.hidden
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(widths[:-1], widths[1:]))
        n_out = N_ANCHORS * (1 + len(odd)) if config.equivariant else 2 * N_ANCHORS
        self.head = nn.Linear(widths[-1], n_out)
        self.act = ACTIVATIONS[config.activation]

    def g(self, x: torch.Tensor, dx: torch.Tensor | None = None):
        """The plain network on inputs x (n, 4) in physical units -> anchors (n, 20) mm.

        With input tangents dx (n, 4, 4) (row t: d x / d input_t), also returns the output
        tangents (n, 4, 20), propagated layer by layer (forward-mode AD): for
        h' = act(W h + b), dh' = act'(W h + b) * (dh W^T). They stay differentiable in the
        weights, which the Sobolev loss needs.
        """
        z = x / self.input_scale
        dz = None if dx is None else dx / self.input_scale
        if self.config.equivariant:
            o, q, dq = self._invariants(z, dz)
        else:
            q, dq = z, dz
        if self.config.abs_pressure:
            q = torch.cat([q, z[:, :1].abs()], dim=1)
            if dz is not None:
                dq = torch.cat([dq, dz[:, :, :1] * torch.sign(z[:, None, :1])], dim=2)
        h, dh = q, dq
        for i, layer in enumerate(self.layers):
            a, da = self.act(layer(h), dz is not None)
            residual = self.config.residual and i > 0 and a.shape == h.shape
            h = h + a if residual else a
            if dz is not None:
                da = da[:, None, :] * (dh @ layer.weight.T)
                dh = dh + da if residual else da
        if self.config.equivariant:
            return self._equivariant_head(o, h, None if dx is None else dz, dh)
        y = self.output_mean + self.output_scale * self.head(h)
        if dx is None:
            return y
        return y, (dh @ self.head.weight.T) * self.output_scale

    def _invariants(self, z, dz):
        """Odd inputs o (n, 3) and mirror invariants q = (z_F1, o_i o_j for i <= j) (n, 7),
        with the tangent dq (n, 4, 7) of q when dz (n, 4, 4) is given."""
        o = z[:, self.odd_inputs]
        i, j = self.pairs
        q = torch.cat([z[:, self.even_inputs], o[:, i] * o[:, j]], dim=1)
        if dz is None:
            return o, q, None
        do = dz[:, :, self.odd_inputs]
        dq = torch.cat([dz[:, :, self.even_inputs], do[:, :, i] * o[:, None, j] + o[:, None, i] * do[:, :, j]],
                       dim=2)
        return o, q, dq

    def _equivariant_head(self, o, h, dz, dh):
        """Anchors (n, 20) mm from the trunk output h (n, w): even coordinates from a,
        odd ones as sum_j o_j c_j (module docstring); with tangents (n, 4, 20) if dz.
        The anchors interleave (x_k, y_k), so a stack, not a masked scatter, assembles
        them (~10 % faster batched at width 64)."""
        n, k = h.shape[0], N_ANCHORS
        out = self.head(h)
        c = out[:, k:].reshape(n, -1, k)
        y = torch.stack([out[:, :k], (o[:, :, None] * c).sum(1)], dim=-1).reshape(n, 2 * k)
        y = self.output_mean * (self.output_mirror > 0) + self.output_scale * y
        if dz is None:
            return y
        dout = dh @ self.head.weight.T                                       # (n, 4, 40)
        dc = dout[:, :, k:].reshape(n, -1, o.shape[1], k)
        do = dz[:, :, self.odd_inputs]
        dodd = (do[:, :, :, None] * c[:, None] + o[:, None, :, None] * dc).sum(2)
        dy = torch.stack([dout[:, :, :k], dodd], dim=-1).reshape(n, dz.shape[1], 2 * k)
        return y, dy * self.output_scale

    def flat(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs (n, 4) -> anchors (n, 20) mm, symmetrised if the config says so."""
        if not self.config.symmetric:
            return self.g(x)
        n = x.shape[0]
        y = self.g(torch.cat([x, x * self.input_mirror]))
        return 0.5 * (y[:n] + y[n:] * self.output_mirror)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs (..., 4) -> anchors (..., 10, 2) mm."""
        batch = x.shape[:-1]
        return self.flat(x.reshape(-1, N_INPUTS)).reshape(*batch, N_ANCHORS, 2)

    def with_jacobian(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Inputs (n, 4) -> (anchors (n, 10, 2) mm, d anchors.reshape(20) / d inputs (n, 20, 4)).

        Symmetric form: J(x) = (J_g(x) + S J_g(Bx) B) / 2, from the tangents of g at x
        (seeded with I) and at Bx (seeded with B, since d(Bx)/dx = B).
        """
        n = x.shape[0]
        eye = torch.eye(N_INPUTS, dtype=x.dtype).expand(n, N_INPUTS, N_INPUTS)
        if not self.config.symmetric:
            y, dy = self.g(x, eye)
        else:
            y, dy = self.g(torch.cat([x, x * self.input_mirror]),
                           torch.cat([eye, eye * self.input_mirror]))
            y = 0.5 * (y[:n] + y[n:] * self.output_mirror)
            dy = 0.5 * (dy[:n] + dy[n:] * self.output_mirror)
        return y.reshape(n, N_ANCHORS, 2), dy.transpose(1, 2)


def save_checkpoint(path: str | Path, model: JointSurrogate, train_config: dict,
                    metrics: dict, dataset: dict) -> None:
    """Write a self-contained checkpoint of kind FORMAT, atomically (surrogate.checkpoint)."""
    checkpoint.save(path, FORMAT, {
        "model_config": asdict(model.config),
        "normalisation": model.normalisation,
        "model_state": {k: v.detach().to(torch.float64).clone()
                        for k, v in model.state_dict().items()},
        "train_config": train_config,
        "metrics": metrics,
        "dataset": dataset,
    })


def _one_line(exc: BaseException) -> str:
    """First sentence of an exception, on one line."""
    return " ".join(f"{type(exc).__name__}: {str(exc).split('. ')[0]}".split())[:200]


def load_checkpoint(path: str | Path) -> dict:
    """The payload dict of checkpoint ``path`` (module docstring); raises ModelError."""
    try:
        ckpt = checkpoint.load(path, FORMAT, WHAT)
    except CheckpointError as exc:
        raise ModelError(str(exc)) from None
    missing = [k for k in ("model_config", "normalisation", "model_state", "train_config",
                           "metrics", "dataset") if k not in ckpt]
    if missing:
        raise ModelError(f"{path}: {WHAT} lacks {missing}")
    return ckpt


def build_model(ckpt: dict, where: str = "checkpoint") -> JointSurrogate:
    """The float64 JointSurrogate described by a checkpoint dict; raises ModelError."""
    try:
        config = ModelConfig(**ckpt["model_config"])
        model = JointSurrogate(config, ckpt["normalisation"]).to(torch.float64)
        model.load_state_dict(ckpt["model_state"])
    except Exception as exc:
        raise ModelError(f"{where}: inconsistent surrogate checkpoint ({_one_line(exc)})") from None
    values = list(model.parameters()) + list(model.buffers())
    if not all(torch.isfinite(v).all() for v in values):
        raise ModelError(f"{where}: surrogate checkpoint holds non-finite weights")
    return model


def load_surrogate(path: str | Path) -> JointSurrogate:
    """Load a checkpoint as a frozen float64 module in eval mode.

    The module maps inputs (..., 4) [P MPa, F1 N, F2 N, M N·mm] to anchors (..., 10, 2) mm
    in the joint frame; it is batched and differentiable in its inputs (the weights do not
    require grad). Raises ModelError with a one-line message if the file is missing or bad.
    """
    model = build_model(load_checkpoint(path), str(path))
    model.eval().requires_grad_(False)
    return model
