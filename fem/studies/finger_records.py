"""Whole-finger FEM cases as records: one JSON record and one render per case, and the rules
the finger studies share (fem.studies.finger_cases, finger_grid, grasp_cases, bench_finger),
as fem.studies.joint_cases is the joint studies'. No command of its own.

* CASES: the finger validation cases (name, P1, P2, gravity), pressures MPa (issue 14 §4,
  fem.studies.finger_cases' default table), each named as ``case_name`` spells it,
  ``gravity_P1_P2`` or ``free_P1_P2``.
* A case is one ``FingerSolver.solve`` (fem.solvers.finger) on one mesh built once
  (``solve_cases``: the mesh build and the form compilation, ``setup_s``, are reported apart
  from each case's solve time, ``fem_s``), written atomically (``write_case``) as
  ``<case><suffix>.json`` (FingerResult.summary plus the run's settings, fem.artefacts.FINGER_CASE)
  and, where it converged, ``<case><suffix>.png``.
* The suffix (``default_suffix``): ``_hexN`` or ``_hexNsS`` for hexahedra (no colon in a
  file name), ``_mixed`` for tetrahedra in the mixed formulation, none for tetrahedra in
  displacement, then ``_plane`` with the plane X = 0: a default never names another kind's
  file, so a run on another discretisation leaves the committed cases alone, and a plane
  case never resumes from, nor replaces, a case without it.
* The render (``render``): the deformed finger (the full model, mirrored about z = 0), seen
  along -z in the global plane with a parallel projection, coloured by |u| (mm), rendered
  off-screen by pyvista with no colour bar or axes, so that predictor.validation.finger can
  draw the predictor's centre lines over it: the record's ``render`` gives the image's
  global extent [X0, X1, Y0, Y1] mm and the |u| colour range.
* The skip rule (``record_stands``, ``pending``): a case whose JSON exists for the same
  finger (by its values: contract.finger.same_finger), mesh and formulation
  (``case_settings``) is skipped, so a killed run resumes (the settings record the
  formulation only when it is not "displacement", ``"plane": true`` only with the plane,
  and the joints' digests, ``joints``, only when some joint is not the paper's, so the
  cases solved before the mixed formulation, the plane and joint files existed stand). A
  solve that does not converge is recorded as such (``converged: false``, no figures) with
  the solver controls it ran with (``solver``, ``solver_settings``), and is tried again
  when they change.
* The studies' command-line pieces: ``part_slice`` (``--part K/N``) and
  ``parse_on_one_rank`` (mpirun refused before parsing, so that no output folder is made).

Data flow: cases [(name, P1, P2, gravity)] -> ``pending`` (those whose record does not
stand, each with its path) -> ``solve_cases`` (one FingerSolver) -> ``write_case`` (render,
then record) -> ``<out>/<case><suffix>.json`` and ``.png``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np
import pyvista  # before dolfinx: VTK crashes (std::bad_alloc) if loaded after it
from mpi4py import MPI

from contract import cli
from contract.files import atomic_path, json_safe
from contract.joint import is_paper_joint, joint_digest
from fem.artefacts import FINGER_CASE
from fem.mesh.geometry import JointGeometry, finger_joints
from fem.options import one_rank
from fem.physics.finger import rotation_matrix
from fem.solvers.finger import FINGER_CONFIG, FingerLoad, FingerSolver, same_settings
from fem.solvers.joint import config_for

#: (name, P1, P2, gravity)
CASES = [
    ("free_0.05_0.05", 0.05, 0.05, False), ("free_0.1_0.1", 0.1, 0.1, False),
    ("free_0.05_-0.05", 0.05, -0.05, False), ("free_0.1_-0.1", 0.1, -0.1, False),
    ("gravity_-0.1_0.1", -0.1, 0.1, True), ("gravity_0.1_-0.1", 0.1, -0.1, True),
    ("gravity_0.2_0.2", 0.2, 0.2, True), ("gravity_0.3_0.3", 0.3, 0.3, True),
    ("gravity_-0.2_0.1", -0.2, 0.1, True), ("gravity_0.3_-0.3", 0.3, -0.3, True),
    ("gravity_-0.1_-0.25", -0.1, -0.25, True), ("gravity_0.15_0", 0.15, 0.0, True),
    ("gravity_0_0.25", 0.0, 0.25, True), ("gravity_-0.15_-0.05", -0.15, -0.05, True),
    ("gravity_0.25_0.1", 0.25, 0.1, True), ("gravity_0.1_0.3", 0.1, 0.3, True),
    ("gravity_0.05_-0.2", 0.05, -0.2, True), ("gravity_-0.25_0.2", -0.25, 0.2, True),
]
WINDOW = (900, 900)   # render size, pixels


def case_name(p1: float, p2: float, gravity: bool = True) -> str:
    """A case's name as CASES spell it: gravity_P1_P2 or free_P1_P2 (MPa, %g)."""
    return f"{'gravity' if gravity else 'free'}_{p1:g}_{p2:g}"


def default_suffix(joint: JointGeometry, formulation: str, plane: bool = False) -> str:
    """The default file-name suffix of a finger whose joints are ``joint`` (module
    docstring): ``_hexN`` or ``_hexNsS`` on hexahedra (fem.mesh.discretisation.Discretisation.key's
    spelling; a colon is no file name), ``_mixed`` on tetrahedra in the mixed formulation,
    else none; then ``_plane`` with the plane X = 0."""
    if joint.divisions:
        kind = f"_hex{joint.divisions}" + (f"s{joint.hex_size:g}" if joint.hex_size else "")
    else:
        kind = "" if formulation == "displacement" else f"_{formulation}"
    return kind + ("_plane" if plane else "")


def case_settings(finger, geometry, formulation: str, plane: bool = False) -> dict:
    """The settings a case records, by which a later run resumes it (fem.solvers.finger.same_settings;
    module docstring): the finger's digest and geometry, and only where they differ from
    the first cases' the formulation (not "displacement"), the plane X = 0 (on) and the
    joints' digests (some joint not the paper's)."""
    settings = {"finger_sha256": finger.digest, "geometry": geometry.as_dict()}
    if formulation != "displacement":
        settings["formulation"] = formulation
    if plane:
        settings["plane"] = True
    joints = finger_joints(finger)
    if not all(is_paper_joint(j) for j in joints):
        settings["joints"] = [joint_digest(j) for j in joints]
    return settings


def solver_settings(geometry) -> dict:
    """The controls FingerSolver solves with on ``geometry`` (fem.solvers.finger.FINGER_CONFIG,
    fem.solvers.joint.config_for), as a case records them (``solver``)."""
    return json_safe(asdict(config_for(geometry, FINGER_CONFIG)))


def record_stands(path: Path, settings: dict, solver: dict, finger) -> bool:
    """Whether the case record at ``path`` stands, so that a run skips the case (module
    docstring): it is a JSON object of the same ``settings`` (fem.solvers.finger.same_settings: the
    same finger by its values, mesh, formulation, ...) that converged, or that failed with
    the same ``solver`` controls. A missing, damaged or foreign file does not stand."""
    if not path.is_file():
        return False
    try:
        done = json.loads(path.read_text())
    except ValueError:
        return False        # a foreign or damaged file: solve again and replace it
    if not isinstance(done, dict):
        return False
    # A converged case stands while the finger and mesh are the same; a failed one is
    # tried again once the solver's controls change.
    return same_settings(done.get("settings"), json_safe(settings), finger) and bool(
        done.get("converged") or done.get("solver") == solver)


def pending(cases: list, out: Path, suffix: str, settings: dict, solver: dict, finger) -> list:
    """The cases [(name, P1, P2, gravity)] whose record ``out/<name><suffix>.json`` does not
    stand (``record_stands``), each with that path appended: what a run solves."""
    paths = [(case, Path(out) / f"{case[0]}{suffix}.json") for case in cases]
    return [(*case, path) for case, path in paths if not record_stands(path, settings, solver, finger)]


def part_slice(ap: cli.Parser, text: str) -> slice:
    """The cases of ``--part K/N``: every N-th starting at the K-th (a usage error unless
    1 <= K <= N)."""
    try:
        k, n = (int(v) for v in text.split("/"))
        assert 1 <= k <= n
    except (ValueError, AssertionError):
        ap.error(f"--part {text!r}: use K/N with 1 <= K <= N")
    return slice(k - 1, None, n)


def render(solver: FingerSolver, path: Path, outline: np.ndarray | None = None) -> dict:
    """The deformed finger in the global plane, coloured by |u|, to ``path`` (PNG, atomic).
    ``outline`` (n, 2) mm, global: a closed polyline drawn over it in black (fem.studies.grasp_cases:
    the object's outline), which the extent then takes in too. Returns {"extent_mm": [X0,
    X1, Y0, Y1], "u_max_mm": ..., "cmap": ...} for the overlay."""
    from dolfinx import plot

    finger = solver.finger
    field = solver.displacement()       # u in its own P2 space (mixed: w's u block)
    topology, cell_types, x = plot.create_vtk_mesh(field.function_space)
    u = field.x.array.reshape(-1, 3)
    grid = pyvista.UnstructuredGrid(topology, cell_types, x)
    grid.point_data["u"] = u.copy()
    mirror = grid.copy()
    mirror.points[:, 2] *= -1
    mirror.point_data["u"][:, 2] *= -1
    full = grid.merge(mirror)
    moved = full.points + full.point_data["u"]
    turn = rotation_matrix(finger.base_angle)
    xy = moved[:, :2] @ turn.T + [0.5 * finger.base_gap, 0.0]
    full.points = np.column_stack([xy, moved[:, 2]])
    full.point_data["|u|"] = np.linalg.norm(full.point_data["u"], axis=1)
    shown = xy if outline is None else np.vstack([xy, outline])
    lo, hi = shown.min(0) - 15.0, shown.max(0) + 15.0
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo).max()
    extent = [centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half]
    umax = float(full.point_data["|u|"].max())
    p = pyvista.Plotter(off_screen=True, window_size=WINDOW, border=False)
    p.set_background("white")
    p.add_mesh(full.extract_surface(nonlinear_subdivision=0, algorithm='dataset_surface'), scalars="|u|", cmap="viridis",
               clim=(0.0, umax), show_scalar_bar=False)
    if outline is not None:
        # above the finger (|z| <= width / 2) so that the camera on +z sees it on top
        line = pyvista.lines_from_points(np.column_stack([outline, np.full(len(outline), 100.0)]), close=True)
        p.add_mesh(line, color="black", line_width=3)
    p.enable_parallel_projection()
    p.camera.focal_point = (centre[0], centre[1], 0.0)
    p.camera.position = (centre[0], centre[1], 1000.0)
    p.camera.up = (0.0, 1.0, 0.0)
    p.camera.parallel_scale = half
    with atomic_path(path) as tmp:
        p.screenshot(str(tmp))
    p.close()
    return {"extent_mm": extent, "u_max_mm": umax, "cmap": "viridis"}


def parse_on_one_rank(ap: cli.Parser, argv) -> tuple[argparse.Namespace, MPI.Comm]:
    """(args, MPI.COMM_WORLD) of a case study's command line (here, fem.studies.finger_grid,
    grasp_cases): mpirun refused (one_rank) before parsing, so that no output folder is made."""
    comm = MPI.COMM_WORLD
    one_rank(ap, comm)
    return ap.parse_args(argv), comm


def write_case(path: Path, record: dict, fmt, solver: FingerSolver, converged: bool,
               outline: np.ndarray | None = None) -> None:
    """Write one solved case: if ``converged``, its ``render`` (the deformed ``solver``,
    ``outline`` over it: ``render``) beside ``path`` as .png and into ``record``; then
    ``record`` to ``path`` in ``fmt`` (a fem.artefacts format: atomic), the folder
    made if needed. Shared by solve_cases and fem.studies.grasp_cases."""
    if converged:
        record["render"] = render(solver, path.with_suffix(".png"), outline)
    cli.make_output_folder(path.parent)
    fmt.write(path, record)


def solve_cases(todo: list, geometry, formulation: str, plane: bool, settings: dict, solver: dict,
                comm: MPI.Comm = MPI.COMM_WORLD, after: Callable[[Path, dict], None] | None = None) -> None:
    """Solve the cases ``todo`` [(name, P1, P2, gravity, path)] on one FingerSolver built
    once (the mesh build and the forms' compilation are ``setup_s``), each written to its
    ``path`` (FINGER_CASE, atomic; the folder made if needed) with its settings and solver
    controls (``case_settings``, ``solver_settings``: the resume key) and, if converged,
    its render beside it (``render``); one line per case on stdout. ``after(path, record)``
    is called once each record is written (fem.studies.finger_grid: its summary)."""
    t0 = time.perf_counter()
    fem_solver = FingerSolver(geometry, comm, formulation=formulation, plane=plane)
    setup_s = time.perf_counter() - t0
    for name, p1, p2, gravity, path in todo:
        res = fem_solver.solve(FingerLoad((p1, p2), gravity))
        record = {"case": name, **res.summary(), "fem_s": res.wall_time, "fem_cpu_s": res.cpu_time,
                  "load_average": os.getloadavg()[0], "setup_s": setup_s,
                  "mesh": fem_solver.mesh_info(), "formulation": formulation, "settings": settings,
                  "solver": solver,
                  "ranks": comm.size}
        write_case(path, record, FINGER_CASE, fem_solver, res.converged)
        print(f"{name}: " + (f"converged, tip ({res.tip[0]:.3f}, {res.tip[1]:.3f}) mm, "
                             f"{math.degrees(res.tip_angle):.2f} deg" if res.converged else
                             f"did not converge ({res.reason}), no figures") + f", {res.wall_time:.0f} s", flush=True)
        if after is not None:
            after(path, record)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.studies.finger_cases")
