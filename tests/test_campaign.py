"""Tests of the MPI data campaign (workflow.campaign) on the coarse joint mesh (4 mm).

One uninterrupted reference campaign (4 samples in 2 units of 2, seed 11) is run once
per module in a subprocess; the kill/resume, corrupt-shard and 2-rank runs must reproduce
it exactly (every array except the timings). In-process checks share one coarse solver.
On a shared 2-core machine the file takes about 2.5 minutes (the mpirun test, marked
``mpi``, about 25 s of it).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from contract.spec import INPUT_BOX
from workflow import campaign, dataset, shards, store
from workflow.shards import Manifest

PY = sys.executable
ROOT = Path(__file__).resolve().parents[1]
COARSE = 4.0
ARGS = ["--samples", "4", "--seed", "11", "--unit-size", "2", "--mesh-size", str(COARSE),
        "--formulation", "displacement", "--fresh-check-every", "2", "--quiet", "--json"]
#: the committed datasets' discretisation (fem.mesh.discretisation.PAPER; `make dataset` passes it)
PAPER_MESH = ["--mesh-size", "1.8", "--formulation", "displacement"]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OMPI_ALLOW_RUN_AS_ROOT": "1",
       "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


def run_campaign(out, *extra, mpirun=None):
    """Run the campaign CLI into ``out``; return (exit code, JSON summary or None)."""
    cmd = (mpirun or []) + [PY, "-m", "workflow.campaign", *ARGS, "--out", str(out), *extra]
    r = subprocess.run(cmd, cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=900)
    start = r.stdout.find("{\n")
    return r.returncode, (json.loads(r.stdout[start:r.stdout.rindex("}") + 1]) if start >= 0 else None)


def assert_same_samples(a, b):
    """Two datasets hold identical samples and failures (timings aside)."""
    x, _ = shards.load_dataset(a)
    y, _ = shards.load_dataset(b)
    for k in store.REPRODUCIBLE_KEYS:
        np.testing.assert_array_equal(x[k], y[k], err_msg=k)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted reference campaign (exit 0, 4 converged samples, complete)."""
    out = tmp_path_factory.mktemp("campaign") / "ref"
    code, summary = run_campaign(out)
    assert code == 0 and summary["complete"] and summary["samples"] == 4, summary
    return out


@pytest.fixture(scope="module")
def solver():
    from mpi4py import MPI

    from fem.mesh.geometry import JointGeometry
    from fem.solvers.joint import JointSolver
    return JointSolver(JointGeometry(mesh_size=COARSE, divisions=0, hex_size=None), MPI.COMM_SELF,
                       formulation="displacement")


def test_walk_is_seeded_in_box_and_rank_free():
    """unit_walk: same (seed, unit) -> same inputs; a longer unit extends a shorter one; all
    inputs inside the box; consecutive points `step` apart in box-normalised coordinates
    unless a face reflection shortened the step; different units differ."""
    a = campaign.unit_walk(3, 5, 50, 0.2)
    np.testing.assert_array_equal(a, campaign.unit_walk(3, 5, 50, 0.2))
    np.testing.assert_array_equal(a[:20], campaign.unit_walk(3, 5, 20, 0.2))
    assert (np.abs(a) <= INPUT_BOX).all()
    d = np.linalg.norm(np.diff(a / INPUT_BOX, axis=0), axis=1)
    assert (d <= 0.2 + 1e-12).all() and np.mean(np.isclose(d, 0.2)) > 0.8
    assert not np.allclose(a, campaign.unit_walk(3, 6, 50, 0.2))


def test_walk_sweeps_the_box():
    """The persistent walk keeps the uniform distribution (each box-normalised input has
    mean 0 and variance 1/3, to sampling error) and, over 40 units of 64 steps of 0.1,
    occupies >= 85 % of the 4^4 grid cells, well above a plain random walk of the same step
    (turn -> infinity: a fresh random direction each step), which stays near its start."""
    def walks(turn):
        z = np.concatenate([campaign.unit_walk(1, u, 64, 0.1, turn) for u in range(40)])
        return z / INPUT_BOX

    def occupancy(z):
        return len({tuple(c) for c in np.floor((z + 1) / 0.5).clip(0, 3).astype(int)}) / 4 ** 4

    z = walks(campaign.WALK_TURN)
    assert np.abs(z.mean(0)).max() < 0.1 and np.abs(z.var(0) - 1 / 3).max() < 0.05
    steps = np.diff(z.reshape(40, 64, 4), axis=1)            # within units
    cos = (steps[:, 1:] * steps[:, :-1]).sum(-1) / np.linalg.norm(steps[:, 1:], axis=-1) \
        / np.linalg.norm(steps[:, :-1], axis=-1)
    assert np.median(cos) > 0.9                              # persistent, not a random walk
    assert occupancy(z) >= 0.85 and occupancy(z) > occupancy(walks(1e9)) + 0.15


def test_cli_errors_and_budget_stop(tmp_path):
    """--help exits 0; bad arguments exit 2 with a one-line error; a budget too small for
    any unit exits 3 (resume later) leaving a valid, empty, incomplete manifest."""
    r = subprocess.run([PY, "-m", "workflow.campaign", "--help"], cwd=ROOT, capture_output=True)
    assert r.returncode == 0
    for bad in (["--samples", "0"], ["--step", "3"], ["--units", "5:9"], ["--bogus"]):
        r = subprocess.run([PY, "-m", "workflow.campaign", *ARGS, "--out", str(tmp_path), *bad],
                           cwd=ROOT, capture_output=True, text=True)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (bad, r.stderr)
    code, summary = run_campaign(tmp_path / "budget", "--max-hours", "1e-9")
    assert code == campaign.EXIT_INCOMPLETE and summary["stopped_by_budget"]
    m = Manifest.load(tmp_path / "budget")
    assert m.complete is False and m.shards == () and m.units_total == 2


def _snapshot(root: Path) -> dict[str, bytes]:
    """Every file and folder under root (relative path -> bytes, b"/" for a folder)."""
    return {str(p.relative_to(root)): b"/" if p.is_dir() else p.read_bytes() for p in root.rglob("*")}


def test_refused_run_leaves_the_dataset_untouched(tmp_path):
    """A campaign refused by the compatibility check (another --seed, another config: here
    the mesh, named with both values, or the production discretisation of the defaults
    against the 1.8 mm reference set's paper-fidelity one; or fewer --samples: a campaign never
    shrinks) exits 2 with one line and leaves an existing dataset folder byte for
    byte as it was (the mesh, or the wall mesh alone): no .campaign.lock, no shards/ folder, no manifest rewrite; pointed at a
    folder that does not exist yet, a refused run (--units beyond the unit count) creates
    nothing either."""
    held = ROOT / "results/data/heldout_h1.8"              # the 1.8 mm reference set (seed 2)
    partial = tmp_path / "heldout"
    shutil.copytree(held, partial)
    (partial / "shards" / "unit-00003.npz").unlink()      # an unfinished campaign to resume
    args = ["--unit-size", "16", "--quiet", "--out"]
    for out, extra, needle in ((held, ["--seed", "3", *PAPER_MESH], "--seed 2, not --seed 3"),
                               (partial, ["--seed", "3", *PAPER_MESH], "--seed 2, not --seed 3"),
                               (partial, ["--seed", "2", "--mesh-size", "4", "--formulation", "displacement"],
                                "made with --mesh-size 1.8 mm (this run: 4 mm)"),
                               (partial, ["--seed", "2", "--wall-mesh-size", "0.9", "--formulation", "displacement"],
                                "made with --wall-mesh-size unset (this run: 0.9 mm)"),
                               (partial, ["--seed", "2"], "made with --formulation displacement (this run: mixed); "
                                "--divisions tetrahedra (this run: 2); --hex-size uniform (this run: 3 mm)"),
                               (partial, ["--seed", "2", "--samples", "128", *PAPER_MESH],
                                "holds a campaign of --samples 256; --samples 128 would drop")):
        extra = extra if "--samples" in extra else [*extra, "--samples", "256"]
        before = _snapshot(out)
        r = subprocess.run([PY, "-m", "workflow.campaign", *args, str(out), *extra], cwd=ROOT,
                           env=ENV, capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and needle in r.stderr, r.stderr
        assert _snapshot(out) == before and not (out / ".campaign.lock").exists()
    r = subprocess.run([PY, "-m", "workflow.campaign", *args, str(tmp_path / "new"), "--seed", "1",
                        "--samples", "256", "--units", "16:17"], cwd=ROOT, env=ENV, capture_output=True, text=True)
    assert r.returncode == 2 and "outside 0:16" in r.stderr and not (tmp_path / "new").exists()


@pytest.mark.fem
def test_kill9_midway_then_resume_is_identical(reference, tmp_path):
    """kill -9 during unit 1 (after unit 0's shard appeared), then the same command: exit 0,
    only the missing unit is solved again, no temp file remains, and the dataset equals
    the uninterrupted reference sample for sample."""
    out = tmp_path / "killed"
    cmd = [PY, "-m", "workflow.campaign", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    first = out / store.shard_file(0)
    deadline = time.time() + 600
    while not first.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)                       # inside unit 1's first (from-zero) solve (~5 s)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / store.shard_file(1)).exists(), "kill came too late to test resume"
    (out / "shards" / ".unit-00001.npz.stale.tmp").write_bytes(b"half a shard")
    code, summary = run_campaign(out)
    assert code == 0 and summary["units_run"] == 1 and summary["complete"]
    assert not list(out.rglob("*.tmp"))
    assert_same_samples(out, reference)


@pytest.mark.fem
def test_corrupt_shard_is_detected_and_redone(reference, tmp_path):
    """One flipped byte in unit 1's shard: verify exits 1; the campaign re-run redoes
    exactly that unit; the result equals the reference and verifies clean."""
    out = tmp_path / "corrupt"
    shutil.copytree(reference, out)
    path = out / store.shard_file(1)
    blob = bytearray(path.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    path.write_bytes(bytes(blob))
    assert dataset.main(["verify", str(out)]) == 1
    code, summary = run_campaign(out)
    assert code == 0 and summary["units_run"] == 1
    assert_same_samples(out, reference)
    assert dataset.main(["verify", str(out)]) == 0


@pytest.mark.fem
def test_harvested_sample_equals_fresh_solve(reference, solver):
    """The second sample of each unit, reached by continuation along the walk, equals a
    solve from zero at the same inputs to 1e-6 mm: unit 0 by the campaign's own check
    (--fresh-check-every 2, recorded in the shard meta), unit 1 here."""
    from fem.solvers.joint import Load

    data, _ = shards.load_dataset(reference)
    _, meta = shards.read_shard(reference / store.shard_file(0))
    (check,) = meta["fresh_checks"]
    assert check["stored"] == "harvested" and check["max_anchor_diff_mm"] < 1e-6
    i = int(np.flatnonzero(data["sample_id"] == 3)[0])          # unit 1, harvested
    res = solver.solve(Load.from_array(data["inputs"][i]), continuation=False)
    assert res.converged
    assert np.abs(res.anchors - data["anchors"][i]).max() < 1e-6


@pytest.mark.fem
def test_jacobian_matches_central_differences(reference, solver):
    """The stored Jacobian (20, 4) of sample 3 matches central differences of converged
    solves at x ± h e_k (h = 1e-3 of the box half-width) to 1e-3 relative error, column by
    column (scaled by the column's largest entry)."""
    from fem.solvers.joint import Load

    data, _ = shards.load_dataset(reference)
    i = int(np.flatnonzero(data["sample_id"] == 3)[0])
    x, jac = data["inputs"][i], data["jacobian"][i]
    # Continuation from whatever state the shared solver holds: a converged path either way.
    assert solver.solve(Load.from_array(x), continuation=True).converged
    fd = np.empty((20, 4))
    for k in range(4):
        h = 1e-3 * INPUT_BOX[k]
        r = []
        for sign in (1.0, -1.0):
            e = x.copy()
            e[k] += sign * h
            res = solver.solve(Load.from_array(e), continuation=True)
            assert res.converged
            r.append(res.anchors.reshape(20))
        fd[:, k] = (r[0] - r[1]) / (2 * h)
    err = np.abs(fd - jac).max(axis=0) / np.abs(fd).max(axis=0)
    assert (err < 1e-3).all(), err


@pytest.mark.fem
def test_mirror_relation_via_verify(reference):
    """verify --mirror 1 solves the y-mirror of one stored sample: exit 0, anchors within
    1e-6 mm of R·diag(1,-1) and the Jacobian within 1e-4 of S·J·B (docs/physics.md; the
    mesh itself is mirror symmetric, so this holds to solver tolerance)."""
    r = subprocess.run([PY, "-m", "workflow.dataset", "verify", str(reference), "--mirror", "1",
                        "--json"], cwd=ROOT, env=ENV, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(r.stdout[r.stdout.find("{\n"):])
    assert report["mirror"]["max_anchor_error_mm"] < 1e-6
    assert report["mirror"]["max_jacobian_rel_error"] < 1e-4


@pytest.mark.fem
@pytest.mark.mpi
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_two_ranks_give_identical_samples(reference, tmp_path):
    """mpirun -n 2 (two groups of one rank, one unit each) yields the same samples as the
    1-rank reference, bit for bit (timings aside)."""
    code, summary = run_campaign(tmp_path / "mpi", mpirun=["mpirun", "--oversubscribe", "-n", "2"])
    assert code == 0 and summary["ranks"] == 2 and summary["complete"]
    assert_same_samples(tmp_path / "mpi", reference)


#: The config of the production held-out campaign (`make dataset`: --samples 256 --seed 2
#: --unit-size 16 --divisions 2 --hex-size 3 --formulation mixed), frozen from its manifest
#: (results/data/heldout, the production walk): the default campaign of
#: the paper's joint file must keep producing it, or that campaign could not resume.
HEX2S3_CONFIG = {
    "formulation": "mixed", "fresh_check_every": 8,
    "geometry": {"cap": 3.0, "divisions": 2, "height": 20.0, "hex_size": 3.0, "length": 45.45, "mesh_size": 1.8,
                 "n_cells": 5, "spine": 2.4, "valley_height": 8.8, "valley_width": 2.5, "wall": 1.2,
                 "wall_mesh_size": None, "width": 14.0},
    "input_box": [0.3, 3.0, 3.0, 100.0], "material": {"E": 12.2, "cap_nu": 0.3, "cap_stiffness": 100.0, "nu": 0.49},
    "solver": {"atol": 1e-08, "box_step": 0.25, "chord_steps": 3, "contact_penalty": 100.0, "degree": 2,
               "first_step": None, "grow": 1.5, "krylov_max_it": 30, "krylov_rtol": 1e-09, "max_it": 12,
               "max_step": 1.0, "min_step": 0.00390625, "mumps_blr": 1e-08, "quadrature_degree": 4,
               "sensitivity_rtol": 1e-10, "stol": 1e-09},
    "source": "fem-campaign", "unit_size": 16, "walk_step": 0.1, "walk_turn": 0.2}


def _cli_config(tmp_path, *flags) -> dict:
    """The manifest config workflow.campaign would record for these command-line flags."""
    args = campaign.parse_args(["--samples", "256", "--seed", "2", "--out", str(tmp_path / "new"), *flags])
    return campaign.campaign_config(args.geometry, args.unit_size, args.step, args.fresh_check_every,
                                    args.formulation or args.joint.formulation, args.joint)


def test_production_is_hex2s3_mixed_and_the_default_campaign_is_its_manifest(tmp_path):
    """fem.mesh.discretisation.PRODUCTION is hex2:3 mixed with quadrature 4 (key
    hex2s3_mixed_q4_k100), and it is every default: JointGeometry's mesh, JointSolver's
    formulation and (config_for) quadrature, the paper joint file's [mesh], fem.studies.bench_joint's
    --mesh/--formulation. The campaign of the paper's joint without mesh options, and the
    one `make dataset` spells out, both record HEX2S3_CONFIG key for key, and the
    defaults record the committed sets' configs; the PAPER options record the 1.8 mm
    reference sets' (results/data/*_h1.8)."""
    import inspect

    from contract.joint import load_joint
    from fem.mesh.discretisation import FORMULATION, PAPER, PRODUCTION, discretisation
    from fem.mesh.geometry import JointGeometry
    from fem.solvers.joint import JointSolver, config_for

    assert (PRODUCTION.mesh, PRODUCTION.formulation, PRODUCTION.quadrature, PRODUCTION.key) == \
        ("hex2:3", "mixed", 4, "hex2s3_mixed_q4_k100")
    assert (PRODUCTION.H, PRODUCTION.W, PRODUCTION.divisions, PRODUCTION.hex_size) == (None, None, 2, 3.0)
    assert PRODUCTION.geometry() == JointGeometry() and FORMULATION == PRODUCTION.formulation
    assert discretisation(PRODUCTION.mesh, formulation=PRODUCTION.formulation) == PRODUCTION   # bench_joint's defaults
    defaults = {k: p.default for k, p in inspect.signature(JointSolver.__init__).parameters.items()}
    assert defaults["geometry"] == JointGeometry() and defaults["formulation"] == "mixed"
    assert config_for(JointGeometry()).quadrature_degree == PRODUCTION.quadrature
    paper = load_joint()
    assert JointGeometry(**paper.geometry_kwargs()) == JointGeometry() and paper.formulation == "mixed"
    assert (PAPER.key, PAPER.mesh) == ("h1.8_wnone_displacement_q2_k100", "1.8")
    assert _cli_config(tmp_path, "--unit-size", "16") == HEX2S3_CONFIG
    assert _cli_config(tmp_path, "--unit-size", "16", "--divisions", "2", "--hex-size", "3", "--formulation",
                       "mixed") == HEX2S3_CONFIG
    assert campaign.campaign_config(JointGeometry(divisions=2, hex_size=3.0), 16, campaign.DEFAULT_STEP, 8,
                                    "mixed") == HEX2S3_CONFIG
    for name, flags in (("heldout", ["--unit-size", "16"]), ("train", ["--unit-size", "64"])):
        reference = Manifest.load(ROOT / "results/data" / f"{name}_h1.8").config
        assert _cli_config(tmp_path, *flags, *PAPER_MESH) == reference, name
        assert _cli_config(tmp_path, *flags) != reference
        assert _cli_config(tmp_path, *flags) == Manifest.load(ROOT / "results/data" / name).config, name
    assert not (tmp_path / "new").exists()


def test_a_failed_sample_resolved_on_a_finer_path_equals_the_campaigns_answer(reference, tmp_path, capsys):
    """workflow.resolve: sample 3 (unit 1's continuation sample) turned into a failure is
    re-solved from zero along segments of the load path and stored back in its unit's
    shard, in sample order, with how it was solved in the shard's meta: its anchors equal
    the campaign's to 1e-6 mm and its Jacobian to 1e-6 relative (a static equilibrium does
    not depend on the path that reached it), its walk pair's trapezoid miss is the
    campaign's, and the dataset verifies as before. A re-run finds nothing to do; an id
    that is not a failure is refused with exit 2."""
    from workflow import resolve
    from workflow.artefacts import RESOLVED

    root = tmp_path / "ds"
    shutil.copytree(reference, root)
    shard = root / store.shard_file(1)
    arrays, meta = shards.read_shard(shard)
    ref = {k: v.copy() for k, v in arrays.items()}
    i = int(np.flatnonzero(arrays["sample_id"] == 3)[0])
    keep = arrays["sample_id"] != 3
    failed = {k: arrays[k][keep] for k in shards.DATA_KEYS}
    failed.update(failed_sample_id=np.array([3]), failed_inputs=arrays["inputs"][i:i + 1],
                  failed_reason=np.array(["no convergence (made up by the test)"]))
    shards.write_shard(shard, {**arrays, **failed}, meta)          # the manifest is stale now
    summary = tmp_path / "resolved.json"
    assert resolve.main([str(root), "--fine-step", "0.05", "--out", str(summary), "--quiet", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (entry,) = out["samples"]
    assert entry["sample_id"] == 3 and entry["converged"] and out["failures"] == 0 and out["stored"] == 4
    assert entry["stiffness"]["unstable_modes"] == 0 and entry["stiffness"]["lowest_eigenvalue"] > 0   # stable
    got, meta2 = shards.read_shard(shard)
    assert got["sample_id"].tolist() == ref["sample_id"].tolist() and len(got["failed_sample_id"]) == 0
    assert np.abs(got["anchors"][i] - ref["anchors"][i]).max() < 1e-6
    assert np.abs(got["jacobian"][i] - ref["jacobian"][i]).max() < 1e-6 * np.abs(ref["jacobian"][i]).max()
    np.testing.assert_array_equal(got["inputs"], ref["inputs"])
    ((pair, miss),) = entry["walk_miss_mm"].items()
    assert pair == "2-3" and miss == pytest.approx(store.walk_misses(ref, 2)[-1][2], abs=1e-6)
    (how,) = meta2["resolved"]
    assert how["sample_id"] == 3 and how["max_it"] == 24 and how["path_points"][-1] == 1.0
    v = store.verify(root)
    assert v["ok"] and v["n"] == 4 and v["failures"] == 0, v
    doc = RESOLVED.load(summary)              # the summary JSON, rebuilt from the shards' meta
    (row,) = doc["samples"]
    assert (doc["stored"], doc["failures"], row["sample_id"], row["unstable_modes"]) == (4, 0, 3, 0)
    assert row["walk_pairs"] == [{"pair": "2-3", "miss_mm": pytest.approx(miss, abs=1e-12)}]
    summary.unlink()
    assert resolve.main([str(root), "--summary-only", "--out", str(summary)]) == 0 and RESOLVED.load(summary) == doc
    assert resolve.main([str(root), "--out", str(summary), "--quiet", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["samples"] == []
    with pytest.raises(SystemExit) as exc:
        resolve.main([str(root), "--samples", "3"])
    assert exc.value.code == 2 and "not failed samples" in capsys.readouterr().err
