"""The equilibrium solvers: from pressures to the gesture tau with zero Equation-1 residual
(floor 2 of predictor).

* ``solve``: ``solve`` (the front door: Newton, L-BFGS, the contact ramp), ``gesture_result``,
  ``APPROACH``; ``options``: ``SolverOptions`` (method, tolerances, limits);
* ``newton``, ``lm`` (Levenberg-Marquardt with the complementarity of contact), ``ramp``
  (the pressure ramp of a solve with contact, snap-off), ``plane_newton`` (the plane
  X = 0 held by an active-set KKT Newton, then the penalty's own root), ``graphs`` (the residual as
  recorded graphs), ``jacobians`` (dR/dx by forward differences), ``result``
  (``GestureResult`` and its JSON summary), ``progress`` (heartbeat lines on stderr);
* ``problem``: the question put to the solvers, checked once for every tool and the API
  (``Check``, ``load_problem``: GripperProblem of predictor.cli.gesture's defaults,
  ``finger_error``, ``placement_error``) and the tools' shared options.

Imports: contract, surrogate, predictor.defaults, predictor.model.
"""
