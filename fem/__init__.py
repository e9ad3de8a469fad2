"""FEM ground truth of the bellow joint and the whole finger (DOLFINx 0.5, gmsh); see
docs/physics.md, and docs/packages.md for the map of the packages.

Five sub-packages, each importing only those before it (tests/test_layers.py checks):

* ``fem.mesh``: geometries, discretisations (value objects, no dolfinx) and the mesh builders;
* ``fem.physics``: materials, contact terms and the joint's ``Problem`` (UFL forms);
* ``fem.solvers``: the load-path Newton solver and the joint, finger and grasp drivers;
* ``fem.cli``: the command lines a user types (``python -m fem.cli.solve``, ``fem.cli.finger``,
  ``fem.cli.render``);
* ``fem.studies``: studies, case tables and benches that write committed artefacts
  (``python -m fem.studies.mesh_study`` ...).

At the root, two neutral modules (no dolfinx): ``fem.artefacts``, the formats of the
studies' JSON artefacts (predictor and apps read them), and ``fem.options``, the command-line
options the fem commands, the studies and workflow's commands share. Nothing outside fem.cli
and fem.studies imports those two (the library never does; apps run them as subprocesses). ``python -m fem.finger``
and ``python -m fem.solve``, the old paths of the two commands users type most, are thin
aliases (fem/finger.py, fem/solve.py) that run the new ones. Every package file stays
import-free so that ``fem.cli.render`` can load VTK before dolfinx. The joint contract, the
finger description, the command-line contract and atomic files live on the floor below
every package: ``contract`` (dolfinx-free).
"""
