"""FEM ground truth of the bellow joint (DOLFINx 0.5, gmsh); see DESIGN.md §3.

Public API (import the modules; this package file stays import-free so that
``fem.render`` can load VTK before dolfinx):

* ``fem.geometry``: ``JointGeometry``, ``BeamGeometry``, ``build_joint``, ``build_beam``
* ``fem.mesh``: ``create_mesh`` (collective)
* ``fem.solver``: ``Load``, ``Material``, ``SolverConfig``, ``JointSolver``, ``SolveResult``
* ``fem.elastica``: exact elastica references; ``fem.benchmarks``: the beam checks
* command lines: ``fem.solve``, ``fem.benchmarks``, ``fem.bench``, ``fem.mesh_study``,
  ``fem.self_contact``, ``fem.render``
"""
