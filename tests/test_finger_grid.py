"""fem.finger_grid and its report section (issue 36 §1), on JSON only (no solve).

- The grid is the 7 x 7 lattice of the box [-0.3, 0.3]^2 MPa: spacing 0.1 MPa, the origin
  exactly, symmetric under P -> -P.
- A run resumes: converged cases of the same settings stand, failed ones only under the
  same solver controls, none under other settings.
- The report draws one cell per pair (time, failed, pending), judges a complete grid
  (all pairs converged, slowest <= 600 s) and says "Pending" without the file.
"""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from apps.report import build
from contract.files import json_safe
from contract.finger import load_finger
from apps.report.finger_grid import finger_grid_section
from fem.artefacts import FINGER_GRID
from fem.finger_grid import case_record, grid_pairs, kept_cases, summary

FINGER = load_finger()


def test_grid_is_the_box_lattice():
    pairs = np.array(grid_pairs(np.array([0.3, 0.3]), 7))
    assert pairs.shape == (49, 2) and len({tuple(p) for p in pairs}) == 49
    assert np.allclose(np.unique(pairs[:, 0]), np.linspace(-0.3, 0.3, 7))
    assert np.allclose(np.diff(np.unique(pairs[:, 1])), 0.1)
    assert (0.0, 0.0) in {tuple(p) for p in pairs}                   # exactly 0, not 1e-17
    assert {tuple(p) for p in pairs} == {tuple(-p + 0.0) for p in pairs}
    assert tuple(pairs[1]) == (pytest.approx(-0.2), -0.3)            # P1 varies fastest


def _result(converged: bool, wall: float):
    return SimpleNamespace(converged=converged, wall_time=wall, cpu_time=wall / 2,
                           newton_iterations=[7, 9], load_steps=2, cutbacks=int(not converged),
                           factorisations=5, tip=np.array([-120.0, -130.0]), tip_angle=-2.9,
                           reason="" if converged else "no convergence after 9 cut-backs at path 0.6406")


def _grid(tmp_path, cases, pairs=4, points=2):
    settings = json_safe({"finger_sha256": FINGER.digest, "points": points, "formulation": "displacement",
                          "geometry": {"finger": FINGER.summary(), "joint": {"mesh_size": 4.0}}})
    doc = {"finger": {"name": "paper"}, "settings": settings,
           "solver": {"max_it": 25}, "mesh": {"nodes": 11159, "mesh": "4"}, "cases": cases,
           **summary(cases, pairs)}
    path = tmp_path / "fem" / "finger_grid.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    FINGER_GRID.write(path, doc)
    return path, doc


def test_resume_keeps_converged_and_retries_failures_under_new_controls(tmp_path):
    cases = [case_record(-0.3, -0.3, _result(True, 80.0)), case_record(0.3, -0.3, _result(False, 900.0))]
    path, doc = _grid(tmp_path, cases)
    assert cases[1]["tip"] is None and cases[0]["newton_iterations"] == 16
    assert set(kept_cases(path, doc["settings"], doc["solver"], FINGER)) == {(-0.3, -0.3), (0.3, -0.3)}
    assert set(kept_cases(path, doc["settings"], {"max_it": 30}, FINGER)) == {(-0.3, -0.3)}
    assert kept_cases(path, {**doc["settings"], "points": 7}, doc["solver"], FINGER) == {}
    # the same finger by its values (a file whose comments changed) keeps them; a heavier tip does not
    recommented = {**doc["settings"], "finger_sha256": "0" * 64}
    assert set(kept_cases(path, recommented, doc["solver"], FINGER)) == {(-0.3, -0.3), (0.3, -0.3)}
    heavier = dataclasses.replace(FINGER, digest="1" * 64, parts=FINGER.parts[:-1] + (
        dataclasses.replace(FINGER.parts[-1], weight=2 * FINGER.parts[-1].weight),))
    assert kept_cases(path, doc["settings"], doc["solver"], heavier) == {}


def test_report_draws_the_grid_and_judges_it_when_complete(tmp_path):
    partial = [case_record(-0.3, -0.3, _result(True, 80.0)), case_record(0.3, -0.3, _result(False, 900.0)),
               case_record(-0.3, 0.3, _result(True, 120.0))]
    _grid(tmp_path, partial)
    lines, checks = finger_grid_section(tmp_path)
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in lines if ln.startswith("| **")}
    assert rows == {"**0.3**": ["120 s", "pending"], "**-0.3**": ["80 s", "**failed**"]}
    assert checks == [] and "2 of 3 solved pairs converged (1 of 4 still to solve)" in "\n".join(lines)
    _grid(tmp_path, partial + [case_record(0.3, 0.3, _result(True, 300.0))])
    _, (converged, slowest) = finger_grid_section(tmp_path)
    assert (converged.met, converged.values, converged.verdict) == (False, (3,), "no, short by 1 pairs")
    assert (slowest.met, slowest.values) == (False, (900.0,))


def test_report_says_pending_without_the_grid(tmp_path):
    lines, checks = finger_grid_section(tmp_path)
    assert checks == [] and "_Pending: `make finger-grid` has not run" in "\n".join(lines)
    assert "## Finger FEM over the pressure box (issue 36)" in build(tmp_path)[0]
