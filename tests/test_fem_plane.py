"""The finger FEM meeting its mirror finger at the plane X = 0 (fem.physics.plane_contact), coarse.

The paper's finger on 4 mm tetrahedral joints, mixed P2-P1 (the production formulation;
11,159 nodes), one solver with the plane and one without (the module took 83 s wall at
nice 10 on a loaded two-core machine, 37 s of it the plane's gesture):

* gravity at (0.1, 0.1) MPa: without the plane the fingertip ends at X = -29.06 mm, across
  the mirror finger; with it the surface stays within plane_overlap_mm = 0.060 mm of X = 0
  (every node of the mesh, not only the surface the overlap is taken over), the plane
  pushes with 0.0995 N, and the clamp's reaction balances the plane's push and the
  finger's weight (measured to 3e-13 N, asserted to Newton's tolerance 1e-8 N);
* the same gesture by the predictor's outline law (contact36's ``predictor.cli.gesture --p1 0.1
  --p2 0.1 --json`` on the committed production surrogate: tip (9.8487, -215.4137) mm, plane
  force 0.1013 N, overlap 0.027 mm; its default problem, the plane's, checked live: issue
  56; on the 1.8 mm reference surrogate it was (9.8572, -215.4171) mm, 0.0959 N).
  Measured on this mesh: tip (9.8204, -215.4305) mm, 0.033 mm away; force -1.7 %; the FEM's
  own tip is also frozen (to 1e-4 mm);
* the plane term's tangent (UFL's derivative) against central differences of its
  residual at that contact (measured 1.0e-9 of the largest entry, asserted 1e-6);
* GMRES's matrix-free operator there is the assembled tangent, to round-off (1e-10 of the
  largest entry);
* free (0.05, -0.05) MPa, where the finger stays 3.0 mm clear of X = 0: the answer with the
  plane is bit-for-bit the answer without it, and there the term adds exact zeros to the
  residual and the tangent;
* the candidate faces: the inner and end faces of every part, not the outer ones;
* a finger case solved with the plane never resumes from one without it (settings).
"""
import numpy as np
import pytest

pytest.importorskip("dolfinx")

from dolfinx import fem  # noqa: E402

from contract.finger import load_finger  # noqa: E402
from fem.solvers.finger import FingerLoad, FingerSolver  # noqa: E402
from fem.mesh.geometry import FingerGeometry  # noqa: E402
from fem_checks import (COARSE_TET, FINGER_WEIGHT, NEWTON_ATOL, central_difference, term_residual,  # noqa: E402
                        term_tangent)

MEET = (0.1, 0.1)                                 # MPa, with gravity: the fingers meet
APART = (0.05, -0.05)                             # MPa, free: the finger stays 3.0 mm clear
PREDICTOR_TIP = np.array([9.8487, -215.4137])     # mm, the outline law's answer (docstring)
PREDICTOR_FORCE = 0.1013                          # N
FEM_TIP = np.array([9.8204, -215.4305])           # mm, this coarse mesh's answer (measured)
# margins around the measured figures (docstring): overlap 0.060 mm (the law keeps it within
# 0.1 mm), tip 0.033 mm from the predictor's, force -1.7 %
OVERLAP_BOUND, TIP_MARGIN, FORCE_REL = 0.1, 0.2, 0.1


@pytest.fixture(scope="module")
def geometry():
    return FingerGeometry(load_finger(), COARSE_TET)


@pytest.fixture(scope="module")
def plain(geometry):
    return FingerSolver(geometry, formulation="mixed")


@pytest.fixture(scope="module")
def meeting(geometry):
    """The plane's solver at the gesture MEET (its state u, saved), and its summary."""
    solver = FingerSolver(geometry, formulation="mixed", plane=True)
    result = solver.solve(FingerLoad(MEET, True))
    assert result.converged, result.reason
    return solver, result.summary(), solver.u.x.array.copy()


def _all_nodes_x(solver) -> np.ndarray:
    """Global X (mm) of every node of the deformed half-model (finger frame -> global)."""
    u = solver.displacement()
    X = u.function_space.tabulate_dof_coordinates()
    d = u.x.array.reshape(-1, 3)
    finger = solver.finger
    c, s = np.cos(finger.base_angle), np.sin(finger.base_angle)
    return 0.5 * finger.base_gap + c * (X[:, 0] + d[:, 0]) - s * (X[:, 1] + d[:, 1])


def test_plane_holds_the_finger_and_the_clamp_balances_it(meeting):
    solver, out, _ = meeting
    overlap = out["plane_overlap_mm"]
    assert 0 < overlap < OVERLAP_BOUND
    assert _all_nodes_x(solver).min() >= -overlap - 1e-12       # no node deeper than the overlap
    assert out["tip"][0] > 0
    force = out["plane_force_N"]
    assert force > 0.05                                          # the plane carries the finger
    bx, by = out["base_force_N"]
    assert bx + force == pytest.approx(0.0, abs=NEWTON_ATOL)     # the clamp takes the plane's push
    assert by == pytest.approx(FINGER_WEIGHT, abs=NEWTON_ATOL)


def test_the_solve_accounts_for_its_linear_algebra(meeting):
    """The gesture's record splits its wall time: factorisations (tangent assembly
    included) and GMRES within the whole solve, every Newton correction at least one GMRES
    iteration, at least one factorisation per load step."""
    _, out, _ = meeting
    assert 0 < out["factorisation_s"] and 0 < out["krylov_s"]
    assert out["factorisation_s"] + out["krylov_s"] < out["wall_time_s"]
    assert out["krylov_iterations"] >= out["iterations"]
    assert out["factorisations"] >= out["load_steps"]


def test_without_the_plane_the_finger_crosses(plain):
    result = plain.solve(FingerLoad(MEET, True))
    assert result.converged, result.reason
    assert result.tip[0] < -20.0                                 # measured -29.06 mm
    out = result.summary()
    assert out["plane_force_N"] is None and out["plane_overlap_mm"] is None


def test_plane_agrees_with_predictor(meeting):
    _, out, _ = meeting
    tip = np.array(out["tip"])
    assert np.linalg.norm(tip - FEM_TIP) < 1e-4
    assert np.linalg.norm(tip - PREDICTOR_TIP) < TIP_MARGIN
    assert out["plane_force_N"] == pytest.approx(PREDICTOR_FORCE, rel=FORCE_REL)


def test_plane_tangent_matches_differences(meeting):
    solver, _, state = meeting
    term, u = solver.plane_term, solver.u
    u.x.array[:] = state
    A = term_tangent(solver.problem, u, term)
    du = fem.Function(u.function_space)
    for dofs in term.surface_dofs:
        du.x.array[dofs] = np.random.default_rng(5).standard_normal(len(dofs)) * 1e-2     # mm
    Adu = A.createVecLeft()
    A.mult(du.vector, Adu)
    fd = central_difference(term, u, du, eps=1e-4)             # from u = state, left there
    scale = np.abs(fd).max()
    assert scale > 1e-3
    assert np.abs(Adu.array - fd).max() < 1e-6 * scale


def test_matrix_free_plane_tangent_is_the_assembled_one(meeting):
    """GMRES's operator (fem.solvers.load_path.TangentAction: the plane's facet form along x, the
    valleys' blocks, the clamp's unit rows) times a random x is the assembled tangent's
    product, to round-off, where the finger presses on the plane."""
    solver, _, state = meeting
    solver.u.x.array[:] = state
    x = np.random.default_rng(13).standard_normal(solver.u.vector.getLocalSize())
    assembled, free = solver.solver.tangent_products(x)
    assert np.abs(free - assembled).max() < 1e-10 * np.abs(assembled).max()


def test_apart_the_plane_changes_nothing(plain, meeting):
    solver = meeting[0]
    term = solver.plane_term
    with_plane = solver.solve(FingerLoad(APART, False))
    without = plain.solve(FingerLoad(APART, False))
    assert with_plane.converged and without.converged
    assert np.array_equal(with_plane.tip, without.tip)
    assert np.array_equal(np.asarray(with_plane.anchors), np.asarray(without.anchors))
    assert np.array_equal(solver.u.x.array, plain.u.x.array)
    assert 0.5 < term.surface_x(solver.u).min() < 10.0            # near, but clear (3.0 mm)
    assert with_plane.summary()["plane_force_N"] == 0.0
    assert with_plane.summary()["plane_overlap_mm"] == 0.0
    assert not term_residual(term, solver.u).any()     # the term itself is exactly zero there
    assert term_tangent(solver.problem, solver.u, term).norm() == 0.0


def test_candidate_faces_are_inner_and_end_faces(meeting):
    from fem.physics.finger import closed_tags
    from fem.physics.plane_contact import plane_facets
    from dolfinx.cpp.mesh import entities_to_geometry

    solver = meeting[0]
    finger, mesh = solver.finger, solver.mesh_data.mesh
    facets, parts = plane_facets(mesh, solver.mesh_data.facet_tags, finger, closed_tags(finger))
    x = mesh.geometry.x[entities_to_geometry(getattr(mesh, "_mesh", mesh), 2, facets, False)]
    mid = x.mean(axis=1)
    assert set(parts) == set(range(len(finger.parts)))             # every part, joint 1 too
    assert np.isclose(mid[:, 0], finger.length).any()               # the fingertip's end face
    assert np.isclose(mid[:, 1], -10.0).any()                       # the rigid parts' inner faces
    assert not np.isclose(mid[:, 1], 10.0).any()                    # never their outer faces


def test_plane_cases_never_resume_from_cases_without_it(geometry):
    from contract.files import json_safe
    from fem.solvers.finger import same_settings
    from fem.studies.finger_records import case_settings, default_suffix

    finger = geometry.finger
    without = json_safe(case_settings(finger, geometry, "mixed"))
    with_plane = json_safe(case_settings(finger, geometry, "mixed", plane=True))
    assert same_settings(without, json_safe(case_settings(finger, geometry, "mixed")), finger)
    assert not same_settings(without, with_plane, finger)
    assert not same_settings(with_plane, without, finger)
    assert default_suffix(geometry.joint, "mixed", plane=True) == "_mixed_plane"


def test_the_predictors_default_is_the_problem_compared(capsys):
    """predictor.cli.gesture's default problem is this one (issue 56 §1): at MEET, without
    --no-plane, it answers the figures the FEM is compared with above (the committed
    surrogate), and says so."""
    import json

    from predictor.cli.gesture import main

    assert main(["--p1", str(MEET[0]), "--p2", str(MEET[1]), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["plane"] is True
    assert np.linalg.norm(np.array(out["tip"]) - PREDICTOR_TIP) < 1e-3
    assert out["plane_force_N"] == pytest.approx(PREDICTOR_FORCE, abs=1e-4)
