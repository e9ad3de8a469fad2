"""fem.studies.finger_grid and its report section (issue 36 §1, issue 56 §2), on JSON only (no solve).

- The grid is the 7 x 7 lattice of the box [-0.3, 0.3]^2 MPa: spacing 0.1 MPa, the origin
  exactly, symmetric under P -> -P; its 49 cases are fem.studies.finger_cases' gravity cases by
  name (gravity_P1_P2), on the production mesh with the plane ``_hex2s3_plane`` files: the
  names the running queue (``fem.studies.finger_cases --plane --pressures ...``) writes.
- The skip rule is fem.studies.finger_cases': a converged record of the same settings stands, a
  failed one only under the same solver controls, none under other settings (the lone
  finger's, another finger); the summary counts only records that stand.
- The summary from fixture records: pairs 4, solved 3, converged 2, slowest 900 s, median
  120 s, each case with p1, p2, converged, plane, wall_s, tip; ``--summary-only`` writes
  it without solving, the default solves only the pairs whose record does not stand.
- The report draws one cell per pair (time, failed, pending), judges a complete grid
  (all pairs converged, slowest <= 600 s) and says "Pending" without the file.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from apps.report import build
from apps.report.finger_grid import finger_grid_section
from contract.files import json_safe
from contract.finger import load_finger

pytest.importorskip("dolfinx")

from fem.artefacts import FINGER_CASE, FINGER_GRID  # noqa: E402
import fem.studies.finger_cases as fc  # noqa: E402
import fem.studies.finger_records as fr  # noqa: E402
import fem.studies.finger_grid as fg  # noqa: E402
from fem.mesh.geometry import pressure_limits  # noqa: E402
from fem.studies.finger_grid import grid_cases, grid_pairs, grid_summary  # noqa: E402

FINGER = load_finger()
QUEUE = ("-0.3,-0.3;-0.2,-0.3;-0.1,-0.3;0,-0.3;0.1,-0.3;0.2,-0.3;0.3,-0.3;-0.3,-0.2;-0.2,-0.2;-0.1,-0.2;"
         "0,-0.2;0.1,-0.2;0.2,-0.2;0.3,-0.2;-0.3,-0.1;-0.2,-0.1;-0.1,-0.1;0,-0.1;0.1,-0.1;0.2,-0.1;0.3,-0.1;"
         "-0.3,0;-0.2,0;-0.1,0;0,0;0.1,0;0.2,0;0.3,0;-0.3,0.1;-0.2,0.1;-0.1,0.1;0,0.1;0.1,0.1;0.2,0.1;0.3,0.1;"
         "-0.3,0.2;-0.2,0.2;-0.1,0.2;0,0.2;0.1,0.2;0.2,0.2;0.3,0.2;-0.3,0.3;-0.2,0.3;-0.1,0.3;0,0.3;0.1,0.3;"
         "0.2,0.3;0.3,0.3")                  # the running queue's --pressures (P1 fastest)


def test_grid_is_the_box_lattice_of_the_queues_cases():
    pairs = np.array(grid_pairs(np.array([0.3, 0.3]), 7))
    assert pairs.shape == (49, 2) and len({tuple(p) for p in pairs}) == 49
    assert np.allclose(np.unique(pairs[:, 0]), np.linspace(-0.3, 0.3, 7))
    assert np.allclose(np.diff(np.unique(pairs[:, 1])), 0.1)
    assert (0.0, 0.0) in {tuple(p) for p in pairs}                   # exactly 0, not 1e-17
    assert {tuple(p) for p in pairs} == {tuple(-p + 0.0) for p in pairs}
    assert tuple(pairs[1]) == (pytest.approx(-0.2), -0.3)            # P1 varies fastest
    cases = grid_cases(grid_pairs(pressure_limits(FINGER), 7))
    assert cases == fc.pressure_cases(QUEUE)                        # names, pressures, gravity: the queue's
    assert cases[0][0] == "gravity_-0.3_-0.3" and cases[24][0] == "gravity_0_0" and cases[32][0] == "gravity_0.1_0.1"


def test_production_plane_file_names():
    from fem.mesh.geometry import JointGeometry

    joint = JointGeometry(mesh_size=None, divisions=2, hex_size=3.0)
    assert fr.default_suffix(joint, "mixed", plane=True) == "_hex2s3_plane"
    assert fr.default_suffix(joint, "mixed", plane=False) == "_hex2s3"


SETTINGS = json_safe({"finger_sha256": FINGER.digest, "formulation": "mixed", "plane": True,
                      "geometry": {"finger": FINGER.summary(), "joint": {"divisions": 2, "hex_size": 3.0}}})
SOLVER = {"max_it": 25}


def _record(name: str, p1: float, p2: float, converged: bool, wall: float, settings=SETTINGS, solver=SOLVER):
    """A fem.studies.finger_cases record (FINGER_CASE) as the queue writes it."""
    return {"case": name, "pressures_MPa": [p1, p2], "gravity": True, "converged": converged,
            "tip": [10.5, -215.0] if converged else None, "tip_angle_deg": -95.0 if converged else None,
            "plane_force_N": 0.09 if converged else None, "plane_overlap_mm": 0.03 if converged else None,
            "newton_iterations": [7, 9], "iterations": 16, "load_steps": 2, "cutbacks": int(not converged),
            "factorisations": 5, "wall_time_s": wall, "cpu_time_s": wall / 2,
            "reason": "" if converged else "no convergence after 9 cut-backs at path 0.6406",
            "fem_s": wall, "fem_cpu_s": wall / 2, "load_average": 2.0, "setup_s": 90.0,
            "mesh": {"mesh": "hex2:3", "nodes": 60000, "divisions": 2}, "formulation": "mixed",
            "settings": settings, "solver": solver, "ranks": 1}


def _folder(tmp_path, records: dict):
    folder = tmp_path / "validation" / "finger_fem"
    folder.mkdir(parents=True, exist_ok=True)
    for file, record in records.items():
        FINGER_CASE.write(folder / file, record)
    return folder


CASES = grid_cases(grid_pairs(np.array([0.3, 0.3]), 2))          # (-0.3, -0.3), (0.3, -0.3), (-0.3, 0.3), (0.3, 0.3)
GRID = {"case": SETTINGS, "formulation": "mixed", "points": 2, "gravity": True, "plane": True}


def _fixture(tmp_path):
    return _folder(tmp_path, {
        "gravity_-0.3_-0.3_hex2s3_plane.json": _record("gravity_-0.3_-0.3", -0.3, -0.3, True, 80.0),
        "gravity_0.3_-0.3_hex2s3_plane.json": _record("gravity_0.3_-0.3", 0.3, -0.3, False, 900.0),
        "gravity_-0.3_0.3_hex2s3_plane.json": _record("gravity_-0.3_0.3", -0.3, 0.3, True, 120.0),
        # the lone finger's record of the last pair: another problem, it does not stand
        "gravity_0.3_0.3_hex2s3.json": _record("gravity_0.3_0.3", 0.3, 0.3, True, 100.0,
                                                settings={k: v for k, v in SETTINGS.items() if k != "plane"}),
        "gravity_0.3_0.3_hex2s3_plane.json": _record("gravity_0.3_0.3", 0.3, 0.3, True, 100.0,
                                                      settings={k: v for k, v in SETTINGS.items() if k != "plane"}),
    })


def test_summary_of_the_standing_records(tmp_path):
    folder = _fixture(tmp_path)
    doc = grid_summary(CASES, folder, "_hex2s3_plane", GRID, SOLVER, FINGER)
    FINGER_GRID.check(json.loads(json.dumps(doc)), "grid")
    assert (doc["pairs"], doc["solved"], doc["converged"], doc["complete"]) == (4, 3, 2, False)
    assert (doc["max_wall_s"], doc["median_wall_s"]) == (900.0, 120.0)
    assert [(c["p1"], c["p2"]) for c in doc["cases"]] == [(-0.3, -0.3), (0.3, -0.3), (-0.3, 0.3)]
    first, failed = doc["cases"][0], doc["cases"][1]
    assert first["plane"] is True and first["tip"] == [10.5, -215.0] and first["wall_s"] == 80.0
    assert first["newton_iterations"] == 16 and first["plane_force_N"] == 0.09
    assert first["file"] == "gravity_-0.3_-0.3_hex2s3_plane.json"
    assert failed["converged"] is False and failed["tip"] is None and failed["cutbacks"] == 1
    assert doc["settings"]["points"] == 2 and doc["settings"]["plane"] is True and doc["mesh"]["nodes"] == 60000
    # a failed record stands only under the same solver controls
    doc = grid_summary(CASES, folder, "_hex2s3_plane", GRID, {"max_it": 30}, FINGER)
    assert (doc["solved"], doc["converged"]) == (2, 2)
    # the lone finger's settings: none of the plane's records stands
    lone = {**GRID, "case": {k: v for k, v in SETTINGS.items() if k != "plane"}, "plane": False}
    doc = grid_summary(CASES, folder, "_hex2s3", GRID | lone, SOLVER, FINGER)
    assert [(c["p1"], c["p2"], c["plane"]) for c in doc["cases"]] == [(0.3, 0.3, False)]
    assert grid_summary(CASES, folder, "_hex2s4_plane", GRID, SOLVER, FINGER) is None


def _main(monkeypatch, folder, out, *extra):
    """fem.studies.finger_grid.main on a 2 x 2 grid with the fixture's settings and its solve
    replaced: the cases it would solve."""
    todo = []
    monkeypatch.setattr(fg, "solve_cases", lambda cases, *a, **k: todo.extend(cases))
    monkeypatch.setattr(fg, "case_settings", lambda *a: SETTINGS)
    monkeypatch.setattr(fg, "solver_settings", lambda geometry: SOLVER)
    monkeypatch.setattr(fg, "default_suffix", lambda joint, formulation, plane: "_hex2s3" + "_plane" * plane)
    assert fg.main(["--cases", str(folder), "--out", str(out), "--points", "2", *extra]) == 0
    return todo


def test_main_skips_what_stands_and_summary_only_solves_nothing(tmp_path, monkeypatch, capsys):
    folder, out = _fixture(tmp_path), tmp_path / "fem" / "finger_grid.json"
    out.parent.mkdir()
    assert _main(monkeypatch, folder, out, "--summary-only") == []
    doc = FINGER_GRID.load(out)
    assert (doc["pairs"], doc["solved"], doc["converged"]) == (4, 3, 2)
    assert "2 of 3 standing pairs converged (4 in the grid, 1 pending)" in capsys.readouterr().out
    todo = _main(monkeypatch, folder, out)
    assert [(name, path.name) for name, *_, path in todo] == [("gravity_0.3_0.3", "gravity_0.3_0.3_hex2s3_plane.json")]


def test_report_draws_the_grid_and_judges_it_when_complete(tmp_path):
    folder = _fixture(tmp_path)
    doc = grid_summary(CASES, folder, "_hex2s3_plane", GRID, SOLVER, FINGER)
    FINGER_GRID.write(tmp_path / "fem" / "finger_grid.json", doc)
    lines, checks = finger_grid_section(tmp_path)
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in lines if ln.startswith("| **")}
    assert rows == {"**0.3**": ["120 s", "pending"], "**-0.3**": ["80 s", "**failed**"]}
    text = "\n".join(lines)
    assert checks == [] and "2 of 3 solved pairs converged (1 of 4 still to solve)" in text
    assert "the gripper: the right finger against the mirror finger's contact at X = 0" in text
    # the predictor's fingertip error joins a pair's cell from a validation of the same mesh and problem
    entry = lambda variant, mm: {"case": "gravity_-0.3_0.3", "variant": variant, "method": "predictor",  # noqa: E731
                                 "kinematics": "cap", "joint_weight": "split", "tip_error_mm": mm,
                                 "tip_angle_error_deg": 0.0, "predictor_s": 0.01, "tip_angle_deg": 0.0, "tip_mm": None}
    validation = {"discretisation": {"mesh": "hex2:3", "formulation": "mixed"}, "judged_variant": "predictor_cap_split",
                  "targets": dict.fromkeys(("tip_error_mm", "tip_angle_error_deg", "speedup", "fem_s", "fem_cases"), 1),
                  "summary": {}, "joint": "analytic", "repeats": 1, "finger": {"name": "paper"},
                  "fem": [{"case": "gravity_-0.3_0.3", "pressures_MPa": [-0.3, 0.3], "gravity": True, "converged": True,
                           "fem_s": 120.0, "tip": [0.0, 0.0], "tip_angle_deg": 0.0, "mesh": {"nodes": 60000}}],
                  "cases": [entry("predictor_cap_split", 0.123), entry("predictor_tangent_lumped", 9.0)]}
    for plane, cell in ((True, "120 s, 0.12 mm"), (False, "120 s")):   # a lone finger's is another problem
        (tmp_path / "validation").mkdir(exist_ok=True)
        (tmp_path / "validation" / "finger.json").write_text(json.dumps({**validation, "plane": plane}))
        lines, _ = finger_grid_section(tmp_path)
        assert [ln.split("|")[2].strip() for ln in lines if ln.startswith("| **0.3**")] == [cell]
    FINGER_CASE.write(folder / "gravity_0.3_0.3_hex2s3_plane.json", _record("gravity_0.3_0.3", 0.3, 0.3, True, 300.0))
    FINGER_GRID.write(tmp_path / "fem" / "finger_grid.json",
                      grid_summary(CASES, folder, "_hex2s3_plane", GRID, SOLVER, FINGER))
    _, (converged, slowest) = finger_grid_section(tmp_path)
    assert (converged.met, converged.values, converged.verdict) == (False, (3,), "no, short by 1 pairs")
    assert (slowest.met, slowest.values) == (False, (900.0,))


def test_report_says_pending_without_the_grid(tmp_path):
    lines, checks = finger_grid_section(tmp_path)
    assert checks == [] and "_Pending: `make finger-grid` has not run" in "\n".join(lines)
    assert "## Finger FEM over the pressure box (issue 36)" in build(tmp_path)[0]


def test_the_grid_resumes_the_running_queues_records(tmp_path, monkeypatch, capsys):
    """``make finger-grid`` asks for the very records ``fem.studies.finger_cases --plane --pressures
    QUEUE`` writes: the same files, settings and solver controls (so they stand)."""
    seen = {}

    def spy(tool):
        def pending(cases, out, suffix, settings, solver, finger):
            seen[tool] = ([str(out / f"{c[0]}{suffix}.json") for c in cases], json_safe(settings), solver)
            return list(cases) if tool == "grid" else []
        return pending

    monkeypatch.setattr(fc, "pending", spy("cases"))
    monkeypatch.setattr(fg, "pending", spy("grid"))
    assert fc.main(["--plane", "--pressures", QUEUE, "--out", str(tmp_path)]) == 0
    assert fg.main(["--cases", str(tmp_path), "--out", str(tmp_path / "grid.json"), "--summary-only"]) == 0
    assert "no case of the grid stands" in capsys.readouterr().out and not (tmp_path / "grid.json").exists()
    assert seen["grid"] == seen["cases"]
    files, settings, _ = seen["grid"]
    assert len(files) == 49 and files[0].endswith("/gravity_-0.3_-0.3_hex2s3_plane.json")
    assert settings["plane"] is True and settings["formulation"] == "mixed"
