"""FEM ground truth of the bellow joint (DOLFINx 0.5, gmsh); see DESIGN.md §3.

Public API (import the modules; this package file stays import-free so that
``fem.render`` can load VTK before dolfinx):

* ``fem.geometry``: ``JointGeometry``, ``BeamGeometry``, ``build_joint``, ``build_beam``
* ``fem.mesh``: ``create_mesh`` (collective)
* ``fem.solver``: ``Load``, ``Material``, ``SolverConfig``, ``JointSolver``, ``SolveResult``
* ``fem.spec``: the joint contract (input box, phi_end, mirror); ``fem.files``: atomic
  result files; ``fem.cli``: the shared command-line parser (all three dolfinx-free)
* ``fem.elastica``: exact elastica references; ``fem.validation``: the beam against them
* command lines (each with ``--help`` and ``--json``; shared options in ``fem.options``):
  ``fem.solve`` (one load case), ``fem.validation`` (accuracy vs the elastica),
  ``fem.bench_joint`` (solver timings), ``fem.mesh_study``, ``fem.self_contact``,
  ``fem.render``
"""
