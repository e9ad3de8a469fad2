"""The pressure ramp of a solve with an object: the pressures go from 0 (or the approach
gesture) to the target in ``ramp_steps`` sub-steps (``solve_path``), each solved by the
method's ``runner`` from the tangent predictor and halved on failure (``advance``), since
the grasp depends on the pressure history. ``attempts``: the Jacobians tried in turn.

Unknowns x (B, 3J) = (F1 N, F2 N, M N·mm) per joint; pressures (B, J) MPa.
"""
from __future__ import annotations

import dataclasses

import torch

from predictor.graphs import residual_fn, touch
from predictor.jacobians import jacobian_fn
from predictor.lm import lbfgs, levenberg_marquardt
from predictor.options import SolverOptions
from predictor.progress import Heartbeat
from predictor.statics import GripperProblem


# Default grasp approach gesture (MPa): open joint 1, bring the object in (statics.Obstacle).
APPROACH = (-0.15, 0.0)


def approach_for(n_joints: int) -> tuple[float, ...]:
    """The default approach gesture of an n-joint finger: joint 1 opened as APPROACH's,
    the other joints at zero (the paper's finger: APPROACH itself)."""
    return (APPROACH[0],) + (0.0,) * (n_joints - 1)


def ramp_method(options: SolverOptions) -> str:
    """The method that answers on this path (the ``method`` of its results): "lm" for
    options.method newton or lm (Newton's own steps are predictor.newton's, without an
    object), "lbfgs" for lbfgs."""
    return "lbfgs" if options.method == "lbfgs" else "lm"


def attempts(problem: GripperProblem, options: SolverOptions) -> tuple[str, ...]:
    """The Jacobians a Newton solve tries in turn (``jacobian_fn`` kinds). ``auto`` with
    an object: central differences of the traced residual first (cheaper per call for a
    few samples: the bench's contact gesture went from 693 to 208 ms), then the exact one
    for the samples that failed (a difference that straddles a kink of the contact law can
    stall LM: a three-joint grasp did). Both end at the same equilibria (tested on the
    three objects' holds, slips and misses)."""
    if options.method in ("newton", "lm") and options.jacobian == "auto" and problem.obstacle is not None:
        return ("differences", "exact")
    return (options.jacobian,)


def advance(run, x, pa, pb, cutbacks, jac=None):
    """One ramp step pa -> pb (B, J) from the equilibrium x at pa (with its Jacobians
    ``jac``, or None); samples that fail are retried as two half steps, recursively up to
    ``cutbacks`` times (as the FEM does). Returns (x, converged, iterations, jac at x)."""
    x_new, conv, its, jac_new = run(x, pb, pa, jac)
    if bool(conv.all()) or cutbacks == 0:
        return x_new, conv, its, jac_new
    bad = ~conv
    pm = 0.5 * (pa[bad] + pb[bad])
    sub = None if jac is None else tuple(a[bad] for a in jac)
    x1, c1, i1, j1 = advance(run, x[bad], pa[bad], pm, cutbacks - 1, sub)
    x2, c2, i2, j2 = advance(run, x1, pm, pb[bad], cutbacks - 1, j1)
    x_new, conv, its = x_new.clone(), conv.clone(), its.clone()
    x_new[bad], conv[bad], its[bad] = x2, c1 & c2, its[bad] + i1 + i2
    if jac_new is not None:
        for a, b in zip(jac_new, j2):
            a[bad] = b
    return x_new, conv, its, jac_new


def runner(prob: GripperProblem, opts: SolverOptions):
    """The solver of one ramp step: run(x (B, n), p (B, J), p_prev=None, jac=None) ->
    (x, converged (B,), iterations (B,), Jacobians at x or None), by opts.method; with an
    object, an equilibrium deeper than opts.max_penetration counts as failed."""
    if opts.method in ("newton", "lm"):
        jac_fn = jacobian_fn(prob, prob.obstacle is not None, opts.jacobian)  # dr/dP: the ramp's predictor
        cap = None if prob.obstacle is None else opts.contact_max_step
        method = lambda x, p, p_prev=None, jac=None: levenberg_marquardt(  # noqa: E731
            jac_fn, x, p, opts, cap, p_prev, jac)
    else:
        method = lambda x, p, p_prev=None, jac=None: lbfgs(residual_fn(prob), x, p, opts)  # noqa: E731
    if prob.obstacle is None:
        return method

    def with_depth_check(x, p, p_prev=None, jac=None):
        # A step so large that the finger passes into (or through) the object finds a
        # spurious equilibrium; refuse it so that advance cuts the step back.
        x, conv, its, jac = method(x, p, p_prev, jac)
        return x, conv & (touch(prob, x, p)[1] <= opts.max_penetration), its, jac

    return with_depth_check


def solve_path(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0):
    """solve's path (approach, ramp, or from x0) with one kind of Jacobian: (x (B, 3J),
    converged (B,), iterations (B,), first contact (B, J) MPa)."""
    B, n_joints = pressures.shape
    run, run_free = runner(problem, options), runner(dataclasses.replace(problem, obstacle=None), options)
    # Intermediate ramp steps only need to stay on the branch: a 100x looser tolerance
    # saves the last (quadratic) Newton iteration of each; the final step uses the full one.
    loose = dataclasses.replace(options, tol_force=100 * options.tol_force, tol_moment=100 * options.tol_moment)
    run_loose = runner(problem, loose)
    n = 3 * n_joints
    x = torch.zeros(B, n, dtype=torch.float64) if x0 is None else x0.reshape(B, n).double().clone()
    iterations = torch.zeros(B, dtype=torch.long)
    ok = torch.ones(B, dtype=torch.bool)
    first_contact = torch.full((B, n_joints), float("nan"), dtype=torch.float64)

    def record_contact(x, p):
        # One contact evaluation per ramp step (no iterate changes): the first pressures
        # at which the finger touches the object, for grasp planning (predictor.atlas).
        new = (touch(problem, x, p)[0] > 0) & first_contact[:, 0].isnan()
        first_contact[new] = p[new]

    if problem.obstacle is None or x0 is not None:
        x, ok, iterations, _ = run(x, pressures)
        if problem.obstacle is not None:
            record_contact(x, pressures)
    else:
        start = problem.approach
        p0 = (torch.zeros_like(pressures) if start is None else
              torch.as_tensor(start, dtype=torch.float64).expand(B, n_joints))
        if start is not None:  # approach: open without the object, then bring it in
            x, ok, iterations, _ = run_free(x, p0)
        record_contact(x, p0)
        jac = None
        beat = Heartbeat("solve")   # a hard ramp (cut-backs on every step) can take tens of seconds
        for k in range(1, options.ramp_steps + 1):
            beat(lambda: f"ramp step {k} of {options.ramp_steps}, {int(ok.sum())} of {B} on track")
            pa = p0 + (pressures - p0) * ((k - 1) / options.ramp_steps)
            pb = p0 + (pressures - p0) * (k / options.ramp_steps)
            step_run = run if k == options.ramp_steps else run_loose
            x, conv, its, jac = advance(step_run, x, pa, pb, options.cutbacks, jac)
            ok &= conv
            iterations += its
            record_contact(x, pb)
    return x, ok, iterations, first_contact
