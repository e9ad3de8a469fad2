"""Command line: calibrate a gripper to measured gestures (docs/calibration.md).

    python -m predictor.cli.calibrate --observations FILE [--fit NAME,...] [--finger FILE]
        [--model PATH|analytic] [--kinematics cap|tangent] [--joint-weight split|lumped]
        [--prior NAME=MEAN,STD ...] [--starts N] [--no-loo] [--force] --out CALIBRATED.toml [--json]
    python -m predictor.cli.calibrate recovery --out results/calibration/recovery.json
        [--model PATH|analytic] [--seeds N] [--starts N] [--json]
    python -m predictor.cli.calibrate fem --fem results/calibration/fem --out results/calibration/calibration.json
        [--truth FILE] [--pressures "P1,P2;..."] [--calibrate-on "P1,P2;..."] [--fit NAME,...]
        [--recovery results/calibration/recovery.json] [--figure PNG] [--calibrated TOML] [--force] [--json]
    python -m predictor.cli.calibrate bench --out results/bench/calibrate.json [--repeats N] [--beside TEXT]

The first fits the switchable parameters (names or groups of predictor.calibration.model:
gain, offset, stiffness, weight, mount, frame; default gain,offset,stiffness) to the
measurement file (predictor.calibration.observations; its ``problem`` says whether the gripper, the
fingers meeting at X = 0, or a lone finger was measured, and the fit solves that one) by
weighted least squares with exact implicit-function gradients
(predictor.calibration.fit), judges the fit (``trusted``: enough data, every parameter
identifiable and off its bounds, a reduced chi-square within its 99.9 % limit) and, when
trusted (or with ``--force``), writes the calibrated finger file
(predictor.calibration.file) that predictor.cli.gesture --finger, the atlas, the inverse and
the API read. JSON: ``parameters`` (name -> value, std, identifiable),
``rms_before_mm``, ``rms_after_mm``, ``loo_tip_error_mm`` (mean over the observations
with a tip; also its max and each), ``unidentifiable``, ``correlated``, ``chi2``, ``dof``,
``reduced_chi2`` and its limit, ``on_bound``, ``trusted``, ``why``, ``problem``,
``time_s``, ``out`` (null when nothing was written). The output may not lie inside the
package's own folders (contract/, predictor/, fem/, surrogate/, workflow/, apps/: the
default finger files live there), and its folder must exist (contract.cli).

``recovery`` runs the known-truth study (predictor.calibration.recovery) and writes its
JSON. ``fem`` calibrates the paper's predictor on four whole-finger FEM gestures of a
deliberately different finger and predicts the held-out ones (predictor.calibration.fem,
``make calibrate-demo``): the JSON (``heldout_tip_error_uncalibrated_mm``,
``heldout_tip_error_calibrated_mm``, ``observations_used``, ``time_s``, ``recovery``, ...),
the before/after figure (predictor.calibration.plot; default ``heldout.png`` beside the
JSON) and the calibrated finger file (default ``calibrated.toml`` beside it); it refuses
(exit 2, one line, nothing written) FEM cases that are missing, did not converge, or were
solved for another finger, and judges its fit as the first does: an untrusted one (the
JSON's ``fit.trusted``, ``fit.untrusted_because``) exits 1 with one line naming why and
writes none of the three unless ``--force`` (then all three, and the exit is still 1). ``bench`` times the 8-observation calibration
(predictor.calibration.bench, ``make bench-calibrate``).

Exit codes: 0 trusted and written; 1 not trusted (one line on stderr naming every reason)
or not converged: nothing written unless ``--force`` (then the file is written and the
exit is still 1); 2 bad input (a measurement file that fails its schema, an unknown
--fit name, a bad finger file, model or prior, an output inside the package or in a
missing folder) with a one-line reason on stderr, checked before the fit.
"""
from __future__ import annotations

import argparse
import hashlib
import logging
import math
import sys
from pathlib import Path

import torch

from contract import cli
from contract.finger import DEFAULT_FINGER, finger_arg
from predictor.artefacts import RECOVERY
from predictor.defaults import results_dir
from predictor.model.gripper import DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, JOINT_WEIGHTS, KINEMATICS
from predictor.model.joint import load_joint
from predictor.solvers.progress import set_quiet

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


def _parse(ap, argv):
    """Add the options every calibrate command shares (the model: joint model, finger,
    kinematics, joint weight; LM starts; --quiet) to ``ap``, parse ``argv``, and set the
    logging and the solver's heartbeat (predictor.solvers.solve, where the fingers meet)
    quiet or not."""
    ap.add_argument("--model", help="joint surrogate checkpoint or 'analytic' (default: the committed surrogate)")
    ap.add_argument("--finger", type=finger_arg, default=str(DEFAULT_FINGER), help="finger description file")
    ap.add_argument("--kinematics", choices=KINEMATICS, default=DEFAULT_KINEMATICS)
    ap.add_argument("--joint-weight", choices=JOINT_WEIGHTS, default=DEFAULT_JOINT_WEIGHT)
    ap.add_argument("--starts", type=cli.number(1, 20, integer=True), default=3,
                    help="at most this many LM starts; after the first, only while the fit is poor (default 3)")
    cli.add_quiet(ap)
    args = ap.parse_args(argv)
    cli.setup_logging(args.quiet)
    set_quiet(args.quiet)
    return args


def _fit_names(args, model) -> list[str]:
    """``--fit``'s names (parameters or groups), checked against the model's table."""
    from predictor.calibration.model import resolve_fit

    names = [n.strip() for n in args.fit.split(",") if n.strip()]
    resolve_fit(names, model.table)
    return names


def _verdict(prog: str, result, wrote: str | None) -> int:
    """The exit code of a fit: 0 when trusted, else 1 with one line on stderr naming every
    reason and what was written (``wrote``: the files, by --force; None: nothing)."""
    if result.trusted:
        return 0
    print(f"{prog}: not trusted: {'; '.join(result.why)}; "
          f"{'wrote ' + wrote + ' (--force)' if wrote else 'nothing written (--force writes it)'}", file=sys.stderr)
    return 1


def _model(args):
    from predictor.calibration.model import CalibrationModel

    return CalibrationModel(load_joint(args.model, args.finger), args.finger, args.kinematics, args.joint_weight)


def _observations_and_model(args):
    """The measurement file (``--observations``, checked against ``--finger``) and the
    calibration model of the options of _parse."""
    from predictor.calibration.observations import load_observations

    return load_observations(args.observations, args.finger), _model(args)


def main_fit(argv) -> int:
    from predictor.calibration.model import DEFAULT_FIT
    from predictor.calibration.file import write_calibrated
    from predictor.calibration.fit import FitFailed, Prior, calibrate
    from predictor.calibration.observations import GRIPPER

    ap = cli.Parser(prog="python -m predictor.cli.calibrate", description=__doc__.split("\n\n")[0],
                    epilog="subcommands (each with --help): recovery (the known-truth study), fem (calibrate on "
                           "whole-finger FEM gestures), bench (time the 8-observation calibration)")
    ap.add_argument("--observations", required=True, help="measurement file (JSON, docs/calibration.md)")
    ap.add_argument("--fit", default=",".join(DEFAULT_FIT), help="parameters or groups to fit, comma separated")
    ap.add_argument("--prior", type=prior_arg, action="append", default=[], help="NAME=MEAN,STD (repeatable)")
    ap.add_argument("--no-loo", action="store_true", help="skip the leave-one-out predictions")
    ap.add_argument("--force", action="store_true", help="write the finger file even when the fit is not trusted")
    ap.add_output("--out", required=True, suffix=".toml", help="the calibrated finger file to write")
    args = _parse(ap, argv)
    with ap.errors():
        from predictor.calibration.file import outside_package
        outside_package(args.out)
        obs, model = _observations_and_model(args)
        names = _fit_names(args, model)
        priors = {}
        for name, mean, std in args.prior:
            if name in priors:
                raise ValueError(f"--prior {name}: given twice")
            priors[name] = Prior(mean, std)
        LOG.info("fitting %s to %d observations of the %s", ", ".join(names), len(obs),
                 "gripper (fingers meeting at X = 0)" if obs.problem == GRIPPER else "lone finger")
        try:
            res = calibrate(model, obs, names, priors, starts=args.starts, loo=not args.no_loo)
        except FitFailed as exc:
            print(f"python -m predictor.cli.calibrate: {exc}; nothing written", file=sys.stderr)
            return 1
        written = res.trusted or args.force
        if written:
            write_calibrated(args.out, model, res, obs.sha256, str(args.observations))
    out = {**res.summary(), "out": str(args.out) if written else None, "problem": obs.problem,
           "joint": model.joint.name, "observations": len(obs), "observations_sha256": obs.sha256}
    if args.json:
        cli.print_json(out)
    else:
        for n, p in out["parameters"].items():
            print(f"{n:14s} {p['value']:+.6g} ± {p['std']:.3g}{'' if p['identifiable'] else '  (unidentifiable)'}")
        loo, red = out["loo_tip_error_mm"], out["reduced_chi2"]
        print(f"rms {out['rms_before_mm']:.3f} -> {out['rms_after_mm']:.3f} mm; reduced chi-square "
              f"{'n/a' if red is None else f'{red:.3g}'}; leave-one-out tip "
              f"{'n/a' if loo is None else f'{loo:.3f} mm'}; {out['time_s']:.1f} s; "
              f"{f'wrote {args.out}' if written else 'nothing written'}")
    return _verdict("python -m predictor.cli.calibrate", res, str(args.out) if written else None)


def main_recovery(argv) -> int:
    from predictor.calibration.recovery import SEEDS, recovery_study

    ap = cli.Parser(prog="python -m predictor.cli.calibrate recovery", description="the known-truth recovery study")
    ap.add_output("--out", required=True, suffix=".json", help="the study's JSON")
    ap.add_argument("--seeds", type=cli.number(1, 200, integer=True), default=SEEDS, help="noisy seeds")
    args = _parse(ap, argv)
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


def _pairs(text: str):
    from predictor.calibration.fem import pairs_arg

    try:
        return pairs_arg(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def main_fem(argv) -> int:
    from predictor.artefacts import CALIBRATION
    from predictor.calibration.fem import (CALIBRATE_ON, FIT, PRESSURES, TRUTH_FINGER, case_problem, fem_study,
                                           load_cases, recovery_summary)
    from predictor.calibration.file import write_calibrated
    from predictor.calibration.fit import FitFailed
    from predictor.calibration.plot import heldout_figure

    ap = cli.Parser(prog="python -m predictor.cli.calibrate fem",
                    description="calibrate on whole-finger FEM gestures of another finger, predict the others")
    ap.add_argument("--fem", default=str(results_dir() / "calibration" / "fem"),
                    help="folder of fem.studies.finger_cases JSON of --truth (default: results/calibration/fem)")
    ap.add_argument("--truth", type=finger_arg, default=str(TRUTH_FINGER),
                    help="the finger file the FEM solved (default: results/calibration/truth/finger.toml)")
    ap.add_argument("--pressures", type=_pairs, default=PRESSURES, metavar="P1,P2;...",
                    help="the FEM cases' pressure pairs, MPa (default: the 8 of predictor.calibration.fem)")
    ap.add_argument("--calibrate-on", type=_pairs, default=CALIBRATE_ON, metavar="P1,P2;...",
                    help="the pairs calibrated on (default: 4 spread over the box); the others are held out")
    ap.add_argument("--fit", default=",".join(FIT), help="parameters or groups to fit, comma separated")
    ap.add_argument("--recovery", default=str(results_dir() / "calibration" / "recovery.json"),
                    help="the recovery study's JSON (make calibrate-recovery; default results/calibration/recovery.json)")
    ap.add_output("--out", required=True, suffix=".json", help="calibration.json to write")
    ap.add_output("--figure", suffix=".png", help="before/after figure (default: heldout.png beside --out)")
    ap.add_output("--calibrated", suffix=".toml", help="calibrated finger file (default: calibrated.toml beside --out)")
    ap.add_argument("--force", action="store_true", help="write the files even when the fit is not trusted (exit 1 still)")
    args = _parse(ap, argv)
    out = Path(args.out)
    figure = Path(args.figure) if args.figure else out.with_name("heldout.png")
    calibrated = Path(args.calibrated) if args.calibrated else out.with_name("calibrated.toml")
    with ap.errors():
        cases = load_cases(args.fem, args.truth, args.pressures)
        if not Path(args.recovery).is_file():
            raise ValueError(f"{args.recovery}: no recovery study (run `make calibrate-recovery`)")
        recovery = recovery_summary(RECOVERY.load(args.recovery))
        model = _model(args)
        names = _fit_names(args, model)
        LOG.info("calibrating on %d of %d FEM gestures (%s)", len(args.calibrate_on), len(cases),
                 "the gripper, cases solved with the plane X = 0" if case_problem(cases[0]) == "gripper"
                 else "a lone finger, as the cases were solved")
        try:
            study = fem_study(model, cases, args.truth, args.calibrate_on, names, starts=args.starts)
        except FitFailed as exc:
            print(f"python -m predictor.cli.calibrate fem: {exc}; nothing written", file=sys.stderr)
            return 1
        held = {tuple(c["pressures_MPa"]) for c in study.record["heldout"]}
        record = {**study.record, "fem_folder": str(args.fem), "recovery": {"source": str(args.recovery), **recovery},
                  "figure": str(figure), "calibrated_finger": str(calibrated)}
        # as the observations' fit: an untrusted fit writes nothing unless --force
        written = study.result.trusted or args.force
        if written:
            # the finger file first: it is checked before it is written, the JSON (make's target) last
            write_calibrated(calibrated, model, study.result, _cases_digest(cases), str(args.fem))
            heldout_figure(figure, study, [c for c in cases if c.pressures in held])
            CALIBRATION.write(out, record)
    s = {k: record[k] for k in ("heldout_tip_error_uncalibrated_mm", "heldout_tip_error_calibrated_mm",
                                "improvement", "observations_used", "time_s")}
    wrote = ", ".join(map(str, (out, figure, calibrated)))
    if args.json:
        cli.print_json({**s, "problem": record["problem"], "parameters": record["parameters"],
                        "trusted": study.result.trusted, "why": study.result.why,
                        "reduced_chi2": study.result.reduced_chi2, "out": str(out) if written else None})
    else:
        u, c = s["heldout_tip_error_uncalibrated_mm"], s["heldout_tip_error_calibrated_mm"]
        for n, p in record["parameters"].items():
            print(f"{n:14s} {p['value']:+.6g} ± {p['std']:.3g} (true {p['true']:+.6g})")
        print(f"held-out fingertip error mean {u['mean']:.3f} -> {c['mean']:.3f} mm (max {u['max']:.3f} -> "
              f"{c['max']:.3f}), {s['improvement']:.1f}x; calibrated on {s['observations_used']} "
              f"({'lone finger' if record['problem'] == 'finger' else 'gripper'}) in "
              f"{s['time_s']:.1f} s; {f'wrote {wrote}' if written else 'nothing written'}")
    return _verdict("python -m predictor.cli.calibrate fem", study.result, wrote if written else None)


def _cases_digest(cases) -> str:
    """One sha256 over the FEM cases' file digests (the calibrated file's observations)."""
    return hashlib.sha256("".join(c.sha256 for c in cases).encode()).hexdigest()


def main_bench(argv) -> int:
    from predictor.artefacts import CALIBRATION_BENCH
    from predictor.calibration.bench import OBSERVATIONS, REPEATS, bench_calibration

    ap = cli.Parser(prog="python -m predictor.cli.calibrate bench", description="time the 8-observation calibration")
    ap.add_argument("--observations", default=str(OBSERVATIONS),
                    help="measurement file (default docs/examples/observations.json)")
    ap.add_argument("--repeats", type=cli.number(1, 50, integer=True), default=REPEATS, help="timed runs")
    ap.add_argument("--beside", default="", help="what else ran on the machine (recorded)")
    ap.add_output("--out", required=True, suffix=".json", help="the benchmark's JSON")
    args = _parse(ap, argv)
    with ap.errors():
        obs, model = _observations_and_model(args)
        doc = bench_calibration(model, obs, args.repeats, args.beside, progress=LOG.info)
        CALIBRATION_BENCH.write(args.out, doc)
    if args.json:
        cli.print_json(doc)
    else:
        print(f"{doc['observations']} observations, {len(doc['parameters'])} parameters, {doc['repeats']} runs: fit "
              f"median {doc['fit_median_s']:.2f} s ({doc['fit_cpu_median_s']:.2f} CPU s), with leave-one-out "
              f"{doc['with_loo_median_s']:.2f} s ({doc['with_loo_cpu_median_s']:.2f} CPU s); load average "
              f"{doc['load_average_before'][0]:.2f}; wrote {args.out}")
    return 0


SUBCOMMANDS = {"recovery": main_recovery, "fem": main_fem, "bench": main_bench}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    torch.set_num_threads(1)
    if argv[:1] and argv[0] in SUBCOMMANDS:
        return SUBCOMMANDS[argv[0]](argv[1:])
    return main_fit(argv)


if __name__ == "__main__":
    sys.exit(main())
