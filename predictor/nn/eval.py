"""Evaluation of NN gesture predictors: residual statistics of the raw network (``evaluate``,
``residual_stats``), of the delivered contact path (``evaluate_polished``), and the raw
contact network against the ramp solver's equilibria (``evaluate_contact``): the figures
the checkpoints' metrics and bench-predictor record. Forces mN, moments N·mm, lengths mm,
pressures (B, J) MPa.
"""
from __future__ import annotations

import time

import torch
from torch import nn

from predictor.model.joint import JointModel
from predictor.nn.networks import ContactNet, Predictor
from predictor.nn.answer import BRANCH_TIP_MM, newton_on_branch, predict_gesture, raw_answer
from predictor.solvers.options import SolverOptions
from predictor.solvers.solve import meets_tolerances, newton_step, solve
from predictor.model.statics import GripperProblem, grasp_state, residual_norms


def residual_stats(res: torch.Tensor) -> dict:
    """mean / p95 / max over samples of the worst-joint force (mN) and moment (N·mm)."""
    f, m = residual_norms(res)
    f, m = f.amax(-1), m.amax(-1)
    q = lambda v, a: float(torch.quantile(v, a))  # noqa: E731
    return {"force_mN_mean": float(f.mean()), "force_mN_p95": q(f, 0.95), "force_mN_max": float(f.max()),
            "moment_Nmm_mean": float(m.mean()), "moment_Nmm_p95": q(m, 0.95), "moment_Nmm_max": float(m.max())}


def evaluate(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor) -> dict:
    """Residual statistics of the raw NN tau on pressures (B, J) (see residual_stats)."""
    with torch.no_grad():
        return residual_stats(problem.residual(pressures, net(pressures)).residual)


def contact_fraction(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor) -> float:
    """Fraction of pressures (B, J) whose raw NN gesture touches the object."""
    with torch.no_grad():
        return float((problem.residual(pressures, net(pressures)).contact.normal > 0).double().mean())


def evaluate_polished(pred: "Predictor", joint: JointModel, pressures: torch.Tensor) -> dict:
    """The delivered contact predictor (NN + Newton steps kept on its branch, else the capped
    LM polish, then the ramp) on pressures: residual statistics of the answers, how many
    the Newton steps answered and how many needed the ramp."""
    problem = pred.config.problem(joint)
    res = predict_gesture(pred, problem, pressures)
    ok = res.converged
    stats = residual_stats(problem.residual(pressures[ok], res.tau[ok]).residual)
    return {**stats, "converged": int(ok.sum()), "n": len(ok), "fallback": int(res.fallback.sum()),
            "newton_from_nn": int(res.stepped.sum()),
            "median_polish_iterations": float(res.iterations.double().median()),
            "batch_time_ms": res.time_ms}


def evaluate_contact(pred: "Predictor", joint: JointModel, pressures: torch.Tensor) -> dict:
    """The raw contact network on pressures (B, J) against its target, the iterative
    solver's equilibrium along the pressure ramp from the approach gesture (where a final
    pressure pair has several equilibria, the ramp's is the one meant):

    raw, raw_contact, raw_contact_free: residual statistics (residual_stats) of the network's own
    tau over every pressure the solver converged on, and over those whose equilibrium
    touches the object or not; state_agreement: fraction whose grasp state by the network
    (no contact, holds, slips: its classifier's, ContactNet, or else the contact of its
    tau) is the solver's, and state_agreement_of_tau that of its tau's contact alone;
    raw_tip_error_mm: the raw gesture's fingertip against the solver's (mean / p95 / max);
    reference_penetration_mm: the solver's own penetration of the object at its contact
    equilibria (mean / p95), the scale the raw pose must hit for the penalty force to
    balance; newton_step_from_raw: the residual (residual_stats) and fingertip error (mean, mm)
    after one full Gauss-Newton step from the raw tau (exact Jacobian, no damping or
    check), the closed-form step the issue allows beside the raw network (from a network
    far from the equilibrium it jumps branches: 3.1 mm from 0.038 mm); newton_from_raw: where
    full Newton steps from the raw tau end (``branch_figures``), the first stage of the
    delivered path."""
    problem = pred.config.problem(joint)
    ref = solve(problem, pressures)
    ok = ref.converged
    tau, st, by_net = raw_answer(pred.net, problem, pressures)
    of_tau = grasp_state(st.contact.normal, st.contact.slip)
    touch = ref.normal_force_N > 0
    truth = grasp_state(ref.normal_force_N, ref.slip)
    tip = (st.pose.tip_end - ref.pose.tip_end).norm(dim=-1)[ok]
    depth = problem.residual(pressures[ok & touch], ref.tau[ok & touch]).contact.penetration
    kept_res, kept = newton_on_branch(problem, pressures, tau, st, by_net, time.perf_counter())
    conv = meets_tolerances(kept_res, kept_res.tau.reshape(len(tau), -1), SolverOptions()) & ok
    shift = (kept_res.pose.tip_end - st.pose.tip_end).norm(dim=-1)
    on_ref = (kept_res.tau - ref.tau).abs().amax((-1, -2)) <= 1e-4
    x1 = newton_step(problem, pressures, tau)
    st1 = problem.residual(pressures, x1)
    tip1 = (st1.pose.tip_end - ref.pose.tip_end).norm(dim=-1)[ok]
    cfg = pred.config
    return {"raw": residual_stats(st.residual[ok]),
            "raw_contact": residual_stats(st.residual[ok & touch]) if bool((ok & touch).any()) else None,
            "raw_contact_free": residual_stats(st.residual[ok & ~touch]) if bool((ok & ~touch).any()) else None,
            "state_agreement": float((by_net == truth)[ok].double().mean()),
            "state_agreement_of_tau": float((of_tau == truth)[ok].double().mean()),
            "state_by": "classifier" if isinstance(pred.net, ContactNet) else "contact of the raw tau",
            "raw_tip_error_mm": {"mean": float(tip.mean()), "p95": float(torch.quantile(tip, 0.95)),
                                 "max": float(tip.max())},
            "reference_penetration_mm": {"mean": float(depth.mean()), "p95": float(torch.quantile(depth, 0.95))},
            "newton_step_from_raw": {**residual_stats(st1.residual[ok]), "tip_error_mm_mean": float(tip1.mean())},
            "newton_from_raw": branch_figures(conv, kept & ok, on_ref, shift),
            "n": len(ok), "reference_converged": int(ok.sum()), "reference_in_contact": int((ok & touch).sum()),
            "domain_MPa": {"P1": list(cfg.p1_range), "P2": list(cfg.p2_range)},
            "reference": "predictor.solvers.solve along the pressure ramp from the approach gesture"}


def branch_figures(conv: torch.Tensor, kept: torch.Tensor, on_ref: torch.Tensor, shift: torch.Tensor) -> dict:
    """What full Newton steps from a contact network's tau reach (``newton_on_branch``),
    over (B,) masks: converged, kept by the branch check, at the ramp's equilibrium (tau
    within 1e-4), and the fingertip's shift from the network's (B,) mm."""
    there, elsewhere = conv & on_ref, conv & ~on_ref
    extreme = lambda v, f: float(f(v)) if len(v) else None  # noqa: E731
    return {"converged": int(conv.sum()), "converged_to_ramp_equilibrium": int(there.sum()),
            "converged_elsewhere": int(elsewhere.sum()), "kept": int(kept.sum()),
            "kept_elsewhere": int((kept & ~on_ref).sum()),
            "tip_shift_mm_max_at_ramp_equilibrium": extreme(shift[there], torch.max),
            "tip_shift_mm_min_elsewhere": extreme(shift[elsewhere], torch.min),
            "branch_tip_mm": BRANCH_TIP_MM}
