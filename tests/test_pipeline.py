"""One command from a joint file to a predictor (apps.pipeline, issue 37 §3), end to end.

The pipeline runs once (module fixture) on the paper's joint file at a 6 mm tetrahedral
mesh with a tiny budget: 48 training samples (seed 37: its three 16-sample split blocks
fall one in each of train, validation and test), 16 held-out samples, 200 epochs. About
2.5 min on one busy core. Checked:

* the summary's sample counts are the manifests', and every stage wrote its files;
* the surrogate reproduces its own training FEM samples: the mean anchor error on the
  training split, recomputed here from the checkpoint and the shards (an independent
  re-implementation of surrogate.evaluate's figure), equals the summary's to 1e-9 mm and
  is below 10 % of the training samples' mean anchor displacement from rest;
* the gesture of the three-joint finger is in equilibrium with its weights: the base
  joint's undeformed frame is the mount's (vertical), so its axial and transverse loads
  are the weight hanging below its middle, F1 = 0.09/2 + 0.04 + 0.09 + 0.04 + 0.09 + 0.06
  = 0.365 N, and F2 = 0 (to 1e-6 N);
* resume: with the summary deleted, a second run skips every stage (no FEM: the
  manifests and shards keep their bytes and times) and writes the same summary figures;
* bad input exits 2 with one line before any stage: a joint file that does not exist, a
  bad --budget, a joint of another anchor count, another joint on the same folder.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "contract/joints/paper.toml"
TINY = ["--samples", "48", "--heldout-samples", "16", "--seed", "37", "--mesh-size", "6", "--epochs", "200"]
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1",
       "PYVISTA_OFF_SCREEN": "true"}


def pipeline(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "apps.pipeline", *args], cwd=ROOT, env=ENV, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pipeline") / "paper"
    res = pipeline("--joint", str(PAPER), "--out", str(out), *TINY)
    assert res.returncode == 0, res.stdout + res.stderr[-3000:]
    return out, res


def test_pipeline_end_to_end(run):
    torch = pytest.importorskip("torch")
    from contract.joint import joint_digest, load_joint
    from surrogate.model import load_surrogate
    from workflow.shards import Manifest, load_dataset, split_of

    out, res = run
    lines = res.stdout.splitlines()
    assert len(lines) == 9 and all(line.startswith(f"[pipeline] {k + 1}/9 ") for k, line in enumerate(lines))
    summary = json.loads((out / "summary.json").read_text())
    for name, n in (("train", 48), ("heldout", 16)):
        manifest = Manifest.load(out / "data" / name)
        assert manifest.complete and summary["samples"][name]["samples"] == manifest.samples == n
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["heldout"]["samples"] == 16 and metrics["heldout"]["mean_anchor_error_mm"] > 0
    assert metrics["heldout"]["cap_rotation_error_deg"] is not None
    for name in ("render.png", "surrogate.pt", "gesture.png", "summary.txt", "finger.toml", "joint.toml"):
        assert (out / name).stat().st_size > 0, name
    # the outline stage: the pressurised side bulges (measured 3.2 mm at 0.3 MPa on this 6 mm mesh), the
    # paper's joint file has its own table, so DIR/joint.toml is the file as given
    outline = json.loads((out / "joint_outline.json").read_text())
    assert [r["P_MPa"] for r in outline["bulge_mm"]] == [0.025, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3]
    assert 1.0 < summary["outline"]["bulge_max_mm"] < 5.0 and summary["outline"]["table"] == "the joint file's"
    assert np.allclose(outline["mirror"]["pressurised_mm"], outline["bulge_mm"][-1]["pressurised_mm"], atol=1e-8)
    assert (out / "joint.toml").read_text() == PAPER.read_text()

    model = load_surrogate(out / "surrogate.pt")
    assert joint_digest(model.joint) == joint_digest(load_joint(PAPER)) == summary["joint"]["sha256"]
    arrays, manifest = load_dataset(out / "data" / "train")
    train = split_of(arrays["sample_id"], manifest.seed) == 0
    with torch.no_grad():
        pred = model(torch.as_tensor(arrays["inputs"][train])).numpy()
    true = arrays["anchors"][train]
    error = np.linalg.norm(pred - true, axis=-1).mean()
    rest = np.stack([np.arange(1, 11) * 45.45 / 10, np.zeros(10)], -1)
    displacement = np.linalg.norm(true - rest, axis=-1).mean()
    assert summary["train_fit"]["samples"] == train.sum() == 16
    assert abs(summary["train_fit"]["mean_anchor_error_mm"] - error) < 1e-9
    assert error < 0.1 * displacement, (error, displacement)

    gesture = summary["gesture"]
    tau = np.array(json.loads((out / "gesture.json").read_text())["tau"])
    assert gesture["converged"] and tau.shape == (3, 3)
    np.testing.assert_allclose(tau[0, :2], [0.09 / 2 + 0.04 + 0.09 + 0.04 + 0.09 + 0.06, 0.0], rtol=0, atol=1e-6)


def _fem_files(out: Path) -> dict[str, tuple[int, bytes]]:
    """mtime and bytes of every manifest and shard of the two campaigns."""
    files = sorted((out / "data").rglob("*.json")) + sorted((out / "data").rglob("*.npz"))
    return {str(p): (p.stat().st_mtime_ns, p.read_bytes()) for p in files}


def test_resume_skips_every_stage(run):
    out, _ = run
    before = _fem_files(out)
    first = json.loads((out / "summary.json").read_text())
    (out / "summary.json").unlink()
    (out / "summary.txt").unlink()
    again = pipeline("--joint", str(PAPER), "--out", str(out), *TINY, timeout=300)
    assert again.returncode == 0, again.stderr[-3000:]
    lines = again.stdout.splitlines()
    assert len(lines) == 9 and all("skipped, up to date" in line for line in lines[:8]), again.stdout
    assert _fem_files(out) == before and len(before) == 4       # 2 manifests, 2 shards
    second = json.loads((out / "summary.json").read_text())
    assert not any(stage["ran"] for stage in second["stages"])
    for key in ("samples", "heldout", "train_fit", "gesture"):
        assert second[key] == first[key], key


def test_bad_input_exits_2_with_one_line(run, tmp_path):
    out, _ = run
    other = tmp_path / "soft.toml"
    other.write_text(PAPER.read_text().replace('name = "paper"', 'name = "soft"').replace("E = 12.2 ", "E = 6.1 "))
    held = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    rows = [
        (["--joint", str(tmp_path / "none.toml"), "--out", str(tmp_path / "a")], "cannot read joint file"),
        (["--joint", str(PAPER), "--budget", "huge", "--out", str(tmp_path / "a")], "invalid choice: 'huge'"),
        (["--joint", str(other), "--out", str(out), *TINY], "holds the pipeline of another joint"),
    ]
    for args, needle in rows:
        res = pipeline(*args, timeout=120)
        assert res.returncode == 2 and res.stderr.count("\n") == 1, (args, res.stderr)
        assert res.stderr.startswith("python -m apps.pipeline: error:") and needle in res.stderr, res.stderr
        assert res.stdout == ""
    assert not (tmp_path / "a").exists()
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == held


def test_a_joint_without_an_outline_gets_the_measured_one(tmp_path):
    """joint_text: a joint file without [outline] gets the outline stage's table appended
    (contract.joint.outline_table of its record), which parses back to the record's values
    and leaves the digest; a file with its own table is copied as it is."""
    from apps.pipeline import Settings, joint_text
    from contract.joint import joint_digest, load_joint

    text = PAPER.read_text()
    bare = tmp_path / "bare.toml"
    bare.write_text(text[: text.index("[outline]")])
    s = Settings(load_joint(bare), bare, tmp_path, "small", 1, 1, None, None, None, 1, "", None)
    assert joint_text(s) == bare.read_text()                  # nothing measured yet
    rows = [{"P_MPa": p, "pressurised_mm": [0.1 * k + p] * 10, "other_mm": [-p] * 10}
            for k, p in enumerate((0.1, 0.3))]
    (tmp_path / "joint_outline.json").write_text(json.dumps({"bulge_mm": rows}))
    (tmp_path / "joint.toml").write_text(joint_text(s))
    joint = load_joint(tmp_path / "joint.toml")
    assert joint.outline == ((0.1, 0.3), ((0.1,) * 10, (0.4,) * 10), ((-0.1,) * 10, (-0.3,) * 10))
    assert joint_digest(joint) == s.digest
    s = Settings(load_joint(PAPER), PAPER, tmp_path, "small", 1, 1, None, None, None, 1, "", None)
    assert joint_text(s) == text


def test_generated_finger_and_gesture_pressure(tmp_path):
    """finger.toml: joint, 60 mm link, joint, 60 mm link, joint, 65 mm tip, every joint
    naming joint.toml (so its length is the joint's: 3 x 30 + 185 = 275 mm for a 30 mm
    joint); the gesture pressures are (-1, 1, 1) x half the joint's limit, capped at 0.3 MPa."""
    from apps.pipeline import Settings, finger_text, gesture_pressures
    from contract.finger import load_finger
    from contract.joint import load_joint

    text = PAPER.read_text().replace("length = 45.45 ", "length = 30.0 ")
    text = text.replace("pressure_mpa = 0.3", "pressure_mpa = 0.05")
    (tmp_path / "joint.toml").write_text(text)
    joint = load_joint(tmp_path / "joint.toml")
    s = Settings(joint, tmp_path / "joint.toml", tmp_path, "small", 4, 4, None, None, None, 1, "", None)
    (tmp_path / "finger.toml").write_text(finger_text(s))
    finger = load_finger(tmp_path / "finger.toml")
    assert [p.kind for p in finger.parts] == ["joint", "rigid", "joint", "rigid", "joint", "rigid"]
    assert finger.length == pytest.approx(275.0, abs=1e-12) and finger.n_joints == 3
    assert all(finger.parts[k].joint_file == "joint.toml" for k in finger.joints)
    assert gesture_pressures(s) == [-0.025, 0.025, 0.025]
