"""FEM ground truth of the bellow joint (DOLFINx 0.5, gmsh); see docs/physics.md.

Public API (import the modules; this package file stays import-free so that
``fem.render`` can load VTK before dolfinx):

* ``fem.geometry``: ``JointGeometry``, ``BeamGeometry``, ``build_joint``, ``build_beam``
* ``fem.mesh``: ``create_mesh`` (collective)
* ``fem.problem``: the physics as a frozen ``Problem`` (energy, loads, boundary conditions,
  contact) that ``joint_problem`` and ``fem.finger.finger_problem`` build
* ``fem.load_path``: ``LoadPathSolver``, the load-path Newton solver of any ``Problem``
  (stepping, cut-back, MUMPS, sensitivities), and ``SolverConfig``
* ``fem.solver``: ``Load``, ``Material``, ``SolverConfig``, ``JointSolver``, ``SolveResult``
* ``fem.xdmf``: the displacement field of a solve to XDMF (atomic)
* the joint contract, the finger description, the command-line contract and atomic files
  live on the floor below every package: ``contract`` (dolfinx-free)
* ``fem.elastica``: exact elastica references; ``fem.validation``: the beam against them
* command lines (each with ``--help`` and ``--json``; shared options in ``fem.options``):
  ``fem.solve`` (one load case), ``fem.validation`` (accuracy vs the elastica),
  ``fem.bench_joint`` (solver timings), ``fem.mesh_study``, ``fem.self_contact``,
  ``fem.render``
"""
