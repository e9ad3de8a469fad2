"""Command line: the gripper's static gesture for pressures (P1, P2).

    python -m predictor.gesture --p1 -0.1 --p2 0.1 [--object circle:r=30,y=-195]
        [--approach -0.15,0|zero] [--method newton|lbfgs|nn] [--model PATH] [--nn PATH]
        [--no-gravity] [--plot out.png] [--json]

Data flow: pressures (MPa) + object spec -> joint model (``--model``: surrogate
checkpoint; default results/surrogate/improved.pt when present, else the analytic
stand-in) -> predictor.solve (or the NN predictor) -> right-finger figures as JSON:
converged, tau [[F1 N, F2 N, M N·mm] x 2], residual_force_mN, residual_moment_Nmm (per
joint), tip [x, y] mm, tip_angle_deg, contact_force_N, slip, iterations, time_ms.

Exit codes: 0 converged; 1 not converged (the JSON says so, tau is null); 2 bad input
(pressure beyond ±0.3 MPa, unknown object spec, missing or corrupt model) with a
one-line reason on stderr.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import torch

from predictor.joint import load_joint
from predictor.solve import APPROACH, SolverOptions, solve
from predictor.statics import parse_object

DEFAULT_SURROGATE = Path("results/surrogate/improved.pt")


def _pair(text: str) -> tuple[float, float]:
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"expected P1,P2 in MPa, got {text!r}")
    return float(parts[0]), float(parts[1])


def run(args: argparse.Namespace) -> tuple[dict, object, object]:
    """Solve one gesture from parsed arguments. Returns (json dict, result, obstacle)."""
    for name in ("p1", "p2"):
        value = getattr(args, name)
        if not math.isfinite(value) or abs(value) > 0.3:
            raise ValueError(f"--{name} {value} MPa is outside the surrogate's box |P| <= 0.3 MPa")
    model = args.model or (str(DEFAULT_SURROGATE) if DEFAULT_SURROGATE.is_file() else "analytic")
    joint = load_joint(model)
    obstacle = parse_object(args.object) if args.object else None
    start = None if args.approach == "zero" else (_pair(args.approach) if args.approach else APPROACH)
    if start is not None and max(abs(v) for v in start) > 0.3:
        raise ValueError(f"--approach {args.approach} is outside |P| <= 0.3 MPa")
    pressures = torch.tensor([[args.p1, args.p2]], dtype=torch.float64)
    options = SolverOptions(method=args.method if args.method != "nn" else "newton", gravity=not args.no_gravity)
    if args.method == "nn":
        from predictor.nn import load_predictor, predict_gesture

        if args.no_gravity or args.approach:
            raise ValueError("--method nn predicts the trained case only (gravity on, its own approach)")

        predictor = load_predictor(args.nn, joint, obstacle_default=obstacle is not None)
        res = predict_gesture(predictor, joint, pressures, obstacle)
    else:
        res = solve(joint, pressures, obstacle, options=options, start=start)
    ok = bool(res.converged[0])
    out = {
        "converged": ok,
        "tau": res.tau[0].tolist() if ok else None,
        "residual_force_mN": res.residual_force_mN[0].tolist(),
        "residual_moment_Nmm": res.residual_moment_Nmm[0].tolist(),
        "tip": res.pose.tip_end[0].tolist() if ok else None,
        "tip_angle_deg": math.degrees(float(res.pose.phi[0, 1])) if ok else None,
        "contact_force_N": float(res.normal_force_N[0]),
        "friction_N": float(res.friction_N[0]),
        "friction_ratio": float(res.friction_ratio[0]),
        "slip": bool(res.slip[0]) if obstacle is not None else False,
        "iterations": int(res.iterations[0]),
        "time_ms": res.time_ms,
        "pressures_MPa": [args.p1, args.p2],
        "method": args.method,
        "joint": joint.name,
        "object": args.object,
        "gravity": not args.no_gravity,
    }
    if args.method == "nn":
        out["nn_fallback_to_ramp"] = bool(res.fallback[0])
    return out, res, obstacle


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m predictor.gesture", description=__doc__.split("\n\n")[0])
    ap.add_argument("--p1", type=float, required=True, help="joint-1 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--p2", type=float, required=True, help="joint-2 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--object", help="circle[:r=,x=,y=,deg=] | ellipse[:a=,b=,...] | rectangle[:w=,h=,...] (mm)")
    ap.add_argument("--approach", help="P1,P2 (MPa) at which the object is brought in (grasp history; "
                    f"default {APPROACH[0]},{APPROACH[1]}), or 'zero' to ramp from 0 with the object present")
    ap.add_argument("--method", choices=("newton", "lbfgs", "nn"), default="newton")
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: "
                    f"{DEFAULT_SURROGATE} if present, else analytic)")
    ap.add_argument("--nn", help="NN predictor checkpoint for --method nn (default: results/predictor/"
                    "gravity_nn.pt, or contact_nn.pt with --object)")
    ap.add_argument("--no-gravity", action="store_true", help="drop all weights")
    ap.add_argument("--plot", help="write the gesture PNG here")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    try:
        out, res, obstacle = run(args)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"error: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}", file=sys.stderr)
        return 2
    if args.plot:
        from predictor.plot import save_gesture

        save_gesture(args.plot, res, 0, obstacle)
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for key, value in out.items():
            print(f"{key:>20}: {value}")
    if not out["converged"]:
        print("error: the equilibrium solve did not converge; no gesture returned", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
