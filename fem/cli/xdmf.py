"""Displacement fields to XDMF (+ HDF5), published atomically (collective).

``write_xdmf(path, solver)`` writes the mesh and the displacement u (mm) of a solved model
(fem.solvers.joint.JointSolver, fem.solvers.finger.FingerSolver: anything with ``comm``, ``mesh_data``
and ``displacement()``, u in its own space: the mixed formulation's pressure is not
written) to NAME.xdmf and the NAME.h5 it names. Every rank writes its part into a hidden
folder beside ``path``; rank 0 then fsyncs both files and renames them into place, .h5
first, so a reader never sees a half-written pair.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from fem.options import on_root


def write_xdmf(path: str | Path, solver) -> None:
    """u of ``solver`` to ``path`` (.xdmf) and its .h5 (collective; module docstring).
    An OSError on rank 0 is raised on every rank."""
    from dolfinx.io import XDMFFile

    comm, path = solver.comm, Path(path)
    tmp = None
    if comm.rank == 0:
        tmp = tempfile.mkdtemp(prefix=f".{path.stem}.", suffix=".tmp", dir=path.parent)
    tmp = Path(comm.bcast(tmp, root=0))
    try:
        with XDMFFile(comm, str(tmp / path.name), "w") as f:
            f.write_mesh(solver.mesh_data.mesh)
            f.write_function(solver.displacement())
        comm.barrier()

        def publish():
            for name in (path.with_suffix(".h5").name, path.name):
                with open(tmp / name, "rb+") as fh:
                    os.fsync(fh.fileno())
                os.replace(tmp / name, path.parent / name)

        on_root(comm, publish)
    finally:
        if comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.cli.solve --xdmf OUT.xdmf")
