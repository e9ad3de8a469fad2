"""The gesture solvers' result type: GestureResult, a batch of solved gestures with their
residuals, contact figures and pose (built once by predictor.solvers.solve.gesture_result; a result
derived from another is a ``dataclasses.replace`` of it), and its JSON summary."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields

import torch

from predictor.model.gripper import FACES, FingerPose, part_names, with_rows
from predictor.model.statics import NOT_CONVERGED, STATES, GripperProblem, Statics, grasp_state, meets, plane_contact

#: The faces a contact site names (gripper.FACES, then the paper's centre-line points).
SITE_FACES = FACES + ("centre_line",)


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
    ``problem.pose(pressures, 0)``: predictor.model.plot draws it);
    first_contact (B, J) MPa: the pressures of the first ramp step (or the approach, when
    the object is brought in) after which the finger touches the object, NaN when it never
    does (without the ramp, x0 given: the target pressures if the final gesture touches);
    None without an object. joint: the joint model's name; mu: the contact law's friction
    coefficient and object_weight_N: the object's weight (N, 0 without gravity), both None
    without an object. method: what produced the answers (predictor.solvers.solve: "newton", "lm",
    "lbfgs", "newton+lm" where the LM finished rows; predictor.nn.answer: "nn",
    "nn+newton", "nn+lm", "nn+newton+lm").

    friction_ratio is the signed lambda of the contact law (statics.contact_loads; ±1e3
    where nothing touches): internal. The figure reported everywhere is the friction use
    u = |f|/(mu N) = |lambda|/mu (``friction_use``), null where nothing touches.

    Where it touches (``contact_fields``; None in results that do not carry them, e.g. a
    network's raw answer): sites (B, P, 4, 3) per part (chain order) and face
    (SITE_FACES) the object's normal force N on it and the force-weighted mean point
    [X, Y] mm of its contact (on that face; NaN where it carries none); plane_force_N (B,)
    the symmetry plane's push on the finger where the fingers meet; plane_overlap_mm (B,)
    how far the right finger's outline crosses X = 0.
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
    plane: bool | None = None           # the problem: the gripper (the plane X = 0) or one finger alone
    sites: torch.Tensor | None = None
    plane_force_N: torch.Tensor | None = None
    plane_overlap_mm: torch.Tensor | None = None

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
        without an object), plane (the problem solved: true, the gripper, the mirror
        finger's contact at X = 0; false, one finger alone; null if unrecorded). Every
        figure of the gesture is null unless converged. Time
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
                "joint": self.joint, "mu": self.mu, "object_weight_N": self.object_weight_N,
                "plane": self.plane, **self.where_it_touches(i)}

    def where_it_touches(self, i: int = 0) -> dict:
        """Sample i's contact places as plain JSON types: contacts, a list of {part, face,
        normal_force_N, point_mm} (part names of gripper.part_names, faces SITE_FACES),
        most force first; contact_part, contact_face, contact_point_mm of the first (null
        where nothing touches); plane_force_N, plane_overlap_mm (X = 0). Every figure is
        null unless converged or when the result does not carry them."""
        ok = bool(self.converged[i])
        out = {"contacts": None, "contact_part": None, "contact_face": None, "contact_point_mm": None,
               "plane_force_N": None, "plane_overlap_mm": None}
        if not ok:
            return out
        if self.plane_force_N is not None:
            out["plane_force_N"] = float(self.plane_force_N[i])
            out["plane_overlap_mm"] = float(self.plane_overlap_mm[i])
        if self.sites is None or self.mu is None:
            return out
        names = part_names(self.pose.finger)
        site = self.sites[i]                                   # (P, 4, 3)
        order = torch.argsort(site[..., 0].flatten(), descending=True).tolist()
        contacts = [{"part": names[k // 4], "face": SITE_FACES[k % 4], "normal_force_N": float(site[k // 4, k % 4, 0]),
                     "point_mm": site[k // 4, k % 4, 1:].tolist()} for k in order if site[k // 4, k % 4, 0] > 0]
        out["contacts"] = contacts
        if contacts:
            out.update(contact_part=contacts[0]["part"], contact_face=contacts[0]["face"],
                       contact_point_mm=contacts[0]["point_mm"])
        return out

    def rows(self, index) -> "GestureResult":
        """The result of samples ``index`` (a bool mask or indices over B); the time and
        method stay this result's."""
        new = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, FingerPose):
                v = v.rows(index)
            elif isinstance(v, torch.Tensor):
                v = v[index]
            new[f.name] = v
        return dataclasses.replace(self, **new)

    def with_rows(self, rows: torch.Tensor, other: "GestureResult") -> "GestureResult":
        """A copy whose solved rows ``rows`` (B,) bool come from ``other`` (a result for the
        pressures[rows]); the given fields, time and method stay this result's."""
        new = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if not f.metadata.get("given") and isinstance(v, (torch.Tensor, FingerPose)):
                mine = getattr(other, f.name)
                if mine is None:                  # figures the other result does not carry
                    v = None
                else:
                    v = v.with_rows(rows, mine) if isinstance(v, FingerPose) else with_rows(v, rows, mine)
            new[f.name] = v
        return dataclasses.replace(self, **new)


def result_labels(problem: GripperProblem) -> dict:
    """The GestureResult fields that name what was solved: joint, mu, object_weight_N and
    plane (the fingers meet at X = 0: statics.meets)."""
    has = problem.obstacle is not None
    weight = problem.params.object_weight if problem.gravity else 0.0
    return {"joint": problem.joint.name, "mu": problem.contact.mu if has else None,
            "object_weight_N": weight if has else None, "plane": meets(problem)}


def contact_fields(problem: GripperProblem, st: Statics) -> dict:
    """The GestureResult fields of where the finger touches, from the statics ``st`` of a
    batch (B): sites (the object's normal force and mean point per part and face) and the
    symmetry plane's force and overlap (GestureResult docstring)."""
    params = problem.params
    plane = st.plane if st.plane is not None else plane_contact(st.pose, params, problem.contact)
    force = plane.force if problem.contact.plane_stiffness > 0 else torch.zeros_like(plane.force)
    return {"sites": contact_sites(st, params.layout, len(params.finger.parts)),
            "plane_force_N": force, "plane_overlap_mm": plane.overlap}


def contact_sites(st: Statics, layout, n_parts: int) -> torch.Tensor:
    """(B, P, 4, 3): per part and face (SITE_FACES) the object's normal force N on the
    finger and the force-weighted mean point [X, Y] mm of those loads (NaN where none).
    Each point's normal force is |f_k| / sqrt(1 + lambda_c²), since f_k = N_k (n_k -
    lambda_c t_k) (statics.contact_loads)."""
    c = st.contact
    B = len(c.normal)
    out = torch.zeros(B, n_parts * 4, 3, dtype=c.normal.dtype)
    if c.forces.shape[1]:
        used = torch.where(c.normal > 0, c.friction / c.normal.clamp_min(1e-300), 0.0)
        n = c.forces.norm(dim=-1) / torch.sqrt(1.0 + used * used)[:, None]          # (B, K)
        face = torch.where(layout.contact_face < 0, 3, layout.contact_face)
        site = (c.part * 4 + face).expand(B, -1)
        out[..., 0].scatter_add_(1, site, n)
        out[..., 1].scatter_add_(1, site, n * c.points[..., 0])
        out[..., 2].scatter_add_(1, site, n * c.points[..., 1])
    out[..., 1:] = out[..., 1:] / out[..., :1]          # NaN where no force (0 / 0)
    return out.reshape(B, n_parts, 4, 3)
