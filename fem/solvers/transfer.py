"""A joint solve started from another discretisation's answer at the same load.

Units: mm, N, MPa, N·mm; angles in rad.

A fine mesh solved from zero follows the load path (fem.solvers.load_path.LoadPathSolver.follow:
several load steps, tens of Newton iterations, several LU factorisations). A coarser
mesh's converged answer at the SAME load is a close initial guess instead: same geometry,
nearly the same field and contact state, so Newton needs a few iterations. For two
:class:`fem.solvers.joint.EndLoadedSolver` of one joint (``target`` and ``source``: any meshes,
tetrahedra or hexahedra, either formulation), :func:`seed` sets the target to

    u_t(x_i) = u_s(x_i)        at every displacement node x_i of the target
    p_t(y_j) = p_s(y_j)        at every pressure node y_j (mixed target, mixed source)
    p_t      = 0               (mixed target, displacement source)
    a_t      = a_s             the load vector (the source's converged ``state``)
    theta_t  = cap rotation of u_t (the lagged constant, fem.physics.problem.end_loads)

with u_t = 0 and u_t,z = 0 on the target's Dirichlet faces exactly. The source fields are
evaluated at the target's nodes by point location (fem.solvers.load_path.Probes: bounding-box tree,
colliding cells, Function.eval); both meshes represent the same polyhedral joint exactly,
so every target node lies in the source mesh. A displacement source leaves p = 0: p enters
the mixed residual linearly (the p-equation ∫ q (ln J + p / kappa) dX = 0 and the stress
term -p cofac(F)), so Newton's first correction recovers p from a close u; the source's own
volumetric state -kappa ln J is the locked one the mixed formulation exists to avoid, so
it would be no better a start.

:func:`solve_seeded` then converges at that load from the guess (LoadPathSolver.converge)
and returns a fem.solvers.joint.SolveResult as EndLoadedSolver.solve does; when Newton fails the
target is left at rest, for a solve from zero.

One rank: Probes evaluates one point set that every rank holds, whereas under MPI each
rank owns different target nodes; several ranks are refused.

Data flow: source EndLoadedSolver.solve(load) -> seed(target, source) -> target's
LoadPathSolver.converge -> SolveResult (fem.studies.joint_cases.solve_missing, seed_from).
"""

from __future__ import annotations

import math
import time

import numpy as np
from dolfinx.fem.petsc import set_bc

from contract.spec import outside_box, phi_end
from fem.solvers.load_path import Probes
from fem.solvers.joint import EndLoadedSolver, Load, SolveResult


def check_pair(target: EndLoadedSolver, source: EndLoadedSolver) -> None:
    """Raise ValueError unless both solvers run on one rank and describe one joint (the
    same probe points and input box)."""
    if target.comm.size > 1 or source.comm.size > 1:
        raise ValueError("seeding from another mesh runs on one rank (the point evaluation is "
                         f"not parallel-safe), not {max(target.comm.size, source.comm.size)}")
    if target.probe_points.shape != source.probe_points.shape or \
            not np.allclose(target.probe_points, source.probe_points, atol=1e-9):
        raise ValueError("seed and target solvers have different anchors: not one joint")
    if not np.array_equal(target.input_box, source.input_box):
        raise ValueError("seed and target solvers have different input boxes: not one joint")


def unknown_blocks(problem) -> list[tuple[np.ndarray, np.ndarray]]:
    """The blocks of a problem's unknown as (indices into its local array, (n, c); node
    coordinates, (n, 3) mm): the displacement (c = 3) and, for the mixed formulation, the
    pressure (c = 1)."""
    V = problem.V
    if problem.displacement_space is None:
        x = V.tabulate_dof_coordinates()
        return [(np.arange(3 * len(x)).reshape(-1, 3), x)]
    U, to_u = V.sub(0).collapse()
    Q, to_p = V.sub(1).collapse()
    return [(np.asarray(to_u).reshape(-1, 3), U.tabulate_dof_coordinates()),
            (np.asarray(to_p).reshape(-1, 1), Q.tabulate_dof_coordinates())]


def source_fields(problem) -> list:
    """The source's fields that fill a target's blocks (unknown_blocks' order): u (a
    mixed unknown: Probes takes its displacement block) and p, or None (p = 0) when the
    source has no pressure."""
    if problem.displacement_space is None:
        return [problem.u, None]
    return [problem.u, problem.u.sub(1).collapse()]


def seed(target: EndLoadedSolver, source: EndLoadedSolver) -> None:
    """Put ``target`` at the load of ``source``'s converged state with the source's answer
    as its field (module docstring): unknown, load ``state`` and lagged cap rotation.
    Raises ValueError for several ranks, another joint, or a target node outside the
    source's mesh."""
    check_pair(target, source)
    w = target.problem.u
    for (index, points), field in zip(unknown_blocks(target.problem), source_fields(source.problem)):
        if field is None:
            w.x.array[index] = 0.0
            continue
        try:
            values = Probes(source.V.mesh, points).values(field)
        except RuntimeError:
            raise ValueError("a node of the target mesh lies outside the seed mesh: not one joint") from None
        # A scalar (the pressure) fills every column of Probes' (n, 3) values.
        w.x.array[index] = values[:, :index.shape[1]]
    set_bc(w.vector, target.problem.bcs)      # Dirichlet values exactly (round-off otherwise)
    w.x.scatter_forward()
    target.solver.state = source.solver.state.copy()
    target.problem.set_load(target.solver.state)
    for mine, theirs in zip(target.problem.lagged, source.problem.lagged):
        mine.constant.value = theirs.constant.value   # branch reference of the rotation
        mine.constant.value = mine.average.value(target.comm)


def solve_seeded(target: EndLoadedSolver, source: EndLoadedSolver) -> SolveResult:
    """Seed ``target`` from ``source`` (:func:`seed`) and converge by Newton at the
    source's load. The result is that of EndLoadedSolver.solve (anchors mm, angles rad,
    Newton figures of this solve, wall time s of the seeding and Newton); not converged:
    the target is back at rest (LoadPathSolver.converge) and the result's reason says why."""
    solver = target.solver
    t0, lu0, kr0 = time.perf_counter(), solver.factorisations, solver.krylov_iterations
    seed(target, source)
    path = solver.converge()
    load = Load.from_array(source.solver.state)
    anchors = target.positions()
    return SolveResult(
        load=load, converged=path.converged, anchors=anchors,
        phi_end=float(phi_end(anchors)) if len(anchors) > 1 else math.nan,
        cap_rotation=float(target.problem.lagged[0].constant.value),
        newton_iterations=path.newton_iterations, load_steps=path.load_steps, cutbacks=0,
        factorisations=solver.factorisations - lu0, krylov_iterations=solver.krylov_iterations - kr0,
        wall_time=time.perf_counter() - t0, reason=path.reason,
        extrapolated=bool(outside_box(load.as_array(), target.input_box)), u=target.u)
