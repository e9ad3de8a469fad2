"""Grasp planning from Python, without the command line.

    from predictor import load_gripper, solve_gesture, grasp_atlas, inverse_pressures
    g = load_gripper(object="circle")                 # committed surrogate, default placement
    gesture = solve_gesture(g, 0.2, 0.3)              # Gesture: .summary() -> dict
    atlas = grasp_atlas(g, grid=21)                   # predictor.planning.atlas.Atlas: .summary(), .to_json()
    answer = inverse_pressures(g, goal="hold", atlas=atlas)   # InverseResult: .summary()
    path = track_tip(load_gripper(), [(40, -212), (41, -212.5)])   # TrackResult: .summary()
    fit = calibrate("observations.json", fit=("gain", "offset"), out="calibrated.toml")

Units: pressures MPa, lengths mm (global frame of docs/gripper.md, right finger), forces N.
Every call goes through the same solver and history as ``predictor.cli.gesture --object``
(approach gesture APPROACH, then the pressure ramp) and the same checks as the command
lines (predictor.solvers.problem: one validation per input, ValueError with the CLI's reason);
the default joint model is found from the package (predictor.defaults), never the
working directory. The problem is the command lines' default, the gripper: the right
finger against the mirror finger's contact at X = 0 (``load_gripper(plane=True)``);
``plane=False`` is one finger alone (``--no-plane``). Every result names its joint model,
mu, object weight and problem (``plane``); the objects are frozen dataclasses.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch

from contract.finger import FingerSpec, load_finger
from predictor.planning import atlas as _atlas
from predictor.planning import inversion as _inverse
from predictor.model.gripper import DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, DEFAULT_OUTLINE, GripperParams, default_finger
from predictor.solvers.problem import FULL_BOX, load_problem
from predictor.solvers.solve import GestureResult, SolverOptions, solve
from predictor.model.statics import STATES


@dataclass(frozen=True)
class Gripper:
    """A gripper problem (predictor.model.statics.GripperProblem) and the spec it came from."""

    problem: object
    object_spec: str | None = None


@dataclass(frozen=True)
class Gesture:
    """One solved gesture: ``result`` (a one-row GestureResult); summary() as in
    ``predictor.cli.gesture --json`` (GestureResult.summary: state, tip mm, tip_angle_deg,
    contact_force_N, friction_use, slip, joint, mu, object_weight_N, plane; null figures unless
    converged) plus ``first_contact_MPa`` (None without an object or contact)."""

    result: GestureResult
    state: str

    def summary(self) -> dict:
        first = self.result.first_contact
        first = None if first is None or bool(first[0].isnan().any()) else first[0].tolist()
        return {**self.result.summary(0), "first_contact_MPa": first}


def load_gripper(model: str | None = None, object: str | None = None, gravity: bool = True,
                 finger: str | Path | FingerSpec | None = None, kinematics: str = DEFAULT_KINEMATICS,
                 joint_weight: str = DEFAULT_JOINT_WEIGHT, mu: float | None = None,
                 object_weight: float | None = None, plane: bool = True, outline: str = DEFAULT_OUTLINE) -> Gripper:
    """model: a surrogate checkpoint path, "analytic", or None (the committed surrogate,
    results/surrogate/improved.pt of this package or $SOFTJOINT_RESULTS; ValueError when
    missing); object: a spec such as "circle" or "ellipse:a=35,b=25,y=-200" (None: no
    object); finger: a finger description file or FingerSpec (None: the paper's,
    contract/fingers/paper.toml); kinematics "tangent" | "cap"; joint_weight "lumped" | "split";
    mu: friction coefficient, object_weight: N (None: the defaults 0.3 and 0.2 N)
    plane: the gripper, the mirror finger's contact at X = 0 (True), or one finger alone
    (False); outline "band" | "bulged" (predictor.cli.gesture's --finger, --kinematics,
    --joint-weight, --mu, --object-weight, --no-plane, --outline).
    ValueError (one line) for a bad spec, finger file, model, option, an object the model
    cannot represent or one cutting through the fingers at the approach gesture."""
    if finger is not None and not isinstance(finger, FingerSpec):
        finger = load_finger(finger)
    params = GripperParams(finger or default_finger(), kinematics=kinematics, joint_weight=joint_weight,
                           outline=outline)
    return Gripper(load_problem(model, object, gravity, params, mu=mu, object_weight=object_weight, plane=plane),
                   object)


def solve_gesture(gripper: Gripper, *pressures: float) -> Gesture:
    """The equilibrium gesture at pressures (P1, .., PJ) MPa, one per joint of the finger
    (p1, p2 for the paper's)."""
    res = solve(gripper.problem, torch.tensor([pressures], dtype=torch.float64))
    return Gesture(res, STATES[int(res.states()[0])])


def grasp_atlas(gripper: Gripper, grid: int = 61, box=FULL_BOX,
                options: SolverOptions = SolverOptions(), path: str = "sweep") -> _atlas.Atlas:
    """The grid x grid atlas over box (P1lo, P1hi, P2lo, P2hi) MPa (predictor.planning.atlas;
    path: sweep or ramp)."""
    return _atlas.grasp_atlas(gripper.problem, grid, box, options, path)


def calibrate(observations: str | Path, fit=("gain", "offset", "stiffness"), finger: str | Path | FingerSpec | None = None,
              model: str | None = None, priors: dict | None = None, out: str | Path | None = None, starts: int = 3,
              loo: bool = True, kinematics: str = DEFAULT_KINEMATICS, joint_weight: str = DEFAULT_JOINT_WEIGHT,
              force: bool = False):
    """Fit the gripper to a measurement file, as ``python -m predictor.cli.calibrate``
    (docs/calibration.md): fit names or groups, priors {name: (mean, std)} in the
    parameters' units; out: the calibrated finger file to write (None: none), written
    only when the fit is trusted or ``force``. Returns
    predictor.calibration.fit.CalibrationResult (summary() is the CLI's JSON; ``.trusted``,
    ``.why``). ValueError (one line) for a bad file, name, prior or finger, an ``out``
    inside the package, and an untrusted fit with ``out`` (nothing written)."""
    from predictor.calibration.model import CalibrationModel
    from predictor.calibration.file import write_calibrated
    from predictor.calibration.fit import Prior, calibrate as fit_calibration
    from predictor.model.joint import load_joint
    from predictor.calibration.observations import load_observations

    if out is not None:
        from predictor.calibration.file import outside_package

        outside_package(out)
    if finger is not None and not isinstance(finger, FingerSpec):
        finger = load_finger(finger)
    finger = finger or default_finger()
    obs = load_observations(observations, finger)
    cal = CalibrationModel(load_joint(model, finger), finger, kinematics, joint_weight)
    res = fit_calibration(cal, obs, tuple(fit), {k: Prior(*v) for k, v in (priors or {}).items()}, starts=starts,
                          loo=loo)
    if out is not None:
        if not (res.trusted or force):
            raise ValueError(f"not trusted: {'; '.join(res.why)}; nothing written to {out} (force=True writes it)")
        write_calibrated(out, cal, res, obs.sha256, str(observations))
    return res


def inverse_pressures(gripper: Gripper, goal: str = "hold", min_normal: float = 0.0, least_pressure: bool = False,
                      atlas: _atlas.Atlas | None = None, box=FULL_BOX) -> _inverse.InverseResult:
    """Pressures for goal "hold" or "tip:X,Y[,DEG]" (mm, degrees), predictor.planning.inversion;
    min_normal: N, as --min-normal; atlas: this gripper's atlas for the starts (else a
    coarse one is solved; refused when solved with other settings)."""
    g = dataclasses.replace(_inverse.parse_goal(goal), min_normal=min_normal, least_pressure=least_pressure)
    return _inverse.inverse_pressures(_inverse.InverseProblem(gripper.problem, g, box), atlas)


def track_tip(gripper: Gripper, goals, box=FULL_BOX):
    """Fingertip goals along a trajectory (predictor.planning.track, ``predictor.cli.inverse --track``):
    goals a list of (X, Y) or (X, Y, DEG) (mm, degrees) or "tip:X,Y[,DEG]" strings, each
    answered warm-started from the previous answer and verified through the forward
    equilibrium; the gripper without an object. Returns predictor.planning.track.TrackResult
    (answers: TrackAnswer each, with status reached | unreachable (the closest reachable
    answer), position_error_mm, angle_error_deg wrapped, verified, robust, time_ms;
    summary() -> dict)."""
    from predictor.planning.track import track

    goals = [_inverse.parse_goal(g) if isinstance(g, str) else g for g in goals]
    if any(isinstance(g, _inverse.Goal) and g.kind != "tip" for g in goals):
        raise ValueError("a track's goals are fingertip goals tip:X,Y[,DEG]")
    return track(gripper.problem, goals, box)

