"""Command line: the gripper's static gesture for pressures (P1, P2).

    python -m predictor.gesture --p1 -0.1 --p2 0.1 [--object circle:r=30,y=-195]
        [--approach -0.15,0|zero] [--method newton|lbfgs|nn] [--model PATH] [--nn PATH]
        [--no-gravity] [--plot out.png] [--json]

Data flow: pressures (MPa) + object spec -> GripperProblem (joint model from ``--model``:
surrogate checkpoint; default results/surrogate/improved.pt when present, else the
analytic stand-in) -> predictor.solve (or the NN predictor) -> right-finger figures
(GestureResult.summary plus friction_N, time_ms and the run's settings) as text or as
strict JSON: converged, tau [[F1 N, F2 N, M N·mm] x 2], residual_force_mN,
residual_moment_Nmm (per joint), tip [x, y] mm, tip_angle_deg, contact_force_N, slip,
iterations, time_ms.

Exit codes: 0 converged; 1 not converged (the JSON says so, tau is null); 2 bad input
(a pressure that is not a number or beyond ±0.3 MPa, a bad object spec, an unwritable
--plot, a missing, damaged or other-kind model) with a one-line reason on stderr,
checked before the solve.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from fem import cli
from fem.spec import PRESSURE_LIMIT
from predictor.joint import load_joint
from predictor.solve import APPROACH, SolverOptions, solve
from predictor.statics import GripperProblem, parse_object

DEFAULT_SURROGATE = Path("results/surrogate/improved.pt")
PRESSURE = cli.number(-PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa")
PRESSURE_PAIR = cli.numbers(2, -PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa")


def _approach(text: str):
    """--approach: ``zero`` or P1,P2 in MPa."""
    return "zero" if text.strip().lower() == "zero" else PRESSURE_PAIR(text)


def _object(text: str) -> str:
    """--object: the spec, checked while parsing (so a bad one is refused before any load)."""
    try:
        parse_object(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def run(args: argparse.Namespace):
    """Solve one gesture from parsed arguments. Returns (json dict, result, problem)."""
    model = args.model or (str(DEFAULT_SURROGATE) if DEFAULT_SURROGATE.is_file() else "analytic")
    joint = load_joint(model)
    pressures = torch.tensor([[args.p1, args.p2]], dtype=torch.float64)
    obstacle = parse_object(args.object) if args.object else None
    if args.method == "nn":
        from predictor.nn import load_predictor, predict_gesture

        predictor = load_predictor(args.nn, joint, contact=args.object is not None)
        problem = GripperProblem(joint, obstacle=obstacle, approach=predictor.config.approach)
        res = predict_gesture(predictor, problem, pressures)
    else:
        start = None if args.approach == "zero" else (args.approach or APPROACH)
        problem = GripperProblem(joint, obstacle=obstacle, gravity=not args.no_gravity, approach=start)
        res = solve(problem, pressures, SolverOptions(method=args.method))
    out = {**res.summary(0), "friction_N": float(res.friction_N[0]), "time_ms": res.time_ms,
           "method": args.method, "joint": joint.name, "object": args.object, "gravity": problem.gravity}
    if args.method == "nn":
        out["nn_fallback_to_ramp"] = bool(res.fallback[0])
    return out, res, problem


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.gesture", description=__doc__.split("\n\n")[0])
    ap.add_argument("--p1", type=PRESSURE, required=True, help="joint-1 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--p2", type=PRESSURE, required=True, help="joint-2 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--object", type=_object,
                    help="circle[:r=,x=,y=,deg=] | ellipse[:a=,b=,...] | rectangle[:w=,h=,...] (mm)")
    ap.add_argument("--approach", type=_approach, help="P1,P2 (MPa) at which the object is brought in "
                    f"(grasp history; default {APPROACH[0]},{APPROACH[1]}), or 'zero' to ramp from 0 with the "
                    "object present")
    ap.add_argument("--method", choices=("newton", "lbfgs", "nn"), default="newton")
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: "
                    f"{DEFAULT_SURROGATE} if present, else analytic)")
    ap.add_argument("--nn", help="NN predictor checkpoint for --method nn (default: results/predictor/"
                    "gravity_nn.pt, or contact_nn.pt with --object)")
    ap.add_argument("--no-gravity", action="store_true", help="drop all weights")
    ap.add_output("--plot", suffix=".png", help="write the gesture PNG here")
    args = ap.parse_args(argv)
    if args.method == "nn" and (args.no_gravity or args.approach is not None):
        ap.error("--method nn predicts the trained case only (gravity on, its own approach): "
                 "drop --no-gravity and --approach")
    torch.set_num_threads(1)
    with ap.errors():
        out, res, problem = run(args)
        if args.plot:
            from predictor.plot import save_gesture

            save_gesture(args.plot, res, 0, problem.obstacle)
    if args.json:
        cli.print_json(out)
    else:
        for key, value in out.items():
            print(f"{key:>20}: {value}")
    if not out["converged"]:
        print(f"{ap.prog}: the equilibrium solve did not converge; no gesture returned", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
