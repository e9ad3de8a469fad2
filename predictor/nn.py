"""Neural gesture predictor: an MLP (P1, P2) -> tau = (tau_1, tau_2), trained on the
equilibrium loss of predictor.statics (Equation 1), so no FEM labels are needed.

Network: input P/0.3 (dimensionless), hidden widths ``config.widths``, output
(F1, F2, M)_1,2 multiplied by TAU_SCALE = (1 N, 1 N, 30 N·mm). Data flow: random
(P1, P2) -> net -> tau -> statics.residual -> loss = mean_b [R_F² + (R_M/100 mm)²]
(+ out-of-box penalty). The gesture then follows from forward kinematics.

Variants (``python -m predictor.nn --variant ...``):
- ``gravity-paper``: the paper's 2 -> 32 -> 64 -> 64 -> 32 -> 6 ReLU MLP, 4000 training and
  800 validation pairs uniform in [-0.3, 0.3]², Adam, batch 20, lr 3e-4 decayed ×0.94 per
  epoch, 75 epochs, equilibrium loss only.
- ``gravity-improved``: 2 -> 128 -> 128 -> 128 -> 6 with SiLU (smooth, so the residual
  can go to zero instead of stalling on ReLU's kinks), supervised by the Newton solver's
  equilibria at 20,000 pressures (labels: one batched solve, seconds), Adam with batch
  200 and lr 3e-3 decayed ×0.95 for 60 epochs, then 500 iterations of full-batch L-BFGS.
  Tried and dropped: the same kind of net (2 -> 64 x 3 -> 6) trained on the equilibrium
  loss alone (Adam, then 3000 L-BFGS iterations on 4000 pairs) stayed worse than the
  paper's MLP (0.52 against 0.39 mN, 0.078 against 0.034 N·mm).
- ``contact``: the grasp of the circle (r = 30 mm, 0.2 N, centre Y = -195 mm, approach
  P = (-0.15, 0), see statics.Obstacle) for (P1, P2) in [-0.15, 0.2] x [-0.05, 0.25],
  which contains gestures without contact (about 24 %), holding (11 %) and slipping (65 %).
  The equilibrium loss alone is as stiff as the penalty (dR/dtau ~ k_c × contact
  length), which is where the paper stalled. What works: supervision from the batched
  iterative solver along the pressure ramp (labels are cheap: one batched solve of 20,000
  pressures), and a ContactNet: a grasp-state classifier (SiLU 2 -> 128 -> 128 -> 128 ->
  3, cross-entropy, Adam) and one SiLU 2 -> 128 -> 128 -> 128 -> 6 head per state (Adam +
  L-BFGS on its state's labels), so that no head has to round off a kink of the contact
  law. Each head's loss is the scaled tau error, plus, for the holding and slipping
  heads, the squared miss (mm², weight ``pose_weight`` = 1) of the finger's contact
  sample points at its tau against the label's: while slipping, a small tau error moves
  the fingertip far (the finger slides along the object), and the penalty contact
  answers the pose (bench-predictor, previous checkpoint against the next: raw fingertip
  error 0.066 -> 0.038 mm, raw residual 261 -> 135 mN; weight 100 fitted worse in an
  exploratory run). Each head then has ``refine_stages`` = 2 correction stages
  (multi-stage training, ``_fit_stage``): SiLU 2 -> 64 -> 64 -> 64 -> 6 MLPs, each fitted
  (200 Adam epochs, lr decayed x0.99, then 1500 L-BFGS iterations) to the tau error the
  head and the stages before it leave on the state's labels, divided by that error's
  RMS, so that its loss starts near 6 (one per output). Every network (classifier,
  heads, stages) sees |P| beside P (``abs_pressure``, ``features``): the joint surrogate
  takes |P| as an input, so the equilibria have kinks along P1 = 0 and P2 = 0, where the
  largest raw residuals of the networks without it lay. In the committed checkpoint's
  history the first stage's loss ends at 2.1e-3 (holds) and 1.8e-3 (slips), the
  second's at 4.8 for both: a stage resolves what the head's own
  optimisation no longer does, once (a third stage, tried in an exploratory run, fitted
  nothing more). bench-predictor, the checkpoint before the stages, then with the stages
  alone, then with |P| as well: raw residual 135 -> 2.49 -> 1.04 mN mean (p95 615 -> 8.2
  -> 3.1 mN; moment 19.4 -> 0.35 -> 0.15 N·mm), raw fingertip error 0.038 mm -> 0.6 µm ->
  0.3 µm: the issue's raw bounds (2 mN, 1.2 N·mm mean; 10 mN, 5 N·mm p95) are met with
  no solver; one closed-form Gauss-Newton step from the raw tau (``evaluate_contact``'s
  ``newton_step_from_raw``) gives 0.0056 mN mean.
  The delivered gesture starts full Newton steps from the network's tau
  (solve.newton_iterate) and keeps their answer where it converges on the network's
  branch (``_newton_on_branch``: fingertip within BRANCH_TIP_MM, the classifier's grasp
  state); elsewhere it warm-starts the LM from the network's tau with a small step cap
  (a local polish, Jacobian by differences, the exact one where that stalls), and
  samples it cannot converge fall back to the full ramp (bench-predictor:
  ``contact_nn_newton_rate``, ``contact_nn_polished_fallback_rate``); the checkpoint
  records the raw and the delivered figures. Tried and dropped (no longer in the
  code): one MLP for all states (2,000 labels: fingertip 0.25 mm from the solver's, state
  by its tau's contact 39 %); before the correction stages, a fixed number of
  closed-form Newton steps as the network's own answer (one full Gauss-Newton step took
  the mean fingertip error from 0.038 to 3.1 mm: the steps converge only from close to
  the equilibrium); and
  fine-tuning on the equilibrium loss: the raw residual fell to 88 mN / 16 N·mm, the
  paper's regime, but the net learned to lift the finger off the object (contact fraction
  42 % -> 27 %) and the polish then needed the fallback for 23 % of the queries. Corners
  of the pressure box where the ramp's grasp changes branch (the tip slides off the
  object: tau jumps) are left out of the NN's domain.

Fingers (issue 14): the network is (P1..PJ) -> tau (J, 3) for the finger of its config
(``finger``: contract.finger.finger_to_dict, None = the paper's finger, which is what
checkpoints written before the option record), with its ``kinematics`` and
``joint_weight`` options (default: predictor.gripper's, cap and split); ``--finger``, ``--kinematics`` and
``--joint-weight`` train for others. A predictor answers only for the finger and options
it was trained for (``load_predictor(..., params=)`` refuses others with one line).

Checkpoints (DESIGN.md §5): integrity-checked files (surrogate.checkpoint) of kind
``softjoint-gravity-nn/1`` (no object) or ``softjoint-contact-nn/1``, whose payload holds
the training config, normalisation (input 0.3 MPa, TAU_SCALE), the weights, the joint
name it was trained on, metrics and per-epoch history; ``load_predictor`` needs only the
file, and refuses a damaged, foreign or other-kind file with one line (CheckpointError).
"""
from __future__ import annotations

import argparse
import copy
import math
import sys
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import torch
from torch import nn

from contract import cli
from contract.finger import finger_arg, finger_from_dict, finger_to_dict
from contract.spec import PRESSURE_LIMIT
from predictor import progress
from predictor.defaults import default_nn_dir
from predictor.gripper import (DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, JOINT_WEIGHTS, KINEMATICS, GripperParams,
                               check_pressures, default_finger, nan_unless)
from predictor.joint import JointModel, load_joint
from predictor.solve import (APPROACH, GestureResult, SolverOptions, gesture_result, meets_tolerances,
                             newton_iterate, newton_polish, newton_step, result_labels, solve, statics_at)
from predictor.statics import (HOLDS, NO_CONTACT, SLIPS, GripperProblem, Obstacle, Statics, grasp_state, loss,
                               residual_norms)
from surrogate import checkpoint

TAU_SCALE = (1.0, 1.0, 30.0, 1.0, 1.0, 30.0)
P_SCALE = PRESSURE_LIMIT  # MPa: the network sees P / 0.3, in [-1, 1] over the box
#: Checkpoint kinds, by whether the predictor was trained with an object.
GRAVITY_FORMAT = "softjoint-gravity-nn/1"
CONTACT_FORMAT = "softjoint-contact-nn/1"
#: The committed NN predictors' folder (predictor.defaults: from the package or
#: $SOFTJOINT_RESULTS, never the working directory).
DEFAULT_DIR = default_nn_dir()
# LM step cap (scaled units) when polishing a contact NN prediction: small enough that the
# iterates stay on the NN's branch (0.3, the ramp's cap, let 8 of 55 jump to another one).
POLISH_STEP = 0.02
# The NN bound: a prediction counts as an answer only within it.
NN_FORCE_TOL_MN = 2.0
NN_MOMENT_TOL_NMM = 1.2
# mm: a Newton answer from the contact NN's tau counts only if its fingertip is this close to
# the network's (``_newton_on_branch``; bench-predictor's details.contact_nn_vs_solver.
# newton_from_raw gives the largest shift to the ramp's equilibrium and the smallest to another).
BRANCH_TIP_MM = 1.0
BRANCH_ROUNDS = 3    # newton_iterate calls from the contact network's tau (``_newton_on_branch``)


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

    def params(self) -> GripperParams:
        """The finger and chain options this predictor is trained for."""
        finger = finger_from_dict(self.finger) if self.finger is not None else default_finger()
        return GripperParams(finger, kinematics=self.kinematics, joint_weight=self.joint_weight)

    def problem(self, joint: JointModel) -> GripperProblem:
        """The gesture problem this predictor is trained for, on ``joint`` (its finger and
        options; default contact law and gravity)."""
        return GripperProblem(joint, self.params(), obstacle=Obstacle(**self.obstacle) if self.obstacle else None,
                              approach=self.approach)

    def for_params(self, params: GripperParams) -> "NNConfig":
        """This config for another finger or options: the finger recorded, the network's
        input and output widths set to its J pressures and 3J loads (pressure ranges:
        joint 1 takes p1_range, every other joint p2_range)."""
        J = params.n_joints
        return replace(self, finger=finger_to_dict(params.finger), kinematics=params.kinematics,
                       joint_weight=params.joint_weight, widths=(J,) + tuple(self.widths[1:-1]) + (3 * J,))


VARIANTS = {
    "gravity-paper": NNConfig(),
    "gravity-improved": NNConfig(variant="gravity-improved", widths=(2, 128, 128, 128, 6), activation="silu",
                                 n_train=20000, epochs=60, batch=200, lr=3e-3, decay=0.95, lbfgs_iters=500,
                                 supervised=True),
    "contact": NNConfig(variant="contact", widths=(2, 128, 128, 128, 6), activation="silu", n_train=20000,
                        n_val=400, epochs=60, batch=200, lr=3e-3, decay=0.95, lbfgs_iters=500, supervised=True,
                        state_heads=True, pose_weight=1.0, refine_stages=2, abs_pressure=True, p1_range=(-0.15, 0.2),
                        p2_range=(-0.05, 0.25),
                        obstacle=asdict(Obstacle()), approach=APPROACH),
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


def raw_answer(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor):
    """The network's own answer, no solver: (tau (B, J, 3), Statics at it, grasp state
    (B,) codes: its classifier's for a ContactNet, else its tau's contact)."""
    with torch.no_grad():
        tau, state = net.tau_and_state(pressures) if isinstance(net, ContactNet) else (net(pressures), None)
        st = statics_at(problem, pressures, tau)
    return tau, st, grasp_state(st.contact.normal, st.contact.slip) if state is None else state


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


def _stats(res: torch.Tensor) -> dict:
    """mean / p95 / max over samples of the worst-joint force (mN) and moment (N·mm)."""
    f, m = residual_norms(res)
    f, m = f.amax(-1), m.amax(-1)
    q = lambda v, a: float(torch.quantile(v, a))  # noqa: E731
    return {"force_mN_mean": float(f.mean()), "force_mN_p95": q(f, 0.95), "force_mN_max": float(f.max()),
            "moment_Nmm_mean": float(m.mean()), "moment_Nmm_p95": q(m, 0.95), "moment_Nmm_max": float(m.max())}


def evaluate(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor) -> dict:
    """Residual statistics of the raw NN tau on pressures (B, J) (see _stats)."""
    with torch.no_grad():
        return _stats(problem.residual(pressures, net(pressures)).residual)


def evaluate_polished(pred: "Predictor", joint: JointModel, pressures: torch.Tensor) -> dict:
    """The delivered contact predictor (NN + Newton steps kept on its branch, else the capped
    LM polish, then the ramp) on pressures: residual statistics of the answers, how many
    the Newton steps answered and how many needed the ramp."""
    problem = pred.config.problem(joint)
    res = predict_gesture(pred, problem, pressures)
    ok = res.converged
    stats = _stats(problem.residual(pressures[ok], res.tau[ok]).residual)
    return {**stats, "converged": int(ok.sum()), "n": len(ok), "fallback": int(res.fallback.sum()),
            "newton_from_nn": int(res.stepped.sum()),
            "median_polish_iterations": float(res.iterations.double().median()),
            "batch_time_ms": res.time_ms}


def evaluate_contact(pred: "Predictor", joint: JointModel, pressures: torch.Tensor) -> dict:
    """The raw contact network on pressures (B, J) against its target, the iterative
    solver's equilibrium along the pressure ramp from the approach gesture (where a final
    pressure pair has several equilibria, the ramp's is the one meant):

    raw, raw_contact, raw_contact_free: residual statistics (_stats) of the network's own
    tau over every pressure the solver converged on, and over those whose equilibrium
    touches the object or not; state_agreement: fraction whose grasp state by the network
    (no contact, holds, slips: its classifier's, ContactNet, or else the contact of its
    tau) is the solver's, and state_agreement_of_tau that of its tau's contact alone;
    raw_tip_error_mm: the raw gesture's fingertip against the solver's (mean / p95 / max);
    reference_penetration_mm: the solver's own penetration of the object at its contact
    equilibria (mean / p95), the scale the raw pose must hit for the penalty force to
    balance; newton_step_from_raw: the residual (_stats) and fingertip error (mean, mm)
    after one full Gauss-Newton step from the raw tau (exact Jacobian, no damping or
    check), the closed-form step the issue allows beside the raw network (from a network
    far from the equilibrium it jumps branches: 3.1 mm from 0.038 mm); newton_from_raw: where
    full Newton steps from the raw tau end (``_branch_figures``), the first stage of the
    delivered path."""
    problem = pred.config.problem(joint)
    ref = solve(problem, pressures)
    ok = ref.converged
    tau, st, by_net = raw_answer(pred.net, problem, pressures)
    of_tau = grasp_state(st.contact.normal, st.contact.slip)
    touch = ref.normal_force_N > 0
    truth = grasp_state(ref.normal_force_N, ref.slip)
    tip = (st.pose.tip_end - ref.pose.tip_end).norm(dim=-1)[ok]
    depth = problem.residual(pressures[ok & touch], ref.tau[ok & touch]).contact.penetration
    kept_res, kept = _newton_on_branch(problem, pressures, tau, st, by_net, time.perf_counter())
    conv = meets_tolerances(kept_res, kept_res.tau.reshape(len(tau), -1), SolverOptions()) & ok
    shift = (kept_res.pose.tip_end - st.pose.tip_end).norm(dim=-1)
    on_ref = (kept_res.tau - ref.tau).abs().amax((-1, -2)) <= 1e-4
    x1 = newton_step(problem, pressures, tau)
    st1 = problem.residual(pressures, x1)
    tip1 = (st1.pose.tip_end - ref.pose.tip_end).norm(dim=-1)[ok]
    cfg = pred.config
    return {"raw": _stats(st.residual[ok]),
            "raw_contact": _stats(st.residual[ok & touch]) if bool((ok & touch).any()) else None,
            "raw_contact_free": _stats(st.residual[ok & ~touch]) if bool((ok & ~touch).any()) else None,
            "state_agreement": float((by_net == truth)[ok].double().mean()),
            "state_agreement_of_tau": float((of_tau == truth)[ok].double().mean()),
            "state_by": "classifier" if isinstance(pred.net, ContactNet) else "contact of the raw tau",
            "raw_tip_error_mm": {"mean": float(tip.mean()), "p95": float(torch.quantile(tip, 0.95)),
                                 "max": float(tip.max())},
            "reference_penetration_mm": {"mean": float(depth.mean()), "p95": float(torch.quantile(depth, 0.95))},
            "newton_step_from_raw": {**_stats(st1.residual[ok]), "tip_error_mm_mean": float(tip1.mean())},
            "newton_from_raw": _branch_figures(conv, kept & ok, on_ref, shift),
            "n": len(ok), "reference_converged": int(ok.sum()), "reference_in_contact": int((ok & touch).sum()),
            "domain_MPa": {"P1": list(cfg.p1_range), "P2": list(cfg.p2_range)},
            "reference": "predictor.solve along the pressure ramp from the approach gesture"}


def _branch_figures(conv: torch.Tensor, kept: torch.Tensor, on_ref: torch.Tensor, shift: torch.Tensor) -> dict:
    """What full Newton steps from a contact network's tau reach (``_newton_on_branch``),
    over (B,) masks: converged, kept by the branch check, at the ramp's equilibrium (tau
    within 1e-4), and the fingertip's shift from the network's (B,) mm."""
    there, elsewhere = conv & on_ref, conv & ~on_ref
    extreme = lambda v, f: float(f(v)) if len(v) else None  # noqa: E731
    return {"converged": int(conv.sum()), "converged_to_ramp_equilibrium": int(there.sum()),
            "converged_elsewhere": int(elsewhere.sum()), "kept": int(kept.sum()),
            "kept_elsewhere": int((kept & ~on_ref).sum()),
            "tip_shift_mm_max_at_ramp_equilibrium": extreme(shift[there], torch.max),
            "tip_shift_mm_min_elsewhere": extreme(shift[elsewhere], torch.min),
            "branch_tip_mm": BRANCH_TIP_MM}


@dataclass
class NNGestureResult(GestureResult):
    """GestureResult of the NN predictor. raw_residual_force_mN, raw_residual_moment_Nmm
    (B, J): Equation 1 at the network's own tau, before any solver; polished (B,): the
    answer is a solver's polish of the network's tau (contact; gravity with ``polish``),
    not the network's; fallback (B,): the polish did not converge and the full pressure
    ramp solved the sample instead (gravity: the Newton step's check failed and the LM went
    on from it);
    raw_state (B,) codes of statics.STATES: the grasp state by the network itself (its
    classifier; the contact of its tau for a network without one), None without an object;
    stepped (B,): contact, the answer is full Newton steps' from the network's tau (kept on
    its branch, ``_newton_on_branch``), not the capped LM's; None without an object."""

    fallback: torch.Tensor = None
    raw_residual_force_mN: torch.Tensor = None
    raw_residual_moment_Nmm: torch.Tensor = None
    polished: torch.Tensor = None
    raw_state: torch.Tensor = None
    stepped: torch.Tensor = None


def predict_gesture(pred: Predictor, problem: GripperProblem, pressures: torch.Tensor,
                    polish: bool = False, options: SolverOptions = SolverOptions()) -> NNGestureResult:
    """NN gesture in the solver's result format, pressures (B, J) MPa.

    ``problem`` must be the one the NN was trained for (``pred.config.problem(joint)``),
    ValueError otherwise. Gravity: the raw NN tau; ``converged`` means its residual is
    within the NN bound (2 mN, 1.2 N·mm), other samples get NaN. Gravity with ``polish``:
    the NN tau finished by one Newton step (solve.newton_polish; the LM where its check
    fails, ``fallback``) to the iterative solver's tolerances. Contact: full Newton steps
    from the NN tau (solve.newton_iterate), kept where they converge on the network's
    branch (``stepped``, ``_newton_on_branch``); the other samples start again from the NN
    tau with the LM under a small step cap (POLISH_STEP) so the iterates stay on the NN's
    branch, with the Jacobian by differences and then, for the samples that did not
    converge, the exact one; samples neither converges in ``max_iter`` steps are
    re-solved by the full ramp (``fallback``). ``options``: the solvers' tolerances and
    limits (default: the solver's 1e-4 mN, 1e-5 N·mm); a batch job content with the issue's
    0.1 mN, 0.01 N·mm (``SolverOptions(tol_force=1e-4, tol_moment=1e-2)``) mostly takes one
    Newton step instead of two or three.
    """
    trained = pred.config.problem(problem.joint)
    if problem != trained:
        diff = "; ".join(f"{f.name} {getattr(trained, f.name)} (given {getattr(problem, f.name)})"
                         for f in fields(trained) if getattr(problem, f.name) != getattr(trained, f.name))
        raise ValueError(f"this NN predictor was trained for {diff}")
    check_pressures(pressures)
    t0 = time.perf_counter()
    if polish and problem.obstacle is None:
        with torch.no_grad():
            tau = pred.net(pressures)
        res, start = newton_polish(problem, pressures, tau, options, t0=t0)
        f, m = residual_norms(start)   # the network's own residual, from the step's pass
        return NNGestureResult(**{**res.__dict__, "method": "nn+newton"},
                               fallback=res.iterations > 1, polished=res.converged, raw_residual_force_mN=f,
                               raw_residual_moment_Nmm=m)
    tau, st, raw_state = raw_answer(pred.net, problem, pressures)
    f, m = residual_norms(st.residual)
    raw = {"raw_residual_force_mN": f, "raw_residual_moment_Nmm": m}
    if problem.obstacle is None:
        ok = (f.amax(-1) <= NN_FORCE_TOL_MN) & (m.amax(-1) <= NN_MOMENT_TOL_NMM)
        c = st.contact
        return NNGestureResult(
            pressures=pressures, tau=nan_unless(ok, tau), converged=ok, residual_force_mN=f, residual_moment_Nmm=m,
            normal_force_N=c.normal, friction_N=c.friction, friction_ratio=c.ratio, slip=c.slip,
            iterations=torch.zeros(len(ok), dtype=torch.long), time_ms=1e3 * (time.perf_counter() - t0),
            pose=st.pose.masked(ok), method="nn", **result_labels(problem),
            fallback=torch.zeros_like(ok), polished=torch.zeros_like(ok), **raw)
    raw["raw_state"] = raw_state
    res, stepped = _newton_on_branch(problem, pressures, tau, st, raw_state, t0, options)
    rest = ~stepped
    fallback = torch.zeros_like(stepped)
    if bool(rest.any()):
        # The capped LM from the NN's tau (Jacobian by differences, and the exact one where
        # that stalls at a kink of the contact law: solve.attempts), then the full ramp.
        lm = solve(problem, pressures[rest], replace(options, contact_max_step=POLISH_STEP), x0=tau[rest])
        fallback[rest] = ~lm.converged
        if bool((~lm.converged).any()):
            lm = lm.with_rows(~lm.converged, solve(problem, pressures[rest][~lm.converged], options))
        lm.iterations += res.iterations[rest]   # the Newton steps tried first count too
        res = res.with_rows(rest, lm)
    return NNGestureResult(**{**res.__dict__, "time_ms": 1e3 * (time.perf_counter() - t0), "method": "nn+newton"},
                           fallback=fallback, polished=~fallback, stepped=stepped, **raw)


def _newton_on_branch(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor, raw: Statics,
                      raw_state: torch.Tensor, t0: float,
                      options: SolverOptions = SolverOptions()) -> tuple[GestureResult, torch.Tensor]:
    """Full Newton steps from the contact network's tau (solve.newton_iterate) and which of
    their answers to keep: (GestureResult, stepped (B,) bool).

    From the network's tau undamped steps converge for most pressures, but some land on
    another equilibrium, the finger tens of mm away in another grasp state, while the
    ramp's equilibria lie within a fraction of a mm of the network's fingertip
    (``_branch_figures``, in bench-predictor). An answer is kept (``stepped``) when it
    meets the solver's tolerances and stays on the network's branch: fingertip within
    BRANCH_TIP_MM of the network's, the grasp state of its classifier raw_state (B,),
    penetration within max_penetration. The network's own tau is the answer (0 steps)
    where it meets them already; an answer on the branch but short of the tolerances (a
    step that straddled a kink of the contact law contracts less) goes on from where it
    is, up to BRANCH_ROUNDS calls of newton_iterate in all. pressures (B, J) MPa; tau (B,
    J, 3) the network's and raw its Statics; t0: perf_counter time the query began."""
    B, n_joints = pressures.shape
    rows, x, steps, st, res = torch.arange(B), tau.reshape(B, -1), torch.zeros(B, dtype=torch.long), raw, None
    for k in range(BRANCH_ROUNDS + 1):
        p = pressures[rows]
        if k:   # Newton steps from where these rows are
            x, more, _ = newton_iterate(problem, p, x.reshape(-1, n_joints, 3), options)
            steps = steps + more
            st = statics_at(problem, p, x.reshape(-1, n_joints, 3))
        c = st.contact
        first = torch.where((c.normal > 0)[:, None], p, torch.full_like(p, float("nan")))
        part = gesture_result(problem, p, x, torch.ones_like(c.slip), steps, t0, "nn+newton", first, st)
        on_branch = ((grasp_state(c.normal, c.slip) == raw_state[rows])
                     & ((st.pose.tip_end - raw.pose.tip_end[rows]).norm(dim=-1) <= BRANCH_TIP_MM)
                     & (c.penetration <= options.max_penetration))
        part.converged = meets_tolerances(part, x, options) & on_branch
        if res is None:
            res = part
        else:
            mask = torch.zeros(B, dtype=torch.bool)
            mask[rows] = True
            res = res.with_rows(mask, part)
        again = ~part.converged if k == 0 else on_branch & ~part.converged
        if not bool(again.any()):
            break
        rows, x, steps = rows[again], x[again], steps[again]
    return res, res.converged.clone()


def _labels(joint: JointModel, pressures: torch.Tensor, cfg: NNConfig) -> tuple[torch.Tensor, ...]:
    """Iterative-solver labels for pressures (n, J): (pressures, tau (n, J, 3), grasp
    state (n,) codes of statics.STATES), restricted to the converged samples."""
    res = solve(cfg.problem(joint), pressures)
    ok = res.converged
    print(f"[nn] labels: {int(ok.sum())}/{len(ok)} converged in {res.time_ms / 1e3:.1f} s", file=sys.stderr,
          flush=True)
    return pressures[ok], res.tau[ok], grasp_state(res.normal_force_N, res.slip)[ok]


def _fit(module: nn.Module, batch_loss, n: int, cfg: NNConfig, gen: torch.Generator, log=None,
         lbfgs: bool = True) -> float:
    """Train ``module`` on batch_loss(idx) (a scalar over samples idx (b,) of n; idx None:
    all): cfg.epochs of Adam over shuffled mini-batches of cfg.batch (lr cfg.lr decayed
    x cfg.decay per epoch), calling log(epoch, mean loss) 25 times, then (``lbfgs``)
    cfg.lbfgs_iters of full-batch L-BFGS. Returns the final mean loss."""
    opt = torch.optim.Adam(module.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, cfg.decay)
    total = math.nan
    for epoch in range(1, cfg.epochs + 1):
        perm = torch.randperm(n, generator=gen)
        total = 0.0
        for i in range(0, n, cfg.batch):
            idx = perm[i:i + cfg.batch]
            opt.zero_grad()
            value = batch_loss(idx)
            value.backward()
            opt.step()
            total += value.item() * len(idx)
        total /= n
        sched.step()
        if log and (epoch % max(1, cfg.epochs // 25) == 0 or epoch == cfg.epochs):
            log(epoch, total)
    if lbfgs and cfg.lbfgs_iters:
        opt = torch.optim.LBFGS(module.parameters(), lr=1.0, max_iter=cfg.lbfgs_iters, history_size=50,
                                tolerance_grad=1e-14, tolerance_change=1e-18, line_search_fn="strong_wolfe")

        def closure():
            opt.zero_grad()
            value = batch_loss(None)
            value.backward()
            return value

        opt.step(closure)
        with torch.no_grad():
            total = float(batch_loss(None))
        if log:
            log(cfg.epochs + 1, total)
    return total


def tau_error(tau: torch.Tensor, target: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Mean over samples of the squared error of tau (n, J, 3) against target (n, J, 3),
    each output divided by scale ((3,) or (J, 3)) and summed: the supervised loss."""
    return ((tau - target) / scale).pow(2).sum((-1, -2)).mean()


def _fit_stage(net: ContactNet, k: int, s: int, p: torch.Tensor, tau: torch.Tensor, cfg: NNConfig,
               gen: torch.Generator) -> float:
    """Fit correction stage s of state k's head (multi-stage training, Wang and Lai 2024)
    to the error e = tau - head_tau(k, p, s) (n, J, 3) that the head and the stages before
    it leave on the state's labels p (n, J) MPa, tau (n, J, 3): its tau_scale is e's RMS
    per output, so it fits e / RMS, of order 1, and the loss is the mean squared miss of
    that (per sample, summed over outputs). Returns the final loss.

    A fitted MLP's error is a smooth function of P orders of magnitude below its target,
    which the first net's optimisation no longer resolves; a fresh net on the rescaled
    error resolves it again. The contact heads need this: the penalty turns a 1 µm pose
    error into several mN."""
    stage = net.refine[k][s]
    with torch.no_grad():
        err = tau - net.head_tau(k, p, s)
        stage.tau_scale.copy_(err.pow(2).mean(0).sqrt().flatten().clamp_min(1e-12))
    scale = stage.tau_scale.reshape(-1, 3)

    def stage_loss(idx):
        q, e = (p, err) if idx is None else (p[idx], err[idx])
        return tau_error(stage(q), e, scale)

    return _fit(stage, stage_loss, len(p), replace(cfg, epochs=cfg.refine_epochs, decay=cfg.refine_decay,
                                                   lbfgs_iters=cfg.refine_lbfgs_iters), gen)


def train(cfg: NNConfig, joint: JointModel) -> Predictor:
    """Train one variant; prints progress on stderr; returns the Predictor with history and
    metrics.

    Equilibrium loss (unsupervised) or, with ``supervised``, the scaled squared error to
    the solver's labels. With ``state_heads`` (ContactNet) the classifier learns the
    states (cross-entropy, Adam only), then each head the labels of its own state, then
    its correction stages in turn (``_fit_stage``); the history has one point per step
    (classifier, then each head and its stages, in statics.STATES order) at its cumulative
    epoch."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    p_train, p_val = sample_pressures(cfg.n_train, cfg, gen), sample_pressures(cfg.n_val, cfg, gen)
    problem = cfg.problem(joint)
    t_start = time.perf_counter()
    label_time = 0.0
    if cfg.supervised:
        p_train, tau_train, s_train = _labels(joint, p_train, cfg)
        p_val, tau_val, _ = _labels(joint, p_val, cfg)
        label_time = time.perf_counter() - t_start
    scale = torch.tensor(TAU_SCALE[:3], dtype=torch.float64)
    net = network(cfg)

    def label_loss(module, p, target):
        return tau_error(module(p), target, scale)

    def equilibrium_loss(p):
        tau = net(p)
        return loss(problem.residual(p, tau).residual, tau).mean()

    def pick(t, idx):
        return t if idx is None else t[idx]

    history = {"epoch": [], "train_loss": [], "val_loss": [], "val_force_mN": [], "val_moment_Nmm": []}

    def log(epoch: int, train_loss: float) -> None:
        with torch.no_grad():
            val = float(label_loss(net, p_val, tau_val) if cfg.supervised else equilibrium_loss(p_val))
        ev = evaluate(net, problem, p_val)
        for k, v in (("epoch", epoch), ("train_loss", train_loss), ("val_loss", val),
                     ("val_force_mN", ev["force_mN_mean"]), ("val_moment_Nmm", ev["moment_Nmm_mean"])):
            history[k].append(v)
        if not progress.quiet():   # the training's progress lines (--quiet: none)
            print(f"[nn {cfg.variant}] epoch {epoch:4d} train {train_loss:.3e} val {val:.3e} "
                  f"force {ev['force_mN_mean']:.3f} mN moment {ev['moment_Nmm_mean']:.3f} N·mm", file=sys.stderr,
                  flush=True)

    if not cfg.state_heads:
        _fit(net, lambda idx: (label_loss(net, pick(p_train, idx), pick(tau_train, idx)) if cfg.supervised
                               else equilibrium_loss(pick(p_train, idx))), p_train.shape[0], cfg, gen, log)
    else:
        if not cfg.supervised:
            raise ValueError("state_heads needs the solver's labels (supervised)")
        final = _fit(net.classifier, lambda idx: nn.functional.cross_entropy(
            net.logits(pick(p_train, idx)), pick(s_train, idx)), p_train.shape[0], cfg, gen,
            lbfgs=False)
        epochs = cfg.epochs
        log(epochs, final)
        for k, head in enumerate(net.heads):
            pk, tk = p_train[s_train == k], tau_train[s_train == k]
            # The contact states' heads also fit the label's contact points (pose_weight, mm²):
            # while slipping a small tau error moves the fingertip far, and the penalty answers
            # the pose. Not the contact-free head: there it cost tau accuracy (the raw
            # contact-free residual rose from 0.12 to 0.95 mN in bench-predictor).
            with torch.no_grad():
                points = problem.pose(pk, tk).points if cfg.pose_weight and len(pk) and k != NO_CONTACT else None

            def head_loss(idx, head=head, pk=pk, tk=tk, points=points):
                p = pick(pk, idx)
                tau = head(p)
                value = tau_error(tau, pick(tk, idx), scale)
                if points is not None:
                    miss = (problem.pose(p, tau).points - pick(points, idx)).pow(2).sum(-1).mean(-1).mean()
                    value = value + cfg.pose_weight * miss
                return value

            if len(pk):   # a state the domain never reaches keeps an untrained head it never picks
                final = _fit(head, head_loss, len(pk), cfg, gen)
                epochs += cfg.epochs
                log(epochs, final)
                for s in range(len(net.refine[k])):
                    final = _fit_stage(net, k, s, pk, tk, cfg, gen)
                    epochs += cfg.refine_epochs
                    log(epochs, final)
    train_time = time.perf_counter() - t_start
    metrics = {"val": evaluate(net, problem, p_val), "train_time_s": train_time,
               "label_time_s": label_time, "n_train": int(p_train.shape[0]), "n_val": int(p_val.shape[0])}
    if problem.obstacle is not None:
        metrics["val_polished"] = evaluate_polished(Predictor(net, cfg, joint.name), joint, p_val)
        metrics["val_contact_fraction"] = contact_fraction(net, problem, p_val)
    return Predictor(net, cfg, joint.name, metrics, history)


def contact_fraction(net: nn.Module, problem: GripperProblem, pressures: torch.Tensor) -> float:
    """Fraction of pressures (B, J) whose raw NN gesture touches the object."""
    with torch.no_grad():
        return float((problem.residual(pressures, net(pressures)).contact.normal > 0).double().mean())


def nn_folder(text: str) -> Path:
    """argparse type: an existing folder of NN predictor checkpoints."""
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder")
    return Path(text)


def _format(contact: bool) -> str:
    return CONTACT_FORMAT if contact else GRAVITY_FORMAT


def save_predictor(pred: Predictor, path: str | Path) -> None:
    """Write the checkpoint (config, normalisation, metrics, history, weights) atomically,
    of kind CONTACT_FORMAT when the config has an object, else GRAVITY_FORMAT."""
    checkpoint.save(path, _format(pred.config.obstacle is not None), {
        "config": asdict(pred.config), "state_dict": pred.net.state_dict(), "joint": pred.joint_name,
        "normalisation": {"p_scale_MPa": P_SCALE, "tau_scale": TAU_SCALE},
        "metrics": pred.metrics, "history": pred.history})


def load_predictor(path: str | Path | None, joint: JointModel | None = None, contact: bool = False,
                   params: GripperParams | None = None) -> Predictor:
    """Load a checkpoint of the gravity (or, with ``contact``, the contact) kind; path
    None picks results/predictor/{gravity,contact}_nn.pt. ``joint`` None skips the check
    that the NN was trained on that joint (reading its history only); ``params`` None
    skips the check that it was trained for that finger, kinematics and joint weights.

    Raises ValueError (one line): a missing, damaged, foreign or other-kind file
    (surrogate.checkpoint.CheckpointError), a joint mismatch or a finger/options mismatch.
    """
    path = Path(path) if path else default_nn_dir() / ("contact_nn.pt" if contact else "gravity_nn.pt")
    ck = checkpoint.load(path, _format(contact), "NN predictor checkpoint")
    try:
        # Checkpoints written before the chain options record them were trained with the
        # paper's chain (tangent kinematics, lumped joint weights), not today's defaults.
        saved = {"kinematics": "tangent", "joint_weight": "lumped", **ck["config"]}
        cfg = NNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved.items()})
        trained_params = cfg.params()
        net = network(cfg)
        net.load_state_dict(ck["state_dict"])
        joint_name, metrics, history = ck["joint"], ck["metrics"], ck["history"]
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:  # intact file, inconsistent payload
        raise checkpoint.CheckpointError(f"{path}: inconsistent NN predictor checkpoint "
                                         f"({type(exc).__name__}: {str(exc).splitlines()[0][:120]})") from None
    if params is not None and params != trained_params:
        raise ValueError(f"{path} was trained for {trained_params.describe()}, not {params.describe()}")
    if joint is not None and joint_name != joint.name:
        raise ValueError(f"{path} was trained with joint {joint_name!r}, not {joint.name!r}")
    return Predictor(net.eval(), cfg, joint_name, metrics, history)


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.nn", description="train an NN gesture predictor")
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
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = ap.parse_args(argv)
    progress.set_quiet(args.quiet)
    torch.set_num_threads(1)
    cfg = VARIANTS[args.variant]
    with ap.errors():
        joint = load_joint(args.model)
        params = GripperParams(args.finger or default_finger(), kinematics=args.kinematics,
                               joint_weight=args.joint_weight)
        if params != cfg.params() or params.n_joints != cfg.widths[0]:
            cfg = cfg.for_params(params)
        if cfg.approach is not None and len(cfg.approach) != params.n_joints:
            from predictor.solve import approach_for

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
