"""Gripper gesture predictor (docs/gripper.md). The grasp-planning API (predictor.api) is
re-exported here: load_gripper, solve_gesture, grasp_atlas, inverse_pressures, track_tip,
Gripper, Gesture. They are loaded on first use, so that ``python -m predictor.cli.<tool>`` does
not import its own module twice (and importing predictor stays light: no torch, no dolfinx).

The sub-packages by concern, each importing only those before it (docs/packages.md):
model -> solvers -> nn -> planning -> calibration -> validation -> cli; at the root ``api``
(the Python front door), the neutral ``defaults`` (where the default models are) and
``artefacts`` (the JSON formats), and the old command paths (aliases)."""

__all__ = ["Gesture", "Gripper", "grasp_atlas", "inverse_pressures", "load_gripper", "solve_gesture", "track_tip"]


def __getattr__(name):
    if name in __all__:
        from predictor import api

        return getattr(api, name)
    raise AttributeError(f"module 'predictor' has no attribute {name!r}")
