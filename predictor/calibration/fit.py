"""The calibration's fit (predictor.calibration.model has the model and its equations).

Weighted least squares over the fitted subset of theta: r = (m - y)/sigma for every
measured scalar plus (theta_k - mu_k)/sigma_k for each prior, minimised by a bounded
Levenberg-Marquardt in scaled variables (theta = nominal + scale·u, scale a quarter of
the bounds' width) from several starts, with the exact Jacobian of
predictor.calibration.model.sensitivities. The Gauss-Newton covariance C = (J^T J)^+ (sigma as
stated, no rescaling by the residual) gives each parameter's std. A pair whose
|correlation| exceeds CORRELATED is reported. A parameter is unidentifiable from the data
when its variance inflation VIF_k = C_kk·(J^T J)_kk (its variance over the variance it
would have were the others known; 1/(1 - R_k²) with R_k its multiple correlation with
the others) exceeds MAX_VIF, or its std exceeds half its bounds' width. Leave-one-out: each
observation with a tip is predicted by the fit to the others (one start, from the full
fit's values and equilibria, at most LOO_ITERATIONS steps); its tip error is the
distance (mm). It is run for a trusted fit only (below): a refused fit is not worth the
check.

Trust (``judge``): the fit is trusted only when none of these holds, each a reason of
one line in ``why``:

- more fitted parameters than measured values (with the priors): dof = N + priors - k <= 0;
- an unidentifiable parameter (above);
- a fitted parameter on its bound (within BOUND_TOL of the bounds' width): the data push
  it beyond what the model allows, so its value says nothing;
- chi2 = |r|² beyond the CHI2_P upper quantile of the chi-square distribution with dof
  degrees of freedom, reported as the reduced chi-square chi2/dof against its limit
  chi2_isf(CHI2_P, dof)/dof (2.51 for 15 dof, 2.35 for 18, 1.49 for 100): with the sigmas as stated,
  the model (its problem, gripper or lone finger, and the parameters left at their
  nominal values) does not explain the observations.

Starts: the nominal values first; further starts (uniform draws within the bounds' middle
half) only while the best answer so far fails the chi-square or bound test, up to
``starts``: a good answer costs one start.

Data flow: CalibrationModel + Observations + fitted names (+ priors) -> ``calibrate`` ->
CalibrationResult (summary() is the CLI's JSON; ``trusted``, ``why``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from predictor.calibration.model import (CalibrationModel, DEFAULT_FIT, Design, design, equilibrium, predict, resolve_fit,
                                         sensitivities)
from predictor.calibration.observations import Observations

class FitFailed(RuntimeError):
    """No start of the fit reached a point where every observed gesture converges."""


CORRELATED = 0.95  # |correlation| above which a pair is reported as hard to separate
MAX_VIF = 1e4      # variance inflation (std x100 by the others) beyond which a parameter is unidentifiable
CHI2_P = 1e-3      # a chi2 this improbable (upper tail) for its degrees of freedom: the model does not fit
BOUND_TOL = 1e-3   # a fitted value within this share of its bounds' width of one is on its bound
LOO_ITERATIONS = 8  # LM iterations of each leave-one-out refit (from the full fit's answer)


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
        self.x = None   # warm start of the equilibria (None: a cold solve, calibration.equilibrium)
        self.anchor = None   # (v, x, dx/dv) at the last Jacobian: the Euler predictor of x at a new v
        self.evaluations = 0

    def start(self, x: torch.Tensor | None, v: np.ndarray | None = None, rates: torch.Tensor | None = None) -> None:
        """Warm-start the equilibria from x (B, 3J) (None: cold), predicted to other values
        by the rates dx/dv (B, 3J, k) at v when given."""
        self.x = x
        self.anchor = None if rates is None else (v.copy(), x, rates)

    def _guess(self, v: np.ndarray) -> torch.Tensor | None:
        """The equilibria to start Newton from at v: the last ones moved by the Euler
        predictor x + dx/dv·(v - v_anchor) (a stiff contact with the plane X = 0 makes the
        last ones alone a poor start: the finger's new pose crosses it)."""
        if self.anchor is None:
            return self.x
        v0, x0, rates = self.anchor
        return x0 + rates @ torch.as_tensor(v - v0, dtype=torch.float64)

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
        x, ok = equilibrium(self.model, self.d, th[None].repeat(B, 1), self._guess(v))
        if not bool(ok.all()):
            return (None, None) if jacobian else None
        self.x = x
        pr, pj = self._prior_terms(v)
        if not jacobian:
            with torch.no_grad():
                m = predict(self.model, self.d, x, th[None].repeat(B, 1)).numpy()
            return np.concatenate(((m - self.d.y) / self.d.sigma, pr))
        m, jac, rates = sensitivities(self.model, self.d, x, th, rates=True)
        self.anchor = (np.array(v, dtype=float), x, rates[:, :, self.fit])
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
    n_values: int = 0          # measured scalars
    n_priors: int = 0
    on_bound: list = None      # names of the fitted parameters on a bound
    why: list = None           # the reasons not to trust the fit (empty: trusted)

    @property
    def dof(self) -> int:
        """Degrees of freedom: measured values and priors minus fitted parameters."""
        return self.n_values + self.n_priors - len(self.names)

    @property
    def reduced_chi2(self) -> float | None:
        return 2.0 * self.cost / self.dof if self.dof > 0 else None

    @property
    def trusted(self) -> bool:
        return self.converged and not self.why

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
            "chi2": 2.0 * self.cost, "values": self.n_values, "priors": self.n_priors, "dof": self.dof,
            "reduced_chi2": self.reduced_chi2, "reduced_chi2_limit": chi2_limit(self.dof),
            "on_bound": self.on_bound or [], "trusted": self.trusted, "why": self.why or [],
            "starts": self.starts, "converged": self.converged, "time_s": self.time_s}


def chi2_limit(dof: int) -> float | None:
    """The reduced chi-square beyond which a fit is refused: the chi-square distribution's
    upper CHI2_P quantile over dof (None without degrees of freedom)."""
    from scipy.stats import chi2

    return float(chi2.isf(CHI2_P, dof) / dof) if dof > 0 else None


def on_bounds(prob: "Problem", v: np.ndarray) -> list:
    """Indices (into the fitted) of the values v on a bound (BOUND_TOL of the width)."""
    tol = BOUND_TOL * (prob.hi - prob.lo)
    return [i for i in range(len(v)) if v[i] <= prob.lo[i] + tol[i] or v[i] >= prob.hi[i] - tol[i]]


def poor_fit(prob: "Problem", v: np.ndarray, cost: float) -> bool:
    """Whether a converged answer fails the chi-square or the bound test (module docstring)."""
    dof = len(prob.d.y) + len(prob.priors) - len(v)
    if dof <= 0:   # too few data: no start can make the answer trusted
        return False
    return not math.isfinite(cost) or bool(on_bounds(prob, v)) or 2.0 * cost / dof > chi2_limit(dof)


def judge(res: "CalibrationResult", lo: np.ndarray, hi: np.ndarray) -> list:
    """The reasons (one line each, module docstring) not to trust ``res``."""
    why = []
    if res.dof <= 0:
        why.append(f"{res.n_values} measured values{f' and {res.n_priors} priors' if res.n_priors else ''} for "
                   f"{len(res.names)} fitted parameters: more parameters than data (measure more gestures or fit "
                   "fewer parameters)")
    if res.unidentifiable:
        why.append(f"{', '.join(res.unidentifiable)} cannot be identified from these observations (VIF > {MAX_VIF:g} "
                   "or std > half the bounds; fit fewer parameters or give priors)")
    for n in res.on_bound or []:
        k = res.names.index(n)
        why.append(f"{n} = {res.values[k]:.6g} is on its bound [{lo[k]:g}, {hi[k]:g}]")
    red, limit = res.reduced_chi2, chi2_limit(res.dof)
    if red is not None and red > limit:
        why.append(f"reduced chi-square {red:.3g} > {limit:.3g} (the {1 - CHI2_P:.1%} limit for {res.dof} degrees of "
                   "freedom): the model does not explain the observations (is the problem, gripper or finger, the "
                   "measured one? are parameters left unfitted? are the sigmas too small?)")
    return why


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


def fit(prob: Problem, starts: int = 3, seed: int = 0, x_start: torch.Tensor | None = None
        ) -> tuple[np.ndarray, float, bool, int]:
    """The best LM answer over up to ``starts`` starts: the nominal values, then uniform
    draws within the bounds' middle half while the best answer is a poor fit
    (``poor_fit``); each start's equilibria from ``x_start`` (the nominal ones: a cold
    solve where the fingers meet costs a ramp). Returns (v, cost, converged, starts run)."""
    rng = np.random.default_rng(seed)
    v0 = prob.base[prob.fit].numpy()
    best = (v0, math.inf, None)
    k = 0
    while k < starts and (k == 0 or poor_fit(prob, best[0], best[1])):
        start = v0 if k == 0 else prob.lo + (prob.hi - prob.lo) * rng.uniform(0.25, 0.75, len(v0))
        prob.start(x_start)
        v, cost, _ = levenberg_marquardt(prob, start)
        if cost < best[1]:
            best = (v, cost, prob.anchor)
        k += 1
    prob.anchor = best[2]   # the winner's equilibria and rates: the answer's start
    prob.x = None if best[2] is None else best[2][1]
    return best[0], best[1], math.isfinite(best[1]), k


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
    v, cost, ok, ran = fit(prob, starts, seed, prob.x)
    r, jac = prob.residual(v, jacobian=True) if ok else (None, None)
    if r is None:
        raise FitFailed(f"no start of the fit of {', '.join(model.table[i].name for i in idx)} converged")
    # a parameter the data do not see at all (zero column) has an infinite variance: no
    # warnings for it, its correlations 0, its VIF inf (unidentifiable)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        cov = covariance(jac)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = np.nan_to_num(cov / np.outer(np.maximum(std, 1e-300), np.maximum(std, 1e-300)), nan=0.0)
        vif = np.diag(cov) * np.diag(jac.T @ jac)
    vif = np.where(np.isfinite(vif), vif, np.inf)
    names = [model.table[i].name for i in idx]
    bad, pairs = _identifiability(names, std, corr, vif, prob.lo, prob.hi)
    theta = prob.theta(v)
    res = CalibrationResult(names, v, std, corr, vif, bad, pairs, before, _rms_mm(prob, v), cost, theta, [], ran,
                            0.0, ok, len(d.y), len(prob.priors), [names[i] for i in on_bounds(prob, v)])
    res.why = judge(res, prob.lo, prob.hi)
    if loo and not res.why:   # a refused fit is not worth checking (and its refits crawl)
        res.loo_tip_error_mm = leave_one_out(model, obs, idx, priors, v, prob.x, prob.anchor[2])
    res.time_s = time.perf_counter() - t0
    return res


def leave_one_out(model, obs: Observations, idx, priors, v_all: np.ndarray, x_all: torch.Tensor | None = None,
                  rates: torch.Tensor | None = None) -> list:
    """Per observation with a tip: the tip error (mm) of the fit to the others (one start,
    from the full fit's values, equilibria x_all (B, 3J) and their rates dx/dv (B, 3J, k)),
    None for the others."""
    out = []
    for i, o in enumerate(obs.items):
        if o.tip is None or len(obs) < 2:
            out.append(None)
            continue
        keep = [k for k in range(len(obs)) if k != i]
        prob = Problem(model, design(obs.subset(keep), model.finger), idx, priors)
        if x_all is not None:
            prob.start(x_all[keep], v_all, None if rates is None else rates[keep])
        # from the full fit, a few steps suffice: past them the cost changes by < 1e-6 of
        # itself, and a flat valley's crawl moves the predicted tip by far less than its noise
        v, _, _ = levenberg_marquardt(prob, v_all, max_iter=LOO_ITERATIONS, tol=1e-6)
        one = design(obs.subset([i]), model.finger)
        th = prob.theta(v)[None]
        guess = None if x_all is None else x_all[i:i + 1] + (
            0.0 if rates is None else rates[i:i + 1] @ torch.as_tensor(v - v_all, dtype=torch.float64))
        x, ok = equilibrium(model, one, th, guess)
        if not bool(ok.all()):
            out.append(None)
            continue
        with torch.no_grad():
            m = predict(model, one, x, th).numpy()
        rx, ry = one.tip_rows[0]
        out.append(float(math.hypot(m[rx] - one.y[rx], m[ry] - one.y[ry])))
    return out


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.calibrate")
