"""A distributed mesh with its tags: what every mesh builder (fem.mesh.build's gmsh models,
fem.mesh.hexahedra's structured hexahedra) returns and every problem (fem.physics.problem,
fem.physics.finger) is built on. No dolfinx import: the fields hold dolfinx objects, typed loosely."""

from __future__ import annotations

from dataclasses import dataclass

from fem.mesh.geometry import BeamGeometry, FingerGeometry, JointGeometry


@dataclass
class MeshData:
    """A distributed mesh with its cell tags (volumes) and facet tags (surfaces)."""

    mesh: object
    cell_tags: object
    facet_tags: object
    geometry: JointGeometry | BeamGeometry | FingerGeometry
