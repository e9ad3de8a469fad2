"""The calibrated finger file: a finger description (contract.finger) that every tool reads.

The fit's values go where the finger file holds them: part weights (N), the mount
(base_gap += 2·mount_x mm, the two mounts move symmetrically; base_angle_deg +=
mount_deg), and per joint pressure_gain, pressure_offset (MPa), stiffness_scale. The
measurement frame (frame_x, frame_y mm, frame_deg) belongs to the camera, not the
gripper: it is recorded in the ``[calibration]`` table with the measurements' sha256,
the joint model, the fitted names, each parameter's value and std, and the fit's figures
(rms before and after, leave-one-out tip error, mm).

Data flow: FingerSpec + CalibrationResult -> ``calibrated_finger_text`` (TOML) ->
contract.finger.parse_finger (checked before writing) -> ``write_calibrated``.
"""
from __future__ import annotations

import math
from pathlib import Path

from contract.files import write_text
from contract.finger import FORMAT, FingerSpec, parse_finger
from predictor.calibration.model import CalibrationModel
from predictor.calibration.fit import CalibrationResult


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) and math.isfinite(v) else ("nan" if isinstance(v, float) else str(v))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def calibrated_finger_text(model: CalibrationModel, res: CalibrationResult, observations_sha256: str,
                           observations_source: str = "") -> str:
    """The TOML text of the calibrated finger (module docstring)."""
    f: FingerSpec = model.finger
    th = {p.name: float(res.theta[i]) for i, p in enumerate(model.table)}
    lines = ["# A calibrated finger: python -m predictor.cli.calibrate (docs/calibration.md).",
             f"format = {_toml(FORMAT)}", f"name = {_toml(f.name + '-calibrated')}",
             f"base_gap = {_toml(f.base_gap + 2.0 * th['mount_x'])}",
             f"base_angle_deg = {_toml(math.degrees(f.base_angle) + th['mount_deg'])}", ""]
    j = 0
    for k, part in enumerate(f.parts, 1):
        lines += ["[[part]]", f"kind = {_toml(part.kind)}", f"weight = {_toml(th[f'weight_{k}'])}"]
        if part.kind == "joint":
            j += 1
            lines += [f"contact = {_toml(part.contact)}", f"pressure_gain = {_toml(th[f'gain_J{j}'])}",
                      f"pressure_offset = {_toml(th[f'offset_J{j}'])}",
                      f"stiffness_scale = {_toml(th[f'stiffness_J{j}'])}"]
        else:
            lines += [f"{key} = {_toml(getattr(part, key))}" for key in ("length", "height", "width", "contact_points")]
        lines.append("")
    s = res.summary()
    lines += ["[calibration]", f"observations_sha256 = {_toml(observations_sha256)}",
              f"observations = {_toml(observations_source)}", f"source_finger = {_toml(f.name)}",
              f"source_finger_sha256 = {_toml(f.digest)}", f"joint_model = {_toml(model.joint.name)}",
              f"kinematics = {_toml(model.params.kinematics)}", f"joint_weight = {_toml(model.params.joint_weight)}",
              f"fitted = {_toml(res.names)}", f"unidentifiable = {_toml(res.unidentifiable)}",
              f"rms_before_mm = {_toml(s['rms_before_mm'])}", f"rms_after_mm = {_toml(s['rms_after_mm'])}"]
    if s["loo_tip_error_mm"] is not None:
        lines.append(f"loo_tip_error_mm = {_toml(s['loo_tip_error_mm'])}")
    lines += [f"frame_x_mm = {_toml(th['frame_x'])}", f"frame_y_mm = {_toml(th['frame_y'])}",
              f"frame_deg = {_toml(th['frame_deg'])}", ""]
    for name, v, sd in zip(res.names, res.values, res.std):
        lines += [f"[calibration.parameters.{name}]", f"value = {_toml(float(v))}", f"std = {_toml(float(sd))}", ""]
    return "\n".join(lines)


def write_calibrated(path: str | Path, model: CalibrationModel, res: CalibrationResult, observations_sha256: str,
                     observations_source: str = "") -> FingerSpec:
    """Write the calibrated finger file (atomically, after parse_finger accepts its text);
    returns the FingerSpec it describes. ValueError (one line) when a fitted value leaves
    the finger file's ranges."""
    text = calibrated_finger_text(model, res, observations_sha256, observations_source)
    spec = parse_finger(text, str(path))
    write_text(path, text)
    return spec


#: The installed package's folders: a calibrated file written there would replace what
#: every later call reads (contract/fingers/paper.toml is the default finger).
PACKAGE_FOLDERS = ("contract", "predictor", "fem", "surrogate", "workflow", "apps")


def outside_package(path: str | Path) -> None:
    """ValueError (one line) when ``path`` resolves inside one of PACKAGE_FOLDERS."""
    from predictor.defaults import ROOT

    where = Path(path).resolve()
    for name in PACKAGE_FOLDERS:
        folder = (ROOT / name).resolve()
        if where == folder or folder in where.parents:
            raise ValueError(f"--out {path}: inside the package ({folder}); write the calibrated finger elsewhere")
