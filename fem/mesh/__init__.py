"""What the FEM is solved on: geometries, discretisations and meshes (floor 1 of fem).

* ``geometry``: ``JointGeometry``, ``BeamGeometry``, ``FingerGeometry`` and their gmsh
  builders (``build_joint``, ``build_beam``, ``build_finger``), the physical-group TAGS;
* ``discretisation``: the discretisation (mesh, formulation, quadrature, penalty), PAPER
  and PRODUCTION, and ``SolverConfig`` (value objects, no dolfinx);
* ``data``: ``MeshData``, the distributed mesh with its tags every builder returns;
* ``hexahedra``: swept Q2 hexahedral meshes of the joint and the finger (no gmsh);
* ``build``: ``create_mesh`` (collective), the builder registry: gmsh or hexahedra.

Imports: contract only (no other fem sub-package).
"""
