"""Measurement files for the calibration (predictor.calibration.model, docs/calibration.md).

A JSON file, format tag ``softjoint-observations/1``. Top level: ``problem``, what was
measured: ``"gripper"`` (the default when absent: the two mirror fingers meeting at the
plane X = 0, predictor.cli.gesture's problem) or ``"finger"`` (a lone finger, nothing at
X = 0: statics.apart; the whole-finger FEM cases are one); and ``observations``, a list
of observed gestures of the right finger, each with

    pressures   [P1, .., PJ] MPa, |P| <= 0.3, one per joint of the finger
    gravity     true | false (default true)
    object      an object spec (contract.grasp.parse_object) or null (default)
    tip         {"x": mm, "y": mm, "sigma_mm": mm}            the fingertip (end of last part)
    tip_angle   {"deg": deg, "sigma_deg": deg}                the last part's direction
    markers     [{"part": k, "s": mm, "x": mm, "y": mm, "sigma_mm": mm}, ...]
                a point on part k (1-based, chain order) s mm from its proximal end
                along the undeformed part (0 <= s <= the part's length)

in the measurement frame (a camera's, say; the calibration may fit the rigid transform
from the gripper's frame to it). At least one of tip, tip_angle, markers per observation.
Every error is an ObservationError (a ValueError) of one line naming the file, the key
and the allowed range; the check needs only the finger (no model, no solve).

Data flow: file -> ``load_observations(path, finger)`` -> Observations (tuple of
Observation, the file's sha256).
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

from contract.finger import FingerSpec
from contract.grasp import parse_object
from contract.spec import PRESSURE_LIMIT

FORMAT = "softjoint-observations/1"
GRIPPER, FINGER = "gripper", "finger"
PROBLEMS = (GRIPPER, FINGER)   # what was measured; absent = GRIPPER (files written before the key)
MAX_OBSERVATIONS = 1000
MAX_MARKERS = 100
COORD = 2000.0            # mm: |x|, |y| of a measured point
SIGMA_MM = (1e-4, 100.0)  # mm: a point's standard uncertainty
SIGMA_DEG = (1e-4, 90.0)  # deg: the tip angle's


class ObservationError(ValueError):
    """A measurement file that cannot be used (one line: file, key, reason)."""


@dataclass(frozen=True)
class Marker:
    """A measured point (x, y) mm on part ``part`` (0-based chain index) at s mm along it."""

    part: int
    s: float
    x: float
    y: float
    sigma: float


@dataclass(frozen=True)
class Observation:
    """One observed gesture (module docstring); tip and tip_angle may be None."""

    pressures: tuple[float, ...]
    gravity: bool = True
    object: str | None = None
    tip: tuple[float, float, float] | None = None          # x, y, sigma (mm)
    tip_angle: tuple[float, float] | None = None           # deg, sigma (deg)
    markers: tuple[Marker, ...] = ()
    name: str = ""

    @property
    def n_values(self) -> int:
        """Scalar measurements: 2 per point, 1 for the angle."""
        return 2 * (len(self.markers) + (self.tip is not None)) + (self.tip_angle is not None)


@dataclass(frozen=True)
class Observations:
    """Observed gestures, the file's sha256 and name, and what was measured (``problem``:
    GRIPPER or FINGER, module docstring)."""

    items: tuple[Observation, ...]
    sha256: str = ""
    source: str = ""
    problem: str = GRIPPER

    def __len__(self) -> int:
        return len(self.items)

    def subset(self, keep) -> "Observations":
        """The observations whose indices are in ``keep``."""
        return Observations(tuple(self.items[i] for i in keep), self.sha256, self.source, self.problem)


def _number(where: str, value, lo: float, hi: float, unit: str, open_lo: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ObservationError(f"{where} = {value!r}: must be a number in {'(' if open_lo else '['}{lo:g}, {hi:g}] {unit}")
    v = float(value)
    if not math.isfinite(v) or not ((lo < v) if open_lo else (lo <= v)) or v > hi:
        raise ObservationError(f"{where} = {value!r}: outside {'(' if open_lo else '['}{lo:g}, {hi:g}] {unit}".rstrip())
    return v


def _table(where: str, value, keys: set[str], required: set[str]) -> dict:
    if not isinstance(value, dict):
        raise ObservationError(f"{where}: must be an object with keys {', '.join(sorted(keys))}")
    for k in value:
        if k not in keys:
            raise ObservationError(f"{where}: unknown key {k!r} (use {', '.join(sorted(keys))})")
    for k in sorted(required - set(value)):
        raise ObservationError(f"{where}: missing {k!r}")
    return value


def _point(where: str, d: dict) -> tuple[float, float, float]:
    return (_number(f"{where}.x", d["x"], -COORD, COORD, "mm"), _number(f"{where}.y", d["y"], -COORD, COORD, "mm"),
            _number(f"{where}.sigma_mm", d["sigma_mm"], *SIGMA_MM, "mm"))


def _marker(where: str, d, finger: FingerSpec) -> Marker:
    d = _table(where, d, {"part", "s", "x", "y", "sigma_mm"}, {"part", "s", "x", "y", "sigma_mm"})
    n = len(finger.parts)
    k = d["part"]
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= n:
        raise ObservationError(f"{where}.part = {k!r}: must be an integer in [1, {n}] (the finger's parts, base to tip)")
    length = finger.parts[k - 1].length
    s = _number(f"{where}.s", d["s"], 0.0, length, "mm")
    x, y, sigma = _point(where, d)
    return Marker(k - 1, s, x, y, sigma)


def _observation(where: str, d, finger: FingerSpec) -> Observation:
    keys = {"name", "pressures", "gravity", "object", "tip", "tip_angle", "markers"}
    d = _table(where, d, keys, {"pressures"})
    J = finger.n_joints
    ps = d["pressures"]
    if not isinstance(ps, list) or len(ps) != J:
        raise ObservationError(f"{where}.pressures = {ps!r}: must be a list of {J} numbers (MPa, one per joint)")
    ps = tuple(_number(f"{where}.pressures[{i}]", p, -PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa") for i, p in enumerate(ps))
    gravity = d.get("gravity", True)
    if not isinstance(gravity, bool):
        raise ObservationError(f"{where}.gravity = {gravity!r}: must be true or false")
    obj = d.get("object")
    if obj is not None:
        if not isinstance(obj, str):
            raise ObservationError(f"{where}.object = {obj!r}: must be an object spec such as 'circle:r=30' or null")
        try:
            parse_object(obj)
        except ValueError as exc:
            raise ObservationError(f"{where}.object: {exc}") from None
    tip = None
    if "tip" in d:
        tip = _point(f"{where}.tip", _table(f"{where}.tip", d["tip"], {"x", "y", "sigma_mm"}, {"x", "y", "sigma_mm"}))
    angle = None
    if "tip_angle" in d:
        t = _table(f"{where}.tip_angle", d["tip_angle"], {"deg", "sigma_deg"}, {"deg", "sigma_deg"})
        angle = (_number(f"{where}.tip_angle.deg", t["deg"], -360.0, 360.0, "deg"),
                 _number(f"{where}.tip_angle.sigma_deg", t["sigma_deg"], *SIGMA_DEG, "deg"))
    ms = d.get("markers", [])
    if not isinstance(ms, list) or len(ms) > MAX_MARKERS:
        raise ObservationError(f"{where}.markers: must be a list of at most {MAX_MARKERS} markers")
    markers = tuple(_marker(f"{where}.markers[{i}]", m, finger) for i, m in enumerate(ms))
    if tip is None and angle is None and not markers:
        raise ObservationError(f"{where}: measures nothing (give tip, tip_angle or markers)")
    name = d.get("name", "")
    if not isinstance(name, str):
        raise ObservationError(f"{where}.name = {name!r}: must be a string")
    return Observation(ps, gravity, obj, tip, angle, markers, name)


def parse_observations(text: str, finger: FingerSpec, source: str = "<observations>") -> Observations:
    """Observations from JSON text for ``finger`` (module docstring); ObservationError."""
    try:
        doc = json.loads(text, parse_constant=lambda c: math.nan)
    except json.JSONDecodeError as exc:
        raise ObservationError(f"{source}: not valid JSON ({exc})") from None
    doc = _table(source, doc, {"format", "finger", "observations", "note", "problem"}, {"format", "observations"})
    if doc["format"] != FORMAT:
        raise ObservationError(f"{source}: format = {doc['format']!r}, expected {FORMAT!r}")
    problem = doc.get("problem", GRIPPER)
    if problem not in PROBLEMS:
        raise ObservationError(f"{source}: problem = {problem!r}: must be \"gripper\" (the fingers meeting at "
                               "X = 0) or \"finger\" (a lone finger)")
    items = doc["observations"]
    if not isinstance(items, list) or not 1 <= len(items) <= MAX_OBSERVATIONS:
        raise ObservationError(f"{source}: observations must be a list of 1 to {MAX_OBSERVATIONS} observations")
    obs = tuple(_observation(f"{source}: observations[{i}]", d, finger) for i, d in enumerate(items))
    return Observations(obs, hashlib.sha256(text.encode()).hexdigest(), source, problem)


def load_observations(path: str | Path, finger: FingerSpec) -> Observations:
    """Read and check a measurement file (ObservationError, one line)."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ObservationError(f"cannot read observations {path}: {getattr(exc, 'strerror', None) or exc}") from None
    return parse_observations(text, finger, str(path))


def observations_to_json(obs: Observations, note: str = "") -> dict:
    """The JSON document of ``obs`` (parse_observations reads it back; part numbers 1-based)."""
    items = []
    for o in obs.items:
        d = {"name": o.name, "pressures": list(o.pressures), "gravity": o.gravity, "object": o.object}
        if o.tip is not None:
            d["tip"] = dict(zip(("x", "y", "sigma_mm"), o.tip))
        if o.tip_angle is not None:
            d["tip_angle"] = dict(zip(("deg", "sigma_deg"), o.tip_angle))
        if o.markers:
            d["markers"] = [{"part": m.part + 1, "s": m.s, "x": m.x, "y": m.y, "sigma_mm": m.sigma} for m in o.markers]
        items.append(d)
    return {"format": FORMAT, **({"note": note} if note else {}), "problem": obs.problem, "observations": items}
