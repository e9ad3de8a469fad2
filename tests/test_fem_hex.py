"""The swept hexahedral joint mesh (fem.mesh.hexahedra) against the tetrahedral one and physics.

* geometry: the hex mesh's volume per cell tag and area per facet tag equal the OCC
  tetrahedral mesh's (fem.mesh.geometry.build_joint, an independent construction of the same
  polyhedral joint) to 1e-6 relative; the node set is its own y-mirror exactly; the meshes
  of n divisions are nested (hex1's vertices are hex2's), which the mesh study's
  Richardson ratios rely on;
* a solve (Q2-Q1 mixed, hex1, 3,333 nodes): a load and its y-mirror give mirrored
  anchors and sensitivities, and the answer agrees with the finest committed tetrahedral
  answer (1.2:0.6 mm P2-P1, 136,875 nodes, results/fem/joint_cases), an independent
  discretisation of the same problem, within hex1's own measured error (4.35 %, 0.69°).
"""

import json
import os

import numpy as np
import pytest

pytest.importorskip("dolfinx")
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from dolfinx.mesh import compute_midpoints  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from fem.mesh.discretisation import Discretisation, discretisation  # noqa: E402
from fem.mesh.geometry import TAGS, JointGeometry, anchor_points  # noqa: E402
from fem.studies.joint_cases import difference  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.mesh.hexahedra import hexahedra, q2_nodes  # noqa: E402
from fem.solvers.joint import JointSolver, Load  # noqa: E402
from fem_checks import COARSE_TET, assert_mirror_symmetric  # noqa: E402

pytestmark = pytest.mark.fem
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: the paper joint on uniform hexahedra (JointGeometry's default mesh is the graded hex2:3)
GEO = JointGeometry(hex_size=None)
HEX2 = JointGeometry(divisions=2, hex_size=None)
HEX1 = discretisation("hex1", formulation="mixed")
FINE_TET = os.path.join(ROOT, "results/fem/joint_cases/h1.2_w0.6_mixed_q2_k100_0.15_1_-1_30.json")


def measures(mesh_data) -> dict:
    """{tag name: volume (mm³) or area (mm²)} of a MeshData's cell and facet tags."""
    mesh = mesh_data.mesh
    one = fem.Constant(mesh, PETSc.ScalarType(1))
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=mesh_data.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=mesh_data.facet_tags)
    return {name: fem.assemble_scalar(fem.form(one * (dx(tag) if name in ("solid", "distal_cap") else ds(tag))))
            for name, tag in TAGS.items()}


def test_hex_mesh_has_the_tet_meshs_volumes_and_tag_areas():
    """Every tag's volume or area: hex2 = the gmsh tetrahedra (4 mm) to 1e-6 relative."""
    hexes = measures(create_mesh(HEX2, MPI.COMM_SELF))
    tets = measures(create_mesh(COARSE_TET, MPI.COMM_SELF))
    for name in TAGS:
        assert hexes[name] == pytest.approx(tets[name], rel=1e-6), name
    assert hexes["top_chamber"] > 0 and hexes["valley_faces"] > 0


def test_hex_meshes_are_mirrored_node_by_node_and_nested():
    """Every vertex (x, y, z) of hex2 has the vertex (x, -y, z) exactly; the top chamber's
    facets are the bottom one's mirror images; every vertex of hex1 is a vertex of hex2
    (nested refinement) and hex2 has 8 times hex1's cells."""
    data = create_mesh(HEX2, MPI.COMM_SELF)
    x = data.mesh.geometry.x
    assert cKDTree(x).query(x * [1.0, -1.0, 1.0])[0].max() == 0.0
    ft = data.facet_tags
    top = compute_midpoints(data.mesh, 2, ft.find(TAGS["top_chamber"]))
    bottom = compute_midpoints(data.mesh, 2, ft.find(TAGS["bottom_chamber"]))
    assert len(top) == len(bottom) and (top[:, 1] > 0).all()
    assert cKDTree(bottom).query(top * [1.0, -1.0, 1.0])[0].max() < 1e-12
    (p1, c1), (p2, c2) = hexahedra(GEO, 1), hexahedra(GEO, 2)
    assert cKDTree(p2).query(p1)[0].max() < 1e-12 and len(c2) == 8 * len(c1)


def test_graded_hex_mesh_lies_between_hex2_and_hex4():
    """hex2:3 (JointGeometry.hex_size = 3 mm): an interval of length d is cut into
    2 ceil(d / 3) elements. So it holds every hex2 vertex and is held by hex4 (nested between
    them); its node set is its own y-mirror; the joint's volume and tag areas are hex2's to
    1e-9 relative; its elements are at most 1.5 mm long (the 3 mm caps: 1.5 mm; the
    chambers' 5.8 mm along z: 1.45 mm), through-wall ones 0.6 mm; 42,105 Q2 nodes."""
    graded = JointGeometry(divisions=2, hex_size=3.0)
    assert graded.mesh == "hex2:3" and discretisation("hex2:3").key == "hex2s3_mixed_q4_k100"
    assert discretisation("hex2:3", formulation="displacement").key == "hex2s3_displacement_q4_k100"
    (p2, _), (pg, cg), (p4, _) = hexahedra(GEO, 2), hexahedra(graded, 2), hexahedra(GEO, 4)
    assert cKDTree(pg).query(p2)[0].max() < 1e-12 and cKDTree(p4).query(pg)[0].max() < 1e-12
    assert cKDTree(pg).query(pg * [1.0, -1.0, 1.0])[0].max() == 0.0
    for axis, longest in ((0, 1.5), (1, 1.2), (2, 1.45)):
        steps = np.diff(np.unique(pg[:, axis]))
        assert steps.max() == pytest.approx(longest, abs=1e-9) and steps.min() == pytest.approx(0.6, abs=1e-9)
    assert q2_nodes(graded) == 42_105
    meshes = {g: measures(create_mesh(g, MPI.COMM_SELF)) for g in (graded, HEX2)}
    for name in TAGS:
        assert meshes[graded][name] == pytest.approx(meshes[HEX2][name], rel=1e-9), name
    with pytest.raises(ValueError, match="hexahedra"):
        JointGeometry(divisions=0, hex_size=2.5)
    with pytest.raises(ValueError, match="hexahedra"):
        JointGeometry(mesh_size=4.0, divisions=0)      # the default hex_size is the production mesh's


def test_a_hexahedral_discretisation_needs_its_quadrature_and_no_sizes():
    """Q2 hexahedra under-integrated (degree 2: 2 x 2 x 2 points) are refused, as are
    tetrahedron sizes on a hexahedral mesh; the key names the divisions."""
    assert HEX1.key == "hex1_mixed_q4_k100" and HEX1.mesh == "hex1" and HEX1.sizes == (1.0, 1.0)
    with pytest.raises(ValueError, match="quadrature"):
        Discretisation(H=None, W=None, divisions=1, quadrature=2)
    with pytest.raises(ValueError, match="no tetrahedron sizes"):
        Discretisation(H=1.8, divisions=1, quadrature=4)


@pytest.fixture(scope="module")
def hex_joint():
    return JointSolver(HEX1.geometry(), MPI.COMM_SELF, config=HEX1.config(), formulation=HEX1.formulation)


def test_hex_joint_solve_is_mirror_symmetric(hex_joint):
    """(P, F1, F2, M) and its mirror (-P, F1, -F2, -M) on hex1: mirrored anchors
    (1e-6 mm), phi_end (1e-8 rad) and sensitivities (1e-6 of the largest)."""
    assert_mirror_symmetric(hex_joint, np.array([0.1, 1.0, 1.5, 40.0]))


def test_hex_joint_tangent_is_symmetric_and_factorised_as_ldlt(hex_joint):
    """Under pressure and end loads the tangent of the hexahedral joint (quadrature 4) is
    symmetric to round-off, ||K - K^T|| <= 1e-14 ||K|| (measured 7e-17): the Hessian of
    the potential energy, the follower pressure on the closed chambers included. So the
    solver keeps factorising it as LDL^T (MUMPS' symmetric indefinite factorisation)."""
    assert hex_joint.solve(Load(0.15, 1.0, -1.0, 30.0)).converged
    K = hex_joint.solver._P
    assert (K - K.transpose(PETSc.Mat())).norm() <= 1e-14 * K.norm()
    assert hex_joint.solver.pc.getType() == "cholesky"


def test_hex_joint_agrees_with_the_finest_tetrahedral_answer(hex_joint):
    """(0.15, 1, -1, 30) on hex1 (one Q2 element through the wall) against 1.2:0.6 P2-P1
    tetrahedra: anchors within 5 % of the largest anchor displacement (measured 4.35 %),
    phi_end and the cap rotation within 0.8° (0.55°, 0.69°): the two element families
    converge to one answer."""
    with open(FINE_TET) as f:
        ref = json.load(f)
    r = hex_joint.solve(Load(0.15, 1.0, -1.0, 30.0))
    assert r.converged
    case = {"anchors": r.anchors, "phi_end_deg": np.degrees(r.phi_end),
            "cap_rotation_deg": np.degrees(r.cap_rotation)}
    d = difference(case, ref, anchor_points(GEO.length)[:, :2])
    assert d["anchor_percent"] < 5.0
    assert d["phi_end_deg"] < 0.8 and d["cap_rotation_deg"] < 0.8
