"""The mixed u-p (Taylor-Hood) formulation of fem.physics.problem against exact answers and the
displacement formulation (coarse meshes, one rank, about 2 min).

* a slender beam (L/h = 20) rolled up by a pure couple, whose exact tip is the circular
  arc of curvature M/EI (fem.studies.elastica; M = EI kappa holds for any nu in pure bending): at
  nu = 0.3, where P2 displacements do not lock, both formulations are converged and agree;
  at nu = 0.49 the mixed one is the closer (less volumetric locking);
* uniform tension of that beam: the pressure is the lambda-part of the hydrostatic stress,
  p = -lambda ln J = -(lambda / 3K) sigma in the linear range, and J = exp(-p / lambda);
* the joint at nu = 0.49: y-mirror symmetry of anchors and sensitivities, and the valley
  contact (on the displacement block of the mixed unknown) keeps the walls apart.
"""

import math

import numpy as np
import pytest

pytest.importorskip("dolfinx")
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from fem.studies.elastica import rollup_tip  # noqa: E402
from fem.mesh.geometry import TAGS, BeamGeometry  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.physics.problem import lame  # noqa: E402
from fem.solvers.joint import EndLoadedSolver, JointSolver, Load, Material, SolverConfig  # noqa: E402
from fem_checks import COARSE_TET, assert_matrix_free_tangent, assert_mirror_symmetric  # noqa: E402

pytestmark = pytest.mark.fem
BEAM = BeamGeometry(length=40.0, thickness=2.0, width=2.0, cap=1.0, mesh_size=1.0)
E = 12.2
EI = E * BEAM.width * BEAM.thickness ** 3 / 12      # N·mm², full section


def beam(nu: float, formulation: str) -> EndLoadedSolver:
    tip = np.array([BEAM.length, 0.0, 0.0])
    return EndLoadedSolver(create_mesh(BEAM, MPI.COMM_SELF), ref_point=tip, probe_points=tip[None],
                           material=Material(E=E, nu=nu), config=SolverConfig(first_step=0.5),
                           formulation=formulation)


def rollup_error(solver: EndLoadedSolver, T: float = 1.0) -> tuple[np.ndarray, float]:
    """Tip (x, y)/L under M = T EI / L and its distance from the exact arc (fraction of L)."""
    r = solver.solve(Load(M=T * EI / BEAM.length))
    assert r.converged
    tip = r.anchors[0] / BEAM.length
    exact = rollup_tip(T)
    return tip, math.hypot(tip[0] - exact["x_over_L"], tip[1] - exact["y_over_L"])


def test_mixed_and_displacement_agree_where_both_converge_and_mixed_locks_less():
    """nu = 0.3: both within 0.2 % of L of the arc and within 0.03 % of L of each other
    (measured 0.12 %, 0.11 % and 0.008 %). nu = 0.49: the mixed tip is closer to the arc
    than the displacement one (measured 0.36 % against 0.52 % of L)."""
    tip_d, err_d = rollup_error(beam(0.3, "displacement"))
    tip_m, err_m = rollup_error(beam(0.3, "mixed"))
    assert err_d < 2e-3 and err_m < 2e-3
    assert np.linalg.norm(tip_m - tip_d) < 3e-4
    _, lock_d = rollup_error(beam(0.49, "displacement"))
    _, lock_m = rollup_error(beam(0.49, "mixed"))
    assert lock_m < 0.8 * lock_d


def test_pressure_is_the_volumetric_stress_in_uniform_tension():
    """F1 = 0.3 N on the beam at nu = 0.49 (sigma = F1 / A = 0.075 MPa, strain 0.6 %): in
    the middle third, far from the clamp and the cap, p = -(lambda / 3K) sigma within 0.1 %,
    and ln J = -p / lambda within 0.1 % of |p| / lambda (measured 0.005 % and 0.001 %:
    the pressure there is a converged, non-oscillating field)."""
    solver = beam(0.49, "mixed")
    F1 = 0.3
    assert solver.solve(Load(F1=F1)).converged
    mu, lam = lame(E, 0.49)
    K = lam + 2 * mu / 3
    sigma = F1 / (BEAM.width * BEAM.thickness)
    u, p = ufl.split(solver.u)
    F = ufl.Identity(3) + ufl.grad(u)
    expr = fem.Expression(ufl.as_vector([p, ufl.ln(ufl.det(F))]), np.array([[0.25, 0.25, 0.25]]))
    mesh = solver.problem.mesh_data.mesh
    mid = [c for c in solver.problem.mesh_data.cell_tags.find(TAGS["solid"])
           if BEAM.length / 3 < mesh.geometry.x[mesh.geometry.dofmap.links(c), 0].mean() < 2 * BEAM.length / 3]
    values = expr.eval(np.asarray(mid, dtype=np.int32)).reshape(-1, 2)
    p_mid, lnJ = values[:, 0], values[:, 1]
    expected = -lam / (3 * K) * sigma
    np.testing.assert_allclose(p_mid, expected, rtol=1e-3)
    np.testing.assert_allclose(lnJ, -p_mid / lam, atol=1e-3 * abs(expected) / lam)


@pytest.fixture(scope="module")
def mixed_joint():
    return JointSolver(COARSE_TET, MPI.COMM_SELF, formulation="mixed")


def test_mixed_joint_keeps_mirror_symmetry_and_contact(mixed_joint):
    """The joint (4 mm mesh, nu = 0.49) in the mixed form: (P, F1, F2, M) and its mirror
    (-P, F1, -F2, -M) give mirrored anchors (1e-6 mm), phi_end and sensitivities; the
    load bends the joint ~55 deg and the contact holds the closing valley walls within
    0.02 mm of touching (without contact they overlap by ~0.3 mm, tests/test_fem.py)."""
    solver = mixed_joint
    gaps = assert_mirror_symmetric(solver, np.array([0.1, 1.5, 2.0, 100.0]),
                                   at_load=lambda: solver.contact.gaps(solver.u))
    assert -0.02 < min(g.min() for g in gaps.values()) < 0.05
    assert solver.mesh_info()["formulation"] == "mixed"


def test_mixed_sensitivities_match_central_differences(mixed_joint):
    """d anchors / d (P, F1, F2, M) of the mixed form (tangent solves through the pressure
    block) against central differences of converged solves, within 1e-3 of each column's
    largest entry. The load leaves the valleys open: the contact tangent omits the normal's
    rotation (fem.physics.contact), which would blur the comparison by ~0.3 %."""
    solver = mixed_joint
    load = np.array([0.15, 1.0, -1.0, 30.0])
    assert solver.solve(Load.from_array(load)).converged
    J = solver.sensitivities()
    assert min(g.min() for g in solver.contact.gaps(solver.u).values()) > 0
    for j, h in enumerate((1e-3, 1e-2, 1e-2, 0.2)):
        step = np.eye(4)[j] * h
        plus = solver.solve(Load.from_array(load + step), continuation=True)
        minus = solver.solve(Load.from_array(load - step), continuation=True)
        assert plus.converged and minus.converged
        fd = (plus.anchors - minus.anchors).reshape(-1) / (2 * h)
        np.testing.assert_allclose(J[:, j], fd, atol=1e-3 * np.abs(J[:, j]).max())


def test_probes_of_a_mixed_unknown_read_its_current_u_block(mixed_joint):
    """The probes of w = (u, p) evaluate w's u block exactly as dolfinx's own collapse
    gives it, and follow w's values from call to call (the collapsed space and its dof
    map are built once and kept)."""
    probes = mixed_joint.solver.probes
    w = fem.Function(mixed_joint.V)
    mine = probes.cells >= 0
    rng = np.random.default_rng(3)
    for _ in range(2):
        w.x.array[:] = rng.standard_normal(w.x.array.size)
        exact = w.sub(0).collapse().eval(probes.points[mine], probes.cells[mine])
        np.testing.assert_array_equal(probes.values(w)[mine], exact)


def test_residual_is_lifted_exactly_when_a_dirichlet_value_is_off(mixed_joint):
    """R(u) is dolfinx's lifted residual bit for bit: the lifting -K(u) (g - u) on the
    constrained columns is skipped only while u meets every (homogeneous) condition, where
    it adds exact zeros; a u that is off a condition by 1e-3 mm gets it, and it changes R.
    Newton's corrections keep a solved u exactly on its conditions (u = 0 there), so a
    solve never pays for the lifting."""
    from dolfinx.fem.petsc import apply_lifting, assemble_vector, set_bc
    from petsc4py import PETSc

    path = mixed_joint.solver
    constrained = np.unique(np.concatenate([bc.dof_indices()[0] for bc in path.bcs]))

    def lifted(lift: bool) -> np.ndarray:
        b = assemble_vector(path._R)
        if lift:
            apply_lifting(b, [path._J], bcs=[path.bcs], x0=[path.u.vector], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        path.contact.add_residual(b, path.u)
        set_bc(b, path.bcs, path.u.vector, -1.0)
        return b.array.copy()

    try:
        assert mixed_joint.solve(Load(0.1, 1.0, -1.0, 30.0)).converged
        assert np.all(path.u.x.array[constrained] == 0.0)
        path._residual()
        np.testing.assert_array_equal(path._b.array, lifted(True))
        u = 0.05 * np.random.default_rng(4).standard_normal(path.u.x.array.size)
        u[constrained] = 0.0
        path.u.x.array[:] = u
        path._residual()
        np.testing.assert_array_equal(path._b.array, lifted(True))
        path.u.x.array[constrained[0]] = 1e-3
        path._residual()
        np.testing.assert_array_equal(path._b.array, lifted(True))
        assert np.abs(lifted(True) - lifted(False)).max() > 1e-3
    finally:
        mixed_joint.reset()


def test_the_matrix_free_tangent_is_the_assembled_tangent(mixed_joint):
    """GMRES's operator, the tangent applied matrix-free (fem.solvers.load_path.TangentAction: the
    vector assembly of dR(u)[x] plus the contact blocks), is the assembled tangent K with
    its Dirichlet rows and columns: K x agrees to 1e-13 of |K x| for a random x that is
    nonzero on the constrained dofs, at a state whose closed valley pairs put contact
    blocks into K."""
    assert_matrix_free_tangent(mixed_joint, Load(0.1, 1.5, 2.0, 100.0))



def test_a_step_from_a_state_with_sensitivities_starts_at_their_euler_predictor(mixed_joint):
    """After sensitivities() at a0 a continuation step to a1 starts from the Euler
    predictor u0 + du/da (a1 - a0) that they give, without its tangent solve: the same
    anchors (1e-6 mm) and sensitivities (1e-6 of the largest) as the plain step, whose
    first Newton correction computes that predictor, and one Newton iteration fewer
    (measured 3 against 4, 4e-13 mm and 2e-13 apart)."""
    a0, a1 = Load(0.1, 1.0, -1.0, 30.0), Load(0.12, 1.3, -0.8, 36.0)
    try:
        assert mixed_joint.solve(a0).converged
        mixed_joint.sensitivities()
        fast = mixed_joint.solve(a1, continuation=True)
        J_fast = mixed_joint.sensitivities()
        assert mixed_joint.solve(a0).converged
        mixed_joint.solver._rates = None        # the plain step: no sensitivities at a0
        plain = mixed_joint.solve(a1, continuation=True)
        J_plain = mixed_joint.sensitivities()
        assert fast.converged and plain.converged
        np.testing.assert_allclose(fast.anchors, plain.anchors, atol=1e-6)
        np.testing.assert_allclose(J_fast, J_plain, atol=1e-6 * np.abs(J_plain).max())
        assert fast.iterations == plain.iterations - 1, (fast.iterations, plain.iterations)
    finally:
        mixed_joint.reset()


def test_the_pressurised_tetrahedral_tangent_is_not_symmetric_and_is_factorised_by_lu(mixed_joint):
    """On tetrahedra (quadrature 2) the follower pressure leaves the tangent asymmetric by
    ~6e-6 of its norm (measured 5.7e-6), too much for an LDL^T of its upper triangle as
    preconditioner: the solver has switched to LU (tests/test_fem_hex.py: the hexahedral
    tangent is symmetric and stays LDL^T)."""
    assert mixed_joint.solve(Load(0.1, 2.0, 2.0, 60.0)).converged
    K = mixed_joint.solver._P
    asymmetry = (K - K.transpose(PETSc.Mat())).norm() / K.norm()
    assert 1e-7 < asymmetry < 1e-4
    assert mixed_joint.solver.pc.getType() == "lu"
