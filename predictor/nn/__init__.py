"""Neural gesture predictors: pressures -> tau in one network call (floor 3 of predictor).

* ``networks``: the networks and their configurations (``VARIANTS``);
* ``train``: their training (equilibrium loss or the solvers' labels);
* ``eval``: residual statistics of a network and of its delivered answers;
* ``answer``: a network's answers in the solvers' result format (``NNGestureResult``);
* ``checkpoint``: integrity-checked checkpoint files (``load_predictor``).

``python -m predictor.nn`` (``__main__``, the old path of the training command) runs
predictor.cli.nn without importing it (runpy).

Imports: contract, surrogate, predictor.defaults, predictor.model, predictor.solvers.
"""
