"""The gesture solvers' result type: GestureResult, a batch of solved gestures with their
residuals, contact figures and pose (built once by predictor.solve.gesture_result; a result
derived from another is a ``dataclasses.replace`` of it), and its JSON summary."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields

import torch

from predictor.gripper import FingerPose, with_rows
from predictor.statics import NOT_CONVERGED, STATES, GripperProblem, grasp_state


#: GestureResult field metadata: fixed by the question (the pressures), not by the solve.
GIVEN = {"given": True}


@dataclass(frozen=True)
class GestureResult:
    """Batched solve result for the right finger (mirror with ``pose.mirrored()``), frozen:
    a result derived from another is a ``dataclasses.replace`` (``with_rows``).

    pressures (B, J) MPa; tau (B, J, 3) [F1 N, F2 N, M N·mm], NaN where not converged;
    converged (B,) bool; residual_force_mN, residual_moment_Nmm (B, J) at the last
    iterate; normal_force_N, friction_N (B,) total contact forces on the finger;
    friction_ratio (B,) |f|/N demanded by the object; slip (B,) bool; iterations (B,)
    (summed over ramp steps); time_ms: wall time of the whole batch, up to its residual and
    pose; pose: FingerPose, NaN where not converged (the load-free shape, tau = 0, is
    ``problem.pose(pressures, 0)``: predictor.plot draws it);
    first_contact (B, J) MPa: the pressures of the first ramp step (or the approach, when
    the object is brought in) after which the finger touches the object, NaN when it never
    does (without the ramp, x0 given: the target pressures if the final gesture touches);
    None without an object. joint: the joint model's name; mu: the contact law's friction
    coefficient and object_weight_N: the object's weight (N, 0 without gravity), both None
    without an object. method: what produced the answers (predictor.solve: "newton", "lm",
    "lbfgs", "newton+lm" where the LM finished rows; predictor.nn_answer: "nn",
    "nn+newton", "nn+lm", "nn+newton+lm").

    friction_ratio is the signed lambda of the contact law (statics.contact_loads; ±1e3
    where nothing touches): internal. The figure reported everywhere is the friction use
    u = |f|/(mu N) = |lambda|/mu (``friction_use``), null where nothing touches.
    """

    pressures: torch.Tensor = field(metadata=GIVEN)
    tau: torch.Tensor
    converged: torch.Tensor
    residual_force_mN: torch.Tensor
    residual_moment_Nmm: torch.Tensor
    normal_force_N: torch.Tensor
    friction_N: torch.Tensor
    friction_ratio: torch.Tensor
    slip: torch.Tensor
    iterations: torch.Tensor
    time_ms: float
    pose: FingerPose
    method: str
    first_contact: torch.Tensor | None = None
    joint: str = ""
    mu: float | None = None
    object_weight_N: float | None = None

    def friction_use(self) -> torch.Tensor:
        """u = |f|/(mu N) = |lambda|/mu (B,), NaN where nothing touches, without an object
        or where not converged."""
        touching = self.converged & (self.normal_force_N > 0)
        if self.mu is None:
            return torch.full_like(self.normal_force_N, float("nan"))
        return torch.where(touching, self.friction_ratio.abs() / self.mu, float("nan"))

    def states(self) -> torch.Tensor:
        """Grasp state codes (B,) into statics.STATES: not_converged, else no_contact
        (nothing touches, or no object), holds or slips."""
        state = grasp_state(self.normal_force_N, self.slip)
        return torch.where(self.converged, state, NOT_CONVERGED)

    def summary(self, i: int = 0) -> dict:
        """Sample i as plain JSON types: pressures_MPa, converged, state (statics.STATES),
        tau (Jx3), per-joint residual_force_mN and residual_moment_Nmm (at the last
        iterate), tip [x, y] mm (the end of the last part), tip_angle_deg (the last part's
        direction), contact_force_N and friction_N (N), friction_use |f|/(mu N) and slip
        (null where nothing touches), iterations, joint, mu and object_weight_N (null
        without an object). Every figure of the gesture is null unless converged. Time
        excluded: a summary of the same solve is the same."""
        ok = bool(self.converged[i])
        state = STATES[int(self.states()[i])]
        touching = state in ("holds", "slips")
        use = float(self.friction_use()[i])
        return {"pressures_MPa": self.pressures[i].tolist(), "converged": ok, "state": state,
                "tau": self.tau[i].tolist() if ok else None,
                "residual_force_mN": self.residual_force_mN[i].tolist(),
                "residual_moment_Nmm": self.residual_moment_Nmm[i].tolist(),
                "tip": self.pose.tip_end[i].tolist() if ok else None,
                "tip_angle_deg": math.degrees(float(self.pose.tip_angle[i])) if ok else None,
                "contact_force_N": float(self.normal_force_N[i]) if ok else None,
                "friction_N": float(self.friction_N[i]) if ok else None,
                "friction_use": use if touching else None,
                "slip": bool(self.slip[i]) if touching else None, "iterations": int(self.iterations[i]),
                "joint": self.joint, "mu": self.mu, "object_weight_N": self.object_weight_N}

    def with_rows(self, rows: torch.Tensor, other: "GestureResult") -> "GestureResult":
        """A copy whose solved rows ``rows`` (B,) bool come from ``other`` (a result for the
        pressures[rows]); the given fields, time and method stay this result's."""
        new = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if not f.metadata.get("given") and isinstance(v, (torch.Tensor, FingerPose)):
                mine = getattr(other, f.name)
                v = v.with_rows(rows, mine) if isinstance(v, FingerPose) else with_rows(v, rows, mine)
            new[f.name] = v
        return dataclasses.replace(self, **new)


def result_labels(problem: GripperProblem) -> dict:
    """The GestureResult fields that name what was solved: joint, mu, object_weight_N."""
    has = problem.obstacle is not None
    weight = problem.params.object_weight if problem.gravity else 0.0
    return {"joint": problem.joint.name, "mu": problem.contact.mu if has else None,
            "object_weight_N": weight if has else None}
