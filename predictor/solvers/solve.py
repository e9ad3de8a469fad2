"""Iterative gesture predictor: find tau = (tau_1 .. tau_J) with zero Equation-1 residual.

Unknowns x = (F1, F2, M)_1, .., (F1, F2, M)_J per sample (J joints of the finger, 2 for the
paper's), (B, n = 3J) in N, N, N·mm. The residual vector is r(x) = [R_F,1, R_M,1/100, ..,
R_F,J, R_M,J/100, out-of-box penalties] (2n numbers, see predictor.model.statics); the
equilibrium is r = 0 with the penalties inactive.

Methods, all batched over B pressure pairs and starting from tau = 0:

- ``newton`` (the default): without an object, from tau = 0 a fixed-point (Picard) step
  (tau <- the loads distal to each joint at the current pose), then Newton steps
  x -= (dR/dx)⁻¹ R on the equilibrium rows (dR/dx by forward differences), all recorded
  as one graph with the answer's statics (``_cold_newton``: Picard and two Newton steps
  land within the tolerances across the box); the answer's own residual is the check,
  and where it fails more Newton steps, then the LM below, go on (``_newton_then_lm``).
  From a given x0 (a network's tau) one Newton step and its statics, also one graph
  (``newton_polish``). Where the two fingers meet at X = 0 (statics.plane_contact) the
  problem without the plane is solved first (``_apart_first``: its answer is this one's
  where no vertex of the outline lies at X < 0, the plane's penalty being exactly zero
  there), and only its rows that fail or cross X = 0 go on with the plane; the answer
  then depends on how the fingers closed: rows whose load-free pose already lies across
  the plane, and rows that fail or end across it deeper than max_penetration, are ramped
  from zero pressure instead (predictor.solvers.ramp.plane_ramp).
  With an object: the LM below (predictor.nn.answer starts the same Newton steps,
  ``newton_iterate``, from the contact network's tau and checks their branch itself).
- ``lm``: Levenberg-Marquardt on r with the Jacobian J = dr/dx
  (B, 2n, n) in one batched pass (predictor.solvers.jacobians.jacobian_fn): central differences of the traced
  residual (~1e-10 relative: Newton's quadratic convergence is kept); with an object the
  samples that fail so are solved again with the exact reverse-mode Jacobian (the
  contact law has kinks; ``attempts``).
  Step (JᵀJ + mu·I) δ = -Jᵀr; mu shrinks ×0.1 on success and grows ×10 on failure, per
  sample, and only unfinished samples are evaluated. Near the root mu -> 1e-12 and the
  step is Newton's, so the convergence is quadratic: 3-6 iterations under gravity.
- ``lbfgs`` (the paper's reference): torch L-BFGS with strong-Wolfe line search on the
  scalar loss sum_b |r_b|².

With an object the pressures are ramped from 0 (or from the approach gesture,
``GripperProblem.approach``) to the target in ``ramp_steps`` equal sub-steps: the grasp depends on
the pressure history (the finger must arrive at the object from the open side). Each step
starts from the tangent predictor x + dx/dP·ΔP (exact dr/dP from the same autograd pass,
Jacobians reused from the previous step), converges to a 100x looser tolerance except the
last, caps LM steps so the finger cannot jump through the object, refuses equilibria that
penetrate deeper than ``max_penetration``, and is halved (up to ``cutbacks`` times) when
it fails.

A sample is converged when |R_F,i| <= tol_force and |R_M,i| <= tol_moment for every
joint and tau is inside the surrogate's box. Non-converged samples are reported with
``converged = False`` and NaN in tau and in the gesture: never returned as an answer.

A result's ``method`` names what produced its answers: "newton", "lm" (also for
method="newton" with an object, which the LM answers), "lbfgs", or "newton+lm" where the
LM finished rows the Newton steps' check refused (``joined``).

Where each part lives: the result type predictor.solvers.result, the options predictor.solvers.options,
recorded graphs predictor.solvers.graphs, Jacobians predictor.solvers.jacobians, Newton predictor.solvers.newton,
LM and L-BFGS predictor.solvers.lm, the pressure ramp predictor.solvers.ramp; this module checks answers
and chooses the path.

Data flow: ``solve(problem, pressures, options)`` with a statics.GripperProblem (joint,
finger, object, contact law, gravity, approach) -> GestureResult (tau, residuals, contact
figures, where it touches, the fingers' meeting, pose); ``result.summary(i)`` is sample i
as a JSON-ready dict.
"""
from __future__ import annotations

import dataclasses
import time

import torch

from predictor.solvers.graphs import GRAPHS, as_statics, graph_mode, statics_at, touch, use_graphs
from predictor.model.gripper import check_pressures, nan_unless
from predictor.solvers.lm import within
from predictor.solvers.newton import (COLD_STEPS, NEWTON_STEPS, bounds, newton_iterate, newton_step, traced_cold_fn,
                                      traced_warm_fn)
from predictor.solvers.options import SolverOptions
from predictor.solvers.ramp import (APPROACH, approach_for, attempts, plane_first, plane_ramp, plane_rows, ramp_method,
                                    solve_path)
from predictor.solvers.result import GestureResult, contact_fields, result_labels
from predictor.model.statics import GripperProblem, Statics, apart, box_scale, meets, out_of_reach, residual_norms

__all__ = ["APPROACH", "GRAPHS", "GestureResult", "SolverOptions", "approach_for", "gesture_result", "graph_mode",
           "meets_tolerances", "newton_iterate", "newton_polish", "newton_step", "result_labels", "solve",
           "statics_at", "touch", "use_graphs"]


def solve(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions = SolverOptions(),
          x0: torch.Tensor | None = None) -> GestureResult:
    """Equilibrium gesture of ``problem`` for a batch of pressure pairs.

    pressures: (B, J) or (J,) MPa [P1 .. PJ], |P| <= 0.3 (contract.spec.OutOfBoxError otherwise;
    ValueError for another count than the finger's J joints).
    x0: optional warm start (B, J, 3) (e.g. the NN's prediction); it disables the ramp.
    With an object the gripper first settles at ``problem.approach`` without it (when
    given), the object is brought in, and the pressures ramp to the target.
    Returns a GestureResult (see its docstring for shapes and units).
    """
    n_joints = problem.n_joints
    pressures = torch.as_tensor(pressures, dtype=torch.float64)
    if pressures.shape[-1:] != (n_joints,):
        raise ValueError(f"{pressures.shape[-1] if pressures.dim() else 1} pressures given for finger "
                         f"{problem.params.finger.name!r} of {n_joints} joints")
    pressures = pressures.reshape(-1, n_joints)
    check_pressures(pressures)
    if options.method not in ("newton", "lm", "lbfgs"):
        raise ValueError(f"unknown method {options.method!r}: use newton, lm or lbfgs")
    if out_of_reach(problem):   # nothing can touch it: the object-free gesture, at once
        res = solve(dataclasses.replace(problem, obstacle=None), pressures, options, x0)
        return dataclasses.replace(res, first_contact=torch.full_like(pressures, float("nan")),
                                   **result_labels(problem))
    t0 = time.perf_counter()
    if options.method == "newton" and problem.obstacle is None and options.jacobian != "exact":
        if meets(problem):
            return _apart_first(problem, pressures, options, x0, t0)
        return _free_newton(problem, pressures, options, x0, t0)
    if options.method == "lbfgs":
        options = dataclasses.replace(options, tol_force=options.lbfgs_tol_force,
                                      tol_moment=options.lbfgs_tol_moment, cutbacks=0)
    kinds = attempts(problem, options)
    x, ok, iterations, first_contact = solve_path(problem, pressures, dataclasses.replace(options, jacobian=kinds[0]),
                                                   x0)
    if len(kinds) > 1 and not bool(ok.all()):
        bad = ~ok
        xb, okb, its, fb = solve_path(problem, pressures[bad], dataclasses.replace(options, jacobian=kinds[1]),
                                       None if x0 is None else x0.reshape(len(ok), -1)[bad])
        x[bad], ok[bad], first_contact[bad] = xb, okb, fb
        iterations[bad] += its
    return gesture_result(problem, pressures, x, ok, iterations, t0, ramp_method(options),
                          None if problem.obstacle is None else first_contact)


def _free_newton(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0: torch.Tensor | None,
                 t0: float) -> GestureResult:
    """The object-free Newton solve: from tau = 0 the cold graph (``_cold_newton``; the
    rows that start across X = 0 by the ramp, ``_plane_then_newton``), from x0 a step
    (``newton_polish``), then ``_fingers_meet``."""
    if x0 is None and options.max_iter >= COLD_STEPS:
        deep = plane_first(problem, pressures, options)
        if bool(deep.any()):
            return _plane_then_newton(problem, pressures, options, deep, t0)
        return _fingers_meet(problem, pressures, options, _cold_newton(problem, pressures, options, t0), t0)
    start = torch.zeros(len(pressures), problem.n_joints, 3, dtype=torch.float64) if x0 is None else x0
    return _fingers_meet(problem, pressures, options, newton_polish(problem, pressures, start, options, t0)[0], t0)


def _apart_first(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0: torch.Tensor | None,
                 t0: float) -> GestureResult:
    """The object-free Newton solve where the fingers meet at X = 0, broad phase first:
    ``_free_newton`` of the problem without the plane's penalty (statics.apart), whose
    answer is this problem's wherever it converged with no vertex of the outline at X < 0
    (the plane's penalty is exactly zero there: same residual, same check); the rows that
    failed or cross X = 0 are solved again by ``_free_newton`` of ``problem`` (the plane's
    ramp where they need it), as if alone: their iterations and method are that solve's
    (the broad phase's try is in ``time_ms`` only), so a result is the one the plane's
    path gives."""
    res = dataclasses.replace(_free_newton(apart(problem), pressures, options, x0, t0), plane=True)  # this problem's
    again = ~res.converged | (res.plane_overlap_mm > 0)
    if not bool(again.any()):
        return res
    more = _free_newton(problem, pressures[again], options, None if x0 is None else x0[again], t0)
    return dataclasses.replace(res.with_rows(again, more), method=joined(res.method, more.method),
                               time_ms=1e3 * (time.perf_counter() - t0))


def _plane_then_newton(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, deep: torch.Tensor,
                       t0: float) -> GestureResult:
    """The cold solve where the rows ``deep`` (B,) bool start across X = 0 (ramp.plane_first):
    those by the ramp from zero pressure, the others by the cold Newton solve (and
    ``_fingers_meet``), in one result."""
    B, n = len(pressures), 3 * problem.n_joints
    x = torch.full((B, n), float("nan"), dtype=torch.float64)
    ok, iterations = torch.zeros(B, dtype=torch.bool), torch.zeros(B, dtype=torch.long)
    x[deep], ok[deep], iterations[deep] = plane_ramp(problem, pressures[deep], options)
    method = "lm"
    if not bool(deep.all()):
        rest = _fingers_meet(problem, pressures[~deep], options,
                             _cold_newton(problem, pressures[~deep], options, t0), t0)
        x[~deep], ok[~deep], iterations[~deep] = rest.tau.reshape(-1, n), rest.converged, rest.iterations
        method = joined(rest.method, "lm")
    return gesture_result(problem, pressures, x, ok, iterations, t0, method, None)


def _fingers_meet(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, res: GestureResult,
                  t0: float) -> GestureResult:
    """An object-free result whose rows failed, or ended with the finger across X = 0
    deeper than max_penetration (Newton from tau = 0, whose load-free pose can lie far
    across), solved again by the ramp from zero pressure (predictor.solvers.ramp.plane_ramp); the
    other rows as they are."""
    B = len(pressures)
    again = plane_rows(problem, res.tau.reshape(B, -1), pressures, res.converged, options)
    if not bool(again.any()):
        return res
    x, ok, its = plane_ramp(problem, pressures[again], options)
    more = gesture_result(problem, pressures[again], x, ok, its + res.iterations[again], t0, "lm", None)
    return dataclasses.replace(res.with_rows(again, more), method=joined(res.method, "lm"),
                               time_ms=1e3 * (time.perf_counter() - t0))


def gesture_result(problem: GripperProblem, pressures: torch.Tensor, x: torch.Tensor, ok: torch.Tensor,
                   iterations: torch.Tensor, t0: float, method: str,
                   first_contact: torch.Tensor | None, statics: Statics | None = None) -> GestureResult:
    """The GestureResult of solved unknowns x (B, 3J) at pressures (B, J) MPa: residual,
    contact and pose at x (``statics``, when the caller has them already), NaN where ok
    (B,) is False; time_ms from perf_counter t0 up to the answer."""
    B, n_joints = pressures.shape
    with torch.no_grad():
        tau = x.reshape(B, n_joints, 3)
        st = statics_at(problem, pressures, tau) if statics is None else statics
    force, moment = residual_norms(st.residual)
    every = bool(ok.all())   # nothing to mask (the usual case: saves ~0.1 ms a query)
    tau, pose = (tau, st.pose) if every else (nan_unless(ok, tau), st.pose.masked(ok))
    return GestureResult(
        pressures=pressures, tau=tau, converged=ok, residual_force_mN=force, residual_moment_Nmm=moment,
        normal_force_N=st.contact.normal, friction_N=st.contact.friction, friction_ratio=st.contact.ratio,
        slip=st.contact.slip, iterations=iterations, time_ms=1e3 * (time.perf_counter() - t0), pose=pose,
        method=method, first_contact=first_contact, **result_labels(problem), **contact_fields(problem, st),
    )


def meets_tolerances(res: GestureResult, x: torch.Tensor, options: SolverOptions) -> torch.Tensor:
    """The solver's convergence rule on the rows of a result at unknowns x (B, 3J): (B,)
    bool, every joint's residual within options' tolerances and x in the surrogate's box."""
    return within(res.residual_force_mN / 1e3, res.residual_moment_Nmm,
                   (x.abs() <= box_scale(x.shape[1])[0]).all(-1), options)


def _checked(problem, pressures, x, iterations, options, t0, fallback, statics=None) -> GestureResult:
    """The GestureResult at x (B, n) checked at the solver's tolerances (tau in the box,
    every joint's residual within tol_force and tol_moment), the check inside ``time_ms``;
    the rows it refuses (B,) bool are replaced by ``fallback(rows)``, a GestureResult of
    those rows whose iterations are added to the ``iterations`` (B,) they took here, and
    whose method joins this one's (``joined``: "newton+lm" where the LM answered rows)."""
    res = gesture_result(problem, pressures, x, torch.ones(len(x), dtype=torch.bool), iterations, t0, "newton",
                         None, statics)
    t_check = time.perf_counter()   # the check is part of the answer's time
    ok = meets_tolerances(res, x, options)
    bad = ~ok
    if not bool(bad.any()):
        return dataclasses.replace(res, converged=ok, time_ms=res.time_ms + 1e3 * (time.perf_counter() - t_check))
    more = fallback(bad)
    more = dataclasses.replace(more, iterations=more.iterations + iterations[bad])
    mixed = dataclasses.replace(res, converged=ok).with_rows(bad, more)
    return dataclasses.replace(mixed, method=joined(res.method, more.method),
                               time_ms=1e3 * (time.perf_counter() - t0))


def joined(*methods: str) -> str:
    """The method label of an answer whose rows came from several methods: their parts
    ("nn", "newton", "lm", ...) once each, in order ("newton", "newton+lm" -> "newton+lm")."""
    parts = [part for method in methods for part in method.split("+")]
    return "+".join(dict.fromkeys(parts))


def _cold_newton(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, t0: float) -> GestureResult:
    """``solve``'s default without an object, from tau = 0: the one graph of
    ``traced_cold_fn`` (Picard, two Newton steps, the statics), then the check; rows it
    refuses go on with Newton steps from where they are, then the LM (``_newton_then_lm``)."""
    B, n_joints = pressures.shape
    with torch.inference_mode():
        x, iterations, *out = traced_cold_fn(problem, *bounds(options))(
            torch.zeros(B, 3 * n_joints, dtype=torch.float64), pressures)
        st = as_statics(problem, out)
    x, iterations = x.clone(), iterations.clone()

    rest = dataclasses.replace(options, max_iter=options.max_iter - COLD_STEPS)
    return _checked(problem, pressures, x, iterations, options, t0,
                    lambda bad: _newton_then_lm(problem, pressures[bad], x[bad], rest, t0, NEWTON_STEPS), st)


def newton_polish(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor,
                  options: SolverOptions = SolverOptions(), t0: float | None = None) -> tuple[GestureResult, torch.Tensor]:
    """Newton without an object from x0 (a network's tau: the gravity NN's polish; ``solve``
    with x0): the first Newton step and the statics of its answer in one recorded graph
    (``traced_warm_fn``), checked by that answer's own residual at the solver's
    tolerances (``_checked``): from the gravity NN's tau (~0.2 mN) the one step is the
    answer, from a start within the tolerances no step is taken. Samples the check refuses
    (a start outside the one-step gate, a singular Jacobian, out of the box) go on from
    their iterate with up to NEWTON_STEPS - 1 more steps and the LM (``_newton_then_lm``);
    ``iterations`` counts them all.

    pressures (B, J) MPa; x0 (B, J, 3) [N, N, N·mm]; t0: perf_counter time the caller's
    query began (default: now), for ``time_ms``. Returns (GestureResult, the residual at x0
    (B, J, 3) N, N, N·mm: the start's own, from the step's pass)."""
    if problem.obstacle is not None:
        raise ValueError("newton_polish is for the smooth residual without an object: use solve(..., x0=)")
    t0 = time.perf_counter() if t0 is None else t0
    B, n_joints = pressures.shape
    if options.max_iter < 1:   # no step allowed: the start's own check
        return _newton_then_lm(problem, pressures, x0.reshape(B, -1).double(), options, t0, 0), \
            problem.residual(pressures, x0.reshape(B, n_joints, 3)).residual
    with torch.inference_mode():
        x, stepped, r0, *out = traced_warm_fn(problem, *bounds(options))(x0.reshape(B, -1).double(), pressures)
        st = as_statics(problem, out)
    x, iterations, r0 = x.clone(), stepped.long(), r0.clone()

    rest = dataclasses.replace(options, max_iter=options.max_iter - 1)
    return _checked(problem, pressures, x, iterations, options, t0,
                    lambda bad: _newton_then_lm(problem, pressures[bad], x[bad], rest, t0, NEWTON_STEPS - 1), st), r0


def _newton_then_lm(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor, options: SolverOptions,
                    t0: float, steps: int) -> GestureResult:
    """Up to ``steps`` Newton steps from x0 (B, 3J) (``newton_iterate``), the last iterate
    checked (``_checked``), and the LM from the iterate of the samples it refuses within what
    is left of ``options.max_iter`` (NaN when nothing is): the rows that one recorded step
    did not finish (``newton_polish``, ``_cold_newton``)."""
    n_joints = pressures.shape[1]
    x, iterations, _ = newton_iterate(problem, pressures, x0.reshape(-1, n_joints, 3), options, steps)

    def fallback(bad):   # the LM's answer within the rest of max_iter, or NaN
        budget = options.max_iter - int(iterations[bad].max())
        if budget <= 0:
            return gesture_result(problem, pressures[bad], x[bad], torch.zeros(int(bad.sum()), dtype=torch.bool),
                                  torch.zeros_like(iterations[bad]), t0, "newton", None)
        return solve(problem, pressures[bad], dataclasses.replace(options, method="lm", max_iter=budget),
                     x0=x[bad].reshape(-1, n_joints, 3))

    return _checked(problem, pressures, x, iterations, options, t0, fallback)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.gesture")
