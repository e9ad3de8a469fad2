"""Load-path Newton solver of any :class:`fem.problem.Problem`.

Units: mm, N, MPa (= N/mm²), N·mm; angles in rad.

:class:`LoadPathSolver` solves R(u; v; a) = 0 (the problem's residual, :mod:`fem.problem`)
along the linear load path a(s) = a_0 + s (a_1 - a_0), s from 0 to 1:

* steps in s with automatic cut-back: a step whose Newton iteration fails (or whose
  converged state the contact refuses, its optional ``refuses``) is undone and halved, and
  the path stops at its last converged state below ``min_step``;
* Newton with the exact tangent K = dR/du (contact blocks included), each correction by
  GMRES preconditioned with the MUMPS LU of a recent tangent, plus cheap chord steps; a
  contact term may keep a low-rank part a bᵀ of K out of the matrix (``low_rank``, e.g. the
  object's friction, dense over all its dofs): GMRES then applies K = A + a bᵀ
  (:class:`LowRankTangent`) and the LU factorises A;
* after each converged step the problem's lagged constants take their new values;
* sensitivities at a converged state: du/da = -K^{-1} dR/da, one back-substitution per
  load entry (dR/da_j = sum_i dc_i/da_j G_i over the problem's load terms), evaluated at
  the probe points.

The solver knows no physics: the joint, the beam (fem.solver) and the whole finger
(fem.finger) are problems handed to it. Collective over the problem's communicator; only
rank 0 logs.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import ufl
import dolfinx.cpp
from dolfinx import fem, geometry
from dolfinx.fem.petsc import (apply_lifting, assemble_matrix, assemble_vector, create_matrix,
                               create_vector, set_bc)
from mpi4py import MPI
from petsc4py import PETSc

from fem.problem import Problem

log = logging.getLogger("softjoint.fem")

#: MUMPS ICNTL(14): % allowed over its workspace estimate. Its default failed the 1.2:0.6
#: mesh on 2 ranks (INFOG(1) = -20, reception buffer too small). Memory only, so not a
#: SolverConfig field: a campaign's solver (its config, in every manifest) is unchanged.
MUMPS_WORKSPACE_PERCENT = 100


@dataclass(frozen=True)
class SolverConfig:
    """Discretisation and Newton / load-stepping controls."""

    degree: int = 2                 # Lagrange degree of u
    quadrature_degree: int = 2      # exact for the linearised P2 stiffness; see mesh study
    atol: float = 1e-8              # Newton: absolute residual 2-norm (N)
    stol: float = 1e-9              # Newton: |du| <= stol |u|, just above round-off
    max_it: int = 12
    chord_steps: int = 3            # extra back-substitutions per factorisation (see newton)
    krylov_rtol: float = 1e-9       # Newton corrections: GMRES on the current tangent with
                                    # a recent LU as preconditioner
    sensitivity_rtol: float = 1e-10 # GMRES for d u / d inputs
    krylov_max_it: int = 30         # more: refactorise (the preconditioner went stale)
    mumps_blr: float | None = 1e-8  # MUMPS block low-rank dropping threshold (None: exact LU)
    box_step: float = 0.25          # first step: at most this fraction of the box per input
    first_step: float | None = None # or a fixed first path fraction (e.g. for the beam)
    max_step: float = 1.0
    min_step: float = 1.0 / 256     # give up below this path fraction
    grow: float = 1.5               # step growth after an easy step (<= 6 iterations)
    contact_penalty: float = 100.0  # valley self-contact, MPa/mm of overlap (0: off), at
                                    # E = 12.2 MPa: fem.problem.contact_penalty_for

    def discretisation(self) -> dict:
        """The keyword arguments of the problem builders (fem.problem.joint_problem)."""
        return {"degree": self.degree, "quadrature_degree": self.quadrature_degree,
                "contact_penalty": self.contact_penalty}

@dataclass
class PathOutcome:
    """How a load path went: the load vector reached, Newton figures, and why it stopped."""

    converged: bool
    reached: np.ndarray
    newton_iterations: list[int]
    load_steps: int
    cutbacks: int
    reason: str


class Probes:
    """Point evaluation of vector Functions at fixed material points (mm), gathered on
    every rank (collective): under MPI each rank sees only its own cells."""

    def __init__(self, mesh, points: np.ndarray):
        self.mesh, self.points = mesh, np.asarray(points, dtype=float).reshape(-1, 3)
        tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
        cand = geometry.compute_collisions(tree, self.points)
        coll = geometry.compute_colliding_cells(mesh, cand, self.points)
        self.cells = np.array([coll.links(i)[0] if len(coll.links(i)) else -1
                               for i in range(len(self.points))], dtype=np.int32)
        self._collapsed = None   # (mixed space, its u block's space, u's dofs in it)

    def __len__(self) -> int:
        return len(self.points)

    def values(self, func) -> np.ndarray:
        """Values of ``func`` at the points, shape (n, 3), of its displacement block for a
        mixed (u, p) unknown; raises if one is outside."""
        if type(func.function_space.ufl_element()) is ufl.MixedElement:
            func = self._displacement_block(func)   # dolfinx evaluates no mixed element
        points, cells = self.points, self.cells
        vals = np.full((len(points), 3), np.nan)
        mine = cells >= 0
        if mine.any():
            vals[mine] = func.eval(points[mine], cells[mine])
        gathered = self.mesh.comm.allgather(vals)
        out = np.full_like(vals, np.nan)
        for g in gathered:   # first rank that owns a point wins: no duplicates
            take = np.isnan(out[:, 0]) & ~np.isnan(g[:, 0])
            out[take] = g[take]
        if np.isnan(out).any():
            raise RuntimeError("a probe point lies outside the mesh")
        return out

    def _displacement_block(self, func) -> fem.Function:
        """The u block of a mixed Function, as ``func.sub(0).collapse()`` gives it. The
        collapsed space and its dof map are built once per mixed space: building them costs
        about one tangent assembly, and a continuation sample evaluates the probes five
        times (its state and four sensitivities)."""
        W = func.function_space
        if self._collapsed is None or self._collapsed[0] is not W:
            U, to_parent = W.sub(0).collapse()
            self._collapsed = (W, U, np.asarray(to_parent, dtype=np.int64))
        _, U, to_parent = self._collapsed
        block = fem.Function(U)
        block.x.array[:] = func.x.array[to_parent]
        return block


class LowRankTangent:
    """The operator x -> A x + sum_k a_k (b_k · x) as a PETSc Python shell matrix (``mat``):
    the assembled tangent A plus a contact's low-rank part (module docstring). The pairs are
    zero on the Dirichlet dofs, whose rows and columns stay A's (the identity)."""

    def __init__(self, A: PETSc.Mat):
        self.A, self.pairs = A, []
        self.mat = PETSc.Mat().createPython(A.getSizes(), self, comm=A.getComm())
        self.mat.setUp()

    def set(self, pairs: list, bcs: list) -> None:
        """Take the pairs (a, b) of the current tangent (and destroy the previous ones)."""
        for vec in (v for pair in self.pairs for v in pair):
            vec.destroy()
        for vec in (v for pair in pairs for v in pair):
            set_bc(vec, bcs, scale=0.0)
        self.pairs = list(pairs)

    def mult(self, mat: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.A.mult(x, y)
        for a, b in self.pairs:
            y.axpy(b.dot(x), a)


class LoadPathSolver:
    """Load stepping with cut-back and Newton (GMRES on the exact tangent, preconditioned
    by a recent MUMPS LU) of one :class:`fem.problem.Problem` (module docstring); keeps
    its converged state for continuation. Collective over the problem's communicator.

    ``state``: the load vector of the current converged state; ``factorisations``,
    ``krylov_iterations``: running totals (diagnostics)."""

    def __init__(self, problem: Problem, config: SolverConfig = SolverConfig()):
        self.problem, self.config = problem, config
        self.u, self.bcs, self.contact = problem.u, list(problem.bcs), problem.contact
        self.V, self.comm = problem.V, problem.comm
        R = problem.residual()
        self._R = fem.form(R)
        self._J = fem.form(ufl.derivative(R, self.u, ufl.TrialFunction(self.V)))
        self._load_forms = [fem.form(term.form) for term in problem.loads]
        self._A = self._tangent_matrix()       # the tangent at the current iterate
        # GMRES's operator: _A, or _A plus the contact's low-rank part (LowRankTangent)
        self._low_rank = LowRankTangent(self._A) if hasattr(self.contact, "low_rank") else None
        self._op = self._A if self._low_rank is None else self._low_rank.mat
        self._b = create_vector(self._R)
        self._bc_gap = create_vector(self._R)   # g - u on the Dirichlet dofs (_lifting_needed)
        self._tangent()                          # fixes the sparsity pattern
        self._P = self._A.duplicate(copy=True)   # the last tangent that was factorised
        self._u_saved, self._du, self._chord = (fem.Function(self.V) for _ in range(3))
        self._lagged_saved = [0.0] * len(problem.lagged)
        self.ksp = self._create_ksp()
        self.pc = self.ksp.getPC()
        self.probes = Probes(self.V.mesh, problem.probe_points)
        self.state = np.zeros(len(problem.load_scale))  # load vector of the converged state
        self.factorisations = 0                    # LU factorisations so far (diagnostics)
        self.krylov_iterations = 0                 # GMRES iterations so far (diagnostics)
        self._refactor = True                      # factorise before the next tangent solve?
        self._factor_fresh = False                 # last factorisation near current state?

    def _create_ksp(self) -> PETSc.KSP:
        """GMRES on the current tangent _op (_A, with the contact's low-rank part if any),
        preconditioned by the MUMPS LU of _P (a recent tangent's _A). PETSc refactorises
        only when _P changes, and keeps MUMPS' symbolic factorisation throughout because
        the sparsity pattern never changes."""
        config = self.config
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(self._op, self._P)
        ksp.setOptionsPrefix(f"softjoint_{id(self)}_")
        opts = PETSc.Options()
        prefix = ksp.getOptionsPrefix()
        opts[f"{prefix}ksp_type"] = "gmres"
        opts[f"{prefix}ksp_gmres_restart"] = config.krylov_max_it
        opts[f"{prefix}ksp_atol"] = 0.0
        opts[f"{prefix}ksp_max_it"] = config.krylov_max_it
        opts[f"{prefix}pc_type"] = "lu"
        opts[f"{prefix}pc_factor_mat_solver_type"] = "mumps"
        opts[f"{prefix}mat_mumps_icntl_14"] = MUMPS_WORKSPACE_PERCENT
        if config.mumps_blr:
            # Block low-rank LU: ~40 % faster factorisations at the 1.8 mm P2 mesh; the
            # tangent is then exact to ~1e-8, which Newton (exact residual) absorbs.
            opts[f"{prefix}mat_mumps_icntl_35"] = 1
            opts[f"{prefix}mat_mumps_cntl_7"] = config.mumps_blr
        ksp.setFromOptions()
        return ksp

    # ------------------------------------------------------------------ state
    def _set_load(self, a: np.ndarray) -> None:
        self.problem.set_load(a)

    def _converged_step(self) -> None:
        """A load step converged: the lagged constants take their values (before saving)."""
        for lagged in self.problem.lagged:
            lagged.constant.value = lagged.average.value(self.comm)

    def _save(self) -> None:
        """Keep the converged state as the fall-back of the next step."""
        self._u_saved.x.array[:] = self.u.x.array
        self._lagged_saved = [float(lg.constant.value) for lg in self.problem.lagged]

    def _restore(self) -> None:
        """A load step failed: return to the last saved state."""
        self.u.x.array[:] = self._u_saved.x.array
        for lagged, value in zip(self.problem.lagged, self._lagged_saved):
            lagged.constant.value = value

    def reset(self) -> None:
        """Return to the undeformed, unloaded state."""
        for lagged in self.problem.lagged:
            lagged.constant.value = 0.0
        self.u.x.array[:] = 0.0
        self.state = np.zeros(len(self.problem.load_scale))
        self._set_load(self.state)
        self._factor_fresh = False
        self._refactor = True           # the LU belongs to another state

    # ------------------------------------------------------------------ outputs
    def average(self, name: str) -> float:
        """The problem's volume average ``name`` at the current state (collective)."""
        return self.problem.averages[name].value(self.comm)

    def probe_displacements(self) -> np.ndarray:
        """u (mm) at the problem's probe points, shape (n, 3) (collective)."""
        return self.probes.values(self.u)

    def mesh_info(self) -> dict:
        """Global mesh figures: vertices, cells, nodes (incl. mid-side for P2), dofs, and the
        mesh's size (mm; a hexahedral joint: its ``divisions`` instead, and its ``hex_size``
        when graded)."""
        mesh_data = self.problem.mesh_data
        mesh, geometry = mesh_data.mesh, mesh_data.geometry
        divisions, hex_size = getattr(geometry, "divisions", 0), getattr(geometry, "hex_size", None)
        info = {"vertices": mesh.topology.index_map(0).size_global,
                "cells": mesh.topology.index_map(mesh.topology.dim).size_global,
                "degree": self.config.degree,
                **({"divisions": divisions} if divisions else {"mesh_size": geometry.mesh_size}),
                **({"hex_size": hex_size} if hex_size else {})}
        if self.problem.displacement_space is None:
            nodes = self.V.dofmap.index_map.size_global
            return {**info, "nodes": nodes, "dofs": nodes * self.V.dofmap.index_map_bs}
        # mixed: nodes of u; dofs of the whole unknown (u and p)
        return {**info, "nodes": self.problem.displacement_space.dofmap.index_map.size_global,
                "dofs": self.V.dofmap.index_map.size_global * self.V.dofmap.index_map_bs,
                "formulation": self.problem.formulation}

    # ------------------------------------------------------------------ algebra
    def _residual(self) -> float:
        """Assemble R(u) into self._b (Dirichlet rows: u - 0); return its 2-norm (N)."""
        b = self._b
        with b.localForm() as loc:
            loc.set(0.0)
        assemble_vector(b, self._R)
        if self._lifting_needed():
            apply_lifting(b, [self._J], bcs=[self.bcs], x0=[self.u.vector], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.contact:
            self.contact.add_residual(b, self.u)
        set_bc(b, self.bcs, self.u.vector, -1.0)
        return b.norm()

    def _lifting_needed(self) -> bool:
        """Whether u differs from a Dirichlet value anywhere (on any rank). Only then does
        the lifting, -K(u) (g - u) on the constrained columns, change R: otherwise it adds
        exact zeros, at the price of the tangent's kernel on every constrained cell (~7 %
        of a continuation sample on hexahedra). u meets its conditions from the first
        correction on (the constrained rows of R are u - g)."""
        gap = self._bc_gap
        with gap.localForm() as loc:
            loc.set(0.0)
        set_bc(gap, self.bcs, self.u.vector)            # g - u on the constrained dofs
        return self.comm.allreduce(bool(np.any(gap.array_r != 0.0)), op=MPI.LOR)

    def _tangent_matrix(self) -> PETSc.Mat:
        """The tangent's matrix: the form's sparsity pattern plus the contact pairs' blocks,
        which couple nodes that share no cell. On one rank the pairs are put in the
        pattern before the matrix is made; inserting them afterwards reallocates the
        matrix for every new row, which took 120 s (a minute per ~10k Q2 nodes) on a
        hexahedral joint, whose valley faces carry many nodes. On several ranks a pair's
        nodes may lie on ranks that do not see each other, so the entries are allowed
        into the pattern as they come."""
        if self.contact is None:
            return create_matrix(self._J)
        if self.comm.size > 1:
            A = create_matrix(self._J)
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
            return A
        pattern = fem.create_sparsity_pattern(self._J)
        bs = self.V.dofmap.index_map_bs
        for dofs in self.contact.coupled_dofs():
            blocks = np.unique(dofs // bs).astype(np.int32)   # one rank: local = global
            pattern.insert(blocks, blocks)
        pattern.assemble()
        return dolfinx.cpp.la.petsc.create_matrix(self.comm, pattern)

    def _tangent(self) -> None:
        """Assemble the tangent K(u) at the current iterate into _A (and its low-rank part,
        if any, into _op)."""
        self._A.zeroEntries()
        assemble_matrix(self._A, self._J, bcs=self.bcs)
        if self.contact:
            self.contact.add_tangent(self._A, self.u)
        self._A.assemble()
        if self._low_rank is not None:
            self._low_rank.set(self.contact.low_rank(self.u), self.bcs)

    def _mumps_status(self) -> str:
        """MUMPS' own error figures after a failed factorisation (INFOG(1) < 0: -9/-8
        workspace too small, -10 singular; INFOG(2): its detail), for the failure reason."""
        try:
            F = self.pc.getFactorMatrix()
            return f"MUMPS INFOG(1) = {F.getMumpsInfog(1)}, INFOG(2) = {F.getMumpsInfog(2)}"
        except PETSc.Error:
            return "no MUMPS factor"

    def _factorise(self, assemble: bool = True) -> None:
        """Assemble K(u) (unless _A already holds it) and factorise it as the new _P."""
        if assemble:
            self._tangent()
        self._A.copy(self._P, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.ksp.setOperators(self._op, self._P)
        self.ksp.setUp()
        self._refactor = False
        self.factorisations += 1

    def _solve_tangent(self, b: PETSc.Vec, x: PETSc.Vec, rtol: float | None = None) -> None:
        """x = K(u)^-1 b with K(u) in _A: GMRES preconditioned by the LU of _P.

        A preconditioner that needed more than half of ``krylov_max_it`` iterations is
        drifting away from K: the next call refactorises first, rather than after a failed
        GMRES run (a wasted 30-iteration cycle, about a third of a factorisation). If GMRES still stalls,
        refactorise and solve again."""
        if self._refactor:
            self._factorise(assemble=False)
        self.ksp.setTolerances(rtol=rtol or self.config.krylov_rtol)
        self.ksp.solve(b, x)
        self.krylov_iterations += self.ksp.getIterationNumber()
        if self.ksp.getConvergedReason() <= 0:
            self._factorise(assemble=False)
            self.ksp.solve(b, x)
            self.krylov_iterations += self.ksp.getIterationNumber()
            if self.ksp.getConvergedReason() <= 0:
                raise PETSc.Error(76)   # the caller cuts the step back
        self._refactor = self.ksp.getIterationNumber() > self.config.krylov_max_it // 2

    def newton(self, reuse_factor: bool = False) -> tuple[int, bool]:
        """Newton iterations at the current load from the current u: (iterations, converged).

        Each correction solves with the tangent K(u) by GMRES, preconditioned with the LU
        of a recent tangent (_P): an assembly and a few back-substitutions, ~10x cheaper
        than a factorisation, which happens only when GMRES stalls (``_solve_tangent``).

        With ``reuse_factor`` the first correction uses the tangent already in _A, i.e.
        that of the last converged state under its own load (an Euler predictor).
        This matters: at a new pressure the consistent tangent contains the follower
        load stiffness p dcofac(F)N/du without the wall pre-stress that balances it, and
        from the unstressed state it is near-singular (tip response flips sign at
        P ~ 0.03 MPa), so a consistent first step would overshoot wildly.

        Converged when ||R|| <= atol, or when the last correction satisfies
        ||du|| <= stol ||u|| (the residual then sits at its round-off floor, which grows
        with the cap stiffness and mesh size). Aborts early on a non-finite or exploding
        residual.
        """
        cfg = self.config
        r0 = self._residual()
        norm, du = r0, math.inf
        for it in range(cfg.max_it + 1):
            if it > 0:
                norm = self._residual()
                du = self._du.vector.norm()
            if not math.isfinite(norm) or norm > 1e6 * max(r0, 1.0):
                return it, False
            if self.comm.rank == 0:
                log.debug("  Newton %d: |R| = %.3e N, |du| = %.3e mm", it, norm, du)
            # u is written through numpy (x.array), which PETSc does not see: u.vector.norm()
            # would return the norm PETSc cached at u = 0, so the step test never fired
            if norm <= cfg.atol or du <= cfg.stol * self.u.x.norm():
                return it, True
            if it == cfg.max_it:
                return it, False
            if not (it == 0 and reuse_factor):
                self._tangent()
            self._solve_tangent(self._b, self._du.vector)
            self._exact_on_dirichlet(self._du)
            self._du.x.scatter_forward()
            self.u.x.array[:] -= self._du.x.array
            self._chord_steps(cfg.chord_steps)
        return cfg.max_it, False

    def _exact_on_dirichlet(self, du: fem.Function) -> None:
        """du = u - g on the constrained dofs, exactly: the Krylov solve meets those rows only
        to its tolerance, and u - du would leave ~1e-33 mm off a condition, enough to make
        the residual pay for a lifting (``_lifting_needed``)."""
        set_bc(du.vector, self.bcs, self.u.vector, -1.0)

    def _chord_steps(self, n: int) -> None:
        """Up to n extra corrections with the current LU alone, kept while each at
        least halves ||R||. A Newton step that rotates material leaves a residual spike
        from the linearised rotation (J - 1 ~ theta^2, times lambda ~ 200 MPa at
        nu = 0.49); a chord step removes most of it for ~2 % of a factorisation.
        """
        w = self._chord
        r_prev = self._residual()
        for _ in range(n):
            self.pc.apply(self._b, w.vector)
            self._exact_on_dirichlet(w)
            w.x.scatter_forward()
            self.u.x.array[:] -= w.x.array
            r = self._residual()
            if not r < 0.5 * r_prev:
                self.u.x.array[:] += w.x.array
                return
            r_prev = r

    # ------------------------------------------------------------------ load path
    def follow(self, start: np.ndarray, target: np.ndarray) -> PathOutcome:
        """Follow the linear load path start -> target (load vectors) from the current
        converged state. A step whose Newton iteration fails is undone and halved; below
        ``min_step`` the path stops at its last converged state (never a non-converged
        one), which becomes ``self.state``."""
        cfg = self.config
        span = np.abs((target - start) / self.problem.load_scale).max()
        ds = cfg.first_step or min(cfg.max_step, cfg.box_step / max(span, 1e-300))
        s = 0.0
        iters, cutbacks, steps, reason = [], 0, 0, ""
        self._save()
        while s < 1.0 - 1e-14:
            s_try = min(1.0, s + ds)
            if not self._factor_fresh:      # tangent of the converged state, own load
                self._set_load(start + s * (target - start))
                self._tangent()
                self._factor_fresh = True
            self._set_load(start + s_try * (target - start))
            n, ok, why = self._guarded_newton(reuse_factor=True)
            reason = why or reason
            if ok:
                s, steps = s_try, steps + 1
                iters.append(int(n))
                self._converged_step()
                self._save()
                # The last tangent (previous iterate, same load) is off from the converged
                # one by the last correction only: good enough as the next predictor.
                self._factor_fresh = n > 1
                if self.comm.rank == 0:
                    log.info("load step %d: path %.4f, %d Newton iterations", steps, s, n)
                ds = min(cfg.max_step, ds * cfg.grow) if n <= 6 else ds
            else:
                cutbacks += 1
                self._restore()
                self._factor_fresh = False
                ds /= 2
                if self.comm.rank == 0:
                    log.info("cut back at path %.4f -> step %.5f", s, ds)
                if ds < cfg.min_step:
                    reason = reason or f"no convergence after {cutbacks} cut-backs at path {s:.4f}"
                    break
        converged = s >= 1.0 - 1e-14
        self.state = start + s * (target - start)
        self._set_load(self.state)
        return PathOutcome(converged, self.state, iters, steps, cutbacks, "" if converged else reason)

    def _guarded_newton(self, reuse_factor: bool) -> tuple[int, bool, str]:
        """newton(), with a non-finite iterate or a MUMPS failure (a singular or NaN
        tangent) as a failed solve, and a converged state that the contact refuses (its
        optional ``refuses(u)``: a one-line reason, e.g. the finger tunnelled into an
        object) too: (iterations, converged, reason or "")."""
        try:
            n, ok = self.newton(reuse_factor=reuse_factor)
        except PETSc.Error as exc:
            return self.config.max_it, False, f"{str(exc).splitlines()[0]}, {self._mumps_status()}"
        why = self.contact.refuses(self.u) if ok and hasattr(self.contact, "refuses") else ""
        return n, ok and not why and bool(np.isfinite(self.u.x.array).all()), why

    def converge(self) -> PathOutcome:
        """Newton at the load ``state`` from the current iterate u, which is a guess
        (e.g. fem.transfer.seed: another mesh's answer at that load) rather than a
        converged state: no load path.

        The first correction uses the consistent tangent at the guess, factorised afresh
        (the LU in hand belongs to another state); a guess close to equilibrium carries
        its pre-stress, so the consistent tangent is the right one (unlike a new load
        from a converged state, see ``newton``). Converged: the lagged constants take
        their values and the state is saved, as after a step of ``follow``, so
        continuation and sensitivities work from it. Not converged: the guess had no
        converged state behind it, so the solver returns to the undeformed, unloaded
        state (``reset``), where ``follow`` from zero starts."""
        self._set_load(self.state)
        self._refactor, self._factor_fresh = True, False
        n, ok, reason = self._guarded_newton(reuse_factor=False)
        if self.comm.rank == 0:
            log.info("converge from a guess: %d Newton iterations, converged=%s", n, ok)
        if not ok:
            self.reset()
            return PathOutcome(False, self.state.copy(), [int(n)], 0, 0,
                               reason or f"no convergence from the guess in {n} Newton iterations")
        self._converged_step()
        self._save()
        self._factor_fresh = n > 1          # as in follow: _A is near the converged tangent
        return PathOutcome(True, self.state.copy(), [int(n)], 1, 0, "")

    # ------------------------------------------------------------------ sensitivities
    def sensitivities(self) -> np.ndarray:
        """du/da at the probe points at the current converged state, shape (n, 3, len(a)):
        mm per unit of each load entry.

        Solves with the tangent re-assembled at the converged state, by GMRES to
        ``sensitivity_rtol`` preconditioned with the current LU. The tangent left in _A
        by Newton is that of the iterate before the last correction (and chord steps): it
        is off by that correction, which depends on the iteration path, so serial and
        parallel runs would disagree at ~1e-4. A one-sided load (a chamber pressure) at
        a_j = 0 takes the derivative of its + side.
        """
        self._tangent()
        self._factor_fresh = True       # _A is now the converged tangent at its own load
        out = np.zeros((len(self.probes), 3, len(self.state)))
        w = fem.Function(self.V)
        for j in range(len(self.state)):
            b = self._load_derivative(j)
            if b is None:               # no load term follows a_j here (the beam's P)
                continue
            set_bc(b, self.bcs, scale=0.0)
            self._solve_tangent(b, w.vector, self.config.sensitivity_rtol)
            w.x.scatter_forward()
            out[:, :, j] = -self.probes.values(w)    # K du = -dR/da_j
            b.destroy()
        return out

    def _load_derivative(self, j: int) -> PETSc.Vec | None:
        """dR/da_j = sum_i dc_i/da_j G_i assembled (None when no term acts)."""
        b = None
        for term, form in zip(self.problem.loads, self._load_forms):
            slope = term.slope(self.state)
            if term.index != j or slope == 0.0:
                continue
            g = assemble_vector(form)
            g.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            if b is None:
                b = g
                b.scale(slope)
            else:
                b.axpy(slope, g)
                g.destroy()
        return b
