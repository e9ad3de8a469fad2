"""Neural gesture predictors: networks (P_1 .. P_J) MPa -> tau = (F1 N, F2 N, M N·mm) per
joint of a finger of J joints, and the configurations they are trained with.

Scaling: the input is P / P_SCALE (P_SCALE = 0.3 MPa, so [-1, 1] over the box), with
``abs_pressure`` |P| / 0.3 beside it (``features``); the output is multiplied by TAU_SCALE
= (1 N, 1 N, 30 N·mm) per joint.

Variants (VARIANTS, ``python -m predictor.cli.nn --variant ...``):
- ``gravity-paper``: the paper's 2 -> 32 -> 64 -> 64 -> 32 -> 6 ReLU MLP, 4000 training and
  800 validation pairs uniform in [-0.3, 0.3]², Adam, batch 20, lr 3e-4 decayed ×0.94 per
  epoch, 75 epochs, equilibrium loss only (predictor.nn.train).
- ``gravity-improved``: 2 -> 128 -> 128 -> 128 -> 6 with SiLU (smooth, so the residual can
  go to zero instead of stalling on ReLU's kinks), supervised by the Newton solver's
  equilibria at 20,000 pressures, Adam (batch 200, lr 3e-3 decayed ×0.95, 60 epochs), then
  500 iterations of full-batch L-BFGS.
  Both gravity variants learn one finger alone (``NNConfig.training_problem``, ``plane``
  False), as the paper's do: a smooth map of the pressures whose gestures may cross X = 0.
  They answer the gripper (the right finger against the plane X = 0 where the mirror
  finger meets it): where the finger stays at X >= 0 the two problems are the same and the
  network's own tau is the answer; where it presses on the plane, whose stiff penalty turns
  a tau error of 1e-6 N into a residual over 10 mN, no network's tau meets the NN bound and
  the delivered path polishes it (predictor.nn.answer). ``plane=True``
  (``predictor.cli.nn --plane``) learns the gripper itself instead: measured on the production
  surrogate, that network is about 6x less accurate away from the plane (1.29 mN against
  0.21 mN mean, 400 random pressures) and leaves 89 of 400 pressures unanswered, the lone
  finger's 1 (docs/gripper.md §11).
- ``contact``: the grasp of the default circle (statics.Obstacle: r = 30 mm, 0.2 N, centre
  Y = -195 mm; approach P = APPROACH) for (P1, P2) in [-0.15, 0.2] x [-0.05, 0.25], a domain
  with gestures that touch nothing, hold and slip. A ContactNet: a grasp-state classifier
  (SiLU 2 -> 128 -> 128 -> 128 -> 3 logits) and one SiLU 2 -> 128 -> 128 -> 128 -> 6 head per
  state, each head with ``refine_stages`` = 2 correction MLPs (2 -> 64 -> 64 -> 64 -> 6).
  Inside one state's region of the pressure plane the equilibrium is smooth; across the
  borders (contact onset, the friction cone's edge) it has kinks that one MLP rounds off,
  so each head fits one smooth piece and the classifier puts the borders where the solver's
  labels do. Every network sees |P| beside P: the joint surrogate takes |P| as an input,
  so the equilibria also have kinks along every P_i = 0. Corners of the box where the
  ramp's grasp changes branch (the tip slides off the object: tau jumps) lie outside the
  domain.

Fingers: a network is (P_1 .. P_J) -> tau (J, 3) for the finger of its config (``finger``:
contract.finger.finger_to_dict, None = the paper's finger) with its ``kinematics`` and
``joint_weight`` options (``NNConfig.for_params``); a predictor answers only for those.

Data flow: NNConfig -> ``network`` (untrained) -> predictor.nn.train.train -> Predictor
(network, config, joint name, metrics, history) -> predictor.nn.answer.predict_gesture, or
predictor.nn.checkpoint.save_predictor.
"""
from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field, replace

import torch
from torch import nn

from contract.finger import finger_from_dict, finger_to_dict
from contract.spec import PRESSURE_LIMIT
from predictor.model.gripper import DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, DEFAULT_OUTLINE, GripperParams, default_finger
from predictor.model.joint import JointModel
from predictor.solvers.ramp import APPROACH
from predictor.model.statics import HOLDS, NO_CONTACT, SLIPS, GripperProblem, Obstacle, apart


TAU_SCALE = (1.0, 1.0, 30.0, 1.0, 1.0, 30.0)
P_SCALE = PRESSURE_LIMIT  # MPa: the network sees P / 0.3, in [-1, 1] over the box


@dataclass(frozen=True)
class NNConfig:
    """Training configuration. Pressures MPa; lr per step; decay per epoch."""

    variant: str = "gravity-paper"
    widths: tuple = (2, 32, 64, 64, 32, 6)
    activation: str = "relu"
    n_train: int = 4000
    n_val: int = 800
    epochs: int = 75
    batch: int = 20
    lr: float = 3e-4
    decay: float = 0.94
    lbfgs_iters: int = 0
    supervised: bool = False
    state_heads: bool = False  # ContactNet: a grasp-state classifier and one tau head per state
    # ContactNet heads of the contact states: weight (per mm²) of the contact sample points'
    # squared error against the label's pose, added to the scaled tau error (``train``);
    # 0: tau alone
    pose_weight: float = 0.0
    # ContactNet: correction stages per head (multi-stage training). Stage s of a head is a
    # (J, *refine_hidden, 3J) MLP fitted to the tau error that the head and stages < s leave
    # on its state's labels, that error's RMS per output being its tau_scale (``train``):
    # refine_epochs of Adam (lr decayed x refine_decay per epoch), refine_lbfgs_iters of L-BFGS
    refine_stages: int = 0
    refine_hidden: tuple = (64, 64, 64)
    refine_epochs: int = 200
    refine_decay: float = 0.99
    refine_lbfgs_iters: int = 1500
    abs_pressure: bool = False  # the networks see |P| beside P (``features``)
    p1_range: tuple = (-PRESSURE_LIMIT, PRESSURE_LIMIT)
    p2_range: tuple = (-PRESSURE_LIMIT, PRESSURE_LIMIT)
    obstacle: dict | None = None
    approach: tuple | None = None
    seed: int = 0
    finger: dict | None = None  # contract.finger.finger_to_dict; None: the paper's finger
    kinematics: str = DEFAULT_KINEMATICS
    joint_weight: str = DEFAULT_JOINT_WEIGHT
    # The problem the labels (and the equilibrium loss) are of and the raw residual is
    # judged on (``training_problem``): one finger alone (False, statics.apart: the gravity
    # variants), or the gripper, the right finger against the plane X = 0 where the mirror
    # finger meets it (True, the Newton solver's default problem: the contact variant; a
    # gravity variant with ``predictor.cli.nn --plane``). A checkpoint without the key was
    # trained before it was recorded, on one finger alone (predictor.nn.checkpoint).
    plane: bool = False
    # The joints' outline (GripperParams.outline) of the problem the network answers: it
    # enters the labels only of a network that learns the gripper (``learns_gripper``: the
    # plane or an object touches the outline); one learned apart answers for any outline,
    # polished on the one asked for (predictor.nn.checkpoint). Checkpoints without the key
    # were trained with ``band``.
    outline: str = DEFAULT_OUTLINE

    def params(self) -> GripperParams:
        """The finger and chain options this predictor is trained for."""
        finger = finger_from_dict(self.finger) if self.finger is not None else default_finger()
        return GripperParams(finger, kinematics=self.kinematics, joint_weight=self.joint_weight,
                             outline=self.outline)

    def problem(self, joint: JointModel) -> GripperProblem:
        """The gesture problem this predictor answers, on ``joint``: the gripper (its finger
        and options; default contact law, the plane X = 0 included, and gravity). The
        delivered answers are checked, and polished, on it (predictor.nn.answer)."""
        return GripperProblem(joint, self.params(), obstacle=Obstacle(**self.obstacle) if self.obstacle else None,
                              approach=self.approach)

    def training_problem(self, joint: JointModel) -> GripperProblem:
        """The problem the network learns and its raw residual is judged on: for a gravity
        network (no object) configured ``plane=False`` (the default) one finger alone,
        without the plane (statics.apart), a smooth map of the pressures whose gestures
        may cross X = 0 as the paper's do, whose own tau answers the gripper where its
        finger stays at X >= 0 (where it presses on the plane the answer is its polish,
        predictor.nn.answer); else ``problem`` itself, the gripper with the plane X = 0. A
        contact network's is always the grasp with the plane."""
        problem = self.problem(joint)
        return problem if self.obstacle or self.plane else apart(problem)

    def learns_gripper(self) -> bool:
        """Whether the network learned the gripper's equilibrium, the problem it answers
        (``problem``), rather than one finger alone."""
        return bool(self.obstacle) or self.plane

    def for_params(self, params: GripperParams) -> "NNConfig":
        """This config for another finger or options: the finger recorded, the network's
        input and output widths set to its J pressures and 3J loads (pressure ranges:
        joint 1 takes p1_range, every other joint p2_range)."""
        J = params.n_joints
        return replace(self, finger=finger_to_dict(params.finger), kinematics=params.kinematics,
                       joint_weight=params.joint_weight, outline=params.outline, widths=(J,) + tuple(self.widths[1:-1]) + (3 * J,))


VARIANTS = {
    "gravity-paper": NNConfig(),
    "gravity-improved": NNConfig(variant="gravity-improved", widths=(2, 128, 128, 128, 6), activation="silu",
                                 n_train=20000, epochs=60, batch=200, lr=3e-3, decay=0.95, lbfgs_iters=500,
                                 supervised=True),
    "contact": NNConfig(variant="contact", widths=(2, 128, 128, 128, 6), activation="silu", n_train=20000,
                        n_val=400, epochs=60, batch=200, lr=3e-3, decay=0.95, lbfgs_iters=500, supervised=True,
                        state_heads=True, pose_weight=1.0, refine_stages=2, abs_pressure=True, p1_range=(-0.15, 0.2),
                        p2_range=(-0.05, 0.25),
                        obstacle=asdict(Obstacle()), approach=APPROACH, plane=True),
}


class GestureNet(nn.Module):
    """MLP (B, J) MPa -> tau (B, J, 3) [N, N, N·mm] with fixed input/output scaling
    (J = widths[0]; widths[-1] = 3J); with ``abs_pressure`` it sees |P| beside P
    (``features``)."""

    def __init__(self, widths: tuple, activation: str, abs_pressure: bool = False):
        super().__init__()
        act = {"relu": nn.ReLU, "silu": nn.SiLU, "tanh": nn.Tanh}[activation]
        self.abs_pressure = abs_pressure
        layers: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(widths[:-1], widths[1:])):
            layers.append(nn.Linear(a * (1 + abs_pressure) if i == 0 else a, b))
            if i < len(widths) - 2:
                layers.append(act())
        self.mlp = nn.Sequential(*layers).double()
        self.register_buffer("tau_scale", torch.tensor(TAU_SCALE[:3] * (widths[-1] // 3), dtype=torch.float64))

    def forward(self, pressures: torch.Tensor) -> torch.Tensor:
        return (self.mlp(features(pressures, self.abs_pressure)) * self.tau_scale).reshape(pressures.shape[0], -1, 3)


def features(pressures: torch.Tensor, abs_pressure: bool) -> torch.Tensor:
    """A network's input: P / 0.3 (B, J), and with ``abs_pressure`` |P| / 0.3 beside it (B,
    2J). The joint surrogate takes |P| as an input too (its config's abs_pressure), so its
    response has a kink at P = 0, and the equilibria inherit one along every P_i = 0: the
    raw contact network's largest residuals lay there until it saw |P|."""
    z = pressures / P_SCALE
    return torch.cat((z, z.abs()), -1) if abs_pressure else z


class ContactNet(nn.Module):
    """A grasp-state classifier and one GestureNet per state: (B, J) MPa -> tau (B, J, 3)
    from the head of the predicted state (``state``: codes of statics.STATES).

    Inside one state's region of the pressure plane the equilibrium is smooth; across the
    borders (contact onset, the friction cone's edge, the approach's branch) it has kinks
    that a single MLP rounds off, over a band as wide as its resolution. Here each head
    fits one smooth piece and the classifier (widths[:-1] -> 3 logits, same activation)
    puts the borders where the solver's labels do.

    refine[k] holds ``refine_stages`` correction MLPs (hidden widths ``refine_hidden``) of
    head k: its tau is the head's plus every stage's (``head_tau``).
    """

    def __init__(self, widths: tuple, activation: str, refine_hidden: tuple = (), refine_stages: int = 0,
                 abs_pressure: bool = False):
        super().__init__()
        states = (NO_CONTACT, HOLDS, SLIPS)
        self.abs_pressure = abs_pressure
        self.classifier = GestureNet(tuple(widths[:-1]) + (3,), activation, abs_pressure).mlp
        self.heads = nn.ModuleList(GestureNet(widths, activation, abs_pressure) for _ in states)
        stage = (widths[0],) + tuple(refine_hidden) + (widths[-1],)
        self.refine = nn.ModuleList(nn.ModuleList(GestureNet(stage, activation, abs_pressure)
                                                  for _ in range(refine_stages)) for _ in states)

    def logits(self, pressures: torch.Tensor) -> torch.Tensor:
        """The classifier's (B, 3) logits of the grasp states."""
        return self.classifier(features(pressures, self.abs_pressure))

    def state(self, pressures: torch.Tensor) -> torch.Tensor:
        return self.logits(pressures).argmax(-1)

    def head_tau(self, k: int, pressures: torch.Tensor, stages: int | None = None) -> torch.Tensor:
        """tau (B, J, 3) of state k's head and its first ``stages`` corrections (None: all)."""
        tau = self.heads[k](pressures)
        for stage in self.refine[k][:stages]:
            tau = tau + stage(pressures)
        return tau

    def tau_and_state(self, pressures: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(tau (B, J, 3), state (B,)): each pressure through its state's head only."""
        state = self.state(pressures)
        tau = pressures.new_empty(pressures.shape[0], pressures.shape[1], 3)
        for k in range(len(self.heads)):
            rows = state == k
            if bool(rows.any()):
                tau[rows] = self.head_tau(k, pressures[rows])
        return tau, state

    def forward(self, pressures: torch.Tensor) -> torch.Tensor:
        return self.tau_and_state(pressures)[0]


def network(cfg: NNConfig) -> nn.Module:
    """The untrained network of a config: ContactNet with ``state_heads``, else GestureNet."""
    if cfg.state_heads:
        return ContactNet(cfg.widths, cfg.activation, cfg.refine_hidden, cfg.refine_stages, cfg.abs_pressure)
    return GestureNet(cfg.widths, cfg.activation, cfg.abs_pressure)


@dataclass
class Predictor:
    """A trained network plus what it was trained for (joint name, object, approach)."""

    net: nn.Module  # GestureNet, or ContactNet (config.state_heads)
    config: NNConfig
    joint_name: str
    metrics: dict = field(default_factory=dict)
    history: dict = field(default_factory=dict)

    def astype(self, dtype: torch.dtype) -> "Predictor":
        """A copy whose network is in ``dtype``: with ``problem.astype(dtype)`` and pressures
        of that dtype, predict_gesture runs in it (float32: the batched throughput mode;
        float64, as trained and loaded, otherwise)."""
        return replace(self, net=copy.deepcopy(self.net).to(dtype))


def sample_pressures(n: int, cfg: NNConfig, gen: torch.Generator) -> torch.Tensor:
    """n pressure tuples (n, J) MPa (J = widths[0]), uniform in the config's ranges: P1 in
    p1_range, every other joint's in p2_range."""
    J = cfg.widths[0]
    u = torch.rand(n, J, generator=gen, dtype=torch.float64)
    lo = torch.tensor([cfg.p1_range[0]] + [cfg.p2_range[0]] * (J - 1), dtype=torch.float64)
    hi = torch.tensor([cfg.p1_range[1]] + [cfg.p2_range[1]] * (J - 1), dtype=torch.float64)
    return lo + u * (hi - lo)
