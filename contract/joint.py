"""The joint description: one TOML file that names a bellow joint for every stage.

A joint file (format tag ``softjoint-joint/1``; docs/joints.md) has five tables:

* ``[geometry]`` (mm): the bellow half-model of fem.mesh.geometry.JointGeometry, same names:
  ``length``, ``wall``, ``height``, ``width``, ``spine``, ``n_cells``, ``cap``,
  ``valley_height``, ``valley_width``;
* ``[material]``: the body's hyperelastic ``law`` and its parameters (MPa), one
  volumetric parameter (``nu`` or the bulk modulus ``K``, MPa), and the stiff distal cap
  (``cap_stiffness`` x the body's small-strain E, Poisson ratio ``cap_nu``; neo-Hookean).
  Every law is psi(F) = psi_dev(F) + kappa/2 (ln J)^2 (fem.physics.materials), with

  =================  ==========================  ===========================================
  law                parameters                  psi_dev, small-strain shear modulus mu0
  =================  ==========================  ===========================================
  ``neo-hookean``    ``E``                       mu/2 (I1 - 3) - mu ln J; mu0 = mu,
                                                 kappa = lambda (Lame of E, nu)
  ``mooney-rivlin``  ``C10``, ``C01``            C10 (I1b - 3) + C01 (I2b - 3);
                                                 mu0 = 2 (C10 + C01), kappa = K
  ``yeoh``           ``C10``, ``C20``, ``C30``   sum_i Ci0 (I1b - 3)^i; mu0 = 2 C10, kappa = K
  ``ogden``          ``mu``, ``alpha`` (lists)   sum_i 2 mu_i / alpha_i^2 (lb1^alpha_i +
                                                 lb2^alpha_i + lb3^alpha_i - 3);
                                                 mu0 = sum_i mu_i, kappa = K
  =================  ==========================  ===========================================

  (I1b, I2b: invariants of the isochoric C_bar = J^(-2/3) C; lb_a: its principal stretches;
  the Ogden form is Abaqus's, mu_i of Ogden's own form = 2 mu_i / alpha_i here.) The
  small-strain moduli: K from ``nu`` by K = 2 mu0 (1 + nu) / (3 (1 - 2 nu)); E = 9 K mu0 /
  (3 K + mu0), nu = (3 K - 2 mu0) / (2 (3 K + mu0)). For neo-Hookean, E and nu are the
  file's (a ``K`` gives nu = (3 K - E) / (6 K)) and mu, lambda = fem.physics.problem.lame(E, nu);
* ``[input_box]``: the training box half-widths ``pressure_mpa`` (|P|), ``force_n``
  (|F1| and |F2|) and ``moment_nmm`` (|M|): contract.spec.INPUT_BOX for this joint;
* ``[anchors]``: ``count``, the anchor points X_i = (i L / count, 0, 0), i = 1..count;
* ``[outline]`` (optional): how far a pressurised chamber's cells bulge beyond the band of
  half-height ``height``/2 that the predictor draws the joint as (predictor.model.gripper), mm,
  at |P| = ``pressures`` (MPa, increasing, > 0): ``bulge`` on the pressurised side and
  ``other`` on the opposite one, each one list per pressure of one value per anchor chord
  (``count`` values: chord k from anchor k to k + 1, chord 0 from the proximal face);
  measured by fem.studies.joint_outline (``make joint-outline``). Absent: no bulge. Not
  part of the digest (the FEM never reads it);
* ``[mesh]``: the defaults it is meshed with: tetrahedra of ``size`` (mm) and
  ``wall_size`` (mm, absent: ``size``), or swept hexahedra of ``divisions`` (a whole number
  in [1, 6]: that many elements through every wall, fem.mesh.hexahedra) instead of the sizes,
  optionally graded by ``hex_size`` S (mm: an interval of length d is cut into
  divisions x ceil(d / S) elements); and ``formulation``
  ("displacement" or "mixed").

Shape rules, from fem.mesh.geometry's construction of the y >= 0 quarter (a core bar of height
valley_height/2, caps and cells raised to height/2, one cavity of the cell pockets joined
by a channel above the spine), checked before any meshing:

* the channel exists: valley_height/2 - wall - spine/2 > 0;
* the valleys are lower than the cells: valley_height < height (their faces are the
  contact surfaces, fem.physics.contact);
* every cell holds a pocket: cell_width = (length - 2 cap - (n_cells - 1) valley_width) /
  n_cells > 2 wall;
* the pocket has a side wall: width/2 > wall;
* the mesh is not absurdly fine: length height width / size^3 <= MAX_MESH_BOXES, or
  divisions <= MAX_DIVISIONS.

Every error is a JointFileError (a ValueError), one line naming the file, the table and
key, and the allowed range; unknown keys, a key given twice, a non-number, NaN or inf and
a value outside RANGES are refused. ``joint_digest`` identifies the joint's physics and
contract (every table but ``[mesh]`` and ``[outline]``, and not ``name``). Standard library and numpy only:
no dolfinx (contract floor).

Data flow: file -> load_joint -> JointSpec -> fem (JointGeometry(**spec.geometry_kwargs()),
fem.physics.materials energies of spec.material), campaign manifests (joint_to_dict, joint_digest).
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FORMAT = "softjoint-joint/1"
DEFAULT_JOINT = Path(__file__).with_name("joints") / "paper.toml"
LAWS = {"neo-hookean": ("E",), "mooney-rivlin": ("C10", "C01"), "yeoh": ("C10", "C20", "C30"),
        "ogden": ("mu", "alpha")}
VOLUMETRIC = ("nu", "K")
FORMULATIONS = ("displacement", "mixed")
MAX_OGDEN_TERMS = 6
#: The largest Poisson ratio accepted (K / mu0 = 5000): beyond it even the mixed
#: formulation's kappa swamps the shear stiffness.
MAX_NU = 0.4999
#: At most this many size^3 boxes in the joint's bounding box (the paper's 1.8 mm mesh: 2,182).
MAX_MESH_BOXES = 1e6

GEOMETRY_KEYS = ("length", "wall", "height", "width", "spine", "n_cells", "cap", "valley_height",
                 "valley_width")
#: key -> (low, high, unit), inclusive, for every number of the file; the law's own
#: parameters take PARAMETER_RANGES.
#: most hexahedral divisions of a [mesh] (6: about 500k Q2 nodes in the paper's joint)
MAX_DIVISIONS = 6
RANGES = {
    "length": (5.0, 1000.0, "mm"), "wall": (0.1, 50.0, "mm"), "height": (1.0, 500.0, "mm"),
    "width": (1.0, 500.0, "mm"), "spine": (0.1, 100.0, "mm"), "n_cells": (2, 50, ""),
    "cap": (0.1, 100.0, "mm"), "valley_height": (0.5, 500.0, "mm"), "valley_width": (0.1, 100.0, "mm"),
    "E": (1e-3, 1e3, "MPa"), "nu": (0.0, MAX_NU, ""), "K": (1e-3, 1e7, "MPa"),
    "cap_stiffness": (1.0, 1e4, ""), "cap_nu": (0.0, 0.49, ""),
    "pressure_mpa": (1e-4, 10.0, "MPa"), "force_n": (1e-4, 1000.0, "N"),
    "moment_nmm": (1e-3, 1e5, "N*mm"), "count": (2, 100, ""),
    "size": (0.1, 50.0, "mm"), "wall_size": (0.05, 50.0, "mm"), "divisions": (1, MAX_DIVISIONS, ""),
    "hex_size": (0.3, 50.0, "mm"),
}
PARAMETER_RANGES = {"C10": (-1e3, 1e3, "MPa"), "C01": (-1e3, 1e3, "MPa"), "C20": (-1e3, 1e3, "MPa"),
                    "C30": (-1e3, 1e3, "MPa"), "mu": (-1e3, 1e3, "MPa"), "alpha": (-30.0, 30.0, "")}
#: |alpha_i| >= this: an Ogden term of alpha -> 0 has no stiffness (2 mu / alpha^2 blows up).
MIN_ABS_ALPHA = 0.1
#: The small-strain shear modulus mu0 of any law, MPa.
MU0_RANGE = (1e-4, 1e3)
_TABLES = {"geometry": GEOMETRY_KEYS, "input_box": ("pressure_mpa", "force_n", "moment_nmm"),
           "anchors": ("count",), "mesh": ("size", "wall_size", "divisions", "hex_size", "formulation")}
_TOP_KEYS = ("format", "name", "geometry", "material", "input_box", "anchors", "mesh", "outline")
#: The [outline] table's lists: |P| (MPa) and the two sides' bulges (mm) at each.
OUTLINE_KEYS = ("pressures", "bulge", "other")
_MATERIAL_COMMON = ("law", "nu", "K", "cap_stiffness", "cap_nu")
_OPTIONAL = {"size", "wall_size", "divisions", "hex_size", "formulation", "cap_stiffness", "cap_nu", "nu", "K"}


class JointFileError(ValueError):
    """A joint file that cannot be used (one line: file, table.key, reason)."""


@dataclass(frozen=True)
class BellowShape:
    """The bellow joint's dimensions (mm), fem.mesh.geometry.JointGeometry's names."""

    length: float
    wall: float
    height: float
    width: float
    spine: float
    n_cells: int
    cap: float
    valley_height: float
    valley_width: float

    @property
    def cell_width(self) -> float:
        """Outer length of one cell along x (mm), as fem.mesh.geometry.JointGeometry."""
        return (self.length - 2 * self.cap - (self.n_cells - 1) * self.valley_width) / self.n_cells

    @property
    def channel(self) -> float:
        """Height (mm) of the channel joining a chamber's cells, above the spine."""
        return self.valley_height / 2 - self.wall - self.spine / 2


@dataclass(frozen=True)
class MaterialLaw:
    """A hyperelastic law (module docstring): ``parameters`` in LAWS[law]'s order (MPa;
    Ogden's ``mu`` MPa and ``alpha`` as tuples), exactly one of ``nu`` and ``K`` (MPa),
    and the distal cap's ``cap_stiffness`` (x E) and ``cap_nu``."""

    law: str
    parameters: tuple
    nu: float | None = None
    K: float | None = None
    cap_stiffness: float = 100.0
    cap_nu: float = 0.3

    @property
    def params(self) -> dict:
        return dict(zip(LAWS[self.law], self.parameters))

    @property
    def mu0(self) -> float:
        """Small-strain shear modulus (MPa)."""
        p = self.params
        if self.law == "neo-hookean":
            return self.lame[0]
        if self.law == "mooney-rivlin":
            return 2 * (p["C10"] + p["C01"])
        if self.law == "yeoh":
            return 2 * p["C10"]
        return float(sum(p["mu"]))

    @property
    def lame(self) -> tuple[float, float]:
        """Neo-Hookean (mu, lambda) (MPa) of E and nu, fem.physics.problem.lame's arithmetic."""
        E, nu = self.params["E"], self.poisson
        return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))

    @property
    def bulk(self) -> float:
        """Small-strain bulk modulus K (MPa)."""
        if self.law == "neo-hookean":
            mu, lmbda = self.lame
            return lmbda + 2 * mu / 3 if self.K is None else self.K
        if self.K is not None:
            return self.K
        return 2 * self.mu0 * (1 + self.nu) / (3 * (1 - 2 * self.nu))

    @property
    def kappa(self) -> float:
        """Coefficient of the volumetric energy kappa/2 (ln J)^2 (MPa): lambda for
        neo-Hookean (its psi_dev is not isochoric), K otherwise."""
        return self.lame[1] if self.law == "neo-hookean" else self.bulk

    @property
    def youngs_modulus(self) -> float:
        """Small-strain E (MPa): the file's for neo-Hookean, 9 K mu0 / (3 K + mu0) else."""
        if self.law == "neo-hookean":
            return self.params["E"]
        K, mu0 = self.bulk, self.mu0
        return 9 * K * mu0 / (3 * K + mu0)

    @property
    def poisson(self) -> float:
        """Small-strain nu: the file's, or (3 K - 2 mu0) / (2 (3 K + mu0)) (neo-Hookean
        with K: (3 K - E) / (6 K))."""
        if self.nu is not None:
            return self.nu
        if self.law == "neo-hookean":
            return (3 * self.K - self.params["E"]) / (6 * self.K)
        K, mu0 = self.K, self.mu0
        return (3 * K - 2 * mu0) / (2 * (3 * K + mu0))

    def cap(self) -> MaterialLaw:
        """The distal cap's law: neo-Hookean, E = cap_stiffness x this E, nu = cap_nu."""
        return MaterialLaw("neo-hookean", (self.cap_stiffness * self.youngs_modulus,), nu=self.cap_nu)

    def summary(self) -> dict:
        """The law and its small-strain figures (MPa), JSON-ready."""
        return {"law": self.law, **material_dict(self), "E_small_strain": self.youngs_modulus,
                "nu_small_strain": self.poisson, "mu0": self.mu0, "K": self.bulk}


@dataclass(frozen=True)
class JointSpec:
    """A joint description (module docstring): shape, material, input box (P MPa,
    F1 = F2 N, M N·mm half-widths), anchor count and mesh defaults."""

    shape: BellowShape
    material: MaterialLaw
    pressure_mpa: float
    force_n: float
    moment_nmm: float
    anchors: int
    mesh_size: float | None
    wall_mesh_size: float | None = None
    formulation: str = "displacement"
    divisions: int = 0
    name: str = "joint"
    hex_size: float | None = None
    #: ([outline]) |P| (K,) MPa, the pressurised and the other side's bulge (K, anchors) mm per
    #: anchor chord; None: no bulge.
    outline: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]] | None = None

    @property
    def input_box(self) -> np.ndarray:
        """Half-widths (4,) of (P MPa, F1 N, F2 N, M N·mm), as contract.spec.INPUT_BOX."""
        return np.array([self.pressure_mpa, self.force_n, self.force_n, self.moment_nmm])

    @property
    def length(self) -> float:
        return self.shape.length

    def geometry_kwargs(self) -> dict:
        """Keyword arguments of fem.mesh.geometry.JointGeometry for this joint (mm): every mesh
        field of its kind, and ``divisions=0, hex_size=None`` on tetrahedra (JointGeometry's
        defaults are hexahedra); hexahedra leave the unused tetrahedron size at its default."""
        mesh = ({"divisions": self.divisions, "hex_size": self.hex_size} if self.divisions else
                {"mesh_size": self.mesh_size, "wall_mesh_size": self.wall_mesh_size, "divisions": 0,
                 "hex_size": None})
        return {**{k: getattr(self.shape, k) for k in GEOMETRY_KEYS}, **mesh}

    def anchor_points(self) -> np.ndarray:
        """Material anchor points X_i = (i L / n, 0, 0), i = 1..n: (n, 3) mm."""
        x = np.arange(1, self.anchors + 1) * self.length / self.anchors
        return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


# ---------------------------------------------------------------------- checks
def _range_text(key: str, ranges: dict) -> str:
    lo, hi, unit = ranges[key]
    return f"[{lo:g}, {hi:g}]{' ' + unit if unit else ''}"


def _number(where: str, key: str, value, integer: bool = False, ranges: dict = RANGES):
    """One number of the file, type- and range-checked (one-line JointFileError)."""
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        raise JointFileError(f"{where}.{key} = {value!r} must be {kind} in {_range_text(key, ranges)}")
    if not math.isfinite(value):
        raise JointFileError(f"{where}.{key} = {value!r} is not a finite number (allowed {_range_text(key, ranges)})")
    lo, hi, _ = ranges[key]
    if not lo <= value <= hi:
        raise JointFileError(f"{where}.{key} = {value!r} is outside {_range_text(key, ranges)}")
    return int(value) if integer else float(value)


def _table(source: str, doc: dict, name: str, allowed) -> tuple[str, dict]:
    """The table ``name`` of ``doc`` with only ``allowed`` keys and every required one."""
    where = f"{source}: [{name}]"
    table = doc.get(name)
    if not isinstance(table, dict):
        raise JointFileError(f"{where}: missing table" if table is None else f"{where}: must be a table")
    for key in table:
        if key not in allowed:
            raise JointFileError(f"{where}: unknown key {key!r} (use {', '.join(allowed)})")
    for key in allowed:
        if key not in table and key not in _OPTIONAL:
            raise JointFileError(f"{where}: missing {key!r}")
    return f"{source}: {name}", table


def _shape(source: str, doc: dict) -> BellowShape:
    where, t = _table(source, doc, "geometry", GEOMETRY_KEYS)
    shape = BellowShape(**{k: _number(where, k, t[k], integer=k == "n_cells") for k in GEOMETRY_KEYS})
    _check_shape(where, shape)
    return shape


def _check_shape(where: str, s: BellowShape) -> None:
    """The shape rules of the module docstring, each naming its key and its bound."""
    if s.channel <= 0:
        raise JointFileError(f"{where}.valley_height = {s.valley_height:g} mm leaves no channel between the "
                             f"cells: need valley_height > 2 wall + spine = {2 * s.wall + s.spine:g} mm")
    if s.valley_height >= s.height:
        raise JointFileError(f"{where}.valley_height = {s.valley_height:g} mm must be < height = {s.height:g} mm "
                             f"(the valleys are lower than the cells)")
    if s.cell_width <= 2 * s.wall:
        room = (s.length - 2 * s.cap - s.n_cells * 2 * s.wall) / max(s.n_cells - 1, 1)
        raise JointFileError(f"{where}.valley_width = {s.valley_width:g} mm leaves cells {s.cell_width:.4g} mm long, "
                             f"not more than 2 wall = {2 * s.wall:g} mm: need valley_width < {room:.4g} mm "
                             f"(or a longer length, fewer cells, thinner wall or cap)")
    if s.width / 2 <= s.wall:
        raise JointFileError(f"{where}.width = {s.width:g} mm must be > 2 wall = {2 * s.wall:g} mm "
                             f"(the chamber's side wall)")


def _parameters(where: str, law: str, t: dict) -> tuple:
    """The law's parameters in LAWS[law]'s order (Ogden: two equal-length tuples)."""
    if law != "ogden":
        ranges = {**PARAMETER_RANGES, "E": RANGES["E"]}
        return tuple(_number(where, k, t[k], ranges=ranges) for k in LAWS[law])
    lists = {}
    for key in ("mu", "alpha"):
        value = t[key]
        if not isinstance(value, list) or not 1 <= len(value) <= MAX_OGDEN_TERMS:
            raise JointFileError(f"{where}.{key} = {value!r} must be a list of 1 to {MAX_OGDEN_TERMS} numbers")
        lists[key] = tuple(_number(where, key, v, ranges=PARAMETER_RANGES) for v in value)
    if len(lists["mu"]) != len(lists["alpha"]):
        raise JointFileError(f"{where}: mu has {len(lists['mu'])} terms and alpha {len(lists['alpha'])}: "
                             f"give one alpha per mu")
    for a in lists["alpha"]:
        if abs(a) < MIN_ABS_ALPHA:
            raise JointFileError(f"{where}.alpha = {a!r}: every |alpha_i| must be >= {MIN_ABS_ALPHA:g}")
    return lists["mu"], lists["alpha"]


def _material(source: str, doc: dict) -> MaterialLaw:
    raw = doc.get("material")
    law = raw.get("law") if isinstance(raw, dict) else None
    if isinstance(raw, dict) and law not in LAWS:
        what = "missing 'law'" if law is None else f"law = {law!r}"
        raise JointFileError(f"{source}: material: {what}, use one of {', '.join(LAWS)}")
    where, t = _table(source, doc, "material", _MATERIAL_COMMON + LAWS.get(law, ()))
    given = [k for k in VOLUMETRIC if k in t]
    if len(given) != 1:
        raise JointFileError(f"{where}: give exactly one of nu (allowed {_range_text('nu', RANGES)}) and K "
                             f"(MPa), not {' and '.join(given) or 'neither'}")
    volumetric = {k: _number(where, k, t[k]) for k in given}
    extra = {k: _number(where, k, t[k]) for k in ("cap_stiffness", "cap_nu") if k in t}
    m = MaterialLaw(law, _parameters(where, law, t), **volumetric, **extra)
    _check_moduli(where, m)
    return m


def _check_moduli(where: str, m: MaterialLaw) -> None:
    """mu0 in MU0_RANGE and, for a K, the Poisson ratio it implies in [0, MAX_NU]."""
    mu0 = m.mu0
    if not MU0_RANGE[0] <= mu0 <= MU0_RANGE[1]:
        raise JointFileError(f"{where}: the law's small-strain shear modulus mu0 = {mu0:.6g} MPa is outside "
                             f"[{MU0_RANGE[0]:g}, {MU0_RANGE[1]:g}] MPa")
    if m.K is not None and not 0.0 <= m.poisson <= MAX_NU:
        if m.law == "neo-hookean":
            E = m.params["E"]
            lo, hi = E / 3, E / (3 * (1 - 2 * MAX_NU))
        else:
            lo, hi = 2 * mu0 / 3, 2 * mu0 * (1 + MAX_NU) / (3 * (1 - 2 * MAX_NU))
        raise JointFileError(f"{where}.K = {m.K:g} MPa gives nu = {m.poisson:.4g}: allowed [{lo:.6g}, {hi:.6g}] MPa "
                             f"(nu in [0, {MAX_NU:g}])")


def _mesh(source: str, doc: dict, shape: BellowShape, material: MaterialLaw) -> tuple:
    where, t = _table(source, doc, "mesh", _TABLES["mesh"])
    formulation = t.get("formulation", "displacement")
    if formulation not in FORMULATIONS:
        raise JointFileError(f"{where}.formulation = {formulation!r}, use one of {', '.join(FORMULATIONS)}")
    if formulation == "mixed" and material.kappa <= 0:
        raise JointFileError(f"{where}.formulation = 'mixed' needs a volumetric modulus kappa > 0: "
                             f"material.nu must be > 0")
    if ("divisions" in t) == ("size" in t):
        raise JointFileError(f"{where}: give either size (tetrahedra, mm) or divisions (hexahedra), not "
                             f"{'both' if 'size' in t else 'neither'}")
    if "divisions" in t:
        if "wall_size" in t:
            raise JointFileError(f"{where}.wall_size: tetrahedra only; hexahedra have divisions through every wall")
        hex_size = _number(where, "hex_size", t["hex_size"]) if "hex_size" in t else None
        return None, None, formulation, _number(where, "divisions", t["divisions"], integer=True), hex_size
    if "hex_size" in t:
        raise JointFileError(f"{where}.hex_size: hexahedra only (give divisions)")
    size = _number(where, "size", t["size"])
    wall = _number(where, "wall_size", t["wall_size"]) if "wall_size" in t else None
    boxes = shape.length * shape.height * shape.width / size ** 3
    if boxes > MAX_MESH_BOXES:
        low = (shape.length * shape.height * shape.width / MAX_MESH_BOXES) ** (1 / 3)
        raise JointFileError(f"{where}.size = {size:g} mm is too fine for this joint: allowed >= {low:.3g} mm "
                             f"(at most {MAX_MESH_BOXES:.0e} size^3 boxes)")
    return size, wall, formulation, 0, None


def _outline(source: str, doc: dict, shape: BellowShape, count: int) -> tuple | None:
    """The [outline] table as (pressures (K,), bulge (K, count), other (K, count)) tuples,
    or None when absent (module docstring)."""
    if "outline" not in doc:
        return None
    where, t = _table(source, doc, "outline", OUTLINE_KEYS)
    finite = lambda v: all(not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)  # noqa: E731
                           for x in v)
    pressures = t["pressures"]
    if not isinstance(pressures, list) or not pressures or not finite(pressures):
        raise JointFileError(f"{where}.pressures = {pressures!r} must be a non-empty list of finite numbers")
    if pressures[0] <= 0 or any(b <= a for a, b in zip(pressures, pressures[1:])):
        raise JointFileError(f"{where}.pressures = {pressures} must increase from above 0 MPa")
    half, sides = shape.height / 2, []
    for key in OUTLINE_KEYS[1:]:
        rows = t[key]
        if (not isinstance(rows, list) or len(rows) != len(pressures)
                or any(not isinstance(r, list) or len(r) != count or not finite(r) for r in rows)):
            raise JointFileError(f"{where}.{key} must be {len(pressures)} lists (one per pressure) of "
                                 f"{count} finite numbers (one per anchor chord), mm: remeasure it with "
                                 f"`make joint-outline` or remove [outline]")
        if any(abs(x) >= half for r in rows for x in r):
            raise JointFileError(f"{where}.{key} must lie within +/- height/2 = {half:g} mm")
        sides.append(tuple(tuple(float(x) for x in r) for r in rows))
    return (tuple(float(p) for p in pressures), *sides)


def outline_table(pressures, bulge, other, digits: int = 3) -> str:
    """The [outline] table (TOML text) of |P| (K,) MPa and the two sides' bulges (K, n) mm,
    to ``digits`` decimals of a mm (fem.studies.joint_outline prints it for a joint file)."""
    row = lambda v: "    [" + ", ".join(f"{x:.{digits}f}" for x in v) + "],"  # noqa: E731
    lines = ["[outline]", "pressures = [" + ", ".join(f"{p:g}" for p in pressures) + "]"]
    for key, side in (("bulge", bulge), ("other", other)):
        lines += [f"{key} = [", *(row(r) for r in side), "]"]
    return "\n".join(lines) + "\n"


def mesh_text(size: float | None, wall_size: float | None = None, divisions: int = 0,
              hex_size: float | None = None) -> str:
    """A mesh in words: ``hexN`` (hexahedra of N divisions), ``hexN:S`` (graded: elements
    of at most S / N mm), or ``H`` / ``H:W`` (tetrahedra, mm)."""
    if divisions:
        return f"hex{divisions}" + (f":{hex_size:g}" if hex_size else "")
    return f"{size:g}" + (f":{wall_size:g}" if wall_size else "")


def joint_from_dict(doc: dict, source: str = "<joint>") -> JointSpec:
    """A JointSpec from the file's tables (TOML-decoded, or joint_to_dict's); every check
    of the module docstring, JointFileError (one line) on the first failure."""
    if not isinstance(doc, dict):
        raise JointFileError(f"{source}: a joint description must be a table")
    for key in doc:
        if key not in _TOP_KEYS:
            raise JointFileError(f"{source}: unknown key {key!r} (use {', '.join(_TOP_KEYS)})")
    if doc.get("format") != FORMAT:
        raise JointFileError(f"{source}: format = {doc.get('format')!r}, expected {FORMAT!r}")
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise JointFileError(f"{source}: name = {name!r} must be a non-empty string")
    shape = _shape(source, doc)
    material = _material(source, doc)
    where, box = _table(source, doc, "input_box", _TABLES["input_box"])
    box = {k: _number(where, k, box[k]) for k in _TABLES["input_box"]}
    where, anchors = _table(source, doc, "anchors", _TABLES["anchors"])
    count = _number(where, "count", anchors["count"], integer=True)
    size, wall, formulation, divisions, hex_size = _mesh(source, doc, shape, material)
    return JointSpec(shape, material, **box, anchors=count, mesh_size=size, wall_mesh_size=wall,
                     formulation=formulation, divisions=divisions, name=name, hex_size=hex_size,
                     outline=_outline(source, doc, shape, count))


def parse_joint(text: str, source: str = "<joint>") -> JointSpec:
    """A JointSpec from TOML text; ``source`` names it in errors."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:   # includes a key given twice
        raise JointFileError(f"{source}: not a valid TOML joint file ({exc})") from None
    return joint_from_dict(doc, source)


def load_joint(path: str | Path | None = None) -> JointSpec:
    """Read a joint file (default: the paper's, ``DEFAULT_JOINT``)."""
    path = Path(path) if path is not None else DEFAULT_JOINT
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else "not a text file"
        raise JointFileError(f"cannot read joint file {path}: {why}") from None
    return parse_joint(text, str(path))


def joint_arg(text: str) -> JointSpec:
    """argparse type of ``--joint``: a joint file, read and checked while parsing."""
    try:
        return load_joint(text)
    except JointFileError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# ---------------------------------------------------------------------- round trip
def material_dict(m: MaterialLaw) -> dict:
    """The [material] table of a law (Ogden's lists as lists)."""
    params = {k: list(v) if isinstance(v, tuple) else v for k, v in m.params.items()}
    volumetric = {"nu": m.nu} if m.nu is not None else {"K": m.K}
    return {"law": m.law, **params, **volumetric, "cap_stiffness": m.cap_stiffness, "cap_nu": m.cap_nu}


def joint_to_dict(joint: JointSpec) -> dict:
    """The joint's tables as plain JSON, which ``joint_from_dict`` rebuilds exactly (the
    file's structure; ``wall_size`` absent when it is the size)."""
    mesh = {"divisions": joint.divisions} if joint.divisions else {"size": joint.mesh_size}
    if joint.hex_size is not None:
        mesh["hex_size"] = joint.hex_size
    mesh["formulation"] = joint.formulation
    if joint.wall_mesh_size is not None:
        mesh["wall_size"] = joint.wall_mesh_size
    d = {"format": FORMAT, "name": joint.name,
         "geometry": {k: getattr(joint.shape, k) for k in GEOMETRY_KEYS},
         "material": material_dict(joint.material),
         "input_box": {"pressure_mpa": joint.pressure_mpa, "force_n": joint.force_n,
                       "moment_nmm": joint.moment_nmm},
         "anchors": {"count": joint.anchors}, "mesh": mesh}
    if joint.outline is not None:
        pressures, bulge, other = joint.outline
        d["outline"] = {"pressures": list(pressures), "bulge": [list(r) for r in bulge],
                        "other": [list(r) for r in other]}
    return d


def joint_digest(joint: JointSpec) -> str:
    """sha256 of the joint's physics and contract: the canonical JSON of every table but
    ``[mesh]`` (a discretisation, recorded on its own by the stages) and ``[outline]`` (the
    predictor's drawing of it, which no FEM reads), without ``name``.
    Comments, key order, number spelling (45 or 45.0) and renaming do not change it."""
    d = joint_to_dict(joint)
    body = {k: d[k] for k in ("format", "geometry", "material", "input_box", "anchors")}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


@functools.lru_cache(maxsize=1)
def paper_joint_digest() -> str:
    """``joint_digest`` of the paper's joint (DEFAULT_JOINT), read once."""
    return joint_digest(load_joint())


def is_paper_joint(joint: JointSpec) -> bool:
    """Whether ``joint`` has the paper's physics and contract (its digest: name and [mesh]
    aside): the joint a stage uses without ``--joint``, a finger's joint part without a
    ``joint`` key, and a manifest or checkpoint that records none."""
    return joint_digest(joint) == paper_joint_digest()
