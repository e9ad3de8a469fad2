"""Off-screen pyvista render of the joint: undeformed geometry and one deformed case.

    python -m fem.cli.render --out results/fem/joint.png [--p 0.2 --f2 -1 --m 20] [--joint FILE]

The half-model is mirrored about z = 0 so the full joint is shown. Left: the undeformed
joint, cut open at z = 0 to show the two chambers and bellow cells. Right: the deformed
joint coloured by displacement magnitude |u| (mm), with the 10 anchor points (like the
paper's Figure 2C). The joint is ``--joint FILE`` (contract.joint; default the paper's,
contract/joints/paper.toml), meshed and solved with its [mesh] defaults (the paper's:
the production hex2:3 mixed) unless ``--mesh-size`` / ``--wall-mesh-size`` (tetrahedra),
``--divisions`` (hexahedra) or ``--formulation`` is given (``make joint-render`` passes
the committed render's paper-fidelity 1.8 mm displacement); the mesh and formulation are
written in the picture. Its box bounds the load. A bad joint file exits 2 with one line.
Runs on one rank; needs no display (Plotter(off_screen=True)).
The PNG is written atomically (screenshot and caption go to a temporary name beside it);
``--json`` prints the file and the solve's figures, as ``fem.cli.solve --json`` does.
"""

from __future__ import annotations

import math
import sys
from dataclasses import asdict

import numpy as np
import pyvista  # before dolfinx: VTK crashes (std::bad_alloc) if loaded after it
from mpi4py import MPI

from contract import cli
from contract.files import atomic_path
from contract.joint import joint_digest
from fem.options import (add_divisions, add_formulation, add_joint, add_load, add_mesh_size, add_wall_mesh_size,
                         formulation_of, joint_geometry, joint_of, one_rank, parsed_load)
from fem.solvers.joint import JointSolver, Load


def _grid(solver):
    """pyvista grid of the P2 mesh with point data 'u' (mm), mirrored to z <= 0 too."""
    from dolfinx import plot

    field = solver.displacement()       # u in its own space (mixed: w's u block)
    topology, cell_types, x = plot.create_vtk_mesh(field.function_space)
    grid = pyvista.UnstructuredGrid(topology, cell_types, x)
    grid.point_data["u"] = field.x.array.reshape(-1, 3).copy()
    mirror = grid.copy()
    mirror.points[:, 2] *= -1
    mirror.point_data["u"][:, 2] *= -1
    full = grid.merge(mirror)
    full.point_data["|u| (mm)"] = np.linalg.norm(full.point_data["u"], axis=1)
    return grid, full


def render(solver, result, out: str) -> None:
    """Write the two-panel PNG for a solved ``result`` of ``solver`` to ``out`` (atomic)."""
    with atomic_path(out) as tmp:
        _render(solver, result, str(tmp))


def _render(solver, result, out: str) -> None:
    half, full = _grid(solver)
    deformed = full.copy()
    deformed.points += full.point_data["u"]
    L = result.load
    p = pyvista.Plotter(off_screen=True, shape=(1, 2), window_size=(1800, 800), border=False)
    p.subplot(0, 0)
    p.add_mesh(half.extract_surface(nonlinear_subdivision=0, algorithm='dataset_surface'), color="#7fa7d9",
               show_edges=True, edge_color="#30507a", line_width=0.3, smooth_shading=False)
    p.view_vector((0.35, 0.3, -1.0), viewup=(0, 1, 0))
    p.subplot(0, 1)
    p.add_mesh(deformed.extract_surface(nonlinear_subdivision=0, algorithm='dataset_surface'), scalars="|u| (mm)",
               cmap="viridis", scalar_bar_args={"title": "|u| (mm)", "vertical": True})
    anchors = np.column_stack([result.anchors, np.zeros(len(result.anchors))])
    p.add_points(anchors + [0, 0, solver.mesh_data.geometry.width / 2 + 0.5], color="red",
                 point_size=12, render_points_as_spheres=True)
    p.view_xy()
    p.camera.zoom(1.1)
    p.screenshot(out)
    p.close()
    _caption(out, [
        f"undeformed (half-model, cut open at z = 0); mesh {solver.mesh_data.geometry.mesh}, {solver.formulation}",
        f"P = {L.P:g} MPa, F1 = {L.F1:g} N, F2 = {L.F2:g} N, M = {L.M:g} N·mm;  "
        f"phi_end = {np.degrees(result.phi_end):.1f}°, cap {np.degrees(result.cap_rotation):.1f}°"])


def _caption(path: str, titles: list[str]) -> None:
    """Put one title over each panel with matplotlib (VTK text actors crash in this
    off-screen build when combined with subplots)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img = plt.imread(path)
    h, w = img.shape[:2]
    fig = plt.figure(figsize=(w / 100, h / 100 + 0.5), dpi=100)
    ax = fig.add_axes([0, 0, 1, h / (h + 50)])
    ax.imshow(img)
    ax.axis("off")
    for i, t in enumerate(titles):
        fig.text((i + 0.5) / len(titles), 1 - 25 / (h + 50), t, ha="center", va="center", fontsize=13)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.cli.render", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".png", default="results/fem/joint.png",
                  help="PNG file (default results/fem/joint.png)")
    add_joint(ap)
    add_load(ap, default=(0.2, 0.0, -1.0, 20.0))
    add_mesh_size(ap, None, shown="the joint file's [mesh] size")
    add_wall_mesh_size(ap)
    add_divisions(ap)
    add_formulation(ap, "the joint file's [mesh] formulation (the paper's: the production one)")
    comm = MPI.COMM_WORLD
    one_rank(ap, comm)
    args = ap.parse_args(argv)
    joint = joint_of(args)
    load = Load.from_array(parsed_load(ap, args, joint.input_box))
    with ap.errors():
        geo = joint_geometry(args, joint)
    solver = JointSolver.for_joint(joint, comm, geo, formulation=formulation_of(args, joint))
    result = solver.solve(load, allow_extrapolation=args.allow_extrapolation)
    if not result.converged:
        print(f"{ap.prog}: the solve did not converge: {result.reason}", file=sys.stderr)
        return 1
    with ap.errors():
        render(solver, result, args.out)
    if args.json:
        cli.print_json({"out": args.out, **result.summary(), "mesh": solver.mesh_info(), "geometry": asdict(geo),
                        "formulation": solver.formulation,
                        "joint": {"name": joint.name, "sha256": joint_digest(joint)}, "ranks": comm.size})
    else:
        print(f"wrote {args.out}: phi_end {math.degrees(result.phi_end):.1f} deg, "
              f"cap {math.degrees(result.cap_rotation):.1f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
