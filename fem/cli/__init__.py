"""The FEM's command lines (floor 4 of fem): each module a ``main`` with ``--help`` and ``--json``.

* ``solve``: one joint load case (``python -m fem.cli.solve``; old path ``fem.solve``);
* ``finger``: one whole-finger gesture or grasp (``python -m fem.cli.finger``; old path ``fem.finger``);
* ``render``: the off-screen pyvista render of the joint (pyvista before dolfinx);
* ``options``: the options the fem commands and studies share (no dolfinx), ``on_root``,
  ``one_rank``;
* ``xdmf``: a solve's displacement field to XDMF (+ HDF5), published atomically.

Imports: contract, fem.mesh, fem.physics, fem.solvers (never fem.studies).
"""
