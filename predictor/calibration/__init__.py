"""Calibrating a gripper to measured gestures (floor 5 of predictor; docs/calibration.md).

* ``model``: the parameters theta, the calibrated forward model and its exact sensitivities
  (``CalibrationModel``, ``parameter_table``);
* ``observations``: the measurement files (``softjoint-observations/1``);
* ``fit``: the weighted least squares, covariance and identifiability;
* ``file``: the calibrated finger file written from a fit;
* ``recovery``: the recovery study on a known truth; ``fem``: the calibration against the
  whole-finger FEM of a different finger; ``bench``: the timing of one calibration;
  ``plot``: the before/after figure.

Imports: contract, fem.artefacts (a format, no dolfinx), predictor.artefacts,
predictor.defaults, predictor.model, predictor.solvers, predictor.nn, predictor.planning.
"""
