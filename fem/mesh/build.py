"""Mesh conversion: a geometry builder's gmsh model -> distributed DOLFINx mesh + tags.

Collective over ``comm``: rank 0 builds and meshes the gmsh model; ``model_to_mesh``
distributes it. Only entities in physical groups are imported (fem.mesh.geometry.TAGS). A joint
of hexahedral divisions (JointGeometry.divisions > 0), or a finger whose joint has them, is
meshed by fem.mesh.hexahedra instead (one structured grid, no gmsh).
"""

from __future__ import annotations

from mpi4py import MPI

from fem.mesh.geometry import (BeamGeometry, FingerGeometry, JointGeometry, build_beam, build_finger,
                               build_joint)
from fem.mesh.data import MeshData
from fem.mesh.hexahedra import create_hex_finger_mesh, create_hex_mesh

BUILDERS = {JointGeometry: build_joint, BeamGeometry: build_beam, FingerGeometry: build_finger}


def create_mesh(geometry: JointGeometry | BeamGeometry | FingerGeometry, comm: MPI.Comm = MPI.COMM_WORLD) -> MeshData:
    """Build ``geometry`` with gmsh on rank 0 of ``comm`` and distribute it (collective); a
    joint with hexahedral ``divisions``, or a finger whose joint has them, is built by
    fem.mesh.hexahedra instead."""
    from dolfinx.io import gmshio

    if isinstance(geometry, JointGeometry) and geometry.divisions:
        return create_hex_mesh(geometry, comm)
    if isinstance(geometry, FingerGeometry) and geometry.divisions:
        return create_hex_finger_mesh(geometry, comm)

    import gmsh

    builder = BUILDERS[type(geometry)]
    error = None
    if comm.rank == 0:
        try:
            builder(geometry)
        except Exception as exc:   # raise on every rank, or the others hang below
            error = f"geometry build failed: {exc}"
    error = comm.bcast(error, root=0)
    if error:
        raise RuntimeError(error)
    mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    return MeshData(mesh, cell_tags, facet_tags, geometry)
