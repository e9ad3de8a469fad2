"""Large-deflection validation of the joint's loading code on a slender 3D cantilever.

The beam (fem.mesh.geometry.BeamGeometry, nu = 0 so EI = E b h³/12 is unambiguous) is solved
as the SAME problem as the joint (fem.physics.problem.joint_problem) by the same load-path solver
(fem.solvers.load_path): its end block is the rigid cap, F2 is the dead load at the beam end
(L, 0, 0) and M the pure couple of fem.physics.problem.end_loads. Results are compared with the
exact elastica of fem.studies.elastica:

* ``cantilever --alpha A``: dead transverse tip load P = A·EI/L² (Bisshopp-Drucker),
  A in [0, 10];
* ``rollup --theta T``: pure end moment M = T·EI/L (circular arc), T in [0, 2 pi].

    python -m fem.studies.validation cantilever --alpha 2 --json
    python -m fem.studies.validation rollup --theta 6.2832 --json
    python -m fem.studies.validation table --out results/fem/validation.json   # both sweeps

JSON keys: cantilever -> u_over_L, w_over_L, theta, exact, error_over_L; rollup ->
x_over_L, y_over_L, theta, exact, error_over_L; table -> both lists and the worst errors
(``table --json`` prints those and the file written). Lengths relative to L, angles in rad.
"""


from __future__ import annotations

import math
import sys
from dataclasses import asdict, replace

from mpi4py import MPI

from contract import cli
from fem.studies.elastica import cantilever_tip, rollup_tip
from fem.artefacts import VALIDATION
from fem.mesh.geometry import BeamGeometry
from fem.options import add_mesh_size, on_root

#: Defaults validated in tests/test_fem.py: L/h = 50, two P2 layers per h.
DEFAULT_BEAM = BeamGeometry(length=100.0, thickness=2.0, width=2.0, cap=1.0, mesh_size=1.0)
E_BEAM = 12.2
#: Validated load ranges: alpha = P L²/EI in [0, ALPHA_MAX]; T = M L/EI in [0, THETA_MAX]
#: rad, a full circle (2 pi as printed to 4 decimals, so that 6.2832 is accepted).
ALPHA_MAX = 10.0
THETA_MAX = 6.2832


def bending_stiffness(geo: BeamGeometry, E: float = E_BEAM) -> float:
    """EI of the full (not half) rectangular section, N·mm²."""
    return E * geo.width * geo.thickness ** 3 / 12


def _solve(geo: BeamGeometry, F2: float, M: float, steps: int, comm):
    from fem.solvers.joint import Load, SolverConfig, beam_solver

    solver = beam_solver(geo, comm, E=E_BEAM, config=SolverConfig(first_step=1.0 / steps))
    result = solver.solve(Load(F2=F2, M=M))
    if not result.converged:
        raise RuntimeError(f"beam solve did not converge: {result.reason}")
    return result


def cantilever(alpha: float, geo: BeamGeometry = DEFAULT_BEAM, comm=MPI.COMM_WORLD) -> dict:
    """FEM tip of the tip-loaded cantilever at alpha = P L²/EI against the elastica."""
    if not 0 <= alpha <= ALPHA_MAX:
        raise ValueError(f"alpha = {alpha} outside the validated range [0, {ALPHA_MAX:g}]")
    L = geo.length
    P = alpha * bending_stiffness(geo) / L ** 2
    r = _solve(geo, P, 0.0, steps=max(2, math.ceil(alpha)), comm=comm)
    x, y = r.anchors[0] / L
    fem_ = {"u_over_L": 1.0 - x, "w_over_L": y, "theta": r.cap_rotation}
    exact = cantilever_tip(alpha)
    err = math.hypot(fem_["u_over_L"] - exact["u_over_L"], fem_["w_over_L"] - exact["w_over_L"])
    return {"case": "cantilever", "alpha": alpha, **fem_, "exact": exact, "error_over_L": err,
            "newton_iterations": r.newton_iterations, "wall_time_s": r.wall_time,
            "beam": asdict(geo)}


def rollup(theta: float, geo: BeamGeometry = DEFAULT_BEAM, comm=MPI.COMM_WORLD) -> dict:
    """FEM tip under a pure end moment M = T·EI/L against the circular arc."""
    if not 0 <= theta <= THETA_MAX:
        raise ValueError(f"theta = {theta} outside the validated range [0, {THETA_MAX:g}] rad")
    L = geo.length
    M = theta * bending_stiffness(geo) / L
    r = _solve(geo, 0.0, M, steps=max(2, math.ceil(2 * theta)), comm=comm)
    x, y = r.anchors[0] / L
    exact = rollup_tip(theta)
    err = math.hypot(x - exact["x_over_L"], y - exact["y_over_L"])
    return {"case": "rollup", "theta_load": theta, "x_over_L": x, "y_over_L": y,
            "theta": r.cap_rotation, "exact": exact, "error_over_L": err,
            "newton_iterations": r.newton_iterations, "wall_time_s": r.wall_time,
            "beam": asdict(geo)}


#: The sweeps of ``table``: alpha up to 10 and T up to a full circle.
TABLE_ALPHA = (0.5, 1.0, 2.0, 5.0, 10.0)
TABLE_THETA = (math.pi / 2, math.pi, 3 * math.pi / 2, 2 * math.pi)


def table(geo: BeamGeometry = DEFAULT_BEAM) -> dict:
    """Both sweeps with their worst errors (fraction of L)."""
    cant = [cantilever(a, geo) for a in TABLE_ALPHA]
    roll = [rollup(t, geo) for t in TABLE_THETA]
    return {"cantilever": cant, "rollup": roll,
            "max_cantilever_error_over_L": max(c["error_over_L"] for c in cant),
            "max_rollup_error_over_L": max(r["error_over_L"] for r in roll),
            "required": {"cantilever": 0.015, "rollup": 0.02}}


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.studies.validation", json=False,
                    description="FEM of a slender cantilever against the exact elastica.")
    sub = ap.add_subparsers(dest="case", required=True)
    t = sub.add_parser("table", help="alpha in 0.5..10 and T in pi/2..2 pi, written to --out")
    t.add_output("--out", suffix=".json", default="results/fem/validation.json",
                 help="result file (default results/fem/validation.json)")
    c = sub.add_parser("cantilever", help=f"dead tip load, alpha = P L^2/EI in [0, {ALPHA_MAX:g}]")
    c.add_argument("--alpha", type=cli.number(0, ALPHA_MAX), required=True,
                   help=f"alpha = P L^2/EI in [0, {ALPHA_MAX:g}]")
    r = sub.add_parser("rollup", help=f"pure end moment, T = M L/EI in [0, {THETA_MAX:g}] rad")
    r.add_argument("--theta", type=cli.number(0, THETA_MAX, "rad"), required=True,
                   help=f"T = M L/EI in [0, {THETA_MAX:g}] rad")
    for p in (c, r):
        add_mesh_size(p, DEFAULT_BEAM.mesh_size, "beam tetrahedron size")
    return ap


def _print_case(out: dict) -> None:
    keys = ("u_over_L", "w_over_L") if out["case"] == "cantilever" else ("x_over_L", "y_over_L")
    for k in keys + ("theta",):
        print(f"{k:10s} FEM {out[k]: .5f}   exact {out['exact'][k]: .5f}")
    print(f"tip error {100 * out['error_over_L']:.3f}% of L, Newton {out['newton_iterations']}")


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    try:
        with ap.errors():
            if args.case == "table":
                out = table()
                on_root(comm, lambda: VALIDATION.write(args.out, out))
            else:
                geo = replace(DEFAULT_BEAM, mesh_size=args.mesh_size)
                out = (cantilever(args.alpha, geo, comm) if args.case == "cantilever"
                       else rollup(args.theta, geo, comm))
    except RuntimeError as exc:      # the beam did not converge: not the user's fault
        if comm.rank == 0:
            print(f"{ap.prog}: {exc}", file=sys.stderr)
        return 1
    if comm.rank != 0:
        return 0
    if args.case == "table":
        summary = {k: out[k] for k in ("max_cantilever_error_over_L", "max_rollup_error_over_L",
                                       "required")}
        if args.json:
            cli.print_json({**summary, "out": args.out})
        else:
            print(f"max tip error: cantilever {100 * out['max_cantilever_error_over_L']:.3f}% L, "
                  f"roll-up {100 * out['max_rollup_error_over_L']:.3f}% L -> {args.out}")
    elif args.json:
        cli.print_json(out)
    else:
        _print_case(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
