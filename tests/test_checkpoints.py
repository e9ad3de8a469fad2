"""Integrity of the checkpoint files (issue 13, docs/formats.md).

Exact claims checked here:
- a save/load round trip returns the payload unchanged (tensors bit-equal);
- for every committed checkpoint (the surrogates and the three NN predictors), the file
  with ANY single byte changed is refused by the project's own loader with a one-line
  ValueError: every byte of the header line, 200 seeded random bytes of the archive and
  its last byte are each flipped in turn; so are the truncated file, the file with one
  byte appended and the empty file. (The loader compares the whole archive with the
  header's sha256 and length, so no position can escape; the sample shows it does.)
- a checkpoint of one kind is refused by the loader of another kind, and a plain
  ``torch.save`` file (the pre-integrity format) is refused.
- in a fresh clone make takes the committed checkpoints and figures as up to date (the
  Makefile gives every tracked file one time per clone): ``make -n`` of the predictor's
  targets trains nothing, and an edit of predictor/cli/nn.py makes the NNs stale again.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from surrogate import checkpoint, load_surrogate

ROOT = Path(__file__).resolve().parents[1]
SURROGATES = [ROOT / "results/surrogate/paper.pt", ROOT / "results/surrogate/improved.pt"]
PREDICTORS = {"gravity_nn.pt": False, "gravity_nn_paper.pt": False, "contact_nn.pt": True}


def _predictor_loader():
    from predictor.model.joint import load_joint
    from predictor.cli.nn import load_predictor

    joint = load_joint(str(ROOT / "results/surrogate/improved.pt"))
    return lambda path, contact: load_predictor(path, joint, contact=contact)


def _loaders():
    """(committed path, loader(path)) for every committed checkpoint."""
    out = [(p, load_surrogate) for p in SURROGATES]
    load_nn = _predictor_loader()
    for name, contact in PREDICTORS.items():
        out.append((ROOT / "results/predictor" / name, lambda p, c=contact: load_nn(p, c)))
    return out


def _refused(loader, path: Path) -> str:
    with pytest.raises(ValueError) as info:
        loader(path)
    message = str(info.value)
    assert message and "\n" not in message, message
    return message


def test_round_trip_is_exact(tmp_path):
    payload = {"w": torch.randn(5, 3, dtype=torch.float64), "config": {"widths": (2, 4), "lr": 1e-3},
               "history": [1.0, 0.5], "name": "x"}
    path = tmp_path / "a.pt"
    checkpoint.save(path, "softjoint-test/1", payload)
    back = checkpoint.load(path, "softjoint-test/1")
    assert torch.equal(back["w"], payload["w"]) and back["config"] == payload["config"]
    assert back["history"] == payload["history"] and back["name"] == "x"
    assert [p.name for p in tmp_path.iterdir()] == ["a.pt"]  # no temp file left behind
    with pytest.raises(checkpoint.CheckpointError, match="expected a 'softjoint-other/1'"):
        checkpoint.load(path, "softjoint-other/1")
    torch.save(payload, tmp_path / "old.pt")
    with pytest.raises(checkpoint.CheckpointError, match="no valid checkpoint header"):
        checkpoint.load(tmp_path / "old.pt", "softjoint-test/1")


@pytest.mark.parametrize("index", range(2 + len(PREDICTORS)))
def test_no_flipped_byte_of_a_committed_checkpoint_loads(index, tmp_path):
    path, loader = _loaders()[index]
    loader(path)  # the intact file loads
    data = path.read_bytes()
    header = data.index(b"\n") + 1
    rng = np.random.default_rng(index)
    positions = sorted(set(range(header)) | set(rng.integers(header, len(data), 200).tolist())
                       | {len(data) - 1})
    bad = tmp_path / path.name
    for pos in positions:
        flipped = bytearray(data)
        flipped[pos] ^= int(rng.integers(1, 256))
        bad.write_bytes(bytes(flipped))
        _refused(loader, bad)
    for damaged in (data[: len(data) // 2], data + b"\0", b""):
        bad.write_bytes(damaged)
        _refused(loader, bad)


def test_a_checkpoint_of_another_kind_is_refused(tmp_path):
    load_nn = _predictor_loader()
    surrogate = SURROGATES[1]
    assert "softjoint-" in _refused(lambda p: load_nn(p, False), surrogate)
    _refused(load_surrogate, ROOT / "results/predictor/gravity_nn.pt")
    _refused(lambda p: load_nn(p, True), ROOT / "results/predictor/gravity_nn.pt")
    _refused(lambda p: load_nn(p, False), ROOT / "results/predictor/contact_nn.pt")
    foreign = tmp_path / "hostname.pt"
    foreign.write_bytes(b"not a checkpoint\n")
    _refused(load_surrogate, foreign)


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout")
def test_fresh_clone_takes_the_committed_artefacts_as_up_to_date(tmp_path):
    """A clone of HEAD: ``make -n`` of bench-predictor, gestures and train lists no
    surrogate.train and no predictor.cli.nn training (git writes the files in path order, so
    without the Makefile's one time per clone results/ would be older than the code);
    after predictor/cli/nn.py is edited it lists the three NN trainings. ``make help`` alone
    changes no file time (the stamping is a prerequisite of the artefacts, not parse-time)."""
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    before = (clone / "Makefile").stat().st_mtime_ns
    subprocess.run(["make", "help"], cwd=clone, check=True, capture_output=True)
    assert (clone / "Makefile").stat().st_mtime_ns == before

    def planned() -> str:
        return subprocess.run(["make", "-n", "bench-predictor", "gestures", "train"], cwd=clone, check=True,
                              capture_output=True, text=True).stdout

    first = planned()
    assert "surrogate.train" not in first and "predictor.cli.nn" not in first, first
    assert "predictor.cli.nn" not in planned()
    (clone / "predictor/cli/nn.py").write_text((clone / "predictor/cli/nn.py").read_text() + "\n")
    assert planned().count("-m predictor.cli.nn --variant") == 3
