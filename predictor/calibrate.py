"""Command line: calibrate a gripper to measured gestures (docs/calibration.md).

    python -m predictor.calibrate --observations FILE [--fit NAME,...] [--finger FILE]
        [--model PATH|analytic] [--kinematics cap|tangent] [--joint-weight split|lumped]
        [--prior NAME=MEAN,STD ...] [--starts N] [--no-loo] --out CALIBRATED.toml [--json]
    python -m predictor.calibrate recovery --out results/calibration/recovery.json
        [--model PATH|analytic] [--seeds N] [--starts N] [--json]

The first fits the switchable parameters (names or groups of predictor.calibration:
gain, offset, stiffness, weight, mount, frame; default gain,offset,stiffness) to the
measurement file (predictor.observations) by weighted least squares with exact
implicit-function gradients (predictor.calibration_fit), and writes the calibrated finger
file (predictor.calibration_file) that predictor.gesture --finger, the atlas, the inverse
and the API read. JSON: ``parameters`` (name -> value, std, identifiable),
``rms_before_mm``, ``rms_after_mm``, ``loo_tip_error_mm`` (mean over the observations
with a tip; also its max and each), ``unidentifiable``, ``correlated``, ``time_s``, ``out``.

``recovery`` runs the known-truth study (predictor.calibration_recovery) and writes its
JSON.

Exit codes: 0 done; 1 the fit did not converge (nothing written); 2 bad input (a
measurement file that fails its schema, an unknown --fit name, a bad finger file, model,
prior or output) with a one-line reason on stderr, checked before the fit.
"""
from __future__ import annotations

import argparse
import logging
import math
import sys

import torch

from contract import cli
from contract.finger import DEFAULT_FINGER, finger_arg
from predictor.artefacts import RECOVERY
from predictor.gripper import DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, JOINT_WEIGHTS, KINEMATICS
from predictor.joint import load_joint

LOG = logging.getLogger("softjoint.calibrate")


def prior_arg(text: str):
    """--prior NAME=MEAN,STD (STD > 0, in the parameter's unit)."""
    name, eq, rest = text.partition("=")
    vals = rest.split(",")
    try:
        mean, std = (float(v) for v in vals)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--prior {text!r}: expected NAME=MEAN,STD") from None
    if not eq or not name or not (math.isfinite(mean) and math.isfinite(std) and std > 0):
        raise argparse.ArgumentTypeError(f"--prior {text!r}: expected NAME=MEAN,STD with finite MEAN and STD > 0")
    return name.strip(), mean, std


def _model_args(ap) -> None:
    ap.add_argument("--model", help="joint surrogate checkpoint or 'analytic' (default: the committed surrogate)")
    ap.add_argument("--finger", type=finger_arg, default=str(DEFAULT_FINGER), help="finger description file")
    ap.add_argument("--kinematics", choices=KINEMATICS, default=DEFAULT_KINEMATICS)
    ap.add_argument("--joint-weight", choices=JOINT_WEIGHTS, default=DEFAULT_JOINT_WEIGHT)
    ap.add_argument("--starts", type=cli.number(1, 20, integer=True), default=3, help="LM starts (default 3)")
    cli.add_quiet(ap)


def _model(args):
    from predictor.calibration import CalibrationModel

    return CalibrationModel(load_joint(args.model, args.finger), args.finger, args.kinematics, args.joint_weight)


def main_fit(argv) -> int:
    from predictor.calibration import DEFAULT_FIT, resolve_fit
    from predictor.calibration_file import write_calibrated
    from predictor.calibration_fit import FitFailed, Prior, calibrate
    from predictor.observations import load_observations

    ap = cli.Parser(prog="python -m predictor.calibrate", description=__doc__.split("\n\n")[0],
                    epilog="python -m predictor.calibrate recovery --help: the known-truth recovery study")
    ap.add_argument("--observations", required=True, help="measurement file (JSON, docs/calibration.md)")
    ap.add_argument("--fit", default=",".join(DEFAULT_FIT), help="parameters or groups to fit, comma separated")
    ap.add_argument("--prior", type=prior_arg, action="append", default=[], help="NAME=MEAN,STD (repeatable)")
    ap.add_argument("--no-loo", action="store_true", help="skip the leave-one-out predictions")
    ap.add_output("--out", required=True, suffix=".toml", help="the calibrated finger file to write")
    _model_args(ap)
    args = ap.parse_args(argv)
    cli.setup_logging(args.quiet)
    with ap.errors():
        obs = load_observations(args.observations, args.finger)
        model = _model(args)
        names = [n.strip() for n in args.fit.split(",") if n.strip()]
        resolve_fit(names, model.table)
        priors = {}
        for name, mean, std in args.prior:
            if name in priors:
                raise ValueError(f"--prior {name}: given twice")
            priors[name] = Prior(mean, std)
        try:
            res = calibrate(model, obs, names, priors, starts=args.starts, loo=not args.no_loo)
        except FitFailed as exc:
            print(f"python -m predictor.calibrate: {exc}", file=sys.stderr)
            return 1
        write_calibrated(args.out, model, res, obs.sha256, str(args.observations))
    out = {**res.summary(), "out": str(args.out), "joint": model.joint.name, "observations": len(obs),
           "observations_sha256": obs.sha256}
    if args.json:
        cli.print_json(out)
    else:
        for n, p in out["parameters"].items():
            print(f"{n:14s} {p['value']:+.6g} ± {p['std']:.3g}{'' if p['identifiable'] else '  (unidentifiable)'}")
        loo = out["loo_tip_error_mm"]
        print(f"rms {out['rms_before_mm']:.3f} -> {out['rms_after_mm']:.3f} mm; leave-one-out tip "
              f"{'n/a' if loo is None else f'{loo:.3f} mm'}; {out['time_s']:.1f} s; wrote {args.out}")
    return 0


def main_recovery(argv) -> int:
    from predictor.calibration_recovery import SEEDS, recovery_study

    ap = cli.Parser(prog="python -m predictor.calibrate recovery", description="the known-truth recovery study")
    ap.add_output("--out", required=True, suffix=".json", help="the study's JSON")
    ap.add_argument("--seeds", type=cli.number(1, 200, integer=True), default=SEEDS, help="noisy seeds")
    _model_args(ap)
    args = ap.parse_args(argv)
    cli.setup_logging(args.quiet)
    with ap.errors():
        model = _model(args)
        study = recovery_study(model, seeds=args.seeds, starts=args.starts, progress=LOG.info)
        RECOVERY.write(args.out, study)
    nf = study["noise_free"]
    if args.json:
        cli.print_json({"coverage_95": study["noisy"]["coverage_95"],
                        "all_identifiable_within_2pct": nf["all_identifiable_within_2pct"],
                        "unidentifiable": nf["unidentifiable"], "time_s_8_observations": nf["time_s"],
                        "time_s": study["time_s"], "out": str(args.out)})
    else:
        print(f"noise-free: identifiable within 2 %: {nf['all_identifiable_within_2pct']} (unidentifiable: "
              f"{', '.join(nf['unidentifiable']) or 'none'}); 8 observations in {nf['time_s']:.1f} s; noisy 95 % "
              f"coverage {study['noisy']['coverage_95']:.3f}; wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    torch.set_num_threads(1)
    if argv[:1] == ["recovery"]:
        return main_recovery(argv[1:])
    return main_fit(argv)


if __name__ == "__main__":
    sys.exit(main())
