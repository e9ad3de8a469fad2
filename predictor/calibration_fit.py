"""The calibration's fit (predictor.calibration has the model and its equations).

Weighted least squares over the fitted subset of theta: r = (m - y)/sigma for every
measured scalar plus (theta_k - mu_k)/sigma_k for each prior, minimised by a bounded
Levenberg-Marquardt in scaled variables (theta = nominal + scale·u, scale a quarter of
the bounds' width) from several starts, with the exact Jacobian of
predictor.calibration.sensitivities. The Gauss-Newton covariance C = (J^T J)^+ (sigma as
stated, no rescaling by the residual) gives each parameter's std. A pair whose
|correlation| exceeds CORRELATED is reported. A parameter is unidentifiable from the data
when its variance inflation VIF_k = C_kk·(J^T J)_kk (its variance over the variance it
would have were the others known; 1/(1 - R_k²) with R_k its multiple correlation with
the others) exceeds MAX_VIF, or its std exceeds half its bounds' width. Leave-one-out: each
observation with a tip is predicted by the fit to the others (one start, from the full
fit's values); its tip error is the distance (mm).

Data flow: CalibrationModel + Observations + fitted names (+ priors) -> ``calibrate`` ->
CalibrationResult (summary() is the CLI's JSON).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from predictor.calibration import (CalibrationModel, DEFAULT_FIT, Design, design, equilibrium, predict, resolve_fit,
                                   sensitivities)
from predictor.observations import Observations

class FitFailed(RuntimeError):
    """No start of the fit reached a point where every observed gesture converges."""


CORRELATED = 0.95  # |correlation| above which a pair is reported as hard to separate
MAX_VIF = 1e4      # variance inflation (std x100 by the others) beyond which a parameter is unidentifiable


@dataclass
class Prior:
    """A Gaussian prior on one parameter: mean and std in its unit."""

    mean: float
    std: float


class Problem:
    """The weighted least-squares problem over the fitted subset u of theta (scaled:
    theta_k = nominal_k + scale_k·u_k, scale = a quarter of the bounds' width)."""

    def __init__(self, model: CalibrationModel, d: Design, fit: tuple[int, ...], priors: dict | None = None,
                 theta0: torch.Tensor | None = None):
        self.model, self.d, self.fit = model, d, list(fit)
        self.base = (model.nominal if theta0 is None else theta0).clone()
        t = model.table
        self.lo = np.array([t[i].lo for i in fit])
        self.hi = np.array([t[i].hi for i in fit])
        self.scale = 0.25 * (self.hi - self.lo)
        self.priors = {model.index[k]: v for k, v in (priors or {}).items()}
        self.x = None   # warm start of the equilibria
        self.evaluations = 0

    def theta(self, v: np.ndarray) -> torch.Tensor:
        """Full theta (n,) with the fitted values v (in their units)."""
        th = self.base.clone()
        th[self.fit] = torch.as_tensor(v, dtype=torch.float64)
        return th

    def _prior_terms(self, v):
        r, rows = [], []
        for col, i in enumerate(self.fit):
            if i in self.priors:
                p = self.priors[i]
                r.append((v[col] - p.mean) / p.std)
                row = np.zeros(len(self.fit))
                row[col] = 1.0 / p.std
                rows.append(row)
        return np.array(r), np.array(rows).reshape(len(r), len(self.fit))

    def residual(self, v: np.ndarray, jacobian: bool = False):
        """Weighted residual r (N + priors,), and with ``jacobian`` dr/dv (.., k); None
        when an equilibrium does not converge."""
        self.evaluations += 1
        th = self.theta(v)
        B = self.d.pressures.shape[0]
        x, ok = equilibrium(self.model, self.d, th[None].repeat(B, 1), self.x)
        if not bool(ok.all()):
            x, ok = equilibrium(self.model, self.d, th[None].repeat(B, 1), None)
            if not bool(ok.all()):
                return (None, None) if jacobian else None
        self.x = x
        pr, pj = self._prior_terms(v)
        if not jacobian:
            with torch.no_grad():
                m = predict(self.model, self.d, x, th[None].repeat(B, 1)).numpy()
            return np.concatenate(((m - self.d.y) / self.d.sigma, pr))
        m, jac = sensitivities(self.model, self.d, x, th)
        r = np.concatenate(((m.numpy() - self.d.y) / self.d.sigma, pr))
        jw = jac.numpy()[:, self.fit] / self.d.sigma[:, None]
        return r, np.concatenate((jw, pj), 0)


def levenberg_marquardt(prob: Problem, v0: np.ndarray, max_iter: int = 60, tol: float = 1e-12):
    """Bounded LM in scaled variables from v0; returns (v, cost = ½|r|², iterations)."""
    v = np.clip(v0, prob.lo, prob.hi)
    r, jac = prob.residual(v, jacobian=True)
    if r is None:
        return v, math.inf, 0
    cost, lam, it = 0.5 * r @ r, 1e-3, 0
    for it in range(1, max_iter + 1):
        js = jac * prob.scale
        g, h = js.T @ r, js.T @ js
        step_done = False
        while lam < 1e12:
            du = np.linalg.solve(h + lam * (np.diag(np.diag(h)) + 1e-9 * np.eye(len(v))), -g)
            trial = np.clip(v + prob.scale * du, prob.lo, prob.hi)
            rt = prob.residual(trial)
            ct = math.inf if rt is None else 0.5 * rt @ rt
            if ct < cost:
                lam = max(lam * 0.2, 1e-12)
                step_done = True
                break
            lam *= 10.0
        if not step_done:
            break
        gain = cost - ct
        v, cost = trial, ct
        r, jac = prob.residual(v, jacobian=True)
        if gain <= tol * max(cost, 1.0) or np.abs(du).max() < 1e-10:
            break
    return v, cost, it


@dataclass
class CalibrationResult:
    """A fit: names, values and std (their units), correlation (k, k), variance inflation
    (k,), the unidentifiable
    names, weighted and mm residual figures, leave-one-out tip errors (mm), theta (n,)."""

    names: list
    values: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    vif: np.ndarray
    unidentifiable: list
    correlated: list
    rms_before_mm: float
    rms_after_mm: float
    cost: float
    theta: torch.Tensor
    loo_tip_error_mm: list
    starts: int
    time_s: float
    converged: bool

    def summary(self) -> dict:
        loo = [e for e in self.loo_tip_error_mm if e is not None]
        return {
            "parameters": {n: {"value": float(v), "std": float(s), "vif": float(f),
                               "identifiable": n not in self.unidentifiable}
                           for n, v, s, f in zip(self.names, self.values, self.std, self.vif)},
            "rms_before_mm": self.rms_before_mm, "rms_after_mm": self.rms_after_mm,
            "loo_tip_error_mm": float(np.mean(loo)) if loo else None,
            "loo_tip_error_max_mm": float(np.max(loo)) if loo else None,
            "loo_tip_error_each_mm": self.loo_tip_error_mm,
            "unidentifiable": self.unidentifiable,
            "correlated": [{"a": a, "b": b, "correlation": c} for a, b, c in self.correlated],
            "chi2": 2.0 * self.cost, "starts": self.starts, "converged": self.converged, "time_s": self.time_s}


def _rms_mm(prob: Problem, v: np.ndarray) -> float:
    """RMS (mm) of the point residuals (x, y of tips and markers) at v."""
    r = prob.residual(v)
    if r is None:
        return math.nan
    n = len(prob.d.y)
    pts = np.array([w[0] != "deg" for w in prob.d.what])
    mm = (r[:n] * prob.d.sigma)[pts]
    return float(np.sqrt(np.mean(mm ** 2))) if mm.size else math.nan


def covariance(jac: np.ndarray) -> np.ndarray:
    """(J^T J)^+ of the weighted Jacobian (pseudo-inverse: a singular direction gets a huge,
    not an infinite, variance)."""
    h = jac.T @ jac
    d = np.sqrt(np.clip(np.diag(h), 1e-300, None))
    hn = h / np.outer(d, d)
    w, q = np.linalg.eigh(hn)
    inv = np.where(w > 1e-14 * w.max(), 1.0 / np.maximum(w, 1e-300), 1e14)
    return (q * inv) @ q.T / np.outer(d, d)


def _identifiability(names, std, corr, vif, lo, hi):
    """(unidentifiable names, [(a, b, correlation)] of the pairs beyond CORRELATED)."""
    bad = [n for n, s, v, a, b in zip(names, std, vif, lo, hi) if not (s < 0.5 * (b - a) and v <= MAX_VIF)]
    pairs = [(names[i], names[j], float(corr[i, j])) for i in range(len(names)) for j in range(i + 1, len(names))
             if abs(corr[i, j]) > CORRELATED]
    return bad, pairs


def fit(prob: Problem, starts: int = 3, seed: int = 0) -> tuple[np.ndarray, float, bool]:
    """The best LM answer over ``starts`` starts: the nominal values, then uniform draws
    within the bounds' middle half. Returns (v, cost, converged)."""
    rng = np.random.default_rng(seed)
    v0 = prob.base[prob.fit].numpy()
    best = (v0, math.inf)
    for k in range(starts):
        start = v0 if k == 0 else prob.lo + (prob.hi - prob.lo) * rng.uniform(0.25, 0.75, len(v0))
        prob.x = None
        v, cost, _ = levenberg_marquardt(prob, start)
        if cost < best[1]:
            best = (v, cost)
    return best[0], best[1], math.isfinite(best[1])


def calibrate(model: CalibrationModel, obs: Observations, fit_names=DEFAULT_FIT, priors: dict | None = None,
              starts: int = 3, loo: bool = True, seed: int = 0) -> CalibrationResult:
    """Fit the parameters ``fit_names`` (names or groups) to ``obs`` (module docstring).
    ValueError (one line) for a bad name or prior, or observations the nominal model cannot
    solve; FitFailed when no start converges."""
    t0 = time.perf_counter()
    idx = resolve_fit(fit_names, model.table)
    for k, p in (priors or {}).items():
        if k not in {model.table[i].name for i in idx}:
            raise ValueError(f"--prior {k}: not a fitted parameter")
        if not (math.isfinite(p.mean) and math.isfinite(p.std) and p.std > 0):
            raise ValueError(f"--prior {k}: mean {p.mean!r}, std {p.std!r}: expected finite numbers, std > 0")
    d = design(obs, model.finger)
    prob = Problem(model, d, idx, priors)
    v_nom = prob.base[list(idx)].numpy()
    before = _rms_mm(prob, v_nom)
    if not math.isfinite(before):
        raise ValueError("the nominal gripper has no converged gesture at some observed pressures")
    v, cost, ok = fit(prob, starts, seed)
    prob.x = None
    r, jac = prob.residual(v, jacobian=True) if ok else (None, None)
    if r is None:
        raise FitFailed(f"no start of the fit of {', '.join(model.table[i].name for i in idx)} converged")
    cov = covariance(jac)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    corr = cov / np.outer(np.maximum(std, 1e-300), np.maximum(std, 1e-300))
    vif = np.diag(cov) * np.diag(jac.T @ jac)
    names = [model.table[i].name for i in idx]
    bad, pairs = _identifiability(names, std, corr, vif, prob.lo, prob.hi)
    theta = prob.theta(v)
    errs = leave_one_out(model, obs, idx, priors, v) if loo else []
    return CalibrationResult(names, v, std, corr, vif, bad, pairs, before, _rms_mm(prob, v), cost, theta, errs, starts,
                             time.perf_counter() - t0, ok)


def leave_one_out(model, obs: Observations, idx, priors, v_all: np.ndarray) -> list:
    """Per observation with a tip: the tip error (mm) of the fit to the others (one start,
    from the full fit's values), None for the others."""
    out = []
    for i, o in enumerate(obs.items):
        if o.tip is None or len(obs) < 2:
            out.append(None)
            continue
        rest = obs.subset([k for k in range(len(obs)) if k != i])
        prob = Problem(model, design(rest, model.finger), idx, priors)
        v, _, _ = levenberg_marquardt(prob, v_all)
        one = design(obs.subset([i]), model.finger)
        th = prob.theta(v)[None]
        x, ok = equilibrium(model, one, th)
        if not bool(ok.all()):
            out.append(None)
            continue
        with torch.no_grad():
            m = predict(model, one, x, th).numpy()
        rx, ry = one.tip_rows[0]
        out.append(float(math.hypot(m[rx] - one.y[rx], m[ry] - one.y[ry])))
    return out
