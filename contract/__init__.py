"""The contract floor: what every layer of softjoint agrees on (docs/README.md).

Imports only the standard library and numpy (never dolfinx, gmsh or torch), so that any
layer may import it: apps -> predictor -> surrogate -> workflow -> fem, all on this floor.

* ``contract.spec``: the joint contract: the input box (P MPa, F1 F2 N, M N·mm), the ten
  anchor points, phi_end, the mirror map and the box check (docs/physics.md).
* ``contract.finger``: the finger description (an ordered chain of joints and rigid parts,
  TOML files, ``contract/fingers/paper.toml`` the paper's), its bounds, load, save and
  plain-dict round trip (docs/gripper.md, docs/formats.md).
* ``contract.joint``: the joint description (geometry, material law, input box, anchors,
  mesh defaults; TOML files, ``contract/joints/paper.toml`` the paper's), its shape rules,
  load, plain-dict round trip and digest (docs/joints.md).
* ``contract.cli``: the command-line contract every ``python -m`` tool follows (``--json``,
  one-line errors with exit 2, outputs checked before work).
* ``contract.files``: atomic result files and strict JSON.
* ``contract.records``: artefact formats (the key paths and types an artefact's readers rely
  on), checked by its writer before writing and by its readers on load; figure targets.
"""
