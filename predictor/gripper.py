"""Two-finger gripper geometry: dimensions, weights and forward kinematics (DESIGN.md §4).

Global plane: X horizontal, Y vertical up, gravity along -Y, gripper base on Y = 0.
The right-hand finger is modelled; the left one is its mirror image X -> -X.

Right finger chain, from the base mount B = (d/2, 0) hanging down (theta_1 = -pi/2):

    joint 1 -> rigid link (l_link) -> joint 2 -> rigid tip (l_tip)

Equation 3 of the paper (rotate and translate) places joint i:

    r_global = O_i + Rot(theta_i) · r_local,   Rot(a) = [[cos a, -sin a], [sin a, cos a]]

with O_i its proximal centre and theta_i its proximal orientation. Connections are
tangent (DESIGN.md §4): phi_i = theta_i + phi_end(R_i), the rigid link leaves joint 1's
distal end r_10 along phi_1, so theta_2 = phi_1, and the tip leaves joint 2 along phi_2.
For the right finger, a joint's local +y is global +X at rest, so P > 0 (bending to -y)
closes the finger and P < 0 opens it.

All lengths mm, forces N, angles rad. Batched: pressures (B, 2), tau (B, 2, 3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import torch

from fem.spec import PRESSURE_LIMIT, check_box, phi_end
from predictor.joint import JointModel

#: The gripper's inputs: one pressure per joint, each within the joint's |P| <= 0.3 MPa.
PRESSURE_NAMES = ("P1", "P2")


def check_pressures(pressures) -> None:
    """Refuse pressures (..., 2) MPa that are not finite or beyond |P| <= PRESSURE_LIMIT
    (fem.spec.OutOfBoxError, a ValueError, one line naming the value)."""
    check_box(pressures, names=PRESSURE_NAMES, box=(PRESSURE_LIMIT, PRESSURE_LIMIT), units=("MPa", "MPa"))


def nan_unless(ok: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """v (B, ...) with the rows where ok (B,) bool is False set to NaN."""
    nan = torch.where(ok, 0.0, float("nan"))
    return v + nan.reshape(-1, *([1] * (v.dim() - 1)))


def with_rows(v: torch.Tensor, rows: torch.Tensor, new: torch.Tensor) -> torch.Tensor:
    """A copy of v (B, ...) whose ``rows`` (B,) bool are replaced by new (rows.sum(), ...)."""
    v = v.clone()
    v[rows] = new
    return v


@dataclass(frozen=True)
class GripperParams:
    """Dimensions (mm), weights (N) and contact discretisation of the gripper.

    Assumptions (the paper's Figure S4 is unavailable, DESIGN.md §4): link 60 mm, tip
    65 mm, base mounts 50 mm apart, which give the paper's 50 mm free tip opening and
    ≈3 mm of tip travel per degree of phi_1. Weights: joint 0.09 N at the mean of its
    anchors, link 0.04 N and tip 0.06 N at their midpoints, object 0.2 N.
    """

    link_length: float = 60.0
    tip_length: float = 65.0
    base_gap: float = 50.0
    joint_weight: float = 0.09
    link_weight: float = 0.04
    tip_weight: float = 0.06
    object_weight: float = 0.2
    # Contact sample points per rigid part (segment midpoints, so each carries l/n of length).
    n_link_points: int = 12
    n_tip_points: int = 65


def rot(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors v (..., 2) by angle (...) rad, counter-clockwise."""
    c, s = torch.cos(angle)[..., None], torch.sin(angle)[..., None]
    return torch.cat((c * v[..., :1] - s * v[..., 1:], s * v[..., :1] + c * v[..., 1:]), -1)


def _unit(angle: torch.Tensor) -> torch.Tensor:
    return torch.stack((torch.cos(angle), torch.sin(angle)), -1)


def _segment_midpoints(start: torch.Tensor, direction: torch.Tensor, length: float, n: int) -> torch.Tensor:
    """n midpoints of a straight part (B, n, 2) from start (B, 2) along unit direction (B, 2)."""
    frac = (torch.arange(n, dtype=start.dtype) + 0.5) / n
    return start[:, None, :] + length * frac[None, :, None] * direction[:, None, :]


ANGLE = {"angle": True}  # FingerPose field metadata: an angle (rad), not points (mm)


@dataclass
class FingerPose:
    """Global geometry of one finger, all (B, ...) mm / rad.

    joint1, joint2: (B, 11, 2) polylines, proximal centre then the 10 anchors.
    link, tip: (B, 2, 2) end points. theta: (B, 2) proximal orientation of joints 1, 2.
    phi: (B, 2) distal orientation of joints 1, 2. link_points, tip_points: (B, n, 2)
    contact sample points (segment midpoints). The methods below act on every field
    (``dataclasses.fields``); angle fields carry the ANGLE metadata.
    """

    joint1: torch.Tensor
    joint2: torch.Tensor
    link: torch.Tensor
    tip: torch.Tensor
    theta: torch.Tensor = field(metadata=ANGLE)
    phi: torch.Tensor = field(metadata=ANGLE)
    link_points: torch.Tensor
    tip_points: torch.Tensor

    def _map(self, points, angles=None) -> "FingerPose":
        """Apply points(v) to every point field and angles(v) (default: points) to the angles."""
        angles = angles or points
        return FingerPose(**{f.name: (angles if f.metadata.get("angle") else points)(getattr(self, f.name))
                             for f in fields(self)})

    def mirrored(self) -> "FingerPose":
        """The left finger: X -> -X for points, angle a -> pi - a."""
        return self._map(lambda v: v * v.new_tensor([-1.0, 1.0]), lambda a: math.pi - a)

    def masked(self, ok: torch.Tensor) -> "FingerPose":
        """NaN in every field where ok (B,) bool is False (a non-converged gesture)."""
        return self._map(lambda v: nan_unless(ok, v))

    def with_rows(self, rows: torch.Tensor, other: "FingerPose") -> "FingerPose":
        """A copy whose ``rows`` (B,) bool come from other (a pose of rows.sum() samples)."""
        return FingerPose(**{f.name: with_rows(getattr(self, f.name), rows, getattr(other, f.name))
                             for f in fields(self)})

    @property
    def tip_end(self) -> torch.Tensor:
        """Fingertip position (B, 2) mm."""
        return self.tip[:, 1]


def finger_pose(joint: JointModel, params: GripperParams, pressures: torch.Tensor, tau: torch.Tensor) -> FingerPose:
    """Forward kinematics of the right finger.

    pressures: (B, 2) MPa [P1, P2]; tau: (B, 2, 3) joint loads [F1 N, F2 N, M N·mm] in
    each joint's undeformed frame. Returns the FingerPose (global mm, rad).
    """
    B = pressures.shape[0]
    inputs = torch.cat((pressures[..., None], tau), -1)  # (B, 2, 4)
    anchors = joint(inputs)  # (B, 2, 10, 2) local
    bend = phi_end(anchors)  # (B, 2)
    base = torch.tensor([0.5 * params.base_gap, 0.0], dtype=tau.dtype).expand(B, 2)
    theta1 = torch.full((B,), -0.5 * math.pi, dtype=tau.dtype)
    zero = torch.zeros(B, 1, 2, dtype=tau.dtype)

    j1 = base[:, None, :] + rot(theta1[:, None], torch.cat((zero, anchors[:, 0]), 1))
    phi1 = theta1 + bend[:, 0]
    link_dir = _unit(phi1)
    link_end = j1[:, -1] + params.link_length * link_dir
    theta2 = phi1  # tangent connection
    j2 = link_end[:, None, :] + rot(theta2[:, None], torch.cat((zero, anchors[:, 1]), 1))
    phi2 = theta2 + bend[:, 1]
    tip_dir = _unit(phi2)
    tip_end = j2[:, -1] + params.tip_length * tip_dir
    return FingerPose(
        joint1=j1,
        joint2=j2,
        link=torch.stack((j1[:, -1], link_end), 1),
        tip=torch.stack((j2[:, -1], tip_end), 1),
        theta=torch.stack((theta1, theta2), -1),
        phi=torch.stack((phi1, phi2), -1),
        link_points=_segment_midpoints(j1[:, -1], link_dir, params.link_length, params.n_link_points),
        tip_points=_segment_midpoints(j2[:, -1], tip_dir, params.tip_length, params.n_tip_points),
    )
