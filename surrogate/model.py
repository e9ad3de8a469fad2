"""The joint surrogate R = sur(P, F1, F2, M): a configurable MLP and its checkpoint.

    x = [P MPa, F1 N, F2 N, M N·mm]            (..., 4)
    z = x / box         (+ |z_P| if abs_pressure) the training box is [-1, 1]^4
    h = act(W_0 z + b_0);  h <- act(W_l h + b_l)  or, with residual and equal widths,
        h <- h + act(W_l h + b_l)
    g(x) = output_mean + output_scale * (W_out h + b_out)         (2k,) mm
    R = g(x)                                                        (paper)
    R = (g(x) + S g(B x)) / 2                                       (symmetric)

    equivariant (one pass, exactly symmetric):
    o = (z_P, z_F2, z_M) (odd under B), q = (z_F1, o_i o_j for i <= j [, |z_P|]) (invariant)
    h = MLP(q);  [a, c] = W_out h + b_out,  a (k,), c (3, k)
    x_k = mean_k + scale_k a_k          (even anchor coordinates)
    y_k = scale_k sum_j o_j c_jk        (odd: every odd function is sum_j o_j c_j(invariants))

Cap-rotation head (optional, ModelConfig.cap_rotation): the distal cap's own rotation theta
(rad), from the same trunk output h in the same pass, as a second linear head:

    equivariant:  c = cap_scale sum_j o_j d_j(h)      (odd, like y_k; d = W_cap h + b_cap (3,))
    plain:        c = cap_scale d(h)                  (d (1,))
    symmetric:    c = (c(x) - c(Bx)) / 2              (odd by construction)
    theta = c                          cap_target "absolute" (the improved config's)
    theta = phi_end(R) + c             cap_target "offset": c learns wrap(theta - phi_end),
                                       the tangent connection's error (~2 deg, docs/physics.md),
                                       but theta inherits the error of phi_end(R)

so theta(Bx) = -theta(x) bit for bit for the equivariant and symmetric forms (phi_end is odd
in y exactly: atan2(-a, b) = -atan2(a, b) and (-a) - (-b) = -(a - b) in floating point).
cap_scale (rad) is the RMS of the target over the mirror-augmented training set
(surrogate.data.normalisation).

with the y-mirror of docs/physics.md: B = diag(-1, 1, -1, -1) on the inputs and S = diag(1, -1)
on each anchor. The symmetric form satisfies R(Bx) = S R(x) by construction, for any
weights: g(BBx) = g(x), and a sign flip, a sum and a halving are exact in floating point,
so the identity holds to the last bit when x and Bx are evaluated in the same layout.
The equivariant form needs one pass instead of two (half the cost): q is bitwise invariant
(o_i o_j = (-o_i)(-o_j)) and negating o negates each y_k exactly.

The joint (ModelConfig.n_anchors, ModelConfig.input_box): k anchors r_1..r_k (mm, the
joint's ``[anchors] count``) and the box half-widths (P MPa, F1 N, F2 N, M N·mm, the
joint's ``[input_box]``) that scale the inputs (normalisation ``input_scale`` holds the same
numbers). ModelConfig.for_joint sets both from a contract.joint.JointSpec; their defaults
are the paper's joint (10 anchors, contract.spec.INPUT_BOX), and config_record leaves them
out of a record when they are the paper's, so a paper model writes the same model_config as
before they existed, and a checkpoint without them loads as the paper's joint.

|P| as a feature: P > 0 inflates one chamber and P < 0 the other, so the FEM response has a
kink at P = 0 (the axial elongation grows like |P|). |P| is mirror-invariant, so the
symmetry is kept.

A checkpoint is an integrity-checked file of kind ``softjoint-surrogate/2``
(surrogate.checkpoint: a header line with the archive's length and sha256, then a
weights_only torch archive), whose payload holds model_config, normalisation,
model_state (float64), train_config, metrics, dataset and joint: the joint description it
was trained on ({"sha256": contract.joint.joint_digest, "description":
contract.joint.joint_to_dict}; a checkpoint written before joint files existed has none and
is the paper's joint, contract/joints/paper.toml). The loaded module carries it as
``module.joint`` (a contract.joint.JointSpec), whose anchor count and input box must be the
model config's (ModelError otherwise). Loading needs only the file;
a file with any flipped, missing or added byte, a foreign file or another kind of
checkpoint is refused with one line (ModelError). A checkpoint written before the cap head
existed has no cap_rotation in its model_config: it loads as a model without the head
(has_cap_rotation False), with the same state keys and the same anchors bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import torch
from torch import nn

from contract.joint import JointSpec, joint_digest, joint_from_dict, joint_to_dict, load_joint
from contract.spec import ANCHOR_MIRROR, INPUT_BOX, INPUT_MIRROR, N_ANCHORS, N_INPUTS, phi_end
from surrogate import checkpoint
from surrogate.checkpoint import CheckpointError

FORMAT = "softjoint-surrogate/2"
WHAT = "surrogate checkpoint"
#: what a cap-rotation head learns (module docstring)
CAP_TARGETS = ("absolute", "offset")


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
    cap_rotation: bool = False   # a head for the distal cap's rotation (docstring)
    cap_target: str = "absolute" # what that head learns: one of CAP_TARGETS
    n_anchors: int = N_ANCHORS   # the joint's anchor count k (docstring)
    input_box: tuple[float, ...] = tuple(float(b) for b in INPUT_BOX)  # (P MPa, F1 N, F2 N, M N·mm)

    def __post_init__(self):
        object.__setattr__(self, "hidden", tuple(int(w) for w in self.hidden))
        object.__setattr__(self, "input_box", tuple(float(b) for b in self.input_box))
        if isinstance(self.n_anchors, bool) or not isinstance(self.n_anchors, int) or self.n_anchors < 2:
            raise ValueError(f"n_anchors {self.n_anchors!r} is not a whole number >= 2")
        if len(self.input_box) != N_INPUTS or not all(math.isfinite(b) and b > 0 for b in self.input_box):
            raise ValueError(f"input_box {self.input_box!r} is not {N_INPUTS} positive half-widths")
        if self.symmetric and self.equivariant:
            raise ValueError("symmetric and equivariant are two ways to the same symmetry: "
                             "choose one")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation {self.activation!r} not in {sorted(ACTIVATIONS)}")
        if self.cap_target not in CAP_TARGETS:
            raise ValueError(f"cap_target {self.cap_target!r} not in {list(CAP_TARGETS)}")
        if not self.hidden:
            raise ValueError("the MLP needs at least one hidden layer")

    def for_joint(self, joint) -> "ModelConfig":
        """This config for ``joint`` (a contract.joint.JointSpec): its anchor count and input box."""
        return replace(self, n_anchors=joint.anchors, input_box=tuple(float(b) for b in joint.input_box))


#: ModelConfig fields that describe the joint, not the network (docstring).
JOINT_FIELDS = ("n_anchors", "input_box")
_PAPER_JOINT = {f.name: f.default for f in fields(ModelConfig) if f.name in JOINT_FIELDS}


def config_record(config: ModelConfig) -> dict:
    """The config as a plain dict (a checkpoint's model_config, the records of sweeps and
    learning curves), without the joint fields where they are the paper's (docstring)."""
    return {k: v for k, v in asdict(config).items() if k not in _PAPER_JOINT or v != _PAPER_JOINT[k]}


class JointSurrogate(nn.Module):
    """Inputs (..., 4) [P MPa, F1 N, F2 N, M N·mm] -> anchors (..., k, 2) mm, joint frame
    (k = config.n_anchors); with a cap-rotation head, ``with_cap`` also gives the distal
    cap's rotation (...) rad. ValueError (one line) for a normalisation of another size or
    input box than the config's."""

    def __init__(self, config: ModelConfig, normalisation: dict):
        super().__init__()
        self.config = config
        keys = ("input_scale", "output_mean", "output_scale") + ("cap_scale",) * config.cap_rotation
        self.normalisation = {k: [float(v) for v in normalisation[k]] for k in keys}
        _check_normalisation(config, self.normalisation)
        k = config.n_anchors
        for name, value in self.normalisation.items():
            self.register_buffer(name, torch.tensor(value), persistent=False)
        self.register_buffer("input_mirror", torch.tensor(INPUT_MIRROR), persistent=False)
        self.register_buffer("output_mirror", torch.tensor(ANCHOR_MIRROR).repeat(k), persistent=False)
        odd = [i for i, b in enumerate(INPUT_MIRROR) if b < 0]
        self.register_buffer("odd_inputs", torch.tensor(odd), persistent=False)
        self.register_buffer("even_inputs", torch.tensor([i for i, b in enumerate(INPUT_MIRROR)
                                                          if b > 0]), persistent=False)
        pairs = torch.triu_indices(len(odd), len(odd))
        self.register_buffer("pairs", pairs, persistent=False)
        n_in = N_INPUTS - len(odd) + pairs.shape[1] if config.equivariant else N_INPUTS
        widths = (n_in + config.abs_pressure,) + config.hidden
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(widths[:-1], widths[1:]))
        n_out = k * (1 + len(odd)) if config.equivariant else 2 * k
        self.head = nn.Linear(widths[-1], n_out)
        if config.cap_rotation:  # built after the anchor head: the same seed draws the same trunk
            self.cap_head = nn.Linear(widths[-1], len(odd) if config.equivariant else 1)
        self.act = ACTIVATIONS[config.activation]

    @property
    def has_cap_rotation(self) -> bool:
        """The model predicts the distal cap's rotation (``with_cap``)."""
        return self.config.cap_rotation

    @property
    def n_anchors(self) -> int:
        """The joint's anchor count k: the model gives anchors (..., k, 2)."""
        return self.config.n_anchors

    @property
    def input_box(self) -> tuple[float, ...]:
        """The joint's input box half-widths (P MPa, F1 N, F2 N, M N·mm)."""
        return self.config.input_box

    def g(self, x: torch.Tensor, dx: torch.Tensor | None = None, cap: bool = False):
        """The plain network on inputs x (n, 4) in physical units -> (anchors (n, 2k) mm,
        tangents (n, 4, 2k) or None, raw cap output c (n,) rad or None).

        With input tangents dx (n, 4, 4) (row t: d x / d input_t), the output tangents are
        propagated layer by layer (forward-mode AD): for h' = act(W h + b),
        dh' = act'(W h + b) * (dh W^T). They stay differentiable in the weights, which the
        Sobolev loss needs. With cap, c is the cap head's output (module docstring), from
        the same trunk pass.
        """
        o, h, dz, dh = self._trunk(x, dx)
        c = self._cap_head(o, h) if cap else None
        if self.config.equivariant:
            y, dy = self._equivariant_head(o, h, dz, dh)
        else:
            y = self.output_mean + self.output_scale * self.head(h)
            dy = None if dz is None else (dh @ self.head.weight.T) * self.output_scale
        return y, dy, c

    def _trunk(self, x, dx):
        """Hidden layers: x (n, 4) physical units [, dx (n, 4, 4)] -> (odd inputs o (n, 3) or
        None, trunk output h (n, w), dz (n, 4, 4) or None, dh (n, 4, w) or None)."""
        z = x / self.input_scale
        dz = None if dx is None else dx / self.input_scale
        if self.config.equivariant:
            o, q, dq = self._invariants(z, dz)
        else:
            o, q, dq = None, z, dz
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
        return o, h, dz, dh

    def _cap_head(self, o, h):
        """Raw cap output c (n,) rad from the trunk output h (n, w): cap_scale sum_j o_j d_j
        (equivariant, odd in o) or cap_scale d (module docstring)."""
        d = self.cap_head(h)
        d = (o * d).sum(1) if self.config.equivariant else d[:, 0]
        return self.cap_scale * d

    def _invariants(self, z, dz):
        """Odd inputs o (n, 3) and mirror invariants q = (z_F1, o_i o_j for i <= j) (n, 7),
        with the tangent dq (n, 4, 7) of q when dz (n, 4, 4) is given."""
        o = z.index_select(1, self.odd_inputs)   # index_select: cheaper dispatch than z[:, idx]
        i, j = self.pairs
        q = torch.cat([z.index_select(1, self.even_inputs), o.index_select(1, i) * o.index_select(1, j)], dim=1)
        if dz is None:
            return o, q, None
        do = dz[:, :, self.odd_inputs]
        dq = torch.cat([dz[:, :, self.even_inputs], do[:, :, i] * o[:, None, j] + o[:, None, i] * do[:, :, j]],
                       dim=2)
        return o, q, dq

    def _equivariant_head(self, o, h, dz, dh):
        """(anchors (n, 2k) mm, tangents (n, 4, 2k) if dz else None) from the trunk output
        h (n, w): even coordinates from a, odd ones as sum_j o_j c_j (module docstring).
        The anchors interleave (x_k, y_k), so a stack, not a masked scatter, assembles
        them (~10 % faster batched at width 64)."""
        n, k = h.shape[0], self.config.n_anchors
        out = self.head(h)
        c = out[:, k:].reshape(n, -1, k)
        y = torch.stack([out[:, :k], (o[:, :, None] * c).sum(1)], dim=-1).reshape(n, 2 * k)
        y = self.output_mean * (self.output_mirror > 0) + self.output_scale * y
        if dz is None:
            return y, None
        dout = dh @ self.head.weight.T                                       # (n, 4, 4k)
        dc = dout[:, :, k:].reshape(n, -1, o.shape[1], k)
        do = dz[:, :, self.odd_inputs]
        dodd = (do[:, :, :, None] * c[:, None] + o[:, None, :, None] * dc).sum(2)
        dy = torch.stack([dout[:, :, :k], dodd], dim=-1).reshape(n, dz.shape[1], 2 * k)
        return y, dy * self.output_scale

    def outputs(self, x: torch.Tensor, jacobian: bool = False, cap: bool = False):
        """One pass: inputs (n, 4) -> (anchors (n, k, 2) mm, d anchors.reshape(2k) / d inputs
        (n, 2k, 4) if jacobian else None, cap rotation (n,) rad if cap else None).

        Symmetric form: R = (g(x) + S g(Bx)) / 2, c = (c(x) - c(Bx)) / 2 and
        J(x) = (J_g(x) + S J_g(Bx) B) / 2, from the tangents of g at x (seeded with I) and
        at Bx (seeded with B, since d(Bx)/dx = B). The "offset" cap target adds phi_end of
        the final anchors. The anchors do not depend on jacobian or cap: the same inputs
        give the same bits whichever outputs are asked for (the tangent pass aside, whose
        activations also return their slopes).
        """
        if cap and not self.has_cap_rotation:
            raise ModelError("this surrogate has no cap-rotation head (trained without "
                             "cap_rotation): its cap rotation is only phi_end(anchors)")
        n = x.shape[0]
        eye = torch.eye(N_INPUTS, dtype=x.dtype).expand(n, N_INPUTS, N_INPUTS) if jacobian else None
        if not self.config.symmetric:
            y, dy, c = self.g(x, eye, cap)
        else:
            y, dy, c = self.g(torch.cat([x, x * self.input_mirror]),
                              None if eye is None else torch.cat([eye, eye * self.input_mirror]), cap)
            y = 0.5 * (y[:n] + y[n:] * self.output_mirror)
            dy = None if dy is None else 0.5 * (dy[:n] + dy[n:] * self.output_mirror)
            c = None if c is None else 0.5 * (c[:n] - c[n:])
        y = y.reshape(n, self.config.n_anchors, 2)
        if c is not None and self.config.cap_target == "offset":
            c = phi_end(y) + c
        return y, None if dy is None else dy.transpose(1, 2), c

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs (..., 4) -> anchors (..., k, 2) mm."""
        batch = x.shape[:-1]
        return self.outputs(x.reshape(-1, N_INPUTS))[0].reshape(*batch, self.config.n_anchors, 2)

    def with_cap(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Inputs (..., 4) -> (anchors (..., k, 2) mm, distal cap rotation (...) rad), from
        one pass, differentiable in x; the anchors equal forward(x) bit for bit. Raises
        ModelError (one line) if the model has no cap-rotation head."""
        batch = x.shape[:-1]
        y, _, c = self.outputs(x.reshape(-1, N_INPUTS), cap=True)
        return y.reshape(*batch, self.config.n_anchors, 2), c.reshape(batch)

    def with_jacobian(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Inputs (n, 4) -> (anchors (n, k, 2) mm, d anchors.reshape(2k) / d inputs (n, 2k, 4)),
        by forward-mode tangents (``outputs``)."""
        y, dy, _ = self.outputs(x, jacobian=True)
        return y, dy


def save_checkpoint(path: str | Path, model: JointSurrogate, train_config: dict,
                    metrics: dict, dataset: dict, joint: JointSpec | None = None) -> None:
    """Write a self-contained checkpoint of kind FORMAT, atomically (surrogate.checkpoint),
    for the joint description ``joint`` it was trained on (None: the paper's joint).
    ValueError (one line) if the joint's anchor count or input box is not the model's."""
    joint = joint or load_joint()
    if why := joint_mismatch(model.config, joint):
        raise ValueError(f"{path}: {why}")
    checkpoint.save(path, FORMAT, {
        "model_config": config_record(model.config),
        "normalisation": model.normalisation,
        "model_state": {k: v.detach().to(torch.float64).clone()
                        for k, v in model.state_dict().items()},
        "train_config": train_config,
        "metrics": metrics,
        "dataset": dataset,
        "joint": {"sha256": joint_digest(joint), "description": joint_to_dict(joint)},
    })


def checkpoint_joint(ckpt: dict, where: str = "checkpoint") -> JointSpec:
    """The joint description a checkpoint dict was trained on (module docstring): its
    ``joint`` entry, or the paper's joint for a checkpoint without one; ModelError (one
    line) for an entry that is not a valid joint or does not match its sha256."""
    entry = ckpt.get("joint")
    if entry is None:
        return load_joint()
    try:
        joint = joint_from_dict(entry["description"], f"{where}: joint")
        sha = entry["sha256"]
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{where}: inconsistent surrogate checkpoint joint ({_one_line(exc)})") from None
    if joint_digest(joint) != sha:
        raise ModelError(f"{where}: the checkpoint's joint description does not match its sha256")
    return joint


def joint_mismatch(config: ModelConfig, joint: JointSpec) -> str | None:
    """Why a model of ``config`` is not one of ``joint`` (anchor count, input box), or None."""
    box = tuple(float(b) for b in joint.input_box)
    if config.n_anchors != joint.anchors:
        return f"the model has {config.n_anchors} anchors, joint {joint.name!r} has {joint.anchors}"
    if config.input_box != box:
        return (f"the model's input box {list(config.input_box)} is not joint {joint.name!r}'s "
                f"{list(box)} (P MPa, F1 N, F2 N, M N*mm)")
    return None


def _check_normalisation(config: ModelConfig, norm: dict) -> None:
    """ValueError (one line) unless the normalisation has the config's box and 2k outputs."""
    if tuple(norm["input_scale"]) != config.input_box:
        raise ValueError(f"normalisation input_scale {norm['input_scale']} is not the model's input box "
                         f"{list(config.input_box)}")
    for key in ("output_mean", "output_scale"):
        if len(norm[key]) != 2 * config.n_anchors:
            raise ValueError(f"normalisation {key} has {len(norm[key])} values, not 2 x {config.n_anchors} anchors")


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

    The module maps inputs (..., 4) [P MPa, F1 N, F2 N, M N·mm] to anchors (..., k, 2) mm
    in the joint frame (k its joint's anchor count); it is batched and differentiable in its
    inputs (the weights do not require grad); ``module.joint`` is the joint it was trained on
    (checkpoint_joint). Raises ModelError with a one-line message if the file is missing or
    bad, or its joint's anchor count or input box is not its model's.
    """
    ckpt = load_checkpoint(path)
    model = build_model(ckpt, str(path))
    model.joint = checkpoint_joint(ckpt, str(path))
    if why := joint_mismatch(model.config, model.joint):
        raise ModelError(f"{path}: inconsistent surrogate checkpoint ({why})")
    model.eval().requires_grad_(False)
    return model
