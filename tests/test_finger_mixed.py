"""The whole-finger FEM of a finger whose joints differ in shape (issue 37 §5), on coarse
meshes, one rank: results/joints/soft4/finger_mixed.toml, the paper's joint (45.45 mm, 5
cells, 1.2 mm walls, NinjaFlex, 10 anchors) at the base and soft4 (50 mm, 4 cells, 2 mm
walls, Yeoh silicone, 8 anchors) at the tip.

* geometry: every finger tag's volume or area on swept hexahedra (fem.mesh.hexahedra) equals the
  gmsh tetrahedral finger's (fem.mesh.geometry.build_finger), two independent constructions, to
  1e-9 relative, and each joint's body, cap and chamber walls are those of its own joint
  alone (fem.mesh.geometry.JointGeometry of its joint file's shape);
* physics: without gravity, P_base = 0 and P_tip = 0.05 MPa (soft4's box edge): the tip
  joint's chamber pressure is self-equilibrated and the rigid tip is free, so the base
  joint and the link carry no load (the base joint stays straight) and the tip joint,
  bonded to a link 6700 times stiffer than itself, deforms as soft4 alone clamped at its
  proximal face (fem.solvers.joint.JointSolver: fem.cli.solve's problem, P = 0.05 MPa, no force or
  moment, the same 4 mm P2-P1 mesh settings), up to the two meshes' difference;
* same shape: a finger whose joints share one shape is meshed, recorded and solved as
  before per-joint shapes (node counts and a coarse solve frozen from the code before them).
"""
import math

import numpy as np
import pytest

pytest.importorskip("dolfinx")
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from contract.finger import load_finger  # noqa: E402
from contract.joint import load_joint  # noqa: E402
from fem.solvers.finger import FingerLoad, FingerSolver  # noqa: E402
from fem.cli.finger import build_parser  # noqa: E402
from fem.options import finger_discretisation  # noqa: E402
from fem.mesh.geometry import TAGS, FingerGeometry, JointGeometry, finger_tags, shape_of  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.mesh.hexahedra import hexahedra, q2_nodes  # noqa: E402
from fem.physics.problem import contact_penalty_for  # noqa: E402
from fem.solvers.joint import JointSolver, Load  # noqa: E402

pytestmark = pytest.mark.fem
MIXED = load_finger("results/joints/soft4/finger_mixed.toml")
PAPER_FINGER = load_finger()
SOFT4, PAPER = load_joint("results/joints/soft4/joint.toml"), load_joint()
HEX = JointGeometry(divisions=1, hex_size=4.0)                         # coarse hex1:4
TET = JointGeometry(mesh_size=4.0, divisions=0, hex_size=None)         # coarse 4 mm tetrahedra
P_TIP = 0.05                                                           # MPa, soft4's box
#: the paper's finger on TET, mixed, at (0.05, 0.05) MPa without gravity, solved by the code
#: before per-joint shapes (commit 34b12d9; also test_fem_hex_finger's TET_FREE): 11,159 nodes
SAME_SHAPE = {"nodes": 11159, "tip": [-6.099281540986084, -213.41600635803624],
              "tip_angle_deg": -102.72116037291069}
#: Q2 node count of the paper's finger on HEX before per-joint shapes (34b12d9)
SAME_SHAPE_HEX_NODES = 18319


def measures(mesh_data, finger) -> dict:
    """{tag name: volume (mm³) or area (mm²)} of a MeshData tagged by ``finger`` (a
    FingerSpec: finger_tags) or of a joint alone (None: TAGS)."""
    tags = finger_tags(finger) if finger is not None else TAGS
    mesh = mesh_data.mesh
    one = fem.Constant(mesh, PETSc.ScalarType(1))
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=mesh_data.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=mesh_data.facet_tags)
    volume = ("part", "cap", "solid", "distal_cap")
    return {name: fem.assemble_scalar(fem.form(one * (dx(tag) if name.startswith(volume) else ds(tag))))
            for name, tag in tags.items()}


def own_shape(spec, mesh: JointGeometry) -> JointGeometry:
    """The joint of a joint description's shape on ``mesh``'s settings."""
    kw = spec.geometry_kwargs()
    return JointGeometry(**{**kw, **{k: getattr(mesh, k) for k in ("mesh_size", "wall_mesh_size",
                                                                    "divisions", "hex_size")}})


def test_each_joint_is_meshed_in_its_own_shape():
    """Hexahedra = tetrahedra tag by tag (1e-9 relative; every tag non-empty); joint part k
    of the finger has the body, cap and chamber walls of its joint alone; the hexahedral
    node set is its own y-mirror; the record lists both shapes."""
    geometry = FingerGeometry(MIXED, HEX)
    assert [j.length for j in geometry.joints] == [45.45, 50.0] and not geometry.same_shape
    hexes = measures(create_mesh(geometry, MPI.COMM_SELF), MIXED)
    tets = measures(create_mesh(FingerGeometry(MIXED, TET), MPI.COMM_SELF), MIXED)
    for name in hexes:
        assert hexes[name] > 0 and hexes[name] == pytest.approx(tets[name], rel=1e-9), name
    for k, spec in zip(MIXED.joints, (PAPER, SOFT4)):
        alone = measures(create_mesh(own_shape(spec, HEX), MPI.COMM_SELF), None)
        assert hexes[f"part{k}"] == pytest.approx(alone["solid"], rel=1e-9)
        assert hexes[f"cap{k}"] == pytest.approx(alone["distal_cap"], rel=1e-9)
        assert hexes[f"top{k}"] == pytest.approx(alone["top_chamber"], rel=1e-9)
    assert hexes["part0"] != pytest.approx(hexes["part2"], rel=1e-2)    # two shapes indeed
    x, _ = hexahedra(geometry, 1)
    assert cKDTree(x).query(x * [1.0, -1.0, 1.0])[0].max() == 0.0
    record = geometry.as_dict()
    assert record["joint"]["length"] == 45.45 and record["joint"]["divisions"] == 1
    assert record["joints"] == [shape_of(PAPER.shape), shape_of(SOFT4.shape)]


def test_the_command_line_takes_the_mixed_finger_and_refuses_a_foreign_shape():
    """fem.cli.finger's options on the mixed finger: every joint of its own shape with the
    options' mesh (no refusal); FingerGeometry refuses, in one line, a ``joint`` that is not
    the first joint's shape (it would be ignored)."""
    ap = build_parser()
    args = ap.parse_args(["--finger", "results/joints/soft4/finger_mixed.toml", "--mesh-size", "4"])
    geometry, formulation = finger_discretisation(ap, args, MIXED)
    assert geometry.joint_at(2) == own_shape(SOFT4, TET) and geometry.joint_at(0) == own_shape(PAPER, TET)
    assert formulation == "mixed"
    with pytest.raises(ValueError, match=r"^FingerGeometry: joint\.length = 50\.0 is not the finger's first "
                                         r"joint's \(45\.45\)[^\n]*$"):
        FingerGeometry(MIXED, own_shape(SOFT4, TET))


@pytest.fixture(scope="module")
def tip_only():
    """The mixed finger (TET, mixed) at P = (0, P_TIP) without gravity, and soft4 alone
    (TET, mixed) at P_TIP."""
    solver = FingerSolver(FingerGeometry(MIXED, TET), MPI.COMM_SELF, formulation="mixed")
    finger = solver.solve(FingerLoad((0.0, P_TIP), False))
    joint = JointSolver.for_joint(SOFT4, MPI.COMM_SELF, geometry=own_shape(SOFT4, TET), formulation="mixed")
    alone = joint.solve(Load(P_TIP, 0.0, 0.0, 0.0))
    assert finger.converged and alone.converged
    return solver, finger, alone


def test_base_joint_stays_straight(tip_only):
    """The base joint's 10 anchors stay at rest (global: the mount (25, 0) and 4.545 mm
    steps down) and the link does not turn. Measured: 1.2e-3 mm and 3.0e-3 deg, the 4 mm
    tetrahedra's error in the self-equilibrium of the follower pressure (hex1:4: 1e-10 mm);
    allowed 0.01 mm and 0.02 deg."""
    _, finger, _ = tip_only
    rest = np.column_stack([np.full(10, 25.0), -np.arange(1, 11) * PAPER.length / 10])
    assert len(finger.anchors[0]) == 10 and len(finger.anchors[1]) == 8
    assert np.abs(finger.anchors[0] - rest).max() < 0.01
    assert abs(math.degrees(finger.end_angle[0]) + 90.0) < 0.02
    assert abs(math.degrees(finger.theta[1]) + 90.0) < 0.02


def test_tip_joint_deforms_as_soft4_alone(tip_only):
    """The tip joint in its own frame (its 8 anchors relative to its proximal face; phi_end;
    cap rotation) against soft4 alone at P_TIP: the anchors move 24 mm and bend it by
    -42.9 deg; measured 0.113 mm (anchor distance), 0.13 deg (phi_end) and 0.16 deg (cap)
    apart (the finger's mesh of the joint is graded into its rigid neighbours; on hex1:4,
    whose finger mesh holds the joint's own grid, 0.036 mm and 0.10 deg); allowed 0.2 mm and
    0.25 deg."""
    _, finger, alone = tip_only
    local = finger.local_anchors[1]
    assert np.abs(alone.anchors - SOFT4.anchor_points()[:, :2]).max() > 20.0
    assert math.degrees(alone.phi_end) < -40.0
    assert np.linalg.norm(local - alone.anchors, axis=1).max() < 0.2
    assert abs(finger.chord_angle[1] - finger.theta[1] - alone.phi_end) < math.radians(0.25)
    assert abs(finger.end_angle[1] - finger.theta[1] - alone.cap_rotation) < math.radians(0.25)


def test_valley_contact_is_each_joints_own(tip_only):
    """The contact holds the paper joint's 4 valleys and soft4's 3, numbered along x, each
    with its joint's penalty (fem.physics.problem.contact_penalty_for: 100 and 4.25 MPa/mm) spread
    over its own valley face ((height - valley_height)/2 x width/2 mm²); none closed here."""
    solver, _, _ = tip_only
    gaps = solver.contact.gaps(solver.u)
    assert sorted(gaps) == [(k, side) for k in range(7) for side in ("bottom", "top")]
    assert min(g.min() for g in gaps.values()) > 0
    for part, spec in zip(solver.contact.terms, (PAPER, SOFT4)):
        s = spec.shape
        area = (s.height - s.valley_height) / 2 * s.width / 2
        for a, _, kw in part.groups.values():
            assert kw * len(a) == pytest.approx(contact_penalty_for(100.0, spec.material) * area, rel=1e-12)


def test_same_shape_finger_is_meshed_and_solved_as_before():
    """The paper's finger (one joint shape): the record has no ``joints`` key, the HEX
    finger the node count and the TET finger's solve the answer of the code before
    per-joint shapes (SAME_SHAPE: to 1e-9 mm and deg; the same on this machine to the bit)."""
    assert FingerGeometry(PAPER_FINGER, HEX).same_shape
    assert set(FingerGeometry(PAPER_FINGER, HEX).as_dict()) == {"finger", "joint", "rigid_mesh_size"}
    assert q2_nodes(FingerGeometry(PAPER_FINGER, HEX)) == SAME_SHAPE_HEX_NODES
    solver = FingerSolver(FingerGeometry(PAPER_FINGER, TET), MPI.COMM_SELF, formulation="mixed")
    result = solver.solve(FingerLoad((0.05, 0.05), False))
    assert result.converged and solver.mesh_info()["nodes"] == SAME_SHAPE["nodes"]
    np.testing.assert_allclose(result.tip, SAME_SHAPE["tip"], rtol=0, atol=1e-9)
    assert math.degrees(result.tip_angle) == pytest.approx(SAME_SHAPE["tip_angle_deg"], abs=1e-9)
