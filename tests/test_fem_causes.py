"""The mesh-causes study's measures (fem.studies.mesh_causes) on records with known answers (no
solve), and its command line's bad input."""

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("dolfinx")
from fem.studies import joint_cases  # noqa: E402
from fem.studies import mesh_causes as mc  # noqa: E402
from fem.mesh.geometry import JointGeometry, anchor_points  # noqa: E402

X = anchor_points(JointGeometry().length)[:, :2]


def record(disc, load, shift, phi=10.0, cap=12.0, t=10.0):
    """A record whose anchors are the rest anchors bent by a fixed field plus ``shift``
    (mm) at the tip only."""
    bend = np.outer(np.linspace(0.0, 1.0, len(X)), [-2.0, 10.0])   # tip moves by |(-2, 10)|
    anchors = X + bend
    anchors[-1] += shift
    return {"load": load.as_array().tolist(), "discretisation": disc.as_dict(), "anchors": anchors.tolist(),
            "phi_end_deg": phi, "cap_rotation_deg": cap, "wall_time_s": t,
            "contact": {"closed_pairs": 0, "min_gap_mm": 1.0},
            "mesh": {"nodes": 100, "dofs": 300}}


def records(shifts: dict, loads=mc.LOADS[:2]) -> dict:
    out = {}
    for disc in mc.PLAN:
        if disc.key in shifts:
            out[disc.key] = {mc.load_key(ld.as_array()): record(disc, ld, shifts[disc.key], t=20.0 if
                                                                  disc.formulation == "mixed" else 10.0)
                             for ld in loads}
    return out


def test_difference_is_the_largest_anchor_distance_over_the_largest_displacement():
    ref = record(mc.BASE, mc.LOADS[0], np.zeros(2))
    case = record(mc.BASE, mc.LOADS[0], np.array([0.3, 0.4]), phi=10.5, cap=11.0)
    d = joint_cases.difference(case, ref, X)
    assert d["anchor_mm"] == pytest.approx(0.5)
    assert d["anchor_percent"] == pytest.approx(100 * 0.5 / np.hypot(2.0, 10.0))
    assert d["phi_end_deg"] == pytest.approx(0.5) and d["cap_rotation_deg"] == pytest.approx(1.0)


def test_analyse_names_the_factor_that_moves_the_answer_most():
    """Mixed moves the tip by 0.5 mm, quadrature 4 by 0.05 mm: the formulation dominates,
    each effect is against the base, and the time ratio is the mean ratio (2)."""
    mixed, q4 = replace(mc.BASE, formulation="mixed"), replace(mc.BASE, quadrature=4)
    recs = records({mc.BASE.key: np.zeros(2), mixed.key: np.array([0.3, 0.4]),
                    q4.key: np.array([0.0, 0.05])})
    table = mc.analyse(recs, None)
    rows = {r["key"]: r for r in table["rows"]}
    assert rows[mixed.key]["effect"]["worst"]["anchor_mm"] == pytest.approx(0.5)
    assert rows[q4.key]["effect"]["worst"]["anchor_mm"] == pytest.approx(0.05)
    assert rows[mixed.key]["time_ratio"] == pytest.approx(2.0)
    assert rows[mixed.key]["effect"]["loads"] == 2
    assert table["dominant"]["factor"] == "formulation"
    assert [f for f, _ in table["ranking"]] == ["formulation", "quadrature"]
    assert table["ranking"][1][1] == pytest.approx(100 * 0.05 / np.hypot(2.0, 10.0))
    assert "**formulation**" in mc.markdown(table)


def test_reference_is_the_study_s_finest_mesh_at_its_loads():
    """Against a study out of the asymptotic range whose finest mesh holds only the first
    load, one load is compared; in the range, its extrapolated answers are the reference."""
    base = records({mc.BASE.key: np.zeros(2)})
    ref = record(mc.BASE, mc.LOADS[0], np.array([0.0, 1.0]))
    study = {"reference": "finest mesh",
             "meshes": [{"key": "a", "nodes": 10, "cases": []}, {"key": "b", "nodes": 1000, "cases": [ref]}]}
    table = mc.analyse(base, study)
    assert table["reference"] == "mesh study, finest mesh (b)"
    row = table["rows"][0]
    assert row["against_reference"]["loads"] == 1
    assert row["against_reference"]["worst"]["anchor_mm"] == pytest.approx(1.0)
    ext = {k: {"extrapolated": ref[k]} for k in ("anchors", "phi_end_deg", "cap_rotation_deg")}
    study.update(reference="richardson", formulation="mixed", loads=[ref["load"]], extrapolation=[ext],
                 family=["2.4:1.2", "1.697:0.849", "1.2:0.6"])
    table = mc.analyse(base, study)
    assert table["reference"] == "mesh study, Richardson extrapolation of the mixed family 2.4:1.2, 1.697:0.849, 1.2:0.6"
    assert table["rows"][0]["against_reference"]["worst"]["anchor_mm"] == pytest.approx(1.0)


def test_resume_reads_only_records_of_the_same_discretisation(tmp_path):
    """A record file whose discretisation differs from its name is solved again."""
    good = record(mc.BASE, mc.LOADS[0], np.zeros(2))
    foreign = record(replace(mc.BASE, penalty=1.0), mc.LOADS[1], np.zeros(2))
    (tmp_path / joint_cases.case_file(tmp_path, mc.BASE, mc.LOADS[0]).name).write_text(json.dumps(good))
    (tmp_path / joint_cases.case_file(tmp_path, mc.BASE, mc.LOADS[1]).name).write_text(json.dumps(foreign))
    (tmp_path / joint_cases.case_file(tmp_path, mc.BASE, mc.LOADS[2]).name).write_text("{damaged")
    assert list(joint_cases.read_records(tmp_path, mc.PLAN)[mc.BASE.key]) == [mc.load_key(mc.LOADS[0].as_array())]


@pytest.mark.parametrize("args, message", [(["--max-hours", "-1"], "--max-hours"),
                                           (["--reference", "/nonexistent.json"], "--reference")])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    out = tmp_path / "t.json"
    p = subprocess.run([sys.executable, "-m", "fem.studies.mesh_causes", "--work", str(tmp_path / "w"),
                        "--out", str(out), *args], capture_output=True, text=True)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and message in p.stderr
    assert not out.exists() and not (tmp_path / "w").exists()
