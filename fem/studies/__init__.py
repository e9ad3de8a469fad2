"""Studies, case tables and benches of the FEM (floor 5 of fem, the top): each a command
(``python -m fem.studies.NAME``) that writes committed artefacts, and the modules they
share; none of them imported by the library (fem.mesh, fem.physics, fem.solvers) nor by
fem.cli.

* the joint: ``validation`` (against ``elastica``, the exact references), ``materials_check``,
  ``self_contact``, ``joint_cases`` (the case records that ``mesh_study`` and
  ``mesh_causes`` share), ``bench_joint``;
* the finger: ``finger_cases`` (and ``finger_grid`` over a pressure grid), ``grasp_cases``,
  ``bench_finger``, and ``finger_records`` (the case records, renders and resume rule they
  share; no command).

A study imports no other study: what two share lives in a module without a command
(``joint_cases``, ``finger_records``, ``elastica``).

Their artefacts' formats are fem.artefacts (a neutral module at fem's root, read by predictor
and apps too).

Imports: contract, fem.artefacts, fem.options and every fem sub-package below it.
"""
