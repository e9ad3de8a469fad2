"""The finger description: one file that both the finger FEM and the predictor build from.

A finger is an ordered chain of parts from the base mount to the fingertip (docs/gripper.md):

* ``joint``: one bellow joint, with its weight (N) and whether its anchors take contact.
  Its optional key ``joint`` names its joint description file (contract.joint,
  docs/joints.md; a path relative to the finger file), which gives its shape (and length),
  law, anchors and input box; absent, it is the paper's joint (contract/joints/paper.toml,
  length contract.spec.JOINT_LENGTH, the committed surrogate's joint). So a finger may mix
  joint designs;
* ``rigid``: a straight segment of ``length`` (mm) and cross-section ``height`` x
  ``width`` (mm, in and normal to the bending plane), with its weight (N) and the number
  of contact sample points along it (0: none).

A gripper is two such fingers, mirror images about X = 0, with base mounts ``base_gap``
(mm) apart on Y = 0; the first part leaves its mount at ``base_angle`` (rad; -pi/2 hangs
down). At rest the finger is straight: part k starts at arc length ``rest_start(k)`` (mm)
along that direction.

The file is TOML (format tag ``softjoint-finger/1``); ``contract/fingers/paper.toml`` is the
paper's gripper and the default.

A calibrated finger (predictor.cli.calibrate, docs/calibration.md) adds optional keys, absent
from uncalibrated files (which load exactly as before): per joint ``pressure_gain`` g,
``pressure_offset`` o (MPa) and ``stiffness_scale`` s, under which joint i sees
P_eff = (g·P + o)/s and loads tau/s (a joint of modulus s·E), and a top-level
``[calibration]`` table that records the fit (measurements' digest, figures): kept as read,
never interpreted by the loader beyond being a table. Every error is a FingerFileError (a ValueError) with one
line naming the file and the offending key; every number has a working range (RANGES) and a
finger has at most MAX_PARTS parts and MAX_LENGTH mm. dolfinx-free and torch-free: the predictor
imports it without FEniCSx.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from contract.joint import JointFileError, JointSpec, joint_digest, joint_from_dict, joint_to_dict, load_joint
from contract.spec import JOINT_LENGTH

FORMAT = "softjoint-finger/1"
DEFAULT_FINGER = Path(__file__).with_name("fingers") / "paper.toml"
MAX_PARTS = 16
#: Whole-finger straight length (mm): with RANGES' cross-sections it bounds the rigid
#: mesh (a 500 x 100 x 100 mm part is 61k tetrahedra at the default 6 mm).
MAX_LENGTH = 1000.0


class FingerFileError(ValueError):
    """A finger file that cannot be used (one line: file, key, reason)."""


@dataclass(frozen=True)
class JointPart:
    """A bellow joint: weight (N); contact: its anchors are contact sample points;
    pressure_gain, pressure_offset (MPa), stiffness_scale: its calibration (module
    docstring; 1, 0, 1 = the joint model as it is); ``joint``: its description (None: the
    paper's joint) and ``joint_file`` the file's name as the finger file gives it."""

    weight: float = 0.09
    contact: bool = True
    pressure_gain: float = 1.0
    pressure_offset: float = 0.0
    stiffness_scale: float = 1.0
    joint: JointSpec | None = None
    joint_file: str | None = field(default=None, compare=False)
    kind = "joint"

    @property
    def calibrated(self) -> bool:
        """Whether any calibration key differs from the identity (1, 0, 1)."""
        return (self.pressure_gain, self.pressure_offset, self.stiffness_scale) != (1.0, 0.0, 1.0)

    @property
    def spec(self) -> JointSpec:
        """The joint's description: its own, or the paper's."""
        return self.joint if self.joint is not None else load_joint()

    @property
    def length(self) -> float:
        return JOINT_LENGTH if self.joint is None else self.joint.length


@dataclass(frozen=True)
class RigidPart:
    """A straight rigid segment: length, height, width (mm), weight (N), contact points."""

    length: float
    weight: float
    height: float = 20.0
    width: float = 14.0
    contact_points: int = 0
    kind = "rigid"


@dataclass(frozen=True)
class FingerSpec:
    """An ordered chain of parts and the gripper's base mounts (module docstring)."""

    parts: tuple
    base_gap: float = 50.0
    base_angle: float = -0.5 * math.pi
    name: str = "finger"
    digest: str = field(default="", compare=False)   # sha256 of the file it came from
    # The [calibration] table of a calibrated file, as read (a record, not physics).
    calibration: dict | None = field(default=None, compare=False, repr=False)

    @property
    def joints(self) -> tuple[int, ...]:
        """Indices of the joint parts, base to tip."""
        return tuple(k for k, p in enumerate(self.parts) if p.kind == "joint")

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def rest_start(self, k: int) -> float:
        """Arc length (mm) from the base mount to the start of part k, straight finger."""
        return sum(p.length for p in self.parts[:k])

    @property
    def length(self) -> float:
        """Straight length from the base mount to the fingertip (mm)."""
        return self.rest_start(len(self.parts))

    @property
    def weight(self) -> float:
        """Weight of one finger (N)."""
        return sum(p.weight for p in self.parts)

    @property
    def calibrated(self) -> bool:
        """Whether any joint carries a calibration (JointPart.calibrated)."""
        return any(p.kind == "joint" and p.calibrated for p in self.parts)

    def summary(self) -> dict:
        """JSON-ready description (angles in degrees)."""
        return {"name": self.name, "sha256": self.digest, "base_gap": self.base_gap,
                "base_angle_deg": math.degrees(self.base_angle), "parts": [part_dict(p) for p in self.parts]}


def same_finger(recorded: dict, finger: FingerSpec) -> bool:
    """Whether ``recorded`` (a FingerSpec.summary() read back from a result file)
    describes ``finger``: the same file (sha256), or the same values when only the file's
    comments or name changed (its sha256 is of the text)."""
    if recorded.get("sha256") == finger.digest:
        return True
    values = lambda d: {k: v for k, v in d.items() if k not in ("name", "sha256")}   # noqa: E731
    return values(recorded) == values(json.loads(json.dumps(finger.summary())))


#: A joint's calibration keys and their identity values: part_dict leaves them out when
#: they are the identity, so an uncalibrated finger describes itself as before.
JOINT_CALIBRATION = {"pressure_gain": 1.0, "pressure_offset": 0.0, "stiffness_scale": 1.0}


#: A joint's description fields: part_dict gives them as the file name and its sha256,
#: and only for a joint that names a file (an unnamed one is the paper's).
JOINT_FILE_FIELDS = ("joint", "joint_file")


def part_dict(part) -> dict:
    """A part's keys and values (kind first), calibration keys only when not the identity,
    and a named joint as ``joint`` (its file) and ``joint_sha256`` (contract.joint)."""
    out = {"kind": part.kind, **{k: getattr(part, k) for k in part.__dataclass_fields__
                                 if k not in JOINT_FILE_FIELDS
                                 and JOINT_CALIBRATION.get(k, object()) != getattr(part, k)}}
    if getattr(part, "joint", None) is not None:
        out.update(joint=part.joint_file, joint_sha256=joint_digest(part.joint))
    return out


#: Working ranges (inclusive) of every value that sizes the mesh or the predictor's
#: arrays, or loads the soft joints: outside them meshing breaks (a 1e-9 mm part), memory
#: runs out (1e8 contact points) or no gesture exists (a 1e9 N weight on a joint that
#: carries |M| <= 100 N·mm). key -> (low, high, unit).
RANGES = {
    "length": (1.0, 500.0, "mm"), "height": (1.0, 100.0, "mm"), "width": (1.0, 100.0, "mm"),
    "weight": (0.0, 2.0, "N"), "contact_points": (0, 1000, ""),
    "base_gap": (0.0, 1000.0, "mm"), "base_angle_deg": (-360.0, 360.0, "deg"),
    "pressure_gain": (0.2, 5.0, ""), "pressure_offset": (-0.1, 0.1, "MPa"), "stiffness_scale": (0.2, 5.0, ""),
}

# key -> (type, lower bound, strictly above?) ; bool keys have no bound
_PART_KEYS = {
    "joint": {"weight": (float, 0.0, False), "contact": (bool, None, False),
              "pressure_gain": (float, 0.0, True), "pressure_offset": (float, None, False),
              "stiffness_scale": (float, 0.0, True), "joint": (str, None, False)},
    "rigid": {"length": (float, 0.0, True), "weight": (float, 0.0, False), "height": (float, 0.0, True),
              "width": (float, 0.0, True), "contact_points": (int, 0, False)},
}
_REQUIRED = {"joint": (), "rigid": ("length", "weight")}
_TOP_KEYS = {"format", "name", "base_gap", "base_angle_deg", "part", "calibration"}


def _value(where: str, key: str, value, kind: type, low, strict: bool):
    """Check one value's type, sign and working range (RANGES); return it as ``kind``."""
    if kind is bool:
        if not isinstance(value, bool):
            raise FingerFileError(f"{where}: {key} = {value!r} must be true or false")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and not isinstance(value, int)):
        raise FingerFileError(f"{where}: {key} = {value!r} must be {'an integer' if kind is int else 'a number'}")
    if not math.isfinite(value):
        raise FingerFileError(f"{where}: {key} = {value!r} is not a finite number")
    if low is not None and (value <= low if strict else value < low):
        raise FingerFileError(f"{where}: {key} = {value!r} must be {'>' if strict else '>='} {low}")
    lo, hi, unit = RANGES.get(key, (None, None, ""))
    if lo is not None and not lo <= value <= hi:
        raise FingerFileError(f"{where}: {key} = {value!r} is outside [{lo:g}, {hi:g}]{' ' + unit if unit else ''}")
    return kind(value)


def _part(source: str, k: int, table) -> JointPart | RigidPart:
    where = f"{source}: part {k + 1}"
    if not isinstance(table, dict):
        raise FingerFileError(f"{where}: must be a [[part]] table")
    kind = table.get("kind")
    if kind not in _PART_KEYS:
        raise FingerFileError(f"{where}: kind = {kind!r}, use 'joint' or 'rigid'")
    where = f"{where} ({kind})"
    keys = _PART_KEYS[kind]
    for key in table:
        if key != "kind" and key not in keys:
            raise FingerFileError(f"{where}: unknown key {key!r} (a {kind} takes {', '.join(keys)})")
    for key in _REQUIRED[kind]:
        if key not in table:
            raise FingerFileError(f"{where}: missing {key!r}")
    values = {key: _value(where, key, table[key], *keys[key]) for key in table
              if key not in ("kind", "joint")}
    if kind == "rigid":
        return RigidPart(**values)
    if "joint" in table:
        values.update(joint=_joint_file(where, source, table["joint"]), joint_file=table["joint"])
    return JointPart(**values)


def _joint_file(where: str, source: str, name) -> JointSpec:
    """The joint description file ``name`` of a joint part, relative to the finger file
    ``source`` (one-line FingerFileError naming the part and the joint file's problem)."""
    if not isinstance(name, str) or not name:
        raise FingerFileError(f"{where}: joint = {name!r} must be a joint file name (relative to the finger file)")
    try:
        return load_joint(Path(source).parent / name)
    except JointFileError as exc:
        raise FingerFileError(f"{where}: joint = {name!r}: {exc}") from None


def parse_finger(text: str, source: str = "<finger>") -> FingerSpec:
    """A FingerSpec from TOML text; ``source`` names it in errors."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:   # includes a key given twice
        raise FingerFileError(f"{source}: not a valid TOML finger file ({exc})") from None
    for key in doc:
        if key not in _TOP_KEYS:
            raise FingerFileError(f"{source}: unknown key {key!r} (use {', '.join(sorted(_TOP_KEYS))})")
    if doc.get("format") != FORMAT:
        raise FingerFileError(f"{source}: format = {doc.get('format')!r}, expected {FORMAT!r}")
    tables = doc.get("part", [])
    if not isinstance(tables, list) or not tables:
        raise FingerFileError(f"{source}: no [[part]] tables")
    if len(tables) > MAX_PARTS:
        raise FingerFileError(f"{source}: {len(tables)} parts, at most {MAX_PARTS}")
    parts = tuple(_part(source, k, t) for k, t in enumerate(tables))
    if not any(p.kind == "joint" for p in parts):
        raise FingerFileError(f"{source}: a finger needs at least one joint part")
    length = sum(p.length for p in parts)
    if length > MAX_LENGTH:
        raise FingerFileError(f"{source}: the parts add up to {length:g} mm, at most {MAX_LENGTH:g} mm")
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise FingerFileError(f"{source}: name = {name!r} must be a non-empty string")
    gap = _value(source, "base_gap", doc.get("base_gap", 50.0), float, None, False)
    angle = _value(source, "base_angle_deg", doc.get("base_angle_deg", -90.0), float, None, False)
    calibration = doc.get("calibration")
    if calibration is not None and not isinstance(calibration, dict):
        raise FingerFileError(f"{source}: calibration must be a [calibration] table")
    return FingerSpec(parts, gap, math.radians(angle), name, hashlib.sha256(text.encode()).hexdigest(),
                      calibration)


def load_finger(path: str | Path | None = None) -> FingerSpec:
    """Read a finger file (default: the paper's, ``DEFAULT_FINGER``)."""
    path = Path(path) if path is not None else DEFAULT_FINGER
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise FingerFileError(f"cannot read finger file {path}: {exc.strerror if isinstance(exc, OSError) else exc}") from None
    return parse_finger(text, str(path))


def finger_arg(text: str) -> FingerSpec:
    """argparse type of --finger: a finger description file, read and checked while
    parsing (one line)."""
    try:
        return load_finger(text)
    except FingerFileError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def finger_to_dict(finger: FingerSpec) -> dict:
    """Plain-JSON description of a finger that ``finger_from_dict`` rebuilds exactly
    (angles in rad, so the round trip is bit for bit; for checkpoints' configs). A named
    joint also carries its description (``joint_description``, contract.joint.joint_to_dict)."""
    return {"name": finger.name, "base_gap": finger.base_gap, "base_angle": finger.base_angle,
            "parts": [_part_record(p) for p in finger.parts]}


def _part_record(part) -> dict:
    record = part_dict(part)
    if getattr(part, "joint", None) is not None:
        record["joint_description"] = joint_to_dict(part.joint)
    return record


def finger_from_dict(d: dict) -> FingerSpec:
    """The FingerSpec of ``finger_to_dict`` (ValueError/TypeError/KeyError if malformed)."""
    parts = tuple(_joint_part(p) if p["kind"] == "joint" else
                  RigidPart(**{k: v for k, v in p.items() if k != "kind"}) for p in d["parts"])
    return FingerSpec(parts, float(d["base_gap"]), float(d["base_angle"]), str(d["name"]))


def _joint_part(record: dict) -> JointPart:
    """A JointPart of a finger_to_dict part record (its joint rebuilt from its description)."""
    values = {k: v for k, v in record.items()
              if k not in ("kind", "joint", "joint_sha256", "joint_description")}
    if "joint_description" in record:
        values.update(joint=joint_from_dict(record["joint_description"]), joint_file=record["joint"])
    return JointPart(**values)
