"""Answers of a trained NN predictor in the solver's result format (NNGestureResult),
pressures (B, J) MPa:

- gravity (``polish`` None, the default): the network's tau where its residual (on the
  gripper, the problem answered) is within the NN bound (NN_FORCE_TOL_MN,
  NN_MOMENT_TOL_NMM: 2 mN, 1.2 N·mm), method "nn"; where it is not because the network's
  gesture presses on the plane X = 0 (``at_plane``: its outline within PLANE_REACH_MM of
  X = 0 or across it, as a network that learned one finger alone crosses it where the
  gripper's fingers meet), the network's tau finished by the polish below, reported
  ``polished`` with the raw residual kept beside it: the plane's penalty is so stiff
  (dR/dtau has a singular value over 1e4 there) that no network's tau meets the bound on
  it; NaN elsewhere (a network off by more than the bound away from the plane) and where
  the polish does not converge either;
- gravity raw (``polish`` False): the network's own answer only, NaN outside the bound
  (the float32 throughput mode is this: the polish is a float64 solver);
- gravity with ``polish`` True: every sample's tau finished by one Newton step
  (predictor.solvers.solve.newton_polish; the LM where its check fails, the full pressure ramp
  where that does not converge); method "nn+newton" (joined with "lm" where the LM
  answered rows);
- contact: full Newton steps from the network's tau (``newton_on_branch``), kept where they
  converge on the network's branch (fingertip within BRANCH_TIP_MM, the classifier's grasp
  state, penetration within max_penetration), since undamped steps can land on another
  equilibrium of the contact law; the other samples by the LM from the network's tau with
  a small step cap (POLISH_STEP) that keeps the iterates on the network's branch, and where
  that does not converge by the full pressure ramp (``fallback``). Method "nn+newton"
  where Newton steps answered rows, joined with "lm" where the LM answered rows
  (predictor.solvers.solve.joined): "nn+newton", "nn+newton+lm" or "nn+lm".
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace

import torch
from torch import nn

from predictor.model.gripper import check_pressures, nan_unless, outline_vertices, with_rows
from predictor.nn.networks import ContactNet, Predictor
from predictor.solvers.options import SolverOptions
from predictor.solvers.result import GestureResult, contact_fields, result_labels
from predictor.solvers.solve import gesture_result, joined, meets_tolerances, newton_iterate, newton_polish, solve, statics_at
from predictor.model.statics import GripperProblem, Statics, grasp_state, meets, residual_norms


# LM step cap (scaled units) when polishing a contact NN prediction: small enough that the
# iterates stay on the NN's branch (0.3, the ramp's cap, let 8 of 55 jump to another one).
POLISH_STEP = 0.02
# The NN bound: a prediction counts as an answer only within it.
NN_FORCE_TOL_MN = 2.0
NN_MOMENT_TOL_NMM = 1.2
# mm: a gravity network's own gesture outside the NN bound is finished by the polish
# (``at_plane``) when its outline comes this close to X = 0 (or crosses it): a gesture that
# stops short of the plane where the equilibrium presses on it misses the plane's force.
# Measured (a gripper network on the production surrogate, 400 random pressures): the rows
# outside the bound lay at -1.2..0.9 mm from X = 0 where the Newton equilibrium presses,
# and >= 1.5 mm away where it does not but the network is off by 2.1-5.3 mN.
PLANE_REACH_MM = 1.0
# mm: a Newton answer from the contact NN's tau counts only if its fingertip is this close to
# the network's (``newton_on_branch``; bench-predictor's details.contact_nn_vs_solver.
# newton_from_raw gives the largest shift to the ramp's equilibrium and the smallest to another).
BRANCH_TIP_MM = 1.0
BRANCH_ROUNDS = 3    # newton_iterate calls from the contact network's tau (``newton_on_branch``)


_FIELD = {"obstacle": "object", "params": "the finger"}


def _describe(value) -> str:
    """A problem field for a message: objects and fingers in words, not their reprs."""
    if value is None:
        return "none"
    return value.describe() if hasattr(value, "describe") else str(value)


def raw_answer(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor):
    """The network's own answer, no solver: (tau (B, J, 3), Statics at it, grasp state
    (B,) codes: its classifier's for a ContactNet, else its tau's contact)."""
    with torch.no_grad():
        tau, state = net.tau_and_state(pressures) if isinstance(net, ContactNet) else (net(pressures), None)
        st = statics_at(problem, pressures, tau)
    return tau, st, grasp_state(st.contact.normal, st.contact.slip) if state is None else state


@dataclass(frozen=True)
class NNGestureResult(GestureResult):
    """GestureResult of the NN predictor. raw_residual_force_mN, raw_residual_moment_Nmm
    (B, J): Equation 1 at the network's own tau, before any solver; polished (B,): the
    answer is a solver's polish of the network's tau (contact; gravity with ``polish``),
    not the network's; fallback (B,): the polish did not converge and the full pressure
    ramp solved the sample instead (gravity: the Newton step's check failed and the LM went
    on from it);
    raw_state (B,) codes of statics.STATES: the grasp state by the network itself (its
    classifier; the contact of its tau for a network without one), None without an object;
    stepped (B,): contact, the answer is full Newton steps' from the network's tau (kept on
    its branch, ``newton_on_branch``), not the capped LM's; None without an object;
    at_plane (B,): gravity, the network's own gesture is outside the NN bound where it
    presses on the plane X = 0 (``at_plane``), so the answer is the polish's (``polished``
    where it converged), not the network's; None with an object."""

    fallback: torch.Tensor = None
    raw_residual_force_mN: torch.Tensor = None
    raw_residual_moment_Nmm: torch.Tensor = None
    polished: torch.Tensor = None
    raw_state: torch.Tensor = None
    stepped: torch.Tensor = None
    at_plane: torch.Tensor = None


def predict_gesture(pred: Predictor, problem: GripperProblem, pressures: torch.Tensor,
                    polish: bool | None = None, options: SolverOptions = SolverOptions()) -> NNGestureResult:
    """NN gesture in the solver's result format, pressures (B, J) MPa.

    ``problem`` must be the one the NN was trained for (``pred.config.problem(joint)``),
    ValueError otherwise. Gravity (``polish`` None): the raw NN tau where its residual is
    within the NN bound (2 mN, 1.2 N·mm); where it is not because the network's gesture
    presses on the plane X = 0 (``at_plane``), the NN tau finished as with ``polish``
    below and reported ``polished``; NaN elsewhere and where that polish fails. Gravity
    with ``polish`` False: the raw NN tau only (NaN outside the bound). Gravity with
    ``polish`` True: every NN tau finished by one Newton step (solve.newton_polish; the LM
    where its check fails, ``fallback``; the full ramp where the LM does not converge) to
    the iterative solver's tolerances. Contact
    (``polish`` ignored): full Newton steps
    from the NN tau (predictor.solvers.newton.newton_iterate), kept where they converge on the network's
    branch (``stepped``, ``newton_on_branch``); the other samples start again from the NN
    tau with the LM under a small step cap (POLISH_STEP) so the iterates stay on the NN's
    branch, with the Jacobian by differences and then, for the samples that did not
    converge, the exact one; samples neither converges in ``max_iter`` steps are
    re-solved by the full ramp (``fallback``). ``options``: the solvers' tolerances and
    limits (default: the solver's 1e-4 mN, 1e-5 N·mm); a batch job content with the issue's
    0.1 mN, 0.01 N·mm (``SolverOptions(tol_force=1e-4, tol_moment=1e-2)``) mostly takes one
    Newton step instead of two or three.
    """
    trained = pred.config.problem(problem.joint)
    if problem != trained:
        diff = "; ".join(f"{_FIELD.get(f.name, f.name)} {_describe(getattr(trained, f.name))} "
                         f"(given {_describe(getattr(problem, f.name))})"
                         for f in fields(trained) if getattr(problem, f.name) != getattr(trained, f.name))
        raise ValueError(f"an NN predictor answers only the problem it was trained for: {diff}")
    check_pressures(pressures)
    t0 = time.perf_counter()
    if polish and problem.obstacle is None:
        with torch.no_grad():
            tau = pred.net(pressures)
        return _polished(problem, pressures, tau, options, t0)
    tau, st, raw_state = raw_answer(pred.net, problem, pressures)
    f, m = residual_norms(st.residual)
    raw = {"raw_residual_force_mN": f, "raw_residual_moment_Nmm": m}
    if problem.obstacle is None:
        ok = (f.amax(-1) <= NN_FORCE_TOL_MN) & (m.amax(-1) <= NN_MOMENT_TOL_NMM)
        c = st.contact
        res = NNGestureResult(
            pressures=pressures, tau=nan_unless(ok, tau), converged=ok, residual_force_mN=f, residual_moment_Nmm=m,
            normal_force_N=c.normal, friction_N=c.friction, friction_ratio=c.ratio, slip=c.slip,
            iterations=torch.zeros(len(ok), dtype=torch.long), time_ms=1e3 * (time.perf_counter() - t0),
            pose=st.pose.masked(ok), method="nn", **result_labels(problem),
            fallback=torch.zeros_like(ok), polished=torch.zeros_like(ok), **raw)
        near = torch.zeros_like(ok)
        if polish is None and pressures.dtype == torch.float64:
            near[~ok] = at_plane(problem, pressures[~ok], tau[~ok])
        if not bool(near.any()):
            return replace(res, at_plane=near)
        pol = _polished(problem, pressures[near], tau[near], options, t0)
        mixed = replace(res, **contact_fields(problem, st)).with_rows(near, pol)   # the plane's figures too
        return replace(mixed, method=pol.method,
                       time_ms=1e3 * (time.perf_counter() - t0), at_plane=near,
                       fallback=with_rows(res.fallback, near, pol.fallback),
                       polished=with_rows(res.polished, near, pol.polished), **raw)
    raw["raw_state"] = raw_state
    res, stepped = newton_on_branch(problem, pressures, tau, st, raw_state, t0, options)
    rest = ~stepped
    fallback, method = torch.zeros_like(stepped), "nn+newton" if bool(stepped.any()) else "nn"
    if bool(rest.any()):
        # The capped LM from the NN's tau (Jacobian by differences, and the exact one where
        # that stalls at a kink of the contact law: predictor.solvers.ramp.attempts), then the full ramp.
        lm = solve(problem, pressures[rest], replace(options, contact_max_step=POLISH_STEP), x0=tau[rest])
        fallback[rest] = ~lm.converged
        if bool((~lm.converged).any()):
            lm = lm.with_rows(~lm.converged, solve(problem, pressures[rest][~lm.converged], options))
        # the Newton steps tried first count too
        res = res.with_rows(rest, replace(lm, iterations=lm.iterations + res.iterations[rest]))
        method = joined(method, lm.method)
    return NNGestureResult(**{**res.__dict__, "time_ms": 1e3 * (time.perf_counter() - t0), "method": method},
                           fallback=fallback, polished=~fallback, stepped=stepped, **raw)


def _polished(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor, options: SolverOptions,
              t0: float) -> NNGestureResult:
    """The gravity network's tau (B, J, 3) finished by solve.newton_polish (one Newton step,
    more and the LM where its check fails: ``fallback``), and where that does not converge
    by the full pressure ramp (solve without a start), with the network's own residual
    from the step's pass beside it; ``polished`` where it converged."""
    res, start = newton_polish(problem, pressures, tau, options, t0=t0)
    miss = ~res.converged
    if bool(miss.any()):
        # A start far across X = 0 (a lone-finger network's, where the finger presses on the
        # plane) can leave the LM stalled: the full pressure ramp, as without a network.
        ramp = solve(problem, pressures[miss], options)
        res = replace(res.with_rows(miss, ramp), method=joined(res.method, ramp.method),
                      time_ms=1e3 * (time.perf_counter() - t0))
    f, m = residual_norms(start)
    return NNGestureResult(**{**res.__dict__, "method": joined("nn", res.method)},
                           fallback=res.iterations > 1, polished=res.converged, raw_residual_force_mN=f,
                           raw_residual_moment_Nmm=m, at_plane=None)


def at_plane(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """Whether the gesture at tau (B, J, 3) presses on the plane X = 0 (B,) bool: its
    outline crosses X = 0 or comes within PLANE_REACH_MM of it, where the gripper's fingers
    meet (always False for one finger alone). There a network's raw residual cannot meet
    the NN bound: the plane's penalty (ContactParams.plane_stiffness, N/mm per mm of edge)
    turns a tau error of 1e-6 N into a residual over 10 mN, and a gesture that stops short
    misses the plane's push."""
    if not meets(problem) or not len(pressures):
        return torch.zeros(len(pressures), dtype=torch.bool)
    with torch.no_grad():
        pose = problem.pose(pressures, tau)
    return outline_vertices(pose, problem.params.layout)[..., 0].amin(-1) <= PLANE_REACH_MM


def newton_on_branch(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor, raw: Statics,
                     raw_state: torch.Tensor, t0: float,
                     options: SolverOptions = SolverOptions()) -> tuple[GestureResult, torch.Tensor]:
    """Full Newton steps from the contact network's tau (predictor.solvers.newton.newton_iterate) and which of
    their answers to keep: (GestureResult, stepped (B,) bool).

    From the network's tau undamped steps converge for most pressures, but some land on
    another equilibrium, the finger tens of mm away in another grasp state, while the
    ramp's equilibria lie within a fraction of a mm of the network's fingertip
    (``branch_figures``, in bench-predictor). An answer is kept (``stepped``) when it
    meets the solver's tolerances and stays on the network's branch: fingertip within
    BRANCH_TIP_MM of the network's, the grasp state of its classifier raw_state (B,),
    penetration within max_penetration. The network's own tau is the answer (0 steps)
    where it meets them already; an answer on the branch but short of the tolerances (a
    step that straddled a kink of the contact law contracts less) goes on from where it
    is, up to BRANCH_ROUNDS calls of newton_iterate in all. pressures (B, J) MPa; tau (B,
    J, 3) the network's and raw its Statics; t0: perf_counter time the query began."""
    B, n_joints = pressures.shape
    rows, x, steps, st, res = torch.arange(B), tau.reshape(B, -1), torch.zeros(B, dtype=torch.long), raw, None
    for k in range(BRANCH_ROUNDS + 1):
        p = pressures[rows]
        if k:   # Newton steps from where these rows are
            x, more, _ = newton_iterate(problem, p, x.reshape(-1, n_joints, 3), options)
            steps = steps + more
            st = statics_at(problem, p, x.reshape(-1, n_joints, 3))
        c = st.contact
        first = torch.where((c.normal > 0)[:, None], p, torch.full_like(p, float("nan")))
        part = gesture_result(problem, p, x, torch.ones_like(c.slip), steps, t0, "nn+newton", first, st)
        on_branch = ((grasp_state(c.normal, c.slip) == raw_state[rows])
                     & ((st.pose.tip_end - raw.pose.tip_end[rows]).norm(dim=-1) <= BRANCH_TIP_MM)
                     & (c.penetration <= options.max_penetration))
        part = replace(part, converged=meets_tolerances(part, x, options) & on_branch)
        if res is None:
            res = part
        else:
            mask = torch.zeros(B, dtype=torch.bool)
            mask[rows] = True
            res = res.with_rows(mask, part)
        again = ~part.converged if k == 0 else on_branch & ~part.converged
        if not bool(again.any()):
            break
        rows, x, steps = rows[again], x[again], steps[again]
    return res, res.converged.clone()
