"""Tests of the dataset format and tools (workflow.shards, workflow.store and the
workflow.dataset command line), on fabricated campaign-layout datasets.

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

from contract.spec import BOX_TOL, INPUT_BOX
from workflow import shards, store
from workflow.shards import Manifest, ShardError

PY = sys.executable
CONFIG = {"source": "fem-campaign", "unit_size": 4, "walk_step": 0.2, "geometry": {"mesh_size": 4.0}}


def fabricate(root, samples=10, seed=5, units=None, fail_every=7, config=CONFIG, edit=None):
    """A campaign-layout dataset of ``samples`` random samples (every fail_every-th id a
    failure) in units of 4, written with the campaign's shard and manifest functions;
    ``edit(arrays)`` changes a unit's arrays before they are written."""
    n_units = store.unit_count(samples, CONFIG["unit_size"])
    for u in range(n_units) if units is None else units:
        ids = store.unit_ids(u, samples, CONFIG["unit_size"])
        rng = np.random.default_rng([seed, u])
        ok = ids[ids % fail_every != 3]
        bad = ids[ids % fail_every == 3]
        n = len(ok)
        arrays = shards.empty_arrays() | {
            "sample_id": ok, "inputs": rng.uniform(-1, 1, (n, 4)) * INPUT_BOX,
            "anchors": rng.normal(size=(n, 10, 2)), "jacobian": rng.normal(size=(n, 20, 4)),
            "phi_end": rng.normal(size=n), "cap_rotation": rng.normal(size=n),
            "newton_iterations": np.full(n, 5), "wall_time_s": rng.uniform(1, 2, n),
            "converged": np.ones(n, bool), "failed_sample_id": bad,
            "failed_inputs": np.zeros((len(bad), 4)), "failed_reason": np.array(["cut-back"] * len(bad))}
        if edit:
            edit(arrays)
        meta = {"config": config, "seed": seed, "unit": u, "git_commit": "test", "cpu_s": 10.0}
        shards.write_shard(root / store.shard_file(u), arrays, meta)
    scan = store.ShardScanner(root, samples, config, seed).scan()
    return store.build_manifest(root, samples, config, seed, scan)


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
    d = store.info(tmp_path)
    assert (d["samples"], d["failures"], d["shards"], d["complete"]) == (9, 1, 3, True)
    assert d["failure_rate"] == pytest.approx(0.1)
    assert sum(d["split"].values()) == 9
    for i, c in enumerate(d["coverage"]["per_input"].values()):
        assert -INPUT_BOX[i] <= c["min"] <= c["max"] <= INPUT_BOX[i]
    out = cli("info", tmp_path, "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["samples"] == 9


def test_walk_consistency_is_exact_on_quadratic_data_and_measures_a_cubic(tmp_path):
    """store.walk_consistency: the trapezoid rule on consecutive samples of one unit (both
    converged) is exact where the anchors are quadratic in the inputs (miss at round-off);
    a cubic term c (d.x)^3 on one anchor coordinate makes it miss by exactly |c| |d.dx|^3 / 2
    on each pair (exact solution: g(t) = c (s0 + t s)^3 gives g(1) - g(0) - (g'(0) + g'(1)) / 2
    = -c s^3 / 2). 24 samples in units of 4, id 3 mod 7 failed: 13 pairs."""
    rng = np.random.default_rng(0)
    A, B = rng.normal(size=(20, 4)), rng.normal(size=(20, 4, 4))
    B = B + B.transpose(0, 2, 1)
    d, c = np.array([0.3, -0.2, 0.5, 0.1]), 0.7

    def field(cubic):
        def edit(arrays):
            x = arrays["inputs"] / INPUT_BOX
            a = x @ A.T + 0.5 * np.einsum("ni,kij,nj->nk", x, B, x)
            J = A[None] + np.einsum("kij,nj->nki", B, x)
            if cubic:
                a[:, 0] += c * (x @ d) ** 3
                J[:, 0] += 3 * c * (x @ d)[:, None] ** 2 * d
            arrays["anchors"] = a.reshape(-1, 10, 2)
            arrays["jacobian"] = J / INPUT_BOX          # d a / d inputs (x = inputs / box)
        return edit

    for cubic in (False, True):
        root = tmp_path / str(cubic)
        fabricate(root, samples=24, edit=field(cubic))
        arrays, manifest = shards.load_dataset(root)
        w = store.walk_consistency(arrays, manifest.config["unit_size"])
        ids = arrays["sample_id"]
        pair = np.nonzero((np.diff(ids) == 1) & (ids[1:] // 4 == ids[:-1] // 4))[0]
        assert w["pairs"] == len(pair) == 13
        if not cubic:
            assert w["max_mm"] < 1e-12
            continue
        x = arrays["inputs"] / INPUT_BOX
        exact = 0.5 * abs(c) * np.abs((x[pair + 1] - x[pair]) @ d) ** 3
        assert w["max_mm"] == pytest.approx(exact.max(), rel=1e-9)
        assert w["median_mm"] == pytest.approx(np.median(exact), rel=1e-9)
    assert store.info(root)["walk_consistency"] == w


def test_verify_good_then_corrupt_exit_codes(tmp_path):
    """verify exits 0 on a clean dataset; after one flipped byte inside a shard it exits 1
    naming the corrupt shard; after deleting a listed shard it exits 1 too."""
    fabricate(tmp_path)
    good = cli("verify", tmp_path)
    assert good.returncode == 0, good.stdout + good.stderr
    assert "OK" in good.stdout
    path = tmp_path / store.shard_file(1)
    blob = bytearray(path.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    path.write_bytes(bytes(blob))
    bad = cli("verify", tmp_path, "--json")
    assert bad.returncode == 1
    report = json.loads(bad.stdout)
    assert not report["ok"] and "unit-00001" in report["errors"][0]
    path.unlink()
    assert cli("verify", tmp_path).returncode == 1


def set_input(root, value, column=3):
    """Overwrite input[0, column] of unit 0 in place (shard re-written, manifest rebuilt)."""
    arrays, meta = shards.read_shard(root / store.shard_file(0))
    arrays["inputs"][0, column] = value
    shards.write_shard(root / store.shard_file(0), arrays, meta)
    store.build_manifest(root, 10, CONFIG, 5, store.ShardScanner(root, 10, CONFIG, 5).scan(),
                         Manifest.load(root))


def test_verify_flags_incomplete_and_out_of_box(tmp_path):
    """A campaign with one of 3 units missing verifies with an 'incomplete' warning (exit 0),
    and fails (exit 1) with --require-complete; --require-units A:B (a job-array slice)
    passes for 0:1 and 2:3 and fails naming unit 1 for 0:3. An input outside the box of contract.spec
    (|M| = 150 > 100 N·mm, or NaN) is an error; one on the box edge up to contract.spec's
    relative BOX_TOL (float32 round-off) is not."""
    fabricate(tmp_path, units=[0, 2])
    r = store.verify(tmp_path)
    assert r["ok"] and any("incomplete" in w for w in r["warnings"])
    assert cli("verify", tmp_path, "--require-complete").returncode == 1
    assert [cli("verify", tmp_path, "--require-units", u).returncode for u in ("0:1", "2:3")] == [0, 0]
    r = cli("verify", tmp_path, "--require-units", "0:3")
    assert r.returncode == 1 and "units missing from the slice 0:3: [1]" in r.stdout, r.stdout
    other = tmp_path / "box"
    fabricate(other)
    set_input(other, 100.0 * (1 + BOX_TOL / 2))
    assert store.verify(other)["ok"]
    for value in (150.0, -100.0 * (1 + 2 * BOX_TOL), np.nan):
        set_input(other, value)
        r = store.verify(other)
        assert not r["ok"] and any("1 input(s) non-finite or outside the box" in e for e in r["errors"]), value


def test_merge_pieces_equals_whole(tmp_path):
    """Two pieces of one campaign (units {0, 1} and {1, 2}, overlapping in unit 1) merge into
    a dataset whose samples equal the whole campaign's; a piece with another seed is refused."""
    whole, a, b, out = (tmp_path / n for n in ("whole", "a", "b", "out"))
    fabricate(whole)
    fabricate(a, units=[0, 1])
    fabricate(b, units=[1, 2])
    m = store.merge(out, [a, b])
    assert m.complete and m.samples == 9 and m == Manifest.load(out)
    x, _ = shards.load_dataset(out)
    y, _ = shards.load_dataset(whole)
    for k in store.REPRODUCIBLE_KEYS:
        np.testing.assert_array_equal(x[k], y[k])
    fabricate(tmp_path / "c", seed=6)
    r = cli("merge", tmp_path / "d", a, tmp_path / "c")
    assert r.returncode == 2 and "seed or config differs" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "d").exists()


def test_scanner_rejects_foreign_and_misplaced_shards(tmp_path):
    """The scanner accepts only shards of this campaign: a unit-1 shard copied over unit 2
    (right checksum, wrong unit) and a shard from another seed are reported, not used."""
    fabricate(tmp_path)
    shutil.copyfile(tmp_path / store.shard_file(1), tmp_path / store.shard_file(2))
    scanner = store.ShardScanner(tmp_path, 10, CONFIG, 5)
    assert sorted(scanner.scan()) == [0, 1] and 2 in scanner.problems
    assert store.ShardScanner(tmp_path, 10, CONFIG, 99).scan() == {}


def test_temporaries_are_cleaned_and_never_count_as_shards(tmp_path):
    """A killed writer's temp files (the old ``.NAME.*.tmp`` and contract.files'
    ``.NAME.*.tmp.npz``) are not reported as unlisted shards, and clean_temporaries removes
    exactly them."""
    fabricate(tmp_path)
    junk = [tmp_path / "shards/.unit-00001.npz.x.tmp", tmp_path / "shards/.unit-00001.ab12.tmp.npz",
            tmp_path / ".manifest.cd34.tmp.json"]
    for p in junk:
        p.write_bytes(b"half a file")
    assert store.verify(tmp_path)["warnings"] == []
    assert store.clean_temporaries(tmp_path) == 3 and not any(p.exists() for p in junk)
    assert store.verify(tmp_path)["ok"]


def test_compare_two_meshes_of_one_walk(tmp_path):
    """Exact: the other mesh's anchors all moved by (0.3, 0.4) mm -> 0.5 mm at every anchor;
    its phi_end by +0.1 rad -> 5.7296 deg; its cap rotation by 2 pi - 0.02 rad, which wraps
    to 1.1459 deg. Units 0 and 2 only: ids 0-2 and 8-9 (3 failed), 5 common samples. Another
    walk (seed) or other loads under the same ids are refused with one line, exit 2."""
    def moved(a):
        a["anchors"] = a["anchors"] + [0.3, 0.4]
        a["phi_end"] = a["phi_end"] + 0.1
        a["cap_rotation"] = a["cap_rotation"] + 2 * np.pi - 0.02
    fine = CONFIG | {"geometry": {"mesh_size": 2.0, "wall_mesh_size": 1.0}}
    fabricate(tmp_path / "ref")
    fabricate(tmp_path / "fine", units=[0, 2], config=fine, edit=moved)
    out = tmp_path / "cmp.json"
    r = cli("compare", tmp_path / "ref", tmp_path / "fine", "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert d == json.loads(r.stdout) and d["samples"] == 5 and d["ref_samples"] == 9
    assert d["other_mesh"] == {"mesh": "2:1", "mesh_size": 2.0, "wall_mesh_size": 1.0, "formulation": "displacement"}
    for key, exact in (("anchor_mm", 0.5), ("tip_mm", 0.5), ("phi_end_deg", np.degrees(0.1)),
                       ("cap_rotation_deg", np.degrees(0.02))):
        assert np.allclose(list(d[key].values()), exact, atol=1e-9), key
    fabricate(tmp_path / "seed6", seed=6, config=fine)
    fabricate(tmp_path / "loads", config=fine, edit=lambda a: a.update(inputs=a["inputs"] * 0.5))
    for other, needle in (("seed6", "another campaign walk"), ("loads", "different loads")):
        r = cli("compare", tmp_path / "ref", tmp_path / other, "--out", tmp_path / "x.json")
        assert r.returncode == 2 and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr
        assert not (tmp_path / "x.json").exists()


def test_cli_usage_errors(tmp_path):
    """--help exits 0; a missing subcommand, a negative or NaN --mirror, and a folder that
    is not a dataset (info, verify, merge) exit 2 with a one-line error on stderr."""
    assert cli("--help").returncode == 0
    for args in ([], ["verify", "x", "--mirror", "-1"], ["verify", "x", "--mirror", "nan"],
                 ["info", tmp_path], ["verify", tmp_path], ["merge", tmp_path / "m", tmp_path]):
        r = cli(*args)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "m").exists()


def _manifest_file(tmp_path, edit) -> Path:
    """A copy of a valid campaign manifest with ``edit(dict)`` applied."""
    fabricate(tmp_path)
    raw = json.loads(Manifest.path(tmp_path).read_text())
    edit(raw)
    Manifest.path(tmp_path).write_text(json.dumps(raw))
    return tmp_path


BAD_MANIFESTS = {
    "not a softjoint dataset": lambda raw: raw.clear() or raw.update(hello=1),
    "format 'softjoint-dataset/0'": lambda raw: raw.update(format="softjoint-dataset/0"),
    "no 'seed'": lambda raw: raw.pop("seed"),
    "'seed' must be a int": lambda raw: raw.update(seed="5"),
    "'config' must be an object": lambda raw: raw.update(config=[1]),
    "unknown manifest field(s) ['extra']": lambda raw: raw.update(extra=1),
    "shards[1]: 'sha256' is not a sha256": lambda raw: raw["shards"][1].update(sha256="abc"),
    "shards[0]: 'file' must be a path inside": lambda raw: raw["shards"][0].update(file="../x.npz"),
    "shards[2]: negative count": lambda raw: raw["shards"][2].update(failures=-1),
    "shards[0]: 'n' must be a int": lambda raw: raw["shards"][0].update(n=True),
    "'samples' 10 != 9": lambda raw: raw.update(samples=10),
    "'complete' disagrees": lambda raw: raw.update(complete=False),
    "a shard is listed twice": lambda raw: raw["shards"].append(raw["shards"][0]),
    "without its 'unit'": lambda raw: raw["shards"][0].pop("unit"),
}


@pytest.mark.parametrize("needle", BAD_MANIFESTS)
def test_manifest_is_validated_once_on_load(tmp_path, needle):
    """Manifest.load refuses a foreign, other-format or invalid manifest with ONE line that
    names the field (load_dataset, info, verify and merge all read it through Manifest.load)."""
    root = _manifest_file(tmp_path, BAD_MANIFESTS[needle])
    with pytest.raises(ShardError) as exc:
        shards.load_dataset(root)
    assert needle in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_invalid_manifest_on_the_command_line(tmp_path):
    """info refuses an invalid manifest with one line (exit 2); verify reports it as the
    dataset's problem (exit 1, in its JSON errors)."""
    root = _manifest_file(tmp_path, BAD_MANIFESTS["'samples' 10 != 9"])
    r = cli("info", root)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "'samples' 10 != 9" in r.stderr
    r = cli("verify", root, "--json")
    assert r.returncode == 1 and "'samples' 10 != 9" in json.loads(r.stdout)["errors"][0]


def test_manifest_corrupt_or_missing(tmp_path):
    """A manifest that is not JSON is 'corrupt'; a folder without one is 'not a softjoint
    dataset' (and the message names the folder)."""
    with pytest.raises(ShardError, match="no manifest.json"):
        Manifest.load(tmp_path)
    Manifest.path(tmp_path).write_bytes(b"\x00\xff{")
    with pytest.raises(ShardError, match="corrupt manifest"):
        Manifest.load(tmp_path)
    Manifest.path(tmp_path).write_text("[1, 2]")
    with pytest.raises(ShardError, match="not a softjoint dataset manifest"):
        Manifest.load(tmp_path)


@pytest.mark.parametrize("name, n", [("train", 2560), ("heldout", 256), ("train_h1.8", 2560), ("heldout_h1.8", 256)])
def test_committed_dataset_verifies_complete(name, n):
    """The committed FEM datasets (results/data) verify clean and complete: every shard's
    sha256 and checksum, the unit layout, 0 failures, the paper's 2,560 training samples
    (256 held out), every input inside the box |P| <= 0.3, |F| <= 3, |M| <= 100. Their
    manifest.json loads into a Manifest and writes back byte for byte."""
    root = Path(__file__).resolve().parents[1] / "results/data" / name
    out = cli("verify", root, "--require-complete", "--json")
    assert out.returncode == 0, out.stdout + out.stderr
    data, manifest = shards.load_dataset(root)
    assert manifest.samples == n and manifest.failures == 0 and manifest.complete
    assert manifest.units_done == manifest.units_total == len(manifest.shards)
    assert len(data["sample_id"]) == n and np.isfinite(data["jacobian"]).all()
    assert (np.abs(data["inputs"]) <= INPUT_BOX).all()
    text = json.dumps(manifest.to_json(), indent=1, sort_keys=True)
    assert text == Manifest.path(root).read_text()
