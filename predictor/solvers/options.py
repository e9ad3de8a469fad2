"""The gesture solver's options (predictor.solvers.solve): method, tolerances and limits."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SolverOptions:
    """method: newton | lm | lbfgs (module docstring). Newton and LM tolerances in N and
    N·mm (1e-4 mN, 1e-5 N·mm: 1000x below the issue's 0.1 mN / 0.01 N·mm target; an
    extra Newton step is cheap, docs/decisions.md §11).
    L-BFGS (the paper's reference) runs to its own stall (lbfgs_max_iter iterations per
    ramp step at most) and is accepted at the issue's target (lbfgs_tol_*): on stiff
    contact steps it stalls near 0.02 mN, short of the Newton tolerance. max_iter: LM
    iterations per ramp step (without an object: Picard, Newton and LM steps in all).
    ramp_steps: pressure sub-steps when an object is present; cutbacks: how many times a
    failed Newton sub-step may be halved (L-BFGS: none);
    max_penetration (mm): deeper is treated as tunnelling (a failed step), not as an
    equilibrium; contact_max_step: LM step cap with an object, in scaled units (0.3 N or
    30 N·mm). jacobian: auto (central differences; with an object, exact for the samples
    that fail with them: ``attempts``), exact, or differences. (Gravity is part of the problem:
    GripperProblem.gravity.)"""

    method: str = "newton"
    tol_force: float = 1e-7
    tol_moment: float = 1e-5
    lbfgs_tol_force: float = 1e-4
    lbfgs_tol_moment: float = 1e-2
    max_iter: int = 30
    lbfgs_max_iter: int = 1000
    ramp_steps: int = 12
    cutbacks: int = 4
    max_penetration: float = 1.0
    contact_max_step: float = 0.3
    jacobian: str = "auto"
