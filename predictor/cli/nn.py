"""Command line: train an NN gesture predictor and write its checkpoint.

    python -m predictor.cli.nn --variant gravity-paper|gravity-improved|contact --out FILE.pt
        [--model SURROGATE.pt|analytic] [--epochs N] [--finger FILE.toml]
        [--kinematics K] [--joint-weight W] [--plane] [--quiet] [--json]

The variants are predictor.nn.networks.VARIANTS. The gravity variants learn one finger alone
(a smooth map, as the paper's), the contact variant the grasp, the right finger against the
plane X = 0 where the mirror finger meets it; every one answers the gripper (the problem
predictor.cli.gesture and the Newton solver solve by default; predictor.nn.answer). ``--plane``
trains a gravity variant on the gripper's equilibrium instead (the checkpoint's config
records ``plane``; ``--no-plane``, the gravity default, is accepted). For another finger or chain options the
variant's config is adapted (NNConfig.for_params). Training: predictor.nn.train;
checkpoint: predictor.nn.checkpoint; answers: predictor.nn.answer; evaluation:
predictor.nn.eval. The names re-exported below serve code written against the former
single module; the library modules import them from where they are defined.
"""
from __future__ import annotations

import sys
from dataclasses import asdict, replace

import torch

from contract import cli
from contract.finger import finger_arg
from predictor.solvers import progress
from predictor.model.gripper import (DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, DEFAULT_OUTLINE, JOINT_WEIGHTS, KINEMATICS,
                                     OUTLINES, GripperParams, default_finger)
from predictor.model.joint import load_joint
from predictor.nn.networks import VARIANTS, NNConfig
from predictor.nn.checkpoint import save_predictor
from predictor.nn.train import train
from predictor.solvers.ramp import approach_for

from predictor.nn.networks import (P_SCALE, TAU_SCALE, ContactNet, GestureNet, Predictor,  # noqa: F401
                                   features, network, sample_pressures)
from predictor.nn.answer import NNGestureResult, predict_gesture, raw_answer  # noqa: F401
from predictor.nn.checkpoint import (CONTACT_FORMAT, DEFAULT_DIR, GRAVITY_FORMAT, load_predictor,  # noqa: F401
                                     nn_folder)
from predictor.nn.eval import contact_fraction, evaluate, evaluate_contact, evaluate_polished  # noqa: F401

__all__ = ["CONTACT_FORMAT", "DEFAULT_DIR", "GRAVITY_FORMAT", "P_SCALE", "TAU_SCALE", "VARIANTS", "ContactNet",
           "GestureNet", "NNConfig", "NNGestureResult", "Predictor", "contact_fraction", "evaluate",
           "evaluate_contact", "evaluate_polished", "features", "load_predictor", "main", "network", "nn_folder",
           "predict_gesture", "raw_answer", "sample_pressures", "save_predictor", "train"]


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.cli.nn", description="train an NN gesture predictor")
    ap.add_argument("--variant", choices=sorted(VARIANTS), required=True)
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: the committed surrogate, "
                    "predictor.defaults)")
    ap.add_output("--out", suffix=".pt", required=True, help="checkpoint path (.pt)")
    ap.add_argument("--epochs", type=cli.number(1, None, integer=True),
                    help="override the variant's epochs (smoke runs)")
    ap.add_argument("--finger", type=finger_arg, default=None,
                    help="finger description file (default: the paper's, contract/fingers/paper.toml)")
    ap.add_argument("--kinematics", choices=KINEMATICS, default=DEFAULT_KINEMATICS)
    ap.add_argument("--joint-weight", choices=JOINT_WEIGHTS, default=DEFAULT_JOINT_WEIGHT)
    ap.add_argument("--outline", choices=OUTLINES, default=DEFAULT_OUTLINE,
                    help="the joints' outline the gripper's contacts see (a network learned apart answers for any)")
    side = ap.add_mutually_exclusive_group()
    side.add_argument("--plane", dest="plane", action="store_const", const=True,
                      help="gravity variants: learn the gripper's equilibrium, the right finger against the mirror "
                           "finger's contact at X = 0 (default: one finger alone, which may cross X = 0)")
    side.add_argument("--no-plane", dest="plane", action="store_const", const=False,
                      help="gravity variants: one finger alone (the default)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = ap.parse_args(argv)
    if args.plane is False and VARIANTS[args.variant].obstacle is not None:
        ap.error(f"--no-plane: the {args.variant} variant learns a grasp, which the gripper's plane X = 0 is part of")
    progress.set_quiet(args.quiet)
    torch.set_num_threads(1)
    cfg = VARIANTS[args.variant] if args.plane is None else replace(VARIANTS[args.variant], plane=args.plane)
    with ap.errors():
        finger = args.finger or default_finger()
        joint = load_joint(args.model, finger)
        params = GripperParams(finger, kinematics=args.kinematics, joint_weight=args.joint_weight, outline=args.outline)
        if params != cfg.params() or params.n_joints != cfg.widths[0]:
            cfg = cfg.for_params(params)
        if cfg.approach is not None and len(cfg.approach) != params.n_joints:
            cfg = replace(cfg, approach=approach_for(params.n_joints))
        cfg.problem(joint)  # refuses cap kinematics on a joint without a cap head, before training
    if args.epochs:
        cfg = NNConfig(**{**asdict(cfg), "epochs": args.epochs})
    pred = train(cfg, joint)
    with ap.errors():
        save_predictor(pred, args.out)
    out = {"out": args.out, **pred.metrics}
    if args.json:
        cli.print_json(out)
    else:
        print(f"[nn {cfg.variant}] wrote {args.out}: validation residual {pred.metrics['val']['force_mN_mean']:.3g} mN, "
              f"{pred.metrics['val']['moment_Nmm_mean']:.3g} N·mm (mean, raw NN)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
