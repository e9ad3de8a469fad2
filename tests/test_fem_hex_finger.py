"""The whole finger on swept hexahedra (fem.mesh.hexahedra.create_hex_finger_mesh).

* geometry: every finger tag's volume or area on hex1 equals the OCC tetrahedral finger's
  (fem.mesh.geometry.build_finger, an independent construction of the same polyhedral finger)
  to 1e-6 relative; the node set is its own y-mirror exactly; each joint of the finger is
  meshed exactly as the joint alone (fem.mesh.hexahedra.create_hex_mesh), so the finger inherits
  the joint's mesh study;
* a free pressurisation of the paper's finger (Q2-Q1 mixed, hex1 joints, quadrature 4):
  (P1, P2) and (-P1, -P2) give mirror-image fingers about the mount's vertical line, and
  the fingertip agrees with the coarse tetrahedral finger's (4 mm P2-P1, frozen) within
  the tolerance measured below, an independent discretisation of the same problem;
* the command line: ``python -m fem.cli.finger --divisions 1`` solves the same hexahedral
  finger as the Python call (same answer to round-off, the hexahedra's quadrature
  raised by fem.solvers.joint.config_for) and records its mesh as ``hex1``.
"""

import json
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
from fem.solvers.finger import FINGER_CONFIG, FingerLoad, FingerSolver  # noqa: E402
from fem.cli.finger import main  # noqa: E402
from fem.mesh.geometry import FingerGeometry, JointGeometry, finger_tags  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.mesh.hexahedra import QUADRATURE, hexahedra  # noqa: E402

pytestmark = pytest.mark.fem
PAPER = load_finger()
#: uniform hexahedra and coarse tetrahedra (JointGeometry's default mesh is the graded hex2:3)
HEX1 = FingerGeometry(PAPER, JointGeometry(divisions=1, hex_size=None))
TET = FingerGeometry(PAPER, JointGeometry(mesh_size=4.0, divisions=0, hex_size=None))
FREE = (0.05, 0.05)        # MPa: both joints, no gravity
#: FingerSolver(TET, formulation="mixed").solve(FingerLoad(FREE, False)): the coarse
#: tetrahedral finger's answer (mm, deg), frozen
TET_FREE = {"tip": [-6.099281540986084, -213.41600635803624], "tip_angle_deg": -102.72116037291069}


def measures(mesh_data, finger) -> dict:
    """{finger tag name: volume (mm³) or area (mm²)} of a finger MeshData."""
    mesh = mesh_data.mesh
    one = fem.Constant(mesh, PETSc.ScalarType(1))
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=mesh_data.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=mesh_data.facet_tags)
    return {name: fem.assemble_scalar(fem.form(one * (dx(tag) if name.startswith(("part", "cap")) else ds(tag))))
            for name, tag in finger_tags(finger).items()}


def test_hex_finger_has_the_tet_fingers_volumes_and_tag_areas():
    """part{k}, cap{k}, top{k}, bottom{k}, proximal, symmetry, valley_faces: hex1 = the
    gmsh tetrahedral finger (4 mm joints) to 1e-6 relative, every one of them non-empty."""
    hexes = measures(create_mesh(HEX1, MPI.COMM_SELF), PAPER)
    tets = measures(create_mesh(TET, MPI.COMM_SELF), PAPER)
    assert set(hexes) == {"proximal", "symmetry", "valley_faces", "part0", "cap0", "top0", "bottom0",
                          "part1", "part2", "cap2", "top2", "bottom2", "part3"}
    for name in hexes:
        assert hexes[name] > 0 and hexes[name] == pytest.approx(tets[name], rel=1e-6), name


def test_hex_finger_is_mirrored_node_by_node_and_holds_the_joint_mesh():
    """Every vertex (x, y, z) of the hex2 finger has its mirror (x, -y, z) exactly; the
    vertices within each joint's span are the joint's own hex2 mesh shifted to its
    proximal face (up to round-off of the shift), and the finger has the joints' cells plus
    the rigid parts' (their intervals cut into 2 ceil(l / 6 mm))."""
    geometry = FingerGeometry(PAPER, JointGeometry(divisions=2, hex_size=None))
    x, cells = hexahedra(geometry, 2)
    assert cKDTree(x).query(x * [1.0, -1.0, 1.0])[0].max() == 0.0
    joint, joint_cells = hexahedra(JointGeometry(hex_size=None), 2)
    for k in PAPER.joints:
        x0 = PAPER.rest_start(k)
        mine = x[(x[:, 0] > x0 - 1e-9) & (x[:, 0] < x0 + PAPER.parts[k].length + 1e-9)] - [x0, 0.0, 0.0]
        assert len(mine) == len(joint) and cKDTree(mine).query(joint)[0].max() < 1e-12
    # rigid parts: 2 ceil(l / 6) along x; y and z on the joint's grid (18 x 4 hexahedra)
    rigid = sum(2 * math.ceil(PAPER.parts[k].length / 6.0) for k in (1, 3)) * 18 * 4
    assert len(cells) == 2 * len(joint_cells) + rigid


@pytest.fixture(scope="module")
def hex_free():
    """The paper's finger, hex1 joints, mixed, at FREE and at -FREE; FINGER_CONFIG's
    quadrature degree 2 is raised to the hexahedra's (fem.solvers.joint.config_for)."""
    assert FINGER_CONFIG.quadrature_degree < QUADRATURE
    solver = FingerSolver(HEX1, MPI.COMM_SELF, formulation="mixed")
    assert solver.config.quadrature_degree == QUADRATURE
    plus = solver.solve(FingerLoad(FREE, False))
    minus = solver.solve(FingerLoad(tuple(-p for p in FREE), False))
    assert plus.converged and minus.converged
    return solver, plus, minus


def test_hex_finger_free_pressurisation_is_mirror_antisymmetric(hex_free):
    """(P1, P2) and (-P1, -P2) without gravity: X - 25 flips sign, Y is kept, the tip
    angle mirrors about -90 deg, to solver tolerance; and the finger bends (tip moved by
    more than 10 mm)."""
    _, plus, minus = hex_free
    assert 25.0 - plus.tip[0] > 10.0
    np.testing.assert_allclose(plus.tip[0] - 25.0, -(minus.tip[0] - 25.0), atol=1e-6)
    np.testing.assert_allclose(plus.tip[1], minus.tip[1], atol=1e-6)
    np.testing.assert_allclose(plus.tip_angle + math.pi / 2, -(minus.tip_angle + math.pi / 2), atol=1e-8)
    np.testing.assert_allclose(plus.anchors[..., 0] - 25.0, -(minus.anchors[..., 0] - 25.0), atol=1e-6)


def test_hex_finger_agrees_with_the_tetrahedral_finger(hex_free):
    """The fingertip and tip angle of hex1 (Q2-Q1, 10,561 nodes) against the coarse
    tetrahedral finger (4 mm P2-P1 joints, 11,159 nodes; TET_FREE, frozen: its solve
    would double this file's time) at FREE: measured 0.99 mm and 0.42 deg apart with a
    32.2 mm tip displacement (the 1.8 mm P2-P1 tetrahedra, 34,715 nodes, lie between them:
    0.35 mm and 0.14 deg from hex1); allowed 1.5 mm (5 % of the tip displacement) and
    0.6 deg."""
    _, plus, _ = hex_free
    rest = np.array([0.5 * PAPER.base_gap, -PAPER.length])
    assert np.linalg.norm(plus.tip - rest) > 30.0
    assert np.linalg.norm(plus.tip - TET_FREE["tip"]) < 1.5
    assert abs(math.degrees(plus.tip_angle) - TET_FREE["tip_angle_deg"]) < 0.6


def test_cli_divisions_solves_the_python_calls_finger(hex_free, capsys):
    """``python -m fem.cli.finger --divisions 1 --formulation mixed --no-gravity --no-plane --json``
    at FREE (one finger alone, as the fixture's FingerSolver): the fingertip, tip angle and every joint's end angle of the Python call to 1e-8
    (one rank, the same mesh and solver), the same node count, and the record says hex1:
    ``mesh.mesh`` "hex1" and ``mesh.divisions`` 1 with no tetrahedron ``mesh_size``, and
    the geometry's joint ``divisions`` 1."""
    solver, plus, _ = hex_free
    argv = ["--p1", str(FREE[0]), "--p2", str(FREE[1]), "--no-gravity", "--no-plane", "--divisions", "1",
            "--formulation", "mixed", "--json", "--quiet"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"]
    np.testing.assert_allclose(out["tip"], plus.tip, atol=1e-8)
    assert out["tip_angle_deg"] == pytest.approx(math.degrees(plus.tip_angle), abs=1e-8)
    np.testing.assert_allclose(out["joint_end_angle_deg"], np.degrees(plus.end_angle), atol=1e-8)
    assert out["mesh"]["mesh"] == "hex1" and out["mesh"]["divisions"] == 1 and "mesh_size" not in out["mesh"]
    assert out["mesh"]["nodes"] == solver.mesh_info()["nodes"] == 10561
    assert out["geometry"]["joint"]["divisions"] == 1 and out["formulation"] == "mixed" and out["plane"] is False
