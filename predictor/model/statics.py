"""Equilibrium residual of the right finger (paper's Equation 1), with gravity and contact.

Load convention (must match how the FEM defines the surrogate's inputs, docs/physics.md and docs/gripper.md):
tau_i = (F1, F2, M)_i is the load that the part of the finger distal to joint i exerts ON
joint i's distal end. F1, F2 (N) are dead loads at the end point r_10 expressed in joint
i's UNDEFORMED frame, so their global value is Rot(theta_i)·(F1, F2) with theta_i the
PROXIMAL orientation of joint i (theta_1 = -pi/2, theta_2 = phi_1). M (N·mm) is a pure
couple about +z. The paper's Equation 2 writes Rot(phi_i), the DISTAL orientation; that
would be right only if the FEM force followed the end's rotation. Our FEM applies it in
the undeformed frame ("the coordinate of the force is consistent with the undeformed joint
coordinate"), so theta_i is used here; the full-finger FEM is the arbiter.

Equation 1, per joint i of the J joints, with the external loads (F_k at p_k) on the
parts distal to it:

    R_F,i = Rot(theta_i)·(F1, F2)_i - sum_k F_k                       [N]
    R_M,i = M_i - sum_k (p_k - r_10,i) × F_k                          [N·mm]

A load on part k enters joint i's balance when part k is distal to joint i (k after it in
the finger's chain, predictor.model.gripper.ChainLayout): the paper's finger gives joint 1 the
link, joint 2 and the tip, and joint 2 the tip. Weights act at the rigid parts' midpoints;
a joint's own weight (GripperParams.joint_weight):
- ``lumped`` (the paper's): at the mean of its anchors; it enters only the balances of
  the joints proximal to it, as loads on a joint's body do, since the surrogate takes
  end loads only (as in the paper);
- ``split`` (the default, predictor.model.gripper.DEFAULT_JOINT_WEIGHT): half at its proximal
  centre O_i (the joints proximal to it) and half at its distal end r_10,i, which also
  enters its own balance, with zero moment arm there.
A load distal to no joint (joint 1's own weight when lumped) is carried by the base mount.
The scalar loss is alpha·R_Fx² + beta·R_Fy² + gamma·R_M² with alpha = beta =
1 N⁻², gamma = 1e-4 (N·mm)⁻² (moments scaled by a 100 mm lever, the finger's size).

Contact (object fixed in the plane, signed distance d < 0 inside, outward normal n):
- where: the finger's outline (predictor.model.gripper.outline_vertices: each rigid part's
  rectangle of its height, each joint's band of the joint's outer height about its
  centre line, the last part's end face; GripperParams.surface ``faces``), edge by edge:
  the interval of the edge inside the object is exact (Obstacle.segment_interval) and
  EDGE_GAUSS Gauss points q_k with lengths w_k (mm) integrate the penalty over it
  (``edge_quadrature``), so the force is smooth in the pose. ``centre_line`` keeps the
  paper's fixed points: each rigid part's ``contact_points`` midpoints and the 10 anchors
  of each joint with ``contact = true``, each carrying l/n or L/10;
- normal penalty on the finger: N_k = k_c · s(max(0, -d_k)) · w_k along +n_k (k_c in N/mm²,
  s the C1 ramp ``smooth_penetration``);
- friction: the object (weight W) hangs in two mirror fingers, so each side lifts W/2.
  With t_k the object's tangent turned upwards (t_y >= 0) and a common ratio f_k = λ N_k,
  the object's vertical balance gives λ = (W/2 + Σ N_k n_ky) / Σ N_k t_ky. The finger
  feels N_k n_k - λ_c N_k t_k with λ_c = clip(λ, -mu, mu) (the cone |f| <= mu·N always
  holds); ``slip`` is set when |λ| > mu or nothing touches the object. The split W/2
  assumes the object is symmetric about X = 0 (other objects are refused: grasp.object_error);
- the two mirror fingers meet at X = 0: the same penalty, frictionless, pushes the
  outline's inner and end edges back along +X where they cross it (``plane_contact``,
  stiffness ContactParams.plane_stiffness; 0 lets the fingers cross, as in the paper).

Out-of-range guard (paper): penalty residuals max(0, |F1|-3), max(0, |F2|-3) N and
max(0, |M|-100)/100 per joint, the surrogate's training box (contract.spec.INPUT_BOX).

Data flow: a GripperProblem (joint model, GripperParams = finger + kinematics + joint
weights, object, contact law, gravity, approach pressures) -> ``problem.residual(pressures,
tau)`` with pressures (B, J), tau (B, J, 3) -> Statics (residual (B, J, 3), pose, ContactState,
PlaneContact).
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import torch

from contract import grasp
from contract.grasp import ObjectSpec
from contract.spec import INPUT_BOX
from predictor.model.gripper import (EDGE_GAUSS, PLANE_GAUSS, FingerPose, GripperParams, check_pressures, edge_ends,
                                     edge_points, finger_pose, gauss_rule, outline_vertices, rot)
from predictor.model.joint import JointModel, no_cap_message

MOMENT_SCALE = 100.0  # mm: moment residuals are divided by this in the loss
PENALTY_WEIGHT = 10.0  # weight of the out-of-box residuals relative to the equilibrium ones


_EMPTY = 1e9   # an empty interval's start (its end is -_EMPTY): ignored by min/max unions


def _disc_interval(p: torch.Tensor, D: torch.Tensor, r) -> tuple[torch.Tensor, torch.Tensor]:
    """Parameters (lo, hi) (...) where the line p + u·D (..., 2) lies inside the disc of
    radius r about the origin: the roots of |p + u D|² = r² (lo = _EMPTY, hi = -_EMPTY
    when it misses)."""
    a = (D * D).sum(-1).clamp_min(1e-24)
    b = (p * D).sum(-1)
    disc = b * b - a * ((p * p).sum(-1) - r * r)
    root = disc.clamp_min(1e-30).sqrt()
    hit = disc > 0
    return torch.where(hit, (-b - root) / a, _EMPTY), torch.where(hit, (-b + root) / a, -_EMPTY)


def _box_interval(p: torch.Tensor, D: torch.Tensor, half: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(lo, hi) (...) where p + u·D lies inside the box |x| < half (2,) (slab clipping)."""
    Ds = torch.where(D >= 0, D.clamp_min(1e-12), D.clamp_max(-1e-12))
    t1, t2 = (-half - p) / Ds, (half - p) / Ds
    lo, hi = torch.minimum(t1, t2).amax(-1), torch.maximum(t1, t2).amin(-1)
    hit = hi > lo
    return torch.where(hit, lo, _EMPTY), torch.where(hit, hi, -_EMPTY)


def clip_interval(lo: torch.Tensor, hi: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(u0, u1) = the interval [lo, hi] within [0, 1], u0 <= u1 (u0 = u1 when empty)."""
    u0 = lo.clamp(0.0, 1.0)
    return u0, torch.maximum(hi.clamp(0.0, 1.0), u0)


@dataclass(frozen=True)
class Obstacle(ObjectSpec):
    """A rigid object in the global plane: contract.grasp.ObjectSpec (kind circle | ellipse
    | rectangle; a, b the radius, semi-axes or half width and height, mm; centre x, y mm;
    angle rad, counter-clockwise; a rectangle's corner radius, mm), checked by
    contract.grasp.object_error, with the predictor's torch geometry (distance and normal,
    a segment's part inside).

    Default placement (a documented departure from "230 mm below the base"): centre at
    Y = -195 mm, between the fingers' distal parts. The objects are wider (60-70 mm)
    than the free opening (30 mm between the fingers' inner faces), so an object that
    clears the zero-pressure gesture has to lie below the fingertips (Y_centre < -242 mm
    for the circle); there the closing fingers meet at X = 0 above it or reach only its
    upper shoulder, and mu = 0.3 cannot hold it. The grasp therefore starts from an open
    approach gesture (P = (-0.15, 0) MPa, contact-free for these defaults), brings the
    object in, and ramps to the target.
    """

    @property
    def radius(self) -> float:
        """Radius (mm) of the smallest circle about the centre that holds the object."""
        return math.hypot(self.a, self.b) if self.kind == "rectangle" else max(self.a, self.b)

    def distance_normal(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """points (..., 2) mm -> (d (...) mm, negative inside; n (..., 2) outward unit normal):
        in torch, the d of contract.grasp.ObjectSpec.signed_distance with its normal.

        Circle and rectangle are exact. The ellipse uses the first-order (Taubin) distance
        g/|grad g| with g = (x/a)² + (y/b)² - 1, exact on the boundary and accurate to
        O(d²) near it, which is where penalty contact lives.
        """
        centre = torch.tensor([self.x, self.y], dtype=points.dtype)
        q = points - centre
        if self.angle:
            q = rot(torch.tensor(-self.angle, dtype=points.dtype), q)
        if self.kind == "circle":
            r = q.norm(dim=-1).clamp_min(1e-12)
            d, n = r - self.a, q / r[..., None]
        elif self.kind == "ellipse":
            ab2 = torch.tensor([self.a**2, self.b**2], dtype=points.dtype)
            g = (q * q / ab2).sum(-1) - 1.0
            grad = 2.0 * q / ab2
            gn = grad.norm(dim=-1).clamp_min(1e-12)
            d, n = g / gn, grad / gn[..., None]
        elif self.kind == "rectangle":
            # the rounded rectangle: e = |q| - half + rho; d = |max(e, 0)| + min(max_i e_i, 0) - rho
            half = torch.tensor([self.a, self.b], dtype=points.dtype)
            e = q.abs() - half + self.corner
            out = e.clamp_min(0.0)
            out_len = out.norm(dim=-1)
            d = out_len + e.max(-1).values.clamp_max(0.0) - self.corner
            # where both e_i > 0 (about a corner's arc): radial; elsewhere the nearest face,
            # which inside switches on the diagonal, deeper than the corner radius.
            face = (e[..., 0] >= e[..., 1]).to(points.dtype)
            n_face = torch.stack((face, 1.0 - face), -1)
            n_arc = out / out_len.clamp_min(1e-12)[..., None]
            n = torch.where((e > 0).all(-1)[..., None], n_arc, n_face) * torch.sign(q + (q == 0).to(q.dtype))
        else:
            raise ValueError(f"unknown object kind {self.kind!r} (use circle, ellipse or rectangle)")
        return d, (rot(torch.tensor(self.angle, dtype=points.dtype), n) if self.angle else n)

    def segment_interval(self, start: torch.Tensor, end: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The part of each segment start + u·(end - start), u in [0, 1], inside the object
        (where ``distance_normal``'s d < 0), as (u0, u1) (...) with u0 <= u1 (equal when it
        misses): exact, from the line's intersection with the circle, the ellipse, or the
        rounded rectangle's two boxes and four corner discs (the object is convex, so the
        inside is one interval). start, end (..., 2) mm."""
        centre = torch.tensor([self.x, self.y], dtype=start.dtype)
        p, D = start - centre, end - start
        if self.angle:
            turn = torch.tensor(-self.angle, dtype=start.dtype)
            p, D = rot(turn, p), rot(turn, D)
        if self.kind == "circle":
            return clip_interval(*_disc_interval(p, D, self.a))
        if self.kind == "ellipse":
            scale = torch.tensor([1.0 / self.a, 1.0 / self.b], dtype=start.dtype)
            return clip_interval(*_disc_interval(p * scale, D * scale, 1.0))
        rho = self.corner
        pieces = [_box_interval(p, D, torch.tensor([self.a, self.b - rho], dtype=start.dtype)),
                  _box_interval(p, D, torch.tensor([self.a - rho, self.b], dtype=start.dtype))]
        if rho > 0:
            for sx in (-1.0, 1.0):
                for sy in (-1.0, 1.0):
                    c = torch.tensor([sx * (self.a - rho), sy * (self.b - rho)], dtype=start.dtype)
                    pieces.append(_disc_interval(p - c, D, rho))
        lo = torch.stack([piece[0] for piece in pieces]).amin(0)
        hi = torch.stack([piece[1] for piece in pieces]).amax(0)
        return clip_interval(lo, hi)


def parse_object(spec: str) -> Obstacle:
    """The object of spec ``kind[:key=value,...]`` (contract.grasp.parse_object: lengths mm,
    ``deg`` degrees, a rectangle's corner radius ``rc``), as an Obstacle; ValueError with
    contract.grasp's one-line reason."""
    return Obstacle(**dataclasses.asdict(grasp.parse_object(spec)))


@dataclass(frozen=True)
class ContactParams:
    """Penalty stiffness k_c (N per mm of penetration per mm of finger length), the
    penalty's C1 smoothing width (mm), the friction coefficient mu, and the stiffness k_p
    of the frictionless contact with the symmetry plane X = 0 where the two fingers meet
    (same units; 0: the fingers pass through each other, as in the paper)."""

    stiffness: float = grasp.CONTACT_STIFFNESS
    smoothing: float = grasp.CONTACT_SMOOTHING
    mu: float = grasp.FRICTION
    plane_stiffness: float = grasp.PLANE_STIFFNESS


#: Grasp states of an equilibrium with an object, and their codes (predictor.planning.atlas adds
#: NOT_CONVERGED for a solve that did not converge).
STATES = ("no_contact", "holds", "slips", "not_converged")
NO_CONTACT, HOLDS, SLIPS, NOT_CONVERGED = range(4)


def grasp_state(normal: torch.Tensor, slip: torch.Tensor) -> torch.Tensor:
    """State codes (B,) (NO_CONTACT, HOLDS or SLIPS) from the normal force (B,) N and the
    slip flags (B,) of ContactState."""
    return torch.where(normal > 0, torch.where(slip, SLIPS, HOLDS), NO_CONTACT)


@dataclass
class ContactState:
    """Contact of a batch of right fingers with the object (module docstring).

    points, forces: (B, K, 2) sample points (mm) and total force (N) on the finger at each;
    part: (K,) long, the index in the finger's chain of the part each point lies on (the
    paper's finger: 1 = link, 2 = joint 2, 3 = tip). normal: (B,) N, sum of N_k.
    friction: (B,) N, sum of |λ_c| N_k. ratio: (B,) λ (unclipped; NaN-free, ±inf replaced
    by ±1e3 when nothing touches). slip: (B,) bool. penetration: (B,) mm, max(0, -min d).
    """

    points: torch.Tensor
    forces: torch.Tensor
    part: torch.Tensor
    normal: torch.Tensor
    friction: torch.Tensor
    ratio: torch.Tensor
    slip: torch.Tensor
    penetration: torch.Tensor

    @classmethod
    def none(cls, B: int, dtype: torch.dtype) -> "ContactState":
        """No object: K = 0 sample points, every figure 0, no slip."""
        zeros, empty = torch.zeros(B, dtype=dtype), torch.zeros(B, 0, 2, dtype=dtype)
        return cls(empty, empty, torch.zeros(0, dtype=torch.long), zeros, zeros, zeros,
                   torch.zeros(B, dtype=torch.bool), zeros)


def meets(problem: "GripperProblem") -> bool:
    """Whether the fingers meet at the symmetry plane X = 0 (its penalty is on)."""
    return problem.contact.plane_stiffness > 0


def apart(problem: "GripperProblem") -> "GripperProblem":
    """``problem`` without the plane X = 0's penalty: the same residual wherever no vertex
    of the outline lies at X < 0 (the broad phase of predictor.solvers.graphs.gated)."""
    return dataclasses.replace(problem, contact=dataclasses.replace(problem.contact, plane_stiffness=0.0))


@dataclass
class PlaneContact:
    """The right finger's contact with the symmetry plane X = 0 (the left finger's mirror
    face): points, forces (B, Kp, 2) mm, N, the Gauss points of every outline edge's part
    at X < 0 and the force on the finger there (+X), both zero on a row whose outline does
    not cross X = 0; force (B,) N their sum; overlap (B,)
    mm, how far the outline crosses X = 0 (max(0, -min X of its vertices)). A Statics
    rebuilt from a recorded graph (predictor.solvers.graphs.as_statics) has the figures force and
    overlap only (points and forces None)."""

    points: torch.Tensor
    forces: torch.Tensor
    force: torch.Tensor
    overlap: torch.Tensor


@dataclass
class Statics:
    """Residual (B, J, 3) [R_Fx N, R_Fy N, R_M N·mm] per joint (global frame), the pose it
    was evaluated at, the contact state with the object and the symmetry-plane contact
    (None when it is off; a Statics rebuilt from a recorded graph has its figures only),
    and the pose's ``outline_vertices`` (B, V, 2) mm where the residual built them."""

    residual: torch.Tensor
    pose: FingerPose
    contact: ContactState
    plane: PlaneContact | None = None
    vertices: torch.Tensor | None = None


def _cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def smooth_penetration(pen: torch.Tensor, delta: float) -> torch.Tensor:
    """C1 ramp of the penetration pen (mm): 0 for pen <= 0, pen²/(2 delta) up to delta,
    pen - delta/2 beyond. It removes the force jump when a sample point enters contact,
    which otherwise stalls Newton; it is exactly zero without penetration."""
    pen = pen.clamp_min(0.0)
    return torch.where(pen < delta, pen * pen / (2.0 * delta), pen - 0.5 * delta)


def edge_quadrature(start: torch.Tensor, end: torch.Tensor, u0: torch.Tensor,
                    u1: torch.Tensor, m: int = EDGE_GAUSS) -> tuple[torch.Tensor, torch.Tensor]:
    """Gauss-Legendre points (B, E·m, 2) mm and weights (B, E·m) mm of the intervals
    [u0, u1] (B, E) of the segments start + u·(end - start) (B, E, 2): the points move with
    the interval, so an integral over a contact's extent is smooth in the pose (fixed
    sample points make it bumpy: a contact narrower than their spacing is seen by one or
    two of them)."""
    xi, w = (v.to(start.dtype) for v in gauss_rule(m))
    u = u0[..., None] + (u1 - u0)[..., None] * xi                       # (B, E, G)
    D = end - start
    points = start[:, :, None] + u[..., None] * D[:, :, None]
    weights = ((u1 - u0) * D.norm(dim=-1))[..., None] * w
    return points.flatten(1, 2), weights.flatten(1, 2)


def object_samples(pose: FingerPose, params: GripperParams, obstacle: Obstacle,
                   vertices: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """The finger's contact sample points (B, K, 2) mm and the length (mm) each carries:
    with surface ``faces`` the Gauss points of each object edge's part inside the object
    (``Obstacle.segment_interval``, ``edge_quadrature``), with ``centre_line`` the pose's
    fixed points. vertices: the pose's ``outline_vertices``, when the caller has them."""
    layout = params.layout
    if layout.surface == "centre_line":
        return pose.points, layout.contact_length.to(pose.points.dtype) * torch.ones_like(pose.points[..., 0])
    V = outline_vertices(pose, layout) if vertices is None else vertices
    start, end = edge_ends(V, layout, layout.object_edges)
    return edge_quadrature(start, end, *obstacle.segment_interval(start, end))


def contact_loads(pose: FingerPose, params: GripperParams, obstacle: Obstacle, contact: ContactParams,
                  weight: float, vertices: torch.Tensor | None = None) -> ContactState:
    """Penalty + friction forces on the finger's sample points (module docstring).

    weight: object weight W (N); vertices: the pose's ``outline_vertices`` (optional).
    Returns the ContactState (forces on the finger).
    """
    part = params.layout.contact_part
    points, seg = object_samples(pose, params, obstacle, vertices)
    d, n = obstacle.distance_normal(points)
    normal = contact.stiffness * smooth_penetration(-d, contact.smoothing) * seg  # (B, K) N
    t = torch.stack((-n[..., 1], n[..., 0]), -1)
    t = t * torch.where(t[..., 1:] < 0, -1.0, 1.0)  # upward tangent
    num = 0.5 * weight + (normal * n[..., 1]).sum(-1)
    den = (normal * t[..., 1]).sum(-1)
    holds = den > 1e-9
    ratio = torch.where(holds, num / torch.where(holds, den, 1.0), torch.sign(num) * 1e3)
    used = ratio.clamp(-contact.mu, contact.mu)
    forces = normal[..., None] * (n - used[:, None, None] * t)
    slip = (ratio.abs() > contact.mu) | ~holds
    total = normal.sum(-1)
    depth = (-d.min(-1).values).clamp_min(0.0) if d.shape[-1] else torch.zeros_like(total)
    return ContactState(points, forces, part, total, used.abs() * total, ratio, slip, depth)


def plane_overlap(vertices: torch.Tensor) -> torch.Tensor:
    """How far (B,) mm the outline of ``outline_vertices`` crosses X = 0: its edges are
    straight, so the deepest point is a vertex."""
    return (-vertices[..., 0].amin(-1)).clamp_min(0.0)


def plane_contact(pose: FingerPose, params: GripperParams, contact: ContactParams,
                  vertices: torch.Tensor | None = None) -> PlaneContact:
    """The frictionless penalty of the symmetry plane X = 0 on the right finger's outline
    (module docstring): on every inner and end edge (ChainLayout.plane_edges) the interval
    at X < 0 (X is linear along it), its PLANE_GAUSS Gauss points q_k with lengths w_k,
    force k_p·s(-X_k)·w_k along +X. The overlap is over every vertex."""
    layout = params.layout
    V = outline_vertices(pose, layout) if vertices is None else vertices
    overlap = plane_overlap(V)
    start, end = edge_ends(V, layout, layout.plane_edges)
    # Broad phase, eager only (a recorded graph keeps one branch; predictor.solvers.graphs.gated
    # gates its calls instead): a row with no vertex at X < 0 has no interval and zero
    # force, so the quadrature runs on the rows that cross, and the others get zero forces
    # at zero points, which add exactly nothing to the residual's sums.
    recording = torch.jit.is_tracing() or torch.compiler.is_compiling()
    rows = None if recording else (overlap > 0).nonzero().flatten()
    if rows is not None and len(rows) < len(V):
        points, normal = _plane_penalty(start[rows], end[rows], contact)
        points = torch.zeros(len(V), *points.shape[1:], dtype=V.dtype).index_copy(0, rows, points)
        normal = torch.zeros(len(V), normal.shape[1], dtype=V.dtype).index_copy(0, rows, normal)
    else:
        points, normal = _plane_penalty(start, end, contact)
    forces = torch.stack((normal, torch.zeros_like(normal)), -1)
    return PlaneContact(points, forces, normal.sum(-1), overlap)


def _plane_penalty(start: torch.Tensor, end: torch.Tensor, contact: ContactParams):
    """The plane's Gauss points (B, E·PLANE_GAUSS, 2) mm and normal forces (B, E·PLANE_GAUSS)
    N on the edges start -> end (B, E, 2): on each edge the interval at X < 0 (X is
    linear along it)."""
    xa, xb = start[..., 0], end[..., 0]
    den = xa - xb
    cross = xa / torch.where(den == 0, 1.0, den)       # where X = 0 along the edge (when it changes sign)
    lo = torch.where(xa < 0, 0.0, torch.where(xb < 0, cross, _EMPTY))
    hi = torch.where(xb < 0, 1.0, torch.where(xa < 0, cross, -_EMPTY))
    points, w = edge_quadrature(start, end, *clip_interval(lo, hi), PLANE_GAUSS)
    return points, contact.plane_stiffness * smooth_penetration(-points[..., 0], contact.smoothing) * w


@dataclass(frozen=True)
class GripperProblem:
    """One gesture problem: everything but the pressures and the unknown tau.

    joint: the joint model (every joint). params: the finger (chain, dimensions, weights),
    its kinematics and joint-weight options (GripperParams). obstacle: the object, or None.
    contact: penalty and friction law. gravity: False drops all weights (the gravity-free
    gesture). approach: (P1, .., PJ) MPa of a grasp's history: the gripper first settles
    there without the object, the object is then brought in and the pressures ramp to the
    target; None ramps from zero with the object present (predictor.solvers.solve).

    Refused with a one-line ValueError: an approach of the wrong length or beyond the box,
    and cap kinematics on a joint model without a cap-rotation head.
    """

    joint: JointModel
    params: GripperParams = GripperParams()
    obstacle: Obstacle | None = None
    contact: ContactParams = ContactParams()
    gravity: bool = True
    approach: tuple[float, ...] | None = None

    def __post_init__(self):
        if self.approach is not None:
            if len(self.approach) != self.n_joints:
                raise ValueError(f"approach {tuple(self.approach)} MPa: give {self.n_joints} pressures, one per "
                                 f"joint of finger {self.params.finger.name!r}")
            check_pressures(torch.as_tensor(self.approach, dtype=torch.float64).reshape(1, -1))
        if self.params.kinematics == "cap" and not self.joint.has_cap_rotation:
            raise ValueError(no_cap_message(self.joint.name))

    @property
    def n_joints(self) -> int:
        return self.params.n_joints

    def astype(self, dtype: torch.dtype) -> "GripperProblem":
        """This problem with its joint model in ``dtype`` (JointModel.astype): pressures and
        tau of that dtype then flow through the kinematics and statics in it (float32 for
        batched throughput; the solvers work in float64)."""
        return dataclasses.replace(self, joint=self.joint.astype(dtype))

    def pose(self, pressures: torch.Tensor, tau: torch.Tensor, face_points: bool = True) -> FingerPose:
        """Forward kinematics of the right finger: pressures (B, J) MPa, tau (B, J, 3)
        (finger_pose; ``face_points`` False: without the outline's sample points, for a
        caller that builds the outline itself)."""
        return finger_pose(self.joint, self.params, pressures, tau, face_points)

    def residual(self, pressures: torch.Tensor, tau: torch.Tensor) -> Statics:
        """Equation-1 residual of the right finger.

        pressures: (B, J) MPa; tau: (B, J, 3) [F1 N, F2 N, M N·mm] per joint (joint frames).
        Returns Statics with residual (B, J, 3) in N, N, N·mm.
        """
        pose = finger_pose(self.joint, self.params, pressures, tau, face_points=False)
        B, dt, params = tau.shape[0], tau.dtype, self.params
        layout = params.layout
        g = 1.0 if self.gravity else 0.0
        down = torch.tensor([0.0, -1.0], dtype=dt)
        # Weight points: candidates [rigid midpoints, then anchor means (lumped) or proximal
        # centres and distal ends (split)], picked in chain order by the cached layout.
        joints = pose.joints
        at_joints = ((joints[:, :, 1:].mean(2),) if layout.joint_weight == "lumped" else
                     (joints[:, :, 0], joints[:, :, -1]))
        w_pts = torch.cat((pose.segments.mean(2),) + at_joints, 1).index_select(1, layout.weight_source)
        w_frc = (g * layout.weights.to(dt)[:, None] * down).expand(B, -1, 2)
        pts, frc, distal = [w_pts], [w_frc], [layout.weight_mask]
        meet = self.contact.plane_stiffness > 0
        V = outline_vertices(pose, layout) if meet or layout.surface == "faces" else None
        if self.obstacle is None:
            contact = ContactState.none(B, dt)
            if layout.surface == "faces":
                pose.points = edge_points(V, layout)   # finger_pose's, from the outline built here
        else:
            contact = contact_loads(pose, params, self.obstacle, self.contact, g * params.object_weight, V)
            pts, frc, distal = pts + [contact.points], frc + [contact.forces], distal + [layout.contact_mask]
            pose = dataclasses.replace(pose, points=contact.points)   # where the object's loads act
        plane = plane_contact(pose, params, self.contact, V) if meet else None
        if plane is not None:
            pts, frc, distal = pts + [plane.points], frc + [plane.forces], distal + [layout.plane_mask]
        pts, frc, distal = torch.cat(pts, 1), torch.cat(frc, 1), torch.cat(distal, 1).to(dt)
        ends = joints[:, :, -1]  # (B, J, 2) distal ends r_10
        # Sums over the K load points distal to each joint: F_i = sum_k d_ik f_k and
        # M_i = sum_k d_ik (p_k - e_i) x f_k = sum_k d_ik (p_k x f_k) - e_i x F_i: no
        # (B, J, K, 2) moment arms are formed (the same sums to ~1e-15 N·mm), and the
        # sums over the K loads are one (J, K) x (K, 3B) product.
        sums = torch.einsum("jk,bkc->bjc", distal, torch.cat((frc, _cross(pts, frc)[..., None]), -1))
        f_sum = sums[..., :2]
        m_sum = sums[..., 2] - _cross(ends, f_sum)
        g_force = rot(pose.theta, tau[..., :2])
        res = torch.cat((g_force - f_sum, (tau[..., 2] - m_sum)[..., None]), -1)
        return Statics(res, pose, contact, plane, V)


#: A joint's reach (its chord, mm) is bounded by this multiple of its length: an
#: upper bound well above the stretch the joint models give in the training box (~1%).
JOINT_REACH = 1.5


def finger_reach(params: GripperParams) -> float:
    """An upper bound (mm) on the distance from the base mount of any finger point: the
    rigid parts' lengths plus JOINT_REACH times each joint's length."""
    return sum(p.length * (JOINT_REACH if p.kind == "joint" else 1.0) for p in params.finger.parts)


def out_of_reach(problem: "GripperProblem") -> bool:
    """True when nothing of either finger can touch the object at any pressure: its
    bounding circle (Obstacle.radius) lies farther than ``finger_reach`` from both
    base mounts (the object is symmetric, so one mount suffices)."""
    ob = problem.obstacle
    if ob is None:
        return False
    mount = 0.5 * problem.params.finger.base_gap
    return math.hypot(ob.x - mount, ob.y) - ob.radius > finger_reach(problem.params)


def scaled(res: torch.Tensor) -> torch.Tensor:
    """(B, J, 3) residual -> (B, 3J) with moments divided by MOMENT_SCALE (loss weights)."""
    scale = torch.tensor([1.0, 1.0, 1.0 / MOMENT_SCALE], dtype=res.dtype)
    return (res * scale).reshape(res.shape[0], -1)


#: (F1, F2, M) half-widths of the box as floats (torch.compile guards a numpy array
#: read inside a graph by its dispatch keys, and fails under inference mode).
_TAU_BOX = tuple(float(v) for v in INPUT_BOX[1:])


@functools.lru_cache(maxsize=8)
def box_scale(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(box, scale) (n,) of n = 3J unknowns: (3 N, 3 N, 100 N·mm) and (1, 1, MOMENT_SCALE)
    per joint (cached, read only: the solvers' Jacobians and steps ask for them)."""
    return (torch.tensor(list(_TAU_BOX) * (n // 3), dtype=torch.float64),
            torch.tensor([1.0, 1.0, MOMENT_SCALE] * (n // 3), dtype=torch.float64))


def range_penalty(tau: torch.Tensor) -> torch.Tensor:
    """Out-of-box penalty residuals (B, 3J) of tau (B, J, 3): PENALTY_WEIGHT·max(0, |tau| -
    box)/scale, with box (3 N, 3 N, 100 N·mm) and scale (1, 1, MOMENT_SCALE); zero inside."""
    box = torch.tensor(_TAU_BOX, dtype=tau.dtype)
    scale = torch.tensor([1.0, 1.0, MOMENT_SCALE], dtype=tau.dtype)
    return (PENALTY_WEIGHT * (tau.abs() - box).clamp_min(0.0) / scale).reshape(tau.shape[0], -1)


def loss(res: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """Per-sample loss (B,): alpha R_Fx² + beta R_Fy² + gamma R_M² summed over joints,
    plus the squared out-of-range penalty."""
    return scaled(res).pow(2).sum(-1) + range_penalty(tau).pow(2).sum(-1)


def residual_norms(res: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, J, 3) -> (force mN (B, J) = 1000·|R_F|, moment N·mm (B, J) = |R_M|)."""
    return 1000.0 * res[..., :2].norm(dim=-1), res[..., 2].abs()
