"""Stability along a load path: fem.solvers.load_path.LoadPathSolver.stiffness_spectrum and
workflow.stability.

References:
* the spectrum of a coarse cantilever's tangent computed again densely with numpy, in
  both formulations: the condensed stiffness S = A - B^T C^-1 B (C the mixed form's
  pressure block; the displacement form has none) on the unconstrained dofs, its
  negative eigenvalues and the one nearest zero, against the solver's inertia count
  (Sylvester, MUMPS LDL^T) and inverse iteration; once at a stable bent state and once
  compressed to 1.5x Euler's load, where the straight column has exactly one negative
  eigenvalue (the clamped-free column's first mode, P_cr = pi^2 EI / (4 L^2));
* a fold's square-root law, lambda ~ sqrt(s_c - s), for the extrapolation of the lowest
  eigenvalue to zero;
* the verdict rules and the probed path parameters.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI  # noqa: E402

from fem.mesh.geometry import BeamGeometry  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.solvers.joint import EndLoadedSolver, Load, Material, SolverConfig  # noqa: E402
from workflow.stability import limit_ahead, path_points, verdict  # noqa: E402

BEAM = BeamGeometry(length=24.0, thickness=2.0, width=2.0, cap=1.0, mesh_size=2.0)
E = 12.2
EULER = math.pi ** 2 * E * BEAM.width * BEAM.thickness ** 3 / 12 / (4 * BEAM.length ** 2)   # N


def column(formulation: str) -> EndLoadedSolver:
    tip = np.array([BEAM.length, 0.0, 0.0])
    return EndLoadedSolver(create_mesh(BEAM, MPI.COMM_SELF), ref_point=tip, probe_points=tip[None],
                           material=Material(E=E, nu=0.3), config=SolverConfig(first_step=0.25),
                           formulation=formulation)


def dense_spectrum(solver: EndLoadedSolver) -> tuple[int, float]:
    """(negative eigenvalues, eigenvalue nearest zero) of the condensed stiffness on the free
    dofs, from the tangent the solver assembled last, by numpy."""
    lp = solver.solver
    K = lp._P.copy().convert("dense").getDenseArray().copy()   # convert() is in place
    free = np.ones(len(K), dtype=bool)
    free[lp.constrained_dofs()] = False
    u = np.zeros(len(K), dtype=bool)
    if solver.problem.displacement_space is None:
        u[:] = True
    else:
        u[np.asarray(lp.V.sub(0).collapse()[1])] = True
    a, p = free & u, ~u
    S = K[np.ix_(a, a)]
    if p.any():
        S = S - K[np.ix_(a, p)] @ np.linalg.solve(K[np.ix_(p, p)], K[np.ix_(p, a)])
    lam = np.linalg.eigvalsh(0.5 * (S + S.T))
    return int((lam < 0).sum()), float(lam[np.argmin(np.abs(lam))])


@pytest.mark.fem
@pytest.mark.parametrize("formulation", ["displacement", "mixed"])
def test_spectrum_matches_a_dense_eigendecomposition_and_counts_the_buckled_column(formulation):
    solver = column(formulation)
    assert solver.solve(Load(F2=0.5 * EULER)).converged
    got = solver.solver.stiffness_spectrum()
    modes, nearest = dense_spectrum(solver)
    assert got["unstable_modes"] == modes == 0
    assert got["lowest_eigenvalue"] == pytest.approx(nearest, rel=1e-6)

    # the straight column in compression past P_cr: load control cannot pass the
    # bifurcation (the tangent is singular at P_cr), so Newton starts from the stable
    # straight state at 0.75 P_cr scaled to 1.5 P_cr (the axial shortening is linear to
    # 1e-3 here) and converges to the straight state there, whose first mode is unstable
    assert solver.solve(Load(F1=-0.75 * EULER)).converged
    lp = solver.solver
    lp.u.x.array[:] *= 2.0
    lp.state = Load(F1=-1.5 * EULER).as_array()
    assert lp.converge().converged
    assert abs(solver.positions()[0, 1]) < 1e-3   # straight (the mesh's asymmetry: 1e-5 mm; buckled: ~0.6 L)
    got = solver.solver.stiffness_spectrum()
    modes, nearest = dense_spectrum(solver)
    assert got["unstable_modes"] == modes == 1
    assert got["lowest_eigenvalue"] == pytest.approx(nearest, rel=1e-6)
    assert nearest < 0


def test_a_fold_is_found_ahead_from_the_square_root_law():
    s = [0.90, 0.92, 0.94]
    fold = [math.sqrt(0.3 * (0.95 - v)) for v in s]          # lambda^2 linear, zero at s = 0.95
    assert limit_ahead(s, fold, s_fail=0.95)
    assert limit_ahead(s, fold, s_fail=0.96)
    assert not limit_ahead(s, fold, s_fail=0.945)           # the fold lies beyond the failure
    assert not limit_ahead(s, [1.0 + v for v in s], s_fail=0.95)   # stiffening: no fold


def test_verdicts_and_path_points():
    stable = [{"s": s, "unstable_modes": 0, "lowest_eigenvalue": 1.0, "closed_pairs": 3} for s in (0.8, 0.9, 1.0)]
    assert verdict(stable, None) == "solved"
    fail = {"s_to": 0.95}
    assert verdict(stable[:2], fail) == "solver failure"
    assert verdict(stable[:1] + [{**stable[1], "closed_pairs": 9}], fail) == "contact change"
    assert verdict(stable[:1] + [{**stable[1], "unstable_modes": 1}], fail) == "limit point"
    assert path_points(0.25, 0.5, 0.1) == [0.25, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
    assert path_points(0.1, 0.8, 0.01)[-1] == 1.0 and len(path_points(0.1, 0.8, 0.01)) == 28
