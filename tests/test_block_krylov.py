"""fem.solvers.block_krylov.block_gmres against dense solves (numpy and scipy only, < 1 s).

* a nonsymmetric system with a perturbed LU as preconditioner: every column meets
  ||P^-1 (b - K x)|| <= rtol ||P^-1 b|| (the test of PETSc's left-preconditioned GMRES) and
  is within the matching error of the exact solution; a zero column stays exactly zero;
  the block costs no more products with K than the columns solved one by one;
* dependent right-hand sides (b_3 = 2 b_1 - b_2) are deflated: three columns cost what two
  independent ones cost, and the third solution is 2 x_1 - x_2;
* the exact preconditioner (P = K) solves in one block step; a stall is reported.
"""

import numpy as np
import pytest
import scipy.linalg as sl

from fem.solvers.block_krylov import block_gmres

N = 200
RTOL = 1e-10


def dot(A, C):
    return A @ C.T


@pytest.fixture(scope="module")
def system():
    rng = np.random.default_rng(7)
    K = 4 * np.eye(N) + rng.standard_normal((N, N)) / np.sqrt(N)       # nonsymmetric
    P = K + 0.05 * rng.standard_normal((N, N)) / np.sqrt(N)
    return K, sl.lu_factor(P), rng.standard_normal((4, N))


def solve(K, lu, B, max_it=30):
    return block_gmres(lambda V: (K @ V.T).T, lambda V: sl.lu_solve(lu, V.T).T, B, RTOL, max_it, dot)


def test_every_column_meets_the_preconditioned_residual_test(system):
    K, lu, B = system
    B = B.copy()
    B[2] = 0.0
    X, products, ok = solve(K, lu, B)
    assert ok
    np.testing.assert_array_equal(X[2], 0.0)
    pre = lambda v: sl.lu_solve(lu, v)
    for x, b in zip(X, B):
        if b.any():
            assert np.linalg.norm(pre(b - K @ x)) <= RTOL * np.linalg.norm(pre(b))
            exact = np.linalg.solve(K, b)
            assert np.linalg.norm(x - exact) <= 1e-8 * np.linalg.norm(exact)
    one_by_one = sum(solve(K, lu, b[None])[1] for b in B)
    assert products <= one_by_one


def test_dependent_right_hand_sides_are_deflated(system):
    K, lu, B = system
    two = solve(K, lu, B[:2])
    D = np.vstack([B[:2], 2 * B[0] - B[1]])
    X, products, ok = solve(K, lu, D)
    assert ok and two[2]
    assert products == two[1]
    np.testing.assert_allclose(X[2], 2 * X[0] - X[1], atol=1e-9 * np.abs(X[2]).max())


def test_the_exact_preconditioner_solves_in_one_step_and_a_stall_is_reported(system):
    K, lu, B = system
    X, products, ok = solve(K, sl.lu_factor(K), B)
    assert ok and products == len(B)
    np.testing.assert_allclose(X, np.linalg.solve(K, B.T).T, rtol=0, atol=1e-10 * np.abs(X).max())
    rough = sl.lu_factor(K + 2.0 * np.diag(np.linspace(0, 1, N)))
    assert not solve(K, rough, B, max_it=2)[2]
