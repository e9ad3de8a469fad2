"""NN predictor checkpoints: integrity-checked files (surrogate.checkpoint) of kind
GRAVITY_FORMAT ``softjoint-gravity-nn/1`` (trained without an object) or CONTACT_FORMAT
``softjoint-contact-nn/1``. Payload: ``config`` (NNConfig as a dict), ``state_dict`` (the
weights), ``joint`` (the joint model's name), ``normalisation`` {p_scale_MPa: 0.3,
tau_scale: TAU_SCALE}, ``metrics`` and ``history`` (per logged epoch). ``load_predictor``
needs only the file, and refuses a damaged, foreign or other-kind file, another joint or
another finger with one line, and a joint model whose joint description is not the one
the finger's joint parts name (predictor.model.joint.check_finger).
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, replace
from pathlib import Path

from predictor.defaults import default_nn_dir
from predictor.model.gripper import DEFAULT_OUTLINE, GripperParams
from predictor.model.joint import JointModel, check_finger
from predictor.nn.networks import P_SCALE, TAU_SCALE, NNConfig, Predictor, network
from surrogate import checkpoint


#: Checkpoint kinds, by whether the predictor was trained with an object.
GRAVITY_FORMAT = "softjoint-gravity-nn/1"
CONTACT_FORMAT = "softjoint-contact-nn/1"


#: The committed NN predictors' folder (predictor.defaults: from the package or
#: $SOFTJOINT_RESULTS, never the working directory).
DEFAULT_DIR = default_nn_dir()


def checkpoint_kind(contact: bool) -> str:
    return CONTACT_FORMAT if contact else GRAVITY_FORMAT


def save_predictor(pred: Predictor, path: str | Path) -> None:
    """Write the checkpoint (config, normalisation, metrics, history, weights) atomically,
    of kind CONTACT_FORMAT when the config has an object, else GRAVITY_FORMAT."""
    checkpoint.save(path, checkpoint_kind(pred.config.obstacle is not None), {
        "config": asdict(pred.config), "state_dict": pred.net.state_dict(), "joint": pred.joint_name,
        "normalisation": {"p_scale_MPa": P_SCALE, "tau_scale": TAU_SCALE},
        "metrics": pred.metrics, "history": pred.history})


def load_predictor(path: str | Path | None, joint: JointModel | None = None, contact: bool = False,
                   params: GripperParams | None = None) -> Predictor:
    """Load a checkpoint of the gravity (or, with ``contact``, the contact) kind; path
    None picks results/predictor/{gravity,contact}_nn.pt. ``joint`` None skips the check
    that the NN was trained on that joint (reading its history only); ``params`` None
    skips the check that it was trained for that finger, kinematics and joint weights;
    with both, ``joint`` must be of the joint description the finger names (check_finger).

    Raises ValueError (one line): a missing, damaged, foreign or other-kind file
    (surrogate.checkpoint.CheckpointError), a joint mismatch or a finger/options mismatch.
    """
    path = Path(path) if path else default_nn_dir() / ("contact_nn.pt" if contact else "gravity_nn.pt")
    ck = checkpoint.load(path, checkpoint_kind(contact), "NN predictor checkpoint")
    try:
        # Checkpoints written before the chain options record them were trained with the
        # paper's chain (tangent kinematics, lumped joint weights), not today's defaults;
        # those written before ``plane`` was recorded learned one finger alone (a gravity
        # network's labels without the plane X = 0; a contact network's always had it);
        # those written before ``outline`` was recorded had the band outline.
        legacy = {"kinematics": "tangent", "joint_weight": "lumped", "plane": contact, "outline": "band"}
        saved = {**legacy, **ck["config"]}
        cfg = NNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved.items()})
        if not cfg.learns_gripper():
            # Learned one finger alone: no outline entered its labels, so it answers for the
            # outline asked for (the default one without ``params``), polished on it.
            cfg = replace(cfg, outline=params.outline if params is not None else DEFAULT_OUTLINE)
        trained_params = cfg.params()
        net = network(cfg)
        net.load_state_dict(ck["state_dict"])
        joint_name, metrics, history = ck["joint"], ck["metrics"], ck["history"]
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:  # intact file, inconsistent payload
        raise checkpoint.CheckpointError(f"{path}: inconsistent NN predictor checkpoint "
                                         f"({type(exc).__name__}: {str(exc).splitlines()[0][:120]})") from None
    if params is not None and params != trained_params:
        raise ValueError(f"{path} was trained for {trained_params.describe()}, not {params.describe()}: an NN "
                         "predictor answers only its own finger and options (train one for these with python -m "
                         "predictor.cli.nn --finger FILE, or solve with the iterative solvers)")
    if joint is not None and joint_name != joint.name:
        raise ValueError(f"{path} was trained with joint {joint_name!r}, not {joint.name!r}")
    if joint is not None and params is not None:
        check_finger(joint, params.finger)
    return Predictor(net.eval(), cfg, joint_name, metrics, history)


def nn_folder(text: str) -> Path:
    """argparse type: an existing folder of NN predictor checkpoints."""
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder")
    return Path(text)
