"""Fingertip goals along a trajectory (issue 60): each answered warm-started from the
previous answer, every answer verified through the forward equilibrium.

A closed-loop controller asks, many times a second, which pressures (P1, P2) put the
fingertip at its next goal (X, Y[, DEG]) mm, deg (right finger, no object, the fingers
meeting at X = 0). ``Tracker(problem).answer(goal)`` answers one goal after the other:

1. Search: the projected Gauss-Newton of predictor.planning.inversion (``gauss_newton``: the
   goal residual's gradient through the equilibrium by the implicit function theorem,
   continuation steps with the plane's homotopy, steps capped, bounds) from the previous
   answer's equilibrium; the first goal starts from the best points of the kept grid.
   Near the last answer a position goal is first tried by Newton on the square system
   of the equilibrium and the goal in (x, P) at once (``Tracker._newton``: the problem's
   own residual, with the plane's penalty where the outline crosses X = 0, steps
   backtracked), which needs the steps inside the box and a quadratic descent; where it
   leaves the box or its step is too long (beyond the reach, a bound; not where it
   crawls) the same system with the goal in the least-squares sense (``Tracker.
   _least_squares``: the reduced Gauss-Newton of predictor.planning.inversion on one Jacobian per
   step, no continuation, to gauss_newton's stall); otherwise the Gauss-Newton. The last
   converged point's Jacobian and tip rows (they do not depend on the goal) start the
   next goal's Newton.
2. Unreachable goals: the search stops at the locally closest tip. The kept grid (a
   START_GRID x START_GRID cold grid of forward answers and the coarse COARSE x COARSE
   one of predictor.planning.inversion with the gestures pressed on X = 0, solved once per
   process, refined by every verified answer) is looked up (no solve): when one of its
   tips is closer to the goal than the local answer, the search restarts from the
   N_STARTS best of them (their Gauss-Newton in lockstep, predictor.planning.inversion.
   gauss_newton_all) and the closest verified answer is kept; when the kept grid's
   best is closer by SAME_TIP_MM or less (the search's loose tolerance against a kept
   earlier answer) that kept row itself is the candidate instead. No global search
   otherwise; the answer is flagged ``unreachable`` with its position error (and
   wrapped angle error), never farther from the goal than the kept grid's best.
3. Verification (every answer): the forward equilibrium at the answer's pressures and at
   its 8 ±REGULATOR neighbours (the regulators' resolution), solved anew: in one batched
   cold solve of the predictor (predictor.solvers.solve from tau = 0, without the plane's
   penalty, whose answer is the gripper's wherever the outline stays at X >= 0 — the
   broad phase ``solve`` itself uses), and where the finger presses on X = 0: the centre
   by up to WARM_STEPS of the solver's Newton steps (predictor.solvers.newton.newton_iterate, the
   problem's residual with the plane's penalty) from the search's own equilibrium at the
   same pressures, checked by the solver's rule (``meets_tolerances``) — still a check of
   the forward equilibrium, not of the search: the search's iterate is only the start
   (at 100x the tolerance, from the search's own Jacobians and continuation), the answer
   is the forward residual's root at full tolerance, and its tip (the forward statics)
   must lie within VERIFY_TOL_MM of the search's; the branch is the search's, itself
   continued from the previous verified gesture or a kept forward answer. Where Newton
   fails, the solver's continuation (the LM with the plane's homotopy, full tolerance)
   from the previous verified gesture (the gripper's history along the track). The
   stencil's pressed rows first by Newton (``Tracker._near``: the solver's Newton steps,
   checked by its rule) from the tangent predictor x + dx/dP·ΔP of the nearest verified
   pressed gesture within NEAR_MPA (the last KEEP_PRESSED centres and stencil rows of the
   answers, and this answer's own centre: the path moves little between goals, and an
   answer held at a bound repeats its pressures); the rows it leaves by the
   contact-constrained Newton from the verified centre (``Tracker._kkt``: the KKT of
   predictor.solvers.plane_newton along centre -> row, the continuation's equilibria in a
   fraction of its time), then by the continuation from the verified centre, first as
   one step without cut-backs and then with them, each followed by Newton from its last
   iterate while it contracts (``Tracker._polish``: where an edge lies flat on X = 0 the
   LM creeps and Newton converges only linearly), and last by the forward solve itself
   from zero pressure (``solve``): a row is not converged only where the forward solver
   finds no equilibrium (Newton from a kept x without the predictor, or from a centre
   apart from the plane, lands deep in the stiff penalty: measured). The answer is
   ``verified`` when its forward solve converged and its fingertip lies within
   VERIFY_TOL_MM of the search's; ``robust`` when all 9 converged. The reported tip and
   angle are the forward solve's; an unverified search result is never returned as
   verified (``verified`` false, and ``Tracker.answer`` then retries from the grid).

Data flow: GripperProblem -> Tracker (kept grid) -> answer(Goal) -> TrackAnswer; or
``track(problem, goals)`` -> TrackResult (answers, per-goal time, summary()).
"""
from __future__ import annotations

import csv
import dataclasses
import functools
import io
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from contract.files import read_text, strict_json

from predictor.planning.inversion import (N_STARTS, REGULATOR, START_SEPARATION, TIP_TOL_MM, VERIFY_TOL_MM, Goal,
                                          InverseProblem, Branch, clip_to_box, gauss_newton, gauss_newton_all,
                                          search_tip, tip_errors, tip_met, wrap_deg)
from predictor.solvers.options import SolverOptions
from predictor.solvers.problem import FULL_BOX, check_box
from predictor.solvers.result import GestureResult
from predictor.solvers.solve import gesture_result, meets_tolerances, newton_iterate, solve
from predictor.model.statics import GripperProblem, apart

NEWTON_ITER = 8           # Tracker._newton: iterations before the search takes over
NEWTON_HALVINGS = 4       # Tracker._newton: step halvings of its backtracking
NEWTON_STALL = 0.5        # Tracker._newton: an accepted step must lower |r|² + |e|² below this fraction
WARM_STEPS = 4            # Tracker._warm: Newton steps of a verification warm from a neighbour's equilibrium
TIP_DP = 1e-6 * 0.3       # MPa: the central difference of the tip in P (Tracker._evaluate)
LS_ITER = 8               # Tracker._least_squares: iterations before the search takes over
LS_DP_MPA = 1e-5          # Tracker._least_squares: a step moving P less than this ends it (~1e-3 mm of tip)
SAME_TIP_MM = 1e-3        # Tracker.answer: a kept row no closer than the search's by more is taken as is
START_GRID = 9            # the kept grid of forward answers: START_GRID x START_GRID over the box
KEEP_PRESSED = 90         # Tracker._near: the last verified gestures pressed on X = 0 kept as starts
NEAR_MPA = REGULATOR      # Tracker._near: a kept pressed gesture this close (max norm) starts Newton
NEAR_STEPS = 4            # Tracker._near: Newton steps of one round (newton_iterate)
NEAR_ROUNDS = 2           # Tracker._near: rounds of NEAR_STEPS
POLISH_STEPS = 60         # Tracker._polish: Newton steps at most (~0.4 a step where an edge lies flat on X = 0)
POLISH_CONTRACT = 0.8     # Tracker._polish: each step must shrink the residual (tolerance units) below this fraction
MAX_GOALS = 100_000       # goals in one track file
COORD_MM = 1e6            # |X|, |Y| of a goal in a track file
#: Issue 60's targets (medians, one thread): per goal along a track, a reachable tip goal
#: warm, any tip goal warm, and the rate of a 100-goal track end to end.
TARGET_REACHABLE_MS, TARGET_ANY_MS, TARGET_RATE_HZ = 5.0, 20.0, 50.0


@dataclass(frozen=True)
class TrackAnswer:
    """One goal's answer. goal (X, Y, DEG or None); status ``reached`` | ``unreachable``
    (the closest reachable answer); pressures (P1, P2) MPa; tip (X, Y) mm and
    tip_angle_deg of the verifying forward solve; position_error_mm, angle_error_deg
    (wrapped, None without DEG); verified, robust (module docstring); restarted: the kept
    grid knew a closer tip and the search restarted from it; time_ms: the whole answer,
    verification included; gesture: the verifying GestureResult (one row)."""

    goal: tuple
    status: str
    pressures: tuple[float, float]
    tip: tuple[float, float]
    tip_angle_deg: float
    position_error_mm: float
    angle_error_deg: float | None
    verified: bool
    robust: bool
    restarted: bool
    plane_force_N: float
    time_ms: float
    cpu_ms: float = 0.0
    gesture: GestureResult | None = None

    def summary(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "gesture"}


@functools.lru_cache(maxsize=8)
def start_grid(problem: GripperProblem, box: tuple, options: SolverOptions):
    """The kept grid: START_GRID x START_GRID pressures over ``box`` solved in one batched
    cold solve of the problem without the plane's penalty; the rows that converged with
    the outline at X >= 0 are the problem's own forward answers (the others, pressed on
    X = 0 where the fingers meet, are left out). Returns (P (n, 2), tau (n, 6), tip (n, 2),
    angle (n,) rad) of those rows; solved once per process per problem, box and options."""
    p1 = torch.linspace(box[0], box[1], START_GRID, dtype=torch.float64)
    p2 = torch.linspace(box[2], box[3], START_GRID, dtype=torch.float64)
    P = torch.cartesian_prod(p1, p2)
    res = solve(apart(problem), P, options)
    ok = res.converged & ~(res.plane_overlap_mm > 0) if res.plane_overlap_mm is not None else res.converged
    return (P[ok], res.tau.reshape(-1, 6)[ok], res.pose.tip_end[ok].clone(), res.pose.tip_angle[ok].clone())


class Tracker:
    """Answers tip goals one after the other (module docstring). problem: a 2-joint
    GripperProblem without an object; box (P1lo, P1hi, P2lo, P2hi) MPa."""

    def __init__(self, problem: GripperProblem, box=FULL_BOX, options: SolverOptions = SolverOptions(),
                 keep_coarse: bool = False):
        if problem.obstacle is not None:
            raise ValueError("--track: fingertip goals of the gripper without an object (drop --object)")
        if problem.n_joints != 2:
            raise ValueError(f"the inverse search spans (P1, P2): finger {problem.params.finger.name!r} has "
                             f"{problem.n_joints} joints")
        self.problem, self.box, self.options = problem, check_box(box), options
        P, tau, tip, ang = start_grid(problem, self.box, options)
        # the kept grid, refined by every verified answer (lists of rows)
        self.kept = [P, tau, tip, ang]
        self.branch: Branch | None = None      # the previous answer's equilibrium (search)
        self.anchor = None                      # the previous verified gesture (p (1, 2), x (1, 6))
        self.coarse_kept = False
        self._newton_at = None                  # (x, p, its evaluation) of the last converged _newton
        self.crawled = False                    # the last _newton stopped in a crawl (backtracking failed)
        self._kkt_run = None                    # the contact-constrained Newton of ``_kkt``, built at its first use
        # the verified gestures pressed on X = 0 (centres and stencil rows of the last answers):
        # (P (m, 2), x (m, 6)), starts of the next answers' pressed rows (``_near``)
        self.pressed = (torch.empty(0, 2, dtype=torch.float64), torch.empty(0, 6, dtype=torch.float64))
        if keep_coarse:
            self._keep_coarse()
        self._record_graphs()

    def _record_graphs(self) -> None:
        """Record, before the first goal, the graphs the answers use that the kept grids
        did not (predictor.solvers.graphs.traced, once per process and problem: ~30-40 ms
        each): the search's continuation with the plane's homotopy (its three softer
        planes' residuals), the fingertip's and the verification's Newton steps. Otherwise
        the first goal that needs each pays for it (measured: ~0.3 s within the demo track)."""
        from predictor.planning.inversion import traced_tip_fn

        P, tau = self.kept[0], self.kept[1]
        traced_tip_fn(self.problem)
        if len(P):
            Branch(self._ip(tip_goal(0.0, 0.0)), P[0], tau[0])
            newton_iterate(self.problem, P[:1], tau[:1].reshape(1, 2, 3), self.options, 0)   # records, no step

    def _keep_coarse(self) -> None:
        """Add predictor.planning.inversion.coarse_atlas (COARSE x COARSE, solved by continuation with
        the plane X = 0, once per process) to the kept grid: it holds the gestures pressed on
        X = 0 that the cold grid leaves out; solved at the first goal that is not met."""
        from predictor.planning.inversion import coarse_atlas

        res = coarse_atlas(self.problem, self.box, self.options).result
        ok = res.converged
        P, tau, tip, ang = self.kept
        self.kept = [torch.cat((P, res.pressures[ok])), torch.cat((tau, res.tau.reshape(-1, 6)[ok])),
                     torch.cat((tip, res.pose.tip_end[ok])), torch.cat((ang, res.pose.tip_angle[ok]))]
        self.coarse_kept = True

    def _ip(self, goal: Goal) -> InverseProblem:
        return InverseProblem(self.problem, goal, self.box, self.options)

    def _grid_scores(self, goal: Goal) -> torch.Tensor:
        """The kept grid's goal objective |e|² per row (as the search's)."""
        P, _, tip, ang = self.kept
        e = tip - torch.tensor(search_tip(goal), dtype=torch.float64)
        score = e.pow(2).sum(-1)
        if goal.angle_deg is not None:
            d = ang - math.radians(goal.angle_deg)
            score = score + (self.problem.params.tip_length * torch.atan2(torch.sin(d), torch.cos(d))) ** 2
        return score

    def _grid_starts(self, goal: Goal) -> list[int]:
        P = self.kept[0]
        chosen = []
        for i in torch.argsort(self._grid_scores(goal)).tolist():
            if len(chosen) == N_STARTS:
                break
            if all(float((P[i] - P[j]).abs().max()) >= START_SEPARATION for j in chosen):
                chosen.append(i)
        return chosen

    def _evaluate(self, x: torch.Tensor, p: torch.Tensor):
        """(J, r, dr/dP, tip rows T (17, 2)) at (x (1, 6), p (1, 2)): the solver's difference
        Jacobian of the problem itself (predictor.solvers.jacobians; where the outline crosses X = 0
        the plane's penalty is in r) and the fingertip at the point and at its central
        differences in x (12 rows) and P (4 rows) (predictor.planning.inversion.traced_tip_fn):
        neither depends on the goal."""
        from predictor.planning.inversion import traced_tip_fn
        from predictor.solvers.jacobians import difference_offsets, jacobian_fn

        _, offsets = difference_offsets(6, 1e-6)
        dP = TIP_DP * torch.eye(2, dtype=torch.float64)
        J, r, Jp = jacobian_fn(self.problem)(x, p)
        with torch.inference_mode():
            T = traced_tip_fn(self.problem)(torch.cat((x + offsets, x.expand(4, 6))),
                                            torch.cat((p.expand(13, 2), p + dP, p - dP)))[:, :2].clone()
        return J, r, Jp, T

    @staticmethod
    def _tip_derivatives(T: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(d tip/dx (2, 6), d tip/dP (2, 2)) from ``_evaluate``'s tip rows (central differences)."""
        from predictor.solvers.jacobians import difference_offsets

        hx, _ = difference_offsets(6, 1e-6)
        return ((T[1:7] - T[7:13]) / (2 * hx[:, None])).T, ((T[13:15] - T[15:17]) / (2 * TIP_DP)).T

    def _newton(self, ip: InverseProblem, branch: Branch) -> float | None:
        """The fast path of a position goal near the last answer: Newton on the square
        system of the equilibrium and the goal, r(x, P) = 0 (6 scaled rows) and
        tip(x, P) = (X, Y) (2), in the 8 unknowns (x, P) at once, from the branch's point,
        with the solver's difference Jacobian of the problem itself (predictor.solvers.jacobians;
        where the outline crosses X = 0 the plane's penalty is in r, the broad phase
        ``gated`` leaves it out elsewhere) and the pose's (predictor.planning.inversion.traced_tip_fn).
        Steps backtrack on |r|² + |e|² (NEWTON_HALVINGS: where the finger meets X = 0
        within a step, the full step lands deep in the plane's stiff penalty, which the
        Jacobian at the start did not see); it needs the steps inside the box and under
        MAX_STEP MPa, and each to lower the merit below NEWTON_STALL of the last (pressed
        on X = 0 the outline's vertices enter the plane one by one and Newton crawls: the
        LM of the search does better there). f when it converged (the solver's tolerances,
        ``_converged``, the tip within 0.1 TIP_TOL_MM), the branch moved there; else None,
        the branch unchanged (the search goes on by continuation)."""
        from predictor.planning.inversion import MAX_STEP

        goal = torch.tensor(search_tip(ip.goal), dtype=torch.float64)
        lo = torch.tensor([self.box[0], self.box[2]], dtype=torch.float64)
        hi = torch.tensor([self.box[1], self.box[3]], dtype=torch.float64)
        at = lambda x, p: _scored(self._evaluate(x, p), goal)  # noqa: E731
        self.crawled = False
        x, p = branch.x.clone(), branch.p.clone()
        # the last converged Newton's own evaluation at this very point (the previous
        # answer's): the Jacobians and tip rows do not depend on the goal, only e does
        last = self._newton_at
        same = last is not None and torch.equal(last[0], x) and torch.equal(last[1], p)
        here = _scored(last[2], goal) if same else at(x, p)
        for _ in range(NEWTON_ITER):
            J, r, Jp, T, e, merit = here
            if _converged(r, self.options) and float(e.norm()) <= 0.1 * TIP_TOL_MM:
                branch.restore((p, x, (J[:, :6], Jp)))
                self._newton_at = (x, p, (J, r, Jp, T))
                return float(e @ e)
            ex, ep = self._tip_derivatives(T)
            A = torch.cat((torch.cat((J[0, :6], Jp[0]), 1), torch.cat((ex, ep), 1)))   # (8, 8)
            dz, info = torch.linalg.solve_ex(A, -torch.cat((r[0, :6], e)))
            if int(info) != 0 or float(dz[6:].abs().max()) > MAX_STEP:
                return None
            # backtracking on |r|² + |e|²: where the finger meets X = 0 within the step the
            # full step lands deep in the plane's stiff penalty (its Jacobian did not see it)
            for _ in range(NEWTON_HALVINGS):
                p_new = p + dz[None, 6:]
                if bool(((p_new < lo) | (p_new > hi)).any()):
                    return None                                        # a bound: the projected search
                trial = at(x + dz[None, :6], p_new)
                if trial[-1] < merit:
                    break
                dz = 0.5 * dz
            else:
                self.crawled = True
                return None
            if trial[-1] > NEWTON_STALL * merit and not _converged(trial[1], self.options):
                self.crawled = True
                return None     # a linear crawl (the outline's vertices entering X = 0): the search's LM
            x, p, here = x + dz[None, :6], p_new, trial
        return None

    def _least_squares(self, ip: InverseProblem, branch: Branch) -> float | None:
        """The fast path of a position goal the square Newton cannot meet (beyond the reach,
        or a bound): Gauss-Newton on the same system with the goal in the least-squares
        sense, in (x, P) at once from the branch's point (``_evaluate``: one Jacobian and
        the tip rows per iteration, no continuation). Eliminating dx from the linearised
        equilibrium J dx + dr/dP dP = -r leaves the tip's e + ex dx + ep dP = e' + G dP with
        G = ep - ex J⁻¹ dr/dP (the implicit function theorem's de/dP, module
        predictor.planning.inversion) and e' = e - ex J⁻¹ r; dP minimises |e' + G dP|² (Levenberg-
        damped as predictor.planning.inversion.gauss_newton, a component at a bound whose step points
        out held there, capped at MAX_STEP, clipped to the box), dx follows. Steps backtrack
        on |r|² + |e|² (NEWTON_HALVINGS), or on |r| alone where |e|² stays within the
        model's |e'|² (near a far goal's minimum |e|² is mm², |r|² far below its rounding).
        It stops where the solver's tolerances hold (``_converged``) and the step moves P
        less than LS_DP_MPA or its linear model
        gains less than STALL of f (predictor.planning.inversion.gauss_newton's stall, on the model:
        stationary, Gᵀe' ~ 0, or held at the bounds; a crawl where the outline's vertices
        enter X = 0, whose model promises more than the steps gain, runs out): f, the
        branch moved there; else (LS_ITER steps, a failed backtracking) None, the branch
        unchanged (the search goes on by continuation). The answer's f is the stationary
        value gauss_newton's continuation would reach from here (same objective, same
        stall), reached without a continuation LM per step."""
        from predictor.planning.inversion import MAX_STEP, STALL

        goal = torch.tensor(search_tip(ip.goal), dtype=torch.float64)
        lo = torch.tensor([self.box[0], self.box[2]], dtype=torch.float64)
        hi = torch.tensor([self.box[1], self.box[3]], dtype=torch.float64)
        x, p = branch.x.clone(), branch.p.clone()
        last = self._newton_at
        same = last is not None and torch.equal(last[0], x) and torch.equal(last[1], p)
        here = _scored(last[2] if same else self._evaluate(x, p), goal)
        for _ in range(LS_ITER):
            J, r, Jp, T, e, merit = here
            ex, ep = self._tip_derivatives(T)
            M = torch.linalg.solve(J[0, :6], torch.cat((r[0, :6, None], Jp[0]), 1))   # J⁻¹ [r, dr/dP]
            e1, G = e - ex @ M[:, 0], ep - ex @ M[:, 1:]
            f = float(e @ e)
            A = G.T @ G + 1e-9 * torch.eye(2, dtype=torch.float64)
            dp = -torch.linalg.solve(A, G.T @ e1)
            stuck = ((p[0] <= lo) & (dp < 0)) | ((p[0] >= hi) & (dp > 0))
            if bool(stuck.all()):
                dp = torch.zeros(2, dtype=torch.float64)
            elif bool(stuck.any()):          # slide along the bound: the free component alone
                k = int((~stuck).nonzero()[0])
                dp = torch.zeros(2, dtype=torch.float64)
                dp[k] = -float(G[:, k] @ e1) / float(G[:, k] @ G[:, k] + 1e-9)
            dp = dp * min(1.0, MAX_STEP / max(float(dp.abs().max()), 1e-300))
            dp = torch.minimum(torch.maximum(p[0] + dp, lo), hi) - p[0]
            e2 = e1 + G @ dp
            gain = float(e1 @ e1 - e2 @ e2)        # the linear model's own: nothing left to gain
            if _converged(r, self.options) and (float(dp.abs().max()) <= LS_DP_MPA or gain <= STALL * f):
                branch.restore((p, x, (J[:, :6], Jp)))
                self._newton_at = (x, p, (J, r, Jp, T))
                return f
            dx = -(M[:, 0] + M[:, 1:] @ dp)
            rr = float(r[0] @ r[0])
            for _ in range(NEWTON_HALVINGS):
                trial = _scored(self._evaluate(x + dx[None], p + dp[None]), goal)
                # |r|² and |e|² differ by orders near a far goal's minimum (mm² against the
                # scaled residual's): a step that finishes the equilibrium and keeps the tip's
                # |e|² within that of the equilibrium's own correction (|e'|², the model's) is taken
                if trial[-1] < merit or (float(trial[1][0] @ trial[1][0]) < rr
                                         and float(trial[4] @ trial[4]) <= float(e1 @ e1) + 1e-12 * f):
                    break
                dx, dp = 0.5 * dx, 0.5 * dp
            else:
                return None
            x, p, here = x + dx[None], p + dp[None], trial
        return None

    def _search(self, ip: InverseProblem, branch: Branch) -> float:
        """Gauss-Newton from the branch (the search's iterates at the solver's 100x looser
        tolerance, as predictor.planning.inversion's: the verification's forward solve converges the
        answer fully and its tip is the one reported); f."""
        gauss_newton(ip, branch)
        return self._searched(ip, branch)

    def _searched(self, ip: InverseProblem, branch: Branch) -> float:
        """f of the goal at the branch's point (the fingertip by its recorded graph)."""
        from predictor.planning.inversion import traced_tip_fn

        with torch.inference_mode():
            T = traced_tip_fn(self.problem)(branch.x, branch.p)[0].clone()
        e = T[:2] - torch.tensor(search_tip(ip.goal), dtype=torch.float64)
        f = float(e @ e)
        if ip.goal.angle_deg is not None:
            d = float(T[2]) - math.radians(ip.goal.angle_deg)
            f += (self.problem.params.tip_length * math.atan2(math.sin(d), math.cos(d))) ** 2
        return f

    def answer(self, goal: Goal) -> TrackAnswer:
        """The verified answer to a tip goal (module docstring)."""
        t0, c0 = time.perf_counter(), time.process_time()
        if goal.kind != "tip":
            raise ValueError("a track's goals are fingertip goals tip:X,Y[,DEG]")
        ip = self._ip(goal)
        found = []                                   # (f, branch, anchor)
        exact = (0.1 * TIP_TOL_MM) ** 2
        if self.branch is not None:
            quick = None
            if goal.angle_deg is None:
                quick = self._newton(ip, self.branch)
                if quick is None and not self.crawled:     # a bound or beyond reach, not a crawl
                    quick = self._least_squares(ip, self.branch)
            if quick is not None:
                found.append((quick, self.branch, self.anchor))
            else:
                found.append((self._search(ip, self.branch), self.branch, self.anchor))
        best = lambda: min((t[0] for t in found), default=math.inf)  # noqa: E731
        restarted = False
        for _ in range(2):
            if found and best() > exact and not self.coarse_kept:
                self._keep_coarse()     # an unmet goal: the coarse grid's pressed gestures join the kept grid
            if found and best() <= exact:
                break                   # met: no restart
            if found:
                scores = self._grid_scores(goal)
                i = int(scores.argmin())
                if float(scores[i]) >= best() - 1e-12:
                    break               # the kept grid knows nothing closer: no restart
                if math.sqrt(best()) - math.sqrt(float(scores[i])) <= SAME_TIP_MM:
                    # the kept grid's best is as close as the search's answer (to SAME_TIP_MM:
                    # the search's loose tolerance; a kept earlier answer): that row itself
                    # (a forward answer) is the candidate, verified as any, instead of the
                    # N_STARTS searches that end there (measured: ~1 s on the demo track)
                    b = Branch(ip, self.kept[0][i], self.kept[1][i])
                    found.append((float(scores[i]), b, (b.p.clone(), b.x.clone())))
                    break
            restarted = restarted or bool(found)
            P, tau = self.kept[0], self.kept[1]
            # the grid's starts searched in lockstep (gauss_newton_all), as if one after the
            # other until the first that meets the goal exactly
            starts = [Branch(ip, P[i], tau[i]) for i in self._grid_starts(goal)]
            anchors = [(b.p.clone(), b.x.clone()) for b in starts]
            count = gauss_newton_all(ip, starts, "searched")
            found.extend((self._searched(ip, b), b, a) for b, a in zip(starts[:count], anchors[:count]))
        found.sort(key=lambda t: t[0])
        for f, branch, anchor in found:
            ver = self._verify(ip, branch, anchor)
            if ver is not None:
                break
        else:   # no candidate verified: the best, flagged unverified (never returned as verified)
            f, branch, anchor = found[0]
            ver = self._verify(ip, branch, anchor, force=True)
        gest, verified, robust = ver
        tip = tuple(gest.pose.tip_end[0].tolist())
        angle = math.degrees(float(gest.pose.tip_angle[0]))
        pos, ang = tip_errors(tip, angle, goal)
        if verified:
            self.branch, self.anchor = branch, (gest.pressures.clone(), gest.tau.reshape(1, 6).clone())
            P, tau, tp, an = self.kept
            self.kept = [torch.cat((P, gest.pressures)), torch.cat((tau, gest.tau.reshape(1, 6))),
                         torch.cat((tp, gest.pose.tip_end)), torch.cat((an, gest.pose.tip_angle))]
        return TrackAnswer(goal=(goal.tip[0], goal.tip[1], goal.angle_deg),
                           status="reached" if verified and tip_met(ip, pos, ang) else "unreachable",
                           pressures=tuple(gest.pressures[0].tolist()), tip=tip, tip_angle_deg=angle,
                           position_error_mm=pos, angle_error_deg=ang, verified=verified, robust=robust,
                           restarted=restarted,
                           plane_force_N=0.0 if gest.plane_force_N is None else float(gest.plane_force_N[0]),
                           time_ms=1e3 * (time.perf_counter() - t0), cpu_ms=1e3 * (time.process_time() - c0),
                           gesture=gest)

    def _continue(self, ip: InverseProblem, start, ps: torch.Tensor,
                  cutbacks: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The forward equilibria at ps (n, 2) by the solver's continuation from the
        equilibrium ``start`` (p (1, 2), x (1, 6)) at full tolerance (Branch.neighbours: the
        stiff plane's LM from the tangent predictor, then the homotopy's softer planes and
        ``cutbacks`` (default the options') for the rows it leaves). Returns (x (n, 6),
        converged (n,)); a row not converged has the last iterate of its last step."""
        cont = Branch(ip, start[0], start[1])
        cont.tol = self.options
        if cutbacks is not None:
            cont.opts = dataclasses.replace(cont.opts, cutbacks=cutbacks)
        return cont.neighbours(ps)

    def _kkt(self, start, ps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The forward equilibria at ps (n, 2) pressed on X = 0 by the contact-constrained
        Newton (predictor.solvers.ramp.contact_newton: the KKT along the straight path from
        the equilibrium ``start`` (p (1, 2), x (1, 6)) to each row, the penalty's Newton
        steps, the stiff plane's LM polish with the ramp's checks), at full tolerance.
        Returns (x (n, 6), converged (n,))."""
        from predictor.solvers.ramp import contact_newton

        if self._kkt_run is None:
            self._kkt_run = contact_newton(self.problem, self.options)
        n = len(ps)
        x, ok, _, _ = self._kkt_run(start[1].expand(n, 6).clone(), ps, p0=start[0].expand(n, 2).clone())
        return torch.nan_to_num(x), ok

    def _warm(self, ps: torch.Tensor, x0: torch.Tensor, steps: int = WARM_STEPS) -> tuple[torch.Tensor, torch.Tensor]:
        """The forward equilibria at ps (n, 2) by up to WARM_STEPS of the solver's full Newton
        steps (predictor.solvers.newton.newton_iterate: the problem's own residual, with the plane's
        penalty) from x0 (n, 6), each checked by the solver's convergence rule at its
        answer (``meets_tolerances``: every joint's residual within the tolerances, tau in
        the box). No LM here: a row Newton leaves is the continuation's (``_continue``).
        Returns (x (n, 6), converged (n,))."""
        x, its, _ = newton_iterate(self.problem, ps, x0.reshape(-1, 2, 3), self.options, steps)
        ok = torch.isfinite(x).all(-1)
        x = torch.nan_to_num(x)
        g = gesture_result(self.problem, ps, x, ok, its, time.perf_counter(), "newton", None)
        return x, ok & meets_tolerances(g, x, self.options)

    def _polish(self, ps: torch.Tensor, x0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The forward equilibria at ps (n, 2) by the solver's full Newton steps (one
        newton_iterate step at a time, the problem's residual with the plane's penalty)
        from x0 (n, 6) for as long as each step shrinks the residual's worst joint (in
        tolerance units: max(|R_F| / tol_force, |R_M| / tol_moment)) below POLISH_CONTRACT
        of the last, POLISH_STEPS at most; checked by the solver's rule (``meets_tolerances``).
        Where an edge of the outline lies flat on X = 0 (the penalty's force ~ overlap³
        within its smoothing width) Newton converges only linearly, ~0.43 a step (measured
        at goal 41 of the demo track: |R_F| 1e-3 -> 3e-6 N in 11 steps), so newton_iterate's
        one-step gate (which assumes quadratic convergence) stops it short, and the LM of
        the continuation creeps there through its 30 iterations and fails; a row that does
        not contract (diverging, another branch) stops at once. Returns (x (n, 6), converged (n,))."""
        from predictor.solvers.newton import bounds

        (tf, tm), _ = bounds(self.options)
        x = torch.nan_to_num(x0.clone())
        last = torch.full((len(ps),), math.inf, dtype=torch.float64)
        on = torch.arange(len(ps))
        for k in range(POLISH_STEPS + 1):
            xn, _, r = newton_iterate(self.problem, ps[on], x[on].reshape(-1, 2, 3), self.options, 1)
            m = torch.maximum(r[..., :2].norm(dim=-1).amax(-1) / tf, r[..., 2].abs().amax(-1) / tm)
            # the first step is free: from the continuation's last iterate (an LM's, in the
            # penalty's narrow valley) it raised the residual 44x at goal 41, then contracted
            go = (m > 1.0) & ((m < POLISH_CONTRACT * last[on]) | (k == 1)) & torch.isfinite(xn).all(-1)
            last[on] = m
            on = on[go]
            if not len(on):
                break
            x[on] = xn[go]
        g = gesture_result(self.problem, ps, x, torch.isfinite(x).all(-1), torch.zeros(len(ps), dtype=torch.long),
                           time.perf_counter(), "newton", None)
        return x, torch.isfinite(x).all(-1) & meets_tolerances(g, x, self.options)

    def _verify(self, ip: InverseProblem, branch: Branch, anchor, force: bool = False):
        """(verifying gesture (one row), verified, robust), or None when the forward solve
        disagrees (unless ``force``: then returned with verified False). Module docstring
        §3: the centre and its 8 neighbours in one batched cold solve without the plane's
        penalty, the rows pressed on X = 0 by Newton from a kept pressed gesture (``_near``)
        or by continuation from ``anchor`` (the centre); the stencil's others by the KKT
        (``_kkt``), the continuation (``_continue``, ``_polish``) from the verified centre,
        and last the forward solve from zero pressure."""
        prob, opts = self.problem, self.options
        d = REGULATOR * torch.tensor([(0, 0)] + [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)],
                                     dtype=torch.float64)
        ps = torch.from_numpy(clip_to_box(ip, (branch.p + d).numpy()))
        t0 = time.perf_counter()
        res = solve(apart(prob), ps, opts)
        x, ok = res.tau.reshape(9, 6).clone(), res.converged.clone()
        pressed = ~ok | (res.plane_overlap_mm > 0)
        if not bool(pressed.any()):   # every row the problem's own (the solver's rule checked them)
            g = res
        else:
            # the centre by Newton from the search's own equilibrium at the same pressures
            # (``_warm``), else by continuation from the previous verified gesture; the
            # stencil's pressed rows from kept pressed gestures, by the KKT and by continuation
            # from the verified centre (steps of REGULATOR: Newton alone fails there, the
            # outline's vertices entering and leaving X = 0 within the step: measured)
            if bool(pressed[0]):
                x[:1], ok[:1] = self._warm(ps[:1], branch.x)
                if not bool(ok[0]):
                    x[:1], ok[:1] = self._continue(ip, anchor, ps[:1])
            rest = pressed.clone()
            rest[0] = False
            if bool(rest.any()):
                # first by Newton from a kept pressed gesture of the last answers within
                # NEAR_MPA (``_near``: the path moves little between goals, and an answer
                # held at a bound repeats its pressures), the others by continuation
                centre = (ps[:1], x[:1]) if bool(pressed[0] & ok[0]) else None
                x[rest], ok[rest] = self._near(ps[rest], centre)
                rest = rest & ~ok
            start = (ps[:1], x[:1]) if bool(ok[0]) else anchor
            if bool(rest.any()):
                # the contact-constrained Newton (predictor.solvers.plane_newton: KKT from the
                # verified centre's own state along centre -> row, the penalty's Newton, the
                # stiff LM's polish): the continuation's equilibria (to <= 1e-6 N, N·mm on the
                # demo track) in 10-40 ms a batch where the continuation took 12-820 ms
                x[rest], ok[rest] = self._kkt(start, ps[rest])
                rest = rest & ~ok
            for cutbacks in (0, None):
                if not bool(rest.any()):
                    break
                # the rows the KKT leaves: the continuation, first as one step (no cut-backs),
                # then Newton on from its last iterate (``_polish``: where an edge lies flat on
                # X = 0 the LM creeps and Newton converges linearly; goal 41 of the demo: 107
                # ms against 841 ms with the 4 cut-backs), then the full continuation (and the
                # polish from it)
                x[rest], ok[rest] = self._continue(ip, start, ps[rest], cutbacks)
                rest = rest & ~ok
                if bool(rest.any()):
                    x[rest], ok[rest] = self._polish(ps[rest], x[rest])
                    rest = rest & ~ok
            if bool(rest.any()):
                # the forward solve itself (from zero pressure, as ``solve`` answers any user):
                # a row is not robust only when the forward equilibrium is not found there
                # (before: flagged NOT ROBUST at goal 41 of the demo track, whose row (0.1934,
                # 0.0043) MPa the forward solve converges, pressed on X = 0)
                fwd = solve(prob, ps[rest], opts)
                x[rest], ok[rest] = torch.nan_to_num(fwd.tau.reshape(-1, 6)), fwd.converged
            # the forward model's own convergence rule at the verified points (residual, box)
            g = gesture_result(prob, ps, torch.nan_to_num(x), ok, torch.zeros(9, dtype=torch.long), t0,
                               "track-verify", None)
            ok = ok & meets_tolerances(g, torch.nan_to_num(x), opts)
        centre = g.rows([0])
        from predictor.planning.inversion import traced_tip_fn

        with torch.inference_mode():
            searched = traced_tip_fn(prob)(branch.x, branch.p)[0, :2].clone()   # the search's fingertip
        agree = bool(ok[0]) and float((centre.pose.tip_end[0] - searched).norm()) <= VERIFY_TOL_MM
        if not agree and not force:
            return None
        centre = dataclasses.replace(centre, converged=ok[:1].clone())
        if agree and bool(pressed.any()):
            self._keep_pressed(ps[pressed & ok], x[pressed & ok])
        return centre, agree, agree and bool(ok.all())

    def _keep_pressed(self, ps: torch.Tensor, x: torch.Tensor) -> None:
        """Keep the verified gestures pressed on X = 0 at ps (n, 2), x (n, 6) as starts
        (``_near``), the last KEEP_PRESSED of them."""
        P, X = self.pressed
        self.pressed = (torch.cat((P, ps))[-KEEP_PRESSED:], torch.cat((X, x))[-KEEP_PRESSED:])

    def _near(self, ps: torch.Tensor, centre=None) -> tuple[torch.Tensor, torch.Tensor]:
        """The forward equilibria at ps (n, 2) pressed on X = 0 by the solver's Newton steps
        (``_warm``, checked by the solver's rule) from the nearest kept pressed gesture of
        the last answers (``_keep_pressed``) within NEAR_MPA (max norm): the same branch,
        a step far shorter than the stencil's REGULATOR from its centre, where the tangent
        of a centre apart from the plane (or pressed with other vertices in the plane)
        lands deep in the stiff penalty. Rows with none so near, or that Newton leaves,
        come back not converged (the continuation's, ``_continue``). Returns (x (n, 6),
        converged (n,))."""
        x = torch.zeros(len(ps), 6, dtype=torch.float64)
        ok = torch.zeros(len(ps), dtype=torch.bool)
        P, X = self.pressed
        if centre is not None:      # the answer's own verified centre, pressed on X = 0
            P, X = torch.cat((P, centre[0])), torch.cat((X, centre[1]))
        if len(P) == 0:
            return x, ok
        gap, j = (ps[:, None] - P[None]).abs().amax(-1).min(1)
        near = gap <= NEAR_MPA
        if not bool(near.any()):
            return x, ok
        # the tangent predictor x + dx/dP·ΔP, dx/dP = -(dr/dx)⁻¹ dr/dP at the kept gesture
        # (the solver's difference Jacobian, the plane's penalty in r): from the kept x alone
        # Newton's first step diverges (0.0027 MPa off: |R_F| 0.4 N -> 2e6 N, measured)
        from predictor.solvers.jacobians import jacobian_fn

        pk, xk = P[j[near]], X[j[near]]
        J, _, Jp = jacobian_fn(self.problem)(xk, pk)
        dx, info = torch.linalg.solve_ex(J[:, :6], Jp @ (ps[near] - pk)[..., None])
        x[near] = torch.where((info == 0)[:, None], xk - dx[..., 0], xk)
        # newton_iterate stops at its one-step gate, which assumes quadratic convergence from
        # there; pressed on X = 0 the residual first falls only ~4x a step (measured from a
        # centre's tangent predictor), so a second round goes on from the last iterate
        for _ in range(NEAR_ROUNDS):
            todo = near & ~ok
            if not bool(todo.any()):
                break
            x[todo], ok[todo] = self._warm(ps[todo], x[todo], NEAR_STEPS)
        return x, ok


def _scored(evaluation, goal: torch.Tensor):
    """``Tracker._evaluate``'s (J, r, dr/dP, T) with the goal's e = tip - goal (2,) and the
    merit |r|² + |e|²."""
    J, r, Jp, T = evaluation
    e = T[0] - goal
    return J, r, Jp, T, e, float(r[0] @ r[0] + e @ e)


def _converged(r: torch.Tensor, options: SolverOptions) -> bool:
    """The solver's convergence rule (predictor.solvers.lm.within) on one residual row r (1, 12):
    each joint's |R_F| <= tol_force N, |R_M| <= tol_moment N·mm, no out-of-box penalty."""
    from predictor.solvers.lm import within
    from predictor.model.statics import MOMENT_SCALE

    eq = r[:, :6].reshape(-1, 2, 3)
    return bool(within(eq[..., :2].norm(dim=-1), eq[..., 2].abs() * MOMENT_SCALE, r[:, 6:].abs().amax(-1) == 0,
                       options)[0])


@dataclass(frozen=True)
class TrackResult:
    """answers (one per goal, in order), total_ms (wall time of the goals' answers, end to
    end), setup_ms (the kept grids, solved before the first goal)."""

    answers: tuple[TrackAnswer, ...]
    total_ms: float
    setup_ms: float = 0.0

    def summary(self) -> dict:
        """Per-goal rows and the issue's figures: goals, median_ms, p95_ms, max_ms, rate_hz
        (end to end), max_tip_error_mm (over the reached goals), verified (all), reached,
        unreachable, the reached and unreachable goals' median times."""
        t = np.array([a.time_ms for a in self.answers])
        reached = [a for a in self.answers if a.status == "reached"]
        unreach = [a for a in self.answers if a.status != "reached"]
        med = lambda xs: float(np.median(xs)) if xs else None  # noqa: E731
        c = np.array([a.cpu_ms for a in self.answers])
        return {"goals": len(self.answers), "median_ms": float(np.median(t)), "p95_ms": float(np.percentile(t, 95)),
                "max_ms": float(t.max()), "first_ms": float(t[0]),
                "warm_median_ms": med(t[1:].tolist()),
                "rate_hz": 1e3 * len(t) / self.total_ms, "total_ms": self.total_ms, "setup_ms": self.setup_ms,
                "max_tip_error_mm": max((a.position_error_mm for a in reached), default=None),
                "verified": all(a.verified for a in self.answers),
                "robust": sum(a.robust for a in self.answers),
                "reached": len(reached), "unreachable": len(unreach),
                "reached_warm_median_ms": med([a.time_ms for a in reached[1:]] if reached and reached[0] is
                                              self.answers[0] else [a.time_ms for a in reached]),
                "unreachable_median_ms": med([a.time_ms for a in unreach]),
                "restarts": sum(a.restarted for a in self.answers),
                # CPU time (process, one thread): the answers' own cost on a shared machine
                "cpu_median_ms": float(np.median(c)), "cpu_p95_ms": float(np.percentile(c, 95)),
                "cpu_rate_hz": 1e3 * len(c) / float(c.sum()),
                "reached_warm_cpu_median_ms": med([a.cpu_ms for a in reached if a is not self.answers[0]]),
                "unreachable_cpu_median_ms": med([a.cpu_ms for a in unreach]),
                "answers": [a.summary() for a in self.answers]}


def track(problem: GripperProblem, goals, box=FULL_BOX, options: SolverOptions = SolverOptions()) -> TrackResult:
    """Answer ``goals`` (Goals, or (X, Y[, DEG]) tuples) in order with one Tracker; its
    kept grids (``start_grid`` and the coarse one, once per process) are solved first and
    timed apart (``setup_ms``)."""
    t0 = time.perf_counter()
    tracker = Tracker(problem, box, options, keep_coarse=True)
    goals = [g if isinstance(g, Goal) else tip_goal(*g) for g in goals]
    t1 = time.perf_counter()
    answers = tuple(tracker.answer(g) for g in goals)
    return TrackResult(answers, 1e3 * (time.perf_counter() - t1), 1e3 * (t1 - t0))


def tip_goal(x: float, y: float, deg: float | None = None) -> Goal:
    """A tip Goal from numbers (DEG wrapped to (-180, 180])."""
    return Goal("tip", (float(x), float(y)), None if deg is None else wrap_deg(float(deg)))


def _goal_row(where: str, vals) -> Goal:
    if len(vals) not in (2, 3):
        raise ValueError(f"{where}: a goal is X,Y or X,Y,DEG (mm, mm, deg), got {len(vals)} values")
    nums = []
    for name, v in zip(("X", "Y", "DEG"), vals):
        if isinstance(v, str):
            try:
                v = float(v.strip())
            except ValueError:
                raise ValueError(f"{where}: {name} = {v!r} is not a number") from None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > COORD_MM:
            raise ValueError(f"{where}: {name} = {v!r}: must be a finite number, |{name}| <= {COORD_MM:g}")
        nums.append(float(v))
    return tip_goal(*nums)


def load_track(path: str | Path) -> list[Goal]:
    """The goals of a track file (ValueError, one line): CSV rows X,Y[,DEG] (mm, mm, deg;
    an optional header row x,y[,deg]; # comments and blank lines skipped) or JSON: a list
    of [X, Y(, DEG)] or {"x": , "y": (, "deg": )} (or {"goals": that list}); NaN refused."""
    path = Path(path)
    text = read_text(path, "track")
    goals = []
    if path.suffix.lower() == ".json":
        doc = strict_json(text, path, "track")
        if isinstance(doc, dict):
            if set(doc) - {"goals", "note"} or "goals" not in doc:
                raise ValueError(f"{path}: a track JSON is a list of goals or {{\"goals\": [...]}} (keys: goals, note)")
            doc = doc["goals"]
        if not isinstance(doc, list):
            raise ValueError(f"{path}: a track JSON is a list of goals")
        for i, g in enumerate(doc):
            where = f"{path}: goals[{i}]"
            if isinstance(g, dict):
                if set(g) - {"x", "y", "deg"} or not {"x", "y"} <= set(g):
                    raise ValueError(f"{where}: keys x, y (mm) and optionally deg, got {sorted(g)}")
                g = [g["x"], g["y"]] + ([g["deg"]] if "deg" in g else [])
            if not isinstance(g, list):
                raise ValueError(f"{where}: a goal is [X, Y(, DEG)] or {{x, y(, deg)}}")
            goals.append(_goal_row(where, g))
    else:
        rows = [r for r in csv.reader(io.StringIO(text))]
        for n, row in enumerate(rows, 1):
            row = [c.strip() for c in row]
            if not row or not any(row) or row[0].startswith("#"):
                continue
            if not goals and [c.lower() for c in row] in (["x", "y"], ["x", "y", "deg"]):
                continue
            goals.append(_goal_row(f"{path}:{n}", row))
    if not 1 <= len(goals) <= MAX_GOALS:
        raise ValueError(f"{path}: {len(goals)} goals; a track has 1 to {MAX_GOALS}")
    return goals


def demo_goals(problem: GripperProblem, n: int = 100) -> list[Goal]:
    """``make track``'s path of n goals (mm): across the reachable region and out of it —
    the fingertip of the pressure path P = (-0.25 + 0.5 s, -0.2 + 0.3 s²) for the first
    half (reachable by construction, forward solves), then a straight line from its end
    to (-10, -225) (behind the other finger, below the reach: unreachable), then back to
    the start of the path."""
    h = n // 2
    s = torch.linspace(0.0, 1.0, h, dtype=torch.float64)
    P = torch.stack((-0.25 + 0.5 * s, -0.2 + 0.3 * s * s), -1)
    tips = solve(problem, P).pose.tip_end.tolist()
    out, back = tips[-1], (-10.0, -225.0)
    m = (n - h) // 2
    line = [(out[0] + (back[0] - out[0]) * t, out[1] + (back[1] - out[1]) * t) for t in np.linspace(0, 1, m + 1)[1:]]
    rest = n - h - m
    ret = [(back[0] + (tips[0][0] - back[0]) * t, back[1] + (tips[0][1] - back[1]) * t)
           for t in np.linspace(0, 1, rest + 1)[1:]]
    return [tip_goal(x, y) for x, y in tips + line + ret]


def goal_text(g: Goal) -> str:
    return f"tip:{g.tip[0]:g},{g.tip[1]:g}" + ("" if g.angle_deg is None else f",{g.angle_deg:g}")


def save_track_figure(path: str, result: TrackResult, problem: GripperProblem, label: str,
                      load: str = "") -> None:
    """The closed-loop demonstration: the goals and the verified fingertips (the
    predictor's forward answer) in the plane with the reachable region's kept grid, the
    per-goal time (wall and CPU; ``load``: what the title adds about the machine), the
    position error, and the pressures against goal index (time)."""
    import matplotlib.pyplot as plt

    from predictor.model.plot import save_figure

    a = result.answers
    k = np.arange(len(a))
    goals = np.array([x.goal[:2] for x in a])
    tips = np.array([x.tip for x in a])
    reached = np.array([x.status == "reached" for x in a])
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axes[0, 0]
    g = 61
    p = torch.linspace(-0.3, 0.3, g, dtype=torch.float64)
    ring = torch.cat((torch.stack((p, torch.full_like(p, -0.3)), -1), torch.stack((torch.full_like(p, 0.3), p), -1),
                      torch.stack((p.flip(0), torch.full_like(p, 0.3)), -1),
                      torch.stack((torch.full_like(p, -0.3), p.flip(0)), -1)))
    edge = solve(problem, ring).pose.tip_end.numpy()
    ax.plot(edge[:, 0], edge[:, 1], "-", color="0.75", lw=1, label="tip at the pressure box's edge (forward)")
    ax.axvline(0.0, color="0.5", ls=":", lw=1)
    ax.plot(goals[:, 0], goals[:, 1], "k.", ms=4, label="goals")
    ax.plot(tips[:, 0], tips[:, 1], "-", color="tab:blue", lw=1.2, label="forward tip at the answers")
    ax.plot(tips[~reached, 0], tips[~reached, 1], "o", mfc="none", color="tab:red", ms=5,
            label="closest reachable (unreachable goal)")
    ax.set_aspect("equal")
    ax.set_xlabel("X mm")
    ax.set_ylabel("Y mm")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("fingertip goals and the verified answers")
    ax = axes[0, 1]
    t = np.array([x.time_ms for x in a])
    ax.semilogy(k, t, ".-", lw=0.8, label="wall time")
    ax.axhline(TARGET_ANY_MS, color="tab:red", ls="--", lw=1, label=f"{TARGET_ANY_MS:g} ms (50 Hz)")
    ax.axhline(TARGET_REACHABLE_MS, color="tab:green", ls="--", lw=1, label=f"{TARGET_REACHABLE_MS:g} ms")
    ax.set_xlabel("goal")
    ax.set_ylabel("time per goal, ms (verification included)")
    s = result.summary()
    ax.semilogy(k, [x.cpu_ms for x in a], ".", ms=3, color="0.5", label="CPU time (process, one thread)")
    ax.legend(fontsize=7)
    ax.set_title(f"wall: median {s['median_ms']:.3g} ms, p95 {s['p95_ms']:.3g} ms, {s['rate_hz']:.3g} Hz end to end;\n"
                 f"CPU: median {s['cpu_median_ms']:.3g} ms ({s['cpu_rate_hz']:.3g} Hz)", fontsize=9)
    ax = axes[1, 0]
    err = np.array([x.position_error_mm for x in a])
    ax.semilogy(k, np.maximum(err, 1e-6), ".-", lw=0.8)
    ax.axhline(TIP_TOL_MM, color="tab:red", ls="--", lw=1, label=f"tolerance {TIP_TOL_MM} mm")
    ax.fill_between(k, 1e-6, 1e3, where=~reached, color="tab:red", alpha=0.08, label="unreachable goals")
    ax.set_ylim(1e-6, 1e3)
    ax.set_xlabel("goal")
    ax.set_ylabel("|forward tip - goal|, mm")
    ax.legend(fontsize=7)
    ax.set_title("tip error of the verified forward answer")
    ax = axes[1, 1]
    P = np.array([x.pressures for x in a])
    ax.plot(k, P[:, 0], ".-", lw=0.8, label="P1")
    ax.plot(k, P[:, 1], ".-", lw=0.8, label="P2")
    ax.set_xlabel("goal (one per control step)")
    ax.set_ylabel("pressure, MPa")
    ax.legend(fontsize=7)
    ax.set_title("pressures against time")
    import textwrap

    fig.suptitle("\n".join(textwrap.wrap(label + load, 150)), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, 110)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.inverse --track FILE")
