"""Grasp atlas: where the gripper holds, slips or misses an object over its pressure plane.

The finger, approach and gravity options are predictor.cli.gesture's (a finger of two joints:
the atlas spans (P1, P2)); the JSON records the finger (name, sha256 of its file,
kinematics, joint weights) beside the settings below.

Every (P1, P2) of an N x N grid over the pressure box (MPa, default the full |P| <= 0.3
box) is solved along the same history as ``predictor.cli.gesture --object``: the gripper
settles at the approach gesture APPROACH = (-0.15, 0) MPa without the object, the object
is brought in, and the pressures ramp straight to the target (predictor.solvers.solve). Two
ways to walk that path (``--path``):

- ``sweep`` (default, ``sweep_solve``): by continuation outward from the approach, ring
  by ring, each point starting from its ray's previous grid point (one step of the
  path per point instead of the ramp's 12);
- ``ramp`` (the reference): every point ramped on its own in one batched ``solve``, so
  each row equals a single-sample solve.

Where the equilibrium along the ray is unique both give the same gesture; they can
differ where the path decides the branch (near the boundaries between states), as two
ramps of different step counts do. ``make atlas-reference`` writes the reference atlases
(results/predictor/ramp) and REPORT counts the points where the two agree. Without an
object the equilibrium is unique: where the fingers meet at X = 0 the ``sweep`` solves
the points that ``solve`` would ramp from zero pressure (their load-free pose lies across
the plane) by continuation from a converged grid neighbour (``free_sweep_solve``), the
others in one batched solve; without the plane the grid is one batched solve. Each point
is classified

    not_converged  the ramp solve failed (no gesture is reported);
    no_contact     converged, total normal force N = 0;
    slips          converged, N > 0, friction use u = |f|/(mu N) > 1 (statics: u = |λ|/mu);
    holds          converged, N > 0, u <= 1;

and records N (N), u, the fingertip (X, Y) mm of the right finger, the first-contact
pressures along the ramp (GestureResult.first_contact, MPa, NaN when never), where it
touches (the part and face carrying the most normal force and the mean point of that
contact, GestureResult.where_it_touches) and how far the finger's outline crosses the
symmetry plane X = 0 where the two fingers meet (plane_overlap_mm; the summary's
max_plane_overlap_mm). The friction
margin is 1 - u (> 0 where the grasp holds). The summary and JSON name what was solved:
joint, mu, object_weight_N, gravity, approach_MPa and plane (true: the gripper, the mirror
finger's contact at X = 0, the default; false: one finger alone, ``--no-plane``,
predictor.solvers.problem); ``atlas_from_json`` reads an atlas
back for the same problem and refuses (one line) one of another object, joint or settings.
A run longer than ~10 s prints progress lines on stderr (``--quiet``: none).

Data flow: GripperProblem (joint, object, approach) + grid -> ``grasp_atlas`` -> Atlas
(arrays (N, N[, 2]) indexed [i, j] = (P1 = p1[i], P2 = p2[j]), plus the GestureResult of
the flattened grid) -> ``Atlas.to_json()`` / ``save_atlas_figure``; JSON + GripperProblem ->
``atlas_from_json`` -> Atlas (the stored equilibria re-evaluated, no solve).
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from predictor.artefacts import ATLAS
from predictor.solvers.problem import FULL_BOX, GRID, box_arg, check_box, load_problem, object_arg, placement_error
from predictor.solvers.progress import Heartbeat
from predictor.solvers.jacobians import jacobian_fn
from predictor.solvers.options import SolverOptions
from predictor.solvers.ramp import advance, attempts, plane_first, plane_ramp, ramp_method, runner
from predictor.solvers.ramp import ramp as ramp_between
from predictor.solvers.result import GestureResult, contact_fields, result_labels
from predictor.solvers.solve import gesture_result, solve
from predictor.model.statics import (HOLDS, NO_CONTACT, NOT_CONVERGED, SLIPS, STATES, GripperProblem, Obstacle,
                                     grasp_state, meets, out_of_reach)

__all__ = ["FULL_BOX", "Atlas", "box_arg", "classify", "free_sweep_solve", "grasp_atlas", "load_problem",
           "object_arg", "placement_error", "sweep_solve"]
#: How an atlas point was solved (Atlas.how): continued from its ray's previous grid
#: point, ramped from the approach (no predecessor, or the ``ramp`` path), or ramped after
#: its continuation failed.
HOW = ("swept", "ramped", "retried")
SWEPT, RAMPED, RETRIED = range(3)
PATHS = ("sweep", "ramp")
#: Issue 16's speed target (s per object, 61 x 61 grid, one thread).
TARGET_S_PER_OBJECT = 10.0


def classify(res: GestureResult, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """(state codes (B,) int into STATES, friction use u = |λ|/mu (B,), NaN without
    contact or convergence) of a solve result (GestureResult.states, friction_use)."""
    conv = res.converged.numpy()
    use = np.abs(res.friction_ratio.numpy()) / mu
    state = np.where(~conv, NOT_CONVERGED, grasp_state(res.normal_force_N, res.slip).numpy())
    return state, np.where(conv & (res.normal_force_N.numpy() > 0), use, np.nan)


@dataclass(frozen=True)
class Atlas:
    """Grasp atlas of one object (module docstring). p1, p2: (N,) MPa grid axes; state
    (N, N) int (STATES); normal_N (N, N); friction_use (N, N) |f|/(mu N), NaN without
    contact; tip (N, N, 2) mm (right finger, NaN unless converged); first_contact (N, N, 2)
    MPa; result: the GestureResult of the flattened grid (row i*N + j); time_s: wall time
    of the grid's solve; obstacle, joint, mu, approach (MPa), gravity, object_weight_N
    (N, 0 without gravity): what was solved; path: sweep or ramp (grasp_atlas); how
    (N, N) int: SWEPT, RAMPED or RETRIED per point (None: all ramped)."""

    p1: np.ndarray
    p2: np.ndarray
    state: np.ndarray
    normal_N: np.ndarray
    friction_use: np.ndarray
    tip: np.ndarray
    first_contact: np.ndarray
    result: GestureResult
    time_s: float
    obstacle: Obstacle | None
    joint: str
    mu: float
    approach: tuple[float, float] | None = None
    path: str = "ramp"
    how: np.ndarray | None = None
    gravity: bool = True
    object_weight_N: float | None = None
    plane: bool = True

    def index(self, p1: float, p2: float) -> int:
        """Flat row of the grid point nearest to (p1, p2) MPa in ``result``."""
        i, j = int(np.abs(self.p1 - p1).argmin()), int(np.abs(self.p2 - p2).argmin())
        return i * len(self.p2) + j

    def best_hold(self) -> int | None:
        """Flat row of the holding point with the largest friction margin (least u), or None."""
        use = np.where(self.state == HOLDS, self.friction_use, np.inf).ravel()
        return int(use.argmin()) if np.isfinite(use.min()) else None

    def counts(self) -> dict:
        return {name: int((self.state == k).sum()) for k, name in enumerate(STATES)}

    def summary(self) -> dict:
        """Counts, the best holding point and the time, as plain JSON types."""
        best = self.best_hold()
        point = None if best is None else {
            "pressures_MPa": self.result.pressures[best].tolist(),
            "friction_use": float(self.friction_use.ravel()[best]),
            "normal_force_N": float(self.normal_N.ravel()[best])}
        how = np.full(self.state.shape, RAMPED) if self.how is None else self.how
        how = {name: int((how == k).sum()) for k, name in enumerate(HOW)}
        overlap = self.plane_overlap()
        return {"grid": len(self.p1), "counts": self.counts(), "best_hold": point, "time_s": self.time_s,
                "path": self.path, "solved_by": how, "joint": self.joint, "mu": self.mu,
                "object_weight_N": self.object_weight_N, "gravity": self.gravity, "plane": self.plane,
                "max_plane_overlap_mm": float(np.nanmax(overlap)) if np.isfinite(overlap).any() else None}

    def plane_overlap(self) -> np.ndarray:
        """(N, N) mm: how far the right finger crosses X = 0 at each converged point (NaN
        elsewhere, or when the result does not carry it)."""
        r = self.result
        if r.plane_overlap_mm is None:
            return np.full(self.state.shape, np.nan)
        return np.where(r.converged.numpy(), r.plane_overlap_mm.numpy(), np.nan).reshape(self.state.shape)

    def contact_places(self) -> dict:
        """Where the finger touches the object at each grid point (GestureResult.
        where_it_touches of the place carrying the most normal force): contact_part,
        contact_face (N, N) names or None, contact_point_mm (N, N, 2) (None where nothing
        touches), and plane_force_N (N, N) (None unless converged)."""
        n = len(self.p1), len(self.p2)
        places = [self.result.where_it_touches(i) for i in range(self.state.size)]
        grid = lambda key: np.array([p[key] for p in places], dtype=object).reshape(n).tolist()  # noqa: E731
        points = [p["contact_point_mm"] for p in places]
        return {"contact_part": grid("contact_part"), "contact_face": grid("contact_face"),
                "contact_point_mm": [points[i * n[1]:(i + 1) * n[1]] for i in range(n[0])],
                "plane_force_N": grid("plane_force_N")}

    def to_json(self) -> dict:
        """Everything (grid arrays as nested lists, NaN -> null by the JSON writer)."""
        ob = self.obstacle
        tau = self.result.tau.reshape(len(self.p1), len(self.p2), 2, 3)
        return {**self.summary(),
                "object": None if ob is None else {"kind": ob.kind, "a_mm": ob.a, "b_mm": ob.b, "x_mm": ob.x,
                                                   "y_mm": ob.y, "angle_rad": ob.angle,
                                                   **({"corner_mm": ob.corner} if ob.kind == "rectangle" else {})},
                "approach_MPa": self.approach,
                "states": list(STATES), "p1_MPa": self.p1.tolist(), "p2_MPa": self.p2.tolist(),
                "state": self.state.tolist(), "how": None if self.how is None else self.how.tolist(),
                "normal_force_N": self.normal_N.tolist(),
                "friction_use": self.friction_use.tolist(), "tip_mm": self.tip.tolist(),
                "first_contact_MPa": self.first_contact.tolist(), "tau": tau.tolist(),
                **self.contact_places(), "plane_overlap_mm": self.plane_overlap().tolist(),
                "targets": {"atlas_s_per_object": TARGET_S_PER_OBJECT},
                "measured": {"atlas_s_per_object": self.time_s, "grid_points": int(self.state.size)}}


def grasp_atlas(problem: GripperProblem, grid: int = 61, box=FULL_BOX,
                options: SolverOptions = SolverOptions(), path: str = "sweep") -> Atlas:
    """Solve the grid x grid atlas of ``problem`` (its object and approach) over
    box = (P1lo, P1hi, P2lo, P2hi) MPa. path: ``sweep`` (continuation outward from the
    approach, ``sweep_solve``) or ``ramp`` (every point ramped on its own, one batched
    ``solve``: the reference). Returns an Atlas. The atlas is the pressure plane of a
    2-joint finger (ValueError for another)."""
    if problem.n_joints != 2:
        raise ValueError(f"the grasp atlas spans (P1, P2): finger {problem.params.finger.name!r} has "
                         f"{problem.n_joints} joints")
    if path not in PATHS:
        raise ValueError(f"unknown atlas path {path!r}: use {' or '.join(PATHS)}")
    grid, box = GRID.value("grid", grid), check_box(box)
    p1 = np.linspace(box[0], box[1], grid)
    p2 = np.linspace(box[2], box[3], grid)
    pressures = torch.cartesian_prod(torch.from_numpy(p1), torch.from_numpy(p2)).reshape(-1, 2)
    t0 = time.perf_counter()
    spacing = np.array([p1[1] - p1[0], p2[1] - p2[0]])
    free = problem.obstacle is None
    if (free and not meets(problem)) or out_of_reach(problem):
        path = "ramp"            # no history (or nothing to touch): one batched solve
    if path == "sweep":
        sweep = free_sweep_solve if free else sweep_solve
        res, how = sweep(problem, pressures, spacing, options)
    else:
        res, how = solve(problem, pressures, options), np.full(grid * grid, RAMPED)
    elapsed = time.perf_counter() - t0
    state, use = classify(res, problem.contact.mu)
    shape = (grid, grid)
    first = res.first_contact if res.first_contact is not None else torch.full((grid * grid, 2), float("nan"))
    return Atlas(p1=p1, p2=p2, state=state.reshape(shape), normal_N=res.normal_force_N.numpy().reshape(shape),
                 friction_use=use.reshape(shape), tip=res.pose.tip_end.numpy().reshape(*shape, 2),
                 first_contact=first.numpy().reshape(*shape, 2), result=res, time_s=elapsed,
                 obstacle=problem.obstacle, joint=problem.joint.name, mu=problem.contact.mu,
                 approach=problem.approach, path=path, how=how.reshape(shape), gravity=problem.gravity,
                 object_weight_N=res.object_weight_N, plane=meets(problem))


def sweep_solve(problem: GripperProblem, pressures: torch.Tensor, spacing: np.ndarray,
                options: SolverOptions = SolverOptions()) -> tuple[GestureResult, np.ndarray]:
    """Every grid point of pressures (M, 2) MPa (grid spacing (2,) MPa) along a path from
    the approach p0, by continuation from the grid point before it.

    Ring s holds the points s grid steps from p0 (Chebyshev distance, rounded up); rings
    are solved in order, each as one batch. A point q of ring s continues (one ramp step
    of predictor.solvers.solve: tangent predictor from its predecessor's Jacobians, LM with the
    solve's Jacobians in turn (predictor.solvers.ramp.attempts), depth check, cut-backs) from the converged
    point nearest to p0 + (q - p0)(s - 1)/s, the ray's point one ring back, if that lies
    within one grid step of it. So each point's
    path follows its own straight ray from p0 within half a grid step (exactly on it
    where p0 is a grid node): the reference ramp's path (``solve``), in steps of one grid
    spacing instead of 1/12 of the ray. A point with no such predecessor, and a swept
    point that fails, is ramped from the approach as in ``solve`` (the reference); if it
    fails there too it is not converged.

    Returns (GestureResult of the M points, how (M,) int: SWEPT, RAMPED or RETRIED). Its
    first contact is the first point along the path that touches the object (a ramped
    point's: its ramp's).
    """
    t0 = time.perf_counter()
    Q = pressures.numpy()
    M, J = Q.shape
    n = 3 * J
    p0 = np.asarray(problem.approach if problem.approach is not None else (0.0,) * J)
    ring = np.ceil(np.abs((Q - p0) / spacing).max(1) - 1e-9).astype(int)
    x = torch.full((M, n), float("nan"), dtype=torch.float64)
    jx, jp = torch.zeros(M, n, n, dtype=torch.float64), torch.zeros(M, n, J, dtype=torch.float64)
    ok = torch.zeros(M, dtype=torch.bool)
    iterations = torch.zeros(M, dtype=torch.long)
    pred = np.full(M, -1)
    first = np.full((M, J), np.nan)          # the ramped points' own first contact
    how = np.full(M, SWEPT)
    runs = [runner(problem, dataclasses.replace(options, jacobian=k)) for k in attempts(problem, options)]
    jac_fn = jacobian_fn(problem, True, options.jacobian)

    def ramp(rows):
        # the reference path; its Jacobians at the solution start the points beyond it
        r = solve(problem, pressures[rows], options)
        x[rows], ok[rows], iterations[rows] = r.tau.reshape(len(rows), n), r.converged, r.iterations
        first[rows] = r.first_contact.numpy()
        good = rows[r.converged.numpy()]
        if len(good):
            J_, _, Jp_ = jac_fn(x[good], pressures[good])
            jx[good], jp[good] = J_[:, :n], Jp_

    beat = Heartbeat("atlas")
    for s in np.unique(ring):
        beat(lambda: f"ring {s} of {ring.max()}: {int(ok.sum())} of {M} points converged")
        rows = np.nonzero(ring == s)[0]
        pred[rows] = _predecessors(Q, rows, s, p0, spacing, ring, ok.numpy())
        cont = rows[pred[rows] >= 0]
        for run in runs:                            # the solve's Jacobians in turn (predictor.solvers.ramp.attempts)
            if len(cont) == 0:
                break
            pc = pred[cont]
            xs, conv, its, (J_, Jp_) = advance(run, x[pc], pressures[pc], pressures[cont], options.cutbacks,
                                                (jx[pc], jp[pc]))
            x[cont], ok[cont], jx[cont], jp[cont] = xs, conv, J_, Jp_
            iterations[cont] += its
            cont = cont[~conv.numpy()]
        new = rows[pred[rows] < 0]
        if len(new):
            how[new] = RAMPED
            ramp(new)
    retry = np.nonzero((how == SWEPT) & ~ok.numpy())[0]
    if len(retry):
        how[retry], pred[retry] = RETRIED, -1
        ramp(retry)
    res = gesture_result(problem, pressures, x, ok, iterations, t0, ramp_method(options), None)
    first = _first_contacts(first, Q, ring, pred, res.normal_force_N.numpy() > 0)
    return dataclasses.replace(res, first_contact=torch.from_numpy(first)), how


def free_sweep_solve(problem: GripperProblem, pressures: torch.Tensor, spacing: np.ndarray,
                     options: SolverOptions = SolverOptions()) -> tuple[GestureResult, np.ndarray]:
    """Every grid point of pressures (M, 2) MPa (grid spacing (2,) MPa) of an object-free
    problem whose fingers meet at X = 0: the points whose load-free pose lies clear of
    the plane (not ``predictor.solvers.ramp.plane_first``) by one batched ``solve`` (the
    reference's rows); the others, which ``solve`` ramps from zero pressure
    (``plane_ramp``, 12 sub-steps each), by continuation from a converged grid
    neighbour instead (a ramp of FREE_SUB_STEPS sub-steps, ``_continue``), wave by wave:
    each wave continues the waiting points that have a converged point within one grid
    step (the nearest one, in grid steps). A point that fails, or has no such neighbour,
    is ramped from zero pressure as in ``solve``. The two paths end at the same
    equilibria within the solver's tolerance (the inverse's 5 x 5 grid: 3e-9 N and N·mm;
    tests/test_planning.py freezes it).

    Returns (GestureResult of the M points, how (M,) int: SWEPT, RAMPED or RETRIED).
    """
    t0 = time.perf_counter()
    M, J = pressures.shape
    n = 3 * J
    deep = plane_first(problem, pressures, options).numpy()
    how = np.where(deep, SWEPT, RAMPED)
    x = torch.full((M, n), float("nan"), dtype=torch.float64)
    ok = torch.zeros(M, dtype=torch.bool)
    iterations = torch.zeros(M, dtype=torch.long)
    clear = np.nonzero(~deep)[0]
    if len(clear):
        r = solve(problem, pressures[clear], options)
        x[clear], ok[clear], iterations[clear] = r.tau.reshape(len(clear), n), r.converged, r.iterations
    grid = pressures.numpy() / spacing                      # points in grid steps
    waiting = np.nonzero(deep)[0]
    while len(waiting):
        done = np.nonzero(ok.numpy())[0]
        if not len(done):
            break
        dist = np.abs(grid[waiting, None] - grid[None, done]).max(-1)      # (waiting, done)
        near = dist.argmin(1)
        go = dist[np.arange(len(waiting)), near] <= 1.0 + 1e-9
        if not go.any():
            break
        rows, pred = waiting[go], done[near[go]]
        xs, conv, its = _continue(problem, x[pred], pressures[pred], pressures[rows], options)
        x[rows], ok[rows], iterations[rows] = xs, conv, its
        failed = rows[~conv.numpy()]
        how[failed] = RETRIED
        waiting = waiting[~go]
    again = np.nonzero(deep & ~ok.numpy())[0]
    if len(again):
        how[again] = np.where(how[again] == SWEPT, RAMPED, how[again])
        xr, okr, itr = plane_ramp(problem, pressures[again], options)
        x[again], ok[again], iterations[again] = xr, okr, iterations[again] + itr
    return gesture_result(problem, pressures, x, ok, iterations, t0, ramp_method(options), None), how


#: Ramp sub-steps of a continuation between grid neighbours of ``free_sweep_solve``: a
#: 0.15 MPa step pressed on the plane X = 0 (the inverse's coarse 5 x 5 grid) converges
#: fastest in 2 (its 12 points: 0.62, 0.36, 0.45, 0.61 s for 1 to 4 sub-steps, against
#: 0.77 s for the ramps from zero pressure; the same equilibria to 4e-9 N·mm).
FREE_SUB_STEPS = 2


def _continue(problem: GripperProblem, x: torch.Tensor, pa: torch.Tensor, pb: torch.Tensor,
              options: SolverOptions) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The object-free equilibria x (B, 3J) at pa (B, J) MPa continued to pb by a ramp of
    FREE_SUB_STEPS sub-steps (predictor.solvers.ramp.ramp: the plane's homotopy, depth check,
    cut-backs), each Jacobian of predictor.solvers.ramp.attempts in turn for the samples the
    previous one failed. Returns (x, converged (B,), iterations (B,))."""
    B = len(x)
    out, ok, its = x.clone(), torch.zeros(B, dtype=torch.bool), torch.zeros(B, dtype=torch.long)
    rows = torch.arange(B)
    for kind in attempts(problem, options):
        opts = dataclasses.replace(options, jacobian=kind, ramp_steps=FREE_SUB_STEPS)
        xr, okr, itr = ramp_between(problem, x[rows], pa[rows], pb[rows], opts)
        out[rows], ok[rows], its[rows] = xr, okr, its[rows] + itr
        rows = rows[~okr]
        if not len(rows):
            break
    return out, ok, its


def _predecessors(Q: np.ndarray, rows: np.ndarray, s: int, p0: np.ndarray, spacing: np.ndarray, ring: np.ndarray,
                  ok: np.ndarray) -> np.ndarray:
    """The predecessor (index into Q (M, 2) MPa, or -1) of each point ``rows`` of ring s: the
    converged point (ok (M,) bool) nearest to the ray's point p0 + (q - p0)(s - 1)/s one ring
    back, if within one grid step (spacing (2,) MPa) of it; none on ring 0."""
    # a predecessor within one step of the ray's point on ring s - 1 lies on ring s - 2 or s - 1
    done = np.nonzero(ok & (ring >= s - 2))[0]
    if s == 0 or not len(done):
        return np.full(len(rows), -1)
    ideal = p0 + (Q[rows] - p0) * ((s - 1) / s)
    dist = np.abs((ideal[:, None] - Q[done][None]) / spacing).max(-1)   # (rows, done) grid steps
    k = dist.argmin(1)
    return np.where(dist[np.arange(len(rows)), k] <= 1.0, done[k], -1)


def _first_contacts(first: np.ndarray, Q: np.ndarray, ring: np.ndarray, pred: np.ndarray,
                    touch: np.ndarray) -> np.ndarray:
    """First contact (M, 2) MPa of every point along its path: a swept point (pred >= 0)
    inherits its predecessor's, or is its own first contact where it touches (touch (M,)
    bool) and the path before it did not; ramped points keep ``first``, their ramp's."""
    first = first.copy()
    for s in np.unique(ring):                   # along each path, ring by ring
        rows = np.nonzero((ring == s) & (pred >= 0))[0]
        before = first[pred[rows]]
        first[rows] = np.where(np.isnan(before[:, :1]), np.where(touch[rows, None], Q[rows], np.nan), before)
    return first


def atlas_from_json(path: str | Path, problem: GripperProblem) -> Atlas:
    """An Atlas (with a GestureResult of its converged tau) from predictor.cli.atlas --out
    JSON; ValueError (one line) for a file that is not an atlas of this object."""
    doc = ATLAS.load(path)      # its format (predictor.artefacts): one line when it is not an atlas
    try:
        p1, p2 = np.array(doc["p1_MPa"], float), np.array(doc["p2_MPa"], float)
        tau = torch.tensor(np.array(doc["tau"], dtype=float), dtype=torch.float64).reshape(-1, 2, 3)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a predictor.planning.atlas JSON ({type(exc).__name__})") from None
    ob = problem.obstacle
    keys = ("kind", "a_mm", "b_mm", "x_mm", "y_mm", "angle_rad")
    want = None if ob is None else [ob.kind, ob.a, ob.b, ob.x, ob.y, ob.angle]
    got = None if doc.get("object") is None else [doc["object"][k] for k in keys]
    if ob is not None and ob.kind == "rectangle":   # atlases before the rounded corner were sharp
        want.append(ob.corner)
        got = None if got is None else got + [doc["object"].get("corner_mm", 0.0)]
    if want != got or doc.get("joint") != problem.joint.name:
        raise ValueError(f"{path}: an atlas of another object or joint ({doc.get('object')}, {doc.get('joint')})")
    _same_settings(path, doc, problem)
    pressures = torch.cartesian_prod(torch.from_numpy(p1), torch.from_numpy(p2)).reshape(-1, 2)
    ok = ~tau.reshape(-1, 6).isnan().any(-1)
    # Re-evaluate the stored equilibria (no solve): the same figures as the atlas run.
    with torch.no_grad():
        st = problem.residual(pressures, torch.nan_to_num(tau))
    nan = torch.full_like(st.contact.normal, float("nan"))
    res = GestureResult(pressures=pressures, tau=tau, converged=ok, residual_force_mN=nan, residual_moment_Nmm=nan,
                        normal_force_N=st.contact.normal, friction_N=st.contact.friction,
                        friction_ratio=st.contact.ratio, slip=st.contact.slip, iterations=torch.zeros_like(ok).long(),
                        time_ms=0.0, pose=st.pose.masked(ok), method="atlas-json", **result_labels(problem),
                        **contact_fields(problem, st))
    state, use = classify(res, problem.contact.mu)
    n = len(p1), len(p2)
    return Atlas(p1, p2, state.reshape(n), res.normal_force_N.numpy().reshape(n), use.reshape(n),
                 res.pose.tip_end.numpy().reshape(*n, 2), np.array(doc["first_contact_MPa"], float), res,
                 float(doc.get("time_s", 0.0)), ob, problem.joint.name, problem.contact.mu, problem.approach,
                 doc.get("path", "ramp"), None if doc.get("how") is None else np.array(doc["how"], int),
                 problem.gravity, res.object_weight_N, meets(problem))


def _same_settings(path, doc: dict, problem: GripperProblem) -> None:
    """ValueError (one line) when the atlas JSON was computed with other settings than
    ``problem``: gravity, mu, the object's weight, the approach, the plane X = 0. Atlases
    written before these were recorded were computed with the defaults (gravity on, mu
    0.3, 0.2 N, the plane)."""
    weight = problem.params.object_weight if problem.gravity else 0.0
    recorded = {"plane": doc.get("plane", True), "gravity": doc.get("gravity", True), "mu": doc.get("mu", 0.3),
                "object_weight_N": doc.get("object_weight_N", 0.2 if doc.get("gravity", True) else 0.0),
                "approach_MPa": None if doc.get("approach_MPa") is None else tuple(doc["approach_MPa"])}
    asked = {"plane": meets(problem), "gravity": problem.gravity, "mu": problem.contact.mu, "object_weight_N": weight,
             "approach_MPa": None if problem.approach is None else tuple(problem.approach)}
    for key, value in asked.items():
        if recorded[key] != value:
            flag = {"plane": "--no-plane", "gravity": "--no-gravity", "mu": "--mu", "object_weight_N": "--object-weight",
                    "approach_MPa": "the approach"}[key]
            raise ValueError(f"{path}: an atlas computed with {key} = {recorded[key]}, this question has "
                             f"{value} ({flag}): compute the atlas with the same settings")


def marked_points(atlas: Atlas) -> list[tuple[int, str]]:
    """A few grid rows to draw as gestures: the best hold, the slip point with the most
    normal force and the no-contact point nearest the middle of the box."""
    marks = []
    best = atlas.best_hold()
    if best is not None:
        marks.append((best, "best hold"))
    flat_state, normal = atlas.state.ravel(), atlas.normal_N.ravel()
    slips = np.flatnonzero(flat_state == SLIPS)
    if slips.size:
        marks.append((int(slips[normal[slips].argmax()]), "slips"))
    free = np.flatnonzero(flat_state == NO_CONTACT)
    if free.size:
        P = atlas.result.pressures.numpy()[free]
        mid = np.array([atlas.p1.mean(), atlas.p2.mean()])
        marks.append((int(free[np.abs(P - mid).sum(-1).argmin()]), "no contact"))
    return marks


def save_atlas_figure(path: str, atlas: Atlas, problem: GripperProblem) -> None:
    """PNG: state map and friction-use map of the pressure plane with normal-force contours
    and the marked points, and the marked points' gestures beside them (atlas of
    ``problem``)."""
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    from predictor.model.plot import draw_gesture, save_figure

    marks = marked_points(atlas)
    fig, axes = plt.subplots(1, 2 + len(marks), figsize=(4.6 * (2 + len(marks)), 4.8))
    ext = (atlas.p2[0], atlas.p2[-1], atlas.p1[0], atlas.p1[-1])
    colours = ["#d9d9d9", "tab:green", "tab:orange", "k"]
    ax = axes[0]
    ax.imshow(atlas.state, origin="lower", extent=ext, aspect="auto",
              cmap=mcolors.ListedColormap(colours), vmin=-0.5, vmax=3.5, interpolation="nearest")
    ax.legend(handles=[plt.Rectangle((0, 0), 1, 1, color=c) for c in colours], labels=list(STATES),
              fontsize=7, loc="lower left")
    ax.set_title(f"{atlas.obstacle.kind if atlas.obstacle else 'no object'}: state\n{atlas.joint}", fontsize=9)
    ax = axes[1]
    im = ax.imshow(atlas.friction_use, origin="lower", extent=ext, aspect="auto", cmap="RdYlGn_r",
                   vmin=0.0, vmax=2.0, interpolation="nearest")
    fig.colorbar(im, ax=ax, label="friction use |f|/(mu N)  (holds <= 1)")
    ax.set_title("friction use; contours: normal force N", fontsize=9)
    normal = np.where(atlas.state == NOT_CONVERGED, np.nan, atlas.normal_N)
    for ax in axes[:2]:
        if np.nanmax(normal, initial=0.0) > 0:
            cs = ax.contour(atlas.p2, atlas.p1, normal, levels=6, colors="k", linewidths=0.7)
            ax.clabel(cs, fontsize=6, fmt="%.2f")
        for k, (row, label) in enumerate(marks):
            p1, p2 = atlas.result.pressures[row].tolist()
            ax.plot(p2, p1, "o", mfc="w", mec="k")
            ax.annotate(str(k + 1), (p2, p1), xytext=(4, 4), textcoords="offset points", fontsize=8)
        ax.set_xlabel("P2 (MPa)")
        ax.set_ylabel("P1 (MPa)")
    for k, (row, label) in enumerate(marks):
        p1, p2 = atlas.result.pressures[row].tolist()
        draw_gesture(axes[2 + k], atlas.result, row, problem, f"{k + 1}: {label}, P = ({p1:+.2f}, {p2:+.2f}) MPa")
    fig.tight_layout()
    save_figure(fig, path, 110)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.atlas")
