"""The joint description file (contract.joint): the paper's file is today's joint, every
bad input is refused with one line naming its key and range, the digest identifies the
joint's physics, and the shape rules admit what fem.mesh.geometry can mesh and refuse what it
cannot.

References: fem.mesh.geometry.JointGeometry(), fem.physics.problem.Material() and lame,
fem.mesh.discretisation.PRODUCTION, contract.spec (INPUT_BOX, N_ANCHORS, JOINT_LENGTH); gmsh
itself for the shape rules (a shape at each rule's edge meshes; the ones beyond it fail).
"""
import json
import math
import re
import subprocess
import sys
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from contract import cli
from contract.joint import (DEFAULT_JOINT, JointFileError, MaterialLaw, joint_arg, joint_digest,
                            joint_from_dict, joint_to_dict, load_joint, parse_joint)
from contract.spec import INPUT_BOX, JOINT_LENGTH, N_ANCHORS

ROOT = Path(__file__).resolve().parents[1]
PAPER_TEXT = DEFAULT_JOINT.read_text()
#: sha256 of the paper's joint (joint_digest), frozen: a change of the digest's definition
#: or of the paper's file shows here.
PAPER_DIGEST = "491592062e5bac52313aa5368be0706f7561d725e96c84ef4007f607cfc4a630"


def paper_doc() -> dict:
    return joint_to_dict(load_joint())


def with_law(law: str, **params) -> dict:
    doc = paper_doc()
    doc["material"] = {"law": law, **params}
    return doc


OTHER_LAWS = {
    "mooney-rivlin": dict(C10=0.5, C01=0.1, K=50.0),
    "yeoh": dict(C10=0.1, C20=-0.005, C30=0.002, nu=0.49, cap_stiffness=300.0),
    "ogden": dict(mu=[0.41, 0.003, 0.01], alpha=[1.3, 5.0, -2.0], K=100.0),
}


# ---------------------------------------------------------------------- the paper's joint
def test_paper_file_is_todays_joint():
    """Every JointGeometry field, Material field and Lame pair, the input box, anchors and
    the production discretisation (the [mesh] table: hex2:3 mixed, with the hexahedra's
    quadrature), exactly (==, not approximately)."""
    pytest.importorskip("dolfinx")
    from fem.mesh.discretisation import PRODUCTION
    from fem.mesh.geometry import JointGeometry, anchor_points
    from fem.physics.problem import Material, lame

    j = load_joint()
    geo = JointGeometry(**j.geometry_kwargs())
    assert geo == JointGeometry() and j.length == JOINT_LENGTH
    assert all(getattr(geo, f.name) == getattr(JointGeometry(), f.name) for f in fields(JointGeometry))
    m = j.material
    assert (m.law, m.params["E"], m.poisson, m.cap_stiffness, m.cap_nu) == \
        (m.law, Material().E, Material().nu, Material().cap_stiffness, Material().cap_nu)
    assert m.law == "neo-hookean" and m.lame == lame(Material().E, Material().nu)
    assert m.kappa == lame(Material().E, Material().nu)[1]
    cap = m.cap()   # the cap of fem.physics.problem.bellow_work: cap_stiffness * E, cap_nu
    assert cap.lame == lame(Material().cap_stiffness * Material().E, Material().cap_nu)
    assert np.array_equal(j.input_box, INPUT_BOX) and j.anchors == N_ANCHORS
    assert np.array_equal(j.anchor_points(), anchor_points(JOINT_LENGTH))
    assert (j.mesh_size, j.wall_mesh_size, j.formulation) == (PRODUCTION.H, PRODUCTION.W, PRODUCTION.formulation)
    assert (j.divisions, j.hex_size) == (PRODUCTION.divisions, PRODUCTION.hex_size) == (2, 3.0)
    assert PRODUCTION.geometry(geo) == geo and PRODUCTION.mesh == geo.mesh == "hex2:3"


def test_contract_floor_does_not_import_the_fem():
    code = ("import sys, contract.joint as j; j.load_joint(); "
            "print(sorted(m for m in ('dolfinx', 'ufl', 'gmsh', 'torch') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stderr


def test_small_strain_moduli_of_the_laws():
    """mu0 and K of each law (module docstring), and E, nu by the isotropic relations:
    E = 2 mu0 (1 + nu) is an independent identity of E = 9 K mu0 / (3 K + mu0)."""
    nh = load_joint().material
    mu, lmbda = nh.lame
    assert nh.bulk == pytest.approx(lmbda + 2 * mu / 3, rel=1e-15)
    assert nh.youngs_modulus == 12.2 and nh.poisson == 0.49
    # the paper's law given by K instead of nu is the same law
    by_k = MaterialLaw("neo-hookean", (12.2,), K=nh.bulk)
    assert by_k.poisson == pytest.approx(0.49, rel=1e-13) and by_k.kappa == pytest.approx(lmbda, rel=1e-12)
    for law, params in OTHER_LAWS.items():
        m = joint_from_dict(with_law(law, **params)).material
        mu0 = {"mooney-rivlin": 2 * (0.5 + 0.1), "yeoh": 2 * 0.1, "ogden": 0.41 + 0.003 + 0.01}[law]
        assert m.mu0 == pytest.approx(mu0, rel=1e-15)
        K = m.bulk
        assert m.youngs_modulus == pytest.approx(2 * mu0 * (1 + m.poisson), rel=1e-13)
        assert m.youngs_modulus == pytest.approx(3 * K * (1 - 2 * m.poisson), rel=1e-13)
    yeoh = joint_from_dict(with_law("yeoh", **OTHER_LAWS["yeoh"])).material
    assert yeoh.bulk == pytest.approx(2 * 0.2 * 1.49 / (3 * 0.02), rel=1e-13)
    assert yeoh.cap().youngs_modulus == pytest.approx(300.0 * yeoh.youngs_modulus, rel=1e-15)


# ---------------------------------------------------------------------- round trip, digest
@pytest.mark.parametrize("law", ["paper", *OTHER_LAWS])
def test_dict_and_json_round_trip_is_exact(law):
    j = load_joint() if law == "paper" else joint_from_dict(with_law(law, **OTHER_LAWS[law]))
    again = joint_from_dict(json.loads(json.dumps(joint_to_dict(j))))
    assert again == j and joint_digest(again) == joint_digest(j)


def test_a_hexahedral_mesh_default_reaches_the_fem_geometry():
    """[mesh] divisions = 2 (no size): the JointGeometry of the file is the hexahedral mesh
    of 2 divisions, its tetrahedron sizes JointGeometry's (unused); the round trip is exact
    and the digest, which leaves [mesh] out, is the paper's."""
    doc = paper_doc()
    doc["mesh"] = {"divisions": 2, "formulation": "mixed"}
    j = joint_from_dict(doc)
    from fem.mesh.geometry import JointGeometry

    geo = JointGeometry(**j.geometry_kwargs())
    assert (geo.divisions, geo.mesh, j.mesh_size) == (2, "hex2", None)
    assert joint_from_dict(json.loads(json.dumps(joint_to_dict(j)))) == j and joint_digest(j) == PAPER_DIGEST
    doc["mesh"]["hex_size"] = 2.5          # graded in the bending plane (fem.mesh.hexahedra)
    j = joint_from_dict(doc)
    assert JointGeometry(**j.geometry_kwargs()).mesh == "hex2:2.5" and joint_digest(j) == PAPER_DIGEST
    assert joint_from_dict(json.loads(json.dumps(joint_to_dict(j)))) == j


def test_digest_is_the_joints_physics():
    """Frozen for the paper; unchanged by comments, key order, 45 for 45.0, the name and the
    mesh defaults (another grading, or the paper-fidelity tetrahedra the committed datasets
    and checkpoints were made on); changed by any value of geometry, material, input box or
    anchors."""
    paper = load_joint()
    assert joint_digest(paper) == PAPER_DIGEST
    respelled = PAPER_TEXT.replace("n_cells = 5", "n_cells = 5   # five").replace("cap = 3.0", "cap = 3")
    respelled = respelled.replace('name = "paper"', 'name = "renamed"').replace("hex_size = 3.0", "hex_size = 2.5")
    lines = respelled.splitlines()
    i = lines.index("[input_box]")
    lines[i + 1], lines[i + 3] = lines[i + 3], lines[i + 1]          # key order
    other = parse_joint("\n".join(lines))
    assert (other.name, other.hex_size) == ("renamed", 2.5) and joint_digest(other) == PAPER_DIGEST
    mesh = PAPER_TEXT.index("\n[mesh]\n") + 1
    tetrahedra = parse_joint(PAPER_TEXT[:mesh] + '[mesh]\nsize = 1.8\nformulation = "displacement"\n')
    assert (tetrahedra.mesh_size, tetrahedra.divisions) == (1.8, 0) and joint_digest(tetrahedra) == PAPER_DIGEST
    digests = {PAPER_DIGEST}
    for table, key, value in [("geometry", "wall", 1.3), ("geometry", "n_cells", 4), ("material", "E", 12.3),
                              ("material", "cap_nu", 0.31), ("input_box", "force_n", 2.0),
                              ("anchors", "count", 12)]:
        doc = paper_doc()
        doc.pop("outline")         # the predictor's drawing, one value per chord of 10 anchors
        doc[table][key] = value
        digests.add(joint_digest(joint_from_dict(doc)))
    assert len(digests) == 7


# ---------------------------------------------------------------------- bad input
def _set(path: str, value):
    """A mutation of the paper's document: table.key = value (value None: delete)."""
    def mutate(doc):
        *tables, key = path.split(".")
        node = doc
        for t in tables:
            node = node[t]
        if value is None:
            del node[key]
        else:
            node[key] = value
    return mutate


def _tet(mutation):
    """``mutation`` of the paper's document with its [mesh] as tetrahedra (PAPER's 1.8 mm)."""
    def mutate(doc):
        doc["mesh"] = {"size": 1.8, "formulation": "displacement"}
        mutation(doc)
    return mutate


BAD_DOCS = {
    # class: (mutation, pattern the one line must match)
    "format": (_set("format", "softjoint-joint/9"), r"format = 'softjoint-joint/9', expected"),
    "unknown top key": (_set("colour", 1), r"unknown key 'colour'"),
    "unknown key": (_set("geometry.radius", 3.0), r"\[geometry\]: unknown key 'radius' \(use length"),
    "missing table": (_set("anchors", None), r"\[anchors\]: missing table"),
    "missing key": (_set("geometry.spine", None), r"\[geometry\]: missing 'spine'"),
    "string": (_set("geometry.wall", "1.2"), r"geometry\.wall = '1\.2' must be a number in \[0\.1, 50\] mm"),
    "bool": (_set("input_box.force_n", True), r"input_box\.force_n = True must be a number in \[0\.0001, 1000\] N"),
    "nan": (_set("material.E", math.nan), r"material\.E = nan is not a finite number \(allowed \[0\.001, 1000\] MPa\)"),
    "inf": (_set("input_box.moment_nmm", math.inf), r"input_box\.moment_nmm = inf is not a finite number"),
    "float count": (_set("anchors.count", 10.5), r"anchors\.count = 10\.5 must be an integer in \[2, 100\]"),
    "range": (_set("geometry.n_cells", 1), r"geometry\.n_cells = 1 is outside \[2, 50\]"),
    "range nu": (_set("material.nu", 0.5), r"material\.nu = 0\.5 is outside \[0, 0\.4999\]"),
    "negative pressure": (_set("input_box.pressure_mpa", -0.3), r"input_box\.pressure_mpa = -0\.3 is outside"),
    "law": (_set("material.law", "hooke"), r"material: law = 'hooke', use one of neo-hookean, mooney-rivlin"),
    "no law": (_set("material.law", None), r"material: missing 'law'"),
    "other law's key": (_set("material.C01", 0.1), r"\[material\]: unknown key 'C01' \(use law, nu, K"),
    "nu and K": (_set("material.K", 200.0), r"give exactly one of nu .* and K \(MPa\), not nu and K"),
    "neither nu nor K": (_set("material.nu", None), r"give exactly one of nu .* not neither"),
    "formulation": (_set("mesh.formulation", "hybrid"), r"mesh\.formulation = 'hybrid', use one of displacement, mixed"),
    "too fine": (_tet(_set("mesh.size", 0.1)), r"mesh\.size = 0\.1 mm is too fine for this joint: allowed >= 0\.233 mm"),
    "size and divisions": (_set("mesh.size", 1.8), r"mesh: give either size \(tetrahedra, mm\) or divisions \(hexahedra\), not both"),
    "no mesh size": (_set("mesh.divisions", None), r"mesh: give either size .* not neither"),
    "divisions range": (_set("mesh.divisions", 7), r"mesh\.divisions = 7 is outside \[1, 6\]"),
    "divisions float": (_set("mesh.divisions", 2.0), r"mesh\.divisions = 2\.0 must be an integer"),
    "divisions wall size": (_set("mesh.wall_size", 0.6), r"mesh\.wall_size: tetrahedra only"),
    "hex size on tetrahedra": (_tet(_set("mesh.hex_size", 2.5)), r"mesh\.hex_size: hexahedra only \(give divisions\)"),
    "hex size range": (_set("mesh.hex_size", 0.1), r"mesh\.hex_size = 0\.1 is outside \[0\.3, 50\] mm"),
    "no channel": (_set("geometry.valley_height", 4.8), r"valley_height = 4\.8 mm leaves no channel .* > 2 wall \+ spine = 4\.8 mm"),
    "flat valley": (_set("geometry.valley_height", 20.0), r"valley_height = 20 mm must be < height = 20 mm"),
    "wide valleys": (_set("geometry.valley_width", 7.0), r"valley_width = 7 mm leaves cells 2\.29 mm long, not more than 2 wall = 2\.4 mm: need valley_width < 6\.86[23] mm"),
    "thin": (_set("geometry.width", 2.4), r"geometry\.width = 2\.4 mm must be > 2 wall = 2\.4 mm"),
}


@pytest.mark.parametrize("case", BAD_DOCS)
def test_bad_joint_is_refused_with_one_line(case):
    mutate, pattern = BAD_DOCS[case]
    doc = paper_doc()
    mutate(doc)
    with pytest.raises(JointFileError) as err:
        joint_from_dict(doc, "j.toml")
    message = str(err.value)
    assert "\n" not in message and message.startswith("j.toml"), message
    assert re.search(pattern, message), message


@pytest.mark.parametrize("params, pattern", [
    (dict(C10=-0.05, C01=0.01, nu=0.4), r"mu0 = -0\.08 MPa is outside \[0\.0001, 1000\] MPa"),
    (dict(C10=0.5, C01=0.1, K=0.3), r"K = 0\.3 MPa gives nu = -0\.3571: allowed \[0\.8, 5999\.6\] MPa"),
])
def test_unstable_mooney_rivlin_is_refused(params, pattern):
    with pytest.raises(JointFileError, match=pattern):
        joint_from_dict(with_law("mooney-rivlin", **params))


@pytest.mark.parametrize("mu, alpha, pattern", [
    ([0.4, 0.1], [2.0], r"mu has 2 terms and alpha 1: give one alpha per mu"),
    ([0.4], [0.0], r"alpha = 0\.0: every \|alpha_i\| must be >= 0\.1"),
    ([0.4] * 7, [2.0] * 7, r"must be a list of 1 to 6 numbers"),
    (0.4, [2.0], r"material\.mu = 0\.4 must be a list"),
    ([0.4, "a"], [2.0, 1.0], r"material\.mu = 'a' must be a number in \[-1000, 1000\] MPa"),
])
def test_bad_ogden_terms_are_refused(mu, alpha, pattern):
    with pytest.raises(JointFileError, match=pattern):
        joint_from_dict(with_law("ogden", mu=mu, alpha=alpha, nu=0.45))


def test_mixed_formulation_needs_a_volumetric_modulus():
    doc = paper_doc()
    doc["material"]["nu"], doc["mesh"]["formulation"] = 0.0, "mixed"
    with pytest.raises(JointFileError, match=r"'mixed' needs a volumetric modulus kappa > 0: material\.nu must be > 0"):
        joint_from_dict(doc)
    doc["mesh"]["formulation"] = "displacement"
    assert joint_from_dict(doc).material.kappa == 0.0


def test_file_level_errors(tmp_path):
    twice = PAPER_TEXT.replace("wall = 1.2", "wall = 1.2\nwall = 1.3")
    with pytest.raises(JointFileError, match=r"not a valid TOML joint file \(Cannot overwrite a value"):
        parse_joint(twice, "twice.toml")
    with pytest.raises(JointFileError, match=r"^cannot read joint file .*missing\.toml: No such file"):
        load_joint(tmp_path / "missing.toml")
    binary = tmp_path / "b.toml"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(JointFileError, match=r"b\.toml: not a text file"):
        load_joint(binary)


def test_joint_option_exits_2_with_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(PAPER_TEXT.replace("spine = 2.4", "spine = -2.4"))
    ap = cli.Parser(prog="tool")
    ap.add_argument("--joint", type=joint_arg)
    with pytest.raises(SystemExit) as exit_:
        ap.parse_args(["--joint", str(bad)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1, err
    assert "geometry.spine = -2.4 is outside [0.1, 100] mm" in err
    assert ap.parse_args(["--joint", str(DEFAULT_JOINT)]).joint == load_joint()


# ---------------------------------------------------------------------- shape rules vs gmsh
EDGES = {   # one shape at the edge of each rule (0.2 mm inside it), and a four-cell joint
    "channel": dict(valley_height=2 * 1.2 + 2.4 + 0.2),
    "valley below the cells": dict(valley_height=19.8),
    "cell pocket": dict(valley_width=(45.45 - 6 - 5 * 2.4 - 5 * 0.2) / 4),
    "side wall": dict(width=2 * 1.2 + 0.4),
    "four thick cells": dict(n_cells=4, wall=2.0, length=60.0, valley_height=10.0),
}


@pytest.mark.parametrize("case", EDGES)
def test_shapes_the_rules_admit_mesh(case):
    """A shape 0.2 mm inside each rule builds every physical group of fem.mesh.geometry (coarse
    linear mesh, under a second each)."""
    pytest.importorskip("gmsh")
    import gmsh

    from fem.mesh.geometry import TAGS, JointGeometry, build_joint

    doc = paper_doc()
    doc["geometry"].update(EDGES[case])
    j = joint_from_dict(doc)
    model = build_joint(JointGeometry(**{**j.geometry_kwargs(), "mesh_size": 3.0, "divisions": 0, "hex_size": None}))
    names = {gmsh.model.getPhysicalName(d, t) for d, t in model.getPhysicalGroups()}
    assert names == set(TAGS) and len(gmsh.model.mesh.getNodes()[0]) > 300


@pytest.mark.parametrize("change, failure", [
    (dict(n_cells=1), "physical group 'valley_faces' is empty"),
    (dict(valley_height=20.0), "physical group 'valley_faces' is empty"),
    (dict(width=2.4), "Degenerate box"),
])
def test_shapes_the_rules_refuse_do_not_mesh(change, failure):
    """What the file refuses (n_cells < 2, valley_height >= height, width <= 2 wall), gmsh
    cannot build: the rules are needed, not only sufficient."""
    pytest.importorskip("gmsh")
    from fem.mesh.geometry import JointGeometry, build_joint

    doc = paper_doc()
    doc["geometry"].update(change)
    with pytest.raises(JointFileError):
        joint_from_dict(doc)
    with pytest.raises(Exception, match=failure):
        build_joint(replace(JointGeometry(mesh_size=3.0, divisions=0, hex_size=None), **change))
