"""The physics of the FEM models, apart from how they are solved (floor 2 of fem).

* ``materials``: hyperelastic strain energies (UFL) and their closed-form stresses (numpy);
* ``contact``: the valley self-contact penalty of the bellow walls, ``ContactTerms``;
* ``object_contact``: the finger's contact with a rigid object (the predictor's law);
* ``plane_contact``: the finger's contact with the plane X = 0 where the mirror finger is;
* ``problem``: the frozen ``Problem`` (energy, loads, boundary conditions, contact) and
  ``joint_problem``, the joint's (and the benchmark beam's);
* ``finger``: ``finger_problem``, the whole finger's (every joint of its own law, rigid
  parts, gravity), from the joint's pieces.

Imports: contract, fem.mesh.
"""
