"""The grasp contract: the rigid objects and the contact law that the predictor and the
finger FEM share (docs/gripper.md §7-9, docs/fem-grasps.md).

Plain numpy (never torch or dolfinx), so both layers read the law from one owner.

Objects (``parse_object``, the spec ``kind[:key=value,...]`` of ``--object``; lengths mm,
``deg`` degrees): a circle (r), an ellipse (semi-axes a, b) or a rectangle (full w, h,
corner radius rc) centred at (x, y) in the gripper's global plane (X horizontal, Y up,
base on Y = 0), turned by deg. The model mirrors the right finger, so an object is centred
on X = 0 and mirror-symmetric about it (``object_error``).

Contact law, per length of the finger's planar outline (the predictor) or per area of the
finger's surface (the FEM, whose finger is ``width`` deep: k_area = k_c / width):

    N = k_c · s(max(0, -d)) along +n,    s(q) = q²/(2 delta) (q < delta), q - delta/2
    lambda = (W/2 + Σ N n_y) / Σ N t_y,  friction -clip(lambda, -mu, mu) N t

with d, n the object's signed distance (negative inside) and outward normal, t the
object's tangent turned upwards, W the object's weight (each of the two mirror fingers
lifts W/2); the grasp slips when |lambda| > mu or nothing touches. friction_use = |lambda|/mu.

Where the fingers meet: the two mirror fingers touch at X = 0, and each pushes the other
along X only (frictionless by symmetry). The right finger's faces towards the plane (its
inner and end faces) carry the same ramp against it, with its own stiffness:

    N = k_p · s(max(0, -X))  along +X      (per mm of outline; the FEM: per mm², k_p / width)
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

#: k_c: penalty stiffness, N per mm of penetration per mm of finger outline (N/mm²).
CONTACT_STIFFNESS = 2.0
#: k_p: penalty stiffness of the plane X = 0 where the fingers meet (N per mm of overlap per
#: mm of finger outline, N/mm²): 100 times k_c, so that where the fingers meet at a corner of
#: the outline (a force ~ k_p q²) the overlap stays within 0.1 mm (docs/gripper.md §7).
PLANE_STIFFNESS = 200.0
#: delta: width (mm) of the penalty's C1 ramp s(q).
CONTACT_SMOOTHING = 0.05
#: mu: Coulomb friction coefficient of the finger on the object.
FRICTION = 0.3
#: W: the object's weight (N).
OBJECT_WEIGHT = 0.2
#: A rectangle's default corner radius (mm): the rounded rectangle is the set within it of
#: the rectangle shrunk by it, so its signed distance is C1 to that depth. A sharp corner has
#: no normal: inside it the nearest face, and with it the contact force's direction, jumps
#: by 90 degrees across the diagonal, which stalls a ramp where a corner presses on the
#: finger (issue 36 §4).
RECTANGLE_CORNER = 1.0
#: Default approach gesture of a grasp (MPa, joint 1 then the others at 0): the fingers
#: open there before the object is brought in.
APPROACH_P1 = -0.15

SIZE_RANGE = (0.1, 500.0)      # mm, half sizes
Y_RANGE = (-1000.0, 1000.0)    # mm, the centre's height

_DEFAULTS = {
    "circle": dict(a=30.0, b=30.0, y=-195.0),
    "ellipse": dict(a=35.0, b=25.0, y=-195.0),
    "rectangle": dict(a=30.0, b=25.0, y=-195.0),
}
_KEYS = {
    "circle": {"r": ("a", "b"), "x": ("x",), "y": ("y",), "deg": ("angle",)},
    "ellipse": {"a": ("a",), "b": ("b",), "x": ("x",), "y": ("y",), "deg": ("angle",)},
    "rectangle": {"w": ("a",), "h": ("b",), "x": ("x",), "y": ("y",), "deg": ("angle",), "rc": ("corner",)},
}


def approach_for(n_joints: int) -> tuple[float, ...]:
    """The default approach gesture (MPa) of an n-joint finger: joint 1 at APPROACH_P1."""
    return (APPROACH_P1,) + (0.0,) * (n_joints - 1)


@dataclass(frozen=True)
class ObjectSpec:
    """A rigid object in the global plane: kind circle | ellipse | rectangle; a, b the
    radius (circle), semi-axes (ellipse) or half width and half height (rectangle), mm;
    centre (x, y) mm; angle rad (counter-clockwise); corner: a rectangle's corner radius
    (mm). Refused with a one-line ValueError: ``object_error``."""

    kind: str = "circle"
    a: float = 30.0
    b: float = 30.0
    x: float = 0.0
    y: float = -195.0
    angle: float = 0.0
    corner: float = RECTANGLE_CORNER

    def __post_init__(self):
        why = object_error(self)
        if why:
            raise ValueError(why)

    def describe(self) -> str:
        """One line for messages, in the spec's own keys: ``circle r=30 mm at y=-195 mm``."""
        turn = f", turned {math.degrees(self.angle):g} deg" if self.angle else ""
        size = {"circle": f"r={self.a:g}", "ellipse": f"a={self.a:g}, b={self.b:g}",
                "rectangle": f"w={2 * self.a:g}, h={2 * self.b:g}, rc={self.corner:g}"}.get(self.kind, "")
        return f"{self.kind} {size} mm at y={self.y:g} mm{turn}"

    def local(self, points: np.ndarray) -> np.ndarray:
        """Global points (..., 2) mm in the object's frame (centre, axes)."""
        q = np.asarray(points, dtype=float) - (self.x, self.y)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return q @ np.array([[c, -s], [s, c]])

    def outline(self, n: int = 720) -> np.ndarray:
        """(n, 2) points (mm, global) of the boundary, counter-clockwise, for figures: the
        ellipse (a cos t, b sin t), or the rounded rectangle's four corner arcs of radius
        ``corner`` about (±(a - corner), ±(b - corner)), its sides the chords between
        them; turned by the angle and moved to the centre (``local``'s inverse)."""
        t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
        if self.kind in ("circle", "ellipse"):
            q = np.column_stack([self.a * np.cos(t), self.b * np.sin(t)])
        else:
            # each quarter of t goes round one corner's arc; its centre is in that quadrant
            centre = np.column_stack([np.sign(np.cos(t + 1e-12)) * (self.a - self.corner),
                                      np.sign(np.sin(t + 1e-12)) * (self.b - self.corner)])
            q = centre + self.corner * np.column_stack([np.cos(t), np.sin(t)])
        c, s = math.cos(self.angle), math.sin(self.angle)
        return q @ np.array([[c, s], [-s, c]]) + (self.x, self.y)

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """d (...) mm of global points (..., 2), negative inside: exact for the circle and
        the rounded rectangle, first order (g/|grad g|) for the ellipse."""
        q = self.local(points)
        if self.kind == "circle":
            return np.linalg.norm(q, axis=-1) - self.a
        if self.kind == "ellipse":
            ab2 = np.array([self.a ** 2, self.b ** 2])
            return ((q * q / ab2).sum(-1) - 1.0) / np.linalg.norm(2.0 * q / ab2, axis=-1).clip(1e-12)
        e = np.abs(q) - (self.a, self.b) + self.corner
        return np.linalg.norm(e.clip(0.0), axis=-1) + e.max(-1).clip(max=0.0) - self.corner


def object_error(ob: ObjectSpec) -> str | None:
    """Why the mirrored model cannot represent ``ob`` (one line), or None: an unknown kind,
    a value that is not finite, a half size outside SIZE_RANGE, a corner radius beyond half
    the shorter side, a centre off X = 0 or beyond Y_RANGE, a turn that breaks the mirror
    symmetry (an ellipse or rectangle by other than a multiple of 90 degrees)."""
    if ob.kind not in _KEYS:
        return f"unknown object kind {ob.kind!r} (use circle, ellipse or rectangle)"
    for name, v in dict(size=ob.a, size_b=ob.b, x=ob.x, y=ob.y, angle=ob.angle, corner=ob.corner).items():
        if not math.isfinite(v):
            return f"object {name} = {v}: not a finite number"
    lo, hi = SIZE_RANGE
    for v in (ob.a, ob.b):
        if not lo <= v <= hi:
            return (f"object size {2 * v:g} mm ({ob.kind} half size {v:g} mm) is outside the model's "
                    f"[{lo:g}, {hi:g}] mm half-size range")
    if ob.kind == "rectangle" and not 0.0 <= ob.corner <= min(ob.a, ob.b):
        return (f"rectangle corner radius rc = {ob.corner:g} mm is outside [0, {min(ob.a, ob.b):g}] mm "
                "(0 to half the shorter side)")
    if ob.x != 0.0:
        return (f"object centre x = {ob.x:g} mm: the model mirrors the right finger, so it represents objects "
                "on the gripper's axis only (x = 0)")
    if not Y_RANGE[0] <= ob.y <= Y_RANGE[1]:
        return f"object centre y = {ob.y:g} mm is outside [{Y_RANGE[0]:g}, {Y_RANGE[1]:g}] mm"
    if ob.kind != "circle" and abs(math.sin(2.0 * ob.angle)) > 1e-12:
        return (f"object turned by {math.degrees(ob.angle):g} deg: the model mirrors the right finger, so an "
                f"{ob.kind} must stay symmetric about X = 0 (deg a multiple of 90)")
    return None


def _field(spec: str, kind: str, item: str, seen: set) -> tuple[str, float]:
    """(key, value in model units) of one ``key=value`` item of an object spec."""
    key, eq, text = (part.strip() for part in item.partition("="))
    if not eq or key not in _KEYS[kind]:
        raise ValueError(f"bad object field {item!r} in {spec!r}: {kind} takes {', '.join(_KEYS[kind])}")
    if key in seen:
        raise ValueError(f"object key {key!r} given twice in {spec!r}: give each key once")
    seen.add(key)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"{key}={text} in object {spec!r} is not a finite number")
    if key == "rc" and value < 0:
        raise ValueError(f"rc={text} in object {spec!r}: a corner radius is >= 0 (mm)")
    if _KEYS[kind][key][0] in ("a", "b") and value <= 0:
        raise ValueError(f"{key}={text} in object {spec!r}: sizes must be positive (mm)")
    if key == "deg":
        return key, math.radians(value)
    return key, 0.5 * value if key in ("w", "h") else value


def parse_object(spec: str) -> ObjectSpec:
    """Parse ``kind[:key=value,...]`` (module docstring), e.g. ``circle:r=30,y=-230``,
    ``rectangle:w=60,h=50,y=-245,rc=1``; ValueError with a one-line reason naming the
    offending item (unknown kind or key, a key twice, not a finite number, a size <= 0,
    an object the model cannot represent)."""
    kind, _, rest = spec.strip().partition(":")
    kind = kind.strip().lower()
    if kind not in _KEYS:
        raise ValueError(f"unknown object {kind!r} in {spec!r}: use circle, ellipse or rectangle")
    fields, seen = dict(kind=kind, **_DEFAULTS[kind]), set()
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, value = _field(spec, kind, item, seen)
        for name in _KEYS[kind][key]:
            fields[name] = value
    try:
        return ObjectSpec(**fields)
    except ValueError as exc:
        raise ValueError(f"object {spec!r}: {exc}") from None


def friction_ratio(weight: float, normal_y: float, normal_t: float) -> float:
    """lambda = (W/2 + Σ N n_y) / Σ N t_y (module docstring) from W (N) and the sums
    Σ N n_y, Σ N t_y (N) over one finger; ±1e3 (the sign of the numerator) when nothing
    carries tangentially (Σ N t_y <= 1e-9 N), as the predictor's."""
    num = 0.5 * weight + normal_y
    if normal_t > 1e-9:
        return num / normal_t
    return math.copysign(1e3, num)


@dataclass(frozen=True)
class GraspCase:
    """One grasp: the object's spec (contract.grasp.parse_object), the target pressures
    (MPa) and the region it stands for."""

    spec: str
    p1: float
    p2: float
    region: str = "given"

    @property
    def name(self) -> str:
        return f"{re.sub(r'[^A-Za-z0-9.+-]+', '-', self.spec.strip().replace('=', ''))}_{self.p1:g}_{self.p2:g}"


#: The grasp validation's cases (fem.studies.grasp_cases, ``make grasp-fem``; issue 36 §3), the table
#: the report judges its targets over: the paper's six grasps and ten from the predictor's
#: atlases with the outline contact and the plane X = 0 (results/predictor/atlas_*.json,
#: 61 x 61, committed surrogate; the 12-step reference ramp gives the same state and friction
#: use at each). Comments: the atlas' state, friction use |lambda|/mu, normal force and where
#: on the object the tip's inner face touches.
GRASP_CASES = [
    GraspCase("circle", 0.2, 0.3, "paper"),         # holds, 0.08, 0.448 N, tip inner face
    GraspCase("circle", 0.3, 0.2, "paper"),         # holds, 0.63, 0.554 N
    GraspCase("ellipse", 0.2, 0.3, "paper"),        # holds, 0.14, 0.474 N
    GraspCase("ellipse", 0.3, 0.2, "paper"),        # holds, 0.73, 0.572 N
    GraspCase("rectangle", 0.2, 0.3, "paper"),      # holds, 0.80, 0.416 N, lower half of its side
    GraspCase("rectangle", 0.3, 0.2, "paper"),      # holds, 0.58, 0.573 N, mid-face
    # circle: the boundary runs from (0.3, 0.14) to (-0.04, 0.3)
    GraspCase("circle", 0.1, 0.21, "hold, near the boundary"),      # holds, 0.895, 0.262 N (at P2 0.2: 0.97)
    GraspCase("circle", 0.2, 0.12, "slip, near the boundary"),      # slips, 1.17, 0.343 N
    GraspCase("circle", 0.1, -0.1, "slip"),        # slips, 3.91, 0.116 N: joint 2 bent outwards, touches high
    # ellipse: joint 1 at negative pressure still holds, first contact late (-0.1, 0.1) MPa
    GraspCase("ellipse", -0.05, 0.3, "hold, near the boundary"),    # holds, 0.81, 0.200 N
    GraspCase("ellipse", 0.2, 0.15, "slip, near the boundary"),     # slips, 1.07, 0.377 N
    GraspCase("ellipse", 0.0, 0.1, "slip"),        # slips, 3.16, 0.108 N
    # rectangle: the tip's inner face meets its upper corner (y -172 mm) at low P2, lies flat on
    # its side in between, meets its lower corner (y -214 mm) at high P2; between two hold
    # regions a bay of slips at P1 0.16-0.19, P2 0.16-0.22
    GraspCase("rectangle", 0.2, 0.12, "hold, near the boundary"),   # holds, 0.91, 0.413 N, upper corner
    GraspCase("rectangle", 0.18, 0.14, "hold, near the boundary"),  # holds, 0.90, 0.371 N, flat (y -177 mm)
    GraspCase("rectangle", 0.18, 0.18, "slip, near the boundary"),  # slips, 1.085, 0.307 N, lower corner, the bay
    GraspCase("rectangle", 0.1, 0.1, "slip"),      # slips, 1.52, 0.236 N, upper corner
]
