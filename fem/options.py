"""Command-line pieces shared by the fem tools (fem.cli, fem.studies) and workflow's campaign
commands, on top of :mod:`contract.cli` (no dolfinx; a neutral module at fem's root, so
that no package imports a command line for them).

* ``--mesh-size`` h (mm) in fem.mesh.discretisation.MESH_SIZE_RANGE, [0.3, 10];
* the load x = (P MPa, F1 N, F2 N, M N·mm): each option a finite number; the joint's box
  (the paper's: |P| <= 0.3, |F1|, |F2| <= 3, |M| <= 100) is checked by
  :func:`contract.spec.check_box` right after parsing (before any mesh), unless
  ``--allow-extrapolation``.
* ``--formulation`` {displacement, mixed} (fem.physics.problem: P2 displacement or Taylor-Hood
  u-p); None, its default, means the production formulation fem.mesh.discretisation.FORMULATION,
  which the tool resolves (this module imports no dolfinx);
* ``--joint FILE`` (:func:`add_joint`): a joint description file (contract.joint,
  docs/joints.md), read and checked while parsing (a bad file: one line, exit 2); absent:
  the paper's joint, contract/joints/paper.toml (:func:`joint_of`);
* ``--divisions`` N (:func:`add_divisions`): the joint as swept Q2 hexahedra of N divisions
  (fem.mesh.hexahedra) instead of tetrahedra;
* :func:`joint_geometry`: the joint of ``--mesh-size`` and ``--wall-mesh-size`` (tetrahedra)
  or ``--divisions`` (hexahedra): the joint file's shape and its [mesh] when none is given
  (without a joint file, the production mesh, JointGeometry's defaults: hexahedra "hex2:3");
  :func:`formulation_of` likewise;
* :func:`mesh_text`: an argparse type for a discretisation's mesh text ("H", "H:W", "hexN");
* :func:`on_root`: a writer that runs on rank 0 while every rank learns its error, so that
  under mpirun ``with ap.errors():`` exits every rank with 2 and nothing hangs.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from contract import cli
from contract.finger import FingerSpec
from contract.joint import FORMULATIONS, MAX_DIVISIONS, JointSpec, joint_arg, load_joint
from contract.spec import INPUT_BOX, INPUT_NAMES, INPUT_UNITS, OutOfBoxError, check_box
from fem.mesh.discretisation import MESH_SIZE, MESH_SIZE_RANGE, parse_mesh
from fem.mesh.geometry import FingerGeometry, JointGeometry, finger_joints

MESH_SIZE_TEXT = f"mm in [{MESH_SIZE_RANGE[0]:g}, {MESH_SIZE_RANGE[1]:g}]"
LOAD_HELP = ("chamber pressure P, MPa (signed)", "axial end force F1, N",
             "transverse end force F2, N", "end couple M about +z, N*mm")


def add_mesh_size(ap: cli.Parser, default: float | None, what: str = "tetrahedron size",
                  shown: str = "the production mesh") -> None:
    """``--mesh-size`` in mm (None: the geometry's default, described by ``shown``)."""
    shown = shown if default is None else f"{default:g}"
    ap.add_argument("--mesh-size", type=MESH_SIZE, default=default,
                    help=f"{what}, {MESH_SIZE_TEXT} (default {shown})")


def add_wall_mesh_size(ap: cli.Parser) -> None:
    """``--wall-mesh-size`` W in mm on the 1.2 mm chamber walls (None: ``--mesh-size``)."""
    ap.add_argument("--wall-mesh-size", type=MESH_SIZE, default=None,
                    help=f"tetrahedron size on the chamber walls, {MESH_SIZE_TEXT} (default: --mesh-size)")


def add_divisions(ap: cli.Parser) -> None:
    """``--divisions`` N: hexahedra of N divisions (fem.mesh.hexahedra), exclusive with the
    tetrahedron sizes (joint_geometry checks); ``--hex-size`` S grades them."""
    ap.add_argument("--divisions", type=cli.number(1, MAX_DIVISIONS, integer=True), default=None,
                    help=f"mesh the joint with swept Q2 hexahedra, N elements through every wall, N in [1, "
                         f"{MAX_DIVISIONS}] (instead of --mesh-size/--wall-mesh-size tetrahedra)")
    ap.add_argument("--hex-size", type=MESH_SIZE, default=None,
                    help=f"with --divisions N: grade the hexahedra, an interval of length d cut into N ceil(d / S) "
                         f"elements (walls keep N, long spans get at most S / N), S {MESH_SIZE_TEXT} (default: N)")


def mesh_text(text: str) -> str:
    """argparse type: a discretisation's mesh, "H", "H:W" (tetrahedra, mm) or "hexN"
    (hexahedra), checked by fem.mesh.discretisation.parse_mesh."""
    try:
        parse_mesh(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text.strip()


def add_formulation(ap: cli.Parser,
                    shown: str = "the production formulation (fem.mesh.discretisation.FORMULATION)") -> None:
    """``--formulation`` {displacement, mixed}; default None: the production formulation
    (fem.mesh.discretisation.FORMULATION) or, for a tool with ``--joint``, the joint file's
    (formulation_of), resolved by the tool and described by ``shown``."""
    ap.add_argument("--formulation", choices=FORMULATIONS, default=None,
                    help="finite elements: P2 displacement, or Taylor-Hood P2-P1 u-p 'mixed' "
                         f"(no volumetric locking); default: {shown}")


def add_joint(ap: cli.Parser) -> None:
    """``--joint FILE``: a joint description file, checked while parsing; default None,
    the paper's joint (:func:`joint_of`)."""
    ap.add_argument("--joint", type=joint_arg, default=None, metavar="FILE",
                    help="joint description file (docs/joints.md; default contract/joints/paper.toml, "
                         "the paper's joint)")


def joint_of(args) -> JointSpec:
    """The joint of ``--joint`` (add_joint), or the paper's when it is not given."""
    return getattr(args, "joint", None) or load_joint()


def joint_geometry(args, joint: JointSpec | None = None) -> JointGeometry:
    """The joint of ``args.mesh_size``, ``getattr(args, "wall_mesh_size")`` (mm;
    add_mesh_size with default None, add_wall_mesh_size) and ``getattr(args, "divisions")``
    (add_divisions) on the shape of ``joint``: the joint file's [mesh] when none is given;
    hexahedra of N divisions with --divisions; otherwise tetrahedra of H (default the
    joint's H, or JointGeometry's PAPER_MESH_SIZE when the joint is hexahedral) and W
    (default H, i.e. None). Without ``joint``: JointGeometry's production shape and mesh.
    Both kinds at once: ValueError."""
    base = JointGeometry(**joint.geometry_kwargs()) if joint is not None else JointGeometry()
    wall, divisions = getattr(args, "wall_mesh_size", None), getattr(args, "divisions", None)
    hex_size = getattr(args, "hex_size", None)
    if divisions is not None and (args.mesh_size is not None or wall is not None):
        raise ValueError("--divisions (hexahedra) excludes --mesh-size and --wall-mesh-size (tetrahedra)")
    if hex_size is not None and divisions is None:
        raise ValueError("--hex-size grades hexahedra: give --divisions too")
    if divisions is not None:
        return replace(base, divisions=int(divisions), hex_size=hex_size)
    if args.mesh_size is None and wall is None:
        return base
    return replace(base, mesh_size=args.mesh_size or base.mesh_size, wall_mesh_size=wall, divisions=0, hex_size=None)


def formulation_of(args, joint: JointSpec) -> str:
    """``--formulation`` (add_formulation, if the tool has it), or the joint file's [mesh]
    formulation."""
    return getattr(args, "formulation", None) or joint.formulation


def add_load(ap: cli.Parser, default=(0.0, 0.0, 0.0, 0.0)) -> None:
    """``--p --f1 --f2 --m`` (finite numbers) and ``--allow-extrapolation``."""
    for name, unit, text, value in zip(INPUT_NAMES, INPUT_UNITS, LOAD_HELP, default):
        ap.add_argument(f"--{name.lower()}", type=cli.number(unit=unit), default=value,
                        help=f"{text} (default {value:g})")
    add_extrapolation(ap)


def add_extrapolation(ap: cli.Parser) -> None:
    ap.add_argument("--allow-extrapolation", action="store_true",
                    help="accept loads outside the training box (recorded as extrapolated)")


def checked_loads(ap: cli.Parser, loads, allow_extrapolation: bool, box=INPUT_BOX) -> np.ndarray:
    """(n, 4) or (4,) loads as float64, or one error line naming the first value
    outside ``box`` (4,), the joint's input box (exit 2)."""
    x = np.asarray(loads, dtype=np.float64)
    try:
        check_box(x, allow_extrapolation, box=box)
    except OutOfBoxError as exc:
        ap.error(exc)
    return x


def parsed_load(ap: cli.Parser, args, box=INPUT_BOX) -> np.ndarray:
    """The (4,) load of :func:`add_load`'s options, checked against ``box`` (4,)."""
    return checked_loads(ap, [getattr(args, n.lower()) for n in INPUT_NAMES],
                         args.allow_extrapolation, box)


def one_rank(ap: cli.Parser, comm) -> None:
    """Refuse to run under more than one rank (tools that solve on COMM_SELF); call it
    before parsing, so that no output folder is created."""
    if comm.size > 1:
        ap.error(f"runs on one rank, not {comm.size} (start it without mpirun)")


def on_root(comm, write) -> None:
    """Call ``write()`` on rank 0 of ``comm``; a ValueError or OSError it raises is raised
    on every rank (collective), so all ranks leave ``ap.errors()`` with the same code."""
    error = None
    if comm.rank == 0:
        try:
            write()
        except (ValueError, OSError) as exc:
            error = exc
    error = comm.bcast(error, root=0) if comm.size > 1 else error
    if error is not None:
        raise error


# ---------------------------------------------------------------- the whole finger
def add_finger_mesh(ap: cli.Parser) -> None:
    """The finger's discretisation options, read by :func:`finger_discretisation`: the
    joints' mesh (--mesh-size, --wall-mesh-size, --divisions, --hex-size), the rigid parts'
    element size and the formulation; each absent one is the first joint file's [mesh]."""
    add_mesh_size(ap, None, "joint tetrahedron size", shown="the first joint file's [mesh] size")
    add_wall_mesh_size(ap)
    add_divisions(ap)
    ap.add_argument("--rigid-mesh-size", type=MESH_SIZE, default=FingerGeometry.rigid_mesh_size,
                    help=f"element size in the rigid parts, mm (default {FingerGeometry.rigid_mesh_size:g}; with "
                         "--divisions N their hexahedra are at most this / N long)")
    add_formulation(ap, "the first joint file's [mesh] formulation (the paper's: the production one)")


def add_plane_flags(ap: cli.Parser, names: str = "") -> None:
    """--no-plane and its old opposite --plane (``args.plane``, default True: the gripper,
    module docstring); ``names``: what the flag does to a tool's file names, if anything."""
    ap.add_argument("--no-plane", dest="plane", action="store_false",
                    help="one finger alone, which may cross X = 0 (default: the gripper, the right finger against "
                         "the mirror finger's contact at X = 0, a frictionless penalty, as predictor.cli.gesture)" + names)
    ap.add_argument("--plane", dest="plane", action="store_true",
                    help="the mirror finger's contact at X = 0: the default now (accepted for one release)")
    ap.set_defaults(plane=True)


def finger_discretisation(ap: cli.Parser, args: argparse.Namespace,
                          finger: FingerSpec) -> tuple[FingerGeometry, str]:
    """(FingerGeometry, formulation) of the options on the finger's joints: the first
    joint's shape with its [mesh] defaults unless --mesh-size, --wall-mesh-size,
    --divisions (a parser without it: none) or --formulation are given, every other joint
    of its own shape with the same mesh settings (FingerGeometry); --divisions with a
    tetrahedron size is a usage error."""
    first = finger_joints(finger)[0]
    try:
        geometry = FingerGeometry(finger, joint_geometry(args, first), args.rigid_mesh_size)
    except ValueError as exc:
        ap.error(exc)
    return geometry, args.formulation or first.formulation
