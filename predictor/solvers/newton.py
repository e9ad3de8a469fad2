"""Newton's method on the equilibrium rows R(x) = 0 of the gesture residual (no object:
smooth), as recorded graphs: one step x_next = x - (dR/dx)⁻¹ R(x) (``_newton_fn``), a
Picard step from tau = 0 (``_picard_fn``), the cold solve (Picard and two Newton steps and
the answer's statics, ``traced_cold_fn``) and the warm one (a step from a network's tau,
``traced_warm_fn``); ``newton_iterate`` takes steps until the one-step gate. Nothing here
checks an answer: predictor.solvers.solve does.

Unknowns x (B, 3J) = (F1 N, F2 N, M N·mm) per joint; pressures p (B, J) MPa; tolerances
(N, N·mm).
"""
from __future__ import annotations

import math

import torch

from predictor.solvers.graphs import graph_cache, residual_fn, statics_fn, traced
from predictor.model.gripper import rot
from predictor.solvers.jacobians import autograd_jacobian, difference_offsets
from predictor.solvers.lm import lm_step
from predictor.solvers.options import SolverOptions
from predictor.model.statics import GripperProblem


#: Quadratic convergence of Newton under gravity, |R_k+1| <= |R_k|² / QUADRATIC (N, N·mm):
#: from tau = 0 on 2,000 pressures the worst force went 235 -> 16.5 -> 0.023 mN -> 8e-9 mN
#: (|R_k+1| ~ |R_k|² / 12 N) and the moment 14 -> 0.16 -> 4e-5 N·mm (/ 600 N·mm). A
#: residual within sqrt(tol × QUADRATIC) therefore needs one last step, checked by the
#: answer's own residual instead of another Jacobian.
QUADRATIC = (10.0, 100.0)
NEWTON_STEPS = 8   # Newton steps before the LM takes over
NEWTON_REL_STEP = 1e-7   # forward-difference step of the Newton Jacobian (~sqrt(eps))
COLD_STEPS = 3     # the cold graph's Picard and two Newton steps (``traced_cold_fn``)


def bounds(options: SolverOptions) -> tuple[tuple[float, float], tuple[float, float]]:
    """(tol, gate) in (N, N·mm): the solver's tolerances and the one-step gate sqrt(tol × QUADRATIC)."""
    return ((options.tol_force, options.tol_moment),
            (math.sqrt(options.tol_force * QUADRATIC[0]), math.sqrt(options.tol_moment * QUADRATIC[1])))


def _worst(eq: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Worst joint's |R_F| N and |R_M| N·mm (B,) of residuals eq (B, J, 3)."""
    return eq[..., :2].norm(dim=-1).amax(-1), eq[..., 2].abs().amax(-1)


def _newton_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """step(x (B, n), p (B, J)) -> (x_next (B, n), R (B, J, 3) at x [N, N, N·mm], stepped
    (B,) bool, last (B,) bool): one Newton step on the equilibrium rows,

        x_next = x - (dR/dx)⁻¹ R(x),   dR/dx (B, n, n) by forward differences of R,
                                          steps NEWTON_REL_STEP × (1 N, 1 N, 100 N·mm).

    Forward, not central, differences: 1 + n residuals a row instead of 1 + 2n (half the
    arithmetic of a batch), and their ~1e-7 relative error (truncation h, round-off
    eps/h) only adds a 1e-7 contraction to Newton's quadratic one. With an object R
    includes the penalty contact, which is C1 (statics.smooth_penetration): a difference
    straddling a sample point's contact onset is off by O(h), which slows the last steps
    there, and the caller's check catches it.

    tol, gate: (N, N·mm) bounds on every joint's |R_F| and |R_M|. Where R(x) is within tol
    already, or dR/dx is singular, x_next = x (not ``stepped``); ``last``: those, and the x
    whose R(x) is within the one-step gate, whose x_next is the candidate answer."""
    n_joints, n = problem.n_joints, 3 * problem.n_joints
    h, offsets = difference_offsets(n, NEWTON_REL_STEP, central=False)

    def step(x: torch.Tensor, p: torch.Tensor):
        B = x.shape[0]
        X = x[:, None] + offsets
        R = problem.residual(p.repeat_interleave(1 + n, 0), X.reshape(-1, n_joints, 3)).residual
        R = R.reshape(B, 1 + n, n)
        r, J = R[:, 0], (R[:, 1:] - R[:, :1]).transpose(1, 2) / h
        dx, info = torch.linalg.solve_ex(J, r[..., None])
        eq = r.reshape(B, n_joints, 3)
        force, moment = _worst(eq)
        stepped = (info == 0) & ((force > tol[0]) | (moment > tol[1]))
        last = ~stepped | ((force <= gate[0]) & (moment <= gate[1]))
        return torch.where(stepped[:, None], x - dx[..., 0], x), eq, stepped, last

    return step


def _picard_fn(problem: GripperProblem, tol: tuple[float, float]):
    """picard(x (B, n), p (B, J)) -> (x_next (B, n), moved (B,) bool): one fixed-point
    (Picard) step of a problem without an object, tau <- the loads that balance the parts
    distal to each joint at the pose of tau,

        tau_F <- tau_F - rot(-theta_i) R_F,i,   tau_M <- tau_M - R_M,i

    (Equation 1 is R_F = rot(theta_i) tau_F - F_distal, R_M = tau_M - M_distal); x_next = x
    (not ``moved``) where R(x) is within tol (N, N·mm) already. From tau = 0 it moves the
    start from the weights' full moment (~14 N·mm) to what the finger's own deflection
    changes in it (~2 N·mm), so that Newton needs two steps instead of three."""
    n_joints = problem.n_joints

    def picard(x: torch.Tensor, p: torch.Tensor):
        st = problem.residual(p, x.reshape(-1, n_joints, 3))
        r = st.residual
        force, moment = _worst(r)
        moved = (force > tol[0]) | (moment > tol[1])
        dx = torch.cat((rot(-st.pose.theta, r[..., :2]), r[..., 2:]), -1).reshape(x.shape)
        return torch.where(moved[:, None], x - dx, x), moved

    return picard


@graph_cache
def _traced_newton_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """``_newton_fn`` recorded by ``traced``: Jacobian, solve and update in one call (the
    residual's dispatch is most of its cost; docs/decisions.md §11)."""
    return traced(_newton_fn(problem, tol, gate), 3 * problem.n_joints, problem.n_joints)


@graph_cache
def traced_cold_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """cold(x (B, n), p (B, J)) -> (x (B, n), iterations (B,), then ``statics_fn``'s tuple
    at x): the cold solve's usual path as one recorded graph, from x = 0 a Picard step and
    two Newton steps, then the answer's statics. From tau = 0 in the box the first Newton
    step lands within the one-step gate on every one of 2,000 pressures (the committed
    surrogate and the analytic joint: 0.29 and 0.67 mN at worst), so the second is the
    last; the answer's check decides (``_cold_newton``)."""
    picard, step, statics = _picard_fn(problem, tol), _newton_fn(problem, tol, gate), statics_fn(problem)

    def cold(x: torch.Tensor, p: torch.Tensor):
        x, moved = picard(x, p)
        x, _, first, _ = step(x, p)
        x, _, second, _ = step(x, p)
        return (x, moved.long() + first + second) + statics(x, p)

    return traced(cold, 3 * problem.n_joints, problem.n_joints)


@graph_cache
def traced_warm_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """warm(x0 (B, n), p (B, J)) -> (x (B, n), stepped (B,) bool, R(x0) (B, J, 3), then
    ``statics_fn``'s tuple at x): ``newton_polish``'s usual path as one recorded graph,
    a Newton step from a warm start (a network's tau) and the answer's statics: one call
    where a step and a statics graph took two, with their Python around them."""
    step, statics = _newton_fn(problem, tol, gate), statics_fn(problem)

    def warm(x: torch.Tensor, p: torch.Tensor):
        x, r0, stepped, _ = step(x, p)
        return (x, stepped, r0) + statics(x, p)

    return traced(warm, 3 * problem.n_joints, problem.n_joints)


def newton_iterate(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor,
                   options: SolverOptions = SolverOptions(),
                   steps: int | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Full Newton steps from x0, x_k+1 = x_k - (dR/dx)⁻¹ R(x_k) (``_traced_newton_fn``),
    each sample until R(x_k) is within the one-step gate sqrt(tol × QUADRATIC), at most
    min(steps (default NEWTON_STEPS), options.max_iter) steps; nothing is checked here: the
    caller checks the last iterate (``_newton_then_lm``; with an object, predictor.nn.answer's
    branch check, since undamped steps can land on another equilibrium).

    pressures (B, J) MPa; x0 (B, J, 3) [N, N, N·mm]. Returns (x (B, 3J), Newton steps taken
    (B,) long, the residual at x0 (B, J, 3) from the first step's pass)."""
    B, n_joints = pressures.shape
    step = _traced_newton_fn(problem, *bounds(options))
    x = x0.reshape(B, -1).double().clone()
    iterations = torch.zeros(B, dtype=torch.long)
    active, r0 = torch.arange(B), None
    with torch.inference_mode():
        for _ in range(max(min(NEWTON_STEPS if steps is None else steps, options.max_iter), 0)):
            every = len(active) == B
            x_next, r, stepped, last = step(x if every else x[active], pressures if every else pressures[active])
            r0 = r if r0 is None else r0
            if every:
                x = x_next
            else:
                x[active] = x_next
            iterations[active] += stepped
            if bool(last.all()):
                break
            active = active[~last]
    x, iterations = x.clone(), iterations.clone()   # leave inference mode
    r0 = problem.residual(pressures, x0.reshape(B, n_joints, 3)).residual if r0 is None else r0.clone()
    return x, iterations, r0


def newton_step(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """One full Gauss-Newton step tau - (JᵀJ)⁻¹Jᵀr with the exact Jacobian
    (``autograd_jacobian``), no damping, cap or check: pressures (B, J) MPa, tau (B, J, 3)
    -> (B, J, 3). For measuring what a closed-form step does to a network's tau
    (predictor.nn.eval.evaluate_contact), not an answer."""
    B, n_joints = pressures.shape
    J, r, _ = autograd_jacobian(residual_fn(problem))(tau.reshape(B, -1), pressures)
    return (tau.reshape(B, -1) + lm_step(J, r, 1e-12)).reshape(B, n_joints, 3).detach()
