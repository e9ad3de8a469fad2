"""Tests of the joint surrogate (issue 4) on small synthetic datasets (surrogate.synthetic),
and of the committed FEM-trained checkpoints against their stored metrics.

The synthetic data come from an analytic, exactly mirror-symmetric planar rod with exact
sensitivities; the FEM campaign's datasets have the same format. Every test runs on one
CPU thread; the whole file takes well under two minutes.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from contract.spec import INPUT_BOX, mirror
from surrogate import (KNN, ModelConfig, ModelError, JointSurrogate, OutOfBoxError, check_box,
                       load_surrogate, phi_end)
from surrogate import checkpoint, model as model_mod, sweep, synthetic, train as train_mod
from surrogate.data import augment_mirror, load_samples, load_splits, normalisation
from surrogate.evaluate import evaluate, jacobian, metrics
from surrogate.knn import choose_knn
from surrogate.model import load_checkpoint, save_checkpoint
from workflow.shards import ShardError, split_of
from apps import report as workflow_report

torch.set_num_threads(1)
PY = sys.executable
B = torch.tensor([-1.0, 1.0, -1.0, -1.0], dtype=torch.float64)
S = torch.tensor([1.0, -1.0], dtype=torch.float64)
#: a small improved-style model that trains in seconds
SMALL = ["hidden=32,32,32", "batch_size=16", "lr=0.003", "lr_decay=0.97", "w_phi=10"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A 400-sample synthetic training dataset and a 100-sample held-out one."""
    root = tmp_path_factory.mktemp("synthetic")
    return (synthetic.write_dataset(root / "train", 400, seed=3, shard_size=128),
            synthetic.write_dataset(root / "heldout", 100, seed=4))


@pytest.fixture(scope="module")
def improved(data, tmp_path_factory):
    """An improved-config checkpoint (small MLP, 100 epochs) trained on the synthetic set."""
    out = tmp_path_factory.mktemp("models") / "improved.pt"
    sets = [a for kv in ["epochs=100", *SMALL] for a in ("--set", kv)]
    assert train_mod.main(["--config", "improved", "--data", str(data[0]), "--out", str(out),
                           "--quiet", *sets]) == 0
    return out


def run(*args):
    return subprocess.run([PY, *args], capture_output=True, text=True, timeout=120)


def test_import_does_not_pull_dolfinx_or_predictor():
    """`import surrogate` loads neither dolfinx, predictor nor matplotlib, and of fem only
    its plain-Python contract modules (contract.spec, contract.files)."""
    code = ("import sys, surrogate; bad = [m for m in sys.modules if m.split('.')[0] in "
            "('dolfinx', 'predictor', 'matplotlib') or (m.split('.')[0] == 'fem' and m not in "
            "('fem', 'contract.spec', 'contract.files'))]; print(bad)")
    assert run("-c", code).stdout.strip() == "[]"


def test_synthetic_rod_jacobian_and_symmetry():
    """The generator's Jacobian matches central differences to 1e-6 relative, and the
    mirrored inputs give exactly the mirrored anchors and Jacobian."""
    x = np.array([[0.2, -1.5, 2.0, -40.0], [-0.25, 2.5, -1.0, 80.0]])
    anchors, jac, _, _ = synthetic.solve(x)
    for k in range(4):
        h = 1e-5 * INPUT_BOX[k]
        xp, xm = x.copy(), x.copy()
        xp[:, k] += h
        xm[:, k] -= h
        fd = (synthetic.solve(xp)[0] - synthetic.solve(xm)[0]).reshape(2, 20) / (2 * h)
        assert np.abs(fd - jac[:, :, k]).max() <= 1e-6 * np.abs(jac[:, :, k]).max()
    xm_, am_, jm_ = mirror(x, anchors, jac)
    a2, j2, _, _ = synthetic.solve(xm_)
    np.testing.assert_allclose(a2, am_, atol=1e-12)
    np.testing.assert_allclose(j2, jm_, atol=1e-10)


def test_data_split_augment_normalise(data):
    """The 400 samples split as workflow.shards.split_of labels their ids under the manifest
    seed (its 7:2:1 and walk blocks are tested in test_dataset), the mirror doubles the
    set, and the normalisation's y means are 0 (x means increase, within 5 mm of L·i/10)."""
    parts, manifest = load_splits(data[0])
    n = {k: len(v) for k, v in parts.items()}
    assert sum(n.values()) == 400 and min(n.values()) > 0
    for label, k in enumerate(("train", "val", "test")):
        assert (split_of(parts[k].sample_id.numpy(), manifest.seed) == label).all()
    aug = augment_mirror(parts["train"])
    assert len(aug) == 2 * n["train"]
    torch.testing.assert_close(aug.anchors[n["train"]:], parts["train"].anchors * S)
    assert torch.equal(aug.cap_rotation[n["train"]:], -parts["train"].cap_rotation)
    norm = normalisation(parts["train"])
    assert "cap_scale" not in norm
    # the cap head's scales: RMS of the rod's end rotation (~40 deg) and of its offset from
    # the chord angle phi_end (~1.5 deg)
    absolute = normalisation(parts["train"], "absolute")["cap_scale"][0]
    offset = normalisation(parts["train"], "offset")["cap_scale"][0]
    assert 0.4 < absolute < 1.0 and 0.01 < offset < 0.05
    mean = np.array(norm["output_mean"]).reshape(10, 2)
    assert np.abs(mean[:, 1]).max() < 1e-9
    assert np.all(np.diff(mean[:, 0]) > 3) and np.abs(mean[:, 0] - 4.545 * np.arange(1, 11)).max() < 5
    assert manifest.config["source"] == "synthetic-rod"


def test_corrupt_shard_is_refused(data, tmp_path):
    """Flipping bytes in a shard gives a one-line ShardError, in the loader and the CLI."""
    import shutil
    root = tmp_path / "ds"
    shutil.copytree(data[1], root)
    shard = next((root / "shards").glob("*.npz"))
    raw = bytearray(shard.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    shard.write_bytes(bytes(raw))
    with pytest.raises(ShardError, match="corrupt"):
        load_samples(root)
    with pytest.raises(ShardError, match="no manifest"):
        load_samples(tmp_path / "nothing")
    r = run("-m", "surrogate.train", "--config", "paper", "--data", str(tmp_path / "nothing"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "no manifest.json" in r.stderr


def test_training_reaches_stated_error(improved, data):
    """100 epochs of a 32-32-32 improved model on the 282 training samples: held-out mean
    anchor error < 0.2 mm, phi_end error < 0.5 deg, Jacobian relative error < 0.1
    (measured with the equivariant config and its cap head: 0.055 mm, 0.29 deg, 0.029);
    the checkpoint records the test metrics."""
    heldout, _ = load_samples(data[1])
    m = evaluate(load_surrogate(improved), heldout)
    assert m["n"] == 100
    assert m["mean_anchor_error_mm"] < 0.2
    assert m["phi_end_error_deg"] < 0.5
    assert m["jacobian_rel_error"] < 0.1
    ckpt = load_checkpoint(improved)
    assert ckpt["metrics"]["test"]["mean_anchor_error_mm"] < 0.2
    cfg = ckpt["model_config"]
    assert ckpt["train_config"]["w_jac"] > 0 and (cfg["symmetric"] or cfg["equivariant"])
    assert (improved.parent / "improved_curve.png").stat().st_size > 10_000


def test_gradcheck_loaded_model(improved):
    """The loaded model is float64, batched over any leading shape, and its input
    gradients pass torch.autograd.gradcheck (and gradgradcheck)."""
    model = load_surrogate(improved)
    assert all(p.dtype == torch.float64 and not p.requires_grad for p in model.parameters())
    x = (torch.rand(3, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
         * 2 - 1) * torch.as_tensor(INPUT_BOX)
    x.requires_grad_(True)
    assert torch.autograd.gradcheck(model, (x,), eps=1e-6, atol=1e-5)
    assert torch.autograd.gradgradcheck(model, (x,), eps=1e-6, atol=1e-4)
    assert model(x.detach().reshape(3, 1, 4)).shape == (3, 1, 10, 2)
    assert model(x.detach()[0]).shape == (10, 2)
    # the forward-mode Jacobian used in training equals autograd's
    _, jac = model.with_jacobian(x.detach())
    torch.testing.assert_close(jac, jacobian(model, x.detach()), rtol=1e-10, atol=1e-12)


def _fresh(**config):
    torch.manual_seed(0)
    return JointSurrogate(ModelConfig(hidden=(16, 16), **config),
                          {"input_scale": INPUT_BOX, "output_mean": [1.0] * 20,
                           "output_scale": [2.0] * 20}).double()


def test_exact_mirror_symmetry(improved):
    """The symmetrised and the equivariant models satisfy R(Bx) = S R(x) bit for bit, on
    1000 random inputs, trained or freshly initialised; the Jacobian transforms as
    S J(x) B."""
    x = (torch.rand(1000, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
         * 2 - 1) * torch.as_tensor(INPUT_BOX)
    for model in (load_surrogate(improved), _fresh(activation="tanh", symmetric=True),
                  _fresh(activation="silu", residual=True, equivariant=True, abs_pressure=True)):
        with torch.no_grad():
            assert torch.equal(model(x * B), model(x) * S)
            assert torch.equal(model(torch.zeros(4, dtype=torch.float64))[:, 1],
                               torch.zeros(10, dtype=torch.float64))
        _, j = model.with_jacobian(x[:50])
        _, jm = model.with_jacobian(x[:50] * B)
        torch.testing.assert_close(jm, j * S.repeat(10)[:, None] * B, rtol=0, atol=1e-13)


def test_equivariant_model_derivatives():
    """The one-pass equivariant model: gradcheck and gradgradcheck in float64, and its
    forward-mode Jacobian (the Sobolev term's) equals autograd's to round-off."""
    model = _fresh(activation="silu", residual=True, equivariant=True, abs_pressure=True)
    x = (torch.rand(4, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
         * 2 - 1) * torch.as_tensor(INPUT_BOX)
    assert torch.autograd.gradcheck(model, (x.clone().requires_grad_(True),), eps=1e-6, atol=1e-5)
    assert torch.autograd.gradgradcheck(model, (x.clone().requires_grad_(True),), eps=1e-6,
                                        atol=1e-4)
    _, jac = model.with_jacobian(x)
    torch.testing.assert_close(jac, jacobian(model, x), rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError, match="choose one"):
        ModelConfig(symmetric=True, equivariant=True)


#: a straight joint on average (x_k = k L/10), so phi_end stays far from the branch cut at pi
CAP_NORM = {"input_scale": INPUT_BOX.tolist(),
            "output_mean": [4.545 * (i // 2 + 1) * (i % 2 == 0) for i in range(20)],
            "output_scale": [0.5] * 20, "cap_scale": [0.05]}


def _fresh_cap(**config):
    torch.manual_seed(0)
    return JointSurrogate(ModelConfig(hidden=(16, 16), cap_rotation=True, **config), CAP_NORM).double()


CAP_FORMS = [dict(activation="silu", residual=True, equivariant=True, abs_pressure=True),
             dict(activation="tanh", symmetric=True)]


def test_cap_head_exact_mirror_symmetry_and_anchors(improved):
    """The cap head of the equivariant and the symmetric forms, both targets, fresh or
    trained: theta(Bx) = -theta(x) bit for bit on 1000 random inputs, theta(0) = 0 exactly,
    and with_cap's anchors equal forward's bit for bit (also over a leading batch shape)."""
    x = (torch.rand(1000, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
         * 2 - 1) * torch.as_tensor(INPUT_BOX)
    models = [_fresh_cap(cap_target=t, **form) for form in CAP_FORMS for t in ("offset", "absolute")]
    models.append(load_surrogate(improved))
    for model in models:
        assert model.has_cap_rotation
        with torch.no_grad():
            anchors, cap = model.with_cap(x)
            anchors_m, cap_m = model.with_cap(x * B)
            assert torch.equal(cap_m, -cap) and cap.abs().max() > 0
            assert torch.equal(anchors, model(x)) and torch.equal(anchors_m, model(x) * S)
            zero = model.with_cap(torch.zeros(4, dtype=torch.float64))[1]
            assert zero.shape == () and zero.item() == 0.0
            a3, c3 = model.with_cap(x[:6].reshape(2, 3, 4))
            assert a3.shape == (2, 3, 10, 2) and c3.shape == (2, 3)
            assert torch.equal(a3, model(x[:6].reshape(2, 3, 4)))


def test_cap_head_gradient_matches_finite_differences():
    """d theta / dx by autograd through with_cap (what the predictor takes) matches central
    differences (h = 1e-6 of each half-range) to 1e-7 relative, on small random models of
    each form and target, in float64; gradcheck passes too. The head adds outputs, not a
    pass: with_cap gives the same theta batched and one sample at a time."""
    x = (torch.rand(5, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
         * 2 - 1) * torch.as_tensor(INPUT_BOX)
    for form in CAP_FORMS + [dict(activation="silu")]:
        for target in ("offset", "absolute"):
            model = _fresh_cap(cap_target=target, **form).requires_grad_(False)
            xg = x.clone().requires_grad_(True)
            cap = model.with_cap(xg)[1]
            assert cap.dtype == torch.float64
            (grad,) = torch.autograd.grad(cap.sum(), xg)
            for k in range(4):
                h = 1e-6 * INPUT_BOX[k]
                e = torch.zeros(4, dtype=torch.float64)
                e[k] = h
                fd = (model.with_cap(x + e)[1] - model.with_cap(x - e)[1]) / (2 * h)
                scale = grad[:, k].abs().max()
                assert (fd - grad[:, k]).abs().max() <= 1e-7 * scale, (form, target, k)
            assert torch.autograd.gradcheck(lambda a: model.with_cap(a)[1], (xg,), eps=1e-6, atol=1e-7)
            one = torch.stack([model.with_cap(xi)[1] for xi in x])
            torch.testing.assert_close(one, cap.detach(), rtol=1e-13, atol=1e-15)


def test_model_without_head_and_old_checkpoints(tmp_path):
    """A model without the head refuses with_cap with a one-line ModelError. A checkpoint
    written before the head existed (no cap_rotation/cap_target in its model_config, as
    the 1.8 mm reference's paper.pt) loads without the head and gives the saved model's
    anchors bit for bit; that paper.pt (results/surrogate/h1.8/) loads so, and the committed
    improved.pt has the head."""
    model = _fresh(activation="silu", residual=True, equivariant=True, abs_pressure=True)
    assert not model.has_cap_rotation
    with pytest.raises(ModelError, match="no cap-rotation head") as err:
        model.with_cap(torch.zeros(4, dtype=torch.float64))
    assert "\n" not in str(err.value)
    path = tmp_path / "old.pt"
    save_checkpoint(path, model, {}, {}, {})
    ckpt = load_checkpoint(path)
    for key in ("cap_rotation", "cap_target"):
        del ckpt["model_config"][key]
    checkpoint.save(path, model_mod.FORMAT, ckpt)
    loaded = load_surrogate(path)
    x = torch.randn(50, 4, dtype=torch.float64) * torch.as_tensor(INPUT_BOX)
    assert not loaded.has_cap_rotation and "cap_scale" not in loaded.normalisation
    assert torch.equal(loaded(x), model(x).detach())
    committed = RESULTS / "surrogate/h1.8/paper.pt"  # trained before the head existed
    if committed.is_file():
        ckpt = load_checkpoint(committed)
        assert "cap_rotation" not in ckpt["model_config"]
        assert not any(k.startswith("cap_head") for k in ckpt["model_state"])
        assert not load_surrogate(committed).has_cap_rotation
    committed = RESULTS / "surrogate/improved.pt"   # retrained with it (issue 14)
    if committed.is_file():
        assert load_surrogate(committed).has_cap_rotation


def test_training_learns_cap_rotation(improved, data):
    """The improved config (cap head on, absolute target) on the synthetic rod, 100 epochs
    of a 32-32-32 model: the held-out cap rotation error is below 0.5 deg and below a third
    of the tangent connection's (the model's phi_end taken for the cap rotation: the rod's
    chord and end angles differ by 1.4 deg on average; the cap rotation spans +-85 deg).
    Measured: 0.28 deg against 1.34 (p95 1.0 deg)."""
    heldout, _ = load_samples(data[1])
    m = evaluate(load_surrogate(improved), heldout)
    assert m["cap_rotation_error_deg"] < 0.5
    assert m["cap_rotation_error_deg"] < m["tangent_error_deg"] / 3
    assert m["p95_cap_rotation_error_deg"] >= m["cap_rotation_error_deg"]
    ckpt = load_checkpoint(improved)
    assert ckpt["model_config"]["cap_rotation"] and ckpt["train_config"]["w_cap"] > 0
    assert len(ckpt["metrics"]["history"]["val_cap_deg"]) == 100


def test_checkpoint_round_trip(tmp_path):
    """save -> load_surrogate gives bit-identical outputs, the same config, normalisation,
    training config and metrics."""
    torch.manual_seed(0)
    cfg = ModelConfig(hidden=(8, 8), activation="silu", residual=True, abs_pressure=True)
    norm = {"input_scale": INPUT_BOX.tolist(), "output_mean": list(range(20)),
            "output_scale": [0.5] * 20}
    model = JointSurrogate(cfg, norm).double()
    path = tmp_path / "m.pt"
    save_checkpoint(path, model, {"lr": 1e-3}, {"val": {"mean_anchor_error_mm": 0.1}}, {"seed": 1})
    loaded = load_surrogate(path)
    x = torch.randn(7, 4, dtype=torch.float64)
    assert torch.equal(loaded(x), model(x).detach())
    assert loaded.config == cfg and loaded.normalisation["output_mean"][19] == 19.0
    ckpt = load_checkpoint(path)
    assert ckpt["train_config"] == {"lr": 1e-3}
    assert ckpt["metrics"]["val"]["mean_anchor_error_mm"] == 0.1 and ckpt["dataset"] == {"seed": 1}


def test_bad_or_missing_checkpoint(tmp_path, improved):
    """Missing, garbage, truncated, foreign, pre-integrity (a plain torch.save of a valid
    payload), other-kind, mismatched and NaN-weight files raise ModelError (a ValueError and
    a CheckpointError) with a one-line message; the CLI exits 2 with one stderr line."""
    garbage = tmp_path / "garbage.pt"
    garbage.write_text("not a checkpoint")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(improved.read_bytes()[:200])
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    old_format = tmp_path / "old_format.pt"
    torch.save({"format": "softjoint-surrogate/1", **load_checkpoint(improved)}, old_format)
    other_kind = tmp_path / "other_kind.pt"
    checkpoint.save(other_kind, "softjoint-gravity-nn/1", load_checkpoint(improved))
    mismatched = tmp_path / "mismatched.pt"
    ckpt = load_checkpoint(improved)
    ckpt["model_config"]["hidden"] = (16, 16)
    checkpoint.save(mismatched, model_mod.FORMAT, ckpt)
    nonfinite = tmp_path / "nonfinite.pt"
    ckpt = load_checkpoint(improved)
    ckpt["model_state"]["head.bias"][3] = float("nan")
    checkpoint.save(nonfinite, model_mod.FORMAT, ckpt)
    cases = {tmp_path / "missing.pt": "not found", garbage: "no valid checkpoint header",
             truncated: "damaged surrogate checkpoint", foreign: "no valid checkpoint header",
             old_format: "not a softjoint surrogate checkpoint",
             other_kind: "a 'softjoint-gravity-nn/1' file, expected a 'softjoint-surrogate/2'",
             mismatched: "inconsistent", nonfinite: "non-finite"}
    for path, words in cases.items():
        with pytest.raises(ModelError, match=words) as err:
            load_surrogate(path)
        assert isinstance(err.value, checkpoint.CheckpointError) and "\n" not in str(err.value)
    for path in (garbage, old_format, other_kind):
        r = run("-m", "surrogate.predict", "--model", str(path), "--p", "0", "--f1", "0",
                "--f2", "0", "--m", "0")
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert str(path) in r.stderr and "Traceback" not in r.stderr and r.stdout == ""


def test_predict_cli_and_box(improved):
    """predict --json prints 10 anchors and phi_end consistent with them; inputs outside
    the box exit 2 unless --allow-extrapolation, which the output records."""
    args = ["-m", "surrogate.predict", "--model", str(improved), "--p", "0.1", "--f1", "1",
            "--f2", "0", "--m", "10", "--json"]
    r = run(*args)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    anchors = np.array(out["anchors_mm"])
    assert anchors.shape == (10, 2) and out["extrapolation"] is False
    assert abs(anchors[-1, 0] - 45.45) < 3.0
    d = anchors[-1] - anchors[-2]
    assert out["phi_end_rad"] == pytest.approx(math.atan2(d[1], d[0]), abs=1e-12)
    # the cap head's rotation: what with_cap gives, within a few degrees of phi_end
    with torch.no_grad():
        cap = load_surrogate(improved).with_cap(torch.tensor([0.1, 1.0, 0.0, 10.0],
                                                             dtype=torch.float64))[1].item()
    assert out["cap_rotation_rad"] == cap and abs(cap - out["phi_end_rad"]) < math.radians(5)
    assert out["cap_rotation_deg"] == pytest.approx(math.degrees(cap), rel=1e-12)
    bad = args[:4] + ["--p", "0.5"] + args[6:]
    r = run(*bad)
    assert r.returncode == 2 and "outside the training box" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = run(*bad, "--allow-extrapolation")
    assert r.returncode == 0 and json.loads(r.stdout)["extrapolation"] is True
    r = run(*args[:4], "--p", "nan", *args[6:], "--allow-extrapolation")  # NaN: never
    assert r.returncode == 2 and "'nan' is not a finite number" in r.stderr and r.stdout == ""
    with pytest.raises(OutOfBoxError, match="F2 = 3.5 is outside the training box"):
        check_box(torch.tensor([[0.0, 0.0, 3.5, 0.0]]))
    with pytest.raises(OutOfBoxError, match="M = nan is not a finite number"):
        check_box(torch.tensor([[0.0, 0.0, 0.0, math.nan]]), allow_extrapolation=True)
    assert check_box(torch.tensor([[0.3, -3.0, 3.0, -100.0]])) == 0
    assert check_box(torch.tensor([[0.31, 0.0, 0.0, 0.0]]), allow_extrapolation=True) == 1


def test_overrides_are_checked():
    """--set applies each key to its config with the field's type; an unknown key, a value
    of the wrong kind, a non-finite or out-of-range number and a key given twice are
    refused with one line naming the pair."""
    mc, tc = train_mod.apply_overrides(*train_mod.CONFIGS["paper"],
                                       ["hidden=8,4", "lr=0.01", "epochs=7", "residual=true"])
    assert mc.hidden == (8, 4) and mc.residual is True and tc.lr == 0.01 and tc.epochs == 7
    for pairs, words in ((["bogus=1"], "unknown field 'bogus'"), (["lr=nan"], "'nan' is not a finite"),
                         (["lr=inf"], "'inf' is not a finite"), (["lr=0"], "outside (0, inf]"),
                         (["epochs=2.5"], "not an integer"), (["hidden=8,0"], "0 is outside"),
                         (["residual=maybe"], "true or false"), (["lr"], "expected key=value"),
                         (["lr=1", "lr=2"], "--set lr given twice"),
                         (["cap_target=chord"], "expected one of absolute, offset"),
                         (["w_cap=-1"], "-1 is outside [0, inf]")):
        with pytest.raises(ValueError) as err:
            train_mod.apply_overrides(*train_mod.CONFIGS["improved"], pairs)
        assert words in str(err.value) and pairs[-1] in str(err.value) and "\n" not in str(err.value)
    # the cap head and its loss term come together (checked before any data are read)
    paper, improved = train_mod.CONFIGS["paper"], train_mod.CONFIGS["improved"]
    assert not paper[0].cap_rotation and paper[1].w_cap == 0 and paper[0].hidden == (96, 192, 96)
    assert improved[0].cap_rotation and improved[1].w_cap > 0
    for base, pairs, words in ((paper, ["cap_rotation=true"], "needs w_cap > 0"),
                               (improved, ["w_cap=0"], "needs w_cap > 0"),
                               (improved, ["cap_rotation=false"], "w_cap=10 needs cap_rotation=true")):
        with pytest.raises(ValueError, match=words):
            train_mod.check_configs(*train_mod.apply_overrides(*base, pairs))
    r = run("-m", "surrogate.train", "--config", "paper", "--data", "/nonexistent", "--set",
            "cap_rotation=true")
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "needs w_cap > 0" in r.stderr


def test_evaluate_cli_json(improved, data):
    """evaluate --json on the held-out directory prints the issue's keys with n = 100."""
    r = run("-m", "surrogate.evaluate", "--model", str(improved), "--data", str(data[1]), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("mean_anchor_error_mm", "p95_anchor_error_mm", "tip_error_mm",
                "phi_end_error_deg", "jacobian_rel_error", "cap_rotation_error_deg",
                "p95_cap_rotation_error_deg", "tangent_error_deg", "n"):
        assert key in out
    assert out["n"] == 100 and out["p95_anchor_error_mm"] >= out["mean_anchor_error_mm"] > 0
    assert 0 < out["cap_rotation_error_deg"] < out["tangent_error_deg"]


def test_metrics_definitions():
    """Known errors: shifting every anchor by (0.3, 0.4) mm gives 0.5 mm mean, p95 and tip
    error and zero phi_end error; a Jacobian off by 10 % gives relative error 0.1."""
    true = torch.rand(5, 10, 2, dtype=torch.float64) * 40
    jac = torch.rand(5, 20, 4, dtype=torch.float64) + 0.1
    m = metrics(true + torch.tensor([0.3, 0.4], dtype=torch.float64), true, 1.1 * jac, jac)
    assert m["mean_anchor_error_mm"] == pytest.approx(0.5)
    assert m["p95_anchor_error_mm"] == pytest.approx(0.5)
    assert m["tip_error_mm"] == pytest.approx(0.5)
    assert m["phi_end_error_deg"] == pytest.approx(0.0, abs=1e-9)
    assert m["jacobian_rel_error"] == pytest.approx(0.1)
    assert m["cap_rotation_error_deg"] is None and m["tangent_error_deg"] is None
    # cap rotations: a model 0.01 rad off; a tangent connection off by phi_end - theta
    cap = torch.rand(5, dtype=torch.float64)
    m = metrics(true, true, pred_cap=cap + 0.01, true_cap=cap)
    assert m["cap_rotation_error_deg"] == pytest.approx(math.degrees(0.01))
    assert m["p95_cap_rotation_error_deg"] == pytest.approx(math.degrees(0.01))
    gap = model_mod.wrap(phi_end(true) - cap).abs()
    assert m["tangent_error_deg"] == pytest.approx(math.degrees(gap.mean().item()))
    m = metrics(true, true, pred_cap=cap - 2 * math.pi + 0.01, true_cap=cap)  # wrapped
    assert m["cap_rotation_error_deg"] == pytest.approx(math.degrees(0.01))
    assert phi_end(torch.tensor([[i, i] for i in range(10)], dtype=torch.float64)).item() \
        == pytest.approx(math.pi / 4)


def test_knn_sanity(data):
    """k = 1 reproduces the reference anchors exactly at the reference inputs; the
    validation choice of k is in 1..16 and beats predicting the mean shape by 4x on test
    (measured: 1.06 against 5.24 mm)."""
    parts, _ = load_splits(data[0])
    ref = parts["train"]
    with torch.no_grad():
        assert torch.equal(KNN(ref, 1)(ref.inputs), ref.anchors)
        knn, choice = choose_knn(parts["train"], parts["val"])
        assert 1 <= choice["k"] <= 16 and choice["weighting"] in ("uniform", "distance")
        test = parts["test"]
        err = (knn(test.inputs) - test.anchors).norm(dim=-1).mean()
        mean_shape = augment_mirror(ref).anchors.mean(0)
        assert err < (mean_shape - test.anchors).norm(dim=-1).mean() / 4


def test_training_is_reproducible(data):
    """The same seed and data give bit-identical weights after 3 epochs."""
    parts, _ = load_splits(data[0])
    mc, tc = train_mod.apply_overrides(*train_mod.CONFIGS["improved"],
                                       ["epochs=3", "hidden=16,16", "batch_size=64"])
    a, _ = train_mod.train(mc, tc, parts, log=lambda s: None)
    b, _ = train_mod.train(mc, tc, parts, log=lambda s: None)
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(va, vb), k


def test_sobolev_term_reduces_jacobian_error(data):
    """Same data, small model and seed, 40 epochs: with the Sobolev term (w_jac = 0.05) the
    held-out Jacobian relative error is at least 1.5x lower than without it, and the anchor
    error is lower too (measured: 0.077 against 0.20, and 0.16 against 0.41 mm)."""
    parts, _ = load_splits(data[0])
    heldout, _ = load_samples(data[1])
    base = train_mod.apply_overrides(*train_mod.CONFIGS["improved"], ["epochs=40", *SMALL])
    out = {}
    for w in (0.0, 0.05):
        mc, tc = train_mod.apply_overrides(*base, [f"w_jac={w}"])
        model, _ = train_mod.train(mc, tc, parts, log=lambda s: None)
        out[w] = evaluate(model, heldout)
    assert out[0.05]["jacobian_rel_error"] * 1.5 < out[0.0]["jacobian_rel_error"]
    assert out[0.05]["mean_anchor_error_mm"] < out[0.0]["mean_anchor_error_mm"]


def test_report_writes_metrics_and_figures(data, tmp_path):
    """evaluate --report on two 2-epoch checkpoints writes metrics.json mapping paper,
    improved and knn to {test, heldout} with the issue's keys, plus the table and figure."""
    for name in ("paper", "improved"):
        assert train_mod.main(["--config", name, "--data", str(data[0]), "--quiet",
                               "--out", str(tmp_path / f"{name}.pt"), "--set", "epochs=2",
                               "--set", "hidden=16,16"]) == 0
    r = run("-m", "surrogate.evaluate", "--report", "--train-data", str(data[0]),
            "--heldout", str(data[1]), "--dir", str(tmp_path))
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "metrics.json").read_text())
    for name in ("paper", "improved", "knn"):
        for part, n in (("heldout", 100), ("test", None)):
            m = report[name][part]
            assert set(m) >= {"mean_anchor_error_mm", "p95_anchor_error_mm", "tip_error_mm",
                              "phi_end_error_deg", "jacobian_rel_error", "n"}
            assert n is None or m["n"] == n
        assert report[name]["timing"]["single_ms_float64"] > 0
        # the cap head's error for the improved model only; the tangent one for every model
        assert (report[name]["heldout"]["cap_rotation_error_deg"] is None) == (name != "improved")
        assert report[name]["heldout"]["tangent_error_deg"] > 0
    assert report["datasets"]["train"]["config"]["source"] == "synthetic-rod"
    assert "| improved | heldout | 100 |" in (tmp_path / "metrics.md").read_text()
    assert (tmp_path / "comparison.png").stat().st_size > 20_000
    # REPORT.md's target table reads the same numbers: a 2-epoch model misses 0.1 mm.
    (tmp_path / "surrogate").mkdir()
    (tmp_path / "surrogate/metrics.json").write_text((tmp_path / "metrics.json").read_text())
    mean = report["improved"]["heldout"]["mean_anchor_error_mm"]
    assert mean > 0.1
    assert f"| mean anchor error | {mean:.4g} mm | <= 0.1 mm | no" in workflow_report.report(tmp_path)


def test_sweep_trains_each_variant_as_listed_and_resumes(data, tmp_path, capsys):
    """Each variant's record carries the improved config with exactly its overrides (w64x3:
    hidden 64,64,64; nojac: w_jac 0, the rest as improved); a re-run trains nothing, and a
    record of another config (the improved config changed since), epoch count or dataset
    is kept and marked stale, and redone only with --replace-stale (issue 33)."""
    args = ["--data", str(data[0]), "--heldout", str(data[1]), "--epochs", "2",
            "--only", "w64x3", "nojac", "--dir", str(tmp_path)]
    assert sweep.main(args) == 0
    w64 = json.loads((tmp_path / "w64x3.json").read_text())
    nojac = json.loads((tmp_path / "nojac.json").read_text())
    model, cfg = train_mod.CONFIGS["improved"]
    assert w64["model_config"]["hidden"] == [64, 64, 64]
    assert nojac["model_config"]["hidden"] == list(model.hidden)
    assert nojac["train_config"]["w_jac"] == 0 and w64["train_config"]["w_jac"] == cfg.w_jac
    assert w64["heldout"]["n"] == 100 and w64["val"]["mean_anchor_error_mm"] > 0
    assert (tmp_path / "README.md").read_text().count("\n| ") == 3   # header + 2 rows
    capsys.readouterr()
    assert sweep.main(args) == 0
    assert "2 of 2 variants current, 0 to train" in capsys.readouterr().out
    # another config (as after a code change): kept and marked stale, retrained on request
    w64["model_config"]["hidden"] = [32, 32]
    (tmp_path / "w64x3.json").write_text(json.dumps(w64))
    assert sweep.main(args) == 0
    said = capsys.readouterr().out
    assert "1 of 2 variants current, 0 to train" in said and "w64x3: made with other hidden" in said
    assert json.loads((tmp_path / "w64x3.json").read_text())["model_config"]["hidden"] == [32, 32]
    assert (tmp_path / "README.md").read_text().count("| stale: made with other hidden |") == 1
    assert sweep.main(args + ["--replace-stale"]) == 0
    assert "1 of 2 variants current, 1 to train" in capsys.readouterr().out
    assert json.loads((tmp_path / "w64x3.json").read_text())["model_config"]["hidden"] == [64, 64, 64]
    assert sweep.main(args[:5] + ["3"] + args[6:]) == 0      # another epoch count: both stale
    assert "0 of 2 variants current, 0 to train (3 epochs, 1 job(s)); 2 stale" in capsys.readouterr().out
    assert sweep.main(args[:5] + ["3"] + args[6:] + ["--replace-stale"]) == 0
    assert "0 of 2 variants current, 2 to train" in capsys.readouterr().out
    assert sweep.main(["--data", str(data[1])] + args[2:5] + ["3"] + args[6:]) == 0
    assert "w64x3: made on another dataset" in capsys.readouterr().out
    assert (tmp_path / "README.md").read_text().count("\n| ") == 3   # still header + 2 rows


RESULTS = Path(__file__).resolve().parents[1] / "results"


@pytest.mark.skipif(not (RESULTS / "surrogate/metrics.json").is_file(), reason="no committed surrogate")
def test_committed_models_reproduce_their_metrics_and_meet_targets():
    """Frozen reference: the committed paper and improved checkpoints, re-evaluated on the
    committed held-out FEM set, give the errors stored in results/surrogate/metrics.json
    (to 1e-9 relative: same code, same data), and the improved model meets issue 4's
    accuracy targets (mean <= 0.10 mm, p95 <= 0.30 mm, phi_end <= 0.3 deg, Jacobian <= 5 %)
    and is exactly mirror-symmetric on those inputs."""
    stored = json.loads((RESULTS / "surrogate/metrics.json").read_text())
    held, _ = load_samples(RESULTS / "data/heldout")
    targets = {key: target for _, key, target, _ in workflow_report.SURROGATE_TARGETS}
    for name in ("paper", "improved"):
        model = load_surrogate(RESULTS / f"surrogate/{name}.pt")
        got = evaluate(model, held)
        for k in targets:
            assert got[k] == pytest.approx(stored[name]["heldout"][k], rel=1e-9), (name, k)
    assert got["n"] == 256
    for k, target in targets.items():
        assert got[k] <= target, k
    x = held.inputs.to(torch.float64)
    with torch.no_grad():
        assert torch.equal(model(x * B), model(x) * S)
