"""``make bench-predictor``: timings and residuals of the gesture predictor -> JSON.

All times are medians of single-query wall times on one thread of this CPU (the solver
is also batched; a batched figure is reported separately); the NN throughput (pressures
-> tau -> full gesture for 1e5 queries) is the best of 3 runs. The machine is shared: the
load average at the start is recorded with the figures. Keys required by issue 5:

    gravity_newton_median_ms, gravity_lbfgs_median_ms, contact_median_ms,
    gravity_nn_residual_force_mN, gravity_nn_residual_moment_Nmm,
    contact_nn_residual_force_mN, contact_nn_residual_moment_Nmm, nn_batched_per_s

and by issue 15 (``REQUIRED_KEYS`` lists them all): the raw contact network's figures,
``contact_fast_median_ms`` (the contact NN's warm start finished by Newton steps kept on
its branch, else by the capped LM, over the bench's contact cases),
``gravity_fast_median_ms`` (the gravity NN's warm start finished by one Newton step, over
the gravity cases), ``contact_batched_per_s`` (the delivered contact path, network and
Newton steps on its branch, converged to the issue's 0.1 mN and 0.01 N·mm per second in
one batch of 2,000 pressures on every core in float64; ``details.contact_throughput`` has
it at the solver's own tolerance too, and ``contact_ramp_batched_per_s`` the ramp solve's
batch), ``gravity_batched_per_s`` and ``nn_single_query_ms`` (the
raw NN path, predictor.nn.answer.predict_gesture with ``polish=False``: network,
kinematics and its residual check; the default path also polishes the gestures of a
gripper-trained network that press on the plane X = 0, a solver's time, which
``gravity_fast_median_ms`` measures). The NN throughputs (``nn_batched_per_s``, ``gravity_batched_per_s``) are measured
in float32 on every core (``batched_dtype``, ``batched_threads``; the network and the
joint model cast by ``astype``, answers within 1e-4 mN and 1e-4 mm of float64's), with
float64 on one thread and on every core beside them in the details; every other figure
on one thread in float64. ``gravity_newton_median_ms`` is the default solve from tau = 0
(a Picard step and Newton steps in one recorded graph, predictor.solvers.solve's cold path, predictor.solvers.newton.traced_cold_fn);
``gravity_lm_median_ms`` the LM it replaced,
over the same pressures in the same run.

NN residuals are means over fresh random validation pressures of the worst joint per
sample (p95 and max are recorded beside them). A raw gravity network is judged on the
problem it learns (NNConfig.training_problem; ``details.gravity_nn_problem``): the gripper
with the plane X = 0 ("gripper"), or one finger alone without it ("finger_alone", a
network written before its config recorded ``plane``); its fast path, single query and
throughputs answer the gripper, with the plane. ``contact_nn_residual_*`` is the delivered
contact predictor, the NN's tau finished by Newton steps or the capped LM (ramp fallback
for the few neither converges: ``contact_nn_polished_fallback_rate``; share the Newton
steps answered: ``contact_nn_newton_rate``); the raw network, no solver, is
``contact_nn_raw_*``: its residual over the pressures where the ramp solver converged
(``details.contact_nn_vs_solver`` splits it into contact and contact-free equilibria),
its grasp state's agreement with the solver's (no contact / holds / slips; the state its
classifier gives, ``details.contact_nn_vs_solver.state_by``) and its fingertip error
against the solver's; ``details.contact_nn_vs_solver.newton_step_from_raw`` is the raw
tau after one closed-form Gauss-Newton step (no iteration or check), the fixed step the
issue allows beside the raw network. The paper's numbers are recorded beside ours.

``--graphs compile`` records the solver's graphs by torch.compile instead of
torch.jit.trace (predictor.solvers.solve.use_graphs; ``graphs`` in the JSON): the figures are then
of that mode, and every graph compiles on its first use (in the warm-ups, not timed).

The JSON file is written atomically (strict JSON); ``--json`` prints its top-level figures.
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import time
from types import SimpleNamespace

import torch

from contract import cli
from contract.spec import PRESSURE_LIMIT
from predictor.artefacts import BENCH
from predictor.model.gripper import default_finger
from predictor.model.joint import load_joint
from predictor.nn.networks import sample_pressures
from predictor.nn.answer import predict_gesture
from predictor.nn.checkpoint import DEFAULT_DIR, load_predictor, nn_folder
from predictor.nn.eval import contact_fraction, evaluate, evaluate_contact, evaluate_polished
from predictor.solvers.progress import set_quiet
from predictor.solvers.solve import APPROACH, GRAPHS, SolverOptions, solve, use_graphs
from predictor.model.statics import GripperProblem, Obstacle, meets


#: samples per figure: the committed bench, and ``--quick`` (tests: every key, no timing)
FULL = {"gravity": 30, "lbfgs": 10, "contact": 9, "batch": 1000, "nn_validation": 800, "contact_validation": 400,
        "contact_batch": 108, "throughput": 100_000, "contact_throughput": 2000, "single": 200, "lbfgs_contact": 1}
QUICK = {"gravity": 3, "lbfgs": 1, "contact": 2, "batch": 6, "nn_validation": 16, "contact_validation": 6,
         "contact_batch": 2, "throughput": 1000, "contact_throughput": 8, "single": 3, "lbfgs_contact": 0}
#: the issue's bound on a converged gesture (0.1 mN, 0.01 N·mm), 1000x the solver's default
ISSUE_TOLERANCE = SolverOptions(tol_force=1e-4, tol_moment=1e-2)
#: top-level figures required by issues 5 and 15 (tests/test_predictor_nn.py checks them)
REQUIRED_KEYS = (
    "gravity_newton_median_ms", "gravity_lbfgs_median_ms", "contact_median_ms", "gravity_nn_residual_force_mN",
    "gravity_nn_residual_moment_Nmm", "contact_nn_residual_force_mN", "contact_nn_residual_moment_Nmm",
    "nn_batched_per_s", "nn_single_query_ms", "contact_nn_raw_residual_force_mN",
    "contact_nn_raw_residual_moment_Nmm", "contact_nn_raw_p95_force_mN", "contact_nn_state_agreement",
    "contact_fast_median_ms", "contact_batched_per_s", "gravity_batched_per_s", "gravity_fast_median_ms")


def _median_solve_ms(problem, pressures, options=SolverOptions()):
    """Median single-query time (ms), worst residuals and convergence over pressures (n, 2)."""
    times, force, moment, ok, iters = [], 0.0, 0.0, 0, []
    solve(problem, pressures[:1], options)  # warm-up
    for p in pressures:
        res = solve(problem, p[None], options)
        times.append(res.time_ms)
        ok += int(res.converged[0])
        iters.append(int(res.iterations[0]))
        if bool(res.converged[0]):
            force = max(force, float(res.residual_force_mN.max()))
            moment = max(moment, float(res.residual_moment_Nmm.max()))
    return {"median_ms": statistics.median(times), "max_ms": max(times), "converged": ok, "n": len(pressures),
            "max_residual_force_mN": force, "max_residual_moment_Nmm": moment,
            "median_iterations": statistics.median(iters)}


def _fast_path(pred, problem, pressures, method: str, tol_force_mN: float, tol_moment_Nmm: float,
               polish: bool = False) -> dict:
    """Median single-query time (ms) of predictor.nn.answer.predict_gesture over ``pressures``
    (n, J), a network's tau finished by a solver (contact: Newton steps kept on the
    network's branch, else the capped LM polish, the ramp where it fails; gravity with
    ``polish``: one Newton step, the LM where its check fails), and its worst residuals. A
    query that does not converge or misses tol_force_mN / tol_moment_Nmm counts as a miss,
    not as a time; ``fallbacks``: queries the fallback
    solved; ``newton_from_nn``: contact queries the Newton steps answered."""
    predict_gesture(pred, problem, pressures[:1], polish=polish)  # warm-up
    times, misses, fallbacks, stepped, force, moment = [], 0, 0, 0, 0.0, 0.0
    for p in pressures:
        res = predict_gesture(pred, problem, p[None], polish=polish)
        fallbacks += int(res.fallback[0])
        stepped += 0 if res.stepped is None else int(res.stepped[0])
        f, m = float(res.residual_force_mN.max()), float(res.residual_moment_Nmm.max())
        if not (bool(res.converged[0]) and f <= tol_force_mN and m <= tol_moment_Nmm):
            misses += 1
            continue
        times.append(res.time_ms)
        force, moment = max(force, f), max(moment, m)
    return {"median_ms": statistics.median(times) if times else math.nan, "n": len(pressures), "misses": misses,
            "fallbacks": fallbacks, "newton_from_nn": stepped, "max_residual_force_mN": force,
            "max_residual_moment_Nmm": moment,
            "tolerance": [tol_force_mN, tol_moment_Nmm], "method": method}


def _gravity_throughput(pred, problem, pressures, threads: int, dtype=torch.float64) -> dict:
    """Best of 3 batched runs on ``threads`` torch threads over pressures (N, 2) in
    ``dtype`` (float32: Predictor.astype, GripperProblem.astype): the NN alone, the NN with
    the kinematics (``problem.pose``), and the raw NN path (predict_gesture with
    ``polish=False``: network, kinematics, the residual check). Gestures per second."""
    pred, problem, pressures = pred.astype(dtype), problem.astype(dtype), pressures.to(dtype)
    torch.set_num_threads(threads)
    try:
        with torch.no_grad():
            problem.pose(pressures[:10], pred.net(pressures[:10]))
            batched_s = tau_only_s = math.inf
            for _ in range(3):
                t0 = time.perf_counter()
                tau = pred.net(pressures)
                problem.pose(pressures, tau)
                batched_s = min(batched_s, time.perf_counter() - t0)
                t0 = time.perf_counter()
                pred.net(pressures)
                tau_only_s = min(tau_only_s, time.perf_counter() - t0)
        predict_gesture(pred, problem, pressures[:10], polish=False)
        delivered_s = min(predict_gesture(pred, problem, pressures, polish=False).time_ms for _ in range(3)) / 1e3
    finally:
        torch.set_num_threads(1)
    n = len(pressures)
    return {"threads": threads, "dtype": str(dtype).removeprefix("torch."), "nn_and_kinematics_per_s": n / batched_s,
            "nn_only_per_s": n / tau_only_s, "delivered_per_s": n / delivered_s}


def _contact_throughput(pred, problem, pressures, threads: int) -> dict:
    """The delivered contact path (predict_gesture) on one batch of pressures (N, J) on
    ``threads`` torch threads, in float64: converged gestures per second (median of 5 runs
    after a warm-up), to the issue's bound (0.1 mN, 0.01 N·mm: ISSUE_TOLERANCE) and to the
    solver's default tolerances, with how the answers were reached."""
    torch.set_num_threads(threads)
    out = {"threads": threads, "dtype": "float64", "n": len(pressures)}
    try:
        for name, options in (("issue_bound", ISSUE_TOLERANCE), ("solver_tolerance", SolverOptions())):
            predict_gesture(pred, problem, pressures, options=options)   # warm-up (and compile)
            runs = [predict_gesture(pred, problem, pressures, options=options) for _ in range(5)]
            res = sorted(runs, key=lambda r: r.time_ms)[2]
            out[name] = {"per_s": int(res.converged.sum()) / (res.time_ms / 1e3), "ms": res.time_ms,
                            "converged": int(res.converged.sum()), "newton_from_nn": int(res.stepped.sum()),
                            "ramp_fallback": int(res.fallback.sum()),
                            "median_newton_steps": float(res.iterations.double().median()),
                            "tolerance_mN_Nmm": [1e3 * options.tol_force, options.tol_moment],
                            "max_residual_force_mN": float(res.residual_force_mN[res.converged].max()),
                            "max_residual_moment_Nmm": float(res.residual_moment_Nmm[res.converged].max())}
    finally:
        torch.set_num_threads(1)
    return out


def _solver_figures(joint, n: dict) -> SimpleNamespace:
    """The iterative solvers' timings and batches on the bench's pressures (sizes n):
    gravity Newton, LM and L-BFGS, the grasp ramp, one L-BFGS grasp, a Newton batch."""
    gravity, grasp = GripperProblem(joint), GripperProblem(joint, obstacle=Obstacle(), approach=APPROACH)
    gen = torch.Generator().manual_seed(2026)
    p_grav = torch.rand(n["gravity"], 2, generator=gen, dtype=torch.float64) * (2 * PRESSURE_LIMIT) - PRESSURE_LIMIT
    newton = _median_solve_ms(gravity, p_grav)
    lm = _median_solve_ms(gravity, p_grav, options=SolverOptions(method="lm"))  # the solver before Newton steps
    lbfgs = _median_solve_ms(gravity, p_grav[:n["lbfgs"]], options=SolverOptions(method="lbfgs"))
    g = torch.tensor([0.05, 0.15, 0.25], dtype=torch.float64)
    p_contact = torch.cartesian_prod(g, g)[:n["contact"]]  # closing pressures: all end in contact
    contact = _median_solve_ms(grasp, p_contact)
    # One L-BFGS grasp (the paper's method) takes minutes: not in --quick.
    lbfgs_contact = solve(grasp, p_contact[4:5], SolverOptions(method="lbfgs")) if n["lbfgs_contact"] else None
    t0 = time.perf_counter()
    batch = solve(gravity, p_grav.repeat(n["batch"] // len(p_grav) + 1, 1)[:n["batch"]])
    batched_ms = 1e3 * (time.perf_counter() - t0)
    return SimpleNamespace(gravity=gravity, grasp=grasp, p_grav=p_grav, newton=newton, lm=lm, lbfgs=lbfgs,
                           p_contact=p_contact, contact=contact, lbfgs_contact=lbfgs_contact, batch=batch,
                           batched_ms=batched_ms)


def _nn_figures(joint, grav_pred, paper_pred, cont_pred, s: SimpleNamespace, n: dict) -> SimpleNamespace:
    """The NN predictors' residuals against the solver (raw, delivered, contact state),
    their fast paths' timings and the grasp ramp's batch, on the bench's pressures."""
    grav_nn_problem, cont_problem = grav_pred.config.problem(joint), cont_pred.config.problem(joint)
    p_val = sample_pressures(n["nn_validation"], grav_pred.config, torch.Generator().manual_seed(77))
    # a raw network is judged on the problem it learns (one finger alone for gravity);
    # its delivered answers below, on the gripper's
    grav_nn = evaluate(grav_pred.net, grav_pred.config.training_problem(joint), p_val)
    paper_nn = evaluate(paper_pred.net, paper_pred.config.training_problem(joint), p_val)
    pc_val = sample_pressures(n["contact_validation"], cont_pred.config, torch.Generator().manual_seed(78))
    cont_vs_solver = evaluate_contact(cont_pred, joint, pc_val)
    cont_pol = evaluate_polished(cont_pred, joint, pc_val)
    in_contact = contact_fraction(cont_pred.net, cont_problem, pc_val)
    fast = _fast_path(cont_pred, cont_problem, s.p_contact, "contact NN warm start + Newton steps on its branch "
                      "(else the capped LM polish, then the ramp)", 0.1, 0.01)
    t0 = time.perf_counter()
    cbatch = solve(s.grasp, s.p_contact.repeat(n["contact_batch"] // len(s.p_contact), 1))
    contact_batched_s = time.perf_counter() - t0

    gravity_fast = _fast_path(grav_pred, grav_nn_problem, s.p_grav, "gravity NN warm start + one Newton step "
                                 "(LM where its check fails)", 1e-4, 1e-5, polish=True)
    return SimpleNamespace(grav_nn_problem=grav_nn_problem, cont_problem=cont_problem, grav_nn=grav_nn,
                           paper_nn=paper_nn, cont_vs_solver=cont_vs_solver, cont_pol=cont_pol, in_contact=in_contact,
                           fast=fast, cbatch=cbatch, contact_batched_s=contact_batched_s, gravity_fast=gravity_fast)


def _gravity_throughputs(grav_pred, joint, n: dict) -> SimpleNamespace:
    """Batched throughputs of the gravity NN path on one thread and on every core, and its
    single queries. main measures them first, before any solver graph is recorded: once
    torch.compile's graphs have run in a process, the same eager float32 batch runs slower
    in it (docs/decisions.md §11); a batch job of the network needs no solver graph."""
    # NN throughput: pressures -> tau -> full gesture (forward kinematics), no autograd, on
    # one thread and on every core (best of 3 each: the machine is shared, and the best
    # run is the one least disturbed). The delivered path (predictor.nn.answer.predict_gesture)
    # adds the residual check that refuses an answer outside the NN bound.
    problem = grav_pred.config.problem(joint)
    p_big = torch.rand(n["throughput"], 2, dtype=torch.float64) * (2 * PRESSURE_LIMIT) - PRESSURE_LIMIT
    cores = os.cpu_count() or 1
    one = _gravity_throughput(grav_pred, problem, p_big, 1)
    every64 = _gravity_throughput(grav_pred, problem, p_big, cores)
    every = _gravity_throughput(grav_pred, problem, p_big, cores, torch.float32)
    predict_gesture(grav_pred, problem, p_big[:1], polish=False)   # records the answer's statics graph
    single = [predict_gesture(grav_pred, problem, p_big[i:i + 1], polish=False).time_ms for i in range(n["single"])]
    return SimpleNamespace(one=one, every64=every64, every=every, single=single)


def _record(args, n: dict, joint, load, preds: tuple, s: SimpleNamespace, m: SimpleNamespace,
            h: SimpleNamespace) -> dict:
    """The bench JSON: the required top-level figures, details, the paper's figures and
    the targets, in the order the report reads them."""
    grav_pred, paper_pred, cont_pred = preds
    return {
        "gravity_newton_median_ms": s.newton["median_ms"],
        "gravity_lbfgs_median_ms": s.lbfgs["median_ms"],
        "gravity_lm_median_ms": s.lm["median_ms"],
        "contact_median_ms": s.contact["median_ms"],
        "gravity_nn_residual_force_mN": m.grav_nn["force_mN_mean"],
        "gravity_nn_residual_moment_Nmm": m.grav_nn["moment_Nmm_mean"],
        "contact_nn_residual_force_mN": m.cont_pol["force_mN_mean"],
        "contact_nn_residual_moment_Nmm": m.cont_pol["moment_Nmm_mean"],
        "gravity_fast_median_ms": m.gravity_fast["median_ms"],
        # batched figures in float32 on every core (``batched_threads``, ``batched_dtype``);
        # float64 on one thread and on every core in details.gravity_nn_throughput
        "nn_batched_per_s": h.every["nn_and_kinematics_per_s"],
        "nn_single_query_ms": statistics.median(h.single),
        "gravity_batched_per_s": h.every["delivered_per_s"],
        "batched_threads": h.every["threads"], "batched_dtype": h.every["dtype"],
        "contact_fast_median_ms": m.fast["median_ms"],
        # the delivered contact path (network + Newton steps on its branch, a solver) to the
        # issue's bound, one batch on every core; the ramp solve's batch beside it
        "contact_batched_per_s": h.cthrough["issue_bound"]["per_s"],
        "contact_ramp_batched_per_s": int(m.cbatch.converged.sum()) / m.contact_batched_s,
        "graphs": args.graphs,
        "nn_tau_only_batched_per_s": h.every["nn_only_per_s"],
        # the raw contact network against the ramp solver (issue 15): no solver at inference
        "contact_nn_raw_residual_force_mN": m.cont_vs_solver["raw"]["force_mN_mean"],
        "contact_nn_raw_residual_moment_Nmm": m.cont_vs_solver["raw"]["moment_Nmm_mean"],
        "contact_nn_raw_p95_force_mN": m.cont_vs_solver["raw"]["force_mN_p95"],
        "contact_nn_raw_p95_moment_Nmm": m.cont_vs_solver["raw"]["moment_Nmm_p95"],
        "contact_nn_state_agreement": m.cont_vs_solver["state_agreement"],
        "contact_nn_raw_tip_error_mm": m.cont_vs_solver["raw_tip_error_mm"]["mean"],
        "contact_nn_polished_fallback_rate": m.cont_pol["fallback"] / m.cont_pol["n"],
        "contact_nn_newton_rate": m.cont_pol["newton_from_nn"] / m.cont_pol["n"],
        "details": {
            "gravity_newton": s.newton, "gravity_lm": s.lm, "gravity_lbfgs": s.lbfgs, "contact_newton": s.contact,
            "contact_cases": s.p_contact.tolist(), "contact_approach_MPa": APPROACH,
            "contact_lbfgs_one_case": None if s.lbfgs_contact is None else {
                "pressures_MPa": s.p_contact[4].tolist(), "ms": s.lbfgs_contact.time_ms,
                "converged": bool(s.lbfgs_contact.converged[0]),
                "residual_force_mN": s.lbfgs_contact.residual_force_mN[0].tolist(),
                "residual_moment_Nmm": s.lbfgs_contact.residual_moment_Nmm[0].tolist()},
            "contact_fast": m.fast, "gravity_fast": m.gravity_fast,
            "gravity_nn_throughput": {"one_thread": h.one, "every_core_float64": h.every64, "every_core": h.every},
            "contact_throughput": h.cthrough,
            "contact_batched": {"n": len(m.cbatch.converged), "converged": int(m.cbatch.converged.sum()),
                                   "s": m.contact_batched_s, "method": "newton ramp from the approach, one batch"},
            "gravity_newton_batched_1000_ms": s.batched_ms,
            "gravity_newton_batched_converged": int(s.batch.converged.sum()),
            "gravity_nn_improved": m.grav_nn, "gravity_nn_paper_mlp": m.paper_nn,
            "gravity_nn_problem": "finger_alone" if not meets(grav_pred.config.training_problem(joint)) else "gripper",
            "contact_nn_polished": m.cont_pol, "contact_nn_vs_solver": m.cont_vs_solver,
            "contact_nn_validation_contact_fraction": m.in_contact,
            # the pressures each network was trained on and is validated over here
            "nn_domain_MPa": {name: {"p1": list(pred.config.p1_range), "p2": list(pred.config.p2_range)}
                                 for name, pred in (("gravity_nn", grav_pred), ("gravity_nn_paper", paper_pred),
                                                    ("contact_nn", cont_pred))},
        },
        "paper": {"gravity_lbfgs_s": "2-3", "contact_lbfgs_s": "10-15", "gravity_nn_residual_mN": 2.0,
                  "gravity_nn_residual_Nmm": 1.2, "contact_nn_residual_mN": ">10",
                  "contact_nn_residual_Nmm": ">7", "nn_query_s": "<0.1"},
        "targets": {"gravity_newton_ms": 2, "gravity_fast_ms": 2, "contact_ms": 200, "contact_fast_ms": 50,
                    "contact_batched_per_s": 1e4, "gravity_batched_per_s": 1e5, "iterative_mN": 0.1, "iterative_Nmm": 0.01,
                    "nn_mN": 2.0, "nn_Nmm": 1.2, "nn_batched_per_s": 1e5, "nn_single_ms": 1.0,
                    # issue 15: the raw contact network, no solver at inference
                    "contact_nn_raw_mN": 2.0, "contact_nn_raw_Nmm": 1.2, "contact_nn_raw_p95_mN": 10.0,
                    "contact_nn_raw_p95_Nmm": 5.0, "contact_nn_state_agreement": 0.99},
        "joint": joint.name, "threads": 1, "cpu": platform.processor() or platform.machine(),
        "load_average_at_start": load, "sizes": n,
    }


def _parser() -> cli.Parser:
    """The command line of ``python -m predictor.validation.bench``."""
    ap = cli.Parser(prog="python -m predictor.validation.bench", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/bench/predictor.json")
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: the committed surrogate, "
                    "predictor.defaults)")
    ap.add_argument("--nn-dir", type=nn_folder, default=DEFAULT_DIR, help=f"NN checkpoints (default {DEFAULT_DIR})")
    ap.add_argument("--quick", action="store_true",
                    help="every figure on a few samples (seconds; for tests, not for quoting)")
    ap.add_argument("--graphs", choices=GRAPHS, default="trace",
                    help="record the solver's graphs by torch.jit.trace (default) or torch.compile (inductor's C++: "
                    "faster, but every graph compiles on first use, minutes in all; predictor.solvers.solve.use_graphs)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    set_quiet(args.quiet)
    n = QUICK if args.quick else FULL
    torch.set_num_threads(1)
    use_graphs(args.graphs)
    load = os.getloadavg()
    with ap.errors():  # every input is read before the timings
        joint = load_joint(args.model, default_finger())   # the benchmark's finger: the paper's
        grav_pred = load_predictor(args.nn_dir / "gravity_nn.pt", joint)
        paper_pred = load_predictor(args.nn_dir / "gravity_nn_paper.pt", joint)
        cont_pred = load_predictor(args.nn_dir / "contact_nn.pt", joint, contact=True)
    h = _gravity_throughputs(grav_pred, joint, n)
    s = _solver_figures(joint, n)
    m = _nn_figures(joint, grav_pred, paper_pred, cont_pred, s, n)
    p_contact = sample_pressures(n["contact_throughput"], cont_pred.config, torch.Generator().manual_seed(79))
    h.cthrough = _contact_throughput(cont_pred, m.cont_problem, p_contact, os.cpu_count() or 1)
    out = _record(args, n, joint, load, (grav_pred, paper_pred, cont_pred), s, m, h)
    BENCH.write(args.out, out)
    cli.print_fields({k: v for k, v in out.items() if not isinstance(v, dict)}, args.json, 36)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
