"""Tests of the surrogate's learning curve (surrogate.learning_curve) on small synthetic
datasets (surrogate.synthetic, an analytic planar rod: an exact, smooth function of the
loads, so more samples must mean a better fit).

- The subsets are nested prefixes of one seeded order, and the epoch budget gives every
  size at least min_steps Adam steps with the same learning-rate path (checked against
  the formula, independently of the module).
- A 2-point curve records exactly the documented keys, resumes without retraining the
  finished points, redoes a point whose stored config no longer matches, stops on
  --max-hours before training (exit 3, nothing written) and refuses bad input with exit 2.
- With the same step budget, 200 samples of the rod give a held-out anchor error well
  below 12 samples.
"""

from __future__ import annotations

import json
import math

import pytest
import torch

from surrogate import learning_curve as lc
from surrogate import synthetic
from surrogate.train import CONFIGS
from workflow.shards import dataset_digest

TINY = ["--set", "hidden=16,16", "--set", "epochs=3", "--min-steps", "6"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A 300-sample synthetic train dataset (train split 204) and a 100-sample held-out one."""
    root = tmp_path_factory.mktemp("curve")
    return (synthetic.write_dataset(root / "train", 300, seed=3, shard_size=128),
            synthetic.write_dataset(root / "heldout", 100, seed=4))


def test_subsets_are_nested_and_seeded():
    subs = lc.nested_subsets(50, [5, 10, 50], seed=0)
    small, mid, full = (set(subs[s].tolist()) for s in (5, 10, 50))
    assert [len(subs[s]) for s in (5, 10, 50)] == [5, 10, 50]
    assert len(small) == 5 and small < mid < full == set(range(50))
    assert torch.equal(lc.nested_subsets(50, [10], seed=0)[10], subs[10])
    assert not torch.equal(lc.nested_subsets(50, [10], seed=1)[10], subs[10])
    for bad in (0, 51):
        with pytest.raises(ValueError, match=r"outside \[1, 50\]"):
            lc.nested_subsets(50, [bad], seed=0)


def test_epoch_budget_same_steps_and_learning_rate_path():
    _, base = CONFIGS["improved"]
    final_lr = base.lr * base.lr_decay ** base.epochs
    for samples, epochs in ((100, 11200), (200, 5600), (400, 3200), (800, 1724), (1600, 896), (1792, 800)):
        model_cfg, cfg = lc.point_configs("improved", [], samples, True, 0, lc.MIN_STEPS)
        batches = math.ceil(samples / 64)
        assert cfg.epochs == epochs and cfg.epochs * batches >= 22_400
        assert cfg.lr * cfg.lr_decay ** cfg.epochs == pytest.approx(final_lr, rel=1e-9)
        assert cfg.w_jac == 0.2 and model_cfg == CONFIGS["improved"][0]
        _, without = lc.point_configs("improved", [], samples, False, 0, lc.MIN_STEPS)
        assert without.w_jac == 0 and without == type(cfg)(**{**vars(cfg), "w_jac": 0.0})
    # the full split is trained exactly as the improved config is
    assert lc.point_configs("improved", [], 1792, True, 0, lc.MIN_STEPS)[1] == base
    with pytest.raises(ValueError, match="w_jac = 0"):
        lc.point_configs("improved", ["w_jac=0"], 100, True, 0, lc.MIN_STEPS)


def _args(data, out, sizes="20,40", extra=()):
    return ["--data", str(data[0]), "--heldout", str(data[1]), *TINY, "--sizes", sizes,
            "--modes", "with", "--out", str(out), *extra]


def test_curve_records_keys_and_resumes(data, tmp_path, monkeypatch):
    out = tmp_path / "lc.json"
    trained = []
    real = lc.train
    monkeypatch.setattr(lc, "train", lambda m, c, splits, log: trained.append(len(splits["train"]))
                        or real(m, c, splits, log))
    assert lc.main(_args(data, out)) == 0
    doc = json.loads(out.read_text())
    assert trained == [20, 40] and doc["complete"] and (tmp_path / "lc.png").stat().st_size > 0
    points = doc["points"]
    assert [p["samples"] for p in points] == [20, 40]
    for p in points:
        assert set(p) == set(lc.POINT_KEYS)
        assert p["jacobian_loss"] is True and p["seed"] == 0 and p["steps"] >= 6
        assert p["data_sha256"] == dataset_digest(data[0]) and p["heldout_sha256"] == dataset_digest(data[1])
        assert p["heldout_mean_anchor_error_mm"] > 0 and p["heldout_cap_rotation_error_deg"] > 0
        assert p["heldout_tip_error_mm"] > p["heldout_mean_anchor_error_mm"]  # the tip moves most
    # a re-run trains nothing and leaves the figures as they were
    trained.clear()
    assert lc.main(_args(data, out)) == 0
    assert trained == [] and json.loads(out.read_text())["points"] == points
    # a point whose stored config differs from what the code gives now is redone, alone
    points[1]["train_config"]["lr"] = 1.0
    out.write_text(json.dumps(doc | {"points": points}))
    assert lc.main(_args(data, out)) == 0
    again = json.loads(out.read_text())["points"]
    assert trained == [40] and again[0] == points[0] and again[1]["train_config"]["lr"] == 3e-3
    # a larger curve adds the new size only; "all" is the whole train split
    trained.clear()
    assert lc.main(_args(data, out, "20,40,all")) == 0
    assert trained == [204] and [p["samples"] for p in json.loads(out.read_text())["points"]] == [20, 40, 204]


def test_max_hours_stops_before_training(data, tmp_path, monkeypatch):
    monkeypatch.setattr(lc, "train", lambda *a, **k: pytest.fail("trained past --max-hours"))
    out = tmp_path / "lc.json"
    assert lc.main(_args(data, out, extra=["--max-hours", "1e-9"])) == lc.EXIT_STOPPED
    assert not out.exists()


@pytest.mark.parametrize("bad, message", [
    (["--sizes", "20,5000"], "subset size 5000 is outside [1, 204]"),
    (["--sizes", "0"], "outside [1, inf]"),
    (["--modes", "with,maybe"], "expected with and/or without"),
    (["--repeat", "400"], "expected SAMPLES:SEED"),
    (["--set", "width=3"], "unknown field 'width'"),
    (["--plot", "x.txt"], "expected a .png file"),
])
def test_bad_input_exits_2_with_one_line(data, tmp_path, capsys, monkeypatch, bad, message):
    monkeypatch.setattr(lc, "train", lambda *a, **k: pytest.fail("trained on bad input"))
    args = ["--data", str(data[0]), "--heldout", str(data[1]), "--out", str(tmp_path / "lc.json"), *bad]
    with pytest.raises(SystemExit) as exc:
        lc.main(args)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_more_samples_fit_the_exact_function_better(data):
    """Same 600 Adam steps, same schedule: 200 samples of the rod against 6."""
    from surrogate.data import load_samples, load_splits

    splits, _ = load_splits(data[0])
    heldout, _ = load_samples(data[1])
    subsets = lc.nested_subsets(len(splits["train"]), [6, 200], seed=0)
    err = {}
    for s in (6, 200):
        model_cfg, cfg = lc.point_configs("improved", ["hidden=32,32", "epochs=10"], s, True, 0, 600)
        err[s] = lc.run_point(splits, heldout, subsets[s], model_cfg, cfg)["heldout_mean_anchor_error_mm"]
    assert err[200] < 0.25 * err[6]   # measured: 0.077 against 0.474 mm


def test_report_section_shows_every_point(data, tmp_path):
    """apps.report's learning-curve section: one table row per point, with the JSON's
    figures, and the seed-to-seed spread where a size was run with two seeds."""
    from apps import report as workflow_report

    out = tmp_path / "surrogate/learning_curve.json"
    out.parent.mkdir()
    assert lc.main(_args(data, out, "20", ["--repeat", "20:1"])) == 0
    points = json.loads(out.read_text())["points"]
    text = workflow_report.report(tmp_path)
    section = text.split("## Surrogate learning curve")[1].split("\n## ")[0]
    rows = [ln for ln in section.splitlines() if ln.startswith("| 20 | with |")]
    assert len(rows) == 2 == len(points)
    for p, line in zip(points, rows):
        assert line.startswith(f"| 20 | with | {p['seed']} | {p['heldout_mean_anchor_error_mm']:.4g} "
                               f"| {p['heldout_tip_error_mm']:.4g} |")
    a, b = (p["heldout_mean_anchor_error_mm"] for p in points)
    assert f"{a:.4f} vs {b:.4f} mm ({100 * abs(a - b) / ((a + b) / 2):.0f} % of their mean)" in section
    assert "![the surrogate's learning curve](surrogate/learning_curve.png)" in section
