"""predictor.validation.grasps (issue 36 §3): the predictor against FEM grasp records, on two
frozen coarse records (tests/data/grasps: fem.studies.grasp_cases on 4 mm mixed tetrahedra, plane
on; circle at (0.2, 0.3) MPa holds, rectangle at (0.1, 0.1) slips). No FEM solve.

- Each entry's errors agree with an independent computation: the same grasp asked of the
  command line ``predictor.cli.gesture --object`` and the errors taken from its JSON with
  numpy (fingertip distance, signed angle, normal force, the normal-force-weighted mean of
  its contact points); the verdicts follow the issue's bounds from those numbers; where
  the grasp holds, the object's force on the finger carries exactly W/2 downwards on both
  sides (the contact law's friction ratio), and on this coarse mesh the predictor meets the
  issue's accuracy targets (tip, normal force, contact location, state; the tip angle within
  1.5°, this mesh's own error: 1.36° at the circle, against 0.008° on the production mesh).
- A record solved without the plane X = 0 is predicted without it: at (0.1, 0.1) MPa with
  an object nothing touches, the right fingertip crosses X = 0 without the plane and stays
  on its side with it.
- A record the FEM did not solve is listed as not_converged and meets no target.
- The normal-force bound is 10 % or 0.02 N, whichever is larger; the state is not judged
  where the FEM's friction use is within 0.05 of 1.
- Records on another discretisation than the one asked for are refused in one line.
"""
from __future__ import annotations

import copy
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from contract.grasp import GraspCase  # noqa: E402
from predictor.validation import grasps as vg  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "grasps"
MODEL = ROOT / "results" / "surrogate" / "improved.pt"
COARSE = ["--mesh", "4", "--formulation", "mixed", "--model", str(MODEL)]
pytestmark = pytest.mark.skipif(not MODEL.is_file(), reason="no committed surrogate")


def _record(name: str) -> dict:
    return json.loads((DATA / f"{name}_mixed.json").read_text())


def _validate(folder: Path, tmp: Path, monkeypatch, records: dict, png: bool = False) -> dict:
    """Write ``records`` {stem: record} into ``folder`` (with a stand-in render each when
    ``png``), run the validation once per solve (REPEATS 1) and return grasps.json."""
    folder.mkdir()
    for stem, record in records.items():
        (folder / f"{stem}.json").write_text(json.dumps(record))
        if png:
            import matplotlib.pyplot as plt
            plt.imsave(folder / f"{stem}.png", np.linspace(0.0, 1.0, 64).reshape(8, 8))
    monkeypatch.setattr(vg, "REPEATS", 1)
    out = tmp / "grasps.json"
    assert vg.main(["--fem", str(folder), "--out", str(out), "--figures", str(tmp / "figures"), "--json", *COARSE]) == 0
    return json.loads(out.read_text())


def _gesture(record: dict, capsys) -> dict:
    """The same grasp from predictor.cli.gesture's command line (its JSON)."""
    from predictor.cli import gesture

    capsys.readouterr()
    approach = ",".join(f"{p:g}" for p in record["approach_MPa"])
    code = gesture.main(["--p1", str(record["p1"]), "--p2", str(record["p2"]), "--object", record["object"],
                         "--approach", approach, "--mu", str(record["mu"]), "--object-weight",
                         str(record["object_weight_N"]), "--model", str(MODEL), "--json"])
    assert code == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def coarse(tmp_path_factory):
    """grasps.json of the two frozen coarse records (renders stood in by a tiny image)."""
    tmp = tmp_path_factory.mktemp("coarse")
    mp = pytest.MonkeyPatch()
    try:
        yield _validate(tmp / "fem", tmp, mp, {f"{n}_mixed": _record(n) for n in ("circle_0.2_0.3",
                                                                                     "rectangle_0.1_0.1")}, png=True)
    finally:
        mp.undo()


@pytest.mark.parametrize("name", ["circle_0.2_0.3", "rectangle_0.1_0.1"])
def test_entries_agree_with_an_independent_computation(coarse, name, capsys):
    record, entry = _record(name), next(e for e in coarse["cases"] if e["case"] == name)
    g = _gesture(record, capsys)
    assert entry["predictor_state"] == g["state"] and entry["fem_state"] == record["state"]
    tip_error = float(np.hypot(*(np.array(g["tip"]) - record["tip"])))
    assert entry["tip_error_mm"] == pytest.approx(tip_error, abs=1e-6)
    assert entry["tip_angle_error_deg"] == pytest.approx(g["tip_angle_deg"] - record["tip_angle_deg"], abs=1e-6)
    assert entry["normal_force_fem_N"] == record["contact_force_N"]
    assert entry["normal_force_predictor_N"] == pytest.approx(g["contact_force_N"], abs=1e-9)
    forces = np.array([c["normal_force_N"] for c in g["contacts"]])
    centre = (forces[:, None] * np.array([c["point_mm"] for c in g["contacts"]])).sum(0) / forces.sum()
    assert forces.sum() == pytest.approx(g["contact_force_N"], rel=1e-9)
    location = float(np.hypot(*(centre - record["contact_point_mm"])))
    assert entry["contact_location_error_mm"] == pytest.approx(location, abs=1e-6)
    assert entry["fem_friction_use"] == record["friction_use"]
    assert entry["speedup"] == pytest.approx(record["fem_s"] / entry["predictor_s"])
    n = record["contact_force_N"]
    dn = abs(g["contact_force_N"] - n)
    assert entry["met"] == {
        "tip": tip_error <= 1.0, "tip_angle": abs(g["tip_angle_deg"] - record["tip_angle_deg"]) <= 0.5,
        "normal_force": dn <= max(0.1 * n, 0.02), "contact_location": location <= 2.0,
        "state": g["state"] == record["state"], "fem_time": record["fem_s"] <= 900.0,
        "speedup": record["fem_s"] / entry["predictor_s"] >= 1e4}
    # the physics: on this mesh the predictor meets the issue's accuracy targets but the tip
    # angle's, which is this coarse mesh's own error: the production surrogate is 1.36° from the
    # 4 mm record at circle (0.2, 0.3) and 0.008° from the production FEM's (validation/grasps.json)
    assert entry["predictor_state"] == entry["fem_state"]
    assert all(entry["met"][k] for k in ("tip", "normal_force", "contact_location", "state"))
    assert abs(entry["tip_angle_error_deg"]) <= 1.5
    if record["state"] == "holds":   # friction carries the half weight W/2 exactly
        assert entry["object_force_predictor_N"][1] == pytest.approx(-0.5 * record["object_weight_N"], abs=1e-9)
        assert record["object_force_N"][1] == pytest.approx(-0.5 * record["object_weight_N"], abs=1e-9)
    assert entry["figure"] == f"{name}_mixed.png"
    assert (Path(coarse["figures"][0]).parent / entry["figure"]).is_file()


def test_summary_is_the_worst_of_the_cases(coarse):
    cases, s = coarse["cases"], coarse["summary"]
    assert s["cases"] == s["compared"] == 2
    assert s["tip_error_mm_max"] == max(c["tip_error_mm"] for c in cases)
    assert s["contact_location_error_mm_max"] == max(c["contact_location_error_mm"] for c in cases)
    assert s["speedup_min"] == min(c["fem_s"] / c["predictor_s"] for c in cases)
    for key in vg.JUDGED:
        assert s["met"][key] == {"met": sum(c["met"][key] is True for c in cases),
                                 "judged": sum(c["met"][key] is not None for c in cases)}
    assert s["all_met"] == all(v is not False for c in cases for v in c["met"].values())


def _out_of_reach(record: dict, plane: bool) -> dict:
    """The circle record re-posed as a grasp at (0.1, 0.1) MPa of a 2 mm circle below the
    fingertips (nothing touches it), solved with or without the plane."""
    r = copy.deepcopy(record)
    r.update(object="circle:r=1,y=-240", p1=0.1, p2=0.1, pressures_MPa=[0.1, 0.1], plane=plane,
             case=f"circle-r1-y-240_0.1_0.1{'' if plane else '_noplane'}")
    r["object_geometry"].update(a_mm=1.0, b_mm=1.0, y_mm=-240.0)
    r["settings"]["plane"] = plane
    return r


def test_a_record_without_the_plane_is_predicted_without_it(tmp_path, monkeypatch):
    record = _record("circle_0.2_0.3")
    out = _validate(tmp_path / "fem", tmp_path, monkeypatch,
                    {f"r_{p}": _out_of_reach(record, p) for p in (True, False)})
    by = {e["plane"]: e for e in out["cases"]}
    assert by[False]["predictor_state"] == by[True]["predictor_state"] == "no_contact"
    assert by[False]["tip_predictor_mm"][0] < -10.0           # the fingers cross each other
    assert by[False]["plane_force_predictor_N"] == 0.0
    assert by[True]["tip_predictor_mm"][0] > 0.0              # held on its side of X = 0
    assert by[True]["plane_force_predictor_N"] > 0.0


def test_a_case_the_fem_did_not_solve_meets_nothing(tmp_path, monkeypatch):
    failed = _record("circle_0.2_0.3")
    for key in ("tip", "tip_angle_deg", "contact_force_N", "friction_use", "contact_point_mm", "object_force_N",
                "base_force_N", "contact_patch", "penetration_mm", "plane_force_N"):
        failed[key] = None
    failed.update(converged=False, state="not_converged", reason="no convergence after 9 cut-backs")
    del failed["render"]
    out = _validate(tmp_path / "fem", tmp_path, monkeypatch, {"failed": failed})
    (entry,) = out["cases"]
    assert entry["fem_state"] == "not_converged" and not entry["fem_converged"]
    assert entry["predictor_state"] == "holds"                 # the predictor still answers
    assert entry["tip_error_mm"] is None and entry["contact_location_error_mm"] is None
    assert all(v is False for v in entry["met"].values())
    s = out["summary"]
    assert s["compared"] == 0 and s["fem_converged"] == 0 and not s["all_met"]
    assert all(m == {"met": 0, "judged": 1} for m in s["met"].values())
    assert entry["figure"] is None and out["figures"] == []


def _entry(**kw) -> dict:
    base = dict(fem_converged=True, predictor_converged=True, tip_error_mm=0.1, tip_angle_error_deg=0.1,
                normal_force_fem_N=0.5, normal_force_predictor_N=0.5, normal_force_error_N=0.0,
                contact_location_error_mm=0.1, fem_state="holds", predictor_state="holds", fem_friction_use=0.5,
                fem_s=100.0, speedup=2e4)
    return {**base, **kw}


@pytest.mark.parametrize("n_fem, error, met", [(0.1, 0.019, True), (0.1, -0.021, False), (0.5, 0.049, True),
                                               (0.5, -0.051, False)])
def test_normal_force_is_within_ten_percent_or_twenty_millinewton(n_fem, error, met):
    e = _entry(normal_force_fem_N=n_fem, normal_force_predictor_N=n_fem + error, normal_force_error_N=error)
    assert vg.verdicts(e)["normal_force"] is met


@pytest.mark.parametrize("use, judged", [(0.94, True), (0.96, False), (1.049, False), (1.06, True), (None, True)])
def test_the_state_is_not_judged_at_the_slip_limit(use, judged):
    verdict = vg.verdicts(_entry(fem_friction_use=use, predictor_state="slips"))["state"]
    assert verdict is (False if judged else None)


def test_records_of_another_discretisation_are_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        vg.main(["--fem", str(DATA), "--out", str(tmp_path / "g.json"), "--figures", str(tmp_path / "f")])
    assert exc.value.code == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "no FEM grasp records on mesh hex2:3 (mixed)" in err[0] and "it holds 4 mixed" in err[0]
    assert not any(tmp_path.iterdir())
    assert vg.production_discretisation() == ("hex2:3", "mixed")   # fem.studies.grasp_cases' default, suffix _hex2s3


def test_the_report_states_the_validations_targets():
    from apps.report.grasps import ISSUE_BOUNDS

    assert ISSUE_BOUNDS == vg.TARGETS


def test_the_report_section_shows_each_case_and_judges_every_target(coarse, tmp_path, monkeypatch):
    from apps.report import grasps as section
    from apps.report.grasps import grasps_section

    planned = [SimpleNamespace(name=e["case"]) for e in coarse["cases"]]
    monkeypatch.setattr(section, "GRASP_CASES", planned)     # the two coarse records are the whole table
    (tmp_path / "validation").mkdir()
    v = copy.deepcopy(coarse)
    v["cases"][1]["met"]["tip"] = False                 # a miss the summary counts
    v["summary"]["met"]["tip"]["met"] -= 1
    (tmp_path / "validation/grasps.json").write_text(json.dumps(v))
    lines, checks = grasps_section(tmp_path)
    for e in v["cases"]:
        (row,) = [ln for ln in lines if ln.startswith(f"| {e['case']} |")]
        assert f"| {e['tip_error_mm']:.3f} |" in row and f"| {e['speedup']:,.0f}x |" in row
    verdict = {c.figure.split(" ")[0]: c.met for c in checks}
    assert verdict["fingertip"] is False and verdict["FEM"] is True
    met = v["summary"]["met"]
    assert [c.met for c in checks[1:]] == [met[k]["met"] == met[k]["judged"] for k in vg.JUDGED]
    # a planned case without an FEM grasp is a miss of every target
    monkeypatch.setattr(section, "GRASP_CASES", planned + [GraspCase("ellipse", 0.3, 0.2)])
    lines, checks = grasps_section(tmp_path)
    assert not any(c.met for c in checks) and "1 of the 3 planned cases" in lines[2] and "ellipse_0.3_0.2" in lines[2]
    assert "| 2 of 3 |" in next(ln for ln in lines if ln.startswith("| FEM grasps conv"))


def test_the_report_section_says_not_run_without_the_validation(tmp_path):
    from apps.report.grasps import grasps_section

    lines, checks = grasps_section(tmp_path)
    rows = [ln for ln in lines if ln.startswith("| ") and not ln.startswith("| target")]
    assert checks == [] and len(rows) == len(vg.JUDGED) + 1
    assert all(ln.endswith("| not run |") for ln in rows)
    assert "make grasp-fem" in lines[2]
