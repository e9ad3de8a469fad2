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
- ``gravity-improved``: 2 -> 64 -> 64 -> 64 -> 6 with SiLU (smooth, so the residual can go
  to zero instead of stalling on ReLU's kinks), Adam with batch 100 and lr 3e-3 decayed
  ×0.9 for 30 epochs, then 3000 iterations of full-batch L-BFGS on the same equilibrium
  loss (the loss is a smooth least-squares problem: a quasi-Newton method on all 4000
  pairs at once is what takes it from ~1 mN down).
- ``contact``: the grasp of the circle (r = 30 mm, 0.2 N, centre Y = -195 mm, approach
  P = (-0.15, 0), see statics.Obstacle) for (P1, P2) in [-0.15, 0.2] x [-0.05, 0.25],
  which contains gestures with (about 40 %) and without contact. The equilibrium loss alone is as stiff as
  the penalty (dR/dtau ~ k_c × contact length), which is where the paper stalled. What
  works: (1) supervision from the batched iterative solver (labels are cheap: one
  batched solve), SiLU MLP 2 -> 128 -> 128 -> 128 -> 6, Adam + L-BFGS on the label loss;
  (2) the NN's tau warm-starts the exact-Jacobian LM
  with a small step cap (a local polish, median ~7 iterations), and samples it cannot
  converge fall back to the full ramp. The raw NN is still far from the 2 mN bound
  (penalty stiffness amplifies its error); the checkpoint records both. Tried and
  dropped: one plain Newton step from the NN (diverges: 926 -> 60000 mN mean), and
  fine-tuning the supervised net by L-BFGS on the equilibrium loss (``physics_iters``):
  the raw residual fell to 88 mN / 16 N·mm, the paper's regime, but the net learned to
  lift the finger off the object (contact fraction 42 % -> 27 %) and the polish then
  needed the fallback for 23 % of the queries instead of ~10 %. Corners of the
  pressure box where the ramp's grasp changes branch (the tip slides off the object:
  tau jumps) are left out of the NN's domain: P1 in [-0.15, 0.2], P2 in [-0.05, 0.25].

Checkpoints (DESIGN.md §5): config, normalisation (input 0.3 MPa, TAU_SCALE), training
config, metrics and per-epoch history; ``load_predictor`` needs only the file.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch
from torch import nn

from predictor.gripper import GripperParams
from predictor.joint import JointModel, load_joint
from predictor.solve import APPROACH, GestureResult, SolverOptions, solve
from predictor.statics import Obstacle, loss, residual, residual_norms

TAU_SCALE = (1.0, 1.0, 30.0, 1.0, 1.0, 30.0)
P_SCALE = 0.3
# LM step cap (scaled units) when polishing a contact NN prediction: small enough that the
# iterates stay on the NN's branch (0.3, the ramp's cap, let 8 of 55 jump to another one).
POLISH_STEP = 0.02
# The NN bound: a prediction counts as an answer only within it.
NN_FORCE_TOL_MN = 2.0
NN_MOMENT_TOL_NMM = 1.2


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
    physics_iters: int = 0
    supervised: bool = False
    p1_range: tuple = (-0.3, 0.3)
    p2_range: tuple = (-0.3, 0.3)
    obstacle: dict | None = None
    approach: tuple | None = None
    seed: int = 0


VARIANTS = {
    "gravity-paper": NNConfig(),
    "gravity-improved": NNConfig(variant="gravity-improved", widths=(2, 64, 64, 64, 6), activation="silu",
                                 epochs=30, batch=100, lr=3e-3, decay=0.9, lbfgs_iters=3000),
    "contact": NNConfig(variant="contact", widths=(2, 128, 128, 128, 6), activation="silu", n_train=2000,
                        n_val=400, epochs=150,
                        batch=100, lr=3e-3, decay=0.97, lbfgs_iters=400, supervised=True,
                        p1_range=(-0.15, 0.2), p2_range=(-0.05, 0.25), obstacle=asdict(Obstacle()),
                        approach=APPROACH),
}


class GestureNet(nn.Module):
    """MLP (B, 2) MPa -> tau (B, 2, 3) [N, N, N·mm] with fixed input/output scaling."""

    def __init__(self, widths: tuple, activation: str):
        super().__init__()
        act = {"relu": nn.ReLU, "silu": nn.SiLU, "tanh": nn.Tanh}[activation]
        layers: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(widths[:-1], widths[1:])):
            layers.append(nn.Linear(a, b))
            if i < len(widths) - 2:
                layers.append(act())
        self.mlp = nn.Sequential(*layers).double()
        self.register_buffer("tau_scale", torch.tensor(TAU_SCALE, dtype=torch.float64))

    def forward(self, pressures: torch.Tensor) -> torch.Tensor:
        return (self.mlp(pressures / P_SCALE) * self.tau_scale).reshape(-1, 2, 3)


@dataclass
class Predictor:
    """A trained network plus what it was trained for (joint name, object, approach)."""

    net: GestureNet
    config: NNConfig
    joint_name: str
    metrics: dict = field(default_factory=dict)
    history: dict = field(default_factory=dict)

    @property
    def obstacle(self) -> Obstacle | None:
        return Obstacle(**self.config.obstacle) if self.config.obstacle else None


def sample_pressures(n: int, cfg: NNConfig, gen: torch.Generator) -> torch.Tensor:
    """n pressure pairs (n, 2) MPa, uniform in the config's P1 x P2 ranges."""
    u = torch.rand(n, 2, generator=gen, dtype=torch.float64)
    lo = torch.tensor([cfg.p1_range[0], cfg.p2_range[0]], dtype=torch.float64)
    hi = torch.tensor([cfg.p1_range[1], cfg.p2_range[1]], dtype=torch.float64)
    return lo + u * (hi - lo)


def _stats(res: torch.Tensor) -> dict:
    """mean / p95 / max over samples of the worst-joint force (mN) and moment (N·mm)."""
    f, m = residual_norms(res)
    f, m = f.amax(-1), m.amax(-1)
    q = lambda v, a: float(torch.quantile(v, a))  # noqa: E731
    return {"force_mN_mean": float(f.mean()), "force_mN_p95": q(f, 0.95), "force_mN_max": float(f.max()),
            "moment_Nmm_mean": float(m.mean()), "moment_Nmm_p95": q(m, 0.95), "moment_Nmm_max": float(m.max())}


def evaluate(net: GestureNet, joint: JointModel, pressures: torch.Tensor, obstacle: Obstacle | None) -> dict:
    """Residual statistics of the raw NN tau on pressures (B, 2) (see _stats)."""
    with torch.no_grad():
        return _stats(residual(joint, GripperParams(), pressures, net(pressures), obstacle).residual)


def evaluate_polished(pred: "Predictor", joint: JointModel, pressures: torch.Tensor) -> dict:
    """The delivered contact predictor (NN + local LM polish, ramp fallback) on pressures:
    residual statistics of the answers plus how many needed the fallback."""
    res = predict_gesture(pred, joint, pressures, pred.obstacle)
    ok = res.converged
    stats = _stats(residual(joint, GripperParams(), pressures[ok], res.tau[ok], pred.obstacle).residual)
    return {**stats, "converged": int(ok.sum()), "n": len(ok), "fallback": int(res.fallback.sum()),
            "median_polish_iterations": float(res.iterations.double().median()),
            "batch_time_ms": res.time_ms}


@dataclass
class NNGestureResult(GestureResult):
    """GestureResult of the NN predictor; fallback (B,) marks samples that the local
    polish could not converge and that were solved by the full pressure ramp instead."""

    fallback: torch.Tensor = None


def predict_gesture(pred: Predictor, joint: JointModel, pressures: torch.Tensor,
                    obstacle: Obstacle | None = None) -> NNGestureResult:
    """NN gesture in the solver's result format, pressures (B, 2) MPa.

    Gravity: the raw NN tau; ``converged`` means its residual is within the NN bound
    (2 mN, 1.2 N·mm), other samples get NaN. Contact: the NN tau warm-starts the LM with a
    small step cap (POLISH_STEP) so the iterates stay on the NN's branch; samples it cannot
    converge in ``max_iter`` steps are re-solved by the full ramp (``fallback``).
    """
    if (obstacle is None) != (pred.obstacle is None) or (obstacle is not None and obstacle != pred.obstacle):
        raise ValueError(f"this NN predictor was trained for object {pred.config.obstacle}, not {obstacle}")
    t0 = time.perf_counter()
    with torch.no_grad():
        tau = pred.net(pressures)
    fallback = torch.zeros(pressures.shape[0], dtype=torch.bool)
    if obstacle is None:
        with torch.no_grad():
            st = residual(joint, GripperParams(), pressures, tau, None)
        f, m = residual_norms(st.residual)
        ok = (f.amax(-1) <= NN_FORCE_TOL_MN) & (m.amax(-1) <= NN_MOMENT_TOL_NMM)
        nan = torch.where(ok, 0.0, float("nan"))
        pose = st.pose
        for name in ("joint1", "joint2", "link", "tip", "theta", "phi", "link_points", "tip_points"):
            v = getattr(pose, name)
            setattr(pose, name, v + nan.reshape(-1, *([1] * (v.dim() - 1))))
        free = residual(joint, GripperParams(), pressures, torch.zeros_like(tau), None, gravity=False).pose
        return NNGestureResult(pressures, tau + nan[:, None, None], ok, f, m, st.normal_force, st.friction_force,
                               st.friction_ratio, st.slip, torch.zeros(len(ok), dtype=torch.long),
                               1e3 * (time.perf_counter() - t0), pose, free, "nn", fallback)
    res = solve(joint, pressures, obstacle, x0=tau, options=SolverOptions(contact_max_step=POLISH_STEP))
    fallback = ~res.converged
    if bool(fallback.any()):
        again = solve(joint, pressures[fallback], obstacle, start=pred.config.approach)
        for name in ("tau", "converged", "residual_force_mN", "residual_moment_Nmm", "normal_force_N",
                     "friction_N", "friction_ratio", "slip", "iterations"):
            getattr(res, name)[fallback] = getattr(again, name)
        for name in ("joint1", "joint2", "link", "tip", "theta", "phi", "link_points", "tip_points"):
            getattr(res.pose, name)[fallback] = getattr(again.pose, name)
    return NNGestureResult(**{**res.__dict__, "time_ms": 1e3 * (time.perf_counter() - t0), "method": "nn+lm"},
                           fallback=fallback)


def _labels(joint: JointModel, pressures: torch.Tensor, cfg: NNConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Iterative-solver tau labels (n, 2, 3) for pressures (n, 2); returns (pressures, tau)
    restricted to converged samples."""
    res = solve(joint, pressures, Obstacle(**cfg.obstacle), start=cfg.approach, options=SolverOptions())
    ok = res.converged
    print(f"[nn] labels: {int(ok.sum())}/{len(ok)} converged in {res.time_ms / 1e3:.1f} s", flush=True)
    return pressures[ok], res.tau[ok]


def train(cfg: NNConfig, joint: JointModel) -> Predictor:
    """Train one variant; prints progress; returns the Predictor with history and metrics."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    p_train, p_val = sample_pressures(cfg.n_train, cfg, gen), sample_pressures(cfg.n_val, cfg, gen)
    obstacle = Obstacle(**cfg.obstacle) if cfg.obstacle else None
    params = GripperParams()
    t_start = time.perf_counter()
    label_time = 0.0
    if cfg.supervised:
        p_train, tau_train = _labels(joint, p_train, cfg)
        p_val, tau_val = _labels(joint, p_val, cfg)
        label_time = time.perf_counter() - t_start
        scale = torch.tensor(TAU_SCALE, dtype=torch.float64).reshape(2, 3)

    net = GestureNet(cfg.widths, cfg.activation)

    def batch_loss(p: torch.Tensor, idx: torch.Tensor | None = None) -> torch.Tensor:
        tau = net(p)
        if cfg.supervised:
            target = tau_train if idx is not None else tau_val
            target = target[idx] if idx is not None else target
            return ((tau - target) / scale).pow(2).sum((-1, -2)).mean()
        return loss(residual(joint, params, p, tau, obstacle).residual, tau).mean()

    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, cfg.decay)
    history = {"epoch": [], "train_loss": [], "val_loss": [], "val_force_mN": [], "val_moment_Nmm": []}

    def log(epoch: int, train_loss: float) -> None:
        with torch.no_grad():
            val = float(batch_loss(p_val))
        ev = evaluate(net, joint, p_val, obstacle)
        for k, v in (("epoch", epoch), ("train_loss", train_loss), ("val_loss", val),
                     ("val_force_mN", ev["force_mN_mean"]), ("val_moment_Nmm", ev["moment_Nmm_mean"])):
            history[k].append(v)
        print(f"[nn {cfg.variant}] epoch {epoch:4d} train {train_loss:.3e} val {val:.3e} "
              f"force {ev['force_mN_mean']:.3f} mN moment {ev['moment_Nmm_mean']:.3f} N·mm", flush=True)

    n = p_train.shape[0]
    for epoch in range(1, cfg.epochs + 1):
        perm = torch.randperm(n, generator=gen)
        total = 0.0
        for i in range(0, n, cfg.batch):
            idx = perm[i:i + cfg.batch]
            opt.zero_grad()
            value = batch_loss(p_train[idx], idx)
            value.backward()
            opt.step()
            total += value.item() * len(idx)
        sched.step()
        if epoch % max(1, cfg.epochs // 25) == 0 or epoch == cfg.epochs:
            log(epoch, total / n)
    if cfg.lbfgs_iters:
        lbfgs = torch.optim.LBFGS(net.parameters(), lr=1.0, max_iter=cfg.lbfgs_iters, history_size=50,
                                  tolerance_grad=1e-14, tolerance_change=1e-18, line_search_fn="strong_wolfe")
        all_idx = torch.arange(n)

        def closure():
            lbfgs.zero_grad()
            value = batch_loss(p_train, all_idx)
            value.backward()
            return value

        lbfgs.step(closure)
        with torch.no_grad():
            log(cfg.epochs + 1, float(batch_loss(p_train, all_idx)))
    if cfg.physics_iters:
        # Fine-tune the supervised net on the equilibrium loss itself (the paper's loss),
        # now that it starts near the solution branch.
        phys = torch.optim.LBFGS(net.parameters(), lr=1.0, max_iter=100, history_size=50,
                                 tolerance_grad=1e-14, tolerance_change=1e-18, line_search_fn="strong_wolfe")

        def physics_closure():
            phys.zero_grad()
            tau = net(p_train)
            value = loss(residual(joint, params, p_train, tau, obstacle).residual, tau).mean()
            value.backward()
            return value

        for k in range(cfg.physics_iters // 100):
            value = phys.step(physics_closure)
            log(cfg.epochs + 2 + k, float(value.detach()))
    train_time = time.perf_counter() - t_start
    metrics = {"val": evaluate(net, joint, p_val, obstacle), "train_time_s": train_time,
               "label_time_s": label_time, "n_train": int(p_train.shape[0]), "n_val": int(p_val.shape[0])}
    if obstacle is not None:
        metrics["val_polished"] = evaluate_polished(Predictor(net, cfg, joint.name), joint, p_val)
        with torch.no_grad():
            metrics["val_contact_fraction"] = float((residual(joint, params, p_val, net(p_val), obstacle)
                                                     .normal_force > 0).double().mean())
    return Predictor(net, cfg, joint.name, metrics, history)


def save_predictor(pred: Predictor, path: str | Path) -> None:
    """Write the checkpoint (config, normalisation, metrics, history, weights)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    torch.save({"config": asdict(pred.config), "state_dict": pred.net.state_dict(), "joint": pred.joint_name,
                "normalisation": {"p_scale_MPa": P_SCALE, "tau_scale": TAU_SCALE},
                "metrics": pred.metrics, "history": pred.history}, path)


def load_predictor(path: str | Path | None, joint: JointModel, obstacle_default: bool = False) -> Predictor:
    """Load a checkpoint; path None picks results/predictor/{gravity,contact}_nn.pt.

    Raises ValueError (one line) for a missing or corrupt file or a joint mismatch.
    """
    path = Path(path) if path else Path("results/predictor") / ("contact_nn.pt" if obstacle_default else "gravity_nn.pt")
    if not path.is_file():
        raise ValueError(f"NN predictor checkpoint not found: {path} (run make gestures)")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=False)
        cfg = NNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in ck["config"].items()})
        net = GestureNet(cfg.widths, cfg.activation)
        net.load_state_dict(ck["state_dict"])
    except Exception as exc:  # any unreadable file is the same user error
        raise ValueError(f"corrupt NN predictor checkpoint {path}: {type(exc).__name__}") from None
    if ck["joint"] != joint.name:
        raise ValueError(f"{path} was trained with joint {ck['joint']!r}, not {joint.name!r}")
    return Predictor(net.eval(), cfg, ck["joint"], ck["metrics"], ck["history"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m predictor.nn", description="train an NN gesture predictor")
    ap.add_argument("--variant", choices=sorted(VARIANTS), required=True)
    ap.add_argument("--model", default="analytic", help="joint surrogate checkpoint or 'analytic'")
    ap.add_argument("--out", required=True, help="checkpoint path (.pt)")
    ap.add_argument("--epochs", type=int, help="override the variant's epochs (smoke runs)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    try:
        joint = load_joint(args.model)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    cfg = VARIANTS[args.variant]
    if args.epochs:
        cfg = NNConfig(**{**asdict(cfg), "epochs": args.epochs})
    pred = train(cfg, joint)
    save_predictor(pred, args.out)
    print(json.dumps({"out": args.out, **pred.metrics}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
