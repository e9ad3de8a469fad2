"""The joint contract (docs/physics.md): the one owner of what every package agrees on.

The FEM produces it, the dataset stores it, the surrogate learns it and the predictor
feeds it, so it lives here once, in plain numpy (importing it never imports dolfinx or
torch; the functions also take torch tensors).

Inputs x = [P, F1, F2, M] in [MPa, N, N, N·mm]; the training box is |x_k| <= INPUT_BOX_k:

    |P| <= 0.3 MPa,  |F1| <= 3 N,  |F2| <= 3 N,  |M| <= 100 N·mm

A value counts as inside up to a relative BOX_TOL (1e-6, so float32 round-off of an edge
value is still inside). NaN and inf are outside, even when extrapolation is allowed.

Anchors R = [r_1 .. r_10] (10, 2) mm in the joint frame; r_i is the deformed material
point X_i = (i L / 10, 0, 0), L = JOINT_LENGTH = 45.45 mm. End orientation::

    phi_end = atan2(y_10 - y_9, x_10 - x_9)                      [rad], 0 undeformed

Mirror y -> -y maps (R, P, F1, F2, M) to (R diag(1, -1), -P, F1, -F2, -M); a Jacobian
d R.reshape(20) / d x maps to S J B with S = diag(1, -1, ...) (20) and B = INPUT_MIRROR.
"""

from __future__ import annotations

import numpy as np

INPUT_NAMES = ("P", "F1", "F2", "M")
INPUT_UNITS = ("MPa", "N", "N", "N*mm")
N_INPUTS = 4
N_ANCHORS = 10
JOINT_LENGTH = 45.45  # mm, fixed by the paper
#: Half-widths of the training box for (P MPa, F1 N, F2 N, M N·mm).
INPUT_BOX = np.array([0.3, 3.0, 3.0, 100.0])
BOX_TOL = 1e-6  # relative
PRESSURE_LIMIT = float(INPUT_BOX[0])  # MPa
#: Sign flips of the y-mirror on the inputs and on each anchor's (x, y).
INPUT_MIRROR = np.array([-1.0, 1.0, -1.0, -1.0])
ANCHOR_MIRROR = np.array([1.0, -1.0])


class OutOfBoxError(ValueError):
    """Inputs outside the training box (or not finite) where extrapolation is not allowed."""


def _outside(x: np.ndarray, box) -> np.ndarray:
    """Elementwise: |x| beyond box (1 + BOX_TOL), or not finite."""
    return ~np.isfinite(x) | (np.abs(x) > np.asarray(box, dtype=np.float64) * (1 + BOX_TOL))


def outside_box(inputs, box=INPUT_BOX) -> np.ndarray:
    """(..., k) inputs -> (...,) bool: some |x_j| > box_j (1 + BOX_TOL), or not finite.

    ``box`` (k,) defaults to the joint's 4 inputs; the predictor passes slices of it.
    """
    return _outside(np.asarray(_numpy(inputs), dtype=np.float64), box).any(axis=-1)


def check_box(inputs, allow_extrapolation: bool = False, names=INPUT_NAMES,
              box=INPUT_BOX, units=INPUT_UNITS) -> int:
    """Number of inputs (..., k) outside the box; raises OutOfBoxError if any is not
    finite, or outside and ``allow_extrapolation`` is False. The message names the first
    offending value and the allowed range, on one line. ``names``, ``box`` and ``units``
    (k,) describe other boxes, e.g. the gripper's pressures (P1, P2)."""
    x = np.asarray(_numpy(inputs), dtype=np.float64).reshape(-1, len(box))
    outside, not_finite = _outside(x, box), ~np.isfinite(x)
    rows = outside.any(axis=1)
    if not_finite.any() or (rows.any() and not allow_extrapolation):
        i, j = np.argwhere(not_finite if not_finite.any() else outside)[0]
        what = "not a finite number" if not_finite[i, j] else "outside the training box"
        allowed = ", ".join(f"|{n}| <= {b:g} {u}" for n, b, u in zip(names, box, units))
        hint = ("; pass --allow-extrapolation to go beyond it"
                if not not_finite.any() and tuple(names) == INPUT_NAMES else "")
        raise OutOfBoxError(f"{names[j]} = {x[i, j]:g} is {what} ({int(rows.sum())} of {len(x)} "
                            f"input(s) affected; allowed {allowed}{hint})")
    return int(rows.sum())


def phi_end(anchors):
    """End orientation (...,) rad from anchors (..., 10, 2) mm (numpy or torch)."""
    d = anchors[..., -1, :] - anchors[..., -2, :]
    if hasattr(d, "atan2"):  # torch: keep autograd
        return d[..., 1].atan2(d[..., 0])
    return np.arctan2(d[..., 1], d[..., 0])


def mirror(inputs, anchors, jacobian=None):
    """The y-mirror of a batch: inputs (n, 4), anchors (n, k, 2), jacobian (n, 2k, 4) or
    None -> the same shapes (numpy or torch, whichever is given); k anchors (the joint's)."""
    inputs_m = inputs * _like(INPUT_MIRROR, inputs)
    anchors_m = anchors * _like(ANCHOR_MIRROR, anchors)
    if jacobian is None:
        return inputs_m, anchors_m, None
    s = np.tile(ANCHOR_MIRROR, anchors.shape[-2])
    return inputs_m, anchors_m, jacobian * _like(s[:, None] * INPUT_MIRROR[None, :], jacobian)


def _numpy(a):
    return a.detach().cpu().numpy() if hasattr(a, "detach") else a


def _like(constant: np.ndarray, a):
    """``constant`` as an array of ``a``'s kind (a torch tensor of its dtype, or numpy)."""
    if hasattr(a, "new_tensor"):
        return a.new_tensor(constant)
    return constant
