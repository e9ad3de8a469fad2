"""Mesh conversion: a geometry builder's gmsh model -> distributed DOLFINx mesh + tags.

Collective over ``comm``: rank 0 builds and meshes the gmsh model; ``model_to_mesh``
distributes it. Only entities in physical groups are imported (fem.geometry.TAGS).
"""

from __future__ import annotations

from dataclasses import dataclass

from mpi4py import MPI

from fem.geometry import BeamGeometry, JointGeometry, build_beam, build_joint


@dataclass
class MeshData:
    """A distributed mesh with its cell tags (volumes) and facet tags (surfaces)."""

    mesh: object
    cell_tags: object
    facet_tags: object
    geometry: JointGeometry | BeamGeometry


def create_mesh(geometry: JointGeometry | BeamGeometry, comm: MPI.Comm = MPI.COMM_WORLD) -> MeshData:
    """Build ``geometry`` with gmsh on rank 0 of ``comm`` and distribute it (collective)."""
    from dolfinx.io import gmshio

    builder = build_joint if isinstance(geometry, JointGeometry) else build_beam
    model = None
    if comm.rank == 0:
        model = builder(geometry)
    # Rank 0 raising in the builder would hang the others in model_to_mesh: share status.
    if comm.bcast(model is not None if comm.rank == 0 else None, root=0) is False:
        raise RuntimeError("gmsh geometry build failed on rank 0")
    if comm.rank != 0:
        import gmsh
        model = gmsh.model
    mesh, cell_tags, facet_tags = gmshio.model_to_mesh(model, comm, 0, gdim=3)
    return MeshData(mesh, cell_tags, facet_tags, geometry)
