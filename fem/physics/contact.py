"""Frictionless penalty self-contact of the outer bellow walls across each valley.

When the joint bends (or one chamber balloons) the two outer cell walls facing each other
across a valley (undeformed gap ``valley_width`` = 2.5 mm) close up; without contact they
interpenetrate by up to 2.4 mm inside the input box (``make self-contact``). The geometry
meshes the two faces of a valley translation-periodically (:func:`fem.mesh.geometry.build_joint`),
so every node a on the left face has an exact partner b on the right face. Each pair gets
the one-sided quadratic penalty energy::

    g   = (x_b - x_a) · n                      signed gap (mm), x = X + u
    Pi_c = sum_pairs  kappa w / 2  <-g>^2      <s> = max(s, 0)

with ``kappa`` the penalty (MPa/mm, i.e. contact pressure per mm of overlap; one per joint
of a finger, fem.physics.problem.contact_penalty_for: it scales with the joint's modulus), w the
face area per node (mm²) and n the unit normal of the best-fit plane through both faces
of the valley, projected on the bending plane (z-component dropped: the load is planar).
n is lagged: taken from the current iterate and not differentiated, so the tangent is
exact up to the small rotation of n within one Newton step. Residual and tangent::

    dPi_c/dx_b = -dPi_c/dx_a = -kappa w <-g> n,    K_bb = K_aa = -K_ab = kappa w H(-g) n n^T

At the production penalty the overlap under the largest contact pressures of the input
box is a few hundredths of a mm (``results/fem/self_contact.json``).

The pairs are gathered on every rank (a few hundred nodes) and rank 0 adds the
contributions with global PETSc indices; PETSc moves off-process entries. Every pair's
4 x 4 block is always inserted (zeros when open), so the sparsity pattern, and with it
MUMPS' symbolic factorisation, is fixed after the first assembly.

:class:`ContactTerms` sums several contact terms (a finger's joints, an object:
fem.physics.object_contact) behind the one interface fem.solvers.load_path calls.
"""

from __future__ import annotations

import numpy as np
from dolfinx import fem
from petsc4py import PETSc
from scipy.spatial import cKDTree

from fem.mesh.geometry import TAGS, JointGeometry


class ValleyContact:
    """Node-to-node penalty contact between the periodic valley faces of the joint."""

    def __init__(self, V, facet_tags, geometry: JointGeometry, penalty: float | tuple[float, ...],
                 offsets: tuple[float, ...] = (0.0,), parent=None):
        """``V``: the blocked (3-component) displacement space. ``offsets``: x (mm) of the
        proximal face of every joint in the mesh (a finger holds several); valleys are
        numbered along x across all joints. ``penalty`` (MPa/mm): one for every joint, or
        one per joint (as ``offsets``). ``parent`` = (W, to_parent) when V is the
        displacement block collapsed out of the unknown's mixed space W: ``to_parent[i]``
        is the local dof of W of V's unrolled local dof i."""
        self.comm = V.mesh.comm
        penalties = np.broadcast_to(np.asarray(penalty, dtype=float), (len(offsets),))
        imap = V.dofmap.index_map
        nodes = fem.locate_dofs_topological(V, 2, facet_tags.find(TAGS["valley_faces"]))
        owned = nodes[nodes < imap.size_local]
        unrolled = 3 * owned[:, None] + np.arange(3)
        if parent is None:
            self._local = unrolled
            gdofs = 3 * imap.local_to_global(owned)[:, None] + np.arange(3)
        else:
            W, to_parent = parent
            self._local = np.asarray(to_parent, dtype=np.int32)[unrolled]
            gdofs = W.dofmap.index_map.local_to_global(self._local.reshape(-1)).reshape(-1, 3)
        # Global dofs (x, y, z) of every contact node, gathered: (n, 3).
        self._dofs = np.vstack(self.comm.allgather(gdofs)).astype(PETSc.IntType)
        X = np.vstack(self.comm.allgather(V.tabulate_dof_coordinates()[owned]))
        self.X = X
        # Pairs per valley and side, as indices into the gathered arrays.
        self.groups = {}
        cells = geometry.cells()
        valleys = [(x0 + a, x0 + b, kappa) for x0, kappa in zip(offsets, penalties)
                   for (_, a), (b, _) in zip(cells[:-1], cells[1:])]
        for k, (x1, x2, kappa) in enumerate(valleys):
            for side, sign in (("top", 1.0), ("bottom", -1.0)):
                half = sign * X[:, 1] > 0
                a = np.flatnonzero(half & (np.abs(X[:, 0] - x1) < 1e-6))
                b = np.flatnonzero(half & (np.abs(X[:, 0] - x2) < 1e-6))
                dist, j = cKDTree(X[b]).query(X[a] + [x2 - x1, 0.0, 0.0])
                if len(a) != len(b) or len(a) == 0 or dist.max() > 1e-6:
                    raise RuntimeError(f"valley {k} ({side}): faces are not meshed periodically")
                area = (geometry.height - geometry.valley_height) / 2 * geometry.width / 2
                self.groups[(k, side)] = (a, b[j], kappa * area / len(a))   # kappa w (N/mm)

    def coupled_dofs(self) -> np.ndarray:
        """Global (x, y) dofs of both nodes of every pair, (n_pairs, 4): the entries
        add_tangent writes (for the tangent's sparsity pattern)."""
        return np.vstack([np.column_stack([self._dofs[a][:, :2], self._dofs[b][:, :2]])
                          for a, b, _ in self.groups.values()])

    def positions(self, u: fem.Function) -> np.ndarray:
        """Deformed positions of all contact nodes, gathered on every rank. (n, 3) mm."""
        mine = u.x.array[self._local]
        return self.X + np.vstack(self.comm.allgather(mine))

    @staticmethod
    def normal(xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
        """Unit normal (3,) of the best-fit plane through both faces, in the xy-plane,
        pointing from face a to face b."""
        pts = np.vstack([xa - xa.mean(axis=0), xb - xb.mean(axis=0)])
        if not np.isfinite(pts).all():    # a diverged iterate: let Newton see NaN
            return np.full(3, np.nan)
        n = np.linalg.svd(pts, full_matrices=False)[2][-1]
        n[2] = 0.0
        n /= np.linalg.norm(n)
        return n if n @ (xb.mean(axis=0) - xa.mean(axis=0)) > 0 else -n

    def gaps(self, u: fem.Function) -> dict:
        """Signed gap g (mm) of every pair, per (valley, side): {key: (n_pairs,)}."""
        x = self.positions(u)
        out = {}
        for key, (a, b, _) in self.groups.items():
            out[key] = (x[b] - x[a]) @ self.normal(x[a], x[b])
        return out

    def _terms(self, u: fem.Function):
        """Per pair: global (x, y, z) dofs of a and b (n, 3), normal, k w <-g>, k w H(-g)."""
        x = self.positions(u)
        for a, b, kw in self.groups.values():
            n = self.normal(x[a], x[b])
            g = (x[b] - x[a]) @ n
            closed = g < 0
            yield (self._dofs[a], self._dofs[b], n, kw * np.where(closed, -g, 0.0), kw * closed)

    def add_residual(self, b: PETSc.Vec, u: fem.Function) -> None:
        """b += dPi_c/du (collective)."""
        terms = list(self._terms(u))
        if self.comm.rank == 0:
            for ga, gb, n, f, _ in terms:
                for c in (0, 1):
                    b.setValues(ga[:, c], f * n[c], addv=PETSc.InsertMode.ADD)
                    b.setValues(gb[:, c], -f * n[c], addv=PETSc.InsertMode.ADD)
        b.assemblyBegin()
        b.assemblyEnd()

    def add_tangent(self, A: PETSc.Mat, u: fem.Function) -> None:
        """A += d²Pi_c/du² in the (x, y) dofs of every pair (collective; A is left
        flush-assembled, call A.assemble() after)."""
        A.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)
        A.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)
        terms = list(self._terms(u))
        if self.comm.rank == 0:
            sign = np.array([[1.0, -1.0], [-1.0, 1.0]])
            for ga, gb, n, _, k in terms:
                # One 4 x 4 block per pair on dofs (a_x, a_y, b_x, b_y), all pairs of the
                # group in one CSR insertion: rows = the dofs, each row's columns = its pair's.
                dofs = np.column_stack([ga[:, 0], ga[:, 1], gb[:, 0], gb[:, 1]]).astype(PETSc.IntType)
                blocks = k[:, None, None] * np.kron(sign, np.outer(n[:2], n[:2]))
                A.setValuesIJV(np.arange(0, blocks.size + 1, 4, dtype=PETSc.IntType),
                               np.repeat(dofs, 4, axis=0).reshape(-1), blocks.reshape(-1),
                               addv=PETSc.InsertMode.ADD, rowmap=dofs.reshape(-1))


class ContactTerms:
    """Several contact terms behind the one interface fem.solvers.load_path calls (add_residual,
    add_tangent, coupled_dofs, and the optional refuses and low_rank: fem.physics.object_contact);
    None terms dropped. fem.solvers.load_path.TangentAction reads ``terms`` itself, to apply the
    ones with a facet-form tangent (``action_form``) without a matrix. A problem with one
    term keeps that term itself, so its answers are unchanged."""

    def __init__(self, *terms):
        self.terms = [t for t in terms if t is not None]

    def __bool__(self) -> bool:
        return bool(self.terms)

    def coupled_dofs(self) -> list[np.ndarray]:
        """Every term's rows of coupled global dofs (each row: one dense block)."""
        return [row for t in self.terms for row in t.coupled_dofs()]

    def add_residual(self, b: PETSc.Vec, u: fem.Function) -> None:
        for t in self.terms:
            t.add_residual(b, u)

    def add_tangent(self, A: PETSc.Mat, u: fem.Function) -> None:
        for t in self.terms:
            t.add_tangent(A, u)

    def refuses(self, u: fem.Function) -> str:
        """The first term's reason to refuse a converged state (``refuses``), or ""."""
        reasons = (t.refuses(u) for t in self.terms if hasattr(t, "refuses"))
        return next((why for why in reasons if why), "")

    def low_rank(self, u: fem.Function) -> list:
        """Every term's low-rank tangent pairs (a, b), dR += a bᵀ (a term without them: none)."""
        return [pair for t in self.terms if hasattr(t, "low_rank") for pair in t.low_rank(u)]
