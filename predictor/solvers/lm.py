"""Levenberg-Marquardt and L-BFGS on the gesture residual r(x; P) (2n rows: the scaled
equilibrium of n = 3J unknowns and the out-of-box penalties, predictor.solvers.graphs.residual_fn),
batched over samples, and the convergence rule they share (``within``).

LM step (JᵀJ + mu·I) δ = -Jᵀr, kept where it lowers |r|² (else, with an object, first
retried shortened along δ: SHORTENINGS); mu shrinks ×0.1 on success and grows ×10 on
failure, per sample; near the root mu -> 1e-12 and the step is Newton's (quadratic
convergence).
"""
from __future__ import annotations

import torch

from predictor.solvers.options import SolverOptions
from predictor.model.statics import MOMENT_SCALE, box_scale


def _done(r: torch.Tensor, opts: SolverOptions) -> torch.Tensor:
    """Converged mask (B,) from residual vectors r (B, 2n)."""
    n = r.shape[1] // 2
    eq = r[:, :n].reshape(-1, n // 3, 3)
    return within(eq[..., :2].norm(dim=-1), eq[..., 2].abs() * MOMENT_SCALE, r[:, n:].abs().amax(-1) == 0, opts)


def within(force: torch.Tensor, moment: torch.Tensor, in_box: torch.Tensor, opts: SolverOptions) -> torch.Tensor:
    """Converged mask (B,): every joint's |R_F| (B, J) N and |R_M| (B, J) N·mm within the
    tolerances, and tau in the surrogate's box (in_box (B,) bool: no out-of-box penalty)."""
    return (force.amax(-1) <= opts.tol_force) & (moment.amax(-1) <= opts.tol_moment) & in_box


def lm_step(J: torch.Tensor, r: torch.Tensor, mu) -> torch.Tensor:
    """The damped Gauss-Newton step -(JᵀJ + mu·I)⁻¹ Jᵀ r (B, n) of J (B, m, n), r (B, m),
    mu (B,) or a number; zero for a sample whose system is singular."""
    JT = J.transpose(1, 2)
    mu = torch.as_tensor(mu, dtype=J.dtype).reshape(-1, 1, 1)
    step, info = torch.linalg.solve_ex(JT @ J + mu * torch.eye(J.shape[2], dtype=J.dtype), JT @ r[..., None])
    # A singular system (a pose far across a stiff penalty, where the forces swamp mu)
    # takes no step: the LM then raises mu, as for a step that fails.
    return torch.where((info == 0)[:, None] & step[..., 0].isfinite().all(-1, keepdim=True), -step[..., 0], 0.0)


def levenberg_marquardt(jac_fn, x, p, opts, max_step=None, p_prev=None, prev_jac=None, hand_over=None,
                        shortenings=0):
    """Batched LM from x (B, n = 3J) at pressures p (B, J).

    Returns (x, converged, iterations, (dr/dx (B, n, n), dr/dP (B, n, J)) at the final x);
    the last item is the next ramp step's ``prev_jac``, which saves one Jacobian per step.

    p_prev: the pressures at which x is an equilibrium (a ramp step). The start is then
    the tangent predictor x + dx/dP·(p - p_prev), dx/dP = -(dr/dx)⁻¹ dr/dP: it keeps the
    finger's geometry instead of its loads, so a pressure step does not
    push the finger deep into the object.

    max_step caps each step's largest scaled component (N, N·mm/100): with contact it
    keeps the iterates on the branch of the previous ramp step, since a long step can jump
    the finger through the object to a contact-free root.

    hand_over (k, test): after k iterations the unfinished samples for which test(rows (b,),
    x (b, n), p (b, J)) -> (b,) bool holds (rows: their indices in the batch) stop there,
    not converged, for another solver to take over (predictor.solvers.ramp's plane homotopy); the
    others go on as without it.

    shortenings: how many times a failed step is tried shortened (SHORTENINGS with an
    object, else 0)."""
    n = x.shape[1]
    eye = torch.eye(n, dtype=x.dtype)
    step_scale = box_scale(n)[1]
    x = x.clone()
    if p_prev is not None:
        J0, Jp0 = prev_jac if prev_jac is not None else (lambda a: (a[0][:, :n], a[2]))(jac_fn(x, p_prev))
        dx = -torch.linalg.solve(J0 + 1e-12 * eye, Jp0 @ (p - p_prev)[..., None])[..., 0]
        x = x + dx
    J, r, Jp = jac_fn(x, p, dp=False)    # dr/dP: at the last iterate only (below)
    mu = torch.full((x.shape[0],), 1e-6, dtype=x.dtype)
    iters = torch.zeros(x.shape[0], dtype=torch.long)
    done = _done(r, opts)
    stuck = torch.zeros_like(done)
    handed = torch.zeros_like(done)
    for k in range(opts.max_iter):
        if hand_over is not None and k == hand_over[0]:
            open_ = torch.nonzero(~(done | stuck)).flatten()
            if open_.numel():
                handed[open_] = hand_over[1](open_, x[open_], p[open_])
        act = torch.nonzero(~(done | stuck | handed)).flatten()  # work on unfinished samples only
        if act.numel() == 0:
            break
        if act.numel() == len(x):   # every sample (a single query's usual case): no gathers
            x, r, J, Jp, mu, done = _lm_iteration(jac_fn, x, p, r, J, Jp, mu, opts, max_step, step_scale,
                                                  shortenings)
            iters += 1
        else:
            x[act], r[act], J[act], Jp_act, mu[act], done[act] = _lm_iteration(
                jac_fn, x[act], p[act], r[act], J[act], None if Jp is None else Jp[act], mu[act], opts, max_step,
                step_scale, shortenings)
            if Jp is not None:
                Jp[act] = Jp_act
            iters[act] += 1
        stuck = mu > 1e8
    if Jp is None and getattr(jac_fn, "dp", None) is not None:
        Jp = jac_fn.dp(x, p)
    return x, done, iters, (J[:, :n], Jp)


#: With an object, a step that does not lower |r|² is tried again SHORTENINGS times, each
#: SHORTEN times the last, before mu grows. From a pose clear of the object (a ramp step's
#: tangent predictor can leave contact) the Gauss-Newton step aims at the contact-free
#: root beyond the object and overshoots into its penalty; a shorter step along it lands
#: on the object, where growing mu instead turns the step toward the gradient and creeps
#: (the paper's circle grasp: 194 LM iterations and two cut-backs without, 63 with).
#: Without an object they only cost residuals: the plane X = 0 has its own homotopy
#: (predictor.solvers.ramp), whose stiff tries they slow by ~12 % (an inverse tip goal).
SHORTENINGS, SHORTEN = 3, 0.25


def _lm_iteration(jac_fn, x, p, r, J, Jp, mu, opts, max_step, step_scale, shortenings):
    """One LM iteration of the samples x (b, n) at p (b, J) with residuals r, Jacobians J
    (and dr/dP Jp, or None) and damping mu: the step, capped by max_step (scaled units),
    kept (or, shortened, one of its ``shortenings``) where it lowers |r|²; mu ×0.1 on
    success and ×10 on failure. Returns the new (x, r, J, Jp, mu, done)."""
    step = lm_step(J, r, mu)
    if max_step is not None:
        big = (step / step_scale).abs().amax(-1, keepdim=True) / max_step
        step = step / big.clamp_min(1.0)
    merit = r.pow(2).sum(-1)
    x, r, J = x.clone(), r.clone(), J.clone()
    Jp = None if Jp is None else Jp.clone()
    better = torch.zeros(len(x), dtype=torch.bool)
    rows = torch.arange(len(x))     # the samples whose step has not lowered |r|² yet
    for k in range(shortenings + 1):
        x_try = x[rows] + SHORTEN ** k * step[rows]
        J_try, r_try, Jp_try = jac_fn(x_try, p[rows], dp=False)
        ok = r_try.pow(2).sum(-1) < merit[rows]
        took = rows[ok]
        x[took], r[took], J[took] = x_try[ok], r_try[ok], J_try[ok]
        if Jp is not None:
            Jp[took] = Jp_try[ok]
        better[took] = True
        rows = rows[~ok]
        if not len(rows):
            break
    mu = torch.where(better, (mu * 0.1).clamp_min(1e-12), mu * 10.0)
    return x, r, J, Jp, mu, _done(r, opts)


def lbfgs(loss_fn, x, p, opts):
    """Paper's L-BFGS on sum_b |r_b|² from x (B, 3J). Returns (x, converged, iterations)."""
    x = x.clone().requires_grad_(True)
    opt = torch.optim.LBFGS([x], lr=1.0, max_iter=opts.lbfgs_max_iter, tolerance_grad=1e-15,
                            tolerance_change=1e-20, history_size=20, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        r = loss_fn(x, p)
        total = r.pow(2).sum()
        total.backward()
        return total

    opt.step(closure)
    x = x.detach()
    with torch.no_grad():
        r = loss_fn(x, p)
    n_iter = opt.state[opt._params[0]]["n_iter"]
    return x, _done(r, opts), torch.full((x.shape[0],), n_iter, dtype=torch.long), None
