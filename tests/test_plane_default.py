"""One problem, said (issue 56 §1): the FEM and the predictor default to the same problem.

- fem.cli.finger, fem.studies.finger_cases and fem.studies.finger_grid default to the gripper (the mirror
  finger's contact at X = 0): ``args.plane`` True, ``--no-plane`` False, ``--plane`` (the
  old flag) still True; predictor.cli.gesture defaults to it too and its JSON says which
  (``"plane": true``; ``--no-plane`` false, and at (0.13, -0.07) MPa with gravity the
  finger alone crosses X = 0 by 10 mm where the gripper's stays on its side, pushing on
  the plane); the Python API (load_gripper(plane=...)) likewise.
- The committed lone-finger records stand for the Makefile's commands that resume them
  (``make finger-fem``, ``make calibration-fem``: ``--no-plane``), so those targets solve
  nothing; without ``--no-plane`` the same command would solve all 18 anew.
- A comparison refuses two problems in one line: predictor.solvers.problem.same_problem, the
  demo's gesture against a committed FEM case, predictor.validation.finger asked for the
  plane on the committed lone-finger cases (exit 2).
"""
from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from predictor.solvers.problem import same_problem

ROOT = Path(__file__).resolve().parents[1]
MAKEFILE = (ROOT / "Makefile").read_text()


def _make_var(name: str) -> str:
    return re.search(rf"^{name}\s*:=\s*(.+?)\s*$", MAKEFILE, re.M)[1]


def test_fem_parsers_default_to_the_plane():
    pytest.importorskip("dolfinx")
    from fem.cli.finger import build_parser
    from fem.studies.finger_grid import build_parser as grid_parser

    ap = build_parser()
    assert ap.parse_args([]).plane is True
    assert ap.parse_args(["--no-plane"]).plane is False
    assert ap.parse_args(["--plane"]).plane is True          # the old flag, a no-op now
    grid = grid_parser()
    assert grid.parse_args([]).plane is True and grid.parse_args(["--no-plane"]).plane is False


def test_gesture_defaults_to_the_plane_and_says_so(capsys):
    """The issue's example: (0.13, -0.07) MPa with gravity on the analytic joint."""
    from predictor.cli.gesture import main

    out = {}
    for flags in ((), ("--no-plane",)):
        assert main(["--p1", "0.13", "--p2", "-0.07", "--model", "analytic", "--json", *flags]) == 0
        out[flags] = json.loads(capsys.readouterr().out)
    gripper, alone = out[()], out[("--no-plane",)]
    assert gripper["plane"] is True and alone["plane"] is False
    assert gripper["tip"][0] > 0.0 and gripper["plane_force_N"] > 0.01      # held on its side of X = 0
    assert alone["tip"][0] < -5.0 and alone["plane_force_N"] == 0.0        # crosses the mirror finger


def test_api_defaults_to_the_plane():
    from predictor.api import load_gripper, solve_gesture
    from predictor.model.statics import meets

    g, lone = load_gripper("analytic"), load_gripper("analytic", plane=False)
    assert meets(g.problem) and not meets(lone.problem)
    assert solve_gesture(g, 0.0, 0.0).summary()["plane"] is True
    assert solve_gesture(lone, 0.0, 0.0).summary()["plane"] is False
    with pytest.raises(ValueError, match="plane: 'no' is not True or False"):
        load_gripper("analytic", plane="no")


def _resume(monkeypatch, capsys, argv: list[str]) -> tuple[list, str]:
    """fem.studies.finger_cases.main(argv) with its solve replaced: (the cases it would solve, stdout)."""
    pytest.importorskip("dolfinx")
    import fem.studies.finger_cases as fc

    todo = []
    monkeypatch.setattr(fc, "solve_cases", lambda cases, *a, **k: todo.extend(cases))
    assert fc.main(argv) == 0
    return todo, capsys.readouterr().out


def test_committed_lone_finger_cases_stand_for_the_makefile(monkeypatch, capsys):
    """make finger-fem and make calibration-fem pass --no-plane, and their committed records
    (settings without ``plane``) stand: the targets solve nothing."""
    finger_cases = shlex.split(_make_var("FINGER_CASES").replace("$(PAPER_MESH)", _make_var("PAPER_MESH")))
    assert finger_cases[:3] == ["$(PY)", "-m", "fem.studies.finger_cases"] and "--no-plane" in finger_cases
    args = [a.replace("$(FINGER_FEM)", "results/validation/finger_fem") for a in finger_cases[3:]]
    todo, out = _resume(monkeypatch, capsys, args)
    assert todo == [] and "all 18 cases are up to date" in out
    # without --no-plane the same command is the gripper's: none of the lone cases is its
    todo, _ = _resume(monkeypatch, capsys, [a for a in args if a != "--no-plane"])
    assert len(todo) == 18 and all(str(path).endswith("_plane.json") for *_, path in todo)

    recipe = re.search(r"^calibration-fem:.*\n\t(.+)$", MAKEFILE, re.M)[1]
    assert "--no-plane" in shlex.split(recipe) and "$(CAL_MESH)" in shlex.split(recipe)
    # the truth cases on the production joint mesh (CAL_MESH's default, PROD_MESH)
    todo, out = _resume(monkeypatch, capsys, ["--finger", "results/calibration/truth/finger.toml", "--pressures",
                                              _make_var("CAL_PRESSURES"), "--no-plane",
                                              *shlex.split(_make_var("PROD_MESH")), "--out",
                                              "results/calibration/fem"])
    assert todo == [] and "all 8 cases are up to date" in out


def test_same_problem_refuses_two_problems_in_one_line():
    same_problem(True, True)
    same_problem(False, False)
    with pytest.raises(ValueError) as exc:
        same_problem(False, True, "a.json")
    assert str(exc.value) == ("a.json: the FEM solved one finger alone (--no-plane), the predictor the gripper "
                              "(the plane X = 0): different problems, not compared")


def test_demo_rows_each_solve_one_problem():
    """The demo's rows against an FEM compare like with like: the committed lone-finger cases
    through predictor.validation.finger (each case against the predictor of its own problem),
    and its live finger FEM is a lone finger as its row says; its gesture rows are the
    gripper's (the default), with no FEM beside them."""
    from apps import demo

    steps = {s.key: s.args for s in demo.build_steps("out", 4.0)}
    assert "--no-plane" in steps["finger_fem"] and steps["validate_gravity"][0] == "--fem"
    gestures = [k for k in steps if k.startswith("gesture_")]
    assert gestures and all("--no-plane" not in steps[k] for k in gestures)


def test_validate_finger_refuses_the_plane_on_lone_cases(tmp_path, capsys):
    """The committed cases are one finger alone: --no-plane is their problem, --plane is
    refused (one line, exit 2) before any solve, and nothing is written."""
    from predictor.validation.cases import one_problem
    from predictor.validation.finger import main

    with pytest.raises(SystemExit) as exc:
        main(["--plane", "--model", "analytic", "--out", str(tmp_path / "f.json"), "--figures", str(tmp_path)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert ("were all solved for one finger alone (--no-plane), the predictor was asked for the gripper "
            "(the plane X = 0): different problems, not compared") in err
    assert not (tmp_path / "f.json").exists()
    lone, plane = {"settings": {}}, {"settings": {"plane": True}}
    assert one_problem([lone, plane], None, "x") == ([lone, plane], None)
    assert one_problem([lone, plane], True, "x") == ([plane], True)
    assert one_problem([lone], None, "x") == ([lone], False)
    # each problem is judged on its own issue's targets: the gripper's on issue 56's (1 mm, 0.5 deg and
    # the finger FEM's own refinement), one finger alone's on issue 14's (2 mm, 1 deg)
    from predictor.validation.finger import targets_for
    assert (targets_for(True)["tip_error_mm"], targets_for(True)["refinement_tip_change_mm"]) == (1.0, 0.5)
    assert targets_for(False) == targets_for(None) and targets_for(False)["tip_error_mm"] == 2.0
    assert "refinement_tip_change_mm" not in targets_for(False)


def test_validate_grasps_refuses_a_lone_finger_on_the_grippers_records(tmp_path, capsys):
    from predictor.validation.grasps import main

    with pytest.raises(SystemExit) as exc:
        main(["--fem", "tests/data/grasps", "--mesh", "4", "--formulation", "mixed", "--no-plane",
              "--out", str(tmp_path / "g.json"), "--figures", str(tmp_path)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert ("were all solved for the gripper (the plane X = 0), the predictor was asked for one finger alone "
            "(--no-plane): different problems, not compared") in err
    assert not (tmp_path / "g.json").exists()
