"""Block GMRES: K X = B for several right-hand sides at once, left-preconditioned.

Units: those of K and B (the load-path solver's: N per mm, N).

The columns b_1..b_m of B are stored as the rows of an (m, n) array, each rank holding
its own entries. With a preconditioner P (an LU of a nearby K) the method solves

    M X = Z_0,     M = P^-1 K,   Z_0 = P^-1 B,   X_0 = 0,

by the block Arnoldi process: an orthonormal basis Q (rows q_i, classical Gram-Schmidt
applied twice) with Z_0 = Q^T G and M q_c = sum_i H_ic q_i for every expanded basis
vector q_c. Each block step expands the basis vectors the previous step added: K is
applied to each, then P^-1 to all of them together. The iterate X = Y^T Q_k minimises
every column's preconditioned residual over the block Krylov space,

    Y = argmin ||G - H Y||   (column by column),   r_j = ||G_j - H Y_j||,

and column j has converged when r_j <= rtol ||P^-1 b_j||, the test of PETSc's
left-preconditioned GMRES (KSPConvergedDefault with a zero initial guess). A new vector
that Gram-Schmidt reduces to below 1e-12 of its length lies in the basis already and is
dropped (deflation: the block shrinks).

Why: with a direct solver's P one pass over the factors serves every column, and the block
space is at least as rich as each column's own Krylov space, so m systems cost about what
one costs with single-vector GMRES (its measured cost: docs/decisions.md §1).

Data flow: fem.solvers.load_path.LoadPathSolver.sensitivities -> block_gmres(K products, P^-1 of
a block, dR/da columns) -> du/da columns.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Block = np.ndarray   # (k, n): k vectors of this rank's n entries
DROP = 1e-12         # relative length below which a Gram-Schmidt remainder is dropped


class Basis:
    """Orthonormal rows q_i (this rank's entries), grown by Gram-Schmidt; ``dot(A, C)`` =
    A C^T summed over ranks."""

    def __init__(self, n: int, dot: Callable[[Block, Block], np.ndarray], capacity: int = 8):
        self.q = np.empty((capacity, n))
        self.size, self.dot = 0, dot

    @property
    def rows(self) -> Block:
        return self.q[:self.size]

    def add(self, w: np.ndarray) -> np.ndarray:
        """Orthonormalise w against the basis (twice, classical Gram-Schmidt) and append
        the remainder unless it is negligible: w's coefficients (size after the call)."""
        w = np.array(w, dtype=float)
        length = float(np.sqrt(self.dot(w[None], w[None])[0, 0]))
        h = np.zeros(self.size + 1)
        for _ in range(2):
            c = self.dot(self.rows, w[None])[:, 0]
            w -= c @ self.rows
            h[:self.size] += c
        beta = float(np.sqrt(self.dot(w[None], w[None])[0, 0]))
        if length == 0.0 or beta <= DROP * length:
            return h[:self.size]
        if self.size == len(self.q):
            self.q = np.concatenate([self.q, np.empty_like(self.q)])
        self.q[self.size] = w / beta
        self.size += 1
        h[-1] = beta
        return h


def least_squares(H: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Y = argmin ||G - H Y|| column by column, and the residual norms (m,)."""
    Y = np.linalg.lstsq(H, G, rcond=None)[0]
    return Y, np.linalg.norm(G - H @ Y, axis=0)


def block_gmres(apply_k: Callable[[Block], Block], apply_p: Callable[[Block], Block], B: Block,
                rtol: float, max_it: int, dot: Callable[[Block, Block], np.ndarray]
                ) -> tuple[Block, int, bool]:
    """X (m, n) with K x_j = b_j to ``rtol`` (module docstring) in at most ``max_it`` block
    steps; ``apply_k``/``apply_p`` map a block of vectors to K / P^-1 of each, ``dot(A, C)``
    = A C^T over all ranks. Returns (X, products with K, converged). Collective."""
    m, n = B.shape
    Z0 = apply_p(B)
    target = rtol * np.sqrt(np.diag(dot(Z0, Z0)))
    basis = Basis(n, dot, capacity=max(8, 2 * m))
    columns = [basis.add(z) for z in Z0]                  # Z0 = Q^T G
    G = _stack(columns, basis.size)
    H, expanded, products = np.zeros((basis.size, 0)), 0, 0
    Y, residual = np.zeros((0, m)), np.sqrt(np.diag(dot(Z0, Z0)))
    for _ in range(max_it):
        if np.all(residual <= target) or expanded == basis.size:
            break
        new = basis.rows[expanded:].copy()
        W = apply_p(apply_k(new))
        products += len(new)
        hs = [basis.add(w) for w in W]
        expanded += len(new)
        H = np.hstack([_pad(H, basis.size), _stack(hs, basis.size)])
        Y, residual = least_squares(H, _pad(G, basis.size))
    X = Y.T @ basis.rows[:expanded] if expanded else np.zeros_like(B)
    return X, products, bool(np.all(residual <= target))


def _stack(columns: list[np.ndarray], rows: int) -> np.ndarray:
    """Coefficient vectors of varying length as the columns of a (rows, k) array."""
    out = np.zeros((rows, len(columns)))
    for j, c in enumerate(columns):
        out[:len(c), j] = c
    return out


def _pad(M: np.ndarray, rows: int) -> np.ndarray:
    """M with zero rows appended up to ``rows``."""
    return np.vstack([M, np.zeros((rows - M.shape[0], M.shape[1]))])
