"""Issue 33, FEM / workflow / surrogate side: the Python-API half of the bad-input rows
(tests/test_bad_input.py runs the command lines) and the cases whose right answer is not
an error.

- the shared ``contract.cli.Parser`` takes negative values in comma lists, and still refuses
  an option where a value belongs;
- ``cli.check_output`` probes for real and creates no folder above the one named;
- the finger-file bounds refuse through ``load_finger`` with the CLI's very line;
- a non-converged finger solve reports no figures;
- a campaign refusal names the option and both values, and a campaign never shrinks;
- a shard that cannot be written (a folder in its place) gives one line and keeps it;
- a sweep rerun keeps every variant's row and every committed result;
- progress lines: the heartbeat, and other libraries' INFO chatter filtered out.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import logging
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from contract import cli
from contract.finger import FingerFileError, load_finger

ROOT = Path(__file__).resolve().parents[1]
FINGERS = ROOT / "tests" / "data" / "fingers"


def _parser() -> cli.Parser:
    ap = cli.Parser(prog="t")
    ap.add_argument("--loads", type=cli.numbers(4, -100, 100))
    ap.add_argument("--pressures", type=cli.number_list(-0.3, 0.3, "MPa"))
    ap.add_argument("--x", type=cli.number())
    return ap


def _error(ap: cli.Parser, argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        ap.parse_args(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1
    return lines[0]


def test_negative_values_in_comma_lists(capsys):
    args = _parser().parse_args(["--loads", "-0.1,0,0,-20", "--pressures", "-0.15,0", "--x", "-1e-3"])
    assert args.loads == (-0.1, 0.0, 0.0, -20.0)
    assert args.pressures == (-0.15, 0.0)
    assert args.x == -0.001
    # a negative value is checked like any other, with the usual message
    assert "--pressures: -0.5 is outside [-0.3, 0.3] MPa" in _error(_parser(), ["--pressures", "-0.5,0"], capsys)
    assert "--x: '-inf' is not a finite number" in _error(_parser(), ["--x", "-inf"], capsys)
    # an option where a value belongs is still an option
    assert "expected one argument" in _error(_parser(), ["--x", "--loads", "0,0,0,0"], capsys)


def test_check_output_creates_nothing_above_the_named_folder(tmp_path):
    assert cli.check_output(tmp_path / "x.png") is None
    assert cli.check_output(tmp_path / "new", folder=True) is None   # its parent exists
    why = cli.check_output(tmp_path / "a" / "b" / "x.png")
    assert why == f"cannot create {tmp_path}/a/b/x.png: folder {tmp_path}/a/b does not exist"
    why = cli.check_output(tmp_path / "a" / "b", folder=True)
    assert why == f"cannot create {tmp_path}/a/b: folder {tmp_path}/a does not exist"
    (tmp_path / "file").write_text("")
    assert cli.check_output(tmp_path / "file" / "x.png").endswith(f"{tmp_path}/file is not a folder")
    assert cli.check_output(tmp_path / "file", folder=True) == f"{tmp_path}/file is a file, not a folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]        # probes removed


def test_check_output_probes_for_real():
    """/proc passes os.access for root but takes no file: the probe says so."""
    assert cli.check_output("/proc/x.png").startswith("cannot write /proc/x.png: /proc:")
    assert cli.check_output("/proc/x", folder=True).startswith("cannot write /proc/x: /proc:")


@pytest.mark.parametrize("name, needle", [
    ("huge_length", "part 2 (rigid): length = 1000000000.0 is outside [1, 500] mm"),
    ("tiny_length", "part 2 (rigid): length = 1e-09 is outside [1, 500] mm"),
    ("flat", "part 2 (rigid): height = 1e-09 is outside [1, 100] mm"),
    ("many_contact_points", "part 2 (rigid): contact_points = 100000000 is outside [0, 1000]"),
    ("heavy", "part 2 (rigid): weight = 1000000000.0 is outside [0, 2] N"),
    ("negative_length", "part 2 (rigid): length = -60.0 must be > 0.0"),
    ("too_long", "the parts add up to 1245.45 mm, at most 1000 mm"),
])
def test_finger_bounds_through_the_api(name, needle):
    """load_finger (the API every tool parses with) refuses with the CLI's line."""
    with pytest.raises(FingerFileError) as exc:
        load_finger(FINGERS / f"{name}.toml")
    assert str(exc.value) == f"{FINGERS / name}.toml: {needle}"


def test_fingers_of_other_joint_counts_load():
    for name, n in (("three", 3), ("five_joints", 5)):
        finger = load_finger(FINGERS / f"{name}.toml")
        assert finger.n_joints == n
        assert finger.length == pytest.approx(n * (45.45 + 30.0))


def _finger_result(converged: bool):
    from fem.solvers.finger import FingerLoad, FingerResult

    anchors = np.arange(40.0).reshape(2, 10, 2)
    return FingerResult(load=FingerLoad((0.1, -0.1)), converged=converged, tip=np.array([3.0, -200.0]),
                        tip_angle=-0.5 * math.pi, anchors=anchors, proximal=np.zeros((2, 2)),
                        theta=np.array([-0.5 * math.pi, -0.25 * math.pi]),
                        end_angle=np.array([-0.25 * math.pi, 0.0]), chord_angle=np.zeros(2),
                        local_anchors=anchors, newton_iterations=[12, 25], load_steps=2,
                        reason="" if converged else "no convergence after 10 cut-backs at path 0.4000")


def test_non_converged_finger_reports_no_figures():
    bad = _finger_result(False).summary()
    assert bad["converged"] is False
    assert [bad[k] for k in ("tip", "tip_angle_deg", "joint_end_angle_deg", "joints")] == [None] * 4
    assert bad["reason"].startswith("no convergence") and bad["iterations"] == 37
    assert "NaN" not in cli.dumps(bad)
    good = _finger_result(True).summary()
    assert good["tip"] == [3.0, -200.0] and good["tip_angle_deg"] == pytest.approx(-90.0)
    assert good["joint_end_angle_deg"] == pytest.approx([-45.0, 0.0])
    assert good["joints"][0]["cap_rotation_deg"] == pytest.approx(45.0)   # end - theta


def test_campaign_refusals_name_the_option_and_both_values():
    from workflow.campaign import check_compatible
    from workflow.shards import Manifest, ShardError

    out = ROOT / "results" / "data" / "heldout"
    config = Manifest.load(out).config
    assert Manifest.load(out).samples_requested == 256
    assert check_compatible(out, config, 2, 256).samples_requested == 256
    assert check_compatible(out, config, 2, 512) is not None            # growing is resuming
    cases = [({"geometry": {"mesh_size": 3.0}}, "made with --mesh-size 1.8 mm (this run: 3 mm)"),
             ({"geometry": {"wall_mesh_size": 0.9}}, "made with --wall-mesh-size unset (this run: 0.9 mm)"),
             ({"walk_step": 0.2}, f"made with --step {config['walk_step']:g} (this run: 0.2)"),
             ({"solver": {"max_it": 99}},
              f"made with solver.max_it = {config['solver']['max_it']!r} (this run, from the code: 99)")]
    for change, needle in cases:
        other = copy.deepcopy(config)
        for key, value in change.items():
            other[key] = {**other[key], **value} if isinstance(value, dict) else value
        with pytest.raises(ShardError) as exc:
            check_compatible(out, other, 2, 256)
        assert needle in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ShardError, match="holds a campaign of --samples 256; --samples 255 would drop"):
        check_compatible(out, config, 2, 255)


def test_shard_blocked_by_a_folder_keeps_it(tmp_path):
    from workflow.campaign import save_shard
    from workflow.shards import empty_arrays

    blocked = tmp_path / "unit-00000.npz"
    (blocked / "inside").mkdir(parents=True)
    why = save_shard(blocked, empty_arrays(), {"unit": 0})
    assert why.startswith(f"cannot write {blocked}: Is a directory") and "\n" not in why
    assert [p.name for p in tmp_path.iterdir()] == ["unit-00000.npz"]   # no temp file left
    assert (blocked / "inside").is_dir()


def test_sweep_rerun_keeps_committed_results(tmp_path, capsys):
    """The README's rerun of three variants whose committed results predate the cap head
    (the 1.8 mm reference sweep, on its own data): nothing is retrained or replaced, the
    table keeps all its rows, each stale one says so."""
    from surrogate import sweep

    committed = ROOT / "results" / "surrogate" / "h1.8" / "sweep"
    work = tmp_path / "sweep"
    shutil.copytree(committed, work)
    before = {p.name: p.read_bytes() for p in work.glob("*.json")}
    data = [str(ROOT / "results" / "data" / f"{name}_h1.8") for name in ("train", "heldout")]
    assert sweep.main(["--only", "improved", "nojac", "symmetric-w64x4", "--dir", str(work),
                       "--data", data[0], "--heldout", data[1]]) == 0
    said = capsys.readouterr().out
    assert "0 of 3 variants current, 0 to train" in said and "3 stale result(s) kept" in said
    assert {p.name: p.read_bytes() for p in work.glob("*.json")} == before
    rows = [ln for ln in (work / "README.md").read_text().splitlines() if ln.startswith("| ")][1:]
    assert len(rows) == len(before) == 16
    stale = [r.split(" | ")[0].strip("| ") for r in rows if "stale: made with other" in r]
    assert {"improved", "nojac", "symmetric-w64x4"} <= set(stale)


def test_heartbeat_and_filtered_progress(capsys):
    cli.setup_logging()
    with cli.heartbeat("work", every=0.05):
        time.sleep(0.18)
    logging.getLogger("setuptools").info("running build_ext")        # the form compiler's chatter
    logging.getLogger("softjoint.fem").info("load step 1")
    logging.getLogger("dolfinx").warning("a warning still shows")
    err = capsys.readouterr().err.splitlines()
    beats = [ln for ln in err if ln.startswith("work: still working")]
    assert 2 <= len(beats) <= 4
    assert "running build_ext" not in err and "load step 1" in err and "a warning still shows" in err
    cli.setup_logging(quiet=True)
    logging.getLogger("softjoint.fem").info("load step 2")
    assert capsys.readouterr().err == ""
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, force=True)


@pytest.mark.fem
def test_fem_solve_progress_on_stderr_json_alone_on_stdout():
    """fem.cli.solve --json (coarse mesh): stdout is the result alone (strict JSON), stderr the
    progress (mesh, every load step); --quiet silences the progress, not the result."""
    import os
    import subprocess

    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    base = [sys.executable, "-m", "fem.cli.solve", "--p", "0.1", "--m", "50", "--mesh-size", "4", "--formulation",
            "displacement", "--json"]
    loud, quiet = (subprocess.run(base + extra, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
                   for extra in ([], ["--quiet"]))
    for r in (loud, quiet):
        assert r.returncode == 0, r.stderr[-2000:]
        out = json.loads(r.stdout)
        assert out["converged"] and out["phi_end_deg"] > 0        # P and M both bend it the + way
    lines = loud.stderr.splitlines()
    assert lines[0].startswith("joint 'paper': meshing") and any(ln.startswith("mesh ready") for ln in lines)
    steps = [ln for ln in lines if ln.startswith("load step")]
    assert len(steps) == json.loads(loud.stdout)["load_steps"]
    assert quiet.stderr == ""
    assert json.loads(quiet.stdout)["phi_end_deg"] == json.loads(loud.stdout)["phi_end_deg"]


def test_fem_finger_cli_prints_no_figures_when_not_converged(monkeypatch, capsys):
    """fem.cli.finger's command line around a solve that does not converge (a stand-in solver
    returns it, so no FEM runs): JSON with null figures on stdout, the same in the text
    output, exit 1 and one reason line on stderr (with --quiet, the only line)."""
    import fem.cli.finger as finger_cli

    class Unconverged:
        def __init__(self, geometry, comm, **settings):
            pass

        def solve(self, load):
            assert load.pressures == (-0.1, 0.1) and load.gravity
            return _finger_result(False)

        def mesh_info(self):
            return {"nodes": 1, "vertices": 1, "cells": 1, "dofs": 3, "mesh": "1.8"}

    monkeypatch.setattr(finger_cli, "FingerSolver", Unconverged)
    assert finger_cli.main(["--pressures", "-0.1,0.1", "--json", "--quiet"]) == 1
    got = capsys.readouterr()
    out = json.loads(got.out)
    assert out["converged"] is False and out["tip"] is None and out["joints"] is None
    assert got.err.splitlines() == ["python -m fem.cli.finger: did not converge: no convergence after 10 cut-backs "
                                    "at path 0.4000; no figures reported"]
    assert finger_cli.main(["--p1", "-0.1", "--p2", "0.1", "--quiet"]) == 1
    text = capsys.readouterr().out
    assert "tip = none (did not converge)" in text and "end angle" not in text
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, force=True)


def _shard_arrays(n: int) -> dict:
    from workflow.shards import empty_arrays

    arrays = empty_arrays()
    for key, a in list(arrays.items()):
        if not key.startswith("failed_"):
            arrays[key] = np.ones((n, *a.shape[1:]), a.dtype)
    arrays["sample_id"] = np.arange(n)
    return arrays


# np.savez's zip object, cut off by ENOSPC, fails once more when it is collected
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_full_disk_gives_one_line_and_keeps_the_shard(tmp_path):
    """A 64 KiB tmpfs: a 2-sample shard fits, a 300-sample one (~260 KB) does not. The
    failed write is one line naming the shard and ENOSPC, the old shard stays byte for
    byte, and no temp file is left. Needs root's mount (skipped elsewhere)."""
    import subprocess

    from workflow.campaign import save_shard

    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here")
    try:
        shard = disk / "unit-00000.npz"
        assert save_shard(shard, _shard_arrays(2), {"unit": 0}) is None
        before = shard.read_bytes()
        why = save_shard(shard, _shard_arrays(300), {"unit": 0})
        assert why.startswith(f"cannot write {shard}: No space left on device") and "\n" not in why
        assert shard.read_bytes() == before and [p.name for p in disk.iterdir()] == [shard.name]
    finally:
        subprocess.run(["umount", str(disk)], check=True)


# ---------------------------------------------------------------- issue 57: messages that name the cause

def test_a_finger_no_gesture_can_be_solved_for_is_refused_where_the_problem_is_built():
    """load_problem (every tool and the API build their problem with it) refuses the
    finger of 2 N parts, naming the joint and load that leave the joint model's box in the
    hanging pose, and the finger with base_gap 0, naming the overlap and the least gap; the
    heavy finger without gravity, and the paper's finger, load. The hanging loads are the
    distal weights: joint 1 carries half its own 2 N (split weights) and the 6 N beyond it
    along its axis, joint 2 half its own and the 2 N tip."""
    from predictor.api import load_gripper
    from predictor.model.gripper import GripperParams
    from predictor.solvers.problem import hanging_loads, load_problem

    heavy = GripperParams(load_finger(FINGERS / "heavy_parts.toml"))
    with pytest.raises(ValueError) as exc:
        load_problem("analytic", None, params=heavy)
    assert str(exc.value) == ("finger 'heavy_parts' is too heavy for its joints: hanging at zero pressure under the "
                              "parts' weights, joint 1 F1 = 7.00 N, beyond the joint model's box |F1|, |F2| <= 3 N, "
                              "|M| <= 100 N·mm, so no gesture can be solved (lighten the parts, or solve without "
                              "gravity)")
    free = load_problem("analytic", None, gravity=False, params=heavy)   # no weights: nothing to carry
    assert not hanging_loads(free).any()
    np.testing.assert_allclose(hanging_loads(dataclasses.replace(free, gravity=True)).numpy(),
                               [[7.0, 0.0, 0.0], [3.0, 0.0, 0.0]], atol=1e-9)
    with pytest.raises(ValueError, match="finger 'no_gap': base_gap = 0 mm puts the two fingers across each other "
                                         r"\(the right one crosses X = 0 by 10.0 mm"):
        load_gripper(model="analytic", finger=str(FINGERS / "no_gap.toml"))
    assert load_problem("analytic", None).params.finger.name == "paper"


def test_ctrl_c_inside_errors_is_one_line_and_exit_130(capsys):
    """contract.cli.Parser.errors turns KeyboardInterrupt into '<prog>: interrupted
    (Ctrl-C)' and exit 130, like a ValueError into one line and exit 2."""
    ap = cli.Parser(prog="t")
    with pytest.raises(SystemExit) as exc:
        with ap.errors():
            raise KeyboardInterrupt
    assert exc.value.code == 130 == cli.EXIT_INTERRUPTED
    assert capsys.readouterr().err == "t: interrupted (Ctrl-C)\n"
