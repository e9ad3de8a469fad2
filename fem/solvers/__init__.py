"""How the FEM problems are solved (floor 3 of fem): the library's front door.

* ``block_krylov``: block GMRES for several right-hand sides (the sensitivities);
* ``load_path``: ``LoadPathSolver``, the load-path Newton solver of any Problem (stepping,
  cut-back, MUMPS, sensitivities), ``Probes``;
* ``joint``: ``Load``, ``SolveResult``, ``JointSolver`` (and ``beam_solver``): the joint's driver;
* ``finger``: ``FingerSolver``, the whole finger's driver (the plane X = 0 included), ``FingerResult``;
* ``grasp``: ``GraspSolver``, the finger holding a rigid object along the predictor's history;
* ``transfer``: a joint solve seeded from another discretisation's answer.

Imports: contract, fem.mesh, fem.physics (never fem.cli or fem.studies).
"""
