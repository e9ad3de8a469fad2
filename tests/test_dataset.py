"""Tests of the dataset tools (workflow.dataset), on fabricated campaign-layout datasets.

No FEM here: the shards hold random numbers laid out exactly as workflow.campaign writes
them (unit u = sample ids [u K, u K + n_u), converged samples as data, the rest as
failures). The FEM-backed checks (mirror relation, resume) are in test_campaign.py.
The whole file takes a few seconds.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workflow import dataset, shards

PY = sys.executable
CONFIG = {"source": "fem-campaign", "unit_size": 4, "walk_step": 0.2, "geometry": {"mesh_size": 4.0}}


def fabricate(root, samples=10, seed=5, units=None, fail_every=7):
    """A campaign-layout dataset of ``samples`` random samples (every fail_every-th id a
    failure) in units of 4, written with the campaign's shard and manifest functions."""
    n_units = dataset.unit_count(samples, CONFIG["unit_size"])
    for u in range(n_units) if units is None else units:
        ids = dataset.unit_ids(u, samples, CONFIG["unit_size"])
        rng = np.random.default_rng([seed, u])
        ok = ids[ids % fail_every != 3]
        bad = ids[ids % fail_every == 3]
        n = len(ok)
        arrays = shards.empty_arrays() | {
            "sample_id": ok, "inputs": rng.uniform(-1, 1, (n, 4)) * shards.INPUT_BOX,
            "anchors": rng.normal(size=(n, 10, 2)), "jacobian": rng.normal(size=(n, 20, 4)),
            "phi_end": rng.normal(size=n), "cap_rotation": rng.normal(size=n),
            "newton_iterations": np.full(n, 5), "wall_time_s": rng.uniform(1, 2, n),
            "converged": np.ones(n, bool), "failed_sample_id": bad,
            "failed_inputs": np.zeros((len(bad), 4)), "failed_reason": np.array(["cut-back"] * len(bad))}
        meta = {"config": CONFIG, "seed": seed, "unit": u, "git_commit": "test", "cpu_s": 10.0}
        shards.write_shard(root / dataset.shard_file(u), arrays, meta)
    scan = dataset.ShardScanner(root, samples, CONFIG, seed).scan()
    return dataset.build_manifest(root, samples, CONFIG, seed, scan)


def cli(*args):
    return subprocess.run([PY, "-m", "workflow.dataset", *map(str, args)],
                          capture_output=True, text=True)


def test_split_keeps_walk_blocks_whole_and_is_stable():
    """Each block of SPLIT_BLOCK consecutive ids (a stretch of one walk) has one label; the
    paper's 2,560 samples split exactly 1792/512/256, and so does every group of 10 blocks;
    a dataset's first 1,000 ids keep their labels when it grows; another seed gives
    another split."""
    ids = np.arange(4000 * shards.SPLIT_BLOCK)
    label = shards.split_of(ids, seed=1)
    blocks = label.reshape(-1, shards.SPLIT_BLOCK)
    assert (blocks == blocks[:, :1]).all()
    assert np.bincount(label[:2560]).tolist() == [1792, 512, 256]
    assert (np.stack([np.bincount(g, minlength=3) for g in blocks[:, 0].reshape(-1, 10)]) == [7, 2, 1]).all()
    np.testing.assert_array_equal(shards.split_of(ids[:1000], seed=1), label[:1000])
    assert (shards.split_of(ids, seed=2) != label).mean() > 0.3


def test_info_counts_split_and_coverage(tmp_path):
    """info on a 10-sample dataset (ids 3 a failure): 9 samples, 1 failure (10%), 3 shards,
    a 7:2:1-style split summing to 9, per-input ranges inside the box, complete=True."""
    fabricate(tmp_path)
    d = dataset.info(tmp_path)
    assert (d["samples"], d["failures"], d["shards"], d["complete"]) == (9, 1, 3, True)
    assert d["failure_rate"] == pytest.approx(0.1)
    assert sum(d["split"].values()) == 9
    for i, c in enumerate(d["coverage"]["per_input"].values()):
        assert -shards.INPUT_BOX[i] <= c["min"] <= c["max"] <= shards.INPUT_BOX[i]
    out = cli("info", tmp_path, "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["samples"] == 9


def test_verify_good_then_corrupt_exit_codes(tmp_path):
    """verify exits 0 on a clean dataset; after one flipped byte inside a shard it exits 1
    naming the corrupt shard; after deleting a listed shard it exits 1 too."""
    fabricate(tmp_path)
    good = cli("verify", tmp_path)
    assert good.returncode == 0, good.stdout + good.stderr
    assert "OK" in good.stdout
    path = tmp_path / dataset.shard_file(1)
    blob = bytearray(path.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    path.write_bytes(bytes(blob))
    bad = cli("verify", tmp_path, "--json")
    assert bad.returncode == 1
    report = json.loads(bad.stdout)
    assert not report["ok"] and "unit-00001" in report["errors"][0]
    path.unlink()
    assert cli("verify", tmp_path).returncode == 1


def test_verify_flags_incomplete_and_out_of_box(tmp_path):
    """A campaign with one of 3 units missing verifies with an 'incomplete' warning (exit 0),
    and fails (exit 1) with --require-complete. An out-of-box input is an error."""
    fabricate(tmp_path, units=[0, 2])
    r = dataset.verify(tmp_path)
    assert r["ok"] and any("incomplete" in w for w in r["warnings"])
    assert cli("verify", tmp_path, "--require-complete").returncode == 1
    other = tmp_path / "box"
    fabricate(other)
    arrays, meta = shards.read_shard(other / dataset.shard_file(0))
    arrays["inputs"][0, 3] = 150.0                                  # |M| > 100 N·mm
    shards.write_shard(other / dataset.shard_file(0), arrays, meta)
    m = shards.load_manifest(other)
    dataset.build_manifest(other, 10, CONFIG, 5, dataset.ShardScanner(other, 10, CONFIG, 5).scan(), m)
    r = dataset.verify(other)
    assert not r["ok"] and any("outside the box" in e for e in r["errors"])


def test_merge_pieces_equals_whole(tmp_path):
    """Two pieces of one campaign (units {0, 1} and {1, 2}, overlapping in unit 1) merge into
    a dataset whose samples equal the whole campaign's; a piece with another seed is refused."""
    whole, a, b, out = (tmp_path / n for n in ("whole", "a", "b", "out"))
    fabricate(whole)
    fabricate(a, units=[0, 1])
    fabricate(b, units=[1, 2])
    m = dataset.merge(out, [a, b])
    assert m["complete"] and m["samples"] == 9
    x, _ = shards.load_dataset(out)
    y, _ = shards.load_dataset(whole)
    for k in dataset.REPRODUCIBLE_KEYS:
        np.testing.assert_array_equal(x[k], y[k])
    fabricate(tmp_path / "c", seed=6)
    r = cli("merge", tmp_path / "d", a, tmp_path / "c")
    assert r.returncode == 1 and "seed or config differs" in r.stderr


def test_scanner_rejects_foreign_and_misplaced_shards(tmp_path):
    """The scanner accepts only shards of this campaign: a unit-1 shard copied over unit 2
    (right checksum, wrong unit) and a shard from another seed are reported, not used."""
    fabricate(tmp_path)
    shutil.copyfile(tmp_path / dataset.shard_file(1), tmp_path / dataset.shard_file(2))
    scanner = dataset.ShardScanner(tmp_path, 10, CONFIG, 5)
    assert sorted(scanner.scan()) == [0, 1] and 2 in scanner.problems
    assert dataset.ShardScanner(tmp_path, 10, CONFIG, 99).scan() == {}


def test_cli_usage_errors():
    """--help exits 0; a missing subcommand or a negative --mirror exits 2 with a one-line
    error on stderr."""
    assert cli("--help").returncode == 0
    for args in ([], ["verify", "x", "--mirror", "-1"]):
        r = cli(*args)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("name, n", [("train", 2560), ("heldout", 256)])
def test_committed_dataset_verifies_complete(name, n):
    """The committed FEM datasets (results/data) verify clean and complete: every shard's
    sha256 and checksum, the unit layout, 0 failures, the paper's 2,560 training samples
    (256 held out), every input inside the box |P| <= 0.3, |F| <= 3, |M| <= 100."""
    root = Path(__file__).resolve().parents[1] / "results/data" / name
    out = cli("verify", root, "--require-complete", "--json")
    assert out.returncode == 0, out.stdout + out.stderr
    data, manifest = shards.load_dataset(root)
    assert manifest["samples"] == n and manifest["failures"] == 0 and manifest["complete"]
    assert len(data["sample_id"]) == n and np.isfinite(data["jacobian"]).all()
    assert (np.abs(data["inputs"]) <= shards.INPUT_BOX).all()
