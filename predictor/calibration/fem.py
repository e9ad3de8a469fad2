"""Calibrating the predictor to the whole-finger FEM of a deliberately different finger
(issue 38 §3(b); docs/calibration.md §9).

The truth is a finger file (``TRUTH_FINGER``: the paper's finger with joints of E x 1.15,
a tip part 20 % heavier and the mount turned by 2 deg) solved by the whole-finger FEM
(fem.studies.finger_cases) at gravity pressure pairs ``PRESSURES`` (``make calibration-fem``).
The model is what a user starts from: the paper's finger file and the committed surrogate
(predictor.calibration.model.CalibrationModel).

Observations, per FEM case (global frame of the right finger, mm, deg): the fingertip
(x, y), the tip angle, and both ends of every rigid part between two joints (for the
paper's finger the link, part 2 at s = 0 and 60 mm: the FEM's last anchor of the joint
before it and the proximal centre of the joint after it), with the stated uncertainties
``SIGMA_MM``, ``SIGMA_DEG``: the predictor's own error against the paper finger's FEM
(results/validation/finger_h1.8.json: fingertip 0.22 mm mean, 0.46 mm max; tip angle 0.19 deg
max), so the fit is not asked to reproduce the FEM closer than the model can.

What was measured: a case solved with the mirror finger's contact at X = 0
(fem.studies.finger_cases ``--plane``, its settings ``"plane": true``) is the gripper, every
other case (the committed ones among them) a lone finger; the observations say so
(predictor.calibration.observations ``problem``: ``case_problem``), so a lone finger is fitted and
predicted alone, and cases of both kinds together are refused.

Split and fit: the cases at ``CALIBRATE_ON`` (four pairs spread over the box) are
calibrated on, the others held out. Fitted (``FIT``): each joint's stiffness scale s_i (a
material stiffer or softer than its datasheet), the tip part's weight (N) and the mount's
turn (deg) -- what a user suspects of a printed gripper. Not the regulators' gain and
offset (the FEM applies the pressure exactly) nor the camera frame (the FEM reports in the
gripper's frame).

Held-out: each held-out case's fingertip error e = |tip_pred - tip_FEM| (mm) by the model
at its nominal parameters (uncalibrated) and at the fitted ones (calibrated); the figures
are their mean and max. ``known_changes`` reads what the truth file changed (weights, mount
turn, and the stiffness ratio E_truth/E_model of joints of one law and Poisson ratio), so
the fitted values are shown beside it.

Data flow: case JSONs -> ``load_cases`` (FemCaseError, one line: missing, not converged,
foreign, several meshes) -> ``case_observation`` -> Observations -> ``fem_study`` ->
FemStudy (the record of calibration.json, and the held-out poses for
predictor.calibration.plot).
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from contract.finger import FingerSpec, same_finger
from fem.artefacts import FINGER_CASE
from predictor.calibration.model import CalibrationModel, design, equilibrium, predict
from predictor.calibration.fit import CalibrationResult, FitFailed, calibrate
from predictor.defaults import ROOT
from predictor.calibration.observations import FINGER, GRIPPER, Marker, Observation, Observations

TRUTH_FINGER = ROOT / "results" / "calibration" / "truth" / "finger.toml"
#: Gravity pressure pairs (P1, P2) MPa of the FEM cases, inside |P| <= 0.2 MPa (chosen when
#: three validation cases at 0.25-0.3 MPa did not converge; docs/decisions.md §6); the Makefile's
#: CAL_PRESSURES spells the same list for fem.studies.finger_cases (tests check they agree).
PRESSURES = ((0.2, 0.2), (-0.2, 0.15), (0.15, -0.2), (-0.15, -0.15),
             (0.0, 0.0), (0.1, 0.05), (-0.1, 0.2), (0.05, -0.1))
#: The four calibrated on: one near each corner of the box.
CALIBRATE_ON = PRESSURES[:4]
FIT = ("stiffness", "weight_4", "mount_deg")
WHY_FIT = ("each joint's stiffness scale (its material), the tip part's weight and the mount's turn: what a "
           "user suspects of a printed gripper; not the regulators' gain and offset (the FEM applies the "
           "pressure exactly) nor the camera frame (the FEM reports in the gripper's frame)")
SIGMA_MM = 0.3    # mm: a point's stated uncertainty (the predictor's error against the FEM)
SIGMA_DEG = 0.2   # deg: the tip angle's
TARGETS = {"improvement_at_least": 5.0, "calibrated_tip_error_mm_at_most": 1.0}


class FemCaseError(ValueError):
    """FEM cases that cannot be calibrated on (one line: which file and why)."""


def pairs_arg(text: str) -> tuple[tuple[float, float], ...]:
    """"P1,P2;P1,P2;..." (MPa) -> pressure pairs; ValueError (one line) if malformed."""
    out = []
    for item in text.split(";"):
        try:
            p1, p2 = (float(v) for v in item.split(","))
        except ValueError:
            raise ValueError(f"{text!r}: expected pressure pairs 'P1,P2;P1,P2;...' (MPa)") from None
        if not (math.isfinite(p1) and math.isfinite(p2)):
            raise ValueError(f"{text!r}: pressures must be finite numbers (MPa)")
        out.append((p1, p2))
    return tuple(out)


@dataclass(frozen=True)
class FemCase:
    """One converged FEM case: its record (fem.studies.finger_cases JSON), file and sha256."""

    record: dict
    path: Path
    sha256: str

    @property
    def pressures(self) -> tuple[float, ...]:
        return tuple(self.record["pressures_MPa"])

    @property
    def mesh(self) -> str:
        """The joints' mesh in words ("1.8", "hex2", ...; older records: the size)."""
        m = self.record["mesh"]
        return m.get("mesh") or f"{m['mesh_size']:g}"


def _read_case(path: Path) -> FemCase:
    text = path.read_bytes()
    try:
        record = FINGER_CASE.check(json.loads(text), str(path))
    except (ValueError, UnicodeDecodeError) as exc:
        raise FemCaseError(f"{path}: not a case of fem.studies.finger_cases ({' '.join(str(exc).split())})") from None
    return FemCase(record, path, hashlib.sha256(text).hexdigest())


def load_cases(folder: str | Path, truth: FingerSpec, pressures=PRESSURES) -> list[FemCase]:
    """The FEM case of every pair of ``pressures`` (gravity on) in ``folder``, in that
    order. FemCaseError (one line) when a pair has no case, a case did not converge, was
    solved for another finger than ``truth``, or the cases are on several meshes."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FemCaseError(f"{folder}: no such folder of FEM cases (run `make calibration-fem`)")
    found = {}
    for path in sorted(folder.glob("*.json")):
        case = _read_case(path)
        if not case.record["gravity"]:
            continue
        finger = case.record.get("settings", {}).get("geometry", {}).get("finger", {})
        if not same_finger(finger, truth):
            raise FemCaseError(f"{path}: solved for finger {finger.get('name')!r}, not {truth.name!r} "
                               f"({truth.digest[:12]}): a foreign case")
        found.setdefault(tuple(round(p, 9) for p in case.pressures), []).append(case)
    cases = []
    for pair in pressures:
        here = found.get(tuple(round(p, 9) for p in pair), [])
        if not here:
            raise FemCaseError(f"{folder}: no FEM case at P = ({pair[0]:g}, {pair[1]:g}) MPa with gravity "
                               f"(run `make calibration-fem`)")
        if len(here) > 1:
            raise FemCaseError(f"{folder}: {len(here)} cases at P = ({pair[0]:g}, {pair[1]:g}) MPa "
                               f"({', '.join(c.path.name for c in here)}): keep one mesh per folder")
        if not here[0].record["converged"]:
            raise FemCaseError(f"{here[0].path}: the FEM did not converge ({here[0].record.get('reason') or 'no reason'})")
        cases.append(here[0])
    meshes = sorted({c.mesh for c in cases})
    if len(meshes) > 1:
        raise FemCaseError(f"{folder}: cases on several meshes ({', '.join(meshes)}): keep one mesh per folder")
    return cases


def check_same_chain(model: FingerSpec, truth: FingerSpec) -> None:
    """ValueError (one line) unless both fingers have the same parts' kinds and lengths
    (the observations are placed on the model's parts)."""
    shape = lambda f: [(p.kind, p.length) for p in f.parts]   # noqa: E731
    if shape(model) != shape(truth):
        raise ValueError(f"finger {model.name!r} and the FEM's {truth.name!r} differ in their parts' kinds or "
                         "lengths: the calibration places the FEM's points on the model's parts")


def link_points(finger: FingerSpec) -> list[tuple[int, float, str]]:
    """(part k 0-based, s mm, where) of the FEM points at both ends of every rigid part
    between two joints: s = 0 is the last anchor of joint part k-1 (``anchor``), s = its
    length the proximal centre of joint part k+1 (``proximal``)."""
    out, parts = [], finger.parts
    for k, part in enumerate(parts[:-1]):
        if part.kind != "rigid":
            continue
        if k > 0 and parts[k - 1].kind == "joint":
            out.append((k, 0.0, "anchor"))
        if parts[k + 1].kind == "joint":
            out.append((k, part.length, "proximal"))
    return out


def case_observation(case: FemCase, finger: FingerSpec, sigma_mm: float = SIGMA_MM,
                     sigma_deg: float = SIGMA_DEG) -> Observation:
    """The Observation of one FEM case (module docstring) on ``finger``'s parts."""
    r = case.record
    joints = r["joints"]
    markers = []
    for k, s, where in link_points(finger):
        j = finger.joints.index(k - 1 if where == "anchor" else k + 1)
        x, y = joints[j]["anchors_mm"][-1] if where == "anchor" else joints[j]["proximal_mm"]
        markers.append(Marker(k, s, float(x), float(y), sigma_mm))
    p = case.pressures
    return Observation(p, True, None, (float(r["tip"][0]), float(r["tip"][1]), sigma_mm),
                       (float(r["tip_angle_deg"]), sigma_deg), tuple(markers),
                       r.get("case") or f"P=({p[0]:g}, {p[1]:g})")


def case_problem(case: FemCase) -> str:
    """GRIPPER for a case solved with the plane X = 0 (its settings ``"plane": true``),
    else FINGER (a lone finger: every case solved without it, which records no such key)."""
    return GRIPPER if (case.record.get("settings") or {}).get("plane") else FINGER


def known_changes(truth: FingerSpec, model: FingerSpec) -> dict:
    """The parameters (predictor.calibration.model names) the truth file changes against the
    model's finger, with their true values: weights that differ, the mount's turn (deg),
    and per joint the stiffness ratio of its modulus (one law and Poisson ratio only)."""
    out = {}
    for k, (a, b) in enumerate(zip(truth.parts, model.parts), 1):
        if a.weight != b.weight:
            out[f"weight_{k}"] = a.weight
    turn = math.degrees(truth.base_angle - model.base_angle)
    if abs(turn) > 1e-12:
        out["mount_deg"] = turn
    for i, (ka, kb) in enumerate(zip(truth.joints, model.joints), 1):
        ma, mb = truth.parts[ka].spec.material, model.parts[kb].spec.material
        if (ma.law, ma.nu, len(ma.parameters)) == (mb.law, mb.nu, 1) and ma.parameters[0] != mb.parameters[0]:
            out[f"stiffness_J{i}"] = ma.parameters[0] / mb.parameters[0]
    return out


@dataclass
class Prediction:
    """Predicted gestures of some observations at one theta: tips (B, 2) mm, tip angles
    (B,) deg and every part's polyline [(B, n, 2)] in the measurement frame."""

    tips: np.ndarray
    tip_angle_deg: np.ndarray
    polylines: list


def predict_gestures(model: CalibrationModel, obs: Observations, theta: torch.Tensor) -> Prediction:
    """The model's gestures of ``obs`` at parameters theta (n,); ValueError if one does not
    converge."""
    d = design(obs, model.finger)
    th = theta[None].repeat(len(obs), 1)
    x, ok = equilibrium(model, d, th)
    if not bool(ok.all()):
        bad = [obs.items[i].name for i in range(len(obs)) if not bool(ok[i])]
        raise ValueError(f"the predictor has no converged gesture at {', '.join(bad)}")
    with torch.no_grad():
        m = predict(model, d, x, th).numpy()
        pose = model.pose(x, th, d.pressures)
        lines = [model.to_frame(poly, th).numpy() for _, poly in pose.part_polylines()]
    tips = np.array([[m[a], m[b]] for a, b in d.tip_rows])
    return Prediction(tips, _tip_angles(d, m), lines)


def _tip_angles(d, m: np.ndarray) -> np.ndarray:
    """The predicted tip angle (deg) of each observation: its design's ``deg`` row."""
    rows = {b: j for j, (b, w) in enumerate(zip(d.obs.tolist(), d.what)) if w[0] == "deg"}
    return np.array([m[rows[b]] for b in range(len(d.tip_rows))])


def _stats(v: np.ndarray) -> dict:
    return {"mean": float(np.mean(v)), "max": float(np.max(v))}


@dataclass
class FemStudy:
    """The study's record (calibration.json without the recovery), the fit, and the
    held-out observations with their uncalibrated and calibrated predictions."""

    record: dict
    result: CalibrationResult
    heldout: Observations
    before: Prediction
    after: Prediction


def fem_study(model: CalibrationModel, cases: list[FemCase], truth: FingerSpec, calibrate_on=CALIBRATE_ON,
              fit=FIT, starts: int = 3, sigma_mm: float = SIGMA_MM, sigma_deg: float = SIGMA_DEG) -> FemStudy:
    """Calibrate ``model`` on the cases at ``calibrate_on`` and predict the others
    (module docstring). ValueError (one line) for a split that leaves nothing out or
    names a pair without a case; FitFailed when no start converges or the calibrated
    predictor cannot solve a held-out case. The record's ``fit.trusted`` is the fit's
    verdict (predictor.calibration.fit.judge); the caller refuses an untrusted one."""
    check_same_chain(model.finger, truth)
    problems = {case_problem(c) for c in cases}
    if len(problems) > 1:
        raise ValueError("the FEM cases mix lone fingers and gripper cases (fem.studies.finger_cases --plane): "
                         "calibrate on one kind")
    obs = Observations(tuple(case_observation(c, model.finger, sigma_mm, sigma_deg) for c in cases),
                       problem=problems.pop())
    key = lambda p: tuple(round(v, 9) for v in p)   # noqa: E731
    on = {key(p) for p in calibrate_on}
    fit_idx = [i for i, c in enumerate(cases) if key(c.pressures) in on]
    held_idx = [i for i, c in enumerate(cases) if key(c.pressures) not in on]
    if len(fit_idx) != len(on) or not held_idx:
        raise ValueError(f"--calibrate-on: {len(on)} pairs, {len(fit_idx)} of them among the FEM cases and "
                         f"{len(held_idx)} left to hold out: name pairs of the cases and leave some out")
    res = calibrate(model, obs.subset(fit_idx), fit, starts=starts, loo=False)
    heldout = obs.subset(held_idx)
    before = predict_gestures(model, heldout, model.nominal)
    try:
        after = predict_gestures(model, heldout, res.theta)
    except ValueError as exc:   # the fit's answer, not the input, is at fault: exit 1, not 2
        why = f" (not trusted: {'; '.join(res.why)})" if res.why else ""
        raise FitFailed(f"calibrated, {exc}{why}") from None
    measured = np.array([o.tip[:2] for o in heldout.items])
    angle = np.array([o.tip_angle[0] for o in heldout.items])
    e0, e1 = (np.linalg.norm(p.tips - measured, axis=1) for p in (before, after))
    changes = known_changes(truth, model.finger)
    record = {
        "truth_finger": truth.summary(), "model_finger": model.finger.summary(), "joint_model": model.joint.name,
        "kinematics": model.params.kinematics, "joint_weight": model.params.joint_weight, "problem": obs.problem,
        "fem": {"mesh": cases[0].mesh, "nodes": cases[0].record["mesh"]["nodes"],
                "cases": [{"case": c.record["case"], "file": c.path.name, "sha256": c.sha256,
                           "pressures_MPa": list(c.pressures), "fem_s": c.record["fem_s"],
                           "role": "calibrate" if i in fit_idx else "heldout"} for i, c in enumerate(cases)]},
        "observations": {"per_case": ["tip (x, y)", "tip angle"] + [
            f"part {k + 1} at s = {s:g} mm (FEM: {where})" for k, s, where in link_points(model.finger)],
            "sigma_mm": sigma_mm, "sigma_deg": sigma_deg},
        "fit": {"parameters": res.names, "why": WHY_FIT, "starts": starts, "trusted": res.trusted,
                "untrusted_because": res.why, "reduced_chi2": res.reduced_chi2, "dof": res.dof},
        "parameters": {n: {"value": float(v), "std": float(s), "nominal": float(model.nominal[model.index[n]]),
                           "true": changes.get(n, float(model.nominal[model.index[n]])),
                           "identifiable": n not in res.unidentifiable}
                       for n, v, s in zip(res.names, res.values, res.std)},
        "observations_used": len(fit_idx), "heldout_observations": len(held_idx),
        "calibrate_on_MPa": [list(cases[i].pressures) for i in fit_idx],
        "heldout_MPa": [list(cases[i].pressures) for i in held_idx],
        "heldout_tip_error_uncalibrated_mm": _stats(e0), "heldout_tip_error_calibrated_mm": _stats(e1),
        "heldout_tip_angle_error_uncalibrated_deg": _stats(np.abs(before.tip_angle_deg - angle)),
        "heldout_tip_angle_error_calibrated_deg": _stats(np.abs(after.tip_angle_deg - angle)),
        "improvement": float(np.mean(e0) / np.mean(e1)),
        "rms_before_mm": res.rms_before_mm, "rms_after_mm": res.rms_after_mm,
        "heldout": [{"case": o.name, "pressures_MPa": list(o.pressures), "fem_tip_mm": list(o.tip[:2]),
                     "uncalibrated_tip_mm": before.tips[b].tolist(), "calibrated_tip_mm": after.tips[b].tolist(),
                     "uncalibrated_error_mm": float(e0[b]), "calibrated_error_mm": float(e1[b])}
                    for b, o in enumerate(heldout.items)],
        "time_s": res.time_s, "targets": TARGETS}
    return FemStudy(record, res, heldout, before, after)


def recovery_summary(recovery: dict) -> dict:
    """The recovery study's figures (results/calibration/recovery.json) that
    calibration.json carries: per parameter true, fitted (noise-free), its 95 % interval
    and the noisy seeds' coverage; the overall coverage and the 8-observation time."""
    nf, cover = recovery["noise_free"], recovery["noisy"]["coverage_95_per_parameter"]
    return {"parameters": {p["name"]: {"true": p["true"], "fitted": p["fitted"], "interval_95": p["interval_95"],
                                       "identifiable": p["identifiable"], "coverage_95": cover.get(p["name"])}
                           for p in nf["parameters"]},
            "all_identifiable_within_2pct": nf["all_identifiable_within_2pct"],
            "coverage_95": recovery["noisy"]["coverage_95"], "seeds": recovery["seeds"],
            "time_s_8_observations": nf["time_s"], "targets": recovery["targets"]}


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.calibrate fem")
