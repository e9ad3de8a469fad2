"""predictor.validation.contact_change and the report's contact section (issue 36) on small hand-made
artefacts whose answers are known: the atlas points whose state changed and how, the
reference ramps' failures, the gestures' tip shifts (a 3-4-5 triangle), the worst overlap
across X = 0 judged against 0.1 mm, what the section says the model costs from the bench's
own figures, and bad input (exit 2, one line, nothing written)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from apps.report import contact
from apps.report.contact import contact_section
from predictor.validation.contact_change import compare

ROOT = Path(__file__).resolve().parents[1]
STATES = ["no_contact", "holds", "slips", "not_converged"]


def _atlas(state, overlap=None, steps=None):
    """A 2 x 2 atlas of the circle with grid codes ``state`` (and plane overlaps, mm)."""
    counts = {name: sum(row.count(k) for row in state) for k, name in enumerate(STATES)}
    doc = {"grid": 2, "approach_MPa": [0.0, -0.05], "mu": 0.3, "states": STATES, "state": state, "counts": counts,
           "object": {"kind": "circle"}, "p1_MPa": [0.0, 0.3], "p2_MPa": [0.0, 0.3],
           "targets": {"atlas_s_per_object": 10.0}, "measured": {"atlas_s_per_object": 1.0, "grid_points": 4}}
    if overlap is not None:
        doc.update(plane_overlap_mm=overlap, max_plane_overlap_mm=max(v for row in overlap for v in row))
    if steps:
        doc["ramp_steps"] = steps
    return doc


def _gesture(p, tip, state=None, overlap=None):
    g = {"pressures_MPa": p, "converged": tip is not None, "tip": tip, "tip_angle_deg": -90.0,
         "contact_force_N": 0.0, "plane_overlap_mm": overlap}
    return g if state is None else {**g, "state": state}


def _gestures(shift: float, overlap=None):
    return {"joint": "analytic", "approach_MPa": [0.0, -0.05],
            "gravity": [_gesture([0.1, 0.1], [10.0, -200.0], overlap=overlap)],
            "free": [_gesture([0.3, 0.3], [10.0 - 3 * shift, -200.0 + 4 * shift], overlap=overlap)],
            "grasps": {"circle": [_gesture([0.2, 0.3], [20.0, -210.0 + shift], "holds" if shift == 0 else "slips",
                                           overlap)]}}


def _write(folder: Path, atlas, ramp, fine, gestures, inverse=None):
    (folder / "ramp").mkdir(parents=True)
    (folder / "ramp_fine").mkdir()
    for rel, doc in (("atlas_circle.json", atlas), ("ramp/atlas_circle.json", ramp),
                     ("ramp_fine/atlas_circle.json", fine), ("gestures.json", gestures), ("inverse.json", inverse)):
        if doc is not None:
            (folder / rel).write_text(json.dumps(doc))


@pytest.fixture()
def folders(tmp_path):
    before, after = tmp_path / "before" / "predictor", tmp_path / "after" / "predictor"
    _write(before, _atlas([[0, 1], [2, 1]]), _atlas([[0, 3], [3, 1]]), _atlas([[3, 3], [3, 1]], steps=48),
           _gestures(0.0))
    over = [[0.0, 0.02], [0.08, 0.03]]
    inverse = {"joint": "analytic", "targets": {"inverse_tip_ms": 1.0, "inverse_hold_ms": 1.0},
               "measured": {"inverse_tip_ms": 1.0, "inverse_hold_ms": 1.0, "inverse_hold_cold_ms": 1.0},
               "tolerances": {"regulator_MPa": 0.01},
               "cases": [{"goal": "hold", "object": "circle", "status": "feasible", "pressures": [0.2, 0.3],
                          "friction_use": 0.5, "verified": True, "robust": True, "time_ms_median": 1.0,
                          "plane_overlap_mm": 0.12}]}
    _write(after, _atlas([[0, 2], [2, 2]], over), _atlas([[0, 2], [3, 2]], over), _atlas([[0, 2], [2, 2]], over, 48),
           _gestures(5.0, 0.01), inverse)
    return before, after


def test_changes_are_counted_exactly(folders):
    """Two of four points changed (holds -> slips twice), the references' failures 2 -> 1
    and 3 -> 0 (48 sub-steps), the free tip moved along a 3-4-5 triangle by 25 mm, the
    grasp by 5 mm with its state, the gravity gesture not at all."""
    before, after = folders
    doc = compare(before, after, "test")
    a = doc["atlas"]["circle"]
    assert (a["points"], a["changed"], a["transitions"]) == (4, 2, {"holds -> slips": 2})
    assert (a["counts_before"]["holds"], a["counts_after"]["slips"]) == (2, 3)
    ref, fine = doc["reference"]["circle"], doc["reference_fine"]["circle"]
    assert (ref["not_converged_before"], ref["not_converged_after"], ref["ramp_steps_before"]) == (2, 1, 12)
    assert (fine["not_converged_before"], fine["not_converged_after"], fine["ramp_steps_after"]) == (3, 0, 48)
    shifts = {(g["group"], g["object"]): g for g in doc["gestures"]}
    assert shifts[("gravity", None)]["tip_shift_mm"] == 0.0
    assert shifts[("free", None)]["tip_shift_mm"] == pytest.approx(25.0, abs=1e-12)
    grasp = shifts[("grasps", "circle")]
    assert grasp["tip_shift_mm"] == pytest.approx(5.0, abs=1e-12)
    assert (grasp["state_before"], grasp["state_after"], grasp["plane_overlap_mm"]) == ("holds", "slips", 0.01)


def test_report_judges_the_worst_overlap(folders, tmp_path):
    """The report's section on the 'after' folder: the worst overlap over gestures, atlas
    points and inverse answers is the inverse answer's 0.12 mm, over the 0.1 mm target by
    0.02; with it at 0.05 mm the worst is the atlases' 0.08 mm, met."""
    _, after = folders
    root = after.parent
    out = tmp_path / "after" / "predictor" / "h1.8" / "contact_change.json"   # where the report reads it
    out.parent.mkdir(parents=True)
    run = subprocess.run([sys.executable, "-m", "predictor.validation.contact_change", "--before", str(folders[0]),
                          "--after", str(after), "--label", "test", "--out", str(out)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    lines, checks = contact_section(root)
    assert len(checks) == 1 and not checks[0].met and checks[0].values == (0.12,)
    assert checks[0].verdict.startswith("no, over by 0.02")
    text = "\n".join(lines)
    assert "| circle | 2 of 4 | holds -> slips 2 | 2 -> 1 of 4 | 3 -> 0 of 4 |" in text
    assert "| circle | 0.2, 0.3 | holds -> slips | 5.00 mm | 0.010 mm |" in text
    inv = json.loads((after / "inverse.json").read_text())
    inv["cases"][0]["plane_overlap_mm"] = 0.05
    (after / "inverse.json").write_text(json.dumps(inv))
    _, checks = contact_section(root)
    assert checks[0].met and checks[0].values == (0.08,)


def test_costs_quote_the_bench_and_its_machine(monkeypatch, tmp_path):
    """The section's costs take the bench's own figures: how many gravity fastest-path
    cases the LM finished, and, where the bench's runs on every core were slower than on
    one (2e4 against 3e4 gestures per second at load 3.8), that its times are the
    machine's; with every core faster than one, the load without that clause."""
    thr = {"one_thread": {"nn_and_kinematics_per_s": 3.0e4}, "every_core_float64": {"nn_and_kinematics_per_s": 2.0e4}}
    bench = {"load_average_at_start": [3.84, 3.7, 4.1], "batched_threads": 2,
             "details": {"gravity_fast": {"n": 30, "fallbacks": 28}, "gravity_nn_throughput": thr}}
    monkeypatch.setattr(contact, "load", lambda root, rel: bench if rel == "bench/predictor.json" else None)
    text = "\n".join(contact_section(tmp_path)[0])
    assert "the Newton step from it misses its check, so the LM finishes it (28 of 30 bench cases)." in text
    assert ("a load average of 3.8 on this machine's 2 cores, where its runs on every core were slower than on one "
            "(the gravity NN's network and kinematics, float64: 2e+04 against 3e+04 gestures per second)") in text
    thr["every_core_float64"]["nn_and_kinematics_per_s"] = 6.0e4
    text = "\n".join(contact_section(tmp_path)[0])
    assert "a load average of 3.8 on this machine's 2 cores." in text and "slower than on one" not in text


def test_bad_input_exits_2_and_writes_nothing(tmp_path):
    """A folder without predictor results, or two atlases of different grids: one line on
    stderr, exit 2, no output file."""
    out = tmp_path / "c.json"
    run = [sys.executable, "-m", "predictor.validation.contact_change", "--label", "x", "--out", str(out)]
    r = subprocess.run(run + ["--before", str(tmp_path), "--after", str(tmp_path)], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "no predictor results" in r.stderr
    before, after = tmp_path / "b", tmp_path / "a"
    bigger = _atlas([[0, 1], [2, 1]])
    bigger.update(grid=3, p1_MPa=[0.0, 0.15, 0.3])
    _write(before, bigger, None, None, None)
    _write(after, _atlas([[0, 1], [2, 1]]), None, None, None)
    r = subprocess.run(run + ["--before", str(before), "--after", str(after)], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "different grids" in r.stderr
    assert not out.exists()
