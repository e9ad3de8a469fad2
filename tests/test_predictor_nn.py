"""NN gesture predictors (predictor.nn.networks, nn_train, nn_answer, nn_eval, nn_checkpoint
and the predictor.cli.nn command line): training, correction stages, checkpoints, the
delivered gravity and contact paths against the solver, and the benchmark's record.

Every test states the exact or expected answer it checks.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from predictor.model.gripper import DEFAULT_OUTLINE, GripperParams
from predictor.model.joint import AnalyticJoint, load_joint
from predictor.solvers.solve import solve
from predictor.model.statics import GripperProblem

from test_predictor_common import (CONTACT_NN, DT, GRASP, GRAVITY, GRAVITY_NN, PAPER_CHAIN, ROOT, SURROGATE,
                                   THREE_FINGER, THREE_P, J, LeftJoint, run_gesture_cli, t)

torch.set_num_threads(1)


# ---------------------------------------------------------------- NN and CLI
def test_nn_training_reduces_equilibrium_residual():
    """Two epochs of the paper's gravity NN on 400 pairs (equilibrium loss, no labels) cut
    the mean validation force residual below 1/3 of the untrained network's."""
    from predictor.nn.networks import GestureNet, NNConfig
    from predictor.nn.eval import evaluate
    from predictor.nn.train import train

    cfg = NNConfig(n_train=400, n_val=100, epochs=2, lr=3e-3)
    torch.manual_seed(cfg.seed)
    before = evaluate(GestureNet(cfg.widths, cfg.activation), GRAVITY, torch.rand(100, 2, dtype=DT) * 0.6 - 0.3)
    pred = train(cfg, J)
    assert pred.metrics["val"]["force_mN_mean"] < before["force_mN_mean"] / 3


def test_correction_stage_cuts_a_fitted_heads_error_fourfold():
    """Multi-stage training (predictor.nn.train.fit_stage) on labels with an exact solution,
    tau(P) = (sin 3P1 cos 2P2, P1 P2, 20 tanh(P1 - P2)) per joint (the second joint's
    halved): a small head fitted by Adam and L-BFGS leaves an error e; the correction
    stage's tau_scale is e's RMS per output, and head + stage leave less than a quarter
    of e's RMS in every output, on the training pressures and on 300 others (0.11-0.17
    on the others when written)."""
    from predictor.nn.networks import VARIANTS, network
    from predictor.nn.train import fit, fit_stage

    def exact(p):
        one = torch.stack((torch.sin(3 * p[:, 0] / 0.3) * torch.cos(2 * p[:, 1] / 0.3), p[:, 0] * p[:, 1] / 0.09,
                           20 * torch.tanh((p[:, 0] - p[:, 1]) / 0.3)), -1)
        return torch.stack((one, 0.5 * one), 1)

    cfg = dataclasses.replace(VARIANTS["contact"], widths=(2, 24, 24, 6), refine_hidden=(24, 24), refine_stages=1,
                              abs_pressure=False,
                              epochs=40, batch=50, lbfgs_iters=400, refine_epochs=40, refine_lbfgs_iters=400)
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    net = network(cfg)
    p, q = ((2 * torch.rand(n, 2, generator=gen, dtype=DT) - 1) * 0.3 for n in (600, 300))
    scale = torch.tensor([1.0, 1.0, 30.0], dtype=DT)
    fit(net.heads[1], lambda i: ((net.heads[1](p if i is None else p[i]) - exact(p if i is None else p[i]))
                                  / scale).pow(2).sum((-1, -2)).mean(), len(p), cfg, gen)
    rms = lambda x, stages: (net.head_tau(1, x, stages) - exact(x)).pow(2).mean(0).sqrt()  # noqa: E731
    with torch.no_grad():
        before_p, before_q = rms(p, 0), rms(q, 0)
    fit_stage(net, 1, 0, p, exact(p), cfg, gen)
    with torch.no_grad():
        assert torch.allclose(net.refine[1][0].tau_scale, before_p.flatten(), rtol=1e-12, atol=0)
        assert bool((rms(p, None) < before_p / 4).all()) and bool((rms(q, None) < before_q / 4).all())


def test_nn_checkpoint_round_trip_and_refusals(tmp_path):
    """save_predictor/load_predictor return the same network bit for bit (outputs on 500
    pressures torch.equal); the file is the gravity kind (no object), so loading it as a
    contact predictor is refused by name, as are a flipped byte, a plain torch.save file,
    a joint other than the one it was trained on, and a query with an object: each a
    one-line ValueError."""
    from predictor.nn.networks import NNConfig
    from predictor.nn.answer import predict_gesture
    from predictor.nn.checkpoint import GRAVITY_FORMAT, load_predictor, save_predictor
    from predictor.nn.train import train

    pred = train(NNConfig(n_train=100, n_val=20, epochs=1), J)
    path = tmp_path / "g.pt"
    save_predictor(pred, path)
    assert path.read_bytes().startswith(b'{"bytes":') and GRAVITY_FORMAT.encode() in path.read_bytes()[:200]
    back = load_predictor(path, J)
    p = torch.rand(500, 2, dtype=DT) * 0.6 - 0.3
    with torch.no_grad():
        assert torch.equal(back.net(p), pred.net(p))
    assert back.config == pred.config and back.joint_name == "analytic" and back.history == pred.history
    data = path.read_bytes()
    bad = tmp_path / "bad.pt"
    for damaged, needle in ((data[:100] + bytes([data[100] ^ 1]) + data[101:], "damaged"),
                            (data[:-1], "damaged")):
        bad.write_bytes(damaged)
        with pytest.raises(ValueError, match=needle):
            load_predictor(bad, J)
    torch.save({"config": {}}, bad)
    for call, needle in ((lambda: load_predictor(path, J, contact=True), "softjoint-gravity-nn/1"),
                         (lambda: load_predictor(bad, J), "no valid checkpoint header"),
                         (lambda: load_predictor(path, LeftJoint()), "trained with joint"),
                         (lambda: predict_gesture(back, GRASP, p), "trained for: object none")):
        with pytest.raises(ValueError, match=needle) as info:
            call()
        assert "\n" not in str(info.value)


@pytest.mark.skipif(not GRAVITY_NN.is_file(), reason="no trained NN predictor (make gestures)")
def test_nn_predictor_cli_matches_solver():
    """--method nn with the committed gravity NN at (-0.1, 0.1), on the joint model it was
    trained on (analytic or the committed surrogate): converged (residual within 2 mN /
    1.2 N·mm), tau within 0.01 N / 1 N·mm of the Newton solution and its raw residual is
    its residual (no solver); with the contact NN at (0.1, 0.2) on the circle the answer is
    the solver's polish (or the ramp's) within 1e-4 mN, and the raw network's larger
    residual is reported beside it."""
    from predictor.nn.checkpoint import load_predictor

    trained_on = load_predictor(GRAVITY_NN).joint_name
    model = "analytic" if trained_on == "analytic" else str(SURROGATE)
    if model != "analytic" and not (SURROGATE.is_file() and load_joint(model).name == trained_on):
        pytest.skip(f"NN trained on joint model {trained_on!r}, not the committed one")
    out = run_gesture_cli("--p1", "-0.1", "--p2", "0.1", "--model", model, "--method", "nn", "--json")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    ref = solve(GripperProblem(load_joint(model)), t([-0.1, 0.1])).tau[0].numpy()
    assert got["converged"] and max(got["residual_force_mN"]) <= 2.0
    np.testing.assert_allclose(np.array(got["tau"])[:, :2], ref[:, :2], atol=0.01)
    np.testing.assert_allclose(np.array(got["tau"])[:, 2], ref[:, 2], atol=1.0)
    # gravity: the answer is the network's own, so its raw residual is the residual
    assert (got["raw_residual_force_mN"], got["raw_residual_moment_Nmm"]) == \
        (got["residual_force_mN"], got["residual_moment_Nmm"])
    assert not got["polished"] and not got["fallback"]
    # gravity, --polish: one Newton step from the same tau reaches the solver's tolerance
    # and the cold solve's tau; the raw figures are the network's, as above
    out = run_gesture_cli("--p1", "-0.1", "--p2", "0.1", "--model", model, "--method", "nn", "--polish", "--json")
    assert out.returncode == 0, out.stderr
    pol = json.loads(out.stdout)
    assert pol["converged"] and pol["polished"] and max(pol["residual_force_mN"]) <= 1e-4
    np.testing.assert_allclose(np.array(pol["tau"]), ref, atol=1e-6)
    assert pol["raw_residual_force_mN"] == pytest.approx(got["raw_residual_force_mN"], rel=1e-9, abs=1e-12)
    # contact: the raw network's residual is reported beside the polished answer's
    out = run_gesture_cli("--p1", "0.1", "--p2", "0.2", "--object", "circle", "--model", model, "--method", "nn",
                          "--json")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["polished"] != got["fallback"] and max(got["residual_force_mN"]) <= 1e-4
    assert len(got["raw_residual_force_mN"]) == 2 and max(got["raw_residual_force_mN"]) > max(got["residual_force_mN"])


@pytest.mark.skipif(not (SURROGATE.is_file() and GRAVITY_NN.is_file()), reason="no committed surrogate and NN")
def test_gravity_nn_learns_one_finger_and_the_gripper_adds_the_plane():
    """A gravity network configured ``plane=False`` learns one finger alone
    (NNConfig.training_problem: the plane X = 0 off), a contact network the grasp with the
    plane either way. The committed gravity NN (written before the config recorded
    ``plane``, so read as one finger alone) on
    400 pressures of its domain: raw residual on one finger within the NN bound (mean 2 mN,
    1.2 N·mm); on the gripper the residual is the same (1e-12) where its outline stays at
    X >= 0, and only there does the delivered path answer with the network's own tau (90 %
    of those rows at least); every crossing row is ``at_plane``, finished by the polish
    (Newton steps, the LM where the check fails, the ramp where that stalls), so at least
    99 % of the box is answered; the polish finishes on the gripper's equilibrium, the
    solver's (tau within 1e-5 N, N·mm), the outline within 0.1 mm of X = 0."""
    from predictor.model.gripper import outline_vertices
    from predictor.nn.networks import VARIANTS, sample_pressures
    from predictor.nn.answer import predict_gesture
    from predictor.nn.checkpoint import load_predictor
    from predictor.nn.eval import evaluate
    from predictor.model.statics import meets

    for name in ("gravity-improved", "gravity-paper"):
        alone = dataclasses.replace(VARIANTS[name], plane=False)
        assert not meets(alone.training_problem(J)) and meets(alone.problem(J)), name
    assert VARIANTS["contact"].training_problem(J) == VARIANTS["contact"].problem(J)
    joint = load_joint(SURROGATE)
    pred = load_predictor(GRAVITY_NN, joint)
    assert not pred.config.learns_gripper()
    alone, gripper = pred.config.training_problem(joint), pred.config.problem(joint)
    p = sample_pressures(400, pred.config, torch.Generator().manual_seed(5))
    own = evaluate(pred.net, alone, p)
    assert own["force_mN_mean"] <= 2.0 and own["moment_Nmm_mean"] <= 1.2
    with torch.no_grad():
        tau = pred.net(p)
        a, g = alone.residual(p, tau), gripper.residual(p, tau)
    apart_rows = outline_vertices(a.pose, alone.params.layout)[..., 0].amin(-1) >= 0
    assert 100 <= int(apart_rows.sum()) <= 300     # the fingers meet over about half the box
    assert float((a.residual - g.residual)[apart_rows].abs().max()) <= 1e-12
    raw = predict_gesture(pred, gripper, p)
    own = raw.converged & ~raw.at_plane
    assert torch.equal(own, apart_rows & own) and int(own.sum()) >= 0.9 * int(apart_rows.sum())
    assert bool(raw.at_plane[~apart_rows].all()) and int(raw.converged.sum()) >= 0.99 * len(p)
    assert torch.equal(raw.polished, raw.at_plane & raw.converged)
    cross = p[~apart_rows][:8]
    pol = predict_gesture(pred, gripper, cross, polish=True)
    ref = solve(gripper, cross)
    assert bool(pol.converged.all()) and bool(ref.converged.all())
    assert float((pol.tau - ref.tau).abs().max()) <= 1e-5
    assert float(outline_vertices(pol.pose, gripper.params.layout)[..., 0].amin()) >= -0.1


@pytest.mark.skipif(not (SURROGATE.is_file() and GRAVITY_NN.is_file()), reason="no committed surrogate and NN")
def test_float32_batched_gravity_nn_agrees_with_float64():
    """The float32 throughput mode (Predictor.astype, GripperProblem.astype) on 2,000
    pressures of the committed gravity NN's domain: computed in float32 throughout, and
    against float64 the same samples pass the NN bound, and on those tau agrees to 1e-4
    N / N·mm, the fingertip to 1e-3 mm and the residuals to 1e-3 mN / N·mm (float32's 6e-8
    relative rounding on ~200 mm and ~1 N is 1e-5 of those). The network, which learns one
    finger alone, answers the gripper only where the fingers stay apart (1,052 of the
    2,000; where its finger crosses X = 0 the plane's penalty puts the residual far over
    the bound, docs/gripper.md §11), so the refused samples' residuals are compared only
    through the verdict."""
    from predictor.nn.networks import sample_pressures
    from predictor.nn.answer import predict_gesture
    from predictor.nn.checkpoint import load_predictor

    pred = load_predictor(GRAVITY_NN, load_joint(SURROGATE))
    if pred.joint_name != load_joint(SURROGATE).name:
        pytest.skip("the gravity NN was trained on another joint model")
    problem = pred.config.problem(load_joint(SURROGATE))
    p = sample_pressures(2000, pred.config, torch.Generator().manual_seed(11))
    a = predict_gesture(pred, problem, p, polish=False)   # the raw network: float32 has no polish
    b = predict_gesture(pred.astype(torch.float32), problem.astype(torch.float32), p.float(), polish=False)
    assert b.tau.dtype == b.pose.tip_end.dtype == b.residual_force_mN.dtype == torch.float32
    assert torch.equal(a.converged, b.converged) and int(a.converged.sum()) >= 1000
    ok = a.converged
    assert float((a.tau[ok] - b.tau[ok].double()).abs().max()) <= 1e-4
    assert float((a.pose.tip_end[ok] - b.pose.tip_end[ok].double()).abs().max()) <= 1e-3
    assert float((a.residual_force_mN[ok] - b.residual_force_mN[ok].double()).abs().max()) <= 1e-3
    assert float((a.residual_moment_Nmm[ok] - b.residual_moment_Nmm[ok].double()).abs().max()) <= 1e-3
    # the analytic joint follows its inputs' dtype: its float32 anchors are float64's to 1e-4 mm
    inputs = t([[0.2, 1.0, -2.0, 50.0], [-0.3, -3.0, 3.0, -100.0]])
    a32 = AnalyticJoint().astype(torch.float32)(inputs.float())
    assert a32.dtype == torch.float32 and float((a32.double() - J(inputs)).abs().max()) <= 1e-4


def test_nn_for_another_finger(tmp_path):
    """An NN config moved to the three-joint finger (NNConfig.for_params) trains a 3 -> 9
    network; its checkpoint records the finger and options and loads back with them, and
    loading it for the paper finger (or other options) is refused with one line; an old
    checkpoint without the fields means the paper finger and chain (tangent, lumped)."""
    from predictor.nn.networks import NNConfig
    from predictor.nn.checkpoint import load_predictor, save_predictor
    from predictor.nn.train import train

    params = GripperParams(THREE_FINGER, kinematics="tangent", joint_weight="split")
    cfg = NNConfig(n_train=60, n_val=20, epochs=1).for_params(params)
    assert cfg.widths[0] == 3 and cfg.widths[-1] == 9 and cfg.params() == params
    pred = train(cfg, J)
    assert pred.net(THREE_P).shape == (3, 3, 3)
    path = tmp_path / "three.pt"
    save_predictor(pred, path)
    back = load_predictor(path, J, params=params)
    assert back.config.params() == params
    with pytest.raises(ValueError, match="was trained for finger 'three', tangent kinematics, split joint weights, "
                                         f"{DEFAULT_OUTLINE} outline, not finger 'paper', cap kinematics, split joint weights"):
        load_predictor(path, J, params=GripperParams())
    assert NNConfig().params() == GripperParams()
    # a checkpoint written before the chain options were recorded: the paper's chain
    from dataclasses import asdict

    from predictor.nn.checkpoint import checkpoint_kind
    from surrogate import checkpoint

    old = train(NNConfig(n_train=60, n_val=20, epochs=1), J)
    old_path = tmp_path / "old.pt"
    payload = {"config": {k: v for k, v in asdict(old.config).items() if k not in ("kinematics", "joint_weight")},
               "state_dict": old.net.state_dict(), "joint": old.joint_name, "metrics": old.metrics,
               "history": old.history}
    checkpoint.save(old_path, checkpoint_kind(False), payload)
    with pytest.raises(ValueError, match="not finger 'paper', cap kinematics"):
        load_predictor(old_path, J, params=GripperParams())
    assert load_predictor(old_path, J, params=PAPER_CHAIN).config.params() == PAPER_CHAIN


@pytest.mark.skipif(not (SURROGATE.is_file() and (ROOT / "results/predictor/contact_nn.pt").is_file()),
                    reason="no committed surrogate or NN checkpoints")
def test_bench_writes_every_required_key(tmp_path):
    """``python -m predictor.validation.bench --quick`` (a few samples per figure, the committed models)
    writes every top-level figure issues 5 and 15 require as a finite number, and figures
    that agree with their details: the batched rates are converged gestures over measured seconds, and
    the fast contact path's misses and times add up to its cases. Physics: every gravity
    Newton solve converged to the solver's 1e-4 mN / 1e-5 N·mm, the polished contact NN (a
    solver result) to the issue's 0.1 mN / 0.01 N·mm, and no answer of the Newton steps
    from the contact NN that the branch check kept is another equilibrium than the ramp's."""
    from predictor.validation import bench

    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "predictor.validation.bench", "--quick", "--model", str(SURROGATE),
                          "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    b = json.loads(out.read_text())
    for key in bench.REQUIRED_KEYS:
        assert isinstance(b[key], (int, float)) and math.isfinite(b[key]), key
    cb = b["details"]["contact_batched"]
    assert cb["converged"] <= cb["n"] and abs(b["contact_ramp_batched_per_s"] - cb["converged"] / cb["s"]) < 1e-9
    through = b["details"]["contact_throughput"]   # the delivered path's batch, to two tolerances
    assert through["n"] == bench.QUICK["contact_throughput"] and through["threads"] == os.cpu_count()
    assert b["contact_batched_per_s"] == through["issue_bound"]["per_s"] and b["graphs"] == "trace"
    for key, (force, moment) in (("issue_bound", (0.1, 0.01)), ("solver_tolerance", (1e-4, 1e-5))):
        r = through[key]
        assert r["converged"] == through["n"] and abs(r["per_s"] - r["converged"] / (r["ms"] / 1e3)) < 1e-6
        assert r["max_residual_force_mN"] <= force and r["max_residual_moment_Nmm"] <= moment
    fast = b["details"]["contact_fast"]
    assert fast["n"] == bench.QUICK["contact"] and 0 <= fast["misses"] < fast["n"]
    assert 0.0 <= b["contact_nn_state_agreement"] <= 1.0
    assert b["contact_nn_raw_p95_force_mN"] >= 0.0 and b["gravity_batched_per_s"] > 0.0
    assert (b["batched_dtype"], b["batched_threads"]) == ("float32", os.cpu_count())
    thr = b["details"]["gravity_nn_throughput"]
    assert thr["one_thread"]["dtype"] == "float64" and thr["one_thread"]["threads"] == 1
    assert b["gravity_batched_per_s"] == thr["every_core"]["delivered_per_s"]
    gf = b["details"]["gravity_fast"]
    assert gf["n"] == bench.QUICK["gravity"] and gf["misses"] == 0 and gf["max_residual_force_mN"] <= 1e-4
    g = b["details"]["gravity_newton"]
    assert g["converged"] == g["n"] == bench.QUICK["gravity"]
    assert g["max_residual_force_mN"] <= 1e-4 and g["max_residual_moment_Nmm"] <= 1e-5
    assert b["contact_nn_residual_force_mN"] <= 0.1 and b["contact_nn_residual_moment_Nmm"] <= 0.01
    steps = b["details"]["contact_nn_vs_solver"]["newton_from_raw"]   # no kept answer off the ramp's branch
    assert steps["kept_elsewhere"] == 0 and steps["kept"] <= steps["converged_to_ramp_equilibrium"]
    assert 0.0 <= b["contact_nn_newton_rate"] <= 1.0 and fast["newton_from_nn"] + fast["fallbacks"] <= fast["n"]


def test_contact_net_answers_from_the_head_of_its_state(tmp_path):
    """ContactNet's tau for each pressure is exactly the output of the head its classifier
    picks plus that head's correction stages (random weights, so every state occurs on 200
    pressures and every stage adds something), and its checkpoint round-trips bit for bit."""
    from predictor.nn.networks import VARIANTS, ContactNet, features, network, Predictor
    from predictor.nn.checkpoint import load_predictor, save_predictor

    cfg = VARIANTS["contact"]
    torch.manual_seed(5)   # a seed whose random classifier picks all three states
    net = network(cfg)
    assert isinstance(net, ContactNet)
    p = (2 * torch.rand(200, 2, dtype=torch.float64) - 1) * 0.3
    # every network sees P / 0.3 and |P| / 0.3 (the joint model's kink at P = 0)
    assert cfg.abs_pressure and torch.equal(features(p, True), torch.cat((p / 0.3, (p / 0.3).abs()), 1))
    assert {m.mlp[0].in_features for m in [*net.heads, *(s for r in net.refine for s in r)]} == {4}
    assert net.classifier[0].in_features == 4
    with torch.no_grad():
        net.classifier[-1].weight.mul_(100.0)  # an untrained classifier's logits barely vary
        state, tau = net.state(p), net(p)
        assert set(state.tolist()) == {0, 1, 2}
        for k, head in enumerate(net.heads):
            rows = p[state == k]
            assert torch.equal(tau[state == k], net.head_tau(k, rows))
            stages = [stage(rows) for stage in net.refine[k]]
            assert len(stages) == cfg.refine_stages and all(bool(c.abs().min() > 0) for c in stages)
            assert torch.allclose(tau[state == k], head(rows) + sum(stages), rtol=0, atol=1e-12)
    save_predictor(Predictor(net, cfg, J.name), tmp_path / "c.pt")
    back = load_predictor(tmp_path / "c.pt", J, contact=True)
    with torch.no_grad():
        assert isinstance(back.net, ContactNet) and torch.equal(back.net(p), tau)


@pytest.mark.skipif(not (SURROGATE.is_file() and CONTACT_NN.is_file()), reason="no committed contact NN")
def test_contact_nn_raw_residual_and_state_on_a_fixed_set():
    """The committed contact NN on 60 fixed pressures of its domain (seed 5; 50 end in
    contact), against the ramp solver (the reference): its classifier's grasp state is the
    solver's on at least 57 (the bench's 400 give the >= 99 % figure); with no solver its
    raw tau meets the issue's bounds over every equilibrium, contact or not (mean <= 2 mN,
    1.2 N·mm; p95 <= 10 mN, 5 N·mm; 0.96 mN, 0.13 N·mm mean when written), is within
    1e-3 mN at every contact-free one, and its fingertip is within 2 µm of the solver's on
    average. One closed-form Gauss-Newton step (exact Jacobian, no iteration or check)
    from it cuts the mean force residual at least tenfold."""
    from predictor.nn.networks import sample_pressures
    from predictor.nn.checkpoint import load_predictor
    from predictor.nn.eval import evaluate_contact

    joint = load_joint(SURROGATE)
    pred = load_predictor(CONTACT_NN, joint, contact=True)
    p = sample_pressures(60, pred.config, torch.Generator().manual_seed(5))
    ev = evaluate_contact(pred, joint, p)
    assert ev["reference_converged"] == 60 and ev["state_by"] == "classifier"
    assert ev["state_agreement"] >= 57 / 60
    raw, free, step = ev["raw"], ev["raw_contact_free"], ev["newton_step_from_raw"]
    assert raw["force_mN_mean"] <= 2.0 and raw["moment_Nmm_mean"] <= 1.2
    assert raw["force_mN_p95"] <= 10.0 and raw["moment_Nmm_p95"] <= 5.0
    assert free is not None and free["force_mN_max"] <= 1e-3
    assert ev["raw_tip_error_mm"]["mean"] <= 0.002
    assert step["force_mN_mean"] <= raw["force_mN_mean"] / 10


@pytest.mark.skipif(not (SURROGATE.is_file() and CONTACT_NN.is_file()), reason="no committed contact NN")
def test_contact_nn_newton_answers_are_the_ramps_equilibria(monkeypatch):
    """The delivered contact NN path on 24 fixed pressures of its domain (seed 11): every
    answer converges to the solver's tolerances; the answers of the Newton steps from the
    network's tau (``stepped``: most of them; 95 % on the 400 validation pressures) are
    the ramp solver's equilibria (tau within 1e-4 N, 1e-4 N·mm), not another branch's.
    With the branch check made impossible (BRANCH_TIP_MM = -1) nothing is stepped and
    the capped LM answers the same equilibria."""
    import predictor.nn.answer as answer
    from predictor.nn.checkpoint import load_predictor
    from predictor.nn.networks import sample_pressures

    joint = load_joint(SURROGATE)
    pred = load_predictor(CONTACT_NN, joint, contact=True)
    problem = pred.config.problem(joint)
    p = sample_pressures(24, pred.config, torch.Generator().manual_seed(11))
    ref = solve(problem, p)
    res = answer.predict_gesture(pred, problem, p)
    assert bool(ref.converged.all()) and bool(res.converged.all())
    # method: "nn+newton", joined with "lm" where the capped LM answered rows
    assert int(res.stepped.sum()) >= 12 and res.method == ("nn+newton" if bool(res.stepped.all()) else "nn+newton+lm")
    assert torch.allclose(res.tau, ref.tau, rtol=0, atol=1e-4)
    # a stepped answer took Newton steps, or the network's own tau met the tolerances already
    # (contact-free raw residuals reach 1e-4 mN)
    raw_done = (res.raw_residual_force_mN.amax(-1) <= 1e-4) & (res.raw_residual_moment_Nmm.amax(-1) <= 1e-5)
    assert bool(((res.iterations >= 1) | raw_done)[res.stepped].all())
    monkeypatch.setattr(answer, "BRANCH_TIP_MM", -1.0)
    lm = answer.predict_gesture(pred, problem, p[:6])
    assert not bool(lm.stepped.any()) and bool(lm.converged.all()) and lm.method == "nn+lm"
    assert torch.allclose(lm.tau, ref.tau[:6], rtol=0, atol=1e-4)


# ---------------------------------------------------------------- issue 55 §3: the problem a gravity NN learns and answers
def test_gravity_nn_learns_the_problem_its_config_records(tmp_path):
    """NNConfig.plane (default False) is the problem a gravity network's labels are of:
    every gravity variant learns one finger alone (statics.apart, as the paper's), and
    answers the gripper (its ``problem``, the plane X = 0 on); plane=True
    (``predictor.cli.nn --plane``) learns the gripper itself; a contact network learns the
    grasp with the plane either way. The checkpoint records it; one written before it was
    recorded reads as what it was trained on: a gravity checkpoint one finger alone, a
    contact checkpoint the grasp with the plane."""
    from dataclasses import asdict

    from predictor.nn.networks import VARIANTS, NNConfig
    from predictor.nn.checkpoint import checkpoint_kind, load_predictor, save_predictor
    from predictor.nn.train import train
    from predictor.model.statics import apart, meets
    from surrogate import checkpoint

    for name in ("gravity-improved", "gravity-paper"):
        cfg = VARIANTS[name]
        assert not cfg.plane and not cfg.learns_gripper() and cfg.training_problem(J) == apart(cfg.problem(J)), name
        assert meets(cfg.problem(J)), name   # it answers the gripper
        gripper = dataclasses.replace(cfg, plane=True)
        assert gripper.learns_gripper() and gripper.training_problem(J) == gripper.problem(J), name
    contact = VARIANTS["contact"]
    assert contact.plane and contact.learns_gripper() and contact.training_problem(J) == contact.problem(J)
    contact = dataclasses.replace(contact, plane=False)
    assert contact.learns_gripper() and contact.training_problem(J) == contact.problem(J)

    for plane in (True, False):
        pred = train(NNConfig(n_train=60, n_val=20, epochs=1, plane=plane), J)
        path = tmp_path / f"{plane}.pt"
        save_predictor(pred, path)
        assert load_predictor(path, J).config.plane is plane
    # written before ``plane`` was recorded: a gravity network learned one finger alone
    payload = {"config": {k: v for k, v in asdict(pred.config).items() if k != "plane"},
               "state_dict": pred.net.state_dict(), "joint": pred.joint_name, "metrics": pred.metrics,
               "history": pred.history}
    old = tmp_path / "old.pt"
    checkpoint.save(old, checkpoint_kind(False), payload)
    back = load_predictor(old, J)
    assert back.config.plane is False and not meets(back.config.training_problem(J))
    checkpoint.save(old, checkpoint_kind(True), {**payload, "config": {**payload["config"],
                                                                        "obstacle": VARIANTS["contact"].obstacle}})
    assert load_predictor(old, J, contact=True).config.plane is True


def test_nn_outline_enters_only_a_network_that_learned_the_gripper(tmp_path):
    """The joints' outline (band or bulged) is part of the problem only where the plane or
    an object touches the finger: a gravity network learned one finger alone loads for
    either outline and answers (is polished on) the one asked for; a network that learned
    the gripper is refused for another outline with one line naming both; a checkpoint
    written before the outline was recorded learned the band."""
    from dataclasses import asdict

    from predictor.nn.checkpoint import checkpoint_kind, load_predictor, save_predictor
    from predictor.nn.networks import NNConfig
    from predictor.nn.train import train
    from surrogate import checkpoint

    band, bulged = GripperParams(outline="band"), GripperParams(outline="bulged")
    apart_path, gripper_path = tmp_path / "apart.pt", tmp_path / "gripper.pt"
    save_predictor(train(NNConfig(n_train=60, n_val=20, epochs=1).for_params(band), J), apart_path)
    for params in (band, bulged):
        cfg = load_predictor(apart_path, J, params=params).config
        assert cfg.params() == params and cfg.problem(J).params.outline == params.outline
    gripper = train(NNConfig(n_train=60, n_val=20, epochs=1, plane=True).for_params(bulged), J)
    save_predictor(gripper, gripper_path)
    assert load_predictor(gripper_path, J, params=bulged).config.params() == bulged
    with pytest.raises(ValueError, match="split joint weights, bulged outline, not finger 'paper', cap kinematics, "
                                         "split joint weights, band outline"):
        load_predictor(gripper_path, J, params=band)
    payload = {"config": {k: v for k, v in asdict(gripper.config).items() if k != "outline"},
               "state_dict": gripper.net.state_dict(), "joint": gripper.joint_name, "metrics": gripper.metrics,
               "history": gripper.history}
    checkpoint.save(gripper_path, checkpoint_kind(False), payload)
    assert load_predictor(gripper_path, J).config.outline == "band"


@pytest.mark.skipif(not (GRAVITY_NN.is_file() and (ROOT / "results/predictor/contact_nn.pt").is_file()),
                    reason="no committed NN checkpoints")
def test_committed_nn_checkpoints_read_as_the_problem_they_learned():
    """The committed checkpoints were written before the config recorded ``plane``: the
    gravity networks read as one finger alone (their labels and equilibrium loss had the
    plane off), the contact network as the grasp with the plane (its labels had it on)."""
    from predictor.nn.checkpoint import load_predictor

    for name in ("gravity_nn.pt", "gravity_nn_paper.pt"):
        cfg = load_predictor(GRAVITY_NN.parent / name).config
        assert cfg.plane is False and not cfg.learns_gripper(), name
    assert load_predictor(GRAVITY_NN.parent / "contact_nn.pt", contact=True).config.learns_gripper()


def test_gravity_nn_trained_on_the_gripper_stays_on_its_side_of_the_plane():
    """On the analytic joint, the improved architecture (narrowed) trained briefly on 120
    Newton labels of the gripper (the default, plane X = 0 on) and of one finger alone
    (plane=False), judged at six pressures where one finger alone crosses X = 0 by 27-143
    mm. The gripper-trained network's own gesture crosses X = 0 by at most 3 mm (the
    solver's equilibria by <= 0.1 mm) and its tip is within 6 mm of the Newton solver's
    gripper answer (5.6 mm at (0.25, -0.05) MPa when written); the lone-finger network's
    crosses by over 25 mm and misses the tip by over 40 mm, and its residual on the gripper is over 30 times the gripper-trained one's.
    Neither meets the raw NN bound (2 mN) there: at the gripper's equilibrium the
    residual's Jacobian dR/dtau has a singular value over 1e4 (the stiff plane pressed by
    the finger; one finger alone: all below 10), so a tau error of 1e-6 N is a residual
    over 10 mN."""
    from predictor.nn.networks import VARIANTS
    from predictor.nn.train import train
    from predictor.model.statics import apart, plane_overlap

    gripper = GripperProblem(J)
    q = t([[0.1, -0.1], [0.1, 0.1], [0.15, 0.0], [0.2, 0.2], [0.0, 0.25], [0.25, -0.05]])
    ref, lone = solve(gripper, q), solve(apart(gripper), q)
    assert bool(ref.converged.all()) and bool(lone.converged.all())
    from predictor.model.gripper import outline_vertices

    assert float(plane_overlap(outline_vertices(lone.pose, gripper.params.layout)).min()) >= 25.0
    assert float(plane_overlap(outline_vertices(ref.pose, gripper.params.layout)).max()) <= 0.1
    small = dataclasses.replace(VARIANTS["gravity-improved"], widths=(2, 64, 64, 6), n_train=120, n_val=20,
                                epochs=30, batch=40, lbfgs_iters=200, plane=True)
    got = {}
    for plane in (True, False):
        net = train(dataclasses.replace(small, plane=plane), J).net
        with torch.no_grad():
            st = gripper.residual(q, net(q))
        got[plane] = (plane_overlap(st.vertices), (st.pose.tip_end - ref.pose.tip_end).norm(dim=-1),
                      st.residual[..., :2].norm(dim=-1).amax(-1) * 1e3)
    (cross, tip, res), (cross_alone, tip_alone, res_alone) = got[True], got[False]
    assert float(cross.max()) <= 3.0 and float(tip.max()) <= 6.0
    assert float(cross_alone.min()) >= 25.0 and float(tip_alone.min()) >= 40.0
    assert bool((res_alone >= 30 * res).all()) and bool((res > 2.0).all())
    i = 3   # (0.2, 0.2) MPa
    f = lambda problem: lambda x: problem.residual(q[i:i + 1], x.reshape(1, 2, 3)).residual.reshape(-1)  # noqa: E731
    stiff = torch.linalg.svdvals(torch.autograd.functional.jacobian(f(gripper), ref.tau[i].reshape(-1)))
    free = torch.linalg.svdvals(torch.autograd.functional.jacobian(f(apart(gripper)), lone.tau[i].reshape(-1)))
    assert float(stiff.max()) >= 1e4 and float(free.max()) <= 10.0


class _TableNet(torch.nn.Module):
    """A stand-in gravity network: the tau (n, J, 3) stored for each of n pressures (n, J),
    answered for the nearest stored pressure."""

    def __init__(self, pressures: torch.Tensor, tau: torch.Tensor):
        super().__init__()
        self.register_buffer("p", pressures)
        self.register_buffer("tau", tau)

    def forward(self, pressures: torch.Tensor) -> torch.Tensor:
        return self.tau[(pressures[:, None, :] - self.p[None]).abs().amax(-1).argmin(1)]


def test_gravity_nn_gesture_at_the_plane_is_its_polish():
    """The delivered gravity path (predict_gesture, polish None) with a network standing in as the Newton solver's equilibria plus 1e-5 in every tau
    component, at three pressures whose gestures stay 15 mm from X = 0 and five where the
    finger presses on it (0.003-0.054 mm deep). Away from the plane the raw residual is
    0.015 mN, within the NN bound: the answer is the network's own tau (method nn, 0
    iterations, not polished). On the plane the same 1e-5 error is a residual of 9.5-164 mN
    and 1.3-20 N·mm (the plane's stiff penalty): each of those is ``at_plane``, finished by
    the Newton step (and the LM where its check fails, (0.15, 0) MPa), reported polished
    with its raw residual kept, and equals the Newton solver's tau to 1e-8 (its tip to 1e-6
    mm; the raw rows' tips are 1e-3 mm off). polish=False is
    the raw network alone (no answer on the plane); the answer depends on the network's tau
    only, not on the problem it learned (the same table configured to have learned one
    finger alone gives the same answer); polish=True finishes every row."""
    from predictor.nn.networks import VARIANTS, Predictor
    from predictor.nn.answer import NN_FORCE_TOL_MN, predict_gesture

    q = t([[-0.1, 0.1], [0.0, 0.0], [-0.3, -0.3], [0.1, -0.1], [0.1, 0.1], [0.2, 0.2], [0.15, 0.0], [0.0, 0.25]])
    free, plane = torch.arange(8) < 3, torch.arange(8) >= 3
    ref = solve(GRAVITY, q)
    assert bool(ref.converged.all()) and bool((ref.plane_overlap_mm[free] == 0).all())
    assert 0.002 <= float(ref.plane_overlap_mm[plane].min()) and float(ref.plane_overlap_mm[plane].max()) <= 0.06
    pred = Predictor(_TableNet(q, ref.tau + 1e-5), VARIANTS["gravity-improved"], "analytic")
    res = predict_gesture(pred, GRAVITY, q)
    raw_f = res.raw_residual_force_mN.amax(-1)
    assert bool(res.converged.all()) and torch.equal(res.at_plane, plane) and torch.equal(res.polished, plane)
    assert float(raw_f[free].max()) <= 0.02 and float(raw_f[plane].min()) >= 4 * NN_FORCE_TOL_MN
    assert torch.equal(res.tau[free], ref.tau[free] + 1e-5) and bool((res.iterations[free] == 0).all())
    assert torch.equal(res.residual_force_mN[free], res.raw_residual_force_mN[free])
    assert float((res.tau[plane] - ref.tau[plane]).abs().max()) <= 1e-8
    assert float(res.residual_force_mN[plane].max()) <= 1e-4 and bool((res.iterations[plane] >= 1).all())
    tip = (res.pose.tip_end - ref.pose.tip_end).norm(dim=-1)   # mm: the raw 1e-5 moves the tip ~1e-3 mm
    assert float(tip[free].max()) <= 2e-3 and float(tip[plane].max()) <= 1e-6
    assert res.method == "nn+newton+lm" and bool(res.fallback[6])
    assert float((res.plane_overlap_mm[plane] - ref.plane_overlap_mm[plane]).abs().max()) <= 1e-6
    raw = predict_gesture(pred, GRAVITY, q, polish=False)
    assert torch.equal(raw.converged, free) and not bool(raw.at_plane.any()) and raw.method == "nn"
    alone = Predictor(pred.net, dataclasses.replace(pred.config, plane=False), "analytic")
    same = predict_gesture(alone, GRAVITY, q)
    assert torch.equal(same.tau, res.tau) and torch.equal(same.at_plane, res.at_plane)
    every = predict_gesture(pred, GRAVITY, q, polish=True)
    assert bool(every.converged.all()) and bool(every.polished.all()) and every.at_plane is None
    assert float((every.tau - ref.tau).abs().max()) <= 1e-7   # each within the solver tolerance


def test_gravity_nn_cli_answers_at_the_plane_polished(tmp_path):
    """predictor.cli.gesture --method nn with a small gravity network trained on the gripper
    (plane=True, ``predictor.cli.nn --plane``; analytic joint, 120 labels, widths 2-64-64-6;
    written by predictor.cli.nn's save): at
    (0.1, 0.1) MPa its own gesture crosses X = 0 (raw residual thousands of mN), so the
    answer is its tau polished, exit 0, the JSON says polished and at_plane with the raw
    residual beside the answer's, and tau is the Newton solver's to 1e-6; at (0, 0) its
    gesture is 15 mm from X = 0 and its residual (~6 mN) outside the bound: no answer,
    exit 1, and the stderr line names --polish."""
    from predictor.nn.networks import VARIANTS
    from predictor.nn.checkpoint import save_predictor
    from predictor.nn.train import train

    small = dataclasses.replace(VARIANTS["gravity-improved"], widths=(2, 64, 64, 6), n_train=120, n_val=20,
                                epochs=30, batch=40, lbfgs_iters=200, plane=True)
    path = tmp_path / "gripper.pt"
    save_predictor(train(small, J), path)

    def gesture(*args):   # a polish beside other jobs can outlast run_gesture_cli's 60 s
        return subprocess.run([sys.executable, "-m", "predictor.cli.gesture", *args, "--model", "analytic", "--method",
                               "nn", "--nn", str(path), "--json"], cwd=ROOT, capture_output=True, text=True,
                              timeout=600)

    out = gesture("--p1", "0.1", "--p2", "0.1")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["converged"] and got["polished"] and got["at_plane"] and got["nn_problem"] == "gripper"
    assert got["method"].startswith("nn+newton") and max(got["residual_force_mN"]) <= 1e-4
    assert min(got["raw_residual_force_mN"]) >= 1e3 and got["plane_overlap_mm"] <= 0.1
    ref = solve(GRAVITY, t([[0.1, 0.1]]))
    np.testing.assert_allclose(np.array(got["tau"]), ref.tau[0].numpy(), atol=1e-6)
    bad = gesture("--p1", "0", "--p2", "0")
    assert bad.returncode == 1, bad.stderr
    got = json.loads(bad.stdout)
    assert not got["converged"] and not got["at_plane"] and not got["polished"] and got["tau"] is None
    line = bad.stderr.strip()
    assert "\n" not in line and line.startswith("python -m predictor.cli.gesture: the gravity NN's own answer is outside "
                                                "its bound"), line
    assert line.endswith("; --polish finishes it with a Newton step; no gesture returned"), line
