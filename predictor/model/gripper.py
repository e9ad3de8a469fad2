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
and P < 0 opens it. A calibrated finger file (predictor.cli.calibrate) gives joint i a pressure
gain g_i, offset o_i (MPa) and stiffness scale s_i: the joint model is evaluated at
((g_i P_i + o_i)/s_i, tau_i/s_i), the exact similarity of a joint of modulus s_i E.

Weights (N): a rigid part's at its midpoint; a joint's, with ``joint_weight``
``lumped`` (the paper's), at the mean of its 10 anchors, or ``split`` (the default): half at
its proximal centre O_i, half at its distal end r_10,i (predictor.model.statics says which joint
balances each enters).

The finger's outline (``outline_vertices``, the surfaces that touch, ``surface = faces``):
with the cross-section normal nu = Rot(a + pi/2)·e_x of a part's direction a (global +X
for the hanging right finger, so its -nu side faces the gripper's axis X = 0),

    rigid part of height h from S to E:  corners S -/+ (h/2) nu, E -/+ (h/2) nu
    joint (outer height H, joint_height):  P_m -/+ (H/2) nu_m, m = 0..n,

with P_0 = O_i, P_1..P_n its n anchors (its joint description's, 10 for the paper's
joint) and nu_m the normal of theta_i at m = 0, of the exit angle phi_i at m = n and of
the bisector of the two anchor chords meeting at P_m between (so each joint's band meets
its neighbours' faces). The outline's straight edges are each part's ``inner`` (-nu) and
``outer`` (+nu) faces (a joint's: its n chords) and the last part's distal ``end`` face.
The joint's band is its outer envelope over the cells and caps (height H = 20 mm); its
2.5 mm valleys, 5.6 mm deeper, are bridged: a convex object of least radius of curvature
rho sinks g²/(8 rho) into a valley of width g (0.03 mm for the circle, 0.04 mm for the
ellipse's 17.9 mm ends at the rest gap), which the band neglects, as it neglects the
cells' ballooning (the joint model gives the centre line only). ``surface = centre_line`` keeps the paper's sample points on the parts'
centre lines instead: each rigid part's ``contact_points`` segment midpoints (each
carrying l/n of length) and the n anchors of each joint with ``contact = true`` (each
carrying L/n, L and n its own joint description's: 45.45 mm and 10 for the paper's
joint); the paper's finger gives link (12), joint 2 (10), tip (65).

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
from contract.grasp import OBJECT_WEIGHT
from contract.spec import PRESSURE_LIMIT, check_box, phi_end
from predictor.model.joint import JointModel

KINEMATICS = ("tangent", "cap")
JOINT_WEIGHTS = ("lumped", "split")
#: Where the object touches the finger: its outline's faces, or the paper's sample points on
#: the parts' centre lines (module docstring).
SURFACES = ("faces", "centre_line")
DEFAULT_SURFACE = "faces"
#: Outline edge faces (ChainLayout.edge_face codes): -nu side, +nu side, the fingertip's end.
FACES = ("inner", "outer", "end")
#: Gauss-Legendre points per outline edge: a contact's penalty is integrated over each
#: edge's penetrated interval by this rule (predictor.model.statics), exact for the polynomial
#: penetration profiles of a straight edge against a line or a circle.
EDGE_GAUSS = 6
#: Gauss points per edge of the symmetry-plane contact: X is linear along an edge, so its
#: penalty profile is piecewise quadratic (exact where it lies within the C1 ramp, or
#: beyond it).
PLANE_GAUSS = 3
#: A joint's outline across its chambers: ``band`` (half-height H/2 at every anchor) or
#: ``bulged`` (and the bulge of a pressurised chamber's cells, its joint file's [outline]).
OUTLINES = ("band", "bulged")
DEFAULT_OUTLINE = "bulged"
#: The defaults: the chain that matches the whole-finger FEM (results/validation/finger_h1.8.json:
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


@functools.lru_cache(maxsize=1)
def joint_height() -> float:
    """Outer height H (mm) of the bellow joint at its cells and caps: the default joint
    file's ``geometry.height`` (contract/joints/paper.toml, the surrogate's joint; 20 mm).
    Its outline is the band of half-height H/2 about its centre line."""
    from contract.joint import load_joint as load_joint_file   # numpy only: no FEM imports

    return float(load_joint_file().shape.height)


def _legendre(m: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Gauss-Legendre nodes xi (m,) in [0, 1] and weights (m,) summing to 1."""
    import numpy as np

    x, w = np.polynomial.legendre.leggauss(m)
    with torch.inference_mode(False):   # kept: never an inference tensor, autograd may use it
        return torch.tensor(0.5 * (x + 1.0), dtype=torch.float64), torch.tensor(0.5 * w, dtype=torch.float64)


# The rules the outline uses, built at import: a recorded graph (torch.compile) reads them
# as constants; building one inside it would trace numpy and fail the compiled graph's guards.
_GAUSS_RULES = {m: _legendre(m) for m in (EDGE_GAUSS, PLANE_GAUSS)}


def gauss_rule(m: int = EDGE_GAUSS) -> tuple[torch.Tensor, torch.Tensor]:
    """Gauss-Legendre nodes xi (m,) in [0, 1] and weights (m,) summing to 1 (read only;
    EDGE_GAUSS and PLANE_GAUSS are built at import, another m on first use)."""
    if m not in _GAUSS_RULES:
        _GAUSS_RULES[m] = _legendre(m)
    return _GAUSS_RULES[m]


def part_names(finger: FingerSpec) -> tuple[str, ...]:
    """One name per part, in chain order: joints ``joint1``..``jointJ``; the last part, if
    rigid, ``tip``; the other rigid parts ``link`` (one) or ``link1``, ``link2``, ...
    (the paper's finger: joint1, link, joint2, tip)."""
    last_rigid = finger.parts[-1].kind == "rigid"
    links = sum(p.kind == "rigid" for p in finger.parts) - int(last_rigid)
    names, j, r = [], 0, 0
    for k, part in enumerate(finger.parts):
        if part.kind == "joint":
            j += 1
            names.append(f"joint{j}")
        elif k == len(finger.parts) - 1:
            names.append("tip")
        else:
            r += 1
            names.append("link" if links == 1 else f"link{r}")
    return tuple(names)


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

    The outline (module docstring; ``outline_vertices`` stacks its V vertices: per joint
    its n + 1 inner then n + 1 outer band vertices (band_size), then per rigid part its
    corners S-, E-, S+, E+): ``edge_start``, ``edge_end`` (E,) vertex indices of each straight edge,
    ``edge_part`` (E,) its part, ``edge_face`` (E,) its face (FACES), ``object_edges``
    (Eo,) the edges the object can touch (parts with ``contact``). With ``surface`` faces
    the contact points are EDGE_GAUSS Gauss points per object edge, so ``contact_part``,
    ``contact_face`` and ``contact_mask`` are per Gauss point (``contact_length`` is
    unused: each point's length comes with its interval). ``plane_edges`` (Ep,): the
    inner and end edges, which meet the mirror finger at X = 0 (the outer faces face
    away from it), and ``plane_mask`` (J, Ep·PLANE_GAUSS) that of their Gauss points.
    ``joint_half_height`` H/2 (mm, ``joint_height``) and ``rigid_half_height`` (R,) mm:
    the outline's half heights, read once here so that a recorded graph sees constants.
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
    surface: str = DEFAULT_SURFACE
    edge_start: torch.Tensor = None
    edge_end: torch.Tensor = None
    edge_part: torch.Tensor = None
    edge_face: torch.Tensor = None
    object_edges: torch.Tensor = None
    contact_face: torch.Tensor = None
    plane_edges: torch.Tensor = None
    plane_mask: torch.Tensor = None
    rigid_half_height: torch.Tensor = None
    joint_half_height: float = None


def band_size(finger: FingerSpec) -> int:
    """Vertices of each joint's band in ``outline_vertices``: its n + 1 inner then n + 1
    outer points, n the joints' anchor count (their description's; 10 for the paper's
    joint). One joint model poses every joint of a finger, so its joints share one count;
    ValueError (one line) for a finger whose joints differ."""
    counts = sorted({part.spec.anchors for part in finger.parts if part.kind == "joint"})
    if len(counts) != 1:
        raise ValueError(f"finger {finger.name!r}: its joints have {counts} anchors; the outline needs one count")
    return 2 * (counts[0] + 1)


def outline_edges(finger: FingerSpec) -> list[tuple[int, int, int, int, bool]]:
    """The outline's straight edges of ``finger`` in chain order: (start vertex, end
    vertex, part, face code, the object can touch it) (ChainLayout's vertex order)."""
    J, size = finger.n_joints, band_size(finger)
    n = size // 2 - 1
    edges, j, r = [], 0, 0
    for k, part in enumerate(finger.parts):
        last = k == len(finger.parts) - 1
        if part.kind == "joint":
            inner, outer = size * j, size * j + n + 1
            touch = bool(part.contact)
            edges += [(inner + m, inner + m + 1, k, 0, touch) for m in range(n)]
            edges += [(outer + m, outer + m + 1, k, 1, touch) for m in range(n)]
            if last:
                edges.append((inner + n, outer + n, k, 2, touch))
            j += 1
        else:
            base = size * J + 4 * r
            touch = part.contact_points > 0
            edges += [(base, base + 1, k, 0, touch), (base + 2, base + 3, k, 1, touch)]
            if last:
                edges.append((base + 1, base + 3, k, 2, touch))
            r += 1
    return edges


def _part_mask(parts, joint_parts) -> torch.Tensor:
    """(J, K) 1.0 where a load on part parts[k] enters joint i's balance (part after it)."""
    return torch.tensor([[float(k > jp) for k in parts] for jp in joint_parts], dtype=torch.float64).reshape(
        len(joint_parts), len(parts))


@functools.lru_cache(maxsize=16)
def chain_layout(finger: FingerSpec, joint_weight: str = "lumped", surface: str = DEFAULT_SURFACE) -> ChainLayout:
    """The ChainLayout of ``finger`` (module docstring: where weights act and which joint
    balances each load enters; a load on part k enters joint i's balance when k is distal
    to joint i, i.e. k > part index of joint i; a split joint's distal half also enters
    its own joint's balance, with zero moment arm; where the object can touch, by
    ``surface``)."""
    with torch.inference_mode(False):   # cached: never inference tensors, autograd may use them
        return _chain_layout(finger, joint_weight, surface)


def _chain_layout(finger: FingerSpec, joint_weight: str, surface: str) -> ChainLayout:
    """chain_layout, built (outside inference mode)."""
    if joint_weight not in JOINT_WEIGHTS:
        raise ValueError(f"joint weight {joint_weight!r}: use {' or '.join(JOINT_WEIGHTS)}")
    if surface not in SURFACES:
        raise ValueError(f"contact surface {surface!r}: use {' or '.join(SURFACES)}")
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
    c_part, c_len, c_face = [], [], []
    edges = outline_edges(finger)
    object_edges = [e for e, edge in enumerate(edges) if edge[4]]
    if surface == "faces":
        c_part = [edges[e][2] for e in object_edges for _ in range(EDGE_GAUSS)]
        c_face = [edges[e][3] for e in object_edges for _ in range(EDGE_GAUSS)]
    else:
        for k, part in enumerate(finger.parts):
            # A joint's anchors are its own description's (count and length: contract.finger).
            n = part.spec.anchors if part.kind == "joint" and part.contact else getattr(part, "contact_points", 0)
            if n:
                c_part += [k] * n
                c_len += [part.length / n] * n
                c_face += [-1] * n
    mask = lambda rows: torch.tensor(rows, dtype=torch.float64).reshape(J, -1)  # noqa: E731
    w_mask = mask([[float(ld[2][i]) for ld in loads] for i in range(J)])
    c_mask = _part_mask(c_part, jp)
    long = lambda v: torch.tensor(v, dtype=torch.long)  # noqa: E731
    return ChainLayout(
        joint_parts=jp,
        joint_weight=joint_weight,
        weight_source=long([ld[0] for ld in loads]),
        weights=torch.tensor([ld[1] for ld in loads], dtype=torch.float64),
        weight_mask=w_mask,
        contact_part=long(c_part),
        contact_length=torch.tensor(c_len, dtype=torch.float64),
        contact_mask=c_mask,
        full_mask=torch.cat((w_mask, c_mask), 1),
        surface=surface,
        edge_start=long([e[0] for e in edges]),
        edge_end=long([e[1] for e in edges]),
        edge_part=long([e[2] for e in edges]),
        edge_face=long([e[3] for e in edges]),
        object_edges=long(object_edges),
        contact_face=long(c_face),
        plane_edges=long([e for e, edge in enumerate(edges) if edge[3] != 1]),
        plane_mask=_part_mask([e[2] for e in edges if e[3] != 1 for _ in range(PLANE_GAUSS)], jp),
        joint_half_height=0.5 * joint_height(),
        rigid_half_height=torch.tensor([0.5 * p.height for p in finger.parts if p.kind == "rigid"],
                                       dtype=torch.float64))


@dataclass(frozen=True)
class GripperParams:
    """The finger (a FingerSpec: chain, lengths, weights, base mounts, contact sampling),
    the object's weight (N) and the two modelling options of the chain:

    kinematics: ``tangent`` (the paper's, a part leaves joint i along the chord of its last
    two anchors) or ``cap`` (along the distal cap face, the joint model's cap rotation);
    joint_weight: ``lumped`` (at the mean of the anchors) or ``split`` (half at each end);
    surface: where the object touches, ``faces`` (the outline, the default) or
    ``centre_line`` (the paper's sample points on the parts' centre lines);
    outline: a joint's outline, ``band`` or ``bulged`` (its pressurised cells' bulge,
    ``joint_bulge``).

    Paper defaults (docs/gripper.md, contract/fingers/paper.toml; Figure S4 is unavailable): link
    60 mm, tip 65 mm, base mounts 50 mm apart, which give the paper's 50 mm free tip
    opening and ≈3 mm of tip travel per degree of phi_1. Weights: joint 0.09 N, link 0.04 N,
    tip 0.06 N, object 0.2 N.
    """

    finger: FingerSpec = field(default_factory=default_finger)
    object_weight: float = OBJECT_WEIGHT
    kinematics: str = DEFAULT_KINEMATICS
    joint_weight: str = DEFAULT_JOINT_WEIGHT
    surface: str = DEFAULT_SURFACE
    outline: str = DEFAULT_OUTLINE

    def __post_init__(self):
        if self.kinematics not in KINEMATICS:
            raise ValueError(f"kinematics {self.kinematics!r}: use {' or '.join(KINEMATICS)}")
        if self.joint_weight not in JOINT_WEIGHTS:
            raise ValueError(f"joint weight {self.joint_weight!r}: use {' or '.join(JOINT_WEIGHTS)}")
        # Built once per params (not a field: eq, hash and repr ignore it); the residual reads
        # it on every evaluation.
        object.__setattr__(self, "_layout", chain_layout(self.finger, self.joint_weight, self.surface))
        object.__setattr__(self, "_calibration", joint_calibration(self.finger))
        if self.outline not in OUTLINES:
            raise ValueError(f"outline {self.outline!r}: use {' or '.join(OUTLINES)}")
        object.__setattr__(self, "_bulge", joint_bulge(self.finger) if self.outline == "bulged" else None)

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
    def bulge(self) -> tuple | None:
        """The joints' bulge tables (joint_bulge) with outline ``bulged``, else None."""
        return self._bulge

    @property
    def base_gap(self) -> float:
        """mm between the two fingers' base mounts."""
        return self.finger.base_gap

    @property
    def tip_length(self) -> float:
        """Length (mm) of the finger's last part (the rigid tip of the paper's finger)."""
        return self.finger.parts[-1].length

    def describe(self) -> str:
        """One line: the finger's name and its options (for messages)."""
        surface = "" if self.surface == DEFAULT_SURFACE else f", contact on the {self.surface.replace('_', ' ')}"
        return (f"finger {self.finger.name!r}, {self.kinematics} kinematics, {self.joint_weight} joint weights, "
                f"{self.outline} outline{surface}")


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
SIZE = {"size": True}  # FingerPose field metadata: lengths (mm) a mirror keeps, or None


@dataclass
class FingerPose:
    """Global geometry of one finger, all (B, ...) mm / rad, for the chain ``finger``.

    joints: (B, J, 11, 2) polylines, proximal centre then the 10 anchors of each joint.
    segments: (B, R, 2, 2) start and end point of each rigid part, base to tip.
    theta: (B, J) proximal orientation of each joint; phi: (B, J) its exit angle (the
    direction the next part leaves at). points: (B, K, 2) contact sample points in chain
    order (ChainLayout.contact_part says which part each lies on): on the centre lines
    (surface centre_line), or the Gauss points of the object edges of the outline
    (surface faces: over whole edges from ``finger_pose``, over each edge's part inside
    the object in the pose of a GripperProblem.residual). finger: the FingerSpec
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
    band: torch.Tensor | None = field(default=None, metadata=SIZE)

    def _fields(self, fn) -> "FingerPose":
        """A FingerPose of fn(field, value) over every field but the static ones and a
        missing band."""
        return FingerPose(**{f.name: v if f.metadata.get("static") or v is None else fn(f, v)
                             for f in fields(self) for v in (getattr(self, f.name),)})

    def _map(self, points, angles=None, sizes=None) -> "FingerPose":
        """Apply points(v) to every point field, angles(v) (default: points) to the angles
        and sizes(v) (default: points) to the band."""
        angles, sizes = angles or points, sizes or points
        return self._fields(lambda f, v: (angles if f.metadata.get("angle") else
                                          sizes if f.metadata.get("size") else points)(v))

    def mirrored(self) -> "FingerPose":
        """The left finger: X -> -X for points, angle a -> pi - a (the band as it is)."""
        return self._map(lambda v: v * v.new_tensor([-1.0, 1.0]), lambda a: math.pi - a, lambda v: v)

    def masked(self, ok: torch.Tensor) -> "FingerPose":
        """NaN in every field where ok (B,) bool is False (a non-converged gesture)."""
        return self._map(lambda v: nan_unless(ok, v))

    def with_rows(self, rows: torch.Tensor, other: "FingerPose") -> "FingerPose":
        """A copy whose ``rows`` (B,) bool come from other (a pose of rows.sum() samples)."""
        return self._fields(lambda f, v: with_rows(v, rows, getattr(other, f.name)))

    def rows(self, index) -> "FingerPose":
        """The pose of samples ``index`` (a bool mask or indices over B)."""
        return self._fields(lambda f, v: v[index])

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
        # the layout whose sample count this pose has (the pose does not carry its surface)
        K = self.points.shape[1]
        layout = next(lay for lay in (chain_layout(self.finger, surface=s) for s in SURFACES[::-1])
                      if len(lay.contact_part) == K)
        sel = (layout.contact_part == part).nonzero().flatten()
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


def joint_bulge(finger: FingerSpec) -> tuple[tuple[torch.Tensor, torch.Tensor], ...]:
    """Per joint of ``finger``, its [outline] table (contract.joint) as the hinges of a
    piecewise-linear law in |P|: (knots (K,) MPa: 0 and the table's pressures but the last,
    slope changes (2, K, n + 1) mm/MPa) over the band's n + 1 vertices, side 0 the pressurised chamber's, side 1 the
    other's, such that shift(|P|) = sum_k relu(|P| - knot_k) slope_k is the table's value
    at every tabled pressure, 0 at P = 0 and linear beyond the last (joints without a table:
    zero). Vertex m takes the larger bulge of the chords on either side of it, m - 1 and m
    (the ends: their one chord), so the band's edge over chord k lies beyond its material."""
    out = []
    for part in finger.parts:
        if part.kind != "joint":
            continue
        n = part.spec.anchors
        table = part.spec.outline
        if table is None:
            out.append((torch.zeros(1, dtype=torch.float64), torch.zeros(2, 1, n + 1, dtype=torch.float64)))
            continue
        pressures, *sides = table
        x = torch.tensor((0.0,) + pressures, dtype=torch.float64)
        chords = torch.tensor(sides, dtype=torch.float64)                     # (2, K, n)
        before = torch.cat((chords[..., :1], chords), -1)                     # chord m - 1 of vertex m
        after = torch.cat((chords, chords[..., -1:]), -1)                     # chord m
        vertex = torch.maximum(before, after)                                 # (2, K, n + 1)
        y = torch.cat((torch.zeros(2, 1, n + 1, dtype=torch.float64), vertex), 1)
        slope = (y[:, 1:] - y[:, :-1]) / (x[1:] - x[:-1])[:, None]            # (2, K, n + 1)
        change = slope - torch.cat((torch.zeros_like(slope[:, :1]), slope[:, :-1]), 1)
        out.append((x[:-1], change))
    return tuple(out)


def band_half_heights(pressures: torch.Tensor, bulge, half_height: float) -> torch.Tensor:
    """The joints' band half-heights (B, J, 2, n + 1) mm at effective pressures (B, J) MPa:
    side 0 the inner (-nu) face, side 1 the outer (+nu), H/2 plus the bulge of ``bulge``
    (joint_bulge). P > 0 pressurises the chamber on the +nu side (predictor.model.joint), so the
    outer face takes the pressurised bulge where P > 0, the inner face where P < 0."""
    rows = []
    for j, (knots, change) in enumerate(bulge):
        p = pressures[:, j]
        hinge = torch.relu(p.abs()[:, None] - knots.to(p.dtype))              # (B, K)
        press, other = torch.einsum("bk,skv->sbv", hinge, change.to(p.dtype))  # (B, n + 1) each
        opened = (p < 0)[:, None]
        rows.append(torch.stack((torch.where(opened, press, other), torch.where(opened, other, press)), 1))
    return half_height + torch.stack(rows, 1)


def joint_calibration(finger: FingerSpec) -> tuple[tuple[float, ...], ...] | None:
    """(gains, offsets MPa, stiffness scales), one per joint, of a calibrated finger file
    (contract.finger; predictor.cli.calibrate writes them), or None when every joint is the
    joint model as it is."""
    joints = [p for p in finger.parts if p.kind == "joint"]
    if not any(p.calibrated for p in joints):
        return None
    return tuple(tuple(getattr(p, k) for p in joints) for k in ("pressure_gain", "pressure_offset", "stiffness_scale"))


def finger_pose(joint: JointModel, params: GripperParams, pressures: torch.Tensor, tau: torch.Tensor,
                face_points: bool = True) -> FingerPose:
    """Forward kinematics of the right finger (module docstring).

    pressures: (B, J) MPa [P1 .. PJ]; tau: (B, J, 3) joint loads [F1 N, F2 N, M N·mm] in
    each joint's undeformed frame. Returns the FingerPose (global mm, rad). With surface
    ``faces`` its points are ``edge_points`` (not without ``face_points``: the residual
    sets them from the outline it builds anyway).
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
    pose = FingerPose(
        joints=torch.stack(joints, 1),
        segments=torch.stack(segments, 1) if segments else torch.zeros(B, 0, 2, 2, dtype=tau.dtype),
        theta=torch.stack(theta, -1),
        phi=torch.stack(phi, -1),
        points=torch.cat(points, 1) if points else torch.zeros(B, 0, 2, dtype=tau.dtype),
        finger=finger,
        band=None if params.bulge is None else band_half_heights(inputs[..., 0], params.bulge,
                                                                 params.layout.joint_half_height),
    )
    if params.surface == "faces" and face_points:
        pose.points = edge_points(outline_vertices(pose, params.layout), params.layout)
    return pose


def edge_points(vertices: torch.Tensor, layout: ChainLayout) -> torch.Tensor:
    """The object edges' Gauss points (B, Eo·EDGE_GAUSS, 2) mm over whole edges of the
    outline ``vertices`` (B, V, 2): a pose's points with surface ``faces``."""
    start, end = edge_ends(vertices, layout, layout.object_edges)
    xi = gauss_rule()[0].to(vertices.dtype)
    return (start[:, :, None] + xi[:, None] * (end - start)[:, :, None]).flatten(1, 2)


def outline_vertices(pose: FingerPose, layout: ChainLayout) -> torch.Tensor:
    """The outline's vertices (B, V, 2) mm of a pose (module docstring; ChainLayout's
    order: per joint its n + 1 inner then n + 1 outer band vertices (band_size), then per
    rigid part its corners S-, E-, S+, E+, where - is the inner (-nu) side). A joint's band
    is H/2 wide on both faces, or the pose's ``band`` (B, J, 2, n + 1) half-heights where it
    has one (outline ``bulged``)."""
    P = pose.joints                                     # (B, J, n + 1, 2) O_i and the anchors
    chord = P[:, :, 1:] - P[:, :, :-1]
    chord = chord / chord.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    bisector = chord[:, :, :-1] + chord[:, :, 1:]
    bisector = bisector / bisector.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    d = torch.cat((_unit(pose.theta)[:, :, None], bisector, _unit(pose.phi)[:, :, None]), 2)
    nu = torch.stack((-d[..., 1], d[..., 0]), -1)
    if pose.band is None:
        inner = outer = layout.joint_half_height
    else:
        inner, outer = pose.band[:, :, 0, :, None], pose.band[:, :, 1, :, None]
    joints = torch.cat((P - inner * nu, P + outer * nu), 2).flatten(1, 2)
    S, E = pose.segments[:, :, 0], pose.segments[:, :, 1]        # (B, R, 2)
    u = (E - S) / (E - S).norm(dim=-1, keepdim=True).clamp_min(1e-12)
    nr = layout.rigid_half_height.to(S.dtype)[:, None] * torch.stack((-u[..., 1], u[..., 0]), -1)
    rigid = torch.stack((S - nr, E - nr, S + nr, E + nr), 2).flatten(1, 2)
    return torch.cat((joints, rigid), 1)


def edge_ends(vertices: torch.Tensor, layout: ChainLayout, edges: torch.Tensor | None = None):
    """(start, end) (B, E, 2) mm of the outline edges ``edges`` (indices, default all) of
    ``outline_vertices``."""
    i0, i1 = layout.edge_start, layout.edge_end
    if edges is not None:
        i0, i1 = i0.index_select(0, edges), i1.index_select(0, edges)
    return vertices.index_select(1, i0), vertices.index_select(1, i1)
