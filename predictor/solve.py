"""Iterative gesture predictor: find tau = (tau_1, tau_2) with zero Equation-1 residual.

Unknowns x = (F1, F2, M)_1, .., (F1, F2, M)_J per sample (J joints of the finger, 2 for the
paper's), (B, n = 3J) in N, N, N·mm. The residual vector is r(x) = [R_F,1, R_M,1/100, ..,
R_F,J, R_M,J/100, out-of-box penalties] (2n numbers, see predictor.statics); the
equilibrium is r = 0 with the penalties inactive.

Methods, all batched over B pressure pairs and starting from tau = 0:

- ``newton`` (the default): without an object, from tau = 0 a fixed-point (Picard) step
  (tau <- the loads distal to each joint at the current pose), then Newton steps
  x -= (dR/dx)⁻¹ R on the equilibrium rows (dR/dx by forward differences), all recorded
  as one graph with the answer's statics (``_cold_newton``: Picard and two Newton steps
  land within the tolerances across the box); the answer's own residual is the check,
  and where it fails more Newton steps, then the LM below, go on (``_newton_then_lm``).
  From a given x0 (a network's tau) one Newton step and its statics, also one graph
  (``newton_polish``).
  With an object: the LM below (predictor.nn starts the same Newton steps,
  ``newton_iterate``, from the contact network's tau and checks their branch itself).
- ``lm``: Levenberg-Marquardt on r with the Jacobian J = dr/dx
  (B, 2n, n) in one batched pass (``_jacobian_fn``): central differences of the traced
  residual (~1e-10 relative: Newton's quadratic convergence is kept); with an object the
  samples that fail so are solved again with the exact reverse-mode Jacobian (the
  contact law has kinks; ``attempts``).
  Step (JᵀJ + mu·I) δ = -Jᵀr; mu shrinks ×0.1 on success and grows ×10 on failure, per
  sample, and only unfinished samples are evaluated. Near the root mu -> 1e-12 and the step is Newton's, so the
  convergence is quadratic: 3-6 iterations under gravity.
- ``lbfgs`` (the paper's reference): torch L-BFGS with strong-Wolfe line search on the
  scalar loss sum_b |r_b|².

With an object the pressures are ramped from 0 (or from the approach gesture,
``GripperProblem.approach``) to the target in ``ramp_steps`` equal sub-steps: the grasp depends on
the pressure history (the finger must arrive at the object from the open side). Each step
starts from the tangent predictor x + dx/dP·ΔP (exact dr/dP from the same autograd pass,
Jacobians reused from the previous step), converges to a 100x looser tolerance except the
last, caps LM steps so the finger cannot jump through the object, refuses equilibria that
penetrate deeper than ``max_penetration``, and is halved (up to ``cutbacks`` times) when
it fails.

A sample is converged when |R_F,i| <= tol_force and |R_M,i| <= tol_moment for every
joint and tau is inside the surrogate's box. Non-converged samples are reported with
``converged = False`` and NaN in tau and in the gesture: never returned as an answer.

Data flow: ``solve(problem, pressures, options)`` with a statics.GripperProblem (joint,
finger, object, contact law, gravity, approach) -> GestureResult (tau, residuals, contact
figures, pose); ``result.summary(i)`` is sample i as a JSON-ready dict.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
import warnings
from dataclasses import dataclass, field, fields

import numpy as np
import torch

from contract.spec import INPUT_BOX
from predictor.gripper import FingerPose, check_pressures, nan_unless, rot, with_rows
from predictor.progress import Heartbeat
from predictor.statics import (MOMENT_SCALE, NOT_CONVERGED, PENALTY_WEIGHT, STATES, ContactState, GripperProblem,
                               Statics, contact_loads, grasp_state, out_of_reach, range_penalty, residual_norms,
                               scaled)


@dataclass(frozen=True)
class SolverOptions:
    """method: newton | lm | lbfgs (module docstring). Newton and LM tolerances in N and
    N·mm (1e-4 mN, 1e-5 N·mm: 1000x below the issue's 0.1 mN / 0.01 N·mm target; one
    extra Newton step costs ~0.5 ms).
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


#: GestureResult field metadata: fixed by the question (the pressures), not by the solve.
GIVEN = {"given": True}


@dataclass
class GestureResult:
    """Batched solve result for the right finger (mirror with ``pose.mirrored()``).

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
    without an object.

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


#: How ``traced`` records a graph (``use_graphs``): "trace", torch.jit.trace (the default:
#: 0.3 s to record); "compile", torch.compile to inductor's C++ with a C++ wrapper, which
#: fuses the ~150 small operations of a residual into a few loops: ~3x faster for one
#: query and ~2x for a batch on this machine (environment.md), but the first use of each
#: graph compiles for 15-40 s (cached on disk: ~14 s in a later process). For batch jobs
#: and benchmarks, not for one-off queries.
GRAPHS = ("trace", "compile")
_graphs = "trace"
_GRAPH_CACHES: list = []


def graph_cache(builder):
    """functools.lru_cache for a builder of recorded graphs (one per problem): emptied by
    ``use_graphs``, so that its next call records with the new backend."""
    cached = functools.lru_cache(maxsize=16)(builder)
    _GRAPH_CACHES.append(cached)
    return cached


def use_graphs(mode: str) -> None:
    """Record graphs from now on by ``mode`` (one of GRAPHS), process-wide; ValueError
    (one line) for another."""
    global _graphs
    if mode not in GRAPHS:
        raise ValueError(f"graphs {mode!r}: use one of {', '.join(GRAPHS)}")
    _graphs = mode
    for cached in _GRAPH_CACHES:
        cached.cache_clear()


def _residual_fn(problem: GripperProblem):
    """Batched r(x; P): x (B, 3J), P (B, J) -> (B, 6J) [scaled equilibrium, penalties]."""
    n_joints = problem.n_joints

    def r(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        tau = x.reshape(-1, n_joints, 3)
        return torch.cat((scaled(problem.residual(p, tau).residual), range_penalty(tau)), -1)

    return r


@graph_cache
def _traced_residual_fn(problem: GripperProblem):
    """``_residual_fn(problem)`` recorded by ``traced``: one per problem (0.3 s), valid
    for any batch size."""
    return traced(_residual_fn(problem), 3 * problem.n_joints, problem.n_joints)


@graph_cache
def _traced_contact_fn(problem: GripperProblem):
    """c(x (B, 3J), p (B, J)) -> (B, 2) [total normal force N, penetration mm] of the
    object on the finger, recorded by ``traced``: the ramp asks for it after every step
    (the depth check, the first contact), where the whole eager residual (pose, weights,
    Equation 1) costs several times more."""
    n_joints, weight = problem.n_joints, problem.params.object_weight if problem.gravity else 0.0

    def c(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        st = contact_loads(problem.pose(p, x.reshape(-1, n_joints, 3)), problem.params, problem.obstacle,
                           problem.contact, weight)
        return torch.stack((st.normal, st.penetration), -1)

    return traced(c, 3 * n_joints, n_joints)


def touch(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(normal force N (B,), penetration mm (B,)) of the object on the finger at unknowns
    x (B, 3J) and pressures p (B, J) (``_traced_contact_fn``)."""
    with torch.inference_mode():
        c = _traced_contact_fn(problem)(x, p)
    return c[:, 0].clone(), c[:, 1].clone()


def traced(fn, n: int, J: int):
    """fn(x (B, n), p (B, J)) recorded for inference only (no autograd): one evaluation of
    the gesture residual is ~150 small tensor operations, whose Python dispatch costs more
    than their arithmetic. By torch.jit.trace (the default), the recorded graph runs them
    2-3x faster with identical results (no data-dependent Python branches; the joint
    model's weights become constants of the graph); fn itself if the record does not
    reproduce it bit for bit on random x in the box and P in [-0.3, 0.3] MPa. With
    ``use_graphs("compile")``, torch.compile (dynamic batch size), kept where it agrees
    with fn (``_agree``), else the trace."""
    gen = torch.Generator().manual_seed(0)
    x = (2 * torch.rand(4, n, generator=gen, dtype=torch.float64) - 1) * _box_scale(n)[0]
    p = (2 * torch.rand(4, J, generator=gen, dtype=torch.float64) - 1) * INPUT_BOX[0]
    failed = None
    with torch.inference_mode(), warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the tracer's notes on constants; checked below
        if _graphs == "compile":
            record = _compiled(fn)
            try:
                if all(_agree(a, b) for a, b in zip(_tensors(record(x[:1], p[:1])), _tensors(fn(x[:1], p[:1])))):
                    return record
                failed = "its graph disagrees with the eager one"
            except Exception as exc:   # e.g. no C++ compiler: the trace below still works
                failed = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        theirs = _tensors(fn(x[:3], p[:3]))
        record = torch.jit.trace(fn, (x, p), check_trace=False)
        chosen = record if all(map(torch.equal, _tensors(record(x[:3], p[:3])), theirs)) else fn
    if failed:
        warnings.warn(f"torch.compile not used ({failed}): the graph is recorded by torch.jit.trace")
    return chosen


def _compiled(fn):
    """torch.compile of fn(x, p) with a dynamic batch size, its inputs passed as inference
    tensors: a compiled graph is specialised to its inputs' dispatch keys, and callers
    pass both kinds (a clone of a few rows is cheaper than a second compile)."""
    record = torch.compile(fn, dynamic=True, options={"cpp_wrapper": True, "cpp.dynamic_threads": True})

    def run(x: torch.Tensor, p: torch.Tensor):
        with torch.inference_mode():
            return record(x if x.is_inference() else x.clone(), p if p.is_inference() else p.clone())

    run.__wrapped__ = record
    return run


def _agree(a: torch.Tensor, b: torch.Tensor) -> bool:
    """A compiled graph's output a against fn's b: within 1e-6 relative for floats (inductor
    reorders sums, ~1e-15, which a difference quotient's 1/h turns into ~1e-8), equal
    otherwise."""
    return torch.allclose(a, b, rtol=1e-6, atol=1e-9) if a.is_floating_point() else torch.equal(a, b)


def _tensors(out) -> tuple:
    """A graph's output, a tensor or a tuple of them, as a tuple."""
    return out if isinstance(out, tuple) else (out,)


def _statics_fn(problem: GripperProblem):
    """s(x (B, 3J), p (B, J)) -> (residual (B, J, 3), then the FingerPose's tensor fields
    joints, segments, theta, phi, points, then with an object the ContactState's forces,
    normal, friction, ratio, slip, penetration)."""
    n_joints, contact = problem.n_joints, problem.obstacle is not None

    def s(x: torch.Tensor, p: torch.Tensor):
        st = problem.residual(p, x.reshape(-1, n_joints, 3))
        q, c = st.pose, st.contact
        out = (st.residual, q.joints, q.segments, q.theta, q.phi, q.points)
        return out + (c.forces, c.normal, c.friction, c.ratio, c.slip, c.penetration) if contact else out

    return s


@graph_cache
def _traced_statics_fn(problem: GripperProblem):
    """``_statics_fn`` recorded by ``traced``: the answer's statics (``gesture_result``) in a
    third of the eager time (0.43 against 1.21 ms for one query on this machine), bit for
    bit the same."""
    return traced(_statics_fn(problem), 3 * problem.n_joints, problem.n_joints)


def _as_statics(problem: GripperProblem, out) -> Statics:
    """The Statics of ``_statics_fn``'s tuple (cloned: out of inference mode)."""
    res, joints, segments, theta, phi, points, *contact = (v.clone() for v in out)
    pose = FingerPose(joints=joints, segments=segments, theta=theta, phi=phi, points=points,
                      finger=problem.params.finger)
    if not contact:
        return Statics(res, pose, ContactState.none(len(res), res.dtype))
    return Statics(res, pose, ContactState(points, contact[0], problem.params.layout.contact_part, *contact[1:]))


def statics_at(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor) -> Statics:
    """problem.residual(pressures (B, J), tau (B, J, 3)) by its recorded graph in float64
    (``_traced_statics_fn``, recorded in float64; float32 is the throughput mode's,
    eager)."""
    if tau.dtype != torch.float64:
        return problem.residual(pressures, tau)
    with torch.inference_mode():
        return _as_statics(problem, _traced_statics_fn(problem)(tau.reshape(len(tau), -1), pressures))


def _jacobian_fn(problem: GripperProblem, pressure: bool = True, kind: str = "auto"):
    """The batched Jacobian the solver uses: jac(x (B, n), p (B, J)) -> (J (B, 2n, n),
    r (B, 2n), dr/dP (B, n, J), None unless ``pressure``). kind: auto, exact or
    differences.

    Without an object the residual is smooth (the surrogate's SiLU network and the chain's
    trigonometry): central differences of the traced residual (``_difference_jacobian``),
    ~10x faster than reverse mode for one query. With an object it has kinks (contact
    onset, stick/slip): a difference that straddles one averages the two sides, and LM then
    stalls at grasps on the stick/slip boundary (a three-joint grasp did), so the exact
    reverse-mode Jacobian (``_autograd_jacobian``) is used there.
    """
    if kind not in ("auto", "exact", "differences"):
        raise ValueError(f"unknown jacobian {kind!r}: use auto, exact or differences")
    if kind == "differences" or (kind == "auto" and problem.obstacle is None):
        return _difference_jacobian(_traced_residual_fn(problem), pressure)
    return _autograd_jacobian(_residual_fn(problem))


def _autograd_jacobian(r_fn):
    """Exact batched Jacobian by one reverse pass over n = 3J copies of each sample.

    Copy k of sample b only feeds output row k, so the gradient of sum_k r[b, k, k]
    with respect to copy k is row k of dr/dx: J (B, n, n) of the equilibrium rows in
    one forward + one backward of an nB batch (vmap(jacfwd) was 7x slower here). The
    penalty rows are elementwise in x, so their Jacobian is diagonal and written out.
    The same pass gives dr/dP (B, n, J) for the ramp's tangent predictor.
    """

    def jac(x: torch.Tensor, p: torch.Tensor, dp: bool = True):   # dr/dP comes with the same pass
        B, n = x.shape
        with torch.enable_grad():
            xr = x.detach().repeat_interleave(n, 0).requires_grad_(True)
            pr = p.detach().repeat_interleave(n, 0).requires_grad_(True)
            r = r_fn(xr, pr).reshape(B, n, 2 * n)
            g, gp = torch.autograd.grad(torch.diagonal(r[..., :n], dim1=1, dim2=2).sum(), (xr, pr))
        return torch.cat((g.reshape(B, n, n), _penalty_jacobian(x)), 1), r[:, 0].detach(), gp.reshape(B, n, p.shape[1])

    return jac


def _difference_jacobian(r_fn, pressure: bool = True, rel_step: float = 1e-6):
    """Batched Jacobian by central differences in one inference-mode pass.

    For each sample, the residual is evaluated at x and at x ± h_k e_k, P ± h_P e_j
    (1 + 2n + 2J rows of one batch; without ``pressure`` the P rows are skipped and dr/dP
    is None), with h_k = rel_step × (1 N, 1 N, 100 N·mm) and h_P = rel_step × 0.3 MPa.
    For a smooth residual truncation (h²) and round-off (eps/h) errors are both ~1e-10
    relative, far below what Newton's quadratic convergence needs. ``jac(x, p, dp=False)``
    skips the P rows too, and ``jac.dp(x, p)`` gives dr/dP alone (2J rows a sample): LM
    iterates without it and takes it once at its last iterate, not 2J of 1 + 2n + 2J rows
    on every iterate.
    """

    hp = rel_step * INPUT_BOX[0]

    def jac(x: torch.Tensor, p: torch.Tensor, dp: bool = True):
        B, n = x.shape
        m = p.shape[1] if pressure and dp else 0
        hx, offsets = _difference_offsets(n, rel_step)
        ep = hp * torch.eye(p.shape[1], dtype=x.dtype)[:m]   # (m, J)
        X = torch.cat((x[:, None] + offsets, x[:, None].expand(B, 2 * m, n)), 1)
        P = torch.cat((p[:, None].expand(B, 1 + 2 * n, p.shape[1]), p[:, None] + ep, p[:, None] - ep), 1)
        with torch.inference_mode():
            R = r_fn(X.reshape(-1, n), P.reshape(B * (1 + 2 * n + 2 * m), -1)).reshape(B, -1, 2 * n)
        R = R.clone()                     # leave inference mode: the caller writes into it
        g = (R[:, 1:1 + n, :n] - R[:, 1 + n:1 + 2 * n, :n]).transpose(1, 2) / (2 * hx)
        gp = (R[:, 1 + 2 * n:1 + 2 * n + m, :n] - R[:, 1 + 2 * n + m:, :n]).transpose(1, 2) / (2 * hp) if m else None
        return torch.cat((g, _penalty_jacobian(x)), 1), R[:, 0], gp

    def jac_p(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        # dr/dP (B, n, J) alone (2J rows a sample): LM needs it at its last iterate only
        B, n = x.shape
        ep = hp * torch.eye(p.shape[1], dtype=x.dtype)
        P = torch.cat((p[:, None] + ep, p[:, None] - ep), 1)
        with torch.inference_mode():
            R = r_fn(x.repeat_interleave(2 * p.shape[1], 0), P.reshape(-1, p.shape[1])).reshape(B, 2, -1, 2 * n)
        return ((R[:, 0, :, :n] - R[:, 1, :, :n]).transpose(1, 2) / (2 * hp)).clone()

    jac.dp = jac_p if pressure else None
    return jac


@functools.lru_cache(maxsize=8)
def _difference_offsets(n: int, rel_step: float, central: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """(h (n,), offsets (1 + 2n or 1 + n, n)): the steps h_k = rel_step × (1 N, 1 N, 100
    N·mm) and the rows 0, +h_k e_k (and -h_k e_k when ``central``) at which a difference
    quotient evaluates the residual; cached (read only), as every LM Jacobian asks for them."""
    h = rel_step * _box_scale(n)[1]
    rows = (torch.zeros(1, n, dtype=h.dtype), torch.diag(h)) + ((-torch.diag(h),) if central else ())
    return h, torch.cat(rows)


def _penalty_jacobian(x: torch.Tensor) -> torch.Tensor:
    """d(range penalty)/dx (B, n, n): diagonal, PENALTY_WEIGHT sign(x)/scale outside the box."""
    box, scale = _box_scale(x.shape[1])
    return torch.diag_embed(PENALTY_WEIGHT * torch.sign(x) * (x.abs() > box).to(x.dtype) / scale)


# Default grasp approach gesture (MPa): open joint 1, bring the object in (statics.Obstacle).
APPROACH = (-0.15, 0.0)


def approach_for(n_joints: int) -> tuple[float, ...]:
    """The default approach gesture of an n-joint finger: joint 1 opened as APPROACH's,
    the other joints at zero (the paper's finger: APPROACH itself)."""
    return (APPROACH[0],) + (0.0,) * (n_joints - 1)


@functools.lru_cache(maxsize=8)
def _box_scale(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(box, scale) (n,) of n = 3J unknowns: (3 N, 3 N, 100 N·mm) and (1, 1, MOMENT_SCALE) per joint."""
    return (torch.tensor(np.tile(INPUT_BOX[1:], n // 3), dtype=torch.float64),
            torch.tensor([1.0, 1.0, MOMENT_SCALE] * (n // 3), dtype=torch.float64))


def _done(r: torch.Tensor, opts: SolverOptions) -> torch.Tensor:
    """Converged mask (B,) from residual vectors r (B, 2n)."""
    n = r.shape[1] // 2
    eq = r[:, :n].reshape(-1, n // 3, 3)
    return _within(eq[..., :2].norm(dim=-1), eq[..., 2].abs() * MOMENT_SCALE, r[:, n:].abs().amax(-1) == 0, opts)


def _within(force: torch.Tensor, moment: torch.Tensor, in_box: torch.Tensor, opts: SolverOptions) -> torch.Tensor:
    """Converged mask (B,): every joint's |R_F| (B, J) N and |R_M| (B, J) N·mm within the
    tolerances, and tau in the surrogate's box (in_box (B,) bool: no out-of-box penalty)."""
    return (force.amax(-1) <= opts.tol_force) & (moment.amax(-1) <= opts.tol_moment) & in_box


def _lm_step(J: torch.Tensor, r: torch.Tensor, mu) -> torch.Tensor:
    """The damped Gauss-Newton step -(JᵀJ + mu·I)⁻¹ Jᵀ r (B, n) of J (B, m, n), r (B, m),
    mu (B,) or a number."""
    JT = J.transpose(1, 2)
    mu = torch.as_tensor(mu, dtype=J.dtype).reshape(-1, 1, 1)
    return -torch.linalg.solve(JT @ J + mu * torch.eye(J.shape[2], dtype=J.dtype), JT @ r[..., None])[..., 0]


def _levenberg_marquardt(jac_fn, x, p, opts, max_step=None, p_prev=None, prev_jac=None):
    """Batched LM from x (B, n = 3J) at pressures p (B, J).

    Returns (x, converged, iterations, (dr/dx (B, n, n), dr/dP (B, n, J)) at the final x);
    the last item is the next ramp step's ``prev_jac``, which saves one Jacobian per step.

    p_prev: the pressures at which x is an equilibrium (a ramp step). The start is then
    the tangent predictor x + dx/dP·(p - p_prev), dx/dP = -(dr/dx)⁻¹ dr/dP: it keeps the finger's geometry instead of its loads, so a pressure step does not
    push the finger deep into the object.

    max_step caps each step's largest scaled component (N, N·mm/100): with contact it
    keeps the iterates on the branch of the previous ramp step, since a long step can jump
    the finger through the object to a contact-free root."""
    n = x.shape[1]
    eye = torch.eye(n, dtype=x.dtype)
    step_scale = _box_scale(n)[1]
    x = x.clone()
    if p_prev is not None:
        J0, Jp0 = prev_jac if prev_jac is not None else (lambda a: (a[0][:, :n], a[2]))(jac_fn(x, p_prev))
        dx = -torch.linalg.solve(J0 + 1e-12 * eye, Jp0 @ (p - p_prev)[..., None])[..., 0]
        x = x + dx
    J, r, Jp = jac_fn(x, p, dp=False)    # dr/dP: at the last iterate only (below)
    mu = torch.full((x.shape[0],), 1e-6, dtype=x.dtype)
    iters = torch.zeros(x.shape[0], dtype=torch.long)
    done = _done(r, opts)
    stuck = torch.zeros_like(done)
    for _ in range(opts.max_iter):
        act = torch.nonzero(~(done | stuck)).flatten()  # work on unfinished samples only
        if act.numel() == 0:
            break
        Ja, ra, ma = J[act], r[act], mu[act]
        step = _lm_step(Ja, ra, ma)
        if max_step is not None:
            big = (step / step_scale).abs().amax(-1, keepdim=True) / max_step
            step = step / big.clamp_min(1.0)
        x_try = x[act] + step
        J_try, r_try, Jp_try = jac_fn(x_try, p[act], dp=False)
        better = r_try.pow(2).sum(-1) < ra.pow(2).sum(-1)
        x[act] = torch.where(better[:, None], x_try, x[act])
        r[act] = torch.where(better[:, None], r_try, ra)
        J[act] = torch.where(better[:, None, None], J_try, Ja)
        if Jp is not None:
            Jp[act] = torch.where(better[:, None, None], Jp_try, Jp[act])
        mu[act] = torch.where(better, (ma * 0.1).clamp_min(1e-12), ma * 10.0)
        iters[act] += 1
        done[act] = _done(r[act], opts)
        stuck = mu > 1e8
    if Jp is None and getattr(jac_fn, "dp", None) is not None:
        Jp = jac_fn.dp(x, p)
    return x, done, iters, (J[:, :n], Jp)


def _lbfgs(loss_fn, x, p, opts):
    """Paper's L-BFGS on sum_b |r_b|² from x (B, 3J). Returns (x, converged, iterations)."""
    x = x.clone().requires_grad_(True)
    opt = torch.optim.LBFGS([x], lr=1.0, max_iter=opts.lbfgs_max_iter, tolerance_grad=1e-15,
                            tolerance_change=1e-20, history_size=20, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        r = loss_fn(x, p)
        total = r.pow(2).sum()
        total.backward()
        return total

    opt.step(closure)
    x = x.detach()
    with torch.no_grad():
        r = loss_fn(x, p)
    n_iter = opt.state[opt._params[0]]["n_iter"]
    return x, _done(r, opts), torch.full((x.shape[0],), n_iter, dtype=torch.long), None


def _advance(run, x, pa, pb, cutbacks, jac=None):
    """One ramp step pa -> pb (B, J) from the equilibrium x at pa (with its Jacobians
    ``jac``, or None); samples that fail are retried as two half steps, recursively up to
    ``cutbacks`` times (as the FEM does). Returns (x, converged, iterations, jac at x)."""
    x_new, conv, its, jac_new = run(x, pb, pa, jac)
    if bool(conv.all()) or cutbacks == 0:
        return x_new, conv, its, jac_new
    bad = ~conv
    pm = 0.5 * (pa[bad] + pb[bad])
    sub = None if jac is None else tuple(a[bad] for a in jac)
    x1, c1, i1, j1 = _advance(run, x[bad], pa[bad], pm, cutbacks - 1, sub)
    x2, c2, i2, j2 = _advance(run, x1, pm, pb[bad], cutbacks - 1, j1)
    x_new, conv, its = x_new.clone(), conv.clone(), its.clone()
    x_new[bad], conv[bad], its[bad] = x2, c1 & c2, its[bad] + i1 + i2
    if jac_new is not None:
        for a, b in zip(jac_new, j2):
            a[bad] = b
    return x_new, conv, its, jac_new


def _runner(prob: GripperProblem, opts: SolverOptions):
    """The solver of one ramp step: run(x (B, n), p (B, J), p_prev=None, jac=None) ->
    (x, converged (B,), iterations (B,), Jacobians at x or None), by opts.method; with an
    object, an equilibrium deeper than opts.max_penetration counts as failed."""
    if opts.method in ("newton", "lm"):
        jac_fn = _jacobian_fn(prob, prob.obstacle is not None, opts.jacobian)  # dr/dP: the ramp's predictor
        cap = None if prob.obstacle is None else opts.contact_max_step
        method = lambda x, p, p_prev=None, jac=None: _levenberg_marquardt(  # noqa: E731
            jac_fn, x, p, opts, cap, p_prev, jac)
    else:
        method = lambda x, p, p_prev=None, jac=None: _lbfgs(_residual_fn(prob), x, p, opts)  # noqa: E731
    if prob.obstacle is None:
        return method

    def with_depth_check(x, p, p_prev=None, jac=None):
        # A step so large that the finger passes into (or through) the object finds a
        # spurious equilibrium; refuse it so that _advance cuts the step back.
        x, conv, its, jac = method(x, p, p_prev, jac)
        return x, conv & (touch(prob, x, p)[1] <= opts.max_penetration), its, jac

    return with_depth_check


def solve(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions = SolverOptions(),
          x0: torch.Tensor | None = None) -> GestureResult:
    """Equilibrium gesture of ``problem`` for a batch of pressure pairs.

    pressures: (B, J) or (J,) MPa [P1 .. PJ], |P| <= 0.3 (contract.spec.OutOfBoxError otherwise;
    ValueError for another count than the finger's J joints).
    x0: optional warm start (B, J, 3) (e.g. the NN's prediction); it disables the ramp.
    With an object the gripper first settles at ``problem.approach`` without it (when
    given), the object is brought in, and the pressures ramp to the target.
    Returns a GestureResult (see its docstring for shapes and units).
    """
    n_joints = problem.n_joints
    pressures = torch.as_tensor(pressures, dtype=torch.float64)
    if pressures.shape[-1:] != (n_joints,):
        raise ValueError(f"{pressures.shape[-1] if pressures.dim() else 1} pressures given for finger "
                         f"{problem.params.finger.name!r} of {n_joints} joints")
    pressures = pressures.reshape(-1, n_joints)
    check_pressures(pressures)
    if options.method not in ("newton", "lm", "lbfgs"):
        raise ValueError(f"unknown method {options.method!r}: use newton, lm or lbfgs")
    if out_of_reach(problem):   # nothing can touch it: the object-free gesture, at once
        res = solve(dataclasses.replace(problem, obstacle=None), pressures, options, x0)
        return dataclasses.replace(res, first_contact=torch.full_like(pressures, float("nan")),
                                   **result_labels(problem))
    t0 = time.perf_counter()
    if options.method == "newton" and problem.obstacle is None and options.jacobian != "exact":
        if x0 is None and options.max_iter >= COLD_STEPS:
            return _cold_newton(problem, pressures, options, t0)
        start = torch.zeros(len(pressures), n_joints, 3, dtype=torch.float64) if x0 is None else x0
        return newton_polish(problem, pressures, start, options, t0)[0]
    if options.method == "lbfgs":
        options = dataclasses.replace(options, tol_force=options.lbfgs_tol_force,
                                      tol_moment=options.lbfgs_tol_moment, cutbacks=0)
    kinds = attempts(problem, options)
    x, ok, iterations, first_contact = _solve_path(problem, pressures, dataclasses.replace(options, jacobian=kinds[0]),
                                                   x0)
    if len(kinds) > 1 and not bool(ok.all()):
        bad = ~ok
        xb, okb, its, fb = _solve_path(problem, pressures[bad], dataclasses.replace(options, jacobian=kinds[1]),
                                       None if x0 is None else x0.reshape(len(ok), -1)[bad])
        x[bad], ok[bad], first_contact[bad] = xb, okb, fb
        iterations[bad] += its
    return gesture_result(problem, pressures, x, ok, iterations, t0, options.method,
                          None if problem.obstacle is None else first_contact)


#: Quadratic convergence of Newton under gravity, |R_k+1| <= |R_k|² / QUADRATIC (N, N·mm):
#: from tau = 0 on 2,000 pressures the worst force went 235 -> 16.5 -> 0.023 mN -> 8e-9 mN
#: (|R_k+1| ~ |R_k|² / 12 N) and the moment 14 -> 0.16 -> 4e-5 N·mm (/ 600 N·mm). A
#: residual within sqrt(tol × QUADRATIC) therefore needs one last step, checked by the
#: answer's own residual instead of another Jacobian.
QUADRATIC = (10.0, 100.0)
NEWTON_STEPS = 8   # Newton steps before the LM takes over
NEWTON_REL_STEP = 1e-7   # forward-difference step of the Newton Jacobian (~sqrt(eps))
COLD_STEPS = 3     # the cold graph's Picard and two Newton steps (``_traced_cold_fn``)


def _bounds(options: SolverOptions) -> tuple[tuple[float, float], tuple[float, float]]:
    """(tol, gate) in (N, N·mm): the solver's tolerances and the one-step gate sqrt(tol × QUADRATIC)."""
    return ((options.tol_force, options.tol_moment),
            (math.sqrt(options.tol_force * QUADRATIC[0]), math.sqrt(options.tol_moment * QUADRATIC[1])))


def _worst(eq: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Worst joint's |R_F| N and |R_M| N·mm (B,) of residuals eq (B, J, 3)."""
    return eq[..., :2].norm(dim=-1).amax(-1), eq[..., 2].abs().amax(-1)


def _newton_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """step(x (B, n), p (B, J)) -> (x_next (B, n), R (B, J, 3) at x [N, N, N·mm], stepped
    (B,) bool, last (B,) bool): one Newton step on the equilibrium rows,

        x_next = x - (dR/dx)⁻¹ R(x),   dR/dx (B, n, n) by forward differences of R,
                                          steps NEWTON_REL_STEP × (1 N, 1 N, 100 N·mm).

    Forward, not central, differences: 1 + n residuals a row instead of 1 + 2n (half the
    arithmetic of a batch), and their ~1e-7 relative error (truncation h, round-off
    eps/h) only adds a 1e-7 contraction to Newton's quadratic one. With an object R
    includes the penalty contact, which is C1 (statics.smooth_penetration): a difference
    straddling a sample point's contact onset is off by O(h), which slows the last steps
    there, and the caller's check catches it.

    tol, gate: (N, N·mm) bounds on every joint's |R_F| and |R_M|. Where R(x) is within tol
    already, or dR/dx is singular, x_next = x (not ``stepped``); ``last``: those, and the x
    whose R(x) is within the one-step gate, whose x_next is the candidate answer."""
    n_joints, n = problem.n_joints, 3 * problem.n_joints
    h, offsets = _difference_offsets(n, NEWTON_REL_STEP, central=False)

    def step(x: torch.Tensor, p: torch.Tensor):
        B = x.shape[0]
        X = x[:, None] + offsets
        R = problem.residual(p.repeat_interleave(1 + n, 0), X.reshape(-1, n_joints, 3)).residual
        R = R.reshape(B, 1 + n, n)
        r, J = R[:, 0], (R[:, 1:] - R[:, :1]).transpose(1, 2) / h
        dx, info = torch.linalg.solve_ex(J, r[..., None])
        eq = r.reshape(B, n_joints, 3)
        force, moment = _worst(eq)
        stepped = (info == 0) & ((force > tol[0]) | (moment > tol[1]))
        last = ~stepped | ((force <= gate[0]) & (moment <= gate[1]))
        return torch.where(stepped[:, None], x - dx[..., 0], x), eq, stepped, last

    return step


def _picard_fn(problem: GripperProblem, tol: tuple[float, float]):
    """picard(x (B, n), p (B, J)) -> (x_next (B, n), moved (B,) bool): one fixed-point
    (Picard) step of a problem without an object, tau <- the loads that balance the parts
    distal to each joint at the pose of tau,

        tau_F <- tau_F - rot(-theta_i) R_F,i,   tau_M <- tau_M - R_M,i

    (Equation 1 is R_F = rot(theta_i) tau_F - F_distal, R_M = tau_M - M_distal); x_next = x
    (not ``moved``) where R(x) is within tol (N, N·mm) already. From tau = 0 it moves the
    start from the weights' full moment (~14 N·mm) to what the finger's own deflection
    changes in it (~2 N·mm), so that Newton needs two steps instead of three."""
    n_joints = problem.n_joints

    def picard(x: torch.Tensor, p: torch.Tensor):
        st = problem.residual(p, x.reshape(-1, n_joints, 3))
        r = st.residual
        force, moment = _worst(r)
        moved = (force > tol[0]) | (moment > tol[1])
        dx = torch.cat((rot(-st.pose.theta, r[..., :2]), r[..., 2:]), -1).reshape(x.shape)
        return torch.where(moved[:, None], x - dx, x), moved

    return picard


@graph_cache
def _traced_newton_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """``_newton_fn`` recorded by ``traced``: Jacobian, solve and update in one call (0.5
    ms for one query on this machine, the residual's dispatch being most of it)."""
    return traced(_newton_fn(problem, tol, gate), 3 * problem.n_joints, problem.n_joints)


@graph_cache
def _traced_cold_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """cold(x (B, n), p (B, J)) -> (x (B, n), iterations (B,), then ``_statics_fn``'s tuple
    at x): the cold solve's usual path as one recorded graph, from x = 0 a Picard step and
    two Newton steps, then the answer's statics. From tau = 0 in the box the first Newton
    step lands within the one-step gate on every one of 2,000 pressures (the committed
    surrogate and the analytic joint: 0.29 and 0.67 mN at worst), so the second is the
    last; the answer's check decides (``_cold_newton``)."""
    picard, step, statics = _picard_fn(problem, tol), _newton_fn(problem, tol, gate), _statics_fn(problem)

    def cold(x: torch.Tensor, p: torch.Tensor):
        x, moved = picard(x, p)
        x, _, first, _ = step(x, p)
        x, _, second, _ = step(x, p)
        return (x, moved.long() + first + second) + statics(x, p)

    return traced(cold, 3 * problem.n_joints, problem.n_joints)


@graph_cache
def _traced_warm_fn(problem: GripperProblem, tol: tuple[float, float], gate: tuple[float, float]):
    """warm(x0 (B, n), p (B, J)) -> (x (B, n), stepped (B,) bool, R(x0) (B, J, 3), then
    ``_statics_fn``'s tuple at x): ``newton_polish``'s usual path as one recorded graph,
    a Newton step from a warm start (a network's tau) and the answer's statics: one call
    where a step and a statics graph took two, with their Python around them."""
    step, statics = _newton_fn(problem, tol, gate), _statics_fn(problem)

    def warm(x: torch.Tensor, p: torch.Tensor):
        x, r0, stepped, _ = step(x, p)
        return (x, stepped, r0) + statics(x, p)

    return traced(warm, 3 * problem.n_joints, problem.n_joints)


def meets_tolerances(res: GestureResult, x: torch.Tensor, options: SolverOptions) -> torch.Tensor:
    """The solver's convergence rule on the rows of a result at unknowns x (B, 3J): (B,)
    bool, every joint's residual within options' tolerances and x in the surrogate's box."""
    return _within(res.residual_force_mN / 1e3, res.residual_moment_Nmm,
                   (x.abs() <= _box_scale(x.shape[1])[0]).all(-1), options)


def _checked(problem, pressures, x, iterations, options, t0, fallback, statics=None) -> GestureResult:
    """The GestureResult at x (B, n) checked at the solver's tolerances (tau in the box,
    every joint's residual within tol_force and tol_moment), the check inside ``time_ms``;
    the rows it refuses (B,) bool are replaced by ``fallback(rows)``, a GestureResult of
    those rows whose iterations are added to the ``iterations`` (B,) they took here."""
    res = gesture_result(problem, pressures, x, torch.ones(len(x), dtype=torch.bool), iterations, t0, "newton",
                         None, statics)
    t_check = time.perf_counter()   # the check is part of the answer's time
    res.converged = meets_tolerances(res, x, options)
    bad = ~res.converged
    res.time_ms += 1e3 * (time.perf_counter() - t_check)
    if bool(bad.any()):
        more = fallback(bad)
        more.iterations += iterations[bad]
        res = res.with_rows(bad, more)
        res.time_ms = 1e3 * (time.perf_counter() - t0)
    return res


def _cold_newton(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, t0: float) -> GestureResult:
    """``solve``'s default without an object, from tau = 0: the one graph of
    ``_traced_cold_fn`` (Picard, two Newton steps, the statics), then the check; rows it
    refuses go on with Newton steps from where they are, then the LM (``_newton_then_lm``)."""
    B, n_joints = pressures.shape
    with torch.inference_mode():
        x, iterations, *out = _traced_cold_fn(problem, *_bounds(options))(
            torch.zeros(B, 3 * n_joints, dtype=torch.float64), pressures)
        st = _as_statics(problem, out)
    x, iterations = x.clone(), iterations.clone()

    rest = dataclasses.replace(options, max_iter=options.max_iter - COLD_STEPS)
    return _checked(problem, pressures, x, iterations, options, t0,
                    lambda bad: _newton_then_lm(problem, pressures[bad], x[bad], rest, t0, NEWTON_STEPS), st)


def newton_polish(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor,
                  options: SolverOptions = SolverOptions(), t0: float | None = None) -> tuple[GestureResult, torch.Tensor]:
    """Newton without an object from x0 (a network's tau: the gravity NN's polish; ``solve``
    with x0): the first Newton step and the statics of its answer in one recorded graph
    (``_traced_warm_fn``), checked by that answer's own residual at the solver's
    tolerances (``_checked``): from the gravity NN's tau (~0.2 mN) the one step is the
    answer, from a start within the tolerances no step is taken. Samples the check refuses
    (a start outside the one-step gate, a singular Jacobian, out of the box) go on from
    their iterate with up to NEWTON_STEPS - 1 more steps and the LM (``_newton_then_lm``);
    ``iterations`` counts them all.

    pressures (B, J) MPa; x0 (B, J, 3) [N, N, N·mm]; t0: perf_counter time the caller's
    query began (default: now), for ``time_ms``. Returns (GestureResult, the residual at x0
    (B, J, 3) N, N, N·mm: the start's own, from the step's pass)."""
    if problem.obstacle is not None:
        raise ValueError("newton_polish is for the smooth residual without an object: use solve(..., x0=)")
    t0 = time.perf_counter() if t0 is None else t0
    B, n_joints = pressures.shape
    if options.max_iter < 1:   # no step allowed: the start's own check
        return _newton_then_lm(problem, pressures, x0.reshape(B, -1).double(), options, t0, 0), \
            problem.residual(pressures, x0.reshape(B, n_joints, 3)).residual
    with torch.inference_mode():
        x, stepped, r0, *out = _traced_warm_fn(problem, *_bounds(options))(x0.reshape(B, -1).double(), pressures)
        st = _as_statics(problem, out)
    x, iterations, r0 = x.clone(), stepped.long(), r0.clone()

    rest = dataclasses.replace(options, max_iter=options.max_iter - 1)
    return _checked(problem, pressures, x, iterations, options, t0,
                    lambda bad: _newton_then_lm(problem, pressures[bad], x[bad], rest, t0, NEWTON_STEPS - 1), st), r0


def _newton_then_lm(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor, options: SolverOptions,
                    t0: float, steps: int) -> GestureResult:
    """Up to ``steps`` Newton steps from x0 (B, 3J) (``newton_iterate``), the last iterate
    checked (``_checked``), and the LM from the iterate of the samples it refuses within what
    is left of ``options.max_iter`` (NaN when nothing is): the rows that one recorded step
    did not finish (``newton_polish``, ``_cold_newton``)."""
    n_joints = pressures.shape[1]
    x, iterations, _ = newton_iterate(problem, pressures, x0.reshape(-1, n_joints, 3), options, steps)

    def fallback(bad):   # the LM's answer within the rest of max_iter, or NaN
        budget = options.max_iter - int(iterations[bad].max())
        if budget <= 0:
            return gesture_result(problem, pressures[bad], x[bad], torch.zeros(int(bad.sum()), dtype=torch.bool),
                                  torch.zeros_like(iterations[bad]), t0, "newton", None)
        return solve(problem, pressures[bad], dataclasses.replace(options, method="lm", max_iter=budget),
                     x0=x[bad].reshape(-1, n_joints, 3))

    return _checked(problem, pressures, x, iterations, options, t0, fallback)


def newton_iterate(problem: GripperProblem, pressures: torch.Tensor, x0: torch.Tensor,
                   options: SolverOptions = SolverOptions(),
                   steps: int | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Full Newton steps from x0, x_k+1 = x_k - (dR/dx)⁻¹ R(x_k) (``_traced_newton_fn``),
    each sample until R(x_k) is within the one-step gate sqrt(tol × QUADRATIC), at most
    min(steps (default NEWTON_STEPS), options.max_iter) steps; nothing is checked here: the
    caller checks the last iterate (``_newton_then_lm``; with an object, predictor.nn's
    branch check, since undamped steps can land on another equilibrium).

    pressures (B, J) MPa; x0 (B, J, 3) [N, N, N·mm]. Returns (x (B, 3J), Newton steps taken
    (B,) long, the residual at x0 (B, J, 3) from the first step's pass)."""
    B, n_joints = pressures.shape
    step = _traced_newton_fn(problem, *_bounds(options))
    x = x0.reshape(B, -1).double().clone()
    iterations = torch.zeros(B, dtype=torch.long)
    active, r0 = torch.arange(B), None
    with torch.inference_mode():
        for _ in range(max(min(NEWTON_STEPS if steps is None else steps, options.max_iter), 0)):
            every = len(active) == B
            x_next, r, stepped, last = step(x if every else x[active], pressures if every else pressures[active])
            r0 = r if r0 is None else r0
            if every:
                x = x_next
            else:
                x[active] = x_next
            iterations[active] += stepped
            if bool(last.all()):
                break
            active = active[~last]
    x, iterations = x.clone(), iterations.clone()   # leave inference mode
    r0 = problem.residual(pressures, x0.reshape(B, n_joints, 3)).residual if r0 is None else r0.clone()
    return x, iterations, r0


def newton_step(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """One full Gauss-Newton step tau - (JᵀJ)⁻¹Jᵀr with the exact Jacobian
    (``_autograd_jacobian``), no damping, cap or check: pressures (B, J) MPa, tau (B, J, 3)
    -> (B, J, 3). For measuring what a closed-form step does to a network's tau
    (predictor.nn.evaluate_contact), not an answer."""
    B, n_joints = pressures.shape
    J, r, _ = _autograd_jacobian(_residual_fn(problem))(tau.reshape(B, -1), pressures)
    return (tau.reshape(B, -1) + _lm_step(J, r, 1e-12)).reshape(B, n_joints, 3).detach()


def attempts(problem: GripperProblem, options: SolverOptions) -> tuple[str, ...]:
    """The Jacobians a Newton solve tries in turn (``_jacobian_fn`` kinds). ``auto`` with
    an object: central differences of the traced residual first (cheaper per call for a
    few samples: the bench's contact gesture went from 693 to 208 ms), then the exact one
    for the samples that failed (a difference that straddles a kink of the contact law can
    stall LM: a three-joint grasp did). Both end at the same equilibria (tested on the
    three objects' holds, slips and misses)."""
    if options.method in ("newton", "lm") and options.jacobian == "auto" and problem.obstacle is not None:
        return ("differences", "exact")
    return (options.jacobian,)


def _solve_path(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0):
    """solve's path (approach, ramp, or from x0) with one kind of Jacobian: (x (B, 3J),
    converged (B,), iterations (B,), first contact (B, J) MPa)."""
    B, n_joints = pressures.shape
    run, run_free = _runner(problem, options), _runner(dataclasses.replace(problem, obstacle=None), options)
    # Intermediate ramp steps only need to stay on the branch: a 100x looser tolerance
    # saves the last (quadratic) Newton iteration of each; the final step uses the full one.
    loose = dataclasses.replace(options, tol_force=100 * options.tol_force, tol_moment=100 * options.tol_moment)
    run_loose = _runner(problem, loose)
    n = 3 * n_joints
    x = torch.zeros(B, n, dtype=torch.float64) if x0 is None else x0.reshape(B, n).double().clone()
    iterations = torch.zeros(B, dtype=torch.long)
    ok = torch.ones(B, dtype=torch.bool)
    first_contact = torch.full((B, n_joints), float("nan"), dtype=torch.float64)

    def record_contact(x, p):
        # One contact evaluation per ramp step (no iterate changes): the first pressures
        # at which the finger touches the object, for grasp planning (predictor.atlas).
        new = (touch(problem, x, p)[0] > 0) & first_contact[:, 0].isnan()
        first_contact[new] = p[new]

    if problem.obstacle is None or x0 is not None:
        x, ok, iterations, _ = run(x, pressures)
        if problem.obstacle is not None:
            record_contact(x, pressures)
    else:
        start = problem.approach
        p0 = (torch.zeros_like(pressures) if start is None else
              torch.as_tensor(start, dtype=torch.float64).expand(B, n_joints))
        if start is not None:  # approach: open without the object, then bring it in
            x, ok, iterations, _ = run_free(x, p0)
        record_contact(x, p0)
        jac = None
        beat = Heartbeat("solve")   # a hard ramp (cut-backs on every step) can take tens of seconds
        for k in range(1, options.ramp_steps + 1):
            beat(lambda: f"ramp step {k} of {options.ramp_steps}, {int(ok.sum())} of {B} on track")
            pa = p0 + (pressures - p0) * ((k - 1) / options.ramp_steps)
            pb = p0 + (pressures - p0) * (k / options.ramp_steps)
            step_run = run if k == options.ramp_steps else run_loose
            x, conv, its, jac = _advance(step_run, x, pa, pb, options.cutbacks, jac)
            ok &= conv
            iterations += its
            record_contact(x, pb)
    return x, ok, iterations, first_contact


def gesture_result(problem: GripperProblem, pressures: torch.Tensor, x: torch.Tensor, ok: torch.Tensor,
                   iterations: torch.Tensor, t0: float, method: str,
                   first_contact: torch.Tensor | None, statics: Statics | None = None) -> GestureResult:
    """The GestureResult of solved unknowns x (B, 3J) at pressures (B, J) MPa: residual,
    contact and pose at x (``statics``, when the caller has them already), NaN where ok
    (B,) is False; time_ms from perf_counter t0 up to the answer."""
    B, n_joints = pressures.shape
    with torch.no_grad():
        tau = x.reshape(B, n_joints, 3)
        st = statics_at(problem, pressures, tau) if statics is None else statics
    force, moment = residual_norms(st.residual)
    every = bool(ok.all())   # nothing to mask (the usual case: saves ~0.1 ms a query)
    tau, pose = (tau, st.pose) if every else (nan_unless(ok, tau), st.pose.masked(ok))
    return GestureResult(
        pressures=pressures, tau=tau, converged=ok, residual_force_mN=force, residual_moment_Nmm=moment,
        normal_force_N=st.contact.normal, friction_N=st.contact.friction, friction_ratio=st.contact.ratio,
        slip=st.contact.slip, iterations=iterations, time_ms=1e3 * (time.perf_counter() - t0), pose=pose,
        method=method, first_contact=first_contact, **result_labels(problem),
    )


def result_labels(problem: GripperProblem) -> dict:
    """The GestureResult fields that name what was solved: joint, mu, object_weight_N."""
    has = problem.obstacle is not None
    weight = problem.params.object_weight if problem.gravity else 0.0
    return {"joint": problem.joint.name, "mu": problem.contact.mu if has else None,
            "object_weight_N": weight if has else None}
