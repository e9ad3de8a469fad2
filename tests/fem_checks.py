"""Checks the coarse FEM test files share (not a test file: imported by test_fem*.py).

* ``COARSE_TET``: the coarse 4 mm tetrahedral joint (JointGeometry's default mesh is the
  production hexahedra); ``FINGER_WEIGHT`` (N) of the paper's finger and ``NEWTON_ATOL`` (N),
  the Newton tolerance the clamp's balance is asserted to;
* a joint solver's y-mirror symmetry (docs/physics.md): (P, F1, F2, M) -> (-P, F1, -F2, -M)
  mirrors the anchors, phi_end and the sensitivities (contract.spec.mirror);
* GMRES's matrix-free operator (fem.solvers.load_path.TangentAction) against the assembled
  tangent with its Dirichlet rows and columns;
* one contact term's residual and tangent alone (fem.physics's facet terms), and central
  differences of that residual along a direction du: (R(u + eps du) - R(u - eps du)) / 2 eps.
"""
import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import create_matrix

from contract.spec import mirror
from fem.mesh.geometry import JointGeometry
from fem.solvers.joint import Load

#: the coarse 4 mm tetrahedral joint
COARSE_TET = JointGeometry(mesh_size=4.0, divisions=0, hex_size=None)
FINGER_WEIGHT = 0.28                              # N: 2 joints 0.09, link 0.04, tip 0.06
NEWTON_ATOL = 1e-8                                # N, SolverConfig.atol


def assert_mirror_symmetric(joint, load: np.ndarray, at_load=None):
    """``load`` (P, F1, F2, M) and its mirror (-P, F1, -F2, -M) on the solver ``joint``:
    mirrored anchors (1e-6 mm), phi_end (1e-8 rad) and sensitivities (1e-6 of the largest).
    Returns ``at_load()`` called at the state of ``load`` (None without it)."""
    r1 = joint.solve(Load.from_array(load))
    J1 = joint.sensitivities()
    seen = at_load() if at_load is not None else None
    r2 = joint.solve(Load.from_array(load * [-1, 1, -1, -1]))
    J2 = joint.sensitivities()
    assert r1.converged and r2.converged
    _, a_m, J_m = mirror(load[None], r1.anchors[None], J1[None])
    np.testing.assert_allclose(r2.anchors, a_m[0], atol=1e-6)
    assert r2.phi_end == pytest.approx(-r1.phi_end, abs=1e-8)
    np.testing.assert_allclose(J2, J_m[0], atol=1e-6 * np.abs(J1).max())
    return seen


def assert_matrix_free_tangent(joint, load: Load) -> None:
    """At the converged ``load`` with closed valley pairs (their blocks in K), the matrix-free
    K x agrees with the assembled K x to 1e-13 of |K x| for a random x that is nonzero on
    the constrained dofs, and leaves those dofs as x (unit rows); the solver reset after."""
    path = joint.solver
    try:
        assert joint.solve(load).converged
        assert min(g.min() for g in path.contact.gaps(path.u).values()) < 0.0
        x = np.random.default_rng(5).standard_normal(path.u.vector.getLocalSize())
        assembled, free = path.tangent_products(x)
        assert np.linalg.norm(assembled - free) <= 1e-13 * np.linalg.norm(assembled)
        fixed = path.constrained_dofs()
        np.testing.assert_array_equal(free[fixed], x[fixed])
    finally:
        joint.reset()


def term_residual(term, u) -> np.ndarray:
    """The contact term's residual alone at u (a copy of the local array)."""
    b = u.vector.duplicate()
    b.set(0.0)
    term.add_residual(b, u)
    return b.array.copy()


def term_tangent(problem, u, term):
    """The contact term's tangent alone at u, assembled into a matrix of the problem's
    pattern (the residual's derivative in u)."""
    A = create_matrix(fem.form(ufl.derivative(problem.residual(), u, ufl.TrialFunction(u.function_space))))
    A.zeroEntries()
    term.add_tangent(A, u)
    A.assemble()
    return A


def central_difference(term, u, du, eps: float = 1e-4) -> np.ndarray:
    """(R(u + eps du) - R(u - eps du)) / 2 eps of the term's residual (du, eps in mm); u is
    left as it was."""
    u0 = u.x.array.copy()
    u.x.array[:] = u0 + eps * du.x.array
    rp = term_residual(term, u)
    u.x.array[:] = u0 - eps * du.x.array
    rm = term_residual(term, u)
    u.x.array[:] = u0
    return (rp - rm) / (2 * eps)
