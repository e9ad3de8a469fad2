"""make demo (apps.demo): the pure part that turns the steps' JSON into table rows.

Hand-made step JSONs with known answers (anchors offset by a 3-4-5 vector, fingertips
offset by 6-8-10, ...); no FEM, no model. A step's file is read through its artefact's
format (one ``python -m json.tool`` subprocess stands in for the tool).
"""
from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from apps import demo

ANCHORS = [[4.5 * i, -0.5 * i] for i in range(1, 11)]


def joint_fem():
    return {"load": {"P": 0.2, "F1": 1.0, "F2": -1.0, "M": 20.0}, "converged": True,
            "anchors_mm": ANCHORS, "phi_end_deg": -23.0, "cap_rotation_deg": -25.0,
            "wall_time_s": 120.0, "geometry": {"mesh_size": 1.8}}


def surrogate(offset=(3.0, 4.0), last_offset=None):
    anchors = [[x + offset[0], y + offset[1]] for x, y in ANCHORS]
    if last_offset:
        anchors[-1] = [ANCHORS[-1][0] + last_offset[0], ANCHORS[-1][1] + last_offset[1]]
    return {"anchors_mm": anchors, "phi_end_deg": -22.5, "cap_rotation_deg": -25.25}


def gesture(p1, p2, tip, angle, obj=None, normal=0.0, use=None, state="no_contact"):
    return {"pressures_MPa": [p1, p2], "converged": True, "tip": tip, "tip_angle_deg": angle,
            "time_ms": 40.0, "kinematics": "cap", "joint_weight": "split", "object": obj,
            "contact_force_N": normal, "friction_use": use, "slip": None if use is None else state == "slips",
            "state": state}


def finger_case(name, tip, angle, h, fem_s):
    p1, p2 = (float(v) for v in name.split("_")[1:])
    return {"case": name, "pressures_MPa": [p1, p2], "gravity": True, "converged": True, "tip": tip,
            "tip_angle_deg": angle, "fem_s": fem_s, "mesh": {"mesh_size": h}}


def validation(*cases):
    """A predictor.validation.finger JSON: (case, tip, angle) per case, the judged variant's."""
    entries = []
    for case, tip, angle in cases:
        entry = {"case": case, "variant": "predictor_cap_split", "tip_mm": tip, "tip_angle_deg": angle,
                 "predictor_s": 0.02, "kinematics": "cap", "joint_weight": "split"}
        other = {**entry, "variant": "predictor_tangent_lumped", "tip_mm": [0.0, 0.0],
                 "kinematics": "tangent", "joint_weight": "lumped"}
        entries += [other, entry]
    return {"judged_variant": "predictor_cap_split", "cases": entries,
            "targets": {"tip_error_mm": 2.0, "tip_angle_error_deg": 1.0, "speedup": 1000.0, "fem_s": 600.0}}


def data():
    committed = finger_case("gravity_0.1_-0.1", [7.0, -214.0], -88.0, 1.8, 490.0)
    coarse = finger_case("gravity_0.1_-0.1", [7.0 + 6.0, -214.0 - 8.0], -87.5, 4.0, 150.0)
    return {
        "joint": {"fem": joint_fem(), "surrogate": surrogate(), "surrogate_wall_s": 3.0},
        "gravity": [
            {"fem": finger_case("gravity_-0.1_0.1", [40.0, -210.0], -92.0, 1.8, 500.0), "fem_file": "a.json"},
            {"fem": committed, "fem_file": "b.json"},
        ],
        # the lone finger's predictor: 0.5 mm and 1 deg off, then 2 mm and -0.25 deg
        "gravity_validation": validation(("gravity_-0.1_0.1", [40.0 + 0.3, -210.0 - 0.4], -91.0),
                                         ("gravity_0.1_-0.1", [7.0, -214.0 + 2.0], -88.25)),
        "gripper": [gesture(-0.1, 0.1, [40.3, -210.4], -91.0),
                    {**gesture(0.1, -0.1, [3.5, -213.0], -80.0), "plane_force_N": 0.05}],
        "grasp": gesture(0.1, 0.2, [27.0, -214.5], -99.9, obj="circle", normal=0.227, use=0.9, state="holds"),
        "finger": {"fem": coarse, "validation": validation(("gravity_0.1_-0.1", [13.0 - 0.6, -222.0 + 0.8], -87.0)),
                   "committed": committed, "committed_file": "b.json"},
    }


def test_rows_errors_and_times():
    rows = demo.table_rows(data())
    assert [r["case"] for r in rows] == [
        "joint P=0.2 F1=1 F2=-1 M=20", "gravity (-0.1, 0.1) MPa", "gravity (0.1, -0.1) MPa",
        "gripper gravity (-0.1, 0.1) MPa", "gripper gravity (0.1, -0.1) MPa",
        "grasp circle (0.1, 0.2) MPa", "finger gravity (0.1, -0.1) MPa", "finger FEM 4 vs 1.8 mm mesh"]
    joint, g1, g2, r1, r2, grasp, finger, mesh = rows
    # every anchor offset by (3, 4): exactly 5 mm, max and mean
    assert joint["errors"]["anchor_max_mm"] == pytest.approx(5.0, abs=1e-12)
    assert joint["errors"]["anchor_mean_mm"] == pytest.approx(5.0, abs=1e-12)
    assert joint["errors"]["phi_end_deg"] == pytest.approx(0.5)
    assert joint["errors"]["cap_rotation_deg"] == pytest.approx(-0.25)
    assert (joint["fem_s"], joint["model_s"]) == (120.0, 3.0)
    assert "process wall" in joint["model"]
    assert joint["fem"] == "joint FEM, 1.8 mm tetrahedra, displacement (now)"
    assert g1["errors"]["tip_mm"] == pytest.approx(0.5) and g1["errors"]["tip_angle_deg"] == pytest.approx(1.0)
    assert g2["errors"]["tip_mm"] == pytest.approx(2.0) and g2["errors"]["tip_angle_deg"] == pytest.approx(-0.25)
    # the committed finger FEM is one finger alone, its mesh named exactly; so is the predictor of these rows
    assert g1["fem"] == g2["fem"] == "finger FEM, 1.8 mm tetrahedra, displacement (committed)"
    assert g1["problem"] == g2["problem"] == finger["problem"] == mesh["problem"] == demo.LONE_FINGER
    assert (g1["fem_s"], g1["model_s"]) == (500.0, 0.02)
    # the gripper's gestures (the fingers meet at X = 0) have no FEM: never compared with the lone finger's
    assert r1["problem"] == r2["problem"] == demo.GRIPPER
    assert r1["errors"] is None and r1["fem_s"] is None and r1["within_tolerance"] is None
    assert "fingers apart" in r1["error"] and "fingers meet with 0.050 N" in r2["error"]
    assert grasp["fem"] == "n/a" and grasp["errors"] is None and grasp["fem_s"] is None
    assert grasp["grasp"] == {"normal_force_N": 0.227, "friction_use": 0.9, "state": "holds"}
    # the judged variant, not the first entry of the case
    assert finger["errors"]["tip_mm"] == pytest.approx(1.0) and finger["errors"]["tip_angle_deg"] == pytest.approx(0.5)
    assert finger["fem"] == "finger FEM, 4 mm tetrahedra, displacement (now)"
    assert finger["model"] == "predictor (cap/split)"
    assert (finger["fem_s"], finger["model_s"]) == (150.0, 0.02)
    # the coarse mesh against the committed mesh: a 6-8-10 offset, no tolerance (it measures the mesh)
    assert mesh["errors"]["tip_mm"] == pytest.approx(10.0) and mesh["errors"]["tip_angle_deg"] == pytest.approx(0.5)
    assert (mesh["fem_s"], mesh["model_s"]) == (490.0, 150.0)
    assert mesh["within_tolerance"] is None


def test_rows_beyond_their_tolerance_are_flagged():
    rows = demo.table_rows(data())
    # tolerance from the validation JSON's targets: 2 mm, 1 deg; the bounds themselves pass
    assert [r["within_tolerance"] for r in rows] == [None, True, True, None, None, None, True, None]
    assert demo.beyond_tolerance(rows) == []
    assert "Every row with a tolerance is within it." in demo.markdown(rows, [], 1.0)
    d = data()
    d["gravity_validation"]["cases"][-1]["tip_mm"] = [7.0, -214.0 + 7.2]   # a lone finger 7.2 mm off
    rows = demo.table_rows(d)
    assert rows[2]["within_tolerance"] is False and rows[2]["tolerance"] == {"tip_mm": 2.0, "tip_angle_deg": 1.0}
    assert demo.beyond_tolerance(rows) == ["gravity (0.1, -0.1) MPa"]
    assert "NO: beyond 2 mm, 1 deg" in demo.text_table(rows)
    assert "**Beyond tolerance: gravity (0.1, -0.1) MPa.**" in demo.markdown(rows, [], 1.0)


def test_gripper_rows_against_the_gripper_fem_where_it_is_committed():
    """A gripper gesture whose FEM of the gripper (production mesh, the plane) is committed is
    compared with it, same problem, within the production validation's tolerance; the other
    keeps its figures, with no FEM."""
    d = data()
    fem = {**finger_case("gravity_-0.1_0.1", [40.3 - 0.3, -210.4 - 0.4], -91.25, None, 3600.0),
           "mesh": {"mesh": "hex2:3", "nodes": 132765}, "formulation": "mixed", "settings": {"plane": True}}
    d["gripper_fem"] = {"-0.1_0.1": (fem, "c.json")}
    d["gripper_tolerance"] = {"tip_mm": 1.0, "tip_angle_deg": 0.5}
    r1, r2 = demo.table_rows(d)[3:5]
    # a 3-4-5 triangle scaled by 0.1: 0.5 mm; +0.25 deg
    assert r1["errors"]["tip_mm"] == pytest.approx(0.5) and r1["errors"]["tip_angle_deg"] == pytest.approx(0.25)
    assert r1["within_tolerance"] is True and r1["problem"] == demo.GRIPPER and r1["fem_s"] == 3600.0
    assert r1["fem"] == "finger FEM, hex2:3, mixed, the plane (committed)" and "fingers apart" in r1["error"]
    assert r2["errors"] is None and r2["within_tolerance"] is None
    d["gripper_tolerance"] = {"tip_mm": 0.4, "tip_angle_deg": 0.5}
    assert demo.beyond_tolerance(demo.table_rows(d)) == ["gripper gravity (-0.1, 0.1) MPa"]


def test_max_and_mean_differ():
    d = data()
    d["joint"]["surrogate"] = surrogate(offset=(0.0, 0.0), last_offset=(6.0, 8.0))
    joint = demo.table_rows(d)[0]
    assert joint["errors"]["anchor_max_mm"] == pytest.approx(10.0)
    assert joint["errors"]["anchor_mean_mm"] == pytest.approx(1.0)


def test_missing_judged_entry_is_refused():
    d = data()
    d["finger"]["validation"]["cases"] = d["finger"]["validation"]["cases"][:1]
    with pytest.raises(ValueError, match="predictor_cap_split"):
        demo.table_rows(d)


def test_tables_show_every_row_and_figure():
    rows = demo.table_rows(data())
    text = demo.text_table(rows)
    assert len(text.splitlines()) == 2 + len(rows)
    assert "n/a" in text and "5.000 mm" in text
    md = demo.markdown(rows, [{"title": "t", "command": "python -m x", "wall_s": 1.0}], 60.0)
    table = [ln for ln in md.split("## Steps")[0].splitlines() if ln.startswith("| ")]
    assert len(table) == 1 + len(rows)              # the header and one line per row
    for r, line in zip(rows, table[1:]):            # each row links its own figures, in order
        assert line.startswith(f"| {r['case']} | ")
        assert line.endswith(" | " + (", ".join(f"[{Path(p).name}]({p})" for p in r["figures"]) or "-") + " |")
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md.split("## Figures")[1])
    assert pictures == [p for r in rows for p in r["figures"]]
    assert "| t | `python -m x` | 1.0 |" in md


def test_demo_runs_the_packages_command_lines_without_importing_them():
    """The demo runs the packages' command lines, one subprocess each, so importing it
    loads neither torch nor dolfinx, and of surrogate and predictor only the predictor's
    artefact formats (a fresh interpreter, since other test files import those packages)."""
    code = ("import sys, apps.demo; print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('surrogate', 'predictor', 'torch', 'dolfinx')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "['predictor', 'predictor.artefacts']", out.stderr


def test_a_step_file_is_read_through_its_format(tmp_path):
    """A step whose tool writes a finger FEM case (here ``python -m json.tool`` copying the
    committed one) is loaded through fem.artefacts.FINGER_CASE: the case as committed is
    read; with ``tip_angle_deg`` renamed the step fails in one line naming the file and key."""
    from fem.artefacts import FINGER_CASE

    committed = Path(demo.ROOT, demo.COMMITTED_FINGER_FEM, f"{demo.FINGER_CASE}.json")
    case = json.loads(committed.read_text())
    src, out = tmp_path / "src.json", tmp_path / "out.json"

    def step():
        return demo.Step("finger_fem", "copy", "json.tool", [str(src), str(out)], reads=str(out),
                         format=FINGER_CASE)

    src.write_text(json.dumps(case))
    good = step()
    demo.run_step(good, 1, 1, 0.0, dict(os.environ), log=io.StringIO())
    assert good.data == case
    case["tip_angle"] = case.pop("tip_angle_deg")
    src.write_text(json.dumps(case))
    with pytest.raises(demo.StepFailed) as err:
        demo.run_step(step(), 1, 1, 0.0, dict(os.environ), log=io.StringIO())
    assert "\n" not in str(err.value)
    assert f"{out}: tip_angle_deg: missing (format fem-finger-case/1, fem.studies.finger_cases)" in str(err.value)


def test_demo_fem_runs_on_the_committed_discretisation_not_the_production_one():
    """The committed surrogate and finger cases are on fem.mesh.discretisation.PAPER (1.8 mm P2
    displacement): the demo's joint FEM is solved there, its live finger FEM on the coarse
    mesh in the same formulation and validated in it, so no step runs the production
    hexahedra (the tools' default); each committed case the demo compares with is on PAPER,
    and a case on another discretisation is refused in one line."""
    pytest.importorskip("dolfinx")
    from fem.mesh.discretisation import PAPER

    assert (demo.COMMITTED_MESH_SIZE, demo.COMMITTED_FORMULATION) == (PAPER.H, PAPER.formulation)
    assert (PAPER.W, PAPER.divisions) == (None, 0)
    steps = {s.key: s.args for s in demo.build_steps("out", 4.0)}
    paper = ["--mesh-size", "1.8", "--formulation", "displacement"]
    assert any(steps["joint_fem"][i:i + 4] == paper for i in range(len(steps["joint_fem"])))
    for key in ("finger_fem", "validate"):
        args = steps[key]
        assert args[args.index("--mesh-size") + 1] == "4" and args[args.index("--formulation") + 1] == "displacement"
    # the committed cases are validated on their own mesh, one finger alone, those two cases only
    args = steps["validate_gravity"]
    assert any(args[i:i + 4] == paper for i in range(len(args)))
    assert args[args.index("--cases") + 1] == "gravity_-0.1_0.1,gravity_0.1_-0.1"
    for name in ("gravity_-0.1_0.1", "gravity_0.1_-0.1"):
        case, _ = demo.load_committed(name)
        assert case["mesh"]["mesh_size"] == 1.8 and case.get("formulation", "displacement") == "displacement"


def test_a_committed_case_on_another_discretisation_is_refused(monkeypatch, tmp_path):
    """load_committed reads the case's own mesh and formulation: a mixed case at 1.8 mm, or
    a hexahedral one, is not the committed data's discretisation (one line, make finger-fem)."""
    committed = json.loads(Path(demo.ROOT, demo.COMMITTED_FINGER_FEM, f"{demo.FINGER_CASE}.json").read_text())
    folder = tmp_path / "finger_fem"
    folder.mkdir()
    monkeypatch.setattr(demo, "ROOT", tmp_path)
    monkeypatch.setattr(demo, "COMMITTED_FINGER_FEM", "finger_fem")
    for change, found in (({"formulation": "mixed"}, "1.8, mixed"),
                          ({"mesh": {**committed["mesh"], "mesh": "hex2:3", "divisions": 2}}, "hex2:3, displacement")):
        (folder / "x.json").write_text(json.dumps({**committed, **change}))
        with pytest.raises(demo.StepFailed) as err:
            demo.load_committed("x")
        assert "\n" not in str(err.value) and f"(it is on {found})" in str(err.value)
        assert "make finger-fem" in str(err.value)
    (folder / "x.json").write_text(json.dumps(committed))
    assert demo.load_committed("x")[0] == committed


def test_the_demo_takes_a_finger_file():
    """--finger FILE goes to every gesture and finger FEM step; the committed finger FEM is
    the paper's finger, so for another finger the step and rows against it are left out
    (committed_finger), and a finger of three joints is refused in one line, exit 2."""
    from contract.finger import load_finger

    fingers = Path(demo.ROOT, "tests", "data", "fingers")
    assert demo.committed_finger(load_finger(None))
    assert not demo.committed_finger(load_finger(fingers / "long_tip.toml"))
    steps = {s.key: s.args for s in demo.build_steps("out", 4.0, "tests/data/fingers/long_tip.toml", False)}
    assert "validate_gravity" not in steps
    for key in ("gesture_-0.1_0.1", "gesture_0.1_-0.1", "grasp", "finger_fem", "validate"):
        assert steps[key][steps[key].index("--finger") + 1] == "tests/data/fingers/long_tip.toml", key
    assert all("--finger" not in args for args in
               (s.args for s in demo.build_steps("out", 4.0)))    # the paper's: the tools' default
    d = data()
    d["gravity"], d["gravity_validation"], d["finger"]["committed"] = [], None, None
    assert [r["case"] for r in demo.table_rows(d)] == [
        "joint P=0.2 F1=1 F2=-1 M=20", "gripper gravity (-0.1, 0.1) MPa", "gripper gravity (0.1, -0.1) MPa",
        "grasp circle (0.1, 0.2) MPa", "finger gravity (0.1, -0.1) MPa"]
    r = subprocess.run([sys.executable, "-m", "apps.demo", "--finger", "tests/data/fingers/three.toml",
                        "--out", "build/never"], cwd=demo.ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == ("python -m apps.demo: error: argument --finger: finger 'three' has 3 joints: the demo's "
                        "gestures are pressure pairs, for a finger of two joints\n")
    assert not Path(demo.ROOT, "build", "never").exists()
