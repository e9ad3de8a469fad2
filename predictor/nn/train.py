"""Training of the NN gesture predictors (predictor.nn.networks), over pressures P (B, J) MPa
with tau = net(P) (B, J, 3) [N, N, N·mm]:

- equilibrium loss (unsupervised; gravity-paper): mean_b [|R_F|² + (|R_M| / 100 mm)²] of
  Equation 1 at tau plus the out-of-box penalty (statics.loss): no FEM labels needed;
- supervised (the other variants): the scaled squared error sum ((tau - tau*) /
  TAU_SCALE)² (``tau_error``) to the iterative solver's equilibria tau* (labels: one
  batched predictor.solvers.solve.solve of all training pressures; with an object, along the
  pressure ramp from the approach gesture);
- ContactNet (``state_heads``): the classifier by cross-entropy on the labels' grasp states
  (Adam only); each head on its own state's labels, the holding and slipping heads plus
  ``pose_weight`` (per mm²) times the mean squared miss of the finger's contact sample
  points at its tau against the label's, since while slipping a small tau error moves the
  fingertip far and the penalty contact answers the pose; then each head's correction
  stages in turn (``fit_stage``: multi-stage training, Wang and Lai 2024).

Optimisation (``fit``): epochs of Adam over shuffled mini-batches, lr decayed per epoch,
then full-batch L-BFGS (strong Wolfe). The history holds, per logged epoch, the train and
validation losses and the raw network's mean validation residual (mN, N·mm); the metrics
the validation residual statistics (predictor.nn.eval) and, with an object, the delivered
path's.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import replace

import torch
from torch import nn

from predictor.solvers import progress
from predictor.model.joint import JointModel
from predictor.nn.networks import TAU_SCALE, ContactNet, NNConfig, Predictor, network, sample_pressures
from predictor.nn.eval import contact_fraction, evaluate, evaluate_polished
from predictor.solvers.solve import solve
from predictor.model.statics import NO_CONTACT, GripperProblem, grasp_state, loss


def _labels(joint: JointModel, pressures: torch.Tensor, cfg: NNConfig) -> tuple[torch.Tensor, ...]:
    """Iterative-solver labels for pressures (n, J): (pressures, tau (n, J, 3), grasp
    state (n,) codes of statics.STATES), restricted to the converged samples."""
    res = solve(cfg.training_problem(joint), pressures)
    ok = res.converged
    print(f"[nn] labels: {int(ok.sum())}/{len(ok)} converged in {res.time_ms / 1e3:.1f} s", file=sys.stderr,
          flush=True)
    return pressures[ok], res.tau[ok], grasp_state(res.normal_force_N, res.slip)[ok]


def fit(module: nn.Module, batch_loss, n: int, cfg: NNConfig, gen: torch.Generator, log=None,
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


def fit_stage(net: ContactNet, k: int, s: int, p: torch.Tensor, tau: torch.Tensor, cfg: NNConfig,
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

    return fit(stage, stage_loss, len(p), replace(cfg, epochs=cfg.refine_epochs, decay=cfg.refine_decay,
                                                   lbfgs_iters=cfg.refine_lbfgs_iters), gen)


def train(cfg: NNConfig, joint: JointModel) -> Predictor:
    """Train one variant; prints progress on stderr; returns the Predictor with history and
    metrics.

    Equilibrium loss (unsupervised) or, with ``supervised``, the scaled squared error to
    the solver's labels. With ``state_heads`` (ContactNet) the classifier learns the
    states (cross-entropy, Adam only), then each head the labels of its own state, then
    its correction stages in turn (``fit_stage``); the history has one point per step
    (classifier, then each head and its stages, in statics.STATES order) at its cumulative
    epoch."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    p_train, p_val = sample_pressures(cfg.n_train, cfg, gen), sample_pressures(cfg.n_val, cfg, gen)
    problem = cfg.training_problem(joint)
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
        fit(net, lambda idx: (label_loss(net, pick(p_train, idx), pick(tau_train, idx)) if cfg.supervised
                               else equilibrium_loss(pick(p_train, idx))), p_train.shape[0], cfg, gen, log)
    else:
        if not cfg.supervised:
            raise ValueError("state_heads needs the solver's labels (supervised)")
        _fit_state_heads(net, problem, p_train, tau_train, s_train, scale, cfg, gen, log)
    train_time = time.perf_counter() - t_start
    metrics = {"val": evaluate(net, problem, p_val), "train_time_s": train_time,
               "label_time_s": label_time, "n_train": int(p_train.shape[0]), "n_val": int(p_val.shape[0])}
    if problem.obstacle is not None:
        metrics["val_polished"] = evaluate_polished(Predictor(net, cfg, joint.name), joint, p_val)
        metrics["val_contact_fraction"] = contact_fraction(net, problem, p_val)
    return Predictor(net, cfg, joint.name, metrics, history)


def _fit_state_heads(net: ContactNet, problem: GripperProblem, p_train: torch.Tensor, tau_train: torch.Tensor,
                     s_train: torch.Tensor, scale: torch.Tensor, cfg: NNConfig, gen: torch.Generator, log) -> None:
    """A ContactNet's training on labels p_train (n, J) MPa, tau_train (n, J, 3), states
    s_train (n,): the classifier (cross-entropy, Adam only), then each state's head on its
    own labels (scaled tau error, ``scale`` (3,), plus the pose term for the contact
    states), then the head's correction stages in turn (``fit_stage``); log(epoch, loss)
    after each, at its cumulative epoch."""

    def pick(t, idx):
        return t if idx is None else t[idx]

    final = fit(net.classifier, lambda idx: nn.functional.cross_entropy(
        net.logits(pick(p_train, idx)), pick(s_train, idx)), p_train.shape[0], cfg, gen,
        lbfgs=False)
    epochs = cfg.epochs
    log(epochs, final)
    for k, head in enumerate(net.heads):
        pk, tk = p_train[s_train == k], tau_train[s_train == k]
        # The contact states' heads also fit the label's contact points (pose_weight, mm²):
        # while slipping a small tau error moves the fingertip far, and the penalty answers
        # the pose. Not the contact-free head: there it costs tau accuracy (docs/decisions.md).
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
            final = fit(head, head_loss, len(pk), cfg, gen)
            epochs += cfg.epochs
            log(epochs, final)
            for s in range(len(net.refine[k])):
                final = fit_stage(net, k, s, pk, tk, cfg, gen)
                epochs += cfg.refine_epochs
                log(epochs, final)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.nn")
