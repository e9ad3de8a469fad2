"""The calibration (predictor.calibration.model, calibration_fit, calibration_file, observations,
the predictor.cli.calibrate CLI) on the analytic joint: its residual against the statics', the
stiffness similarity against a stiffer analytic beam, its equilibrium against the solver,
the fit's Jacobian against finite differences, exact recovery of a known truth, the
detection of an exact degeneracy, bad measurement files (exit 2, one line, nothing
written) and the calibrated finger file read back by predictor.cli.gesture.
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

from contract.finger import FingerFileError, load_finger, parse_finger
from predictor.cli.calibrate import main as calibrate_main
from predictor.calibration.model import CalibrationModel, ScaledJoint, design, equilibrium, predict
from predictor.calibration.fit import Prior, Problem, calibrate
from predictor.calibration.recovery import synthetic_observations
from predictor.model.gripper import GripperParams, default_finger, rot
from predictor.model.joint import AnalyticJoint
from predictor.calibration.observations import FINGER, GRIPPER, ObservationError, observations_to_json, parse_observations
from predictor.solvers.solve import solve
from predictor.model.statics import ContactParams, GripperProblem, scaled

from test_predictor_common import ROOT

torch.set_num_threads(1)
JOINT = AnalyticJoint()
#: The calibration models one finger's gravity gestures (docs/calibration.md §8): the finger
#: alone, without the symmetry plane X = 0 where the gripper's two fingers meet.
ALONE = ContactParams(plane_stiffness=0.0)
PAPER = default_finger()
P = ((0.0, 0.0), (0.1, 0.0), (0.0, 0.1), (-0.1, 0.05), (0.05, -0.1), (0.12, 0.12))
TRUTH = {"gain_J1": 1.08, "gain_J2": 0.93, "offset_J1": 0.008, "offset_J2": -0.006, "stiffness_J1": 1.12,
         "stiffness_J2": 0.9, "frame_x": 3.0, "frame_y": -2.0, "frame_deg": 1.5}


@pytest.fixture(scope="module")
def model():
    return CalibrationModel(JOINT, PAPER)


def _theta(model, B, **values):
    th = model.nominal.clone()
    for k, v in values.items():
        th[model.index[k]] = v
    return th[None].repeat(B, 1)


def test_residual_is_the_statics_and_a_turned_mount_turns_gravity(model):
    """At the nominal parameters the calibration's residual equals GripperProblem's scaled
    residual at random tau: of the finger alone (ALONE, plane=False) to 1e-15, of the
    gripper (the plane X = 0's penalty on, where most of these poses cross it by up to
    ~160 mm) to 1e-12 of its size; with the mount turned by 3 deg and shifted by 1.5 mm it
    equals, turned back by 3 deg (moments unchanged), the residual of a finger file with
    base_angle + 3 deg and base_gap + 3 mm, to 1e-12 of its size, for both problems."""
    g = torch.Generator().manual_seed(0)
    p = torch.tensor(P + ((0.25, 0.2),), dtype=torch.float64)
    B = len(p)
    x = 0.3 * torch.randn(B, 6, generator=g, dtype=torch.float64)
    ones = torch.ones(B, dtype=torch.float64)
    moved = dataclasses.replace(PAPER, base_angle=PAPER.base_angle + math.radians(3.0), base_gap=PAPER.base_gap + 3.0)
    turn = torch.tensor(math.radians(3.0), dtype=torch.float64)
    for plane, contact in ((False, ALONE), (True, ContactParams())):
        ref = scaled(GripperProblem(JOINT, GripperParams(PAPER), contact=contact).residual(p, x.reshape(-1, 2, 3))
                     .residual)
        err = float((model.residual(x, _theta(model, B), p, ones, plane) - ref).abs().max())
        assert err <= (1e-12 * float(ref.abs().max()) if plane else 1e-15), (plane, err)
        st = GripperProblem(JOINT, GripperParams(moved), contact=contact).residual(p, x.reshape(-1, 2, 3))
        if plane:
            assert float(st.plane.overlap.max()) > 100.0   # not a vacuous check: the plane pushes hard
        ref = scaled(st.residual)
        ours = model.residual(x, _theta(model, B, mount_deg=3.0, mount_x=1.5), p, ones, plane).reshape(-1, 2, 3)
        back = torch.cat((rot(turn, ours[..., :2]), ours[..., 2:]), -1)
        assert float((back.reshape(B, -1) - ref).abs().max()) <= 1e-12 * max(1.0, float(ref.abs().max()))


def test_scaled_joint_is_a_stiffer_beam():
    """The similarity R(P, tau; sE) = R(P/s, tau/s; E) with a gain and offset, against
    an independent analytic beam: modulus s·E scales EI and EA by s, the gain scales the
    pressure couple c_p by g, the offset adds -c_p·o to the end couple."""
    g, o, s = 1.1, 0.02, 1.3
    inputs = torch.tensor([[0.15, 0.4, -0.3, 12.0], [-0.2, -0.5, 0.6, -30.0]], dtype=torch.float64)
    gos = (torch.tensor(v, dtype=torch.float64) for v in (g, o, s))
    ours = ScaledJoint(JOINT, *gos).anchors_and_cap(inputs)
    beam = AnalyticJoint(EI=s * JOINT.EI, c_p=g * JOINT.c_p, EA=s * JOINT.EA)
    shifted = inputs + torch.tensor([0.0, 0.0, 0.0, -JOINT.c_p * o], dtype=torch.float64)
    ref = beam.anchors_and_cap(shifted)
    assert float((ours[0] - ref[0]).abs().max()) <= 1e-12 and float((ours[1] - ref[1]).abs().max()) <= 1e-14


def test_equilibrium_is_the_solvers(model):
    """Newton on the calibration's residual lands on predictor.solvers.solve's gravity gesture
    (tau within 1e-6 N, N·mm: the solver stops at 1e-7 N, 1e-5 N·mm): of the gripper (the
    fingers meet at X = 0 at some of these pressures) for gripper observations, of the
    finger alone for lone-finger ones, with and without gravity."""
    for problem, contact in ((GRIPPER, ContactParams()), (FINGER, ALONE)):
        obs = synthetic_observations(model, {}, P, problem=problem)
        d = design(obs, PAPER)
        assert d.plane == (problem == GRIPPER)
        for gravity in (True, False):
            d.gravity = torch.full((len(P),), 1.0 if gravity else 0.0, dtype=torch.float64)
            x, ok = equilibrium(model, d, _theta(model, len(P)))
            ref = solve(GripperProblem(JOINT, GripperParams(PAPER), contact=contact, gravity=gravity), d.pressures)
            assert bool(ok.all()) and float((x - ref.tau.reshape(len(P), -1)).abs().max()) <= 1e-6, (problem, gravity)
            if problem == GRIPPER and gravity:
                assert float(ref.plane_overlap_mm.max()) > 0.0   # the plane acts at some pressures


def test_fit_jacobian_matches_finite_differences(model):
    """The implicit-function Jacobian of the weighted residual (every group: gains,
    offsets, stiffness, a weight, the mount, the frame; one observation without gravity)
    against central differences (h = 1e-5 of the scale): relative error <= 1e-6."""
    obs = synthetic_observations(model, TRUTH, P[:4], noise_mm=0.3, noise_deg=0.3, seed=3)
    obs = dataclasses.replace(obs, items=obs.items[:3] + (dataclasses.replace(obs.items[3], gravity=False),))
    names = list(TRUTH) + ["weight_4", "mount_x", "mount_deg"]
    prob = Problem(model, design(obs, PAPER), tuple(model.index[n] for n in names), {"weight_4": Prior(0.07, 0.01)})
    v = np.array([model.nominal[model.index[n]].item() for n in names]) + 0.01 * prob.scale
    r, jac = prob.residual(v, jacobian=True)
    fd = np.empty_like(jac)
    for k in range(len(v)):
        h = np.zeros_like(v)
        h[k] = 1e-5 * prob.scale[k]   # the equilibria are exact to 1e-10: smaller h is noise
        fd[:, k] = (prob.residual(v + h) - prob.residual(v - h)) / (2 * h[k])
    assert np.abs(jac - fd).max() <= 1e-6 * np.abs(jac).max()
    assert np.abs(fd[:, names.index("stiffness_J2")]).max() > 1.0   # not a vacuous check


def test_noise_free_recovery_and_exact_degeneracy(model):
    """Noise-free observations of a known truth (6 pressure pairs): every parameter
    recovered to 1e-6 relative, rms from > 1 mm to < 1e-6 mm. Fitting the mount's shift
    beside the frame's to a lone finger (an exact degeneracy: both translate it along X;
    the gripper's plane X = 0 separates them) flags both unidentifiable and the fit
    untrusted."""
    obs = synthetic_observations(model, TRUTH, P)
    res = calibrate(model, obs, list(TRUTH), starts=1, loo=False)
    for n, v in zip(res.names, res.values):
        assert abs(v - TRUTH[n]) <= 1e-6 * abs(TRUTH[n]), n
    assert res.rms_before_mm > 1.0 and res.rms_after_mm < 1e-6
    alone = synthetic_observations(model, TRUTH, P, problem=FINGER)   # the gripper's plane X = 0 fixes mount_x
    res = calibrate(model, alone, ["offset", "mount_x", "frame_x"], starts=1, loo=False)
    assert {"mount_x", "frame_x"} <= set(res.unidentifiable) and not res.trusted
    assert any({p[0], p[1]} == {"mount_x", "frame_x"} and p[2] < -0.999 for p in res.correlated)


def _points(obs) -> np.ndarray:
    """(B, 2 + 2·markers) measured tip and marker coordinates (mm)."""
    return np.array([[*o.tip[:2]] + [v for m in o.markers for v in (m.x, m.y)] for o in obs.items])


def test_covariance_of_a_translation_is_exact(model):
    """The measurements are linear in the frame's translation with unit slope: fitting
    frame_x and frame_y to 6 noisy observations of 2 points each (sigma 0.3 mm) gives the
    exact least-squares answers (the mean offsets) and std 0.3/sqrt(12) mm, uncorrelated."""
    obs = synthetic_observations(model, {"frame_x": 1.0, "frame_y": -2.0}, P, noise_mm=0.3, noise_deg=0.3, seed=5)
    clean = synthetic_observations(model, {}, P)
    res = calibrate(model, obs, ["frame_x", "frame_y"], starts=1, loo=False)
    diff = (_points(obs) - _points(clean)).reshape(-1, 2)
    assert np.allclose(res.values, diff.mean(0), atol=1e-9, rtol=0)
    assert np.allclose(res.std, 0.3 / math.sqrt(12), rtol=1e-9) and abs(res.correlation[0, 1]) < 1e-9


BAD = [
    ({"format": "x", "observations": []}, "format"),
    ({"format": "softjoint-observations/1", "observations": [{"pressures": [0.1]}]}, "list of 2 numbers"),
    ({"format": "softjoint-observations/1", "observations": [{"pressures": [0.5, 0], "tip": {}}]},
     "pressures[0] = 0.5: outside [-0.3, 0.3] MPa"),
    ({"format": "softjoint-observations/1", "observations": [{"pressures": [0, 0]}]}, "measures nothing"),
    ({"format": "softjoint-observations/1", "observations": [
        {"pressures": [0, 0], "tip": {"x": 1, "y": 2, "sigma_mm": 0}}]}, "sigma_mm = 0: outside [0.0001, 100] mm"),
    ({"format": "softjoint-observations/1", "observations": [
        {"pressures": [0, 0], "markers": [{"part": 5, "s": 1, "x": 0, "y": 0, "sigma_mm": 1}]}]}, "part = 5"),
    ({"format": "softjoint-observations/1", "observations": [
        {"pressures": [0, 0], "markers": [{"part": 2, "s": 61, "x": 0, "y": 0, "sigma_mm": 1}]}]},
     "s = 61: outside [0, 60] mm"),
    ({"format": "softjoint-observations/1", "observations": [
        {"pressures": [0, 0], "tip_angle": {"deg": -90, "sigma_deg": 0.3}, "colour": 1}]}, "unknown key 'colour'"),
]


@pytest.mark.parametrize("doc,why", BAD)
def test_bad_measurement_file_exits_2_with_one_line(tmp_path, capsys, doc, why):
    """Each schema violation: exit 2, one stderr line naming the key and the allowed range,
    no output written (checked before any model is loaded)."""
    path, out = tmp_path / "obs.json", tmp_path / "cal.toml"
    path.write_text(json.dumps(doc))
    with pytest.raises(SystemExit) as exc:
        calibrate_main(["--observations", str(path), "--model", "analytic", "--out", str(out)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and why in err, err
    assert not out.exists()
    with pytest.raises(ObservationError):
        parse_observations(json.dumps(doc), PAPER)


def test_cli_writes_a_finger_that_predictor_gesture_reads(tmp_path, model):
    """The CLI (a subprocess, --json) fits a heavier tip and a turned, shifted mount to
    observations of that truth (frame untouched), exits 0 with the issue's keys, and
    writes a finger file: predictor.cli.gesture --finger reads it and its tip at a new
    pressure pair, where the fingers do not meet at X = 0 (the calibration models the
    finger alone), equals the truth's prediction (1e-6 mm); the file records the
    measurements' sha256. A bad --fit name exits 2 with one line."""
    truth = {"weight_4": 0.075, "mount_deg": 2.0, "mount_x": 1.5}
    obs = synthetic_observations(model, truth, P)
    path, out = tmp_path / "obs.json", tmp_path / "cal.toml"
    path.write_text(json.dumps(observations_to_json(obs)))
    run = [sys.executable, "-m", "predictor.cli.calibrate", "--observations", str(path), "--model", "analytic"]
    r = subprocess.run(run + ["--fit", "weight_4,mount", "--out", str(out), "--json"], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert {"parameters", "rms_before_mm", "rms_after_mm", "loo_tip_error_mm", "time_s"} <= set(s)
    assert abs(s["parameters"]["mount_deg"]["value"] - 2.0) <= 1e-6 and s["loo_tip_error_mm"] < 1e-5
    finger = load_finger(out)
    assert finger.calibration["observations_sha256"] == parse_observations(path.read_text(), PAPER).sha256
    g = subprocess.run([sys.executable, "-m", "predictor.cli.gesture", "--finger", str(out), "--model", "analytic",
                        "--p1", "-0.03", "--p2", "0.07", "--json"], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert g.returncode == 0, g.stderr
    one = synthetic_observations(model, truth, ((-0.03, 0.07),))
    gesture = json.loads(g.stdout)
    assert gesture["plane_force_N"] == 0.0
    assert np.allclose(gesture["tip"], one.items[0].tip[:2], atol=1e-6, rtol=0)
    bad = subprocess.run(run + ["--fit", "gain,elasticity", "--out", str(tmp_path / "b.toml")], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "elasticity" in bad.stderr


def test_api_calibrate_with_a_prior(tmp_path, model):
    """predictor.api.calibrate: a measurement file of a heavier tip and a turned camera,
    fitted with a prior on the tip's weight at its true value: both recovered to 1e-6
    (noise-free), the prior's std bounds the weight's (<= 0.002 N); an unknown prior name
    is a one-line ValueError."""
    from predictor.api import calibrate as api_calibrate

    truth = {"weight_4": 0.075, "frame_deg": -1.0}
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(observations_to_json(synthetic_observations(model, truth, P))))
    res = api_calibrate(path, fit=("weight_4", "frame_deg"), model="analytic", priors={"weight_4": (0.075, 0.002)},
                        starts=1, loo=False)
    s = res.summary()["parameters"]
    assert abs(s["weight_4"]["value"] - 0.075) <= 1e-6 and abs(s["frame_deg"]["value"] + 1.0) <= 1e-6
    assert 0 < s["weight_4"]["std"] <= 0.002
    with pytest.raises(ValueError, match="--prior mount_x: not a fitted parameter"):
        api_calibrate(path, fit=("frame",), model="analytic", priors={"mount_x": (0.0, 1.0)}, loo=False)


def test_tools_apply_the_joint_calibration_keys(model):
    """A finger file with a joint's pressure_gain = 1.2 gives GripperProblem the gesture of
    the calibration's model at gain 1.2 (tau within 1e-6 N, N·mm: the solver's tolerances),
    the finger alone (at (0.1, 0.05) MPa the analytic fingers meet at X = 0)."""
    text = (ROOT / "contract/fingers/paper.toml").read_text().replace(
        'weight = 0.09\ncontact = false', 'weight = 0.09\ncontact = false\npressure_gain = 1.2', 1)
    finger = parse_finger(text, "gain.toml")
    p = torch.tensor([[0.1, 0.05]], dtype=torch.float64)
    ref = solve(GripperProblem(JOINT, GripperParams(finger), contact=ALONE), p)
    obs = synthetic_observations(model, {}, ((0.1, 0.05),), problem=FINGER)
    x, _ = equilibrium(model, design(obs, PAPER), _theta(model, 1, gain_J1=1.2))
    assert float((x - ref.tau.reshape(1, -1)).abs().max()) <= 1e-6


def test_finger_files_without_calibration_load_as_before():
    """The paper's file: no calibration, summary without the joint keys (as before), the
    same FingerSpec as one with the identity keys written out; out-of-range or non-table
    calibration keys are one-line FingerFileErrors."""
    text = (ROOT / "contract/fingers/paper.toml").read_text()
    paper = parse_finger(text, "paper.toml")
    assert not paper.calibrated and paper.calibration is None
    assert all(set(p) <= {"kind", "weight", "contact", "length", "height", "width", "contact_points"}
               for p in paper.summary()["parts"])
    same = parse_finger(text.replace("contact = false", "contact = false\npressure_gain = 1.0\nstiffness_scale = 1.0"))
    assert same == paper
    for bad, why in (("pressure_gain = 9.0", "outside [0.2, 5]"), ("stiffness_scale = 0.0", "must be > 0"),
                     ("pressure_offset = 0.5", "outside [-0.1, 0.1] MPa")):
        with pytest.raises(FingerFileError, match=re.escape(why)):
            parse_finger(text.replace("contact = false", f"contact = false\n{bad}"), "f.toml")
    with pytest.raises(FingerFileError, match="calibration must be a"):
        parse_finger(text.replace('name = "paper"', 'name = "paper"\ncalibration = 3'), "f.toml")


def test_predicted_tip_is_the_pose_tip(model):
    """predict's tip (identity frame and mount) is FingerPose.tip_end of the solved gesture,
    and its angle tip_angle in degrees (to 1e-12)."""
    obs = synthetic_observations(model, {}, P[:2])
    d = design(obs, PAPER)
    th = _theta(model, 2)
    x, _ = equilibrium(model, d, th)
    m = predict(model, d, x, th)
    pose = model.pose(x, th, d.pressures)
    rows = list(d.tip_rows[1])
    assert float((m[rows] - pose.tip_end[1]).abs().max()) <= 1e-12
    assert abs(float(m[rows[1] + 3]) - math.degrees(float(pose.tip_angle[1]))) <= 1e-12


# --- issue 57: calibration you can trust -------------------------------------------------------

EXAMPLE = ROOT / "docs" / "examples" / "gripper_observations.json"


def _write(tmp_path, obs, name="obs.json", **top) -> "Path":
    path = tmp_path / name
    path.write_text(json.dumps({**observations_to_json(obs), **top}))
    return path


def _cli(capsys, argv) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of the calibrate CLI in this process (what was printed
    before it, e.g. the solver's progress while the observations were made, dropped)."""
    capsys.readouterr()
    try:
        code = calibrate_main(argv)
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def test_observations_say_what_was_measured(tmp_path):
    """The file's top-level ``problem``: absent = the gripper (files written before it),
    "finger" = a lone finger; it round-trips through observations_to_json; another value
    is one ObservationError line; the design carries it to the residual (plane on/off)."""
    doc = {"format": "softjoint-observations/1", "observations": [{"pressures": [0, 0], "tip_angle": {
        "deg": -90, "sigma_deg": 0.3}}]}
    assert parse_observations(json.dumps(doc), PAPER).problem == GRIPPER
    alone = parse_observations(json.dumps({**doc, "problem": "finger"}), PAPER)
    assert alone.problem == FINGER and not design(alone, PAPER).plane
    assert parse_observations(json.dumps(observations_to_json(alone)), PAPER).problem == FINGER
    with pytest.raises(ObservationError, match='problem = \'both\': must be "gripper"') as exc:
        parse_observations(json.dumps({**doc, "problem": "both"}), PAPER)
    assert "\n" not in str(exc.value)
    assert json.loads(EXAMPLE.read_text())["problem"] == GRIPPER
    assert json.loads((ROOT / "docs/examples/observations.json").read_text())["problem"] == FINGER


def test_hidden_truth_gripper_is_recovered_and_the_readme_example_is_trusted(tmp_path, capsys):
    """Issue 57's hidden truth: the README's example file is the gripper (fingers meeting at
    X = 0) of a finger with gains 0.93/1.06, offsets 0.012/-0.008 MPa and stiffness
    0.88/1.12, solved by predictor.solvers.solve at 8 pressure pairs, noise 0.3 mm / 0.3 deg
    (regenerated here: the same values to 1e-6 mm, the equilibria's own tolerance: the example
    was written by the plane's ramp, today's contact-constrained Newton lands on the same roots
    within ~1e-7 mm). The README's command (committed surrogate,
    gain,offset,stiffness; --no-loo to keep the test short) exits 0 trusted in one start:
    reduced chi-square within [its 0.05 %, 99.95 %] quantiles (0.44 measured for 18 dof),
    nothing on a bound, every parameter within 3 std of the truth. The written finger file,
    solved by predictor.solvers.solve at 6 held-out pairs, puts the fingertip <= 1 mm from the
    truth's (0.54 mm max measured), >= 5x closer than the uncalibrated finger (9.8x)."""
    from scipy.stats import chi2

    from predictor.calibration.fit import chi2_limit
    from predictor.calibration.recovery import (HELDOUT_PRESSURES, HIDDEN_PRESSURES, HIDDEN_TRUTH,
                                                gesture_observations, truth_theta)
    from predictor.model.joint import load_joint

    joint = load_joint(None, PAPER)
    model = CalibrationModel(joint, PAPER)
    made = gesture_observations(model, HIDDEN_TRUTH, HIDDEN_PRESSURES, seed=1)
    example = parse_observations(EXAMPLE.read_text(), PAPER)
    assert np.allclose(_points(example), _points(made), atol=1e-6, rtol=0)
    assert "mkdir -p build" in (ROOT / "README.md").read_text() and str(EXAMPLE.relative_to(ROOT)) in (
        ROOT / "README.md").read_text()
    out = tmp_path / "calibrated.toml"
    code, stdout, err = _cli(capsys, ["--observations", str(EXAMPLE), "--fit", "gain,offset,stiffness", "--out", str(out),
                                      "--no-loo", "--json", "--quiet"])
    assert code == 0, err
    s = json.loads(stdout)
    assert s["trusted"] and s["why"] == [] and s["on_bound"] == [] and s["starts"] == 1 and s["problem"] == GRIPPER
    assert s["dof"] == 18 and chi2.ppf(5e-4, 18) / 18 <= s["reduced_chi2"] <= chi2_limit(18)
    for n, p in s["parameters"].items():
        assert abs(p["value"] - HIDDEN_TRUTH[n]) <= 3 * p["std"], n
    pressures = torch.tensor(HELDOUT_PRESSURES, dtype=torch.float64)

    def tips(finger):
        res = solve(GripperProblem(joint, GripperParams(finger)), pressures)
        assert bool(res.converged.all())
        return res.pose.tip_end.numpy()

    from predictor.calibration.model import finger_at

    truth = tips(finger_at(model, truth_theta(model, HIDDEN_TRUTH)))
    before = np.linalg.norm(tips(PAPER) - truth, axis=1)
    after = np.linalg.norm(tips(load_finger(out)) - truth, axis=1)
    assert after.max() <= 1.0 and before.mean() >= 5.0 * after.mean(), (before, after)


def _gripper_observations(model, pressures, seed=1):
    """Noisy gripper observations (tip, angle) of HIDDEN_TRUTH on ``model``'s joint."""
    from predictor.calibration.recovery import HIDDEN_TRUTH, gesture_observations

    return gesture_observations(model, HIDDEN_TRUTH, pressures, seed=seed)


def test_a_poor_fit_is_refused_and_nothing_is_written(tmp_path, capsys, model):
    """Gripper observations (7 pairs, 0.3 mm / 0.3 deg, the analytic joint) declared a lone
    finger -- issue 57's first case -- cannot be fitted: exit 1, one stderr line naming the
    reduced chi-square beyond its limit, "trusted": false, nothing written; with --force
    the file is written (exit 1 still). The same file declared a gripper is trusted (exit 0)."""
    from predictor.calibration.recovery import HIDDEN_PRESSURES

    obs = _gripper_observations(model, HIDDEN_PRESSURES[:7])
    wrong = _write(tmp_path, obs, "wrong.json", problem="finger")
    out = tmp_path / "cal.toml"
    args = ["--observations", str(wrong), "--model", "analytic", "--no-loo", "--json", "--quiet", "--out", str(out)]
    code, stdout, err = _cli(capsys, args)
    s = json.loads(stdout)
    assert code == 1 and err.count("\n") == 1 and "not trusted" in err and "reduced chi-square" in err, err
    assert not s["trusted"] and s["out"] is None and s["reduced_chi2"] > 10 * s["reduced_chi2_limit"]
    assert not out.exists()
    code, stdout, err = _cli(capsys, args + ["--force"])
    assert code == 1 and out.exists() and "(--force)" in err and json.loads(stdout)["out"] == str(out)
    load_finger(out)
    right = _write(tmp_path, obs, "right.json")
    code, stdout, err = _cli(capsys, args[:1] + [str(right)] + args[2:-1] + [str(tmp_path / "ok.toml")])
    s = json.loads(stdout)
    assert code == 0 and s["trusted"] and s["reduced_chi2"] < s["reduced_chi2_limit"], err


def test_one_observation_is_too_few_for_six_parameters(tmp_path, capsys, model):
    """One observation (3 measured values) for gain, offset, stiffness (6 parameters):
    exit 1, one stderr line saying more parameters than data, no numpy warning, nothing
    written; dof -3 and no reduced chi-square in the JSON."""
    import warnings

    path = _write(tmp_path, _gripper_observations(model, ((0.1, 0.05),)))
    out = tmp_path / "cal.toml"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, stdout, err = _cli(capsys, ["--observations", str(path), "--model", "analytic", "--json", "--quiet",
                                          "--out", str(out)])
    s = json.loads(stdout)
    assert code == 1 and err.count("\n") == 1 and "3 measured values for 6 fitted parameters" in err, err
    assert s["dof"] == -3 and s["reduced_chi2"] is None and not s["trusted"] and not out.exists()


def test_outputs_inside_the_package_or_in_a_missing_folder_are_refused(tmp_path, capsys):
    """--out contract/fingers/paper.toml (the default finger) and any path inside the
    package's folders: exit 2, one line, the file untouched; a missing output folder:
    exit 2, one line (contract.cli: the folder must exist), checked before the fit."""
    path = tmp_path / "obs.json"
    path.write_text(json.dumps({"format": "softjoint-observations/1", "observations": [
        {"pressures": [0, 0], "tip_angle": {"deg": -90, "sigma_deg": 0.3}}]}))
    paper = ROOT / "contract" / "fingers" / "paper.toml"
    before = paper.read_bytes()
    for out, why in ((paper, "inside the package"), (ROOT / "predictor" / "x.toml", "inside the package"),
                     (tmp_path / "missing" / "cal.toml", "does not exist")):
        code, _, err = _cli(capsys, ["--observations", str(path), "--model", "analytic", "--out", str(out)])
        assert code == 2 and err.count("\n") == 1 and why in err, err
    assert paper.read_bytes() == before and not (ROOT / "predictor" / "x.toml").exists()


def test_committed_bench_timed_the_current_example():
    """results/bench/calibrate.json (make bench-calibrate) names the measurement file it
    timed and its sha256: that file as committed now, so the figure is of today's example
    (a changed example needs the bench rerun; the Makefile's rule depends on it); its fit
    was trusted, so its leave-one-out ran and was timed."""
    from predictor.artefacts import CALIBRATION_BENCH
    from predictor.calibration.bench import OBSERVATIONS

    bench = CALIBRATION_BENCH.load(ROOT / "results/bench/calibrate.json")
    assert ROOT / bench["observations_file"] == OBSERVATIONS
    assert bench["observations_sha256"] == parse_observations(OBSERVATIONS.read_text(), PAPER).sha256
    # a trusted fit, so "with leave-one-out" timed the leave-one-out (a refused fit skips it)
    assert bench["trusted"] and bench["loo_tip_error_mm"] is not None
    assert bench["with_loo_cpu_median_s"] > bench["fit_cpu_median_s"]
    rule = re.search(r"^results/bench/calibrate.json:(.*?)\n\t", (ROOT / "Makefile").read_text(), re.M | re.S)[1]
    assert "docs/examples/observations.json" in rule


def test_bench_refuses_to_time_an_untrusted_fit(tmp_path, capsys, model):
    """predictor.cli.calibrate bench on one observation (3 measured values for the bench's 10
    parameters and a prior: dof -6) refuses after the first fit: exit 2, one stderr line
    naming the file and why the fit is not trusted, no JSON written."""
    path = _write(tmp_path, _gripper_observations(model, ((0.1, 0.05),)))
    out = tmp_path / "bench.json"
    code, stdout, err = _cli(capsys, ["bench", "--observations", str(path), "--model", "analytic", "--repeats", "1",
                                      "--quiet", "--out", str(out)])
    assert code == 2 and err.count("\n") == 1 and stdout == "", (code, err)
    assert "the timed fit is not trusted" in err and "3 measured values and 1 priors for 10 fitted parameters" in err, err
    assert not out.exists()
