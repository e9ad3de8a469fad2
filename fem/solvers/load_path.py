"""Load-path Newton solver of any :class:`fem.physics.problem.Problem`.

Units: mm, N, MPa (= N/mm²), N·mm; angles in rad.

:class:`LoadPathSolver` solves R(u; v; a) = 0 (the problem's residual, :mod:`fem.physics.problem`)
along the linear load path a(s) = a_0 + s (a_1 - a_0), s from 0 to 1:

* steps in s with automatic cut-back: a step whose Newton iteration fails is undone and
  halved, and the path stops at its last converged state below ``min_step``;
* each step starts from the Euler predictor u_0 + du/da (a_1 - a_0) at the converged
  state u_0, then Newton with the exact tangent K = dR/du (contact blocks included), each
  correction by GMRES preconditioned with a MUMPS factorisation of a tangent at the
  step's load, plus cheap chord steps;
* GMRES applies K matrix-free (:class:`TangentAction`): y = K(u) x is the vector
  assembly of the linear form dR(u; v)[x] (the derivative of R along x) plus the contact
  terms along x (a facet term's own linear form, ``action_form``; node-pair blocks times
  x), with K's Dirichlet rows and columns (unit rows, zero columns) as dolfinx assembles
  them and the contact added after them, as on the assembled K. It equals the assembled
  K x to round-off and cheaper than assembling K (its costs: docs/decisions.md §1). So K
  is assembled only to be factorised: once a load step, as LDL^T while the tangents are
  symmetric (the Hessian of a potential), LU otherwise;
* after each converged step the problem's lagged constants take their new values;
* sensitivities at a converged state: du/da = -K^{-1} dR/da (dR/da_j = sum_i dc_i/da_j G_i
  over the problem's load terms), all load entries at once by block GMRES
  (:mod:`fem.solvers.block_krylov`), evaluated at the probe points; the whole fields are kept as
  the next step's predictor.

The solver knows no physics: the joint, the beam (fem.solvers.joint) and the whole finger
(fem.solvers.finger) are problems handed to it. Collective over the problem's communicator; only
rank 0 logs.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass

import numpy as np
import ufl
import dolfinx.cpp
from dolfinx import fem, geometry
from dolfinx.fem.petsc import (apply_lifting, assemble_matrix, assemble_vector, create_matrix,
                               create_vector, set_bc)
from mpi4py import MPI
from petsc4py import PETSc

from fem.solvers.block_krylov import block_gmres
from fem.mesh.discretisation import SolverConfig
from fem.physics.problem import Problem

log = logging.getLogger("softjoint.fem")

#: MUMPS ICNTL(14): % allowed over its workspace estimate. Its default failed the 1.2:0.6
#: mesh on 2 ranks (INFOG(1) = -20, reception buffer too small). Memory only, so not a
#: SolverConfig field: a campaign's solver (its config, in every manifest) is unchanged.
MUMPS_WORKSPACE_PERCENT = 100


@dataclass
class Rates:
    """du/da of a converged state (``LoadPathSolver.sensitivities``), kept for the Euler
    predictor of a step from that state: the state's unknown (this rank's array, ghosts
    included), lagged values and load vector, and du/da_j (this rank's entries, exactly
    zero on the Dirichlet dofs) for every load entry j that a load term follows."""

    u: np.ndarray
    lagged: list[float]
    load: np.ndarray
    du_da: dict[int, np.ndarray]


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


class TangentAction:
    """The tangent K(u) of a residual form R(u; v) as an operator x -> K(u) x that is never
    assembled (module docstring): ``mat``, a PETSc Python shell matrix, GMRES's operator.

    K is the matrix dolfinx assembles with Dirichlet conditions ``bcs`` (their rows and
    columns zero but a unit diagonal) plus the ``contact`` terms' tangents (added after the
    conditions, as ``add_tangent`` does to an assembled tangent) and their optional
    low-rank part sum_k a_k b_kᵀ (``low_rank``, e.g. an object's friction, dense over all
    its dofs; zero on the conditions' rows and columns). A term whose tangent is a facet
    form (``action_form``: an object, the plane X = 0) is applied as that form along x, on
    its few facets; the others' node-pair blocks (the valleys) as a matrix of their own
    narrow pattern. The form terms are read at the current values of u and of the
    problem's constants (loads, lagged values) at every product; the lagged values of the
    contact (``linearise``), its blocks and pairs are those of the last :meth:`update`.
    Collective."""

    def __init__(self, residual: ufl.Form, u: fem.Function, bcs: list, contact, template: PETSc.Mat):
        V = u.function_space
        self._x = fem.Function(V)                # the direction x (zero on the conditions for _form)
        self._form = fem.form(ufl.derivative(residual, u, self._x))
        self._y = create_vector(self._form)      # ghosted: the assembly adds into ghosts
        self._u, self.contact, self._bcs = u, contact, bcs
        self._pairs = []                         # the contact's low-rank part [(a, b)]
        self._owned = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        constrained = [bc.dof_indices()[0] for bc in bcs]
        self._fixed = np.unique(np.concatenate(constrained)) if constrained else np.zeros(0, np.int32)
        self.fixed_owned = self._fixed[self._fixed < self._owned]
        terms = list(getattr(contact, "terms", [contact] if contact else []))
        self._facet = [(t, t.action_form(self._x)) for t in terms if hasattr(t, "action_form")]
        self._blocks = [t for t in terms if not hasattr(t, "action_form")]
        self._yc = create_vector(self._form) if self._facet else None
        self._contact = self._contact_matrix(template) if self._blocks else None
        self.mat = PETSc.Mat().createPython(template.getSizes(), self, comm=template.getComm())
        self.mat.setUp()

    def _contact_matrix(self, template: PETSc.Mat) -> PETSc.Mat:
        """An empty matrix of ``template``'s layout with room for the node-pair blocks: a
        row of a coupled dof holds as many columns as the largest coupled group."""
        groups = [row for term in self._blocks for row in term.coupled_dofs()]
        width = max((len(g) for g in groups), default=1)
        C = PETSc.Mat().createAIJ(template.getSizes(), nnz=(width, width), comm=template.getComm())
        C.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        C.setUp()
        return C

    def update(self) -> None:
        """Take the contact's lagged values, blocks and low-rank pairs at the current u (the
        form terms need nothing)."""
        if not self.contact:
            return
        for term, _ in self._facet:
            term.linearise(self._u)
        if self._contact is not None:
            self._contact.zeroEntries()
            for term in self._blocks:
                term.add_tangent(self._contact, self._u)
            self._contact.assemble()
        if hasattr(self.contact, "low_rank"):
            for vec in (v for pair in self._pairs for v in pair):
                vec.destroy()
            self._pairs = self.contact.low_rank(self._u)
            for vec in (v for pair in self._pairs for v in pair):
                set_bc(vec, self._bcs, scale=0.0)

    def apply_block(self, V: np.ndarray) -> np.ndarray:
        """K(u) v for the rows v of V (this rank's entries)."""
        out = np.empty_like(V)
        for v, o in zip(V, out):
            x, y = (PETSc.Vec().createWithArray(a, comm=self.mat.getComm()) for a in (v.copy(), o))
            self.mult(self.mat, x, y)
            x.destroy()
            y.destroy()
        return out

    def mult(self, mat: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """y = K(u) x."""
        xa = self._x.x.array
        xa[:self._owned] = x.array_r
        self._x.x.scatter_forward()
        facet = self._facet_action()             # along the whole x: added after the conditions
        xa[self._fixed] = 0.0
        b = self._y
        with b.localForm() as loc:
            loc.set(0.0)
        assemble_vector(b, self._form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        y.array[:] = b.array_r
        y.array[self.fixed_owned] = x.array_r[self.fixed_owned]
        if facet is not None:
            y.array[:] += facet
        if self._contact is not None:
            self._contact.multAdd(x, y, y)
        for a, b in self._pairs:
            y.axpy(b.dot(x), a)

    def _facet_action(self) -> np.ndarray | None:
        """The active facet terms' tangents along self._x (this rank's entries), or None."""
        forms = [form for term, form in self._facet if term.active]
        if not forms:
            return None
        c = self._yc
        with c.localForm() as loc:
            loc.set(0.0)
        for form in forms:
            assemble_vector(c, form)
        c.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return c.array_r


class LoadPathSolver:
    """Load stepping with cut-back and Newton (GMRES on the exact tangent, preconditioned
    by a MUMPS factorisation of a recent tangent) of one :class:`fem.physics.problem.Problem`
    (module docstring); keeps its converged state for continuation. Collective over the
    problem's communicator.

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
        self._P = self._tangent_matrix()       # the last tangent that was factorised
        self._b = create_vector(self._R)
        self._bc_gap = create_vector(self._R)   # g - u on the Dirichlet dofs (_lifting_needed)
        self._assemble_tangent()                 # fixes the sparsity pattern
        self._K = TangentAction(R, self.u, self.bcs, self.contact, self._P)   # GMRES's operator
        self._load = np.zeros(len(problem.load_scale))   # the load of the residual now
        self._held = self._load                  # the load the problem's constants hold now
        self._factor_load = None                 # the load of the factorised tangent (None: none yet)
        self._u_saved, self._du, self._chord = (fem.Function(self.V) for _ in range(3))
        self._lagged_saved = [0.0] * len(problem.lagged)
        self._factor_type = "cholesky"           # MUMPS LDL^T; "lu" once a tangent is not symmetric
        self._probe = self._P.createVecRight()   # a fixed direction for the symmetry check
        rng = np.random.default_rng([7, self.comm.rank])
        self._probe.array[:] = rng.uniform(-1.0, 1.0, self._probe.getLocalSize())
        self.ksp = self._create_ksp()
        self.pc = self.ksp.getPC()
        self.probes = Probes(self.V.mesh, problem.probe_points)
        self.state = np.zeros(len(problem.load_scale))  # load vector of the converged state
        self.factorisations = 0                    # factorisations so far (diagnostics)
        self.krylov_iterations = 0                 # GMRES iterations so far (diagnostics)
        self.factorisation_seconds = 0.0           # wall time in the factorisations (diagnostics)
        self.krylov_seconds = 0.0                  # wall time in GMRES (diagnostics)
        self._refactor = True                      # factorise before the next tangent solve?
        self._rates: Rates | None = None           # the last sensitivities, for a predictor

    def _create_ksp(self) -> PETSc.KSP:
        """GMRES on the current tangent (_K, applied matrix-free), preconditioned by a MUMPS
        factorisation of _P (a recent tangent, assembled): LDL^T while every tangent
        factorised so far was symmetric (``_factorise``), LU from then on. PETSc
        refactorises only when _P changes, and keeps MUMPS' symbolic factorisation
        throughout because the sparsity pattern never changes."""
        config = self.config
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(self._K.mat, self._P)
        ksp.setOptionsPrefix(f"softjoint_{id(self)}_")
        opts = PETSc.Options()
        prefix = ksp.getOptionsPrefix()
        opts[f"{prefix}ksp_type"] = "gmres"
        opts[f"{prefix}ksp_gmres_restart"] = config.krylov_max_it
        opts[f"{prefix}ksp_atol"] = 0.0
        opts[f"{prefix}ksp_max_it"] = config.krylov_max_it
        opts[f"{prefix}pc_type"] = self._factor_type
        opts[f"{prefix}pc_factor_mat_solver_type"] = "mumps"
        opts[f"{prefix}mat_mumps_icntl_14"] = MUMPS_WORKSPACE_PERCENT
        if config.mumps_blr:
            # Block low-rank factors: ~40 % faster LU at the 1.8 mm P2 mesh; the tangent
            # is then exact to ~1e-8, which Newton (exact residual) absorbs.
            opts[f"{prefix}mat_mumps_icntl_35"] = 1
            opts[f"{prefix}mat_mumps_cntl_7"] = config.mumps_blr
        ksp.setFromOptions()
        return ksp

    # ------------------------------------------------------------------ state
    def _set_load(self, a: np.ndarray) -> None:
        self._load = self._held = np.array(a, dtype=float)
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
        self._refactor = True           # the factorisation belongs to another state

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
        matrix for every new row (docs/decisions.md §1). On several ranks a pair's
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

    def _assemble_tangent(self) -> None:
        """Assemble the tangent K(u) at the current iterate and load into _P."""
        self._P.zeroEntries()
        assemble_matrix(self._P, self._J, bcs=self.bcs)
        if self.contact:
            self.contact.add_tangent(self._P, self.u)
        self._P.assemble()

    def _mumps_status(self) -> str:
        """MUMPS' own error figures after a failed factorisation (INFOG(1) < 0: -9/-8
        workspace too small, -10 singular; INFOG(2): its detail), for the failure reason."""
        try:
            F = self.pc.getFactorMatrix()
            return f"MUMPS INFOG(1) = {F.getMumpsInfog(1)}, INFOG(2) = {F.getMumpsInfog(2)}"
        except PETSc.Error:
            return "no MUMPS factor"

    def _factorise(self) -> None:
        """Assemble K(u) at the current iterate and load as the new _P and factorise it.

        While the tangents are symmetric (the Hessian of the potential energy: on the
        hexahedral joints to round-off) the factorisation is MUMPS' LDL^T of their upper
        triangle, cheaper than an LU in time and memory (docs/decisions.md §1) and as good a
        preconditioner; the first tangent that is not
        (the follower pressure on tetrahedra, ~6e-6 of its norm: an LDL^T of its upper
        triangle then costs GMRES ~4 more iterations a solve) switches to LU for good."""
        t0 = time.perf_counter()
        self._assemble_tangent()
        if self._factor_type == "cholesky" and not self._symmetric():
            self._factor_type = "lu"
            self.pc.setType("lu")
            self.pc.setFactorSolverType("mumps")
        self.ksp.setOperators(self._K.mat, self._P)
        self.ksp.setUp()
        self._refactor = False
        self._factor_load = self._held
        self.factorisations += 1
        self.factorisation_seconds += time.perf_counter() - t0

    def _symmetric(self) -> bool:
        """Whether _P is symmetric to round-off: |(P^T - P) x| <= 1e-12 |P x| along a fixed
        pseudo-random x (two sparse products)."""
        px, ptx = self._probe.duplicate(), self._probe.duplicate()
        self._P.mult(self._probe, px)
        self._P.multTranspose(self._probe, ptx)
        ptx.axpy(-1.0, px)
        symmetric = ptx.norm() <= 1e-12 * px.norm()
        px.destroy()
        ptx.destroy()
        return symmetric

    def _factor_stale(self) -> bool:
        """Whether to factorise before the next solve (``_solve_tangent``): asked for, or
        no factorisation of a tangent at the load the problem holds now."""
        held = self._factor_load
        return self._refactor or held is None or not np.array_equal(held, self._held)

    def _solve_tangent(self, b: PETSc.Vec, x: PETSc.Vec, rtol: float | None = None) -> None:
        """x = K(u)^-1 b, K at the current iterate and load (_K, whose contact blocks
        :meth:`TangentAction.update` took at this u): GMRES preconditioned by the
        factorisation of _P.

        _P is refactorised before the first solve at a load it was not factorised at: the
        tangent moves with the load (follower pressure, contact pairs), and a factorisation
        of another load's tangent leaves each solve of the step ~10 GMRES iterations where
        a fresh one needs 2-6 (on the production joint 10 iterations cost about one
        factorisation). So a continuation step factorises once, at its first Newton iterate,
        and its sensitivities reuse that factorisation. A preconditioner that needed more
        than half of ``krylov_max_it`` iterations is drifting away from K: the next call
        refactorises first, rather than after a failed GMRES run (a wasted 30-iteration
        cycle). If GMRES still stalls, refactorise and solve again."""
        if self._factor_stale():
            self._factorise()
        self.ksp.setTolerances(rtol=rtol or self.config.krylov_rtol)
        self._krylov(b, x)
        if self.ksp.getConvergedReason() <= 0:
            self._factorise()
            self._krylov(b, x)
            if self.ksp.getConvergedReason() <= 0:
                raise PETSc.Error(76)   # the caller cuts the step back
        self._refactor = self.ksp.getIterationNumber() > self.config.krylov_max_it // 2

    def _krylov(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """One GMRES run, counted (krylov_iterations, krylov_seconds)."""
        t0 = time.perf_counter()
        self.ksp.solve(b, x)
        self.krylov_iterations += self.ksp.getIterationNumber()
        self.krylov_seconds += time.perf_counter() - t0

    def work(self) -> dict:
        """The running totals of the linear algebra (diagnostics): factorisations and their
        wall seconds (assembly of the tangent included), GMRES iterations and seconds."""
        return {"factorisations": self.factorisations, "factorisation_s": self.factorisation_seconds,
                "krylov_iterations": self.krylov_iterations, "krylov_s": self.krylov_seconds}

    def newton(self, tangent_load: np.ndarray | None = None) -> tuple[int, bool]:
        """Newton iterations at the current load from the current u: (iterations, converged).

        Each correction solves with the tangent K(u) by GMRES, preconditioned with the
        factorisation of a tangent at this load (_P, ``_solve_tangent``): a few
        back-substitutions and matrix-free products with K.

        With ``tangent_load`` (the load vector of the last converged state, which u still
        is) the first correction uses the tangent at that load (an Euler predictor).
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
            self._K.update()
            with self._tangent_at(tangent_load if it == 0 else None):
                self._solve_tangent(self._b, self._du.vector)
            self._exact_on_dirichlet(self._du)
            self._du.x.scatter_forward()
            self.u.x.array[:] -= self._du.x.array
            self._chord_steps(cfg.chord_steps)
        return cfg.max_it, False

    @contextlib.contextmanager
    def _tangent_at(self, load: np.ndarray | None):
        """The problem's load constants at ``load`` inside the block (the tangent's, and a
        factorisation's, load; the residual is not evaluated there), then back at the
        current load. None: the current load throughout."""
        if load is None:
            yield
            return
        self._held = np.array(load, dtype=float)
        self.problem.set_load(load)
        try:
            yield
        finally:
            self._held = self._load
            self.problem.set_load(self._load)

    def _exact_on_dirichlet(self, du: fem.Function) -> None:
        """du = u - g on the constrained dofs, exactly: the Krylov solve meets those rows only
        to its tolerance, and u - du would leave ~1e-33 mm off a condition, enough to make
        the residual pay for a lifting (``_lifting_needed``)."""
        set_bc(du.vector, self.bcs, self.u.vector, -1.0)

    def _chord_steps(self, n: int) -> None:
        """Up to n extra corrections with the current factorisation alone, kept while each
        at least halves ||R||. A Newton step that rotates material leaves a residual spike
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
            a0, a1 = start + s * (target - start), start + s_try * (target - start)
            self._set_load(a1)
            # Euler predictor: the tangent of the converged state under its own load, or
            # that state's sensitivities when they are in hand
            predicted = self._predict(a0, a1)
            n, ok, why = self._guarded_newton(tangent_load=None if predicted else a0)
            reason = why or reason
            if ok:
                s, steps = s_try, steps + 1
                iters.append(int(n))
                self._converged_step()
                self._save()
                if self.comm.rank == 0:
                    log.info("load step %d: path %.4f, %d Newton iterations", steps, s, n)
                ds = min(cfg.max_step, ds * cfg.grow) if n <= 6 else ds
            else:
                cutbacks += 1
                self._restore()
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

    def _predict(self, a0: np.ndarray, a1: np.ndarray) -> bool:
        """u += sum_j du/da_j (a1 - a0)_j with the sensitivities of the converged state at
        a0, when they are this state's (u, lagged values and load unchanged since) and
        every load term is linear between a0 and a1 (a one-sided pressure that changes
        side is not), then chord steps: whether it did.

        This is the Euler predictor that ``newton`` would compute as its first
        correction, K(u0; a0) du = R(u0; a1) = sum_i (c_i(a1) - c_i(a0)) G_i(u0), up to
        the converged residual R(u0; a0) and the solves' tolerance, without its solve."""
        rates = self._rates
        if (rates is None or not np.array_equal(rates.load, a0) or not np.array_equal(rates.u, self.u.x.array)
                or rates.lagged != [float(lg.constant.value) for lg in self.problem.lagged]):
            return False
        for term in self.problem.loads:
            j = term.index
            if not math.isclose(term.value(a1) - term.value(a0), term.slope(a0) * (a1[j] - a0[j]),
                                rel_tol=1e-12, abs_tol=1e-300):
                return False
        step = sum(du * (a1[j] - a0[j]) for j, du in rates.du_da.items())
        self.u.x.array[:len(step)] += step
        self.u.x.scatter_forward()
        self._chord_steps(self.config.chord_steps)
        return True

    def _guarded_newton(self, tangent_load: np.ndarray | None) -> tuple[int, bool, str]:
        """newton(), with a non-finite iterate or a MUMPS failure (a singular or NaN
        tangent) as a failed solve, and a converged state that the contact refuses (its
        optional ``refuses(u)``: a one-line reason, e.g. the finger tunnelled into an
        object) too: (iterations, converged, reason or "")."""
        try:
            n, ok = self.newton(tangent_load)
        except PETSc.Error as exc:
            return self.config.max_it, False, f"{str(exc).splitlines()[0]}, {self._mumps_status()}"
        why = self.contact.refuses(self.u) if ok and hasattr(self.contact, "refuses") else ""
        return n, ok and not why and bool(np.isfinite(self.u.x.array).all()), why

    def converge(self) -> PathOutcome:
        """Newton at the load ``state`` from the current iterate u, which is a guess
        (e.g. fem.solvers.transfer.seed: another mesh's answer at that load) rather than a
        converged state: no load path.

        The first correction uses the consistent tangent at the guess, factorised afresh
        (the one in hand belongs to another state); a guess close to equilibrium carries
        its pre-stress, so the consistent tangent is the right one (unlike a new load
        from a converged state, see ``newton``). Converged: the lagged constants take
        their values and the state is saved, as after a step of ``follow``, so
        continuation and sensitivities work from it. Not converged: the guess had no
        converged state behind it, so the solver returns to the undeformed, unloaded
        state (``reset``), where ``follow`` from zero starts."""
        self._set_load(self.state)
        self._refactor = True
        n, ok, reason = self._guarded_newton(tangent_load=None)
        if self.comm.rank == 0:
            log.info("converge from a guess: %d Newton iterations, converged=%s", n, ok)
        if not ok:
            self.reset()
            return PathOutcome(False, self.state.copy(), [int(n)], 0, 0,
                               reason or f"no convergence from the guess in {n} Newton iterations")
        self._converged_step()
        self._save()
        return PathOutcome(True, self.state.copy(), [int(n)], 1, 0, "")

    def tangent_products(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """K(u) x at the current state twice, (assembled, matrix-free): by the assembled
        tangent (contact blocks included) and by GMRES's operator :class:`TangentAction`;
        x and both products are this rank's entries. A check of the matrix-free operator
        (they agree to round-off); the next solve refactorises. Collective."""
        self._K.update()
        self._assemble_tangent()
        self._refactor = True           # _P now holds this state's tangent, not its factors'
        vx = self._P.createVecRight()
        vx.array[:] = x
        assembled, free = vx.duplicate(), vx.duplicate()
        self._P.mult(vx, assembled)
        self._K.mat.mult(vx, free)
        out = assembled.array.copy(), free.array.copy()
        for vec in (vx, assembled, free):
            vec.destroy()
        return out

    def stiffness_spectrum(self, iterations: int = 60, rtol: float = 1e-7) -> dict:
        """How stable the current state is: ``unstable_modes``, the number of negative
        eigenvalues of the stiffness (0 where the equilibrium is stable; >= 1 past a limit
        or bifurcation point under these dead and follower loads), and ``lowest_eigenvalue``
        (N/mm), the stiffness's eigenvalue nearest zero, signed, which passes through zero
        at such a point. Collective; the next solve refactorises.

        Both come from one exact MUMPS LDL^T of the assembled tangent K(u) (contact blocks
        included). Sylvester's law of inertia: its negative pivots, INFOG(12), are K's
        negative eigenvalues. The mixed u-p tangent [[A, B^T], [B, -M/kappa]] has n_p of
        them from its pressure block (-M/kappa is negative definite) plus those of the
        condensed stiffness S = A + B^T (M/kappa)^-1 B (Haynsworth), so n_p, the pressure
        dofs, is subtracted. The eigenvalue: inverse iteration on S, whose inverse is
        the u block of K^-1 applied to a right-hand side without pressure entries,
        x <- S^-1 x / |S^-1 x| on the unconstrained displacement dofs, lambda = 1 / (x . S^-1 x).
        Meaningful only while K is symmetric (the hexahedral joints, ``_factorise``)."""
        self._assemble_tangent()
        self._refactor = True           # _P now holds this state's tangent, not its factors'
        pc = PETSc.PC().create(self.comm)
        pc.setOperators(self._P)
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        pc.setUp()
        negative = pc.getFactorMatrix().getMumpsInfog(12)
        free = np.ones(self._P.getLocalSize()[0], dtype=bool)
        free[self.constrained_dofs()] = False
        pressure_dofs = 0
        if self.problem.displacement_space is not None:
            u_dofs = np.asarray(self.V.sub(0).collapse()[1])
            pressure = np.ones_like(free)
            pressure[u_dofs[u_dofs < len(free)]] = False
            free &= ~pressure
            pressure_dofs = self.comm.allreduce(int(pressure.sum()))
        x, y = self._P.createVecRight(), self._P.createVecRight()
        rng = np.random.default_rng([11, self.comm.rank])
        x.array[:] = np.where(free, rng.uniform(-1.0, 1.0, len(free)), 0.0)
        x.normalize()
        lam = math.nan
        for _ in range(iterations):
            pc.apply(x, y)
            y.array[~free] = 0.0
            mu = x.dot(y)
            new = 1.0 / mu if mu else math.inf
            y.normalize()
            x, y = y, x
            if abs(new - lam) <= rtol * abs(new):
                lam = new
                break
            lam = new
        for obj in (pc, x, y):
            obj.destroy()
        return {"unstable_modes": int(negative) - pressure_dofs, "lowest_eigenvalue": float(lam)}

    def constrained_dofs(self) -> np.ndarray:
        """This rank's dofs under a Dirichlet condition (local indices, owned)."""
        return self._K.fixed_owned

    # ------------------------------------------------------------------ sensitivities
    def sensitivities(self) -> np.ndarray:
        """du/da at the probe points at the current converged state, shape (n, 3, len(a)):
        mm per unit of each load entry.

        Solves with the tangent at the converged state (not at Newton's last iterate,
        which depends on the iteration path: serial and parallel runs would disagree at
        ~1e-4), every load entry at once by block GMRES (fem.solvers.block_krylov) to
        ``sensitivity_rtol``, preconditioned with the factorisation of a tangent at this load
        (``_solve_tangent``). A one-sided load (a chamber pressure) at a_j = 0 takes the
        derivative of its + side.
        """
        self._K.update()
        rhs = {}
        for j in range(len(self.state)):
            b = self._load_derivative(j)
            if b is None:               # no load term follows a_j here (the beam's P)
                continue
            set_bc(b, self.bcs, scale=0.0)
            rhs[j] = b.array_r.copy()   # this rank's entries
            b.destroy()
        out = np.zeros((len(self.probes), 3, len(self.state)))
        w = fem.Function(self.V)
        du_da = {}
        if rhs:
            X = self._solve_block(np.array(list(rhs.values())), self.config.sensitivity_rtol)
            for j, x in zip(rhs, X):
                w.x.array[:len(x)] = x
                w.x.scatter_forward()
                out[:, :, j] = -self.probes.values(w)    # K du = -dR/da_j
                du_da[j] = -x
                du_da[j][self._K.fixed_owned] = 0.0
        self._rates = Rates(self.u.x.array.copy(), [float(lg.constant.value) for lg in self.problem.lagged],
                            self.state.copy(), du_da)
        return out

    def _solve_block(self, B: np.ndarray, rtol: float) -> np.ndarray:
        """X with K(u) x_j = b_j for the rows b_j of B (this rank's entries), K at the
        current iterate and load: block GMRES preconditioned by the factorisation of _P, refreshed as
        in ``_solve_tangent``; a stalled solve is refactorised and repeated once."""
        if self._factor_stale():
            self._factorise()
        for attempt in range(2):
            X, products, ok = block_gmres(self._K.apply_block, self._precondition, B, rtol,
                                          self.config.krylov_max_it, self._dot)
            self.krylov_iterations += products
            if ok:
                self._refactor = products > len(B) * (self.config.krylov_max_it // 2)
                return X
            if attempt == 0:
                self._factorise()
        raise PETSc.Error(76)

    def _precondition(self, V: np.ndarray) -> np.ndarray:
        """P^-1 v for the rows v of V (this rank's entries), P = _P's factorisation. On one rank all
        rows in one MUMPS solve with several right-hand sides (one pass over the factors)."""
        out = np.empty_like(V)
        if self.comm.size == 1:
            n, m = V.shape[1], V.shape[0]
            rhs = PETSc.Mat().createDense([n, m], array=np.ascontiguousarray(V).reshape(-1), comm=self.comm)
            sol = PETSc.Mat().createDense([n, m], array=out.reshape(-1), comm=self.comm)
            self.pc.getFactorMatrix().matSolve(rhs, sol)
            rhs.destroy()
            sol.destroy()
            return out
        for v, o in zip(V, out):
            x, y = (PETSc.Vec().createWithArray(a, comm=self.comm) for a in (v.copy(), o))
            self.pc.apply(x, y)
            x.destroy()
            y.destroy()
        return out

    def _dot(self, A: np.ndarray, C: np.ndarray) -> np.ndarray:
        """A C^T over all ranks (rows: vectors of this rank's entries)."""
        local = A @ C.T
        return self.comm.allreduce(local, op=MPI.SUM) if self.comm.size > 1 else local

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
