"""Tests of the multi-fidelity surrogate (surrogate.multifidelity) on small exact datasets.

The coarse set is the analytic rod of surrogate.synthetic; its "coarse surrogate" is an
untrained, seeded JointSurrogate (any frozen model will do). The fine sets are built so
that fine(x) = coarse_surrogate(x) + g(x) exactly, with g a known smooth, mirror-
equivariant function (anchors mm, cap rotation rad) and its Jacobian taken by autograd
independently of the module. So the correction's targets are g itself:

- the multi-fidelity model recovers g: its held-out error is far below the coarse
  surrogate's (which is |g|), and R_C + R_D keeps the mirror symmetry bit for bit;
- the correction's Jacobian target is the fine Jacobian minus the coarse surrogate's
  autograd Jacobian (dg/dx here);
- the equal-cost arithmetic m = round(n + N_c c_c / c_f), against numbers worked by hand;
- a re-run keeps every finished point, --max-hours stops before training (exit 3);
- bad input (missing or foreign sets, a held-out set sharing a walk or another
  discretisation, a coarse model of another set, sizes beyond the pool, no CPU hours)
  exits 2 with one line and writes nothing.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from contract.spec import INPUT_BOX, INPUT_MIRROR, N_ANCHORS, phi_end
from surrogate import learning_curve as lc
from surrogate import multifidelity as mf
from surrogate import synthetic
from surrogate.data import Samples, load_samples, normalisation
from surrogate.evaluate import jacobian
from surrogate.model import JointSurrogate, load_surrogate, save_checkpoint
from surrogate.train import CONFIGS
from workflow import shards

FINE_CONFIG = {"source": "synthetic-rod", "level": "fine"}
K = torch.arange(1, N_ANCHORS + 1, dtype=torch.float64)


def g(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The known fine-minus-coarse difference: anchors (n, 10, 2) mm, cap (n,) rad. Even
    in (P, F2, M) for x, odd for y and the cap, as the mirror y -> -y requires."""
    z = x / torch.as_tensor(INPUT_BOX)
    p, f1, f2, m = z.unbind(-1)
    gx = 0.05 * K * (p ** 2 + 0.5 * f1 + 0.3 * m ** 2)[:, None]
    gy = 0.04 * K * ((m + 0.5 * f2 - 0.4 * p) * (1 + 0.3 * f1))[:, None]
    return torch.stack([gx, gy], -1), 0.02 * (m + p)


def write_set(root, inputs, anchors, jac, cap, seed, config, cpu_hours):
    """One-shard dataset with a manifest that records its CPU hours."""
    n = len(inputs)
    arrays = shards.empty_arrays() | {
        "sample_id": np.arange(n, dtype=np.int64), "inputs": inputs, "anchors": anchors, "jacobian": jac,
        "phi_end": phi_end(anchors), "cap_rotation": cap, "newton_iterations": np.ones(n, np.int64),
        "wall_time_s": np.ones(n), "converged": np.ones(n, bool)}
    file = "shards/unit-00000.npz"
    sha = shards.write_shard(root / file, arrays, {"config": config, "seed": seed, "unit": 0})
    shards.Manifest(seed=seed, config=config, shards=(shards.ShardEntry(file=file, sha256=sha, n=n),),
                    cpu_hours=cpu_hours).save(root)
    return root


def fine_set(root, coarse, n, seed, config=FINE_CONFIG, cpu_hours=0.4):
    """fine(x) = coarse(x) + g(x) at n uniform loads (seeded), with exact Jacobians."""
    x = torch.as_tensor(np.random.default_rng(seed).uniform(-1, 1, (n, 4)) * INPUT_BOX)
    with torch.no_grad():
        r, c = coarse.with_cap(x)
    dr, dc = g(x)
    dg = torch.autograd.functional.jacobian(lambda a: g(a)[0].reshape(len(a), -1).sum(0), x).permute(1, 0, 2)
    jac = jacobian(coarse, x) + dg
    return write_set(root, x.numpy(), (r + dr).numpy(), jac.numpy(), (c + dc).numpy(), seed, config, cpu_hours)


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    """Coarse rod set (160, seed 3, 0.1 CPU h), its seeded untrained surrogate, a fine set
    (160, seed 5, 0.4 CPU h: 9 s per sample) and a fine held-out set (96, seed 6)."""
    root = tmp_path_factory.mktemp("mf")
    coarse = synthetic.write_dataset(root / "coarse", 160, seed=3)
    manifest = dataclasses.replace(shards.Manifest.load(coarse), cpu_hours=0.1)
    manifest.save(coarse)
    torch.manual_seed(7)
    model_cfg = CONFIGS["improved"][0]
    model = JointSurrogate(model_cfg, normalisation(load_samples(coarse)[0], "absolute")).to(torch.float64)
    ckpt = root / "coarse.pt"
    save_checkpoint(ckpt, model, {"name": "untrained"}, {},
                    {"root": str(coarse), "seed": manifest.seed, "config": manifest.config})
    model = load_surrogate(ckpt)
    return {"coarse": coarse, "model": ckpt, "net": model, "root": root,
            "fine": fine_set(root / "fine", model, 160, seed=5),
            "heldout": fine_set(root / "heldout", model, 96, seed=6)}


def _args(sets, out, extra=()):
    return ["--coarse", str(sets["coarse"]), "--fine", str(sets["fine"]), "--heldout", str(sets["heldout"]),
            "--coarse-model", str(sets["model"]), "--out", str(out), *extra]


@pytest.fixture
def cheap_baseline(monkeypatch):
    """The fine-only baseline at a tiny budget (its rule is learning_curve's, tested there)."""
    monkeypatch.setattr(mf, "fine_only_configs", lambda n, seed, steps, joint=None: lc.point_configs(
        "improved", ["hidden=8", "epochs=2"], n, True, seed, 2, joint))


def test_equal_cost_arithmetic():
    # the committed 1.8 mm train set (9.9489 CPU h) against the 1.697:0.849 set (3.1821 h / 256)
    c_f = 3600 * 3.1821 / 256                                   # 44.748 s per fine sample
    assert mf.equal_cost_samples(100, 9.9489, c_f) == 900       # 100 + 35,816.0 / 44.748 = 900.4
    assert mf.equal_cost_samples(0, 1.0, 36.0) == 100
    assert mf.equal_cost_samples(7, 0.0, 10.0) == 7
    cost = {"coarse_h": 1.0, "fine_s": 36.0}
    assert mf.point_cost("multifidelity", 50, cost) == pytest.approx(1.5)
    assert mf.point_cost("fine_only", 150, cost) == pytest.approx(1.5)   # equal cost, m = 150
    # jobs: per size the MF point, fine-only on n, fine-only at min(m, pool)
    assert mf.plan(120, (50, "all"), lambda n: n + 100) == [
        ("multifidelity", 50), ("fine_only", 50), ("fine_only", 120), ("multifidelity", 120)]
    points = [{"kind": "multifidelity", "samples": 50, "cpu_hours": 1.5, "scale_only": None,
               **dict.fromkeys(mf.ERRORS, 0.1)},
              {"kind": "fine_only", "samples": 120, "cpu_hours": 1.2, **dict.fromkeys(mf.ERRORS, 0.3)}]
    (r,) = mf.comparison(points, 120, cost, None)
    assert (r["equal_cost_fine_samples"], r["fine_only_samples"], r["m_exceeds_data"]) == (150, 120, True)
    assert r["fine_only_cpu_hours"] == pytest.approx(1.2) and r["fine_only"]["heldout_tip_error_mm"] == 0.3
    (r,) = mf.comparison(points, 400, cost, None)
    assert (r["fine_only_samples"], r["m_exceeds_data"], r["fine_only"]) == (150, False, None)


def test_reference_curve_interpolates_log_log():
    doc = {"points": [{"samples": s, "seed": 0, "jacobian_loss": True, "heldout_mean_anchor_error_mm": e,
                       "heldout_tip_error_mm": 2 * e, "heldout_cap_rotation_error_deg": None}
                      for s, e in ((100, 0.1), (400, 0.025))]
                     + [{"samples": 200, "seed": 0, "jacobian_loss": False, "heldout_mean_anchor_error_mm": 9.0,
                         "heldout_tip_error_mm": 9.0, "heldout_cap_rotation_error_deg": 9.0}]}
    at = mf.interpolate_curve(doc, 200)          # halfway in log: sqrt(0.1 * 0.025) = 0.05
    assert at["heldout_mean_anchor_error_mm"] == pytest.approx(0.05)
    assert at["heldout_tip_error_mm"] == pytest.approx(0.1) and at["heldout_cap_rotation_error_deg"] is None
    assert mf.interpolate_curve(doc, 400)["heldout_mean_anchor_error_mm"] == pytest.approx(0.025)
    assert mf.interpolate_curve(doc, 401) is None and mf.interpolate_curve(doc, 99) is None


def test_scales_of_an_exactly_scaled_coarse_model_are_recovered(sets):
    """fine = R_C + rho* u_C and theta_C (1 + rho_theta*) exactly: fit_scale returns rho*."""
    net = sets["net"]
    x = torch.as_tensor(np.random.default_rng(2).uniform(-1, 1, (40, 4)) * INPUT_BOX)
    rho = torch.linspace(-0.05, 0.08, 2 * N_ANCHORS, dtype=torch.float64)
    with torch.no_grad():
        r, c = net.with_cap(x)
        u = r.reshape(40, -1) - net(torch.zeros(1, 4)).reshape(-1)
    fine = Samples(x, r + (rho * u).reshape(r.shape), torch.full((40, 20, 4), math.nan), torch.arange(40),
                   c * 1.04)
    base = mf.fit_scale(net, fine)
    assert torch.allclose(base.rho, rho, rtol=0, atol=1e-10) and base.rho_theta == pytest.approx(0.04, abs=1e-10)
    assert mf.residual_samples(base, fine).anchors.abs().max() < 1e-12


def test_sum_is_mirror_symmetric_and_jacobian_targets_are_fine_minus_autograd(sets):
    fine = load_samples(sets["fine"])[0]
    torch.manual_seed(1)
    correction = JointSurrogate(mf.correction_configs(50, 0, 10, [], True)[0],
                                normalisation(fine, "absolute")).to(torch.float64)
    model = mf.MultiFidelitySurrogate(mf.fit_scale(sets["net"], fine), correction.requires_grad_(False))
    assert model.base.rho.abs().max() > 0.01           # g has a part along the coarse displacement
    x = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (20, 4)) * INPUT_BOX)
    r, c = model.with_cap(x)
    rm, cm = model.with_cap(x * torch.as_tensor(INPUT_MIRROR))
    assert torch.equal(rm[..., 0], r[..., 0]) and torch.equal(rm[..., 1], -r[..., 1]) and torch.equal(cm, -c)
    _, jac, _ = model.outputs(x, jacobian=True)
    assert torch.allclose(jac, jacobian(model, x), rtol=0, atol=1e-10)
    # unscaled, the targets are g and its Jacobian dg/dx (taken here by autograd)
    res = mf.residual_samples(mf.ScaledCoarse(sets["net"], torch.zeros(20), 0.0), fine)
    dg = torch.autograd.functional.jacobian(lambda a: g(a)[0].reshape(len(a), -1).sum(0),
                                            fine.inputs).permute(1, 0, 2)
    gr, gc = g(fine.inputs)
    assert torch.allclose(res.anchors, gr, atol=1e-12) and torch.allclose(res.cap_rotation, gc, atol=1e-12)
    assert torch.allclose(res.jacobian, dg, atol=1e-9)


def test_correction_recovers_the_known_difference_and_resumes(sets, tmp_path, monkeypatch, cheap_baseline):
    out = tmp_path / "mf.json"
    trained = []
    real = mf.train
    record = lambda m, c, splits, log: trained.append(len(splits["train"])) or real(m, c, splits, log)
    monkeypatch.setattr(mf, "train", record)
    monkeypatch.setattr(lc, "train", record)           # the fine-only baseline's run_point
    assert mf.main(_args(sets, out, ["--sizes", "all", "--min-steps", "1600"])) == 0
    doc = json.loads(out.read_text())
    assert doc["complete"] and (tmp_path / "mf.png").stat().st_size > 0
    # fine 160 samples split 7:2:1 -> pool 112, val 32; c_f = 0.4 h / 160 = 9 s, c_c = 2.25 s
    assert (doc["fine"]["pool"], doc["fine"]["val"], doc["heldout"]["n"]) == (112, 32, 96)
    assert doc["fine"]["cpu_s_per_sample"] == pytest.approx(9.0)
    (row,) = doc["comparison"]
    assert row["equal_cost_fine_samples"] == 112 + 40 and row["fine_only_samples"] == 112 and row["m_exceeds_data"]
    assert row["multifidelity_cpu_hours"] == pytest.approx(112 * 9 / 3600 + 0.1)
    assert trained == [112, 112] and {p["kind"] for p in doc["points"]} == set(mf.KINDS)
    assert all(set(p) == set(mf.POINT_KEYS) for p in doc["points"])
    coarse, multi = doc["coarse_only"], row["multifidelity"]
    # the coarse surrogate's error is |g| (mean 0.21 mm); scales and network together learn
    # g itself (measured: 0.0017 mm, 0.009 deg, 1/120 and 1/70 of it)
    assert coarse["heldout_mean_anchor_error_mm"] > 0.15
    for key in ("heldout_mean_anchor_error_mm", "heldout_tip_error_mm", "heldout_cap_rotation_error_deg"):
        assert multi[key] < 0.05 * coarse[key], (key, multi[key], coarse[key])
    # the scales alone take out only the part of g along the coarse displacement
    assert multi["heldout_mean_anchor_error_mm"] < 0.1 * row["scale_only"]["heldout_mean_anchor_error_mm"]
    # a re-run trains nothing and keeps every figure
    trained.clear()
    assert mf.main(_args(sets, out, ["--sizes", "all", "--min-steps", "1600"])) == 0
    assert trained == [] and json.loads(out.read_text())["points"] == doc["points"]
    # another correction config redoes the multi-fidelity point alone
    assert mf.main(_args(sets, out, ["--sizes", "all", "--min-steps", "1600", "--set", "hidden=16,16"])) == 0
    again = json.loads(out.read_text())["points"]
    assert trained == [112] and again[1] == doc["points"][1] and again[0]["model_config"]["hidden"] == [16, 16]


def test_max_hours_stops_before_training(sets, tmp_path, monkeypatch):
    for module in (mf, lc):
        monkeypatch.setattr(module, "train", lambda *a, **k: pytest.fail("trained past --max-hours"))
    out = tmp_path / "mf.json"
    assert mf.main(_args(sets, out, ["--sizes", "20", "--max-hours", "1e-9"])) == mf.EXIT_STOPPED
    assert not out.exists()


def _foreign(sets, name, **change):
    """A copy of the fine set (seed 5 unless changed) with its config changed."""
    root = sets["root"] / name
    if not root.exists():
        fine_set(root, sets["net"], 32, seed=change.pop("seed", 5), config=FINE_CONFIG | change)
    return str(root)


@pytest.mark.parametrize("case, message", [
    ("missing", "no manifest.json"),
    ("box", "another joint or input box"),
    ("same_walk", "a seed of its own"),
    ("discretisation", "not on the discretisation of"),
    ("coarse_walk", "which trained the coarse surrogate"),
    ("model", "trained on another dataset"),
    ("size", "subset size 500 is outside [1, 112]"),
    ("cpu", "records no cpu_hours"),
    ("set", "unknown field 'width'"),
    ("twice", "give each key once"),
])
def test_bad_input_exits_2_with_one_line(sets, tmp_path, capsys, monkeypatch, case, message):
    for module in (mf, lc):
        monkeypatch.setattr(module, "train", lambda *a, **k: pytest.fail("trained on bad input"))
    args = {"coarse": str(sets["coarse"]), "fine": str(sets["fine"]), "heldout": str(sets["heldout"]),
            "coarse-model": str(sets["model"])}
    extra = ["--sizes", "20"]
    if case == "missing":
        args["fine"] = str(tmp_path / "nowhere")
    elif case == "box":
        args["fine"] = _foreign(sets, "box", input_box=[0.3, 3, 3, 50])
    elif case == "same_walk":
        args["heldout"] = _foreign(sets, "same_walk")
    elif case == "discretisation":
        args["heldout"] = _foreign(sets, "finer", seed=8, solver={"degree": 3})
    elif case == "coarse_walk":
        args["heldout"] = _foreign(sets, "coarse_walk", seed=3)
    elif case == "model":
        args["coarse"] = str(sets["heldout"])                   # not what the checkpoint learned
        args["heldout"] = _foreign(sets, "other_walk", seed=9)
    elif case == "size":
        extra = ["--sizes", "50,500"]
    elif case == "cpu":
        args["fine"] = _foreign(sets, "no_cpu", seed=10)
        dataclasses.replace(shards.Manifest.load(args["fine"]), cpu_hours=None).save(args["fine"])
    elif case == "set":
        extra = ["--set", "width=3"]
    elif case == "twice":
        extra = ["--set", "hidden=8", "--set", "hidden=16"]
    out = tmp_path / "out"
    out.mkdir()
    argv = [a for k, v in args.items() for a in (f"--{k}", v)] + ["--out", str(out / "mf.json"), *extra]
    with pytest.raises(SystemExit) as exc:
        mf.main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and message in err and err.count("\n") == 1, err
    assert list(out.iterdir()) == []
