"""The finger FEM holding a circle (fem.grasp, fem.object_contact) on a coarse mesh.

One grasp along the predictor's history (approach (-0.15, 0) MPa, the default circle,
ramp to (0.2, 0.25) MPa), then:

* the finger's equilibrium: the clamp's reaction balances the finger's weight (0.28 N)
  and the object's force, whose vertical part is the object's half weight (holds);
* agreement with the predictor's outline law (contact36's predictor.gesture --object
  circle --p1 0.2 --p2 0.25: holds, tip (37.766, -214.428) mm, -97.19 deg, N 0.4187 N,
  friction use 0.382, contact point (29.67, -198.74) mm on the tip's inner face);
  measured on the 4 mm mesh: tip 0.59 mm away, N 0.422 N, friction use 0.46;
* the object term's tangent against central differences of its residual, with the
  friction unclipped (mu = 10) so that the rank-one term is exercised.
"""
import numpy as np
import pytest

pytest.importorskip("dolfinx")

from dolfinx import fem  # noqa: E402
from dolfinx.fem.petsc import create_matrix, create_vector  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from contract.finger import load_finger  # noqa: E402
from contract.grasp import ObjectSpec, parse_object  # noqa: E402
from fem.geometry import FingerGeometry, JointGeometry  # noqa: E402
from fem.grasp import GraspSolver  # noqa: E402

PREDICTOR_TIP = np.array([37.7655, -214.4284])    # mm, the outline law's answer (docstring)
PREDICTOR_NORMAL = 0.4187                         # N
FINGER_WEIGHT = 0.28                              # N: 2 joints 0.09, link 0.04, tip 0.06


@pytest.fixture(scope="module")
def grasp():
    geometry = FingerGeometry(load_finger(), JointGeometry(mesh_size=4.0))
    solver = GraspSolver(geometry, parse_object("circle"), formulation="displacement")
    return solver, solver.solve((0.2, 0.25), (-0.15, 0.0))


def test_grasp_balances_half_weight_and_base(grasp):
    _, result = grasp
    out = result.summary()
    assert out["state"] == "holds"
    fx, fy = out["object_force_N"]
    assert fy == pytest.approx(-0.1, abs=1e-9)             # W/2 carried by the friction
    bx, by = out["base_force_N"]
    assert bx + fx == pytest.approx(0.0, abs=1e-6)          # the clamp takes the object's push
    assert by == pytest.approx(FINGER_WEIGHT + 0.1, abs=1e-6)
    assert out["contact_patch"]["parts"] == ["tip"]


def test_grasp_agrees_with_predictor(grasp):
    _, result = grasp
    out = result.summary()
    assert np.linalg.norm(np.array(out["tip"]) - PREDICTOR_TIP) < 2.0
    assert out["contact_force_N"] == pytest.approx(PREDICTOR_NORMAL, rel=0.15)
    assert 0.0 < out["friction_use"] < 1.0


def _residual(term, u) -> np.ndarray:
    b = create_vector(term._R)
    with b.localForm() as loc:
        loc.set(0.0)
    term.add_residual(b, u)
    return b.array.copy()


def test_object_tangent_matches_differences(grasp):
    solver, _ = grasp
    term, u = solver.object, solver.fem.u
    mu = term.mu
    term.mu = 10.0
    try:
        lam = term.ratio()
        assert 0 < abs(lam) < term.mu                      # unclipped: the rank-one term acts
        A = create_matrix(term._K)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        term.add_tangent(A, u)
        A.assemble()
        rng = np.random.default_rng(3)
        du = fem.Function(u.function_space)
        du.x.array[term._local] = rng.standard_normal(len(term._local)) * 1e-2
        Kdu = A.createVecLeft()
        A.mult(du.vector, Kdu)
        u0, eps = u.x.array.copy(), 1e-4
        u.x.array[:] = u0 + eps * du.x.array
        rp = _residual(term, u)
        u.x.array[:] = u0 - eps * du.x.array
        rm = _residual(term, u)
        u.x.array[:] = u0
        fd = (rp - rm) / (2 * eps)
        assert np.abs(fd).max() > 1e-4
        assert np.abs(Kdu.array - fd).max() < 1e-4 * np.abs(fd).max()
    finally:
        term.mu = mu
