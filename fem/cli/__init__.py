"""The FEM's command lines (floor 4 of fem): each module a ``main`` with ``--help`` and ``--json``.

* ``solve``: one joint load case (``python -m fem.cli.solve``; old path ``fem.solve``);
* ``finger``: one whole-finger gesture or grasp (``python -m fem.cli.finger``; old path ``fem.finger``);
* ``render``: the off-screen pyvista render of the joint (pyvista before dolfinx);
* ``xdmf``: a solve's displacement field to XDMF (+ HDF5), published atomically.

Their shared options are fem.options (a neutral module at fem's root, shared with the
studies and workflow's commands).

Imports: contract, fem.mesh, fem.physics, fem.solvers, fem.artefacts, fem.options (never
fem.studies).
"""
