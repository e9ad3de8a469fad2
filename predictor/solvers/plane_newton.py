"""The fingers pressed on each other at X = 0 by a contact-constrained Newton: the plane's
penalty root (statics.plane_contact) found from a start that crosses X = 0 in a handful of
smooth Newton steps, instead of the LM in the penalty's narrow valley (predictor.solvers.ramp's
homotopy).

The stiff penalty (k_p = 200 N/mm per mm, force ~ overlap³ within the smoothing width at
a corner of the outline) makes |r|² a narrow valley whose floor the LM creeps along; the
equilibrium it holds is, to ~0.05 mm, that of the outline held ON X = 0. So:

1. **Active-set KKT Newton.** The plane's vertices (those of the inner and end edges,
   ChainLayout.plane_edges) in the active set A are held at X_v = -s by a normal force
   lambda_v (N, along +X), the others are free (lambda_v = 0). With r0(x) the residual without
   the plane (statics.apart) and a force lambda_v at vertex v of part k_v entering the
   balances of the joints i proximal to it (m_iv = 1 where k_v > the part of joint i):

       R_F,i = r0_F,i - sum_v m_iv (lambda_v, 0)                                  [N]
       R_M,i = r0_M,i + sum_v m_iv lambda_v (Y_v - e_y,i)                          [N·mm]
       X_v(x) + s = 0 (v in A),   lambda_v = 0 (v not in A)

   e_i the distal end r_10 of joint i (statics.GripperProblem.residual's moment arms).
   Unknowns z = (x (3J), lambda (Vp)), one Newton step solves the (3J + Vp) system with
   dR/dx and dX/dx by central differences (``kkt_jacobian``); the rest is smooth (the
   surrogate and the chain), so Newton converges quadratically from a start far across
   X = 0. After every step the active set changes: the vertices whose force pulls
   (lambda_v < 0) are released, the deepest free vertex across X = -s by more than
   ADD_TOL is added (one a step), as a primal-dual active set.
2. **The penalty's overlap.** Where that converged with s = 0 the outline touches X = 0;
   the penalty needs an overlap s for its force: the rigid shift s of the outline whose
   penalty force equals sum_v lambda_v (``penalty_shift``, a few secant steps on
   log F(log s)), then KKT steps with X_v = -s.
3. **Polish.** Full Newton steps on the penalty residual from there (``penalty_newton``):
   the start lies in the penalty's basin, at its overlap, and they converge to the
   penalty's own root in 1-4 steps where a corner presses, ~40 where an edge lies nearly
   flat on X = 0 (linearly, ~0.7 a step: (0.3, 0.0) MPa on the production surrogate); then
   the stiff plane's LM with the ramp's checks (predictor.solvers.ramp.runner), which takes no
   step where they converged.
4. **Its own ramp.** Where the KKT from the start fails (tau = 0 far across X = 0: the
   first vertex it holds is not the one that touches), ``kkt_path`` follows the pressures
   from zero in a few legs, each KKT from the last one's answer.

It reaches the roots the ramp and its homotopy reach, in far fewer iterations (the figures
against the ramp: docs/gripper.md §9, docs/decisions.md §11).

A sample whose KKT does not converge (or whose polish fails) is reported as not converged:
the caller falls back to the ramp and its homotopy (predictor.solvers.ramp). Units: x (B, 3J) = (F1 N, F2 N,
M N·mm) per joint; pressures (B, J) MPa; lambda N; X, Y, s mm.
"""
from __future__ import annotations

import functools
import math

import torch

from predictor.solvers.graphs import graph_cache, traced
from predictor.model.gripper import ChainLayout, outline_vertices
from predictor.solvers.jacobians import difference_offsets, jacobian_fn
from predictor.solvers.lm import within
from predictor.solvers.options import SolverOptions
from predictor.model.statics import MOMENT_SCALE, GripperProblem, apart, plane_contact, scaled

#: KKT Newton steps at most (each one residual batch of 1 + 2n rows a sample).
KKT_STEPS = 16
#: A free vertex deeper than this across X = -s (mm) joins the active set.
ADD_TOL = 1e-6
#: KKT convergence: every joint's scaled residual (N, N·mm/100) and every active vertex's
#: X + s (mm) within these, and the active set unchanged by the step.
KKT_TOL = (1e-9, 1e-9)
#: Central-difference step of the KKT Jacobian, relative to (1 N, 1 N, 100 N·mm).
REL_STEP = 1e-6
#: Secant steps of ``penalty_shift``.
SHIFT_STEPS = 8
#: Newton steps on the penalty residual from the KKT's answer (3-6 where one corner
#: presses, ~45 where an edge lies flat on X = 0: (0.3, 0.0) MPa on the production model).
NEWTON_POLISH = 60
#: LM iterations of the stiff plane's polish after them (its checks; none where they converged).
POLISH_ITER = 12


@functools.lru_cache(maxsize=16)
def plane_vertex_layout(layout: ChainLayout) -> tuple[torch.Tensor, torch.Tensor]:
    """(index (Vp,) long, mask (J, Vp) float64): the outline vertices of the plane's edges
    (ChainLayout.plane_edges) and, for each, 1.0 where a force on it enters joint i's
    balance (its part is distal to joint i's part)."""
    with torch.inference_mode(False):
        edges = layout.plane_edges
        ends = torch.cat((layout.edge_start.index_select(0, edges), layout.edge_end.index_select(0, edges)))
        parts = torch.cat((layout.edge_part.index_select(0, edges),) * 2)
        index, first = [], {}
        for v, k in zip(ends.tolist(), parts.tolist()):
            if v not in first:
                first[v] = k
                index.append(v)
        mask = torch.tensor([[float(first[v] > jp) for v in index] for jp in layout.joint_parts],
                            dtype=torch.float64)
        return torch.tensor(index, dtype=torch.long), mask


def constrained_fn(problem: GripperProblem):
    """g(x (B, 3J), p (B, J)) -> (r0 (B, 3J) the scaled equilibrium residual without the
    plane, X (B, Vp) and Y (B, Vp) mm of the plane's vertices, e_y (B, J) mm the joints'
    distal ends): what the KKT residual (``kkt_residual``) is made of."""
    free, layout = apart(problem), problem.params.layout
    index, _ = plane_vertex_layout(layout)
    n_joints = problem.n_joints

    def g(x: torch.Tensor, p: torch.Tensor):
        st = free.residual(p, x.reshape(-1, n_joints, 3))
        V = st.vertices if st.vertices is not None else outline_vertices(st.pose, layout)
        Vp = V.index_select(1, index)
        return scaled(st.residual), Vp[..., 0], Vp[..., 1], st.pose.joints[:, :, -1, 1]

    return g


@graph_cache
def traced_constrained_fn(problem: GripperProblem):
    """``constrained_fn`` recorded by ``traced`` (one per problem)."""
    return traced(constrained_fn(problem), 3 * problem.n_joints, problem.n_joints)


def plane_loads(lam: torch.Tensor, Y: torch.Tensor, ends_y: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """The scaled residual (B, 3J) of forces lam (B, Vp) N along +X at the plane's vertices
    of height Y (B, Vp) mm (module docstring): per joint -sum m lam on R_Fx, 0 on R_Fy,
    sum m lam (Y - e_y) / MOMENT_SCALE on R_M."""
    force = lam @ mask.T                                         # (B, J)
    moment = (lam * Y) @ mask.T - force * ends_y
    return torch.stack((-force, torch.zeros_like(force), moment / MOMENT_SCALE), -1).flatten(1)


def kkt_residual(g_out, lam: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """R (B, 3J) of the KKT system (module docstring) from ``constrained_fn``'s outputs."""
    r0, _, Y, ends_y = g_out
    return r0 + plane_loads(lam, Y, ends_y, mask)


def kkt_jacobian(g, x: torch.Tensor, p: torch.Tensor, lam: torch.Tensor, mask: torch.Tensor):
    """At x (B, n), p (B, J) with forces lam (B, Vp): (R (B, n), X (B, Vp), dR/dx (B, n, n),
    dR/dlam (B, n, Vp), dX/dx (B, Vp, n)), the x-derivatives by central differences of one
    batch of 1 + 2n rows a sample (REL_STEP), dR/dlam exactly (R is linear in lam)."""
    B, n = x.shape
    h, offsets = difference_offsets(n, REL_STEP)
    rows = 1 + 2 * n
    with torch.inference_mode():
        r0, X, Y, ey = g((x[:, None] + offsets).reshape(-1, n), p.repeat_interleave(rows, 0))
    lam_r = lam.repeat_interleave(rows, 0)
    R = (r0 + plane_loads(lam_r, Y, ey, mask)).reshape(B, rows, n)
    X = X.reshape(B, rows, -1)
    dR = (R[:, 1:1 + n] - R[:, 1 + n:]).transpose(1, 2) / (2 * h)
    dX = (X[:, 1:1 + n] - X[:, 1 + n:]).transpose(1, 2) / (2 * h)
    Y0, ey0 = Y.reshape(B, rows, -1)[:, 0], ey.reshape(B, rows, -1)[:, 0]
    # plane_loads of a unit force at each vertex, (B, J, 3, Vp) -> (B, 3J, Vp)
    force = mask.expand(B, -1, -1)
    moment = force * (Y0[:, None, :] - ey0[:, :, None]) / MOMENT_SCALE
    dlam = torch.stack((-force, torch.zeros_like(force), moment), 2).reshape(B, n, -1)
    return R[:, 0].clone(), X[:, 0].clone(), dR.clone(), dlam, dX.clone()


def kkt_step(R, X, dR, dlam, dX, lam, active, shift):
    """The Newton step (dx (B, n), new lam (B, Vp)) of the KKT system at the current set
    ``active`` (B, Vp) bool: rows dR dx + dlam·lam_new = -R + dlam·lam, and per vertex
    dX dx = -(X + shift) (active) or lam_new = 0 (free). NaN where singular."""
    B, n = dR.shape[:2]
    Vp = lam.shape[1]
    act = active.to(dR.dtype)
    top = torch.cat((dR, dlam), 2)
    bottom = torch.cat((dX * act[..., None], torch.diag_embed(1.0 - act)), 2)
    K = torch.cat((top, bottom), 1)
    rhs = torch.cat((-R + (dlam @ lam[..., None])[..., 0], -(X + shift[:, None]) * act), 1)
    z, info = torch.linalg.solve_ex(K, rhs[..., None])
    z = torch.where((info == 0)[:, None, None], z, float("nan"))[..., 0]
    return z[:, :n], z[:, n:]


def update_active(active, lam, X, shift):
    """The next active set (B, Vp) bool: those with lam <= 0 released, then the deepest
    free vertex with X < -shift - ADD_TOL added (one per sample); and (B,) bool whether it
    changed."""
    new = active & (lam > 0)
    depth = torch.where(new, -math.inf, -(X + shift[:, None]))
    deepest = depth.argmax(-1)
    add = depth.gather(1, deepest[:, None])[:, 0] > ADD_TOL
    new = new.clone()
    new[add, deepest[add]] = True
    return new, (new != active).any(-1)


def penalty_shift(problem: GripperProblem, vertices: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
    """s (B,) mm, the shift along -X of the outline ``vertices`` (B, V, 2) mm, touching X = 0,
    at which the plane's penalty force (statics.plane_contact) equals ``force`` (B,) N:
    secant steps on log F against log s from the smoothing width (F ~ s³ within it at a
    corner), SHIFT_STEPS at most; 0 where force <= 0."""
    params, contact = problem.params, problem.contact
    ex = torch.tensor([1.0, 0.0], dtype=vertices.dtype)

    def F(s):
        return plane_contact(None, params, contact, vertices - s[:, None, None] * ex).force

    s0 = torch.full_like(force, contact.smoothing)
    f0 = F(s0)
    q = torch.full_like(force, 3.0)
    pos = (force > 0) & (f0 > 0)
    target = torch.where(pos, force, 1.0).log()
    s0, f0 = s0, torch.where(pos, f0, 1.0)
    for _ in range(SHIFT_STEPS):
        s1 = (s0.log() + (target - f0.log()) / q).exp()
        f1 = torch.where(pos, F(s1), 1.0).clamp_min(1e-300)
        slope = (f1.log() - f0.log()) / (s1.log() - s0.log())
        q = torch.where((s1 - s0).abs() > 1e-15 * s0, slope, q).clamp(1.0, 6.0)
        s0, f0 = s1, f1
        if bool(((f1.log() - target).abs() < 1e-10).all()):
            break
    return torch.where(pos, s0, 0.0)


def kkt_solve(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor, steps: int = KKT_STEPS):
    """The KKT of the plane held by forces (module docstring 1-2) from x (B, n) at p (B, J):
    (x (B, n), lam (B, Vp) N, shift (B,) mm, converged (B,), Newton steps (B,)). The start's
    vertices across X = 0 (the deepest) begin the active set."""
    g = traced_constrained_fn(problem)
    _, mask = plane_vertex_layout(problem.params.layout)
    B, n = x.shape
    x = x.clone()
    lam = torch.zeros(B, mask.shape[1], dtype=x.dtype)
    shift = torch.zeros(B, dtype=x.dtype)
    active = torch.zeros(B, mask.shape[1], dtype=torch.bool)
    done = torch.zeros(B, dtype=torch.bool)
    shifted = torch.zeros(B, dtype=torch.bool)
    failed = torch.zeros(B, dtype=torch.bool)
    steps_taken = torch.zeros(B, dtype=torch.long)
    for k in range(steps + 1):
        on = (~done).nonzero().flatten()
        if not len(on):
            break
        R, Xo, dR, dlam, dX = kkt_jacobian(g, x[on], p[on], lam[on], mask)
        # the set at this x: the last step's pulling forces released, the deepest free
        # vertex across added (at the start: the deepest across X = 0)
        act, changed = update_active(active[on], lam[on], Xo, shift[on])
        active[on] = act
        # converged at an unchanged set: residual and constraints met
        met = (~changed & (R.abs().amax(-1) <= KKT_TOL[0])
               & torch.where(act, (Xo + shift[on, None]).abs(), 0.0).le(KKT_TOL[1]).all(-1))
        if bool(met.any()):
            # the touching solution found: give the penalty its overlap, once, then go on
            first = met & ~shifted[on]
            if bool(first.any()):
                rows = on[first]
                V = _vertices(problem, x[rows], p[rows])
                shift[rows] = penalty_shift(problem, V, lam[rows].sum(-1))
                shifted[rows] = True
            fin = met & ~first
            done[on[fin]] = True
            keep = ~fin
            on = on[keep]
            if not len(on):
                break
            R, Xo, dR, dlam, dX = (t[keep] for t in (R, Xo, dR, dlam, dX))
        if k == steps:   # out of steps: not converged
            break
        dx, lam_new = kkt_step(R, Xo, dR, dlam, dX, lam[on], active[on], shift[on])
        ok = dx.isfinite().all(-1) & lam_new.isfinite().all(-1)
        failed[on[~ok]] = True     # a singular system (an over-constrained set): the caller's fallback
        done[on[~ok]] = True
        steps_taken[on] += 1
        x[on[ok]] = x[on[ok]] + dx[ok]
        lam[on[ok]] = lam_new[ok]
    converged = done & shifted & ~failed & x.isfinite().all(-1)
    return x, lam, shift, converged, steps_taken


def _vertices(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """The outline's vertices (B, V, 2) mm at x (B, n), p (B, J)."""
    with torch.no_grad():
        pose = problem.pose(p, x.reshape(len(x), -1, 3), face_points=False)
        return outline_vertices(pose, problem.params.layout)


def kkt_path(problem: GripperProblem, x: torch.Tensor, p0: torch.Tensor, p: torch.Tensor, legs: int = 1):
    """``kkt_solve`` along the straight path p0 -> p (B, J) in ``legs`` equal legs, each from
    the previous leg's answer (the KKT is smooth in the pressures, so a leg's start lies in
    its Newton basin where a start far across X = 0 may not): (x (B, n), converged (B,),
    Newton steps (B,)); a sample stops at the first leg it fails."""
    B = len(x)
    ok = torch.ones(B, dtype=torch.bool)
    its = torch.zeros(B, dtype=torch.long)
    x = x.clone()
    for k in range(1, legs + 1):
        on = ok.nonzero().flatten()
        if not len(on):
            break
        pk = p0[on] + (p[on] - p0[on]) * (k / legs)
        x[on], _, _, ok[on], steps = kkt_solve(problem, x[on], pk)
        its[on] += steps
    return x, ok, its


def penalty_newton(problem: GripperProblem, p: torch.Tensor, x: torch.Tensor, options: SolverOptions):
    """Full Newton steps x <- x - (dr/dx)⁻¹ r on the penalty residual's equilibrium rows
    from x (B, n) at p (B, J), dr/dx by central differences (predictor.jacobians: forward
    ones are too coarse for the stiff penalty, and Newton diverged with them), each sample
    until its residual is within the tolerances (predictor.lm.within), NEWTON_POLISH steps
    at most, or a singular system: (x (B, n), steps (B,))."""
    jac = jacobian_fn(problem, False, "differences")
    n = x.shape[1]
    x = x.clone()
    steps = torch.zeros(len(x), dtype=torch.long)
    on = torch.arange(len(x))
    for _ in range(NEWTON_POLISH + 1):
        J, r, _ = jac(x[on], p[on], dp=False)
        eq = r[:, :n].reshape(len(on), -1, 3)
        done = within(eq[..., :2].norm(dim=-1), eq[..., 2].abs() * MOMENT_SCALE, r[:, n:].abs().amax(-1) == 0, options)
        dx, info = torch.linalg.solve_ex(J[:, :n], r[:, :n, None])
        go = ~done & (info == 0) & dx[..., 0].isfinite().all(-1) & (steps[on] < NEWTON_POLISH)
        on = on[go]
        if not len(on):
            break
        x[on] = x[on] - dx[go, :, 0]
        steps[on] += 1
    return x, steps


def plane_newton(problem: GripperProblem, options: SolverOptions, polish):
    """The step solver run(x, p, p_prev=None, jac=None, p0=None, legs=1) -> (x, converged
    (B,), iterations (B,), Jacobians or None) (predictor.solvers.ramp.homotopy's signature) of
    ``problem`` where the fingers meet: ``kkt_path`` from x at p0 (default p: x need not
    be an equilibrium; p_prev and jac are unused, the KKT needs no predictor), then
    ``penalty_newton`` (full steps: the LM's merit test refuses the step that leaves the
    contact of an edge lying nearly flat on X = 0, and then creeps), then ``polish`` from
    there (a step solver of the stiff plane: predictor.solvers.ramp's LM with its checks and depth
    check, POLISH_ITER iterations, none where the Newton steps converged); converged only
    where the KKT and the polish are. iterations: the KKT's Newton steps, the penalty's and the polish's."""

    def run(x, p, p_prev=None, jac=None, p0=None, legs=1):
        xk, ok, its = kkt_path(problem, x, p if p0 is None else p0, p, legs)
        B = len(x)
        conv = torch.zeros(B, dtype=torch.bool)
        jac_new = None
        x_out = xk.clone()
        if bool(ok.any()):
            rows = ok.nonzero().flatten()
            xn, steps = penalty_newton(problem, p[rows], xk[rows], options)
            xn = torch.where(xn.isfinite().all(-1, keepdim=True), xn, xk[rows])
            xp, cp, ip, jp = polish(xn, p[rows])
            x_out[rows], conv[rows] = xp, cp
            its = its.clone()
            its[rows] += steps + ip
            if jp is not None:
                # the converged rows' Jacobians at their answers, also when some rows failed
                # (theirs zero: the caller retries them, and its retry's Jacobians replace
                # them), so that a row of a batch continues as it does alone
                jac_new = jp if len(rows) == B else tuple(
                    torch.zeros((B,) + a.shape[1:], dtype=a.dtype).index_copy(0, rows, a) for a in jp)
        return x_out, conv, its, jac_new

    return run
