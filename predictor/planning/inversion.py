"""Inverse pressures: which (P1, P2) hold an object, or put the fingertip where asked (the
library; the command line is predictor.cli.inverse).

Goals (right finger; lengths mm in the global frame of docs/gripper.md, pressures MPa):

Every goal is a least-squares one, f = |e|² with a goal residual e:

- ``hold``: the grasp with the largest friction margin, i.e. the least friction use
  u = |λ|/mu (statics.contact_loads; it holds when u <= 1): e = (u); with
  ``--min-normal N0`` e gains 10·max(0, 1 - N/N0); with ``--least-pressure`` instead
  e = (P1/0.3, P2/0.3, √1000·max(0, u - (1 - HOLD_MARGIN))) (+ the normal term): the
  least pressure that holds with a friction margin of HOLD_MARGIN.
- ``tip:X,Y[,DEG]``: the fingertip at (X, Y) mm, and its tip angle at DEG degrees (the
  ``tip_angle_deg`` of ``predictor.cli.gesture --json``, the direction of the rigid tip):
  e = (x_tip - X, y_tip - Y[, l_tip·wrap(phi_2 - DEG)]) mm, the angles' difference wrapped
  to (-180, 180] deg (a goal farther than FAR_GOAL_MM is searched for that far in its
  direction, ``search_tip``). The answer reports the position error (tip_error_mm, mm)
  and the wrapped angle error (angle_error_deg, deg) apart. With DEG the goal has three
  conditions for two pressures: it is met only where the target lies on the reachable
  surface (within TIP_TOL_MM), else it is answered ``infeasible`` with its least-squares
  closest gesture.

Gradients go through the equilibrium itself. At a converged gesture the scaled residual
r(tau, P) = 0 (predictor.solvers.solve, 6 equilibrium rows; the range penalties are inactive),
so by the implicit function theorem

    d tau/dP = -(dr/dtau)⁻¹ dr/dP                                    (6 x 2)
    de/dP    = ∂e/∂P + ∂e/∂tau · d tau/dP                              (k x 2)
    df/dP    = 2 eᵀ de/dP                                            (2)
with dr/dtau and dr/dP from the solver's Jacobian (predictor.solvers.jacobians.jacobian_fn: exact with an
object, central differences to ~1e-10 relative without) at the converged point, and
∂e/∂(tau, P) the same way (``_goal_derivatives_rows``): no unrolled iterations.
Moving P moves the equilibrium by continuation (solve's tangent predictor + LM, cut back
when a step fails), which keeps the grasp on its branch.

Search: multi-start from the best points of a coarse atlas (predictor.planning.atlas; the
object's committed atlas with ``--atlas``, else a COARSE x COARSE grid solved on the
spot and kept for the process's later questions of the same problem, box and options,
``coarse_atlas``: it does not depend on the goal), the pressure box as bounds, a
projected Gauss-Newton on the goal residual e (Levenberg-damped, steps capped at 0.1
MPa, 0.05 with an object, backtracking); the starts stop early once one meets the goal
exactly (``_exact``). The starts' searches run in lockstep (``gauss_newton_all``): each
round's continuation steps of all starts are one batched ramp step and their gradients
one batched pass, and each start takes the steps it takes alone (one residual evaluation
costs about the same for one row as for three: Python dispatch), as if the starts were
searched one after the other up to the first exact one (the same answers to rounding;
where the steps press on X = 0 the stiff plane amplifies the rounding to ~4e-7 MPa). Candidates are
verified, best first, by a forward solve along the ramp from the approach gesture
(predictor.solvers.solve, the history of ``predictor.cli.gesture``) and refused if that
solve disagrees (state, or tip farther than VERIFY_TOL_MM); the
first robust one is the answer. A tip goal that no candidate can meet verifies them all
in one batched solve (``_verifications``). Robustness: the 8 neighbours at ±REGULATOR
MPa (the regulators' resolution) are solved by continuation from the verified gesture
(the pressure error of a regulator acts on the settled grasp) and the answer is robust
when all 9 points keep the goal's state; robust candidates are preferred.

Answers: ``feasible`` (exit 0, goal_met true), or ``infeasible`` (exit 1, goal_met
false) with the closest achievable value and a reason naming the limit (the nearest tip
and its error; the most normal force a hold reaches under --min-normal; the best
friction use found); grasp_state is the state of the gesture at the answer's pressures,
not the verdict. Exit 2 is bad input (bad numbers, goal, box, object spec, an object the
model cannot represent or intersecting the fingers where it is brought in, an object
nothing touches anywhere in the box, an --atlas of another object, joint or settings,
unwritable outputs), one line on stderr. The API applies the same checks.

Data flow: InverseProblem (GripperProblem + Goal + box) -> ``inverse_pressures`` ->
InverseResult (status, pressures, achieved values, verification, robustness, timings).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from contract import cli
from contract.spec import INPUT_BOX
from predictor.planning.atlas import HOLDS, NOT_CONVERGED, STATES, Atlas, classify, grasp_atlas
from predictor.solvers.problem import FULL_BOX, MIN_NORMAL, check_box
from predictor.solvers.progress import Heartbeat
from predictor.solvers.graphs import graph_cache, touch, traced
from predictor.solvers.jacobians import jacobian_fn
from predictor.solvers.lm import SHORTENINGS, levenberg_marquardt
from predictor.solvers.options import SolverOptions
from predictor.solvers.ramp import advance, attempts, contact_newton, homotopy, in_turn
from predictor.solvers.result import GestureResult
from predictor.solvers.solve import solve
from predictor.model.statics import GripperProblem, apart, box_scale, meets

REGULATOR = 0.01  # MPa: the paper's pressure regulators' resolution
HOLD_MARGIN = 0.2  # friction margin 1 - u required by --least-pressure
TIP_TOL_MM = 0.1  # a tip goal is reached when |e| <= this (mm)
VERIFY_TOL_MM = 0.05  # the ramp solve must put the tip within this of the continuation's
LEAST_PRESSURE_SLACK = 0.01
COARSE = 5  # coarse start grid without an atlas
N_STARTS = 3
START_SEPARATION = 0.05  # MPa (max norm) between two starts
#: Issue 16's speed targets (ms per single query, one thread).
TARGET_TIP_MS, TARGET_HOLD_MS = 100.0, 1000.0


@dataclass(frozen=True)
class Goal:
    """kind: hold | tip. tip: (X, Y) mm; angle_deg: tip angle (deg) or None; min_normal:
    N (hold); least_pressure: the least-pressure hold instead of the largest margin."""

    kind: str = "hold"
    tip: tuple[float, float] | None = None
    angle_deg: float | None = None
    min_normal: float = 0.0
    least_pressure: bool = False

    @property
    def terms(self) -> int:
        """k, the length of the goal residual e (``_goal_terms``)."""
        if self.kind == "tip":
            return 2 + (self.angle_deg is not None)
        return (3 if self.least_pressure else 1) + (self.min_normal > 0)


def wrap_deg(angle: float) -> float:
    """An angle (deg) wrapped to (-180, 180]: 631.63 -> -88.37."""
    return 180.0 - (180.0 - angle) % 360.0


#: mm from the origin: a tip goal farther than this is searched for at this distance in
#: its direction (the closest reachable tip of a goal 1e308 mm away is that of one 1e4 mm
#: away, to ~(reach)²/1e4 mm; its squared error would overflow); its errors are the real goal's.
FAR_GOAL_MM = 1e4


def search_tip(goal: "Goal") -> tuple[float, float]:
    """The (X, Y) mm the search aims at: the goal's, pulled in to FAR_GOAL_MM when farther."""
    x, y = goal.tip
    r = math.hypot(x, y)
    return (x, y) if r <= FAR_GOAL_MM else (x * (FAR_GOAL_MM / r), y * (FAR_GOAL_MM / r))


def tip_errors(tip, angle_deg: float, goal: "Goal") -> tuple[float, float | None]:
    """(position error mm, angle error deg or None) of a fingertip (X, Y) mm at tip angle
    ``angle_deg`` against a tip goal: the distance to (X, Y), and achieved minus asked
    angle wrapped to (-180, 180] (None when the goal has no angle). They are reported
    apart; a goal is met when hypot(position, tip_length·angle in rad) <= TIP_TOL_MM."""
    pos = math.hypot(tip[0] - goal.tip[0], tip[1] - goal.tip[1])
    return pos, None if goal.angle_deg is None else wrap_deg(angle_deg - goal.angle_deg)


def tip_met(ip: "InverseProblem", pos_mm: float, angle_err_deg: float | None) -> bool:
    """The tip goal's test: hypot(position error, tip_length × wrapped angle error) <= TIP_TOL_MM."""
    ang = 0.0 if angle_err_deg is None else ip.problem.params.tip_length * math.radians(angle_err_deg)
    return math.hypot(pos_mm, ang) <= TIP_TOL_MM


def parse_goal(text: str) -> Goal:
    """``hold`` or ``tip:X,Y[,DEG]`` (mm, degrees; DEG wrapped to (-180, 180], the range
    of ``tip_angle_deg``); ValueError with a one-line reason."""
    kind, _, rest = text.strip().partition(":")
    if kind == "hold" and not rest:
        return Goal("hold")
    if kind == "tip":
        parts = rest.split(",")
        if len(parts) in (2, 3):
            vals = [cli.number(unit="mm or deg")(p.strip()) for p in parts]
            return Goal("tip", (vals[0], vals[1]), wrap_deg(vals[2]) if len(parts) == 3 else None)
    raise ValueError(f"goal {text!r}: use hold or tip:X,Y[,DEG] (mm, degrees)")


@dataclass(frozen=True)
class InverseProblem:
    """The question: problem (joint, object, gravity, approach), goal, box (P1lo, P1hi,
    P2lo, P2hi) MPa, solver options of the forward solves."""

    problem: GripperProblem
    goal: Goal
    box: tuple[float, float, float, float] = FULL_BOX
    options: SolverOptions = SolverOptions()

    def __post_init__(self):
        object.__setattr__(self, "box", check_box(self.box))
        MIN_NORMAL.value("min_normal", self.goal.min_normal)
        if self.goal.kind == "hold" and self.problem.obstacle is None:
            raise ValueError("--goal hold needs an --object")
        if self.goal.kind == "tip" and (self.goal.min_normal or self.goal.least_pressure):
            raise ValueError("min_normal and least_pressure (--min-normal, --least-pressure) apply to the hold "
                             "goal only")
        if self.problem.n_joints != 2:
            raise ValueError(f"the inverse search spans (P1, P2): finger {self.problem.params.finger.name!r} has "
                             f"{self.problem.n_joints} joints")


@dataclass(frozen=True)
class InverseResult:
    """status: feasible | infeasible (goal_met: the same as a bool); pressures (P1, P2) MPa
    of the answer (or of the closest achievable value when infeasible); grasp_state (atlas
    STATES) of the gesture there, which is not the goal's verdict; tip (X, Y) mm and
    tip_angle_deg; tip_error_mm (tip goals): the position error, mm; angle_error_deg (tip
    goals with an angle): achieved minus asked, wrapped to (-180, 180]; normal_N, friction_use (|f|/(mu N)); objective
    f; verified: the ramp solve agreed; robust: the goal's state holds on the ±REGULATOR
    stencil; stencil_states (9, centre first); candidates: starts tried; time_ms: whole
    query; reason: one line; joint, mu, object_weight_N: what was solved (statics);
    gesture: the verifying GestureResult."""

    status: str
    goal_met: bool
    pressures: tuple[float, float]
    grasp_state: str
    tip: tuple[float, float]
    tip_angle_deg: float
    tip_error_mm: float | None
    normal_N: float
    friction_use: float | None
    objective: float
    verified: bool
    robust: bool
    stencil_states: tuple[str, ...]
    candidates: int
    time_ms: float
    reason: str
    joint: str = ""
    mu: float | None = None
    object_weight_N: float | None = None
    angle_error_deg: float | None = None
    gesture: GestureResult | None = None

    @property
    def state(self) -> str:
        """The grasp state at the answer's pressures (``grasp_state``)."""
        return self.grasp_state

    def summary(self) -> dict:
        """Plain JSON types (the gesture omitted)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "gesture"}


class Branch:
    """An equilibrium (P (1, 2), x (1, 6), Jacobians) moved by continuation."""

    def __init__(self, ip: InverseProblem, p: torch.Tensor, x: torch.Tensor):
        prob, opts = ip.problem, ip.options
        self.problem, self.opts = prob, opts
        # The search iterates need only stay on the branch (solve's intermediate ramp steps
        # use the same 100x looser tolerance); refine() converges the answer fully.
        self.loose = dataclasses.replace(opts, tol_force=100 * opts.tol_force, tol_moment=100 * opts.tol_moment)
        self.tol = self.loose
        # Each continuation step tries the solver's Jacobians in turn (ramp.attempts: with an
        # object, differences of the recorded residual, then the exact one for a step they fail)
        kinds = attempts(prob, opts) if prob.obstacle is not None else (opts.jacobian,)
        self.run = in_turn([self._step_solver(kind) for kind in kinds])
        self.p, self.x = p.reshape(1, 2).double(), x.reshape(1, 6).double()
        J, _, Jp = jacobian_fn(prob, kind=kinds[0])(self.x, self.p)
        self.jac = (J[:, :6], Jp)

    def _step_solver(self, kind: str):
        """run(x, p, p_prev=None, jac=None) of one continuation step by the LM with Jacobian
        ``kind`` (predictor.solvers.jacobians.jacobian_fn); where the fingers meet at X = 0, a step
        pressed on the plane goes through the contact-constrained Newton, then softer
        planes, when the stiff one stalls (as the solver's ramp does); with an object, the
        solver's tunnelling guard."""
        prob, opts = self.problem, self.opts
        cap, shorten = (None, 0) if prob.obstacle is None else (opts.contact_max_step, SHORTENINGS)

        def lm(problem, hand_over=None):
            jac_fn = jacobian_fn(problem, kind=kind)

            def step(x, p, p_prev=None, jac=None):
                return levenberg_marquardt(jac_fn, x, p, self.tol, cap, p_prev, jac, hand_over, shorten)

            return step

        def kkt(x, p, p_prev=None, jac=None):   # the contact-constrained Newton, at the current tolerance
            return contact_newton(prob, self.tol)(x, p)

        solver = lm(prob) if not meets(prob) else homotopy(prob, lm, kkt)

        def run(x, p, p_prev=None, jac=None):
            x, ok, its, jac = solver(x, p, p_prev, jac)
            if prob.obstacle is not None:
                ok = ok & (touch(prob, x, p)[1] <= opts.max_penetration)
            return x, ok, its, jac

        return run

    def move(self, p: torch.Tensor) -> bool:
        """Continue the equilibrium to p (1, 2); False (and unchanged) if it fails."""
        p = p.reshape(1, 2).double()
        if torch.equal(p, self.p):
            return True
        x, ok, _, jac = advance(self.run, self.x, self.p, p, self.opts.cutbacks, self.jac)
        if not bool(ok.all()):
            return False
        self.p, self.x, self.jac = p, x, jac
        return True

    def save(self):
        return self.p, self.x, self.jac

    def restore(self, state) -> None:
        self.p, self.x, self.jac = state

    def refine(self) -> bool:
        """Converge the current point to the full solver tolerance."""
        self.tol = self.opts
        x, ok, _, jac = self.run(self.x, self.p)
        if bool(ok.all()):
            self.x, self.jac = x, jac
        return bool(ok.all())

    def neighbours(self, ps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Continue to each of ps (n, 2) from this point, batched: (x (n, 6), converged (n,))."""
        n = ps.shape[0]
        x, ok, _, _ = advance(self.run, self.x.expand(n, 6), self.p.expand(n, 2), ps.double(),
                               self.opts.cutbacks, tuple(a.expand(n, *a.shape[1:]) for a in self.jac))
        return x, ok


def _goal_terms(ip: InverseProblem, p: torch.Tensor, x: torch.Tensor):
    """(f (B,), goal residual e (B, k) with f = |e|², statics) at p (B, 2), x (B, 6);
    differentiable in both (module docstring: every goal is a least-squares one)."""
    prob, goal = ip.problem, ip.goal
    st = prob.residual(p, x.reshape(-1, 2, 3))
    if goal.kind == "tip":
        tip, (gx, gy) = st.pose.tip_end, search_tip(goal)
        e = [tip[:, 0] - gx, tip[:, 1] - gy]
        if goal.angle_deg is not None:   # the angle's difference wrapped to (-pi, pi]
            d = st.pose.tip_angle - math.radians(goal.angle_deg)
            e.append(prob.params.tip_length * torch.atan2(torch.sin(d), torch.cos(d)))
    else:
        c = st.contact
        use = c.ratio.abs() / prob.contact.mu
        if goal.least_pressure:
            e = [p[:, 0] / 0.3, p[:, 1] / 0.3, math.sqrt(1000.0) * (use - (1.0 - HOLD_MARGIN)).clamp_min(0.0)]
        else:
            e = [use]
        if goal.min_normal > 0:
            e.append(10.0 * (1.0 - c.normal / goal.min_normal).clamp_min(0.0))
    e = torch.stack(e, -1)
    return (e * e).sum(-1), e, st


def gradient(ip: InverseProblem, branch: Branch):
    """At the branch's converged point: (f, df/dP (2,), e (k,), de/dP (k, 2)) by the
    implicit function theorem (module docstring), df/dP = 2 eᵀ de/dP, with ∂e/∂(x, P)
    (``_goal_derivatives_rows``)."""
    return gradients(ip, [branch])[0]


def gradients(ip: InverseProblem, branches: list) -> list:
    """``gradient`` of several branches, their ∂e/∂(x, P) in one batched pass (a row of
    the batch is the row's own evaluation)."""
    if not branches:
        return []
    out = []
    x = torch.cat([b.x for b in branches])
    p = torch.cat([b.p for b in branches])
    for b, (e, ex, ep) in zip(branches, _goal_derivatives_rows(ip, x, p)):
        J, Jp = b.jac[0][0], b.jac[1][0]  # (6, 6), (6, 2)
        de = ep - ex @ torch.linalg.solve(J, Jp)  # d tau/dP = -J⁻¹ dr/dP
        out.append((float(e @ e), 2.0 * de.T @ e, e, de))
    return out


def _goal_derivatives_rows(ip: InverseProblem, x: torch.Tensor, p: torch.Tensor) -> list:
    """(e (k,), ∂e/∂x (k, 6), ∂e/∂P (k, 2)) of each row of x (B, 6), p (B, 2) in one batched
    pass. As the solver's Jacobian (predictor.solvers.jacobians.jacobian_fn): without an
    object, central differences of the traced goal residual (the pose is smooth; steps 1e-6
    of (1 N, 1 N, 100 N·mm) and of 0.3 MPa; a row of the batch is the row's own evaluation,
    bit for bit); with one, exact, by one reverse pass over k copies of every row (copy i
    feeds goal term i only: the contact law has kinks; the rows' own to ~1e-13 relative,
    the batched residual's rounding)."""
    B = len(x)
    if ip.problem.obstacle is not None:   # one reverse pass over k copies of each row
        k = ip.goal.terms
        with torch.enable_grad():
            xr = x.repeat_interleave(k, 0).requires_grad_(True)
            pr = p.repeat_interleave(k, 0).requires_grad_(True)
            e = _goal_terms(ip, pr, xr)[1].reshape(B, k, k)      # copy i of a row feeds its row i
            ex, ep = torch.autograd.grad(e.diagonal(dim1=1, dim2=2).sum(), (xr, pr), allow_unused=True)
        ex = torch.zeros(B * k, 6, dtype=torch.float64) if ex is None else ex
        ep = torch.zeros(B * k, 2, dtype=torch.float64) if ep is None else ep
        ex, ep, e = ex.reshape(B, k, 6), ep.reshape(B, k, 2), e.detach()
        return [(e[b, 0].clone(), ex[b].clone(), ep[b].clone()) for b in range(B)]
    h = 1e-6 * torch.cat((box_scale(6)[1], torch.full((2,), INPUT_BOX[0], dtype=torch.float64)))
    steps = torch.diag(h)
    y = torch.cat((x, p), 1)                                                           # (B, 8)
    Y = torch.cat((y[:, None], y[:, None] + steps, y[:, None] - steps), 1).reshape(-1, 8)   # (17 B, 8)
    with torch.inference_mode():
        fn = traced_tip_fn(ip.problem) if ip.goal.kind == "tip" else _traced_goal_fn(ip)
        E = fn(Y[:, :6].contiguous(), Y[:, 6:].contiguous())
    E = E.reshape(B, 17, -1).clone()
    if ip.goal.kind == "tip":
        return [_tip_terms(ip, E[b], h) for b in range(B)]
    out = []
    for b in range(B):
        d = ((E[b, 1:9] - E[b, 9:]) / (2 * h[:, None])).T.clone()                    # (k, 8)
        out.append((E[b, 0].clone(), d[:, :6], d[:, 6:]))
    return out


def _tip_terms(ip: InverseProblem, T: torch.Tensor, h: torch.Tensor):
    """(e (k,), ∂e/∂x (k, 6), ∂e/∂P (k, 2)) of a tip goal from the fingertip rows T (17, 3)
    at a point and its central differences of steps h (8,)."""
    dT = (T[1:9] - T[9:]) / (2 * h[:, None])                                   # (8, 3)
    (gx, gy), l_tip = search_tip(ip.goal), ip.problem.params.tip_length
    e = [T[0, 0] - gx, T[0, 1] - gy]
    cols = [dT[:, 0], dT[:, 1]]
    if ip.goal.angle_deg is not None:
        a = T[0, 2] - math.radians(ip.goal.angle_deg)
        e.append(l_tip * torch.atan2(torch.sin(a), torch.cos(a)))
        cols.append(l_tip * dT[:, 2])
    d = torch.stack(cols)                                                      # (k, 8)
    return torch.stack(e), d[:, :6].clone(), d[:, 6:].clone()


@graph_cache
def traced_tip_fn(problem: GripperProblem):
    """(x (B, 6), p (B, 2)) -> (B, 3): the fingertip X, Y mm and its angle rad (the pose,
    which the plane X = 0 does not change), recorded once per problem: it does not depend
    on the goal, so the tip goals of one gripper (a track's) share it."""
    prob = apart(problem)

    def tip(x, p):
        pose = prob.residual(p, x.reshape(-1, 2, 3)).pose
        return torch.cat((pose.tip_end, pose.tip_angle[:, None]), -1)

    return traced(tip, 6, 2)


@graph_cache
def _traced_goal_fn(ip: InverseProblem):
    """e(x (B, 6), p (B, 2)) -> (B, k), recorded by predictor.solvers.graphs.traced."""
    return traced(lambda x, p: _goal_terms(ip, p, x)[1], 6, 2)


def clip_to_box(ip: InverseProblem, p: np.ndarray) -> np.ndarray:
    return np.clip(p, [ip.box[0], ip.box[2]], [ip.box[1], ip.box[3]])


MAX_STEP = 0.1  # MPa: Gauss-Newton step cap (the tip map folds where d tip/dP is singular)
MAX_STEP_CONTACT = 0.05  # MPa: with an object, continuation steps stay short
STALL = 1e-3  # stop when a Gauss-Newton step gains less than this fraction of f


def gauss_newton(ip: InverseProblem, branch: Branch) -> None:
    """Projected Gauss-Newton (Levenberg-damped, capped, backtracking) on f = |e|² from the
    branch, within the box: a component at a bound whose step points out is held there
    and the other one moves alone (sliding along the bound). The steps of ``_gn_steps``,
    each continuation and gradient of one branch in turn (``gauss_newton_all`` runs
    several branches' steps in lockstep)."""
    gauss_newton_all(ip, [branch])


def _gn_steps(ip: InverseProblem, branch: Branch):
    """The Gauss-Newton of one branch as a generator: it yields the trial pressures p (2,)
    (numpy) it wants the branch continued to, and is sent the goal's (f, e, de/dP) there,
    or None where the continuation failed (the branch then unchanged); on a success the
    branch has moved there (``Branch.restore`` takes it back). It yields None first, for
    the gradient at the branch's own point; it returns its last f."""
    f, e, de = yield None
    damp = 1e-9
    cap = MAX_STEP if ip.problem.obstacle is None else MAX_STEP_CONTACT
    # with contact the friction use is rough in P (USE_RESOLUTION): a few steps gain all there is
    max_iter = 12 if ip.problem.obstacle is None else 6
    lo, hi = np.array([ip.box[0], ip.box[2]]), np.array([ip.box[1], ip.box[3]])
    for _ in range(max_iter):
        if f <= _exact(ip):
            return f
        A = de.T @ de + damp * torch.eye(2, dtype=torch.float64)
        step = -torch.linalg.solve(A, de.T @ e).numpy()
        p0, here = branch.p[0].numpy().copy(), branch.save()
        stuck = ((p0 <= lo) & (step < 0)) | ((p0 >= hi) & (step > 0))
        if stuck.any() and not stuck.all():
            k = int(np.flatnonzero(~stuck)[0])
            step = np.zeros(2)
            step[k] = -float(de[:, k] @ e) / float(de[:, k] @ de[:, k] + damp)
        step *= min(1.0, cap / max(np.abs(step).max(), 1e-300))
        for _ in range(6):  # backtrack: the bounds and the contact branch may cut the step
            p_try = clip_to_box(ip, p0 + step)
            if np.abs(p_try - p0).max() <= 1e-9:
                return f
            got = yield p_try
            if got is not None:
                f_try, e_try, de_try = got
                if f_try < f:
                    stalled = f_try > (1.0 - STALL) * f  # a minimum with e != 0 (a bound, a fold)
                    f, e, de = f_try, e_try, de_try
                    break
                branch.restore(here)
            step *= 0.5
        else:
            return f
        if stalled:
            return f


def gauss_newton_all(ip: InverseProblem, branches: list, first_exact: str | None = None) -> int:
    """``gauss_newton`` of each branch (the starts of one question), in lockstep: every
    round continues all the branches that ask for a trial point in one batched ramp step
    (predictor.solvers.ramp.advance: each row's own tangent predictor, LM, homotopy and
    cut-backs; a row of a batch is the row's own solve) and takes their gradients in one
    batched pass (``gradients``). Each branch takes the steps it takes alone
    (``_gn_steps``; up to rounding, which the plane's stiff penalty amplifies to ~4e-7 MPa
    where the steps press on X = 0: tests/test_planning.py): one evaluation of the
    residual costs about the same for 1 row as for several (Python dispatch), so
    N_STARTS searches cost about the rounds of the longest.

    first_exact: the starts as if searched one after the other, until the first, in turn,
    that meets the goal exactly (``_exact``): the later ones stop there. "refined": each
    branch is refined (``Branch.refine``) as its search ends and judged then; "searched":
    judged by its search's own last f. Returns how many leading branches count (all, or
    up to that one)."""
    gens = [_gn_steps(ip, b) for b in branches]
    asks = {i: next(g) for i, g in enumerate(gens)}
    count = len(branches)
    run, opts = (branches[0].run, branches[0].opts) if branches else (None, None)
    while asks:
        got = {}
        moving = [i for i, a in asks.items() if a is not None]
        if moving:
            P = torch.cat([branches[i].p for i in moving])
            X = torch.cat([branches[i].x for i in moving])
            jac = tuple(torch.cat([branches[i].jac[k] for i in moving]) for k in range(2))
            target = torch.from_numpy(np.stack([asks[i] for i in moving])).double()
            x, ok, _, jac_new = advance(run, X, P, target, opts.cutbacks, jac)
            for r, i in enumerate(moving):
                if bool(ok[r]):
                    b = branches[i]
                    b.p, b.x = target[r:r + 1].clone(), x[r:r + 1].clone()
                    b.jac = (jac_new[0][r:r + 1].clone(), jac_new[1][r:r + 1].clone())
                else:
                    got[i] = None
        need = [i for i in asks if i not in got]
        for i, grad in zip(need, gradients(ip, [branches[i] for i in need])):
            got[i] = (grad[0], grad[2], grad[3])
        nxt = {}
        for i in sorted(asks):
            if i >= count:
                continue
            try:
                nxt[i] = gens[i].send(got[i])
            except StopIteration as done:
                if first_exact == "refined":   # as the starts in turn: refined, and the first exact one ends them
                    branches[i].refine()
                    if gradient(ip, branches[i])[0] <= _exact(ip):
                        count = i + 1
                elif first_exact == "searched" and done.value <= _exact(ip):
                    count = i + 1
        asks = {i: a for i, a in nxt.items() if i < count}
    return count


USE_RESOLUTION = 0.02  # friction use below which a hold cannot be bettered meaningfully


def _exact(ip: InverseProblem) -> float:
    """f below which an answer cannot be bettered (stop the search): a tip within
    0.1 TIP_TOL_MM; a friction use below USE_RESOLUTION (at that level u is rough in P,
    by ~0.01, as the tip's 65 contact sample points enter and leave contact: measured on
    the circle along P2 = 0.3 MPa); never for --least-pressure."""
    if ip.goal.kind == "tip":
        return (0.1 * TIP_TOL_MM) ** 2
    return -1.0 if ip.goal.least_pressure else USE_RESOLUTION ** 2


def _result_at(ip: InverseProblem, res: GestureResult, i: int) -> dict:
    """Achieved values of row i of a solve result."""
    state, use = classify(res, ip.problem.contact.mu)
    tip = res.pose.tip_end[i].tolist()
    out = {"pressures": tuple(res.pressures[i].tolist()), "state": STATES[state[i]], "tip": tuple(tip),
           "tip_angle_deg": math.degrees(float(res.pose.tip_angle[i])), "normal_N": float(res.normal_force_N[i]),
           "friction_use": None if math.isnan(use[i]) else float(use[i]), "tip_error_mm": None,
           "angle_error_deg": None}
    if ip.goal.kind == "tip":
        out["tip_error_mm"], out["angle_error_deg"] = tip_errors(tip, out["tip_angle_deg"], ip.goal)
    return out


def _meets(ip: InverseProblem, v: dict) -> bool:
    """Does an achieved value meet the goal?"""
    if ip.goal.kind == "tip":
        ok = v["tip_error_mm"] is not None and tip_met(ip, v["tip_error_mm"], v["angle_error_deg"])
        return ok and (ip.problem.obstacle is None or v["state"] != "not_converged")
    ok = v["state"] == "holds" and v["normal_N"] >= ip.goal.min_normal
    # least pressure: the margin is a penalty term, met to within LEAST_PRESSURE_SLACK
    return ok and (not ip.goal.least_pressure or v["friction_use"] <= 1.0 - HOLD_MARGIN + LEAST_PRESSURE_SLACK)


def _starts(ip: InverseProblem, atlas: Atlas) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """The N_STARTS best converged grid points, START_SEPARATION apart, of the atlas for
    the goal: (pressures (2,), tau (6,)) each."""
    res = atlas.result
    ok = res.converged
    if ip.goal.kind == "hold":
        state, use = atlas.state.ravel(), atlas.friction_use.ravel()
        score = np.where(state == HOLDS, use, np.where(np.isnan(use), np.inf, 1.0 + use))
        if ip.goal.least_pressure:
            lightest = np.abs(res.pressures.numpy()).sum(-1) + (use > 1 - HOLD_MARGIN)
            score = np.where(state == HOLDS, lightest, score + 10)
        if ip.goal.min_normal > 0:
            score = score + 10.0 * (atlas.normal_N.ravel() < ip.goal.min_normal)
        score = torch.from_numpy(score)
    else:
        e = res.pose.tip_end - torch.tensor(search_tip(ip.goal), dtype=torch.float64)
        score = e.pow(2).sum(-1)
        if ip.goal.angle_deg is not None:
            d = res.pose.tip_angle - math.radians(ip.goal.angle_deg)
            score = score + (ip.problem.params.tip_length * torch.atan2(torch.sin(d), torch.cos(d))) ** 2
    score = torch.where(ok, score, torch.inf)
    chosen = []
    for i in torch.argsort(score).tolist():
        if not torch.isfinite(score[i]) or len(chosen) == N_STARTS:
            break
        # distinct starts: neighbours of a chosen grid point lead to the same local optimum
        if all(float((res.pressures[i] - res.pressures[j]).abs().max()) >= START_SEPARATION for j in chosen):
            chosen.append(i)
    return [(res.pressures[i], res.tau[i].reshape(6)) for i in chosen]


def _verified(ip: InverseProblem, ver: GestureResult, branch: Branch, f: float) -> dict:
    """A candidate (the continuation's ``branch``, objective f) against its forward ramp
    solve ``ver`` (one row): the achieved values, verified (converged, tip within
    VERIFY_TOL_MM, same contact and hold state) and meets (verified and the goal met)."""
    v = _result_at(ip, ver, 0)
    with torch.no_grad():
        st = ip.problem.residual(branch.p, branch.x.reshape(1, 2, 3))
    c = st.contact
    agree = bool(ver.converged[0]) and float((ver.pose.tip_end[0] - st.pose.tip_end[0]).norm()) <= VERIFY_TOL_MM
    if ip.problem.obstacle is not None:
        agree = agree and (float(c.normal[0]) > 0) == (v["state"] != "no_contact")
        agree = agree and (float(c.normal[0]) > 0 and not bool(c.slip[0])) == (v["state"] == "holds")
    return dict(v, objective=f, verified=agree, meets=agree and _meets(ip, v), index=0, gesture=ver)


def _stencil(ip: InverseProblem, ver: GestureResult, cand: dict) -> dict:
    """Robustness of a candidate: its 8 ±REGULATOR neighbours (clipped to the box) by
    continuation from the verified ramp gesture (or just its verification state when the
    ramp solve failed). Returns robust, stencil_states (centre first)."""
    if not cand["verified"]:
        return {"robust": False, "stencil_states": (cand["state"],)}
    i = cand["index"]
    branch = Branch(ip, ver.pressures[i], ver.tau[i])
    d = REGULATOR * torch.tensor([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)],
                                 dtype=torch.float64)
    ps = torch.from_numpy(clip_to_box(ip, (branch.p + d).numpy()))
    xs, ok = branch.neighbours(ps)
    with torch.no_grad():
        st = ip.problem.residual(ps, xs.reshape(-1, 2, 3))
    c, mu = st.contact, ip.problem.contact.mu
    slips = (c.ratio.abs() > mu) | c.slip
    states = ["not_converged" if not o else "no_contact" if n <= 0 else "slips" if sl else "holds"
              for o, n, sl in zip(ok.tolist(), c.normal.tolist(), slips.tolist())]
    # hold goals must keep holding; tip goals must keep their contact state
    want = "holds" if ip.goal.kind == "hold" else cand["state"]
    return {"robust": cand["meets"] and all(s == want for s in states),
            "stencil_states": (cand["state"],) + tuple(states)}


@functools.lru_cache(maxsize=8)
def coarse_atlas(problem: GripperProblem, box: tuple[float, float, float, float],
                 options: SolverOptions) -> Atlas:
    """The COARSE x COARSE start grid (predictor.planning.atlas.grasp_atlas) of ``problem`` over
    box (P1lo, P1hi, P2lo, P2hi) MPa, solved once per process for each problem, box and
    options (the grid does not depend on the goal): later questions of a planner (tip
    targets of one gripper, cold holds of one object) start at once.
    ``coarse_atlas.cache_clear()`` forgets them (make inverse times cold queries so).
    Without an object the grid is the reference path, every point's own ``solve`` in one
    batched call (``path="ramp"``: the plane's contact-constrained Newton at the target),
    which has the continuation's equilibria (tests/test_planning.py: to 1e-12 N, N·mm on
    the production surrogate) at half its time (131 against 284 ms CPU, measured); with
    one, the continuation (the grasp's history)."""
    return grasp_atlas(problem, COARSE, box, options, "ramp" if problem.obstacle is None else "sweep")


def _verifications(ip: InverseProblem, ordered: list):
    """(candidate, its verifying ramp solve (one row)) of the candidates ``ordered`` ((f,
    P (2,), branch), best first), lazily: one at a time while the best may meet the goal
    (a robust one stops the verification), or every one in one batched solve when none
    can: a tip goal whose best continuation lies farther than TIP_TOL_MM + VERIFY_TOL_MM
    from the target (every candidate is then verified; a row of a batched solve is the
    row's own solve)."""
    batch = ip.goal.kind == "tip" and bool(ordered) and math.sqrt(ordered[0][0]) > TIP_TOL_MM + VERIFY_TOL_MM
    if batch:
        vers = solve(ip.problem, torch.stack([p for _, p, _ in ordered]), ip.options)
        yield from ((c, vers.rows([i])) for i, c in enumerate(ordered))
        return
    for c in ordered:
        yield c, solve(ip.problem, c[1][None], ip.options)


def inverse_pressures(ip: InverseProblem, atlas: Atlas | None = None) -> InverseResult:
    """Answer ``ip`` (module docstring); ``atlas``: the object's atlas for the starts (its
    problem must be ip.problem), else a coarse one is solved. Returns an InverseResult."""
    t0 = time.perf_counter()
    if atlas is not None:
        _atlas_matches(atlas, ip.problem)
    atlas = atlas if atlas is not None else coarse_atlas(ip.problem, ip.box, ip.options)
    if ip.goal.kind == "hold":
        _check_touch(atlas)
    starts = _starts(ip, atlas)
    cands = []
    Heartbeat("inverse")(f"{len(starts)} starts")
    # The starts' searches in lockstep (``gauss_newton_all``: each branch takes the steps it
    # takes alone); the candidates are those of the starts in turn up to the first that
    # meets the goal exactly (up to verification: later starts cannot beat it).
    branches = [Branch(ip, p, x) for p, x in starts]
    branches = branches[:gauss_newton_all(ip, branches, "refined")]   # each refined
    for branch, (f, *_) in zip(branches, gradients(ip, branches)):
        cands.append((branch.p[0].clone(), branch))
        if f <= _exact(ip):
            break
    if not cands:
        raise ValueError("no converged gesture in the atlas of the box: nothing to search from")
    # Verify the candidates best first, each by a forward solve along the ramp, and stop at
    # the first that meets the goal robustly (±REGULATOR stencil): robust answers are
    # preferred, then goal-meeting ones, then the least objective.
    scored = []
    for p, branch in cands:
        with torch.no_grad():
            scored.append((float(_goal_terms(ip, branch.p, branch.x)[0][0]), p, branch))
    checked = []
    for (f, p, branch), ver in _verifications(ip, sorted(scored, key=lambda t: t[0])):
        cand = _verified(ip, ver, branch, f)
        cand.update(_stencil(ip, ver, cand) if cand["meets"] else
                    {"robust": False, "stencil_states": (cand["state"],)})
        checked.append(cand)
        if cand["robust"]:
            break
    cand = min(checked, key=lambda c: (not c["meets"], not c["robust"], c["objective"]))
    robust, stencil = cand["robust"], cand["stencil_states"]
    if cand["meets"]:
        reason = "goal met, verified by the ramp solve" + ("; robust to ±0.01 MPa" if robust else
                                                          "; NOT robust to the regulators' ±0.01 MPa")
    elif ip.goal.kind == "tip":
        reason = unreachable_reason(cand["tip_error_mm"], cand["angle_error_deg"])
    else:
        reason = _hold_reason(ip, cand, checked, atlas)
    return InverseResult(
        status="feasible" if cand["meets"] else "infeasible", goal_met=bool(cand["meets"]),
        pressures=cand["pressures"], grasp_state=cand["state"],
        tip=cand["tip"], tip_angle_deg=cand["tip_angle_deg"], tip_error_mm=cand["tip_error_mm"],
        angle_error_deg=cand["angle_error_deg"],
        normal_N=cand["normal_N"], friction_use=cand["friction_use"], objective=cand["objective"],
        verified=cand["verified"], robust=robust, stencil_states=stencil, candidates=len(cands),
        time_ms=1e3 * (time.perf_counter() - t0), reason=reason, joint=ip.problem.joint.name,
        mu=cand["gesture"].mu, object_weight_N=cand["gesture"].object_weight_N, gesture=cand["gesture"])


def unreachable_reason(pos_mm: float, angle_err_deg: float | None) -> str:
    """The one line of an unreachable tip goal: the closest tip's position error (and its
    wrapped angle error) and the tolerance."""
    ang = "" if angle_err_deg is None else f", its tip angle {angle_err_deg:+.2f} deg off"
    dist = f"{pos_mm:.2f}" if pos_mm < 1e6 else f"{pos_mm:.3g}"
    return f"unreachable: the closest achievable tip is {dist} mm away{ang} (tolerance {TIP_TOL_MM} mm)"


def _atlas_matches(atlas: Atlas, problem: GripperProblem) -> None:
    """ValueError (one line) when ``atlas`` was solved for another question than
    ``problem`` (object, joint, gravity, mu, object weight)."""
    weight = None if problem.obstacle is None else problem.params.object_weight if problem.gravity else 0.0
    ours = (problem.obstacle, problem.joint.name, problem.gravity, problem.contact.mu, weight)
    theirs = (atlas.obstacle, atlas.joint, atlas.gravity, atlas.mu, atlas.object_weight_N)
    names = ("object", "joint", "gravity", "mu", "object_weight_N")
    for name, a, b in zip(names, theirs, ours):
        if a != b:
            raise ValueError(f"the atlas was solved with {name} = {a}, this question has {b}: use its own atlas")


def _check_touch(atlas: Atlas) -> None:
    """ValueError (one line) when the object is touched nowhere in the atlas (every
    converged point no_contact): a hold cannot be searched for."""
    conv = atlas.state != NOT_CONVERGED
    if conv.any() and not (atlas.normal_N[conv] > 0).any():
        raise ValueError(f"nothing touches the object at any pressure of the box ({len(atlas.p1)} x "
                         f"{len(atlas.p2)} grid): the fingers never reach it; place it between them or make it larger")


def _hold_reason(ip: InverseProblem, cand: dict, checked: list, atlas: Atlas) -> str:
    """Why no hold met the goal (one line): the normal force's limit when the friction
    held but --min-normal was not reached, else the best friction use."""
    holds = [c for c in checked if c["state"] == "holds"]
    if ip.goal.min_normal > 0 and (holds or (atlas.state == HOLDS).any()):
        best = max([c["normal_N"] for c in holds] + atlas.normal_N[atlas.state == HOLDS].tolist())
        return (f"the normal force of a hold reaches at most {best:.3f} N, less than the asked "
                f"{ip.goal.min_normal:g} N (--min-normal)")
    use = cand["friction_use"]
    return ("no pressure in the box holds the object: best friction use "
            f"{use if use is not None else float('nan'):.3f} (holds <= 1)")


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.inverse")
