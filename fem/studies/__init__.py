"""Studies, case tables and benches of the FEM (floor 5 of fem, the top): each a command
(``python -m fem.studies.NAME``) that writes committed artefacts, never imported by the
library (fem.mesh, fem.physics, fem.solvers) nor by fem.cli.

* ``artefacts``: the formats of the JSON artefacts written here (contract.records);
* the joint: ``validation`` (against ``elastica``, the exact references), ``materials_check``,
  ``self_contact``, ``joint_cases`` (the case records that ``mesh_study`` and
  ``mesh_causes`` share), ``bench_joint``;
* the finger: ``finger_cases`` (and ``finger_grid`` over a pressure grid), ``grasp_cases``,
  ``bench_finger``.

Imports: contract and every fem sub-package below it.
"""
