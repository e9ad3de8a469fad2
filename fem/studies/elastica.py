"""Exact large-deflection solutions of the inextensible Euler elastica (pure functions).

Cantilever of length L, clamped at s = 0, dead transverse tip load P (Bisshopp & Drucker
1945), load parameter alpha = P L² / EI. With theta(s) the slope and theta_0 the tip
slope, EI theta'' = -P cos(theta) integrates to (EI/2) theta'^2 = P (sin theta_0 - sin theta),
and the substitution sin(theta) = sin(theta_0) - q² removes the end singularity::

    1 = 1/sqrt(2 alpha) ∫_0^sqrt(s0) 2 dq / sqrt(1 - (s0 - q²)²)          (s0 = sin theta_0)
    x_tip / L = sqrt(2 s0 / alpha)
    w_tip / L = 1/sqrt(2 alpha) ∫_0^sqrt(s0) 2 (s0 - q²) dq / sqrt(1 - (s0 - q²)²)

Pure end moment M (roll-up), T = M L / EI: a circular arc of curvature M/EI, so the tip
is at (L sin T / T, L (1 - cos T) / T) with slope T.
"""

from __future__ import annotations

import math

import warnings

from scipy import integrate, optimize


def _quad(f, upper: float) -> float:
    with warnings.catch_warnings():   # near s0 = 1 (alpha -> inf) the end is log-singular
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        return integrate.quad(f, 0.0, upper, epsabs=1e-12, epsrel=1e-10, limit=500)[0]


def _length_integral(s0: float) -> float:
    f = lambda q: 2.0 / math.sqrt(max(1.0 - (s0 - q * q) ** 2, 1e-300))
    return _quad(f, math.sqrt(s0))


def cantilever_tip(alpha: float) -> dict:
    """Exact tip of the tip-loaded elastica for alpha = P L²/EI (0 <= alpha <= ~1000).

    Returns {"u_over_L": horizontal shortening, "w_over_L": deflection, "theta": tip slope rad}.
    """
    if alpha < 0:
        raise ValueError("alpha must be >= 0")
    if alpha == 0:
        return {"u_over_L": 0.0, "w_over_L": 0.0, "theta": 0.0}
    g = lambda s0: _length_integral(s0) / math.sqrt(2 * alpha) - 1.0
    s0 = optimize.brentq(g, 1e-14, 1.0 - 1e-9, xtol=1e-15, rtol=1e-14)
    f = lambda q: 2.0 * (s0 - q * q) / math.sqrt(max(1.0 - (s0 - q * q) ** 2, 1e-300))
    w = _quad(f, math.sqrt(s0))
    return {"u_over_L": 1.0 - math.sqrt(2 * s0 / alpha),
            "w_over_L": w / math.sqrt(2 * alpha),
            "theta": math.asin(s0)}


def rollup_tip(T: float) -> dict:
    """Exact tip of a beam under a pure end moment with T = M L / EI (rad).

    Returns {"x_over_L", "y_over_L", "theta"}.
    """
    if abs(T) < 1e-12:
        return {"x_over_L": 1.0, "y_over_L": 0.0, "theta": 0.0}
    return {"x_over_L": math.sin(T) / T, "y_over_L": (1 - math.cos(T)) / T, "theta": T}


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.studies.validation")
