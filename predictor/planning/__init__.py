"""Grasp planning as a library (floor 4 of predictor): which pressures hold an object or put
the fingertip where asked.

* ``atlas``: the grasp atlas over the pressure plane (``grasp_atlas``, ``Atlas``,
  ``atlas_from_json``; its command line is predictor.cli.atlas);
* ``inversion``: inverse pressures for a goal (hold, tip position), verified by the forward
  solve (``inverse_pressures``, ``InverseProblem``, ``gauss_newton``);
* ``track``: fingertip goals along a trajectory, warm-started (``Tracker``).

Imports: contract, predictor.artefacts, predictor.defaults, predictor.model,
predictor.solvers, predictor.nn.
"""
