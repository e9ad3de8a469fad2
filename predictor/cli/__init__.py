"""The command lines a user types (floor 7 of predictor): argparse, one-line errors, exit 2.

* ``gesture``: the static gesture for given pressures; ``atlas``: the grasp atlas;
  ``inverse``: inverse pressures and tracking; ``calibrate``: calibration and its studies;
  ``nn``: training of a network; ``figures``: the paper's gesture figures (``make gestures``).

The old paths (``python -m predictor.gesture``, ...) are aliases at predictor's root.

Imports: any predictor sub-package below it (never predictor.api, the Python front door),
contract, surrogate.
"""
