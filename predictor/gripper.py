"""Two-finger gripper geometry: the finger chain, its weights and forward kinematics (docs/gripper.md).

Global plane: X horizontal, Y vertical up, gravity along -Y, gripper base on Y = 0.
The right-hand finger is modelled; the left one is its mirror image X -> -X.

The finger is read from a finger description file (contract.finger, default
contract/fingers/paper.toml): an ordered chain of J bellow joints and rigid parts in any
order, from the base mount B = (base_gap/2, 0), leaving it at base_angle (-pi/2: down).
The paper's layout is joint 1 -> rigid link (60 mm) -> joint 2 -> rigid tip (65 mm).

Walking the chain keeps a point O and a direction a (global mm, rad). Equation 3 of the
paper (rotate and translate) places joint i, whose proximal centre is O_i = O and whose
proximal orientation is theta_i = a:

    r_global = O_i + Rot(theta_i) · r_local,   Rot(a) = [[cos a, -sin a], [sin a, cos a]]

and then O <- r_10,i (its distal end) and a <- phi_i, the joint's exit angle:

    tangent kinematics (the paper's):  phi_i = theta_i + phi_end(R_i)  (chord of anchors 9-10)
    cap kinematics (bonded cap face, the default):  phi_i = theta_i + cap_rotation_i
                                       (JointModel.anchors_and_cap)

A rigid part of length l goes from O to O + l·(cos a, sin a) and leaves a unchanged, so
theta_{i+1} = phi_i when a rigid part (or nothing) lies between two joints. For the right
finger, a joint's local +y is global +X at rest, so P > 0 (bending to -y) closes the finger
and P < 0 opens it. A calibrated finger file (predictor.calibrate) gives joint i a pressure
gain g_i, offset o_i (MPa) and stiffness scale s_i: the joint model is evaluated at
((g_i P_i + o_i)/s_i, tau_i/s_i), the exact similarity of a joint of modulus s_i E.

Weights (N): a rigid part's at its midpoint; a joint's, with ``joint_weight``
``lumped`` (the paper's), at the mean of its 10 anchors, or ``split`` (the default): half at
its proximal centre O_i, half at its distal end r_10,i (predictor.statics says which joint
balances each enters). Contact sample points, in chain order: each rigid part's
``contact_points`` segment midpoints (each carrying l/n of length) and the n anchors of each
joint with ``contact = true`` (each carrying L/n, L and n its own joint description's: 45.45 mm
and 10 for the paper's joint); the paper's finger gives link (12),
joint 2 (10), tip (65).

All lengths mm, forces N, angles rad. Batched: pressures (B, J), tau (B, J, 3). The joint
model is evaluated once per call for all J joints, inputs (B, J, 4). Layouts that depend on
the finger only (ChainLayout) are cached: the residual runs thousands of times per solve.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields

import torch

from contract.finger import DEFAULT_FINGER, FingerSpec, load_finger
from contract.spec import PRESSURE_LIMIT, check_box, phi_end
from predictor.joint import JointModel

KINEMATICS = ("tangent", "cap")
JOINT_WEIGHTS = ("lumped", "split")
#: The defaults: the chain that matches the whole-finger FEM (results/validation/finger.json:
#: fingertip within 0.5 mm, against 5 mm for the paper's tangent kinematics).
DEFAULT_KINEMATICS, DEFAULT_JOINT_WEIGHT = "cap", "split"


def pressure_names(n: int) -> tuple[str, ...]:
    """("P1", ..., "Pn"): the pressures of an n-joint finger, base to tip."""
    return tuple(f"P{i + 1}" for i in range(n))


def check_pressures(pressures) -> None:
    """Refuse pressures (..., J) MPa that are not finite or beyond |P| <= PRESSURE_LIMIT
    (contract.spec.OutOfBoxError, a ValueError, one line naming the value)."""
    n = int(pressures.shape[-1])
    check_box(pressures, names=pressure_names(n), box=(PRESSURE_LIMIT,) * n, units=("MPa",) * n)


def nan_unless(ok: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """v (B, ...) with the rows where ok (B,) bool is False set to NaN."""
    nan = torch.where(ok, 0.0, float("nan"))
    return v + nan.reshape(-1, *([1] * (v.dim() - 1)))


def with_rows(v: torch.Tensor, rows: torch.Tensor, new: torch.Tensor) -> torch.Tensor:
    """A copy of v (B, ...) whose ``rows`` (B,) bool are replaced by new (rows.sum(), ...)."""
    v = v.clone()
    v[rows] = new
    return v


@functools.lru_cache(maxsize=4)
def default_finger() -> FingerSpec:
    """The paper's finger (contract/fingers/paper.toml), read once."""
    return load_finger(DEFAULT_FINGER)


@dataclass(frozen=True, eq=False)
class ChainLayout:
    """What the statics needs of a finger's chain, as index tensors (cached per finger and
    joint-weight option; read-only).

    joint_parts: part index of each joint (J,). Weight loads (Kw of them, those entering at
    least one joint balance), in chain order: ``weight_source`` (Kw,) indexes the stacked
    candidate points [rigid midpoints (R), then lumped: joint anchor means (J); split:
    joint proximal centres (J), joint distal ends (J)], ``weights`` (Kw,) N, ``weight_mask`` (J, Kw) 1.0 where the
    load enters joint i's balance. Contact sample points (Kc): ``contact_part`` (Kc,) long,
    the part each lies on; ``contact_length`` (Kc,) mm; ``contact_mask`` (J, Kc).
    full_mask (J, Kw + Kc): weights then contact points, the order in which
    GripperProblem.residual stacks the loads.
    """

    joint_parts: tuple[int, ...]
    joint_weight: str
    weight_source: torch.Tensor
    weights: torch.Tensor
    weight_mask: torch.Tensor
    contact_part: torch.Tensor
    contact_length: torch.Tensor
    contact_mask: torch.Tensor
    full_mask: torch.Tensor


@functools.lru_cache(maxsize=16)
def chain_layout(finger: FingerSpec, joint_weight: str = "lumped") -> ChainLayout:
    """The ChainLayout of ``finger`` (module docstring: where weights act and which joint
    balances each load enters; a load on part k enters joint i's balance when k is distal
    to joint i, i.e. k > part index of joint i; a split joint's distal half also enters
    its own joint's balance, with zero moment arm)."""
    if joint_weight not in JOINT_WEIGHTS:
        raise ValueError(f"joint weight {joint_weight!r}: use {' or '.join(JOINT_WEIGHTS)}")
    jp = finger.joints
    J = len(jp)
    R = len(finger.parts) - J
    loads = []  # (source index, weight, [enters joint i])
    r = j = 0
    for k, part in enumerate(finger.parts):
        distal = [k > jp[i] for i in range(J)]  # part k lies distal to joint i
        if part.kind == "rigid":
            loads.append((r, part.weight, distal))
            r += 1
        elif joint_weight == "lumped":
            loads.append((R + j, part.weight, distal))
            j += 1
        else:
            loads.append((R + j, 0.5 * part.weight, distal))
            loads.append((R + J + j, 0.5 * part.weight, [k >= jp[i] for i in range(J)]))
            j += 1
    # A load distal to no joint (on or before joint 1) is carried by the base mount only.
    loads = [ld for ld in loads if any(ld[2])]
    c_part, c_len = [], []
    for k, part in enumerate(finger.parts):
        # A joint's anchors are its own description's (count and length: contract.finger).
        n = part.spec.anchors if part.kind == "joint" and part.contact else getattr(part, "contact_points", 0)
        if n:
            c_part += [k] * n
            c_len += [part.length / n] * n
    mask = lambda rows: torch.tensor(rows, dtype=torch.float64).reshape(J, -1)  # noqa: E731
    w_mask = mask([[float(ld[2][i]) for ld in loads] for i in range(J)])
    c_mask = mask([[float(k > jp[i]) for k in c_part] for i in range(J)])
    return ChainLayout(
        joint_parts=jp,
        joint_weight=joint_weight,
        weight_source=torch.tensor([ld[0] for ld in loads], dtype=torch.long),
        weights=torch.tensor([ld[1] for ld in loads], dtype=torch.float64),
        weight_mask=w_mask,
        contact_part=torch.tensor(c_part, dtype=torch.long),
        contact_length=torch.tensor(c_len, dtype=torch.float64),
        contact_mask=c_mask,
        full_mask=torch.cat((w_mask, c_mask), 1))


@dataclass(frozen=True)
class GripperParams:
    """The finger (a FingerSpec: chain, lengths, weights, base mounts, contact sampling),
    the object's weight (N) and the two modelling options of the chain:

    kinematics: ``tangent`` (the paper's, a part leaves joint i along the chord of its last
    two anchors) or ``cap`` (along the distal cap face, the joint model's cap rotation);
    joint_weight: ``lumped`` (at the mean of the anchors) or ``split`` (half at each end).

    Paper defaults (docs/gripper.md, contract/fingers/paper.toml; Figure S4 is unavailable): link
    60 mm, tip 65 mm, base mounts 50 mm apart, which give the paper's 50 mm free tip
    opening and ≈3 mm of tip travel per degree of phi_1. Weights: joint 0.09 N, link 0.04 N,
    tip 0.06 N, object 0.2 N.
    """

    finger: FingerSpec = field(default_factory=default_finger)
    object_weight: float = 0.2
    kinematics: str = DEFAULT_KINEMATICS
    joint_weight: str = DEFAULT_JOINT_WEIGHT

    def __post_init__(self):
        if self.kinematics not in KINEMATICS:
            raise ValueError(f"kinematics {self.kinematics!r}: use {' or '.join(KINEMATICS)}")
        if self.joint_weight not in JOINT_WEIGHTS:
            raise ValueError(f"joint weight {self.joint_weight!r}: use {' or '.join(JOINT_WEIGHTS)}")
        # Built once per params (not a field: eq, hash and repr ignore it); the residual reads
        # it on every evaluation.
        object.__setattr__(self, "_layout", chain_layout(self.finger, self.joint_weight))
        object.__setattr__(self, "_calibration", joint_calibration(self.finger))

    @property
    def n_joints(self) -> int:
        return self.finger.n_joints

    @property
    def layout(self) -> ChainLayout:
        return self._layout

    @property
    def calibration(self) -> tuple[tuple[float, ...], ...] | None:
        """The finger file's joint calibration (joint_calibration), read once."""
        return self._calibration

    @property
    def base_gap(self) -> float:
        """mm between the two fingers' base mounts."""
        return self.finger.base_gap

    @property
    def tip_length(self) -> float:
        """Length (mm) of the finger's last part (the rigid tip of the paper's finger)."""
        return self.finger.parts[-1].length

    def describe(self) -> str:
        """One line: finger name and the two options (for messages)."""
        return f"finger {self.finger.name!r}, {self.kinematics} kinematics, {self.joint_weight} joint weights"


def rot(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors v (..., 2) by angle (...) rad, counter-clockwise: v as x + iy times
    e^(i angle). Six tensor operations, two of them views, instead of eleven for cos, sin
    and the products: the traced residual is dispatch-bound. Complex autograd keeps it
    differentiable in both."""
    z = torch.view_as_complex(v.contiguous()) * torch.polar(torch.ones_like(angle), angle)
    return torch.view_as_real(z)


def _unit(angle: torch.Tensor) -> torch.Tensor:
    return torch.stack((torch.cos(angle), torch.sin(angle)), -1)


def _segment_midpoints(start: torch.Tensor, direction: torch.Tensor, length: float, n: int) -> torch.Tensor:
    """n midpoints of a straight part (B, n, 2) from start (B, 2) along unit direction (B, 2)."""
    frac = (torch.arange(n, dtype=start.dtype) + 0.5) / n
    return start[:, None, :] + length * frac[None, :, None] * direction[:, None, :]


ANGLE = {"angle": True}  # FingerPose field metadata: an angle (rad), not points (mm)
STATIC = {"static": True}  # FingerPose field metadata: the same for every sample (not a tensor)


@dataclass
class FingerPose:
    """Global geometry of one finger, all (B, ...) mm / rad, for the chain ``finger``.

    joints: (B, J, 11, 2) polylines, proximal centre then the 10 anchors of each joint.
    segments: (B, R, 2, 2) start and end point of each rigid part, base to tip.
    theta: (B, J) proximal orientation of each joint; phi: (B, J) its exit angle (the
    direction the next part leaves at). points: (B, K, 2) contact sample points in chain
    order (ChainLayout.contact_part says which part each lies on). finger: the FingerSpec
    (static). The methods below act on every tensor field (``dataclasses.fields``); angle
    fields carry the ANGLE metadata. The paper layout's names (joint1, joint2, link, tip,
    link_points, tip_points) are properties of a joint-rigid-joint-rigid chain.
    """

    joints: torch.Tensor
    segments: torch.Tensor
    theta: torch.Tensor = field(metadata=ANGLE)
    phi: torch.Tensor = field(metadata=ANGLE)
    points: torch.Tensor
    finger: FingerSpec = field(metadata=STATIC)

    def _map(self, points, angles=None) -> "FingerPose":
        """Apply points(v) to every point field and angles(v) (default: points) to the angles."""
        angles = angles or points
        return FingerPose(**{f.name: getattr(self, f.name) if f.metadata.get("static") else
                             (angles if f.metadata.get("angle") else points)(getattr(self, f.name))
                             for f in fields(self)})

    def mirrored(self) -> "FingerPose":
        """The left finger: X -> -X for points, angle a -> pi - a."""
        return self._map(lambda v: v * v.new_tensor([-1.0, 1.0]), lambda a: math.pi - a)

    def masked(self, ok: torch.Tensor) -> "FingerPose":
        """NaN in every field where ok (B,) bool is False (a non-converged gesture)."""
        return self._map(lambda v: nan_unless(ok, v))

    def with_rows(self, rows: torch.Tensor, other: "FingerPose") -> "FingerPose":
        """A copy whose ``rows`` (B,) bool come from other (a pose of rows.sum() samples)."""
        return FingerPose(**{f.name: getattr(self, f.name) if f.metadata.get("static") else
                             with_rows(getattr(self, f.name), rows, getattr(other, f.name)) for f in fields(self)})

    def rows(self, index) -> "FingerPose":
        """The pose of samples ``index`` (a bool mask or indices over B)."""
        return FingerPose(**{f.name: getattr(self, f.name) if f.metadata.get("static") else getattr(self, f.name)[index]
                             for f in fields(self)})

    # ---- chain-generic views
    def part_polylines(self) -> list[tuple[str, torch.Tensor]]:
        """[(kind, (B, n, 2) polyline)] of every part in chain order (joints: 11 points,
        rigid parts: their 2 end points)."""
        out, j, r = [], 0, 0
        for part in self.finger.parts:
            if part.kind == "joint":
                out.append(("joint", self.joints[:, j]))
                j += 1
            else:
                out.append(("rigid", self.segments[:, r]))
                r += 1
        return out

    @property
    def tip_end(self) -> torch.Tensor:
        """Fingertip position (B, 2) mm: the end of the last part."""
        if self.finger.parts[-1].kind == "rigid":
            return self.segments[:, -1, 1]
        return self.joints[:, -1, -1]

    @property
    def tip_angle(self) -> torch.Tensor:
        """Global direction (B,) rad of the last part (-pi/2 at rest): the last joint's exit
        angle, which the rigid parts after it keep."""
        return self.phi[:, -1]

    # ---- the paper layout's names (joint, link, joint, tip)
    def _paper(self, name: str) -> None:
        if tuple(p.kind for p in self.finger.parts) != ("joint", "rigid", "joint", "rigid"):
            raise ValueError(f"FingerPose.{name} names a part of the paper's joint-link-joint-tip chain; finger "
                             f"{self.finger.name!r} is another chain: use joints, segments, points")

    def _points_of(self, part: int) -> torch.Tensor:
        sel = (chain_layout(self.finger).contact_part == part).nonzero().flatten()
        return self.points[:, sel]

    @property
    def joint1(self) -> torch.Tensor:
        self._paper("joint1")
        return self.joints[:, 0]

    @property
    def joint2(self) -> torch.Tensor:
        self._paper("joint2")
        return self.joints[:, 1]

    @property
    def link(self) -> torch.Tensor:
        self._paper("link")
        return self.segments[:, 0]

    @property
    def tip(self) -> torch.Tensor:
        self._paper("tip")
        return self.segments[:, 1]

    @property
    def link_points(self) -> torch.Tensor:
        self._paper("link_points")
        return self._points_of(1)

    @property
    def tip_points(self) -> torch.Tensor:
        self._paper("tip_points")
        return self._points_of(3)


def joint_calibration(finger: FingerSpec) -> tuple[tuple[float, ...], ...] | None:
    """(gains, offsets MPa, stiffness scales), one per joint, of a calibrated finger file
    (contract.finger; predictor.calibrate writes them), or None when every joint is the
    joint model as it is."""
    joints = [p for p in finger.parts if p.kind == "joint"]
    if not any(p.calibrated for p in joints):
        return None
    return tuple(tuple(getattr(p, k) for p in joints) for k in ("pressure_gain", "pressure_offset", "stiffness_scale"))


def finger_pose(joint: JointModel, params: GripperParams, pressures: torch.Tensor, tau: torch.Tensor) -> FingerPose:
    """Forward kinematics of the right finger (module docstring).

    pressures: (B, J) MPa [P1 .. PJ]; tau: (B, J, 3) joint loads [F1 N, F2 N, M N·mm] in
    each joint's undeformed frame. Returns the FingerPose (global mm, rad).
    """
    finger = params.finger
    B = pressures.shape[0]
    inputs = torch.cat((pressures[..., None], tau), -1)  # (B, J, 4): one joint-model pass
    calibration = params.calibration
    if calibration is not None:   # joint i of modulus s E sees ((g P + o)/s, tau/s)
        g, o, s = (torch.tensor(v, dtype=tau.dtype) for v in calibration)
        inputs = torch.cat((((g * pressures + o) / s)[..., None], tau / s[:, None]), -1)
    if params.kinematics == "cap":
        anchors, turn = joint.anchors_and_cap(inputs)  # (B, J, 10, 2) local, (B, J) rad
    else:
        anchors = joint(inputs)
        turn = phi_end(anchors)  # tangent: the chord of the last two anchors
    pos = torch.tensor([0.5 * finger.base_gap, 0.0], dtype=tau.dtype).expand(B, 2)
    angle = torch.full((B,), finger.base_angle, dtype=tau.dtype)
    zero = torch.zeros(B, 1, 2, dtype=tau.dtype)
    joints, segments, theta, phi, points = [], [], [], [], []
    for part in finger.parts:  # a loop over the chain's few parts, not over the batch
        if part.kind == "joint":
            i = len(joints)
            poly = pos[:, None, :] + rot(angle[:, None], torch.cat((zero, anchors[:, i]), 1))
            theta.append(angle)
            angle = angle + turn[:, i]
            phi.append(angle)
            joints.append(poly)
            if part.contact:
                points.append(poly[:, 1:])
            pos = poly[:, -1]
        else:
            direction = _unit(angle)
            end = pos + part.length * direction
            segments.append(torch.stack((pos, end), 1))
            if part.contact_points:
                points.append(_segment_midpoints(pos, direction, part.length, part.contact_points))
            pos = end
    return FingerPose(
        joints=torch.stack(joints, 1),
        segments=torch.stack(segments, 1) if segments else torch.zeros(B, 0, 2, 2, dtype=tau.dtype),
        theta=torch.stack(theta, -1),
        phi=torch.stack(phi, -1),
        points=torch.cat(points, 1) if points else torch.zeros(B, 0, 2, dtype=tau.dtype),
        finger=finger,
    )
