"""make demo: the project end to end in a few minutes, FEM against every model.

    python -m apps.demo --out results/demo [--finger-mesh-size 4] [--finger FILE] [--json]

What runs, one subprocess at a time (``sys.executable -m ...``, so at most one FEM runs):

1. ``fem.cli.render --json``: the joint FEM of (P, F1, F2, M) = (0.2 MPa, 1 N, -1 N, 20 N·mm)
   on the committed data's discretisation, rendered -> ``joint.png`` (its JSON is
   ``fem.cli.solve --json``'s);
2. ``surrogate.predict --json``: the same case on the surrogate trained on that
   discretisation's data (FEM_SURROGATE, the 1.8 mm reference results/surrogate/h1.8/);
3. ``predictor.validation.finger --cases``: the predictor (on FEM_SURROGATE) against the committed whole-finger
   FEM of the paper's gravity gestures (-0.1, 0.1) and (0.1, -0.1) MPa
   (results/validation/finger_fem, made by ``make finger-fem``; not solved now) ->
   ``gravity.json`` and the overlays ``committed/finger_gravity_<P1>_<P2>.png``. Those FEM cases are
   one finger alone (no plane X = 0), and so is the predictor here (validate_finger
   matches each case's plane);
4. and 5. ``predictor.cli.gesture --json --plot``: the same gestures of the gripper, whose
   fingers meet at X = 0, on the default (production) surrogate -> ``gesture_<P1>_<P2>.png``,
   against the committed finger FEM of the gripper at the same pressures where it is solved
   (``<case>_hex2s3_plane.json``: the production mesh with the plane, the surrogate's own data
   mesh; ``make finger-grid``), within the production validation's targets
   (results/validation/finger.json); where it is not solved yet the row gives the fingertip
   and the force where the fingers meet;
6. ``predictor.cli.gesture --object circle``: one grasp -> ``grasp.png`` (there is no FEM of
   a grasp here: normal force, friction use |f|/N and hold/slip are shown instead);
7. ``fem.studies.finger_cases --mesh-size H``: the whole-finger FEM of (0.1, -0.1) MPa solved now
   on a coarse joint mesh (one finger alone) -> ``finger_fem/<case>.json`` and its render;
8. ``predictor.validation.finger --mesh-size H``: the predictor (one finger alone, on
   FEM_SURROGATE) against it -> ``finger.json`` and the overlay ``finger_<case>.png``.

``--finger FILE`` (a finger of two joints) runs every gesture and the live finger FEM for
that finger; the committed finger FEM is the paper's finger, so for another finger step 3
and the rows against the committed FEM are left out (``committed_finger``), and the
summary names the finger.

Each row names the problem both sides solved (``problem``: one joint, one finger alone, or
the gripper) and the FEM's discretisation, and a row with a tolerance (the targets of the
finger validation of its problem, from its JSON: one finger alone's tip within 2 mm and
1 deg, the gripper's within 1 mm and 0.5 deg) says whether it is within
it (``within_tolerance``); the cases beyond it are listed in the table, in
``beyond_tolerance`` of summary.json and on stderr (the exit stays 0: the run is complete).

Discretisation: the committed finger cases the demo compares with are on the
paper-fidelity 1.8 mm P2 displacement mesh (fem.mesh.discretisation.PAPER, COMMITTED_MESH_SIZE
and COMMITTED_FORMULATION here), not on the production hex2:3 mixed; so the joint FEM of
step 1 runs on that mesh, and the live finger FEM of step 7 on the coarse H mm (default 4)
tetrahedra in the same displacement formulation, and every step compared with a FEM runs on
the surrogate trained on that mesh's data, the 1.8 mm reference (FEM_SURROGATE; since the
switch, issue 55 §3, the default surrogate is the production one, which the gripper's
gestures use, compared with the committed production-mesh FEM of the gripper). The demo
runs no production-mesh FEM. The problem: the
committed finger cases are one finger alone, so the gestures of steps 3, 4 and the finger
FEM of step 6 are solved with ``--no-plane`` too (a comparison of the gripper, the tools'
default, with a lone finger would measure the difference of problems, issue 56 §1).

Data flow: each step's JSON (its stdout, or the file it writes) -> ``table_rows`` (pure:
the errors, times and labels of every row) -> ``summary.json``, ``summary.md`` (the same
table, PNGs linked) and the table on stdout. Each step prints ``[demo k/N] what ...
(elapsed s)`` before it starts, a heartbeat while it runs and its result after.

Layering: an app (apps -> predictor -> surrogate -> workflow -> fem); it runs the
packages' command lines, one subprocess each, and reads their JSON, the committed finger
FEM cases and the files the steps write through their formats (fem.artefacts,
predictor.artefacts); of the packages it imports only those, fem.mesh.geometry and the
contract (no torch, no dolfinx). Its own summary.json is checked against
SUMMARY before it is written. Exit 0 when every step succeeded; otherwise one line names the failed
step and the exit is 1. The summary is written (atomically) only at the end, and the
previous summary is removed at the start, so no summary ever describes another run.
Units: mm, deg, N, MPa, s.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from contract import cli
from contract.files import write_text
from contract.finger import FingerSpec, finger_arg, load_finger, same_finger
from contract.records import Format, each
from fem import artefacts as fem_artefacts
from fem.mesh.geometry import PAPER_MESH_SIZE
from predictor import artefacts as predictor_artefacts

ROOT = Path(__file__).resolve().parents[1]
SURROGATE = "results/surrogate/improved.pt"
#: The surrogate trained on the data of the demo's FEM discretisation (module docstring): the
#: 1.8 mm reference, so that a FEM row measures the model, not the change of mesh.
FEM_SURROGATE = "results/surrogate/h1.8/improved.pt"
COMMITTED_FINGER_FEM = "results/validation/finger_fem"
#: The gripper's finger FEM cases on the production mesh with the plane X = 0, beside the
#: lone-finger ones (fem.studies.finger_cases' default file names: hex2:3 mixed, ``_plane``), and the
#: validation that judges the production predictor against them (its targets, issue 56).
GRIPPER_SUFFIX, GRIPPER_MESH = "_hex2s3_plane", "hex2:3"
GRIPPER_VALIDATION = "results/validation/finger.json"
JOINT_CASE = {"p": 0.2, "f1": 1.0, "f2": -1.0, "m": 20.0}        # MPa, N, N, N·mm
GRAVITY_GESTURES = [(-0.1, 0.1), (0.1, -0.1)]                     # MPa, the paper's Figure 5A
GRASP = (0.1, 0.2, "circle")                                       # MPa, MPa, object
FINGER_CASE = "gravity_0.1_-0.1"                                   # a fem.studies.finger_cases name
#: Subfolder of the overlays on the committed finger FEM (the live case's overlay of the same
#: gesture, finger_<case>.png, is in the output folder itself).
COMMITTED_FIGURES = "committed"
HEARTBEAT_S = 30.0
#: The discretisation of the committed artefacts the demo compares with (module docstring):
#: fem.mesh.discretisation.PAPER, named without its dolfinx (tests/test_demo.py checks the two).
COMMITTED_MESH_SIZE, COMMITTED_FORMULATION = PAPER_MESH_SIZE, "displacement"

#: results/demo/summary.json: the run's steps and its table rows (docs/formats.md §6.12).
SUMMARY = Format("demo-summary", 1, "apps.demo", {
    "out": str, **each("", float, "total_s", "finger_mesh_size_mm", "load_average_1min"), "units": str,
    "finger?.name": str, "finger?.sha256": str, "committed_fem?": bool,
    **each("steps[]", str, "key", "title", "command"), "steps[].wall_s": float | None,
    **each("rows[]", str, "case", "problem", "fem", "model", "error"), "rows[].errors": dict | None,
    "rows[].tolerance": dict | None, "rows[].within_tolerance": bool | None, "beyond_tolerance": list,
    **each("rows[]", float | None, "fem_s", "model_s"), "rows[].figures": list})


class StepFailed(RuntimeError):
    """A step that did not succeed; the message is the one line the demo prints."""


@dataclass
class Step:
    """One command line: ``python -m module *args``. Its figures are its stdout JSON, or
    the JSON file ``reads`` (relative to the repository) when the tool writes one, loaded
    through that artefact's ``format``."""

    key: str
    title: str
    module: str
    args: list[str]
    reads: str | None = None
    format: Format | None = None
    wall_s: float | None = None
    data: dict = field(default_factory=dict)

    def argv(self) -> list[str]:
        return [sys.executable, "-m", self.module, *self.args]

    def command(self) -> str:
        return shlex.join(["python", "-m", self.module, *self.args])


def _g(v: float) -> str:
    return f"{v:g}"


def gesture_name(p1: float, p2: float) -> str:
    return f"{_g(p1)}_{_g(p2)}"


def build_steps(out: str, finger_mesh_size: float, finger: str | None = None,
                committed_fem: bool = True) -> list[Step]:
    """The demo's steps, in order; ``out`` is the output folder relative to the repository.
    finger: a finger file for every gesture and finger FEM step (None: the paper's);
    committed_fem: whether the committed finger FEM is of that finger (otherwise the step
    that compares with it is left out)."""
    case = [a for k, v in JOINT_CASE.items() for a in (f"--{k}", _g(v))]
    fing = [] if finger is None else ["--finger", finger]
    committed = ["--mesh-size", _g(COMMITTED_MESH_SIZE), "--formulation", COMMITTED_FORMULATION]
    steps = [
        Step("joint_fem", f"joint FEM, the surrogate's data mesh h={_g(COMMITTED_MESH_SIZE)} mm "
             f"{COMMITTED_FORMULATION}, and its render (fem.cli.render)", "fem.cli.render",
             [*case, *committed, "--out", f"{out}/joint.png", "--json"]),
        Step("surrogate", "joint surrogate, same case (surrogate.predict)", "surrogate.predict",
             ["--model", FEM_SURROGATE, *case, "--json"]),
    ]
    # The committed finger FEM cases are one finger alone (no plane X = 0): the predictor is
    # compared with them as one finger alone too (predictor.validation.finger matches the
    # case's plane), and the gripper's gestures (the fingers meet at X = 0) are shown apart.
    if committed_fem:
        steps.append(Step("validate_gravity", "predictor, one finger alone, against the committed finger FEM of "
                          "the paper's gravity gestures (predictor.validation.finger)", "predictor.validation.finger",
                          ["--fem", COMMITTED_FINGER_FEM, "--cases", ",".join(f"gravity_{gesture_name(*p)}"
                                                                              for p in GRAVITY_GESTURES),
                           *committed, "--model", FEM_SURROGATE, *fing, "--out", f"{out}/gravity.json",
                           "--figures", f"{out}/{COMMITTED_FIGURES}",
                           "--json"],
                          reads=f"{out}/gravity.json", format=predictor_artefacts.VALIDATION))
    for p1, p2 in GRAVITY_GESTURES:
        name = gesture_name(p1, p2)
        steps.append(Step(f"gesture_{name}", f"gripper gesture ({_g(p1)}, {_g(p2)}) MPa, the fingers meeting at "
                          "X = 0 (predictor.cli.gesture)",
                          "predictor.cli.gesture", ["--p1", _g(p1), "--p2", _g(p2), *fing, "--json",
                                                "--plot", f"{out}/gesture_{name}.png"]))
    p1, p2, obj = GRASP
    steps.append(Step("grasp", f"grasp of a {obj} at ({_g(p1)}, {_g(p2)}) MPa (predictor.cli.gesture)",
                      "predictor.cli.gesture", ["--p1", _g(p1), "--p2", _g(p2), "--object", obj, *fing, "--json",
                                            "--plot", f"{out}/grasp.png"]))
    h = _g(finger_mesh_size)
    steps.append(Step("finger_fem", f"finger FEM {FINGER_CASE}, joint mesh h={h} mm (fem.studies.finger_cases)",
                      "fem.studies.finger_cases", ["--out", f"{out}/finger_fem", "--cases", FINGER_CASE, "--mesh-size", h,
                                           "--formulation", COMMITTED_FORMULATION, "--no-plane", *fing],
                      reads=f"{out}/finger_fem/{FINGER_CASE}.json", format=fem_artefacts.FINGER_CASE))
    steps.append(Step("validate", "predictor against that finger FEM (predictor.validation.finger)",
                      "predictor.validation.finger", ["--fem", f"{out}/finger_fem", "--mesh-size", h, *fing,
                                                    "--formulation", COMMITTED_FORMULATION, "--model", FEM_SURROGATE,
                                                    "--out", f"{out}/finger.json", "--figures", out, "--json"],
                      reads=f"{out}/finger.json", format=predictor_artefacts.VALIDATION))
    return steps


# ---------------------------------------------------------------- the pure part: rows

def anchor_errors(fem: list, model: list) -> tuple[float, float]:
    """(max, mean) distance between matching anchor points, mm."""
    d = [math.dist(a, b) for a, b in zip(fem, model, strict=True)]
    return max(d), statistics.fmean(d)


def joint_row(fem: dict, sur: dict, sur_wall_s: float) -> dict:
    """The joint FEM (fem.cli.solve JSON) against the surrogate (surrogate.predict JSON, which
    reports no time: its process wall time stands in)."""
    amax, amean = anchor_errors(fem["anchors_mm"], sur["anchors_mm"])
    errors = {"anchor_max_mm": amax, "anchor_mean_mm": amean,
              "phi_end_deg": sur["phi_end_deg"] - fem["phi_end_deg"]}
    if sur.get("cap_rotation_deg") is not None:
        errors["cap_rotation_deg"] = sur["cap_rotation_deg"] - fem["cap_rotation_deg"]
    load = fem["load"]
    text = f"anchors max {amax:.3f}, mean {amean:.3f} mm; phi_end {errors['phi_end_deg']:+.2f} deg"
    if "cap_rotation_deg" in errors:
        text += f"; cap {errors['cap_rotation_deg']:+.2f} deg"
    return {"case": f"joint P={_g(load['P'])} F1={_g(load['F1'])} F2={_g(load['F2'])} M={_g(load['M'])}",
            "problem": "one joint under (P, F1, F2, M)",
            "fem": f"joint FEM, {_g(fem['geometry']['mesh_size'])} mm tetrahedra, "
                   f"{fem.get('formulation') or COMMITTED_FORMULATION} (now)",
            "model": "surrogate (time: process wall)",
            "errors": errors, "error": text, "tolerance": None, "within_tolerance": None,
            "fem_s": fem["wall_time_s"], "model_s": sur_wall_s,
            "produced_by": {"fem": "joint_fem: anchors_mm, phi_end_deg, cap_rotation_deg",
                            "model": "surrogate: anchors_mm, phi_end_deg, cap_rotation_deg",
                            "errors": "model minus FEM; anchors: distance per anchor point",
                            "fem_s": "joint_fem: wall_time_s (the solve)",
                            "model_s": "surrogate: wall time of the whole process (it reports no time)"},
            "figures": ["joint.png"]}


def finger_errors(fem: dict, model_tip: list, model_angle_deg: float) -> dict:
    """Fingertip distance (mm) and tip angle (model minus FEM, deg)."""
    return {"tip_mm": math.dist(model_tip, fem["tip"]), "tip_angle_deg": model_angle_deg - fem["tip_angle_deg"]}


def _tip_text(e: dict) -> str:
    return f"tip {e['tip_mm']:.2f} mm, tip angle {e['tip_angle_deg']:+.2f} deg"


def _predictor_label(d: dict) -> str:
    return f"predictor ({d['kinematics']}/{d['joint_weight']})"


#: The problem each row solves, named in the row (the FEM and the model solve the same one).
LONE_FINGER = "one finger alone (no plane X = 0)"
GRIPPER = "gripper: two mirror fingers meeting at X = 0"


def fem_mesh_label(case: dict) -> str:
    """A finger FEM record's joint discretisation in words: "1.8 mm tetrahedra, displacement"."""
    mesh = fem_artefacts.finger_case_mesh(case)
    kind = mesh if mesh.startswith("hex") else f"{mesh} mm tetrahedra"
    return f"{kind}, {fem_artefacts.finger_case_formulation(case)}"


def judged_entry(validation: dict, case: str) -> dict:
    """The judged variant's entry of ``case`` in a predictor.validation.finger JSON."""
    judged = validation["judged_variant"]
    entry = next((e for e in validation["cases"] if e["case"] == case and e["variant"] == judged), None)
    if entry is None:
        raise ValueError(f"predictor.validation.finger has no {judged} entry for {case}")
    return entry


def tip_tolerance(validation: dict) -> dict:
    """The finger validation's fingertip targets, from its JSON (predictor.validation.finger:
    one finger alone's, issue 14: 2 mm and 1 deg; the gripper's, issue 56: 1 mm and 0.5 deg)."""
    t = validation["targets"]
    return {"tip_mm": t["tip_error_mm"], "tip_angle_deg": t["tip_angle_error_deg"]}


def within(errors: dict | None, tolerance: dict | None) -> bool | None:
    """Every error within its tolerance (absolute values); None where there is none."""
    if errors is None or tolerance is None:
        return None
    return all(abs(errors[k]) <= v for k, v in tolerance.items())


def gravity_row(fem: dict, validation: dict, fem_file: str) -> dict:
    """A gravity gesture of one finger alone: the predictor (predictor.validation.finger JSON,
    its judged variant) against the committed finger FEM of the case, which has no plane."""
    p1, p2 = fem["pressures_MPa"]
    entry = judged_entry(validation, fem["case"])
    errors = finger_errors(fem, entry["tip_mm"], entry["tip_angle_deg"])
    tol = tip_tolerance(validation)
    return {"case": f"gravity ({_g(p1)}, {_g(p2)}) MPa", "problem": LONE_FINGER,
            "fem": f"finger FEM, {fem_mesh_label(fem)} (committed)",
            "model": _predictor_label(entry), "errors": errors, "error": _tip_text(errors),
            "tolerance": tol, "within_tolerance": within(errors, tol),
            "fem_s": fem["fem_s"], "model_s": entry["predictor_s"],
            "produced_by": {"fem": f"{fem_file}: tip, tip_angle_deg (make finger-fem)",
                            "model": f"validate_gravity: {entry['variant']} tip_mm, tip_angle_deg",
                            "errors": "model minus FEM", "tolerance": "validate_gravity: targets",
                            "fem_s": f"{fem_file}: fem_s",
                            "model_s": "validate_gravity: predictor_s (median of its repeats)"},
            "figures": [f"{COMMITTED_FIGURES}/finger_{fem['case']}.png"]}


def gripper_row(g: dict, fem: dict | None = None, fem_file: str = "", tolerance: dict | None = None) -> dict:
    """A gravity gesture of the gripper (predictor.cli.gesture JSON, the default surrogate)
    against the committed finger FEM of the gripper at the same pressures (``fem``, on the
    production mesh with the plane: the same problem, the model's own data mesh) within
    ``tolerance``; without that FEM (not solved yet), its fingertip and the force where the
    fingers meet."""
    p1, p2 = g["pressures_MPa"]
    tip, plane = g["tip"], g.get("plane_force_N")
    meet = "apart" if not plane else f"meet with {plane:.3f} N"
    name = gesture_name(p1, p2)
    row = {"case": f"gripper gravity ({_g(p1)}, {_g(p2)}) MPa", "problem": GRIPPER,
           "fem": "n/a (no FEM of the gripper's gesture)", "model": _predictor_label(g), "errors": None,
           "error": f"n/a; tip ({tip[0]:.2f}, {tip[1]:.2f}) mm, {g['tip_angle_deg']:.2f} deg, fingers {meet}",
           "tolerance": None, "within_tolerance": None, "fem_s": None, "model_s": g["time_ms"] / 1000.0,
           "produced_by": {"error": f"gesture_{name}: tip, tip_angle_deg, plane_force_N",
                           "model_s": f"gesture_{name}: time_ms"},
           "figures": [f"gesture_{name}.png"]}
    if fem is None:
        return row
    errors = finger_errors(fem, tip, g["tip_angle_deg"])
    return {**row, "fem": f"finger FEM, {fem_mesh_label(fem)}, the plane (committed)", "errors": errors,
            "error": _tip_text(errors) + f"; fingers {meet}", "tolerance": tolerance,
            "within_tolerance": within(errors, tolerance), "fem_s": fem["fem_s"],
            "produced_by": {**row["produced_by"], "fem": f"{fem_file}: tip, tip_angle_deg (make finger-grid)",
                            "errors": "model minus FEM", "fem_s": f"{fem_file}: fem_s",
                            **({"tolerance": f"{GRIPPER_VALIDATION}: targets"} if tolerance else {})}}


def grasp_state(g: dict) -> str:
    """The gesture's own state (predictor.cli.gesture --json ``state``) in words."""
    return g["state"].replace("_", " ")


def grasp_row(g: dict) -> dict:
    """A grasp (predictor.cli.gesture --object JSON): no FEM, so the contact figures."""
    p1, p2 = g["pressures_MPa"]
    figures = {"normal_force_N": g["contact_force_N"], "friction_use": g["friction_use"],
               "state": grasp_state(g)}
    return {"case": f"grasp {g['object']} ({_g(p1)}, {_g(p2)}) MPa", "problem": f"{GRIPPER}, holding the object",
            "fem": "n/a", "model": _predictor_label(g), "errors": None, "grasp": figures,
            "error": f"n/a; normal {figures['normal_force_N']:.3f} N, |f|/(mu N) {figures['friction_use']:.3f}, "
                     f"{figures['state']}",
            "tolerance": None, "within_tolerance": None, "fem_s": None, "model_s": g["time_ms"] / 1000.0,
            "produced_by": {"grasp": "grasp: contact_force_N, friction_use, state", "model_s": "grasp: time_ms"},
            "figures": ["grasp.png"]}


def finger_rows(fem: dict, validation: dict, committed: dict, committed_file: str) -> list[dict]:
    """The finger FEM solved now (fem.studies.finger_cases JSON, one finger alone) against the
    predictor (predictor.validation.finger JSON, its judged variant, one finger alone too),
    and the same FEM against the committed FEM of the case (on the committed data's mesh):
    the coarse mesh's own error (no tolerance: it measures the mesh)."""
    h = fem_mesh_label(fem)
    entry = judged_entry(validation, fem["case"])
    p1, p2 = fem["pressures_MPa"]
    pred = finger_errors(fem, entry["tip_mm"], entry["tip_angle_deg"])
    tol = tip_tolerance(validation)
    live = [
        {"case": f"finger gravity ({_g(p1)}, {_g(p2)}) MPa", "problem": LONE_FINGER, "fem": f"finger FEM, {h} (now)",
         "model": _predictor_label(entry), "errors": pred, "error": _tip_text(pred),
         "tolerance": tol, "within_tolerance": within(pred, tol),
         "fem_s": fem["fem_s"], "model_s": entry["predictor_s"],
         "produced_by": {"fem": "finger_fem: tip, tip_angle_deg",
                         "model": f"validate: {entry['variant']} tip_mm, tip_angle_deg",
                         "errors": "model minus FEM", "tolerance": "validate: targets",
                         "fem_s": "finger_fem: fem_s (the solve, not the mesh build)",
                         "model_s": "validate: predictor_s (median of its repeats)"},
         "figures": [f"finger_{fem['case']}.png", f"finger_fem/{fem['case']}.png"]}]
    if committed is None:   # no committed FEM of this finger
        return live
    h0, mesh = fem_mesh_label(committed), finger_errors(committed, fem["tip"], fem["tip_angle_deg"])
    return live + [
        {"case": f"finger FEM {fem_artefacts.finger_case_mesh(fem)} vs {fem_artefacts.finger_case_mesh(committed)} "
                 "mm mesh", "problem": LONE_FINGER, "fem": f"finger FEM, {h0} (committed)",
         "model": f"finger FEM, {h} (now)", "errors": mesh, "error": _tip_text(mesh),
         "tolerance": None, "within_tolerance": None,
         "fem_s": committed["fem_s"], "model_s": fem["fem_s"],
         "produced_by": {"fem": f"{committed_file}: tip, tip_angle_deg", "model": "finger_fem: tip, tip_angle_deg",
                         "errors": "the coarse mesh minus the committed one", "fem_s": f"{committed_file}: fem_s",
                         "model_s": "finger_fem: fem_s"},
         "figures": []},
    ]


def table_rows(data: dict) -> list[dict]:
    """Every row of the demo's table from the steps' JSON: ``data`` holds
    joint {fem, surrogate, surrogate_wall_s}, gravity [{fem, fem_file}, ...] with
    gravity_validation (the lone finger's predictor.validation.finger JSON), gripper
    [gesture, ...] with gripper_fem {gesture name: (FEM case, its file)} where the gripper's
    FEM is committed and gripper_tolerance, grasp, finger {fem, validation, committed,
    committed_file}; without a committed FEM of the finger, no gravity and finger.committed None."""
    j, f = data["joint"], data["finger"]
    return [joint_row(j["fem"], j["surrogate"], j["surrogate_wall_s"]),
            *(gravity_row(g["fem"], data["gravity_validation"], g["fem_file"]) for g in data.get("gravity", [])),
            *(gripper_row(g, *data.get("gripper_fem", {}).get(gesture_name(*g["pressures_MPa"]), (None, "")),
                          data.get("gripper_tolerance")) for g in data["gripper"]),
            grasp_row(data["grasp"]),
            *finger_rows(f["fem"], f["validation"], f["committed"], f["committed_file"])]


def beyond_tolerance(rows: list[dict]) -> list[str]:
    """The cases whose errors exceed their tolerance (flagged in the table and the summary)."""
    return [r["case"] for r in rows if r.get("within_tolerance") is False]


COLUMNS = [("case", "case"), ("problem", "problem"), ("fem", "FEM"), ("model", "model"),
           ("error", "error (model - FEM)"), ("within_tolerance", "within tolerance"),
           ("fem_s", "FEM s"), ("model_s", "model s")]


def _cell(row: dict, key: str) -> str:
    v = row[key]
    if key in ("fem_s", "model_s"):
        return "n/a" if v is None else f"{v:.1f}" if v >= 1 else f"{v:.3f}"
    if key == "within_tolerance":
        if v is None:
            return "-"
        tol = ", ".join(f"{t:g} {'mm' if k.endswith('_mm') else 'deg'}" for k, t in row["tolerance"].items())
        return f"yes (<= {tol})" if v else f"NO: beyond {tol}"
    return str(v)


def text_table(rows: list[dict]) -> str:
    cells = [[head for _, head in COLUMNS]] + [[_cell(r, k) for k, _ in COLUMNS] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(COLUMNS))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


LEGEND = ("errors: model minus FEM (mm, deg), the two solving the problem named in the row; within tolerance: "
          "the targets of the finger validation of the row's problem (its JSON: one finger alone, issue 14's; the "
          "gripper, issue 56's), '-' where a row has none; FEM s: the FEM's solve "
          "time from its JSON; model s: the model's solve time from its JSON, except the surrogate's (it reports "
          "none: its process wall time, start-up included)")


def markdown(rows: list[dict], steps: list[dict], total_s: float) -> str:
    head = [h for _, h in COLUMNS] + ["figures"]
    out = ["# softjoint demo", "",
           f"`make demo` (python -m apps.demo), {total_s:.0f} s in all. {LEGEND}.", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        links = ", ".join(f"[{Path(p).name}]({p})" for p in r["figures"]) or "-"
        cells = [_cell(r, k).replace("|", "\\|") for k, _ in COLUMNS]   # a bare | would split the cell
        out.append("| " + " | ".join(cells + [links]) + " |")
    beyond = beyond_tolerance(rows)
    out += ["", f"**Beyond tolerance: {'; '.join(beyond)}.**" if beyond else
            "Every row with a tolerance is within it."]
    out += ["", "## Steps", "", "| step | command | wall s |", "|---|---|---|"]
    out += [f"| {s['title']} | `{s['command']}` | {s['wall_s']:.1f} |" for s in steps]
    out += ["", "## Figures", ""]
    for r in rows:
        out += [f"![{r['case']}: {Path(p).name}]({p})" for p in r["figures"]]
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------- running the steps

def _brief(step: Step) -> str:
    """The one-line result of a step."""
    d = step.data
    if step.key == "joint_fem":
        return (f"phi_end {d['phi_end_deg']:.2f} deg, cap {d['cap_rotation_deg']:.2f} deg, "
                f"solve {d['wall_time_s']:.0f} s")
    if step.key == "surrogate":
        return f"phi_end {d['phi_end_deg']:.2f} deg"
    if step.key.startswith("gesture_") or step.key == "grasp":
        tip = d["tip"]
        text = f"tip ({tip[0]:.2f}, {tip[1]:.2f}) mm, {d['tip_angle_deg']:.2f} deg, {d['time_ms']:.0f} ms"
        return text + (f", {grasp_state(d)} with {d['contact_force_N']:.3f} N" if step.key == "grasp" else "")
    if step.key == "finger_fem":
        tip = d["tip"]
        return f"tip ({tip[0]:.2f}, {tip[1]:.2f}) mm, {d['tip_angle_deg']:.2f} deg, solve {d['fem_s']:.0f} s"
    s = d["summary"][d["judged_variant"]]
    return (f"{d['judged_variant']}: tip error {s['tip_error_mm_max']:.2f} mm, "
            f"angle {s['tip_angle_error_deg_max']:.2f} deg")


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else "no message"


def run_step(step: Step, k: int, n: int, t0: float, env: dict, log=sys.stdout) -> None:
    """Run one step (heartbeat every HEARTBEAT_S on ``log``), then read its JSON into step.data."""
    tag = f"[demo {k}/{n}]"
    print(f"{tag} {step.title} ... ({time.perf_counter() - t0:.0f} s)", file=log, flush=True)
    print(f"{' ' * len(tag)} $ {step.command()}", file=log, flush=True)
    start = time.perf_counter()
    proc = subprocess.Popen(step.argv(), cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        while True:
            try:
                stdout, stderr = proc.communicate(timeout=HEARTBEAT_S)
                break
            except subprocess.TimeoutExpired:
                print(f"{tag} still running ({time.perf_counter() - t0:.0f} s)", file=log, flush=True)
    finally:
        if proc.poll() is None:   # interrupted: do not leave a FEM running on its own
            proc.kill()
            proc.wait()
    step.wall_s = time.perf_counter() - start
    name = f"step {k}/{n} ({step.title})"
    if proc.returncode != 0:
        raise StepFailed(f"{name} failed with exit {proc.returncode}: {_last_line(stderr)}")
    try:
        step.data = step.format.load(Path(ROOT, step.reads)) if step.format else json.loads(
            Path(ROOT, step.reads).read_text() if step.reads else stdout)
    except (OSError, ValueError) as exc:
        raise StepFailed(f"{name} gave no JSON figures: {' '.join(str(exc).split())}") from None
    if step.data.get("converged") is False:
        raise StepFailed(f"{name} did not converge: {step.data.get('reason') or 'no reason given'}")
    try:
        brief = _brief(step)
    except (KeyError, TypeError, IndexError) as exc:
        raise StepFailed(f"{name} JSON lacks {exc}") from None
    print(f"{tag} -> {brief} [{step.wall_s:.0f} s]", file=log, flush=True)


def load_committed(name: str) -> tuple[dict, str]:
    """A committed whole-finger FEM case on the committed data's discretisation
    (COMMITTED_MESH_SIZE, COMMITTED_FORMULATION): (JSON, its path)."""
    rel = f"{COMMITTED_FINGER_FEM}/{name}.json"
    try:
        case = fem_artefacts.FINGER_CASE.load(Path(ROOT, rel))
    except OSError:
        raise StepFailed(f"committed finger FEM {rel} missing or unreadable: run `make finger-fem`") from None
    except ValueError as exc:
        raise StepFailed(f"{exc}: run `make finger-fem`") from None
    wanted = (_g(COMMITTED_MESH_SIZE), COMMITTED_FORMULATION)
    found = (fem_artefacts.finger_case_mesh(case), fem_artefacts.finger_case_formulation(case))
    if not case["converged"] or found != wanted:
        raise StepFailed(f"committed finger FEM {rel} is not a converged case on the mesh h={wanted[0]} mm "
                         f"({wanted[1]}), the surrogate's data (it is on {found[0]}, {found[1]}): run "
                         "`make finger-fem`")
    return case, rel


def load_gripper_fem(name: str) -> tuple[dict, str] | None:
    """The committed finger FEM of the gripper (production mesh, the plane) of case
    ``name``: (JSON, its path), None where it is not solved yet (make finger-grid)."""
    rel = f"{COMMITTED_FINGER_FEM}/{name}{GRIPPER_SUFFIX}.json"
    if not Path(ROOT, rel).is_file():
        return None
    try:
        case = fem_artefacts.FINGER_CASE.load(Path(ROOT, rel))
    except (OSError, ValueError) as exc:
        raise StepFailed(f"{rel}: {exc}") from None
    if not (case["converged"] and case.get("settings", {}).get("plane") and
            fem_artefacts.finger_case_mesh(case) == GRIPPER_MESH):
        raise StepFailed(f"{rel} is not a converged case of the gripper (the plane X = 0) on {GRIPPER_MESH}")
    return case, rel


def gripper_tolerance() -> dict | None:
    """The targets of the production finger validation (GRIPPER_VALIDATION), None without it."""
    try:
        return tip_tolerance(predictor_artefacts.VALIDATION.load(Path(ROOT, GRIPPER_VALIDATION)))
    except OSError:
        return None


def _relative(path: Path) -> str:
    """``path`` relative to the repository (the steps run there), else absolute."""
    path = path.resolve()
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def committed_finger(finger: FingerSpec) -> bool:
    """Whether the committed finger FEM cases were solved for ``finger`` (their settings
    record it: contract.finger.same_finger)."""
    try:
        case = json.loads(Path(ROOT, COMMITTED_FINGER_FEM, f"{FINGER_CASE}.json").read_text())
    except (OSError, ValueError):
        return False
    return same_finger(case.get("settings", {}).get("geometry", {}).get("finger", {}), finger)


def run(out: Path, finger_mesh_size: float, as_json: bool = False, finger: str | None = None) -> int:
    """Every step, then the summary files and the table (or, ``as_json``, the summary as
    JSON on stdout and the progress on stderr). 0 if every step succeeded, else 1.
    finger: a finger file (None: the paper's); the rows against the committed finger FEM
    are made only when it is of that finger."""
    t0 = time.perf_counter()
    log = sys.stderr if as_json else sys.stdout
    rel = _relative(out)
    spec = load_finger(finger)
    compare = committed_finger(spec)
    steps = build_steps(rel, finger_mesh_size, None if finger is None else _relative(Path(finger)), compare)
    by_key = {s.key: s for s in steps}
    env = dict(os.environ)
    # One thread per process: the demo shares the machine, and the FEM is serial here.
    for var, value in (("OMP_NUM_THREADS", "1"), ("OPENBLAS_NUM_THREADS", "1"), ("PYVISTA_OFF_SCREEN", "true")):
        env.setdefault(var, value)
    try:
        # Checked first: the committed FEM the gravity rows compare with.
        if not compare:
            print(f"[demo] no committed finger FEM of finger {spec.name!r}: its rows against it are left out",
                  file=log, flush=True)
        committed = {gesture_name(*p): load_committed(f"gravity_{gesture_name(*p)}")
                     for p in GRAVITY_GESTURES} if compare else {}
        finger_committed = load_committed(FINGER_CASE) if compare else (None, None)
        gripper_fem = {name: found for name in (gesture_name(*p) for p in GRAVITY_GESTURES)
                       if compare and (found := load_gripper_fem(f"gravity_{name}"))}
        for model in (SURROGATE, FEM_SURROGATE):
            if not Path(ROOT, model).is_file():
                raise StepFailed(f"no committed surrogate {model}: run `make train` (docs/decisions.md §9 for the "
                                 "1.8 mm reference's)")
        # No stale summary may describe this run's figures; and fem.studies.finger_cases skips a case
        # whose JSON exists, so the live finger FEM removes its own last result first.
        for old in (out / "summary.json", out / "summary.md", out / "finger_fem" / f"{FINGER_CASE}.json"):
            old.unlink(missing_ok=True)
        for k, step in enumerate(steps, 1):
            run_step(step, k, len(steps), t0, env, log)
        rows = table_rows({
            "joint": {"fem": by_key["joint_fem"].data, "surrogate": by_key["surrogate"].data,
                      "surrogate_wall_s": by_key["surrogate"].wall_s},
            "gravity": [{"fem": committed[gesture_name(*p)][0], "fem_file": committed[gesture_name(*p)][1]}
                        for p in GRAVITY_GESTURES] if compare else [],
            "gravity_validation": by_key["validate_gravity"].data if compare else None,
            "gripper": [by_key[f"gesture_{gesture_name(*p)}"].data for p in GRAVITY_GESTURES],
            "gripper_fem": gripper_fem, "gripper_tolerance": gripper_tolerance(),
            "grasp": by_key["grasp"].data,
            "finger": {"fem": by_key["finger_fem"].data, "validation": by_key["validate"].data,
                       "committed": finger_committed[0], "committed_file": finger_committed[1]}})
    except StepFailed as exc:
        print(f"[demo] FAILED: {exc}", file=sys.stderr, flush=True)
        return 1
    except (KeyError, TypeError, ValueError) as exc:
        print(f"[demo] FAILED: building the table: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
        return 1
    total = time.perf_counter() - t0
    step_log = [{"key": s.key, "title": s.title, "command": s.command(), "wall_s": s.wall_s} for s in steps]
    beyond = beyond_tolerance(rows)
    summary = {"out": rel, "total_s": total, "finger_mesh_size_mm": finger_mesh_size,
               "finger": {"name": spec.name, "sha256": spec.digest}, "committed_fem": compare,
               "load_average_1min": os.getloadavg()[0], "units": "mm, deg, N, MPa, s",
               "rows": rows, "beyond_tolerance": beyond, "steps": step_log}
    SUMMARY.write(out / "summary.json", summary)
    write_text(out / "summary.md", markdown(rows, step_log, total))
    if as_json:
        cli.print_json(summary)
    else:
        print(f"\n{text_table(rows)}\n{LEGEND}\n", flush=True)
    print(f"[demo] all {len(steps)} steps done in {total:.0f} s: {rel}/summary.md, summary.json and the PNGs",
          file=log, flush=True)
    if beyond:   # the run is complete, its table true: the flag is for the reader
        print(f"[demo] beyond tolerance: {'; '.join(beyond)}", file=sys.stderr, flush=True)
    return 0


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m apps.demo", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", folder=True, default="results/demo", help="output folder (default results/demo)")
    ap.add_argument("--finger-mesh-size", type=cli.number(0.3, 10, "mm"), default=4.0,
                    help="joint mesh size of the live finger FEM, mm (default 4: coarse, for time)")
    ap.add_argument("--finger", type=_finger_file, default=None,
                    help="finger file of every gesture and finger FEM (default the paper's, "
                    "contract/fingers/paper.toml); the rows against the committed finger FEM need the paper's")
    args = ap.parse_args(argv)
    return run(Path(args.out), args.finger_mesh_size, args.json, args.finger)


def _finger_file(text: str) -> str:
    """--finger: a finger file of two joints (the demo's gestures are pressure pairs),
    read and checked while parsing (contract.finger.finger_arg); its path is passed on."""
    spec = finger_arg(text)
    if spec.n_joints != 2:
        raise argparse.ArgumentTypeError(f"finger {spec.name!r} has {spec.n_joints} joints: the demo's gestures "
                                         "are pressure pairs, for a finger of two joints")
    return text


if __name__ == "__main__":
    sys.exit(main())
