"""Static large-deflection solve of the bellow joint (and of the benchmark beam).

Units: mm, N, MPa (= N/mm²), N·mm; angles in rad.

Kinematics and material (compressible neo-Hookean, total Lagrangian, P2 tetrahedra)::

    F = I + grad u,   J = det F,   I1 = tr(F^T F)
    psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2          P = d psi / d F
    mu = E / (2 (1 + nu)),   lambda = E nu / ((1 + nu)(1 - 2 nu))

so the small-strain limit is exactly (E, nu) = (12.2 MPa, 0.49). P2 displacements avoid
the volumetric locking of P1 at nu = 0.49 (mesh convergence: ``make mesh-study``). The
paper used ANSYS linear elasticity with large deflection (St Venant-Kirchhoff-like);
neo-Hookean agrees with it at small strain and stays stable in compression.

Loads (DESIGN.md §3), on the half-model z >= 0, which carries half of each resultant:

* Pressure, a follower load on the deformed chamber walls (Nanson)::

      t0 = -p J F^-T N = -p cofac(F) N,   p_top = max(P, 0),  p_bottom = max(-P, 0)

* The distal cap is bonded to a rigid connector: it is meshed as its own volume with
  ``cap_stiffness`` x E, so it moves rigidly to solver precision. Its rotation about z at
  a material point is ``theta = atan2(F_yx - F_xy, F_xx + F_yy)``, exact for any rigid
  motion (taken relative to the last converged rotation, so it has no branch cut).
* F1, F2 (dead, in the undeformed joint frame) applied at the reference point X_ref
  (the distal centre, r_10) and M (pure couple about +z) enter as the potential::

      Pi_ext = -1/(2 V_cap) ∫_cap [ f·(u + (R(theta) - I)(X_ref - X)) + M theta ] dX

  where u + (R - I)(X_ref - X) is the displacement of X_ref carried rigidly by the cap.
  Its variation is the virtual work f·δu_ref + M δtheta, so the couple is M at ANY end
  rotation (no M cos(phi) error of a dead linear traction; see ``fem.validation rollup``).

Weak form: R(u; v) = ∫ P : grad v dX + ∫_chamber p cofac(F) N·v dA + δPi_ext + δPi_c = 0,
with u = 0 on the proximal face and u_z = 0 on the symmetry plane; Pi_c is the penalty
self-contact of the outer walls across each valley (:mod:`fem.contact`). Newton with the exact
tangent (MUMPS LU) along a load path with automatic cut-back.

Sensitivities: at a converged state, du/dλ = -K^{-1} ∂R/∂λ for λ in (P, F1, F2, M), one
back-substitution each with the last factorisation; anchors are linear in u.

Data flow: JointGeometry -> fem.mesh.create_mesh -> Solver(...) -> Solver.solve(Load) ->
SolveResult (anchors (10, 2) mm, phi_end, cap rotation, u, Newton figures).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import ufl
from dolfinx import fem, geometry
from dolfinx.fem.petsc import (apply_lifting, assemble_matrix, assemble_vector, create_matrix,
                               create_vector, set_bc)
from mpi4py import MPI
from petsc4py import PETSc

from fem.contact import ValleyContact
from fem.geometry import TAGS, BeamGeometry, JointGeometry, anchor_points
from fem.mesh import MeshData, create_mesh
from fem.spec import INPUT_BOX, check_box, outside_box, phi_end

log = logging.getLogger("softjoint.fem")


@dataclass(frozen=True)
class Load:
    """One load case: P (MPa, signed), F1, F2 (N, dead, joint frame), M (N·mm, about +z)."""

    P: float = 0.0
    F1: float = 0.0
    F2: float = 0.0
    M: float = 0.0

    def as_array(self) -> np.ndarray:
        return np.array([self.P, self.F1, self.F2, self.M], dtype=float)

    @classmethod
    def from_array(cls, a) -> "Load":
        return cls(*(float(x) for x in a))


@dataclass(frozen=True)
class Material:
    """Neo-Hookean material (MPa). Defaults: NinjaFlex (DESIGN.md §3)."""

    E: float = 12.2
    nu: float = 0.49
    # Distal cap modulus = cap_stiffness * E: the 3 mm solid cap then bends by < 3e-5 rad
    # under M = 100 N·mm, rigid for every reported figure. Much stiffer caps slow Newton:
    # a linearised rotation step strains a stiff block by ~theta^2/2.
    cap_stiffness: float = 100.0
    # The connector need not be nearly incompressible; nu = 0.3 keeps lambda_cap small,
    # since lambda * theta^2/2 is the spurious stress a linearised rotation step creates.
    cap_nu: float = 0.3


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
    contact_penalty: float = 100.0  # valley self-contact, MPa/mm of overlap (0: off)


@dataclass
class SolveResult:
    """Outcome of one load case. anchors (n_probe, 2) mm; angles rad; times s."""

    load: Load
    converged: bool
    anchors: np.ndarray
    phi_end: float
    cap_rotation: float
    newton_iterations: list[int] = field(default_factory=list)
    load_steps: int = 0
    cutbacks: int = 0
    factorisations: int = 0         # LU factorisations this solve needed
    krylov_iterations: int = 0      # GMRES iterations over its tangent solves
    wall_time: float = 0.0
    reason: str = ""
    extrapolated: bool = False
    u: object = None                # dolfinx.fem.Function (this rank's part)

    @property
    def iterations(self) -> int:
        return int(sum(self.newton_iterations))

    def summary(self) -> dict:
        """JSON-ready figures (no field data)."""
        return {
            "load": asdict(self.load), "converged": self.converged,
            "anchors_mm": np.round(self.anchors, 6).tolist(),
            "phi_end_rad": self.phi_end, "phi_end_deg": math.degrees(self.phi_end),
            "cap_rotation_rad": self.cap_rotation,
            "cap_rotation_deg": math.degrees(self.cap_rotation),
            "tangent_assumption_error_deg": math.degrees(self.cap_rotation - self.phi_end),
            "newton_iterations": self.newton_iterations, "iterations": self.iterations,
            "load_steps": self.load_steps, "cutbacks": self.cutbacks,
            "factorisations": self.factorisations, "krylov_iterations": self.krylov_iterations,
            "wall_time_s": self.wall_time, "reason": self.reason,
            "extrapolated": self.extrapolated,
        }


def _lame(E: float, nu: float) -> tuple[float, float]:
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def neo_hookean_psi(F, mu, lmbda):
    """Strain energy density psi(F) (MPa = N·mm/mm³), compressible neo-Hookean."""
    J = ufl.det(F)
    I1 = ufl.tr(F.T * F)
    return mu / 2 * (I1 - 3) - mu * ufl.ln(J) + lmbda / 2 * ufl.ln(J) ** 2


def clamp_and_symmetry(V, facet_tags) -> list:
    """u = 0 on the ``proximal`` facets and u_z = 0 on the ``symmetry`` plane z = 0."""
    tdim = V.mesh.topology.dim
    zero = np.zeros(3, dtype=PETSc.ScalarType)
    clamp = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(TAGS["proximal"]))
    Vz = V.sub(2)
    sym = fem.locate_dofs_topological(Vz, tdim - 1, facet_tags.find(TAGS["symmetry"]))
    return [fem.dirichletbc(zero, clamp, V), fem.dirichletbc(PETSc.ScalarType(0), sym, Vz)]


def displacement_problem(mesh_data: MeshData, config: SolverConfig):
    """(V, u, v, bcs, dx, ds) of a half-model: P``degree`` vector space, the unknown
    displacement u (mm), its test function, the clamp and symmetry conditions
    (:func:`clamp_and_symmetry`) and the tagged measures at ``quadrature_degree``."""
    mesh, ct, ft = mesh_data.mesh, mesh_data.cell_tags, mesh_data.facet_tags
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    V = fem.VectorFunctionSpace(mesh, ("CG", config.degree))
    md = {"quadrature_degree": config.quadrature_degree}
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=ct, metadata=md)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=ft, metadata=md)
    return V, fem.Function(V, name="u"), ufl.TestFunction(V), clamp_and_symmetry(V, ft), dx, ds


def rotation_about_z(F, theta_ref=0.0):
    """Rotation (rad) about +z of the material at a point, theta = atan2(F_yx - F_xy,
    F_xx + F_yy): exact for any rigid motion, and the polar rotation's angle for a planar
    F. Taken relative to ``theta_ref`` (UFL scalar), so it has no branch cut near it."""
    c, s = ufl.cos(theta_ref), ufl.sin(theta_ref)
    a, b = F[0, 0] + F[1, 1], F[1, 0] - F[0, 1]
    return theta_ref + ufl.atan_2(b * c - a * s, a * c + b * s)


def follower_pressure(F, v, ds):
    """Virtual work per unit pressure of a follower load on the deformed surface ``ds``
    (Nanson: t0 = -p cofac(F) N; this is the residual term divided by p)."""
    N = ufl.FacetNormal(v.ufl_function_space().mesh)
    return ufl.inner(ufl.cofac(F) * N, v) * ds


def facet_tags_present(facet_tags) -> set:
    """The facet tag values present on any rank (collective)."""
    comm = facet_tags.mesh.comm
    tags = set(np.unique(facet_tags.values)) if facet_tags.values.size else set()
    return comm.allreduce(tags, op=MPI.BOR) if comm.size > 1 else tags


@dataclass
class PathOutcome:
    """How a load path went: the load vector reached, Newton figures, and why it stopped."""

    converged: bool
    reached: np.ndarray
    newton_iterations: list[int]
    load_steps: int
    cutbacks: int
    reason: str


class NewtonSolver:
    """Load stepping with cut-back and Newton (GMRES on the exact tangent, preconditioned
    by a recent MUMPS LU) on one residual form: the machinery that the joint
    (:class:`Solver`) and the whole finger (:class:`fem.finger.FingerSolver`) share.

    A subclass builds the function space V, the unknown u, the residual form R(u; v)
    whose loads are ``fem.Constant``s, the Dirichlet conditions and an optional contact
    term (``add_residual``/``add_tangent``, e.g. fem.contact.ValleyContact), then calls
    ``NewtonSolver.__init__``. It implements ``_set_load(a)`` for a load vector a and sets
    ``load_scale`` (the full-range magnitude of each entry of a, which sizes the first
    step). ``_accept()`` / ``_restore()`` keep any state beyond u (the joint's cap rotation).
    """

    load_scale: np.ndarray

    def __init__(self, V, u, R, bcs, config: SolverConfig, contact=None):
        self.V, self.u, self.bcs, self.config, self.contact = V, u, bcs, config, contact
        self.comm = V.mesh.comm
        self._u_saved = fem.Function(V)
        self._R = fem.form(R)
        self._J = fem.form(ufl.derivative(R, u, ufl.TrialFunction(V)))
        self._A = create_matrix(self._J)       # the tangent at the current iterate
        if contact is not None:
            # The pair blocks couple nodes that share no cell: allow them in the pattern.
            self._A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self._b = create_vector(self._R)
        self._tangent()                          # fixes the sparsity pattern
        self._P = self._A.duplicate(copy=True)   # the last tangent that was factorised
        self._du = fem.Function(V)
        self._chord = fem.Function(V)
        # GMRES on the current tangent _A, preconditioned by the MUMPS LU of _P (a recent
        # tangent). PETSc refactorises only when _P changes, and keeps MUMPS' symbolic
        # factorisation throughout because the sparsity pattern never changes.
        self.ksp = ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(self._A, self._P)
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
            # Block low-rank LU: ~40 % faster factorisations at the production mesh; the
            # tangent is then exact to ~1e-8, which Newton (exact residual) absorbs.
            opts[f"{prefix}mat_mumps_icntl_35"] = 1
            opts[f"{prefix}mat_mumps_cntl_7"] = config.mumps_blr
        ksp.setFromOptions()
        self.pc = ksp.getPC()
        self.state = np.zeros(len(self.load_scale))  # load vector of the converged state
        self.factorisations = 0                    # LU factorisations so far (diagnostics)
        self.krylov_iterations = 0                 # GMRES iterations so far (diagnostics)
        self._refactor = True                      # factorise before the next tangent solve?
        self._factor_fresh = False                 # last factorisation near current state?

    # ------------------------------------------------------------------ hooks
    def _set_load(self, a: np.ndarray) -> None:
        raise NotImplementedError

    def _converged_step(self) -> None:
        """A load step converged: update any state beyond u (before it is saved)."""

    def _save(self) -> None:
        """Keep the converged state as the fall-back of the next step."""
        self._u_saved.x.array[:] = self.u.x.array

    def _restore(self) -> None:
        """A load step failed: return to the last saved state."""
        self.u.x.array[:] = self._u_saved.x.array

    def reset(self) -> None:
        """Return to the undeformed, unloaded state."""
        self.u.x.array[:] = 0.0
        self.state = np.zeros(len(self.load_scale))
        self._set_load(self.state)
        self._factor_fresh = False
        self._refactor = True           # the LU belongs to another state

    # ------------------------------------------------------------------ helpers
    def _allsum(self, x: float) -> float:
        return self.comm.allreduce(x, op=MPI.SUM)

    def _locate(self, points: np.ndarray) -> np.ndarray:
        """Owning local cell of each point on this rank, or -1. Shape (n,)."""
        mesh = self.V.mesh
        tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
        cand = geometry.compute_collisions(tree, points)
        coll = geometry.compute_colliding_cells(mesh, cand, points)
        return np.array([coll.links(i)[0] if len(coll.links(i)) else -1
                         for i in range(len(points))], dtype=np.int32)

    def evaluate(self, func, points=None, cells=None) -> np.ndarray:
        """Values of a vector Function at the probe points, gathered on all ranks. (n, 3)."""
        points = self.probe_points if points is None else points
        cells = self._probe_cells if cells is None else cells
        vals = np.full((len(points), 3), np.nan)
        mine = cells >= 0
        if mine.any():
            vals[mine] = func.eval(points[mine], cells[mine])
        gathered = self.comm.allgather(vals)
        out = np.full_like(vals, np.nan)
        for g in gathered:   # first rank that owns a point wins: no duplicates
            take = np.isnan(out[:, 0]) & ~np.isnan(g[:, 0])
            out[take] = g[take]
        if np.isnan(out).any():
            raise RuntimeError("a probe point lies outside the mesh")
        return out

    def _residual(self) -> float:
        """Assemble R(u) into self._b (Dirichlet rows: u - 0); return its 2-norm (N)."""
        b = self._b
        with b.localForm() as loc:
            loc.set(0.0)
        assemble_vector(b, self._R)
        apply_lifting(b, [self._J], bcs=[self.bcs], x0=[self.u.vector], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.contact:
            self.contact.add_residual(b, self.u)
        set_bc(b, self.bcs, self.u.vector, -1.0)
        return b.norm()

    def _tangent(self) -> None:
        """Assemble the tangent K(u) at the current iterate into _A."""
        self._A.zeroEntries()
        assemble_matrix(self._A, self._J, bcs=self.bcs)
        if self.contact:
            self.contact.add_tangent(self._A, self.u)
        self._A.assemble()

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
        self.ksp.setOperators(self._A, self._P)
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
            if norm <= cfg.atol or du <= cfg.stol * self.u.vector.norm():
                return it, True
            if it == cfg.max_it:
                return it, False
            if not (it == 0 and reuse_factor):
                self._tangent()
            self._solve_tangent(self._b, self._du.vector)
            self._du.x.scatter_forward()
            self.u.x.array[:] -= self._du.x.array
            self._chord_steps(cfg.chord_steps)
        return cfg.max_it, False

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
            w.x.scatter_forward()
            self.u.x.array[:] -= w.x.array
            r = self._residual()
            if not r < 0.5 * r_prev:
                self.u.x.array[:] += w.x.array
                return
            r_prev = r

    def mesh_info(self) -> dict:
        """Global mesh figures: vertices, cells, nodes (incl. mid-side for P2), dofs."""
        mesh = self.mesh_data.mesh
        imap = mesh.topology.index_map(0)
        cmap = mesh.topology.index_map(mesh.topology.dim)
        nodes = self.V.dofmap.index_map.size_global
        return {"vertices": imap.size_global, "cells": cmap.size_global,
                "nodes": nodes, "dofs": nodes * self.V.dofmap.index_map_bs,
                "degree": self.config.degree, "mesh_size": self.mesh_data.geometry.mesh_size}

    # ------------------------------------------------------------------ load path
    def _follow(self, start: np.ndarray, target: np.ndarray) -> PathOutcome:
        """Follow the linear load path start -> target (load vectors) from the current
        converged state. A step whose Newton iteration fails is undone and halved; below
        ``min_step`` the path stops at its last converged state (never a non-converged
        one), which becomes ``self.state``."""
        cfg = self.config
        span = np.abs((target - start) / self.load_scale).max()
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
            try:
                n, ok = self.newton(reuse_factor=True)
                ok = ok and bool(np.isfinite(self.u.x.array).all())
            except PETSc.Error as exc:      # MUMPS failure on a singular/NaN tangent
                n, ok = self.config.max_it, False
                reason = f"{str(exc).splitlines()[0]}, {self._mumps_status()}"
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


class Solver(NewtonSolver):
    """Large-deflection solver of one joint-like body (the bellow joint, the benchmark
    beam) on one mesh; keeps its state for continuation. Load vector (P, F1, F2, M).

    ``probe_points`` (n, 3) are material points whose deformed (x, y) are reported
    (the joint's anchors); ``ref_point`` (3,) is where F1, F2 act on the rigid cap.
    """

    load_scale = np.asarray(INPUT_BOX, dtype=float)

    def __init__(self, mesh_data: MeshData, ref_point, probe_points,
                 material: Material = Material(), config: SolverConfig = SolverConfig()):
        self.mesh_data, self.material = mesh_data, material
        mesh, ft = mesh_data.mesh, mesh_data.facet_tags
        self.comm = mesh.comm
        V, u, v, bcs, dx, ds = displacement_problem(mesh_data, config)
        self._dx_cap = dx(TAGS["distal_cap"])

        # --- kinematics and internal energy
        F = ufl.variable(ufl.Identity(len(u)) + ufl.grad(u))
        mu, lmbda = _lame(material.E, material.nu)
        mu_c, lmbda_c = _lame(material.cap_stiffness * material.E, material.cap_nu)
        P_body = ufl.diff(neo_hookean_psi(F, mu, lmbda), F)
        P_cap = ufl.diff(neo_hookean_psi(F, mu_c, lmbda_c), F)
        R_int = (ufl.inner(P_body, ufl.grad(v)) * dx(TAGS["solid"])
                 + ufl.inner(P_cap, ufl.grad(v)) * dx(TAGS["distal_cap"]))

        # --- cap rotation, relative to the last converged rotation theta_ref
        self.theta_ref = fem.Constant(mesh, PETSc.ScalarType(0))
        self._theta_saved = 0.0
        theta = rotation_about_z(F, self.theta_ref)
        self._theta_form = fem.form(theta * self._dx_cap)
        one = fem.Constant(mesh, PETSc.ScalarType(1))
        self.cap_volume = self._allsum(fem.assemble_scalar(fem.form(one * self._dx_cap)))

        # --- end-load potentials per unit F1, F2, M (the half-model carries half)
        # Mesh-dependent numbers are Constants, so one compiled form serves every mesh.
        X = ufl.SpatialCoordinate(mesh)
        Xref = fem.Constant(mesh, np.asarray(ref_point[:2], dtype=PETSc.ScalarType))
        Rth = ufl.as_matrix([[ufl.cos(theta), -ufl.sin(theta)], [ufl.sin(theta), ufl.cos(theta)]])
        arm = Xref - ufl.as_vector([X[0], X[1]])
        u_ref = ufl.as_vector([u[0], u[1]]) + (Rth - ufl.Identity(2)) * arm
        w = fem.Constant(mesh, PETSc.ScalarType(-0.5 / self.cap_volume))
        potentials = [w * u_ref[0] * self._dx_cap, w * u_ref[1] * self._dx_cap,
                      w * theta * self._dx_cap]
        self._dR_dload = [ufl.derivative(pi, u, v) for pi in potentials]   # F1, F2, M

        # --- pressure: follower traction on the deformed chamber walls
        tags = facet_tags_present(ft)
        self._dR_dp = {name: follower_pressure(F, v, ds(TAGS[name]))
                       for name in ("top_chamber", "bottom_chamber") if TAGS[name] in tags}

        # --- load constants and full residual
        self.p = {name: fem.Constant(mesh, PETSc.ScalarType(0)) for name in self._dR_dp}
        self.f = [fem.Constant(mesh, PETSc.ScalarType(0)) for _ in range(3)]  # F1, F2, M
        R = R_int
        for name, form in self._dR_dp.items():
            R = R + self.p[name] * form
        for lam, form in zip(self.f, self._dR_dload):
            R = R + lam * form
        self._forms_p = {n: fem.form(f) for n, f in self._dR_dp.items()}
        self._forms_load = [fem.form(f) for f in self._dR_dload]
        contact = None
        if TAGS["valley_faces"] in tags and config.contact_penalty > 0:
            contact = ValleyContact(V, ft, mesh_data.geometry, config.contact_penalty)
        super().__init__(V, u, R, bcs, config, contact)

        # --- probes (anchor points)
        self.probe_points = np.asarray(probe_points, dtype=float).reshape(-1, 3)
        self._probe_cells = self._locate(self.probe_points)

    @property
    def state_load(self) -> Load:
        """Load of the current converged state."""
        return Load.from_array(self.state)

    def cap_rotation(self) -> float:
        """Volume-averaged rotation of the distal cap about +z (rad)."""
        return self._allsum(fem.assemble_scalar(self._theta_form)) / self.cap_volume

    def _set_load(self, a: np.ndarray) -> None:
        P = a[0]
        if "top_chamber" in self.p:
            self.p["top_chamber"].value = max(P, 0.0)
        if "bottom_chamber" in self.p:
            self.p["bottom_chamber"].value = max(-P, 0.0)
        for lam, val in zip(self.f, a[1:]):
            lam.value = val

    def _converged_step(self) -> None:
        self.theta_ref.value = self.cap_rotation()

    def _save(self) -> None:
        super()._save()
        self._theta_saved = float(self.theta_ref.value)

    def _restore(self) -> None:
        super()._restore()
        self.theta_ref.value = self._theta_saved

    def positions(self) -> np.ndarray:
        """Deformed (x, y) of the probe points (mm), shape (n, 2)."""
        return (self.probe_points + self.evaluate(self.u))[:, :2]

    def reset(self) -> None:
        """Return to the undeformed, unloaded state."""
        self.theta_ref.value = 0.0
        super().reset()

    # ------------------------------------------------------------------ solve
    def solve(self, load: Load, continuation: bool = False) -> SolveResult:
        """Solve for ``load``; from zero, or (continuation) from the current state.

        The load path is linear from the start load to ``load`` (NewtonSolver._follow:
        cut-back on failure; a failed solve returns to its last converged state).
        """
        if not np.isfinite(load.as_array()).all():   # would only fail after every cut-back
            raise ValueError(f"{load} is not finite")
        t0, lu0, kr0 = time.perf_counter(), self.factorisations, self.krylov_iterations
        if not continuation:
            self.reset()
        path = self._follow(self.state.copy(), load.as_array())
        anchors = self.positions()
        result = SolveResult(
            load=load, converged=path.converged, anchors=anchors,
            phi_end=float(phi_end(anchors)) if len(anchors) > 1 else math.nan,
            cap_rotation=float(self.theta_ref.value), newton_iterations=path.newton_iterations,
            load_steps=path.load_steps, cutbacks=path.cutbacks,
            factorisations=self.factorisations - lu0,
            krylov_iterations=self.krylov_iterations - kr0,
            wall_time=time.perf_counter() - t0, reason=path.reason, u=self.u)
        if self.comm.rank == 0:
            log.info("solve %s: converged=%s, %d steps, %d iterations, %.2f s",
                     load, path.converged, path.load_steps, result.iterations, result.wall_time)
        return result

    # ------------------------------------------------------------------ sensitivities
    def sensitivities(self) -> np.ndarray:
        """d(probe x, y)/d(P, F1, F2, M) at the current converged state, shape (2n, 4).

        Rows are the probe coordinates flattened as (x_1, y_1, x_2, ...); columns in
        mm/MPa, mm/N, mm/N, mm/(N·mm). Solves with the tangent re-assembled at the
        converged state, by GMRES to ``sensitivity_rtol`` preconditioned with the current
        LU. The tangent left in _A by Newton is that of the iterate before the last
        correction (and chord steps): it is off by that correction, which depends on the
        iteration path, so serial and parallel runs would disagree at ~1e-4.
        At P = 0 the pressure derivative is the one-sided (top chamber) one.
        """
        self._tangent()
        self._factor_fresh = True       # _A is now the converged tangent at its own load
        P = self.state_load.P
        rhs = []
        if self._forms_p:
            name, sign = ("top_chamber", 1.0) if P >= 0 else ("bottom_chamber", -1.0)
            rhs.append((self._forms_p[name], sign))
        else:
            rhs.append((None, 0.0))
        rhs += [(f, 1.0) for f in self._forms_load]
        w = fem.Function(self.V)
        cols = []
        for form, sign in rhs:
            if form is None:
                cols.append(np.zeros(2 * len(self.probe_points)))
                continue
            b = assemble_vector(form)
            b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            set_bc(b, self.bcs, scale=0.0)
            self._solve_tangent(b, w.vector, self.config.sensitivity_rtol)
            w.x.scatter_forward()
            # K du = -dR/dλ  -> du/dλ = -K^-1 dR/dλ
            cols.append(-sign * self.evaluate(w)[:, :2].reshape(-1))
            b.destroy()
        return np.column_stack(cols)

class JointSolver(Solver):
    """The bellow joint: anchors r_1..r_10 (DESIGN.md §3), loads at r_10."""

    def __init__(self, geometry: JointGeometry = JointGeometry(), comm: MPI.Comm = MPI.COMM_WORLD,
                 material: Material = Material(), config: SolverConfig = SolverConfig()):
        X = anchor_points(geometry.length)
        super().__init__(create_mesh(geometry, comm), ref_point=X[-1], probe_points=X,
                         material=material, config=config)

    def solve(self, load: Load, continuation: bool = False,
              allow_extrapolation: bool = False) -> SolveResult:
        """Solve one load case. Raises fem.spec.OutOfBoxError, before any work, for a
        load that is not finite, or outside the box unless ``allow_extrapolation``."""
        check_box(load.as_array(), allow_extrapolation)
        result = super().solve(load, continuation)
        result.extrapolated = bool(outside_box(load.as_array()))
        return result


def beam_solver(geometry: BeamGeometry = BeamGeometry(), comm: MPI.Comm = MPI.COMM_WORLD,
                E: float = 12.2, config: SolverConfig = SolverConfig()) -> Solver:
    """The slender benchmark cantilever (nu = 0): probes at the beam end (L, 0, 0)."""
    tip = np.array([geometry.length, 0.0, 0.0])
    return Solver(create_mesh(geometry, comm), ref_point=tip, probe_points=tip[None, :],
                  material=Material(E=E, nu=0.0), config=config)
