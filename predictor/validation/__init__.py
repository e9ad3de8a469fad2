"""The predictor judged against the FEM and timed (floor 6 of predictor): studies that write
committed artefacts, each with its command line, and the records they read.

* ``finger``: the gestures against the whole-finger FEM (``make validate-finger``);
* ``grasps``: the grasps against the FEM grasps (``make validate-grasps``);
* ``bench``: timings and residuals of the solvers and the networks (``make bench-predictor``);
* ``contact_change``: what a change of the model changed in the committed artefacts;
* ``cases``: which problem and discretisation each FEM record was solved for, read alike by
  ``finger`` and ``grasps`` (a library: no command, and no command imports another).

Imports: contract, fem.artefacts and fem.mesh.geometry (no dolfinx), predictor.artefacts,
predictor.defaults and every predictor sub-package below cli.
"""
