"""How far a pressurised joint's cells bulge beyond the band of its outline (issue 56).

The predictor draws a joint as a band of half-height H/2 about its centre line
(predictor.model.gripper.outline_vertices: P_m -/+ (H/2) nu_m at the anchors P_m). A pressurised
chamber's cells balloon, so the material on that side lies beyond the band; where the
gripper's fingers meet at X = 0 with P2 < 0 (the plane-facing chamber pressurised), that
bulge carries the plane. This study measures it on the joint FEM, free of end loads:

    offset(X) = (x(X) - C(X1)) · n(X1)        x = X + u, the deformed position of material point X
    bulge_+,k(P) = max over X in chord k of offset - H/2,   bulge_-,k(P) = max of (-offset) - H/2

with C(X1) the deformed centre line at the material axial coordinate X1 (linear between the
proximal centre and the anchors r_1..r_n, as the predictor's band) and n(X1) the unit
normal (+y side) of that anchor chord; chord k holds the material points with X1 between
anchors k and k + 1 (k = 0: from the proximal face to anchor 1), so the profile has one
bulge per chord and side, n per pressure. The + side holds the chamber P > 0 pressurises
(fem.physics.problem), so bulge_+ is the pressurised side's at P > 0 and bulge_- the
other's; the joint's mirror symmetry (y -> -y, P -> -P) gives P < 0, and the study checks
it at the largest pressure. The maximum runs over every node of the displacement space
(any z: the plane X = 0 touches the widest section).

Data flow: the joint description (contract.joint) -> JointSolver (production discretisation
by default) -> one load path over the pressures (continuation), bulges per pressure ->
results/fem/joint_outline.json (``bulge_mm``: per |P| the pressurised and the other side's
profile), which the joint file's [outline] table holds for predictor.model.gripper's outline
(contract.joint.outline_table prints it). Only rank 0 writes, atomically. End loads and
contact change the bulge a little; the study says nothing of them.
"""

from __future__ import annotations

import logging
import sys
import time

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.joint import JointSpec, joint_arg, load_joint, outline_table
from fem.options import add_divisions, add_mesh_size, joint_geometry
from fem.mesh.geometry import JointGeometry
from fem.solvers.joint import JointSolver, Load
from fem.artefacts import JOINT_OUTLINE, outline_of

log = logging.getLogger("softjoint.fem")

#: The pressures the study solves in turn, up the load path (continuation), as fractions of
#: the joint's box |P| <= pressure_mpa: the paper's joint's 0.025, 0.05, 0.1, ..., 0.3 MPa.
FRACTIONS = (1 / 12, 1 / 6, 1 / 3, 1 / 2, 2 / 3, 5 / 6, 1.0)


def pressures_of(joint: JointSpec) -> tuple[float, ...]:
    """The default pressures (MPa) of ``joint``: FRACTIONS of its box, to 1e-6 MPa."""
    return tuple(round(f * joint.pressure_mpa, 6) for f in FRACTIONS)


def centre_line(anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points (n + 1, 2), chord normals (n, 2)) of the deformed centre line: the proximal
    centre (0, 0) then the anchors (n, 2) mm; the unit normal of each chord, its +y side."""
    P = np.vstack([[0.0, 0.0], anchors])
    d = np.diff(P, axis=0)
    d /= np.linalg.norm(d, axis=1)[:, None]
    return P, np.stack([-d[:, 1], d[:, 0]], 1)


def normal_offsets(X: np.ndarray, x: np.ndarray, anchors: np.ndarray, length: float):
    """(offset (N,) mm, chord (N,)) of material points X (N, 3) at deformed positions x
    (N, 3): the distance of x from the centre line point of its axial coordinate, along
    that chord's +y normal, and the chord's index (module docstring)."""
    P, nrm = centre_line(anchors)
    n = len(anchors)
    s = np.clip(X[:, 0] / (length / n), 0.0, n - 1e-9)
    k = s.astype(int)
    t = (s - k)[:, None]
    C = P[k] + t * (P[k + 1] - P[k])
    return np.einsum("ij,ij->i", x[:, :2] - C, nrm[k]), k


def chord_maxima(values: np.ndarray, chord: np.ndarray, n: int) -> np.ndarray:
    """The largest of ``values`` (N,) in each of the n chords (-inf where a chord has none)."""
    out = np.full(n, -np.inf)
    np.maximum.at(out, chord, values)
    return out


def bulges(solver: JointSolver, half_height: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """(bulge_+, bulge_-) (n,) mm per chord of the solver's converged state (module
    docstring), reduced over the ranks."""
    u = solver.displacement()
    X = u.function_space.tabulate_dof_coordinates()
    bs = u.function_space.dofmap.index_map_bs
    x = X + u.x.array.reshape(-1, bs)[: len(X)]
    anchors = solver.positions()
    off, chord = normal_offsets(X, x, anchors, length)
    local = np.stack([chord_maxima(v, chord, len(anchors)) for v in (off, -off)])
    both = np.empty_like(local)
    solver.comm.Allreduce(local, both, op=MPI.MAX)
    return both[0] - half_height, both[1] - half_height


def run(joint: JointSpec | None = None, pressures=None, comm: MPI.Comm = MPI.COMM_WORLD,
        geometry: JointGeometry | None = None) -> dict:
    """The study's record of ``joint`` (default: the paper's) on ``geometry`` (default:
    the joint file's [mesh]): per pressure the bulge of both sides, the mirror check.
    RuntimeError if a solve does not converge."""
    joint = joint or load_joint()
    pressures = pressures or pressures_of(joint)
    solver = JointSolver.for_joint(joint, comm, geometry=geometry)
    H2, L = joint.shape.height / 2, joint.shape.length
    rows, t0 = [], time.perf_counter()
    for P in pressures:
        res = solver.solve(Load(P), continuation=True)
        if not res.converged:
            raise RuntimeError(f"joint at P = {P:g} MPa did not converge ({res.reason}); nothing written")
        plus, minus = bulges(solver, H2, L)
        rows.append({"P_MPa": P, "pressurised_mm": plus.tolist(), "other_mm": minus.tolist(),
                     "cap_rotation_deg": float(np.degrees(res.cap_rotation)), "wall_time_s": res.wall_time})
        if comm.rank == 0:
            log.info("P = %g MPa: bulge up to %.3f mm on the pressurised side, %.3f mm on the other",
                     P, plus.max(), minus.max())
    top = pressures[-1]
    res = solver.solve(Load(-top))          # from zero: the mirror load path
    if not res.converged:
        raise RuntimeError(f"joint at P = {-top:g} MPa did not converge ({res.reason}); nothing written")
    plus, minus = bulges(solver, H2, L)
    return {"joint": joint.name, "discretisation": solver.mesh_info(), "half_height_mm": H2,
            "bulge_mm": rows,
            "mirror": {"P_MPa": -top, "pressurised_mm": minus.tolist(), "other_mm": plus.tolist()},
            "wall_time_s": time.perf_counter() - t0, "ranks": comm.size}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.joint_outline", description=__doc__.split("\n\n")[0])
    ap.add_argument("--joint", type=joint_arg, default=None,
                    help="joint description file (default: the paper's, contract/joints/paper.toml)")
    ap.add_output("--out", suffix=".json", default="results/fem/joint_outline.json",
                  help="result file (default results/fem/joint_outline.json)")
    ap.add_argument("--pressures", type=cli.number_list(0, 10, "MPa"), default=None,
                    metavar="P1,P2,..", help="|P| (MPa, increasing) of the table's rows (default: the joint's "
                    "box |P| <= P_max times 1/12, 1/6, 1/3, 1/2, 2/3, 5/6, 1; the paper's 0.025, 0.05, 0.1, .., 0.3)")
    add_mesh_size(ap, None)
    add_divisions(ap)
    args = ap.parse_args(argv)
    with ap.errors():
        joint = args.joint or load_joint()
        geometry = joint_geometry(args, joint)
        pressures = tuple(args.pressures) if args.pressures else pressures_of(joint)
        if pressures[0] <= 0 or any(b <= a for a, b in zip(pressures, pressures[1:])):
            raise ValueError(f"--pressures {','.join(f'{p:g}' for p in pressures)}: must increase from above 0 MPa")
        if pressures[-1] > joint.pressure_mpa:
            raise ValueError(f"--pressures: {pressures[-1]:g} MPa is beyond the joint's box (|P| <= "
                             f"{joint.pressure_mpa:g} MPa)")
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    try:
        record = run(joint, pressures, geometry=geometry)
    except RuntimeError as exc:          # a pressure that did not converge: nothing is written
        print(f"{ap.prog}: {exc}", file=sys.stderr)
        return 1
    if MPI.COMM_WORLD.rank != 0:
        return 0
    with ap.errors():
        JOINT_OUTLINE.write(args.out, record)
    if args.json:
        cli.print_json({**record, "out": args.out})
    else:
        print(f"# add to the joint file ({args.out}):\n" + outline_table(*outline_of(record)), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
