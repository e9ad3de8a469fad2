"""The pressure ramp of a solve with contact: the pressures go from 0 (or the approach
gesture) to the target in ``ramp_steps`` sub-steps (``solve_path``, ``ramp``), each
solved by the method's ``runner`` from the tangent predictor and halved on failure
(``advance``), since the grasp depends on the pressure history. Where the shortest
step still fails the finger's contact branch has ended (a fold: a fingertip pressing on
the object slides off it), and the finger snaps off the object (``snap_off``).
``attempts``: the Jacobians tried in turn.

Two contacts make a history: the object (every solve with one ramps), and the symmetry
plane X = 0 where the two fingers meet (statics.plane_contact). Without an object the
gesture is first solved directly (``free_path``), and only where that fails or ends with
the outline across X = 0 deeper than max_penetration (it started from tau = 0, whose
load-free pose can lie far across the plane) the plane's path takes over (``plane_ramp``):
the contact-constrained Newton (predictor.solvers.plane_newton: the outline held on X = 0 by
forces, then the penalty's own root) at the target, then along its own short ramp, and only
where both fail the pressures are ramped from zero with the stiff LM and the homotopy, so
that the fingers close until they meet. Within a ramp step the same Newton comes between
the stiff LM and the softer planes (``homotopy``).

Unknowns x (B, 3J) = (F1 N, F2 N, M N·mm) per joint; pressures (B, J) MPa.
"""
from __future__ import annotations

import dataclasses

import torch

from contract.grasp import APPROACH_P1
from predictor.solvers.graphs import graph_cache, residual_fn, traced
from predictor.model.gripper import outline_vertices
from predictor.solvers.jacobians import jacobian_fn
from predictor.solvers.lm import SHORTENINGS, lbfgs, levenberg_marquardt
from predictor.solvers.options import SolverOptions
from predictor.solvers.plane_newton import POLISH_ITER, plane_newton
from predictor.solvers.progress import Heartbeat
from predictor.model.statics import GripperProblem, contact_loads, meets, plane_overlap


# Default grasp approach gesture (MPa): open joint 1, bring the object in (statics.Obstacle).
APPROACH = (APPROACH_P1, 0.0)


def approach_for(n_joints: int) -> tuple[float, ...]:
    """The default approach gesture of an n-joint finger: joint 1 opened as APPROACH's,
    the other joints at zero (the paper's finger: APPROACH itself)."""
    return (APPROACH[0],) + (0.0,) * (n_joints - 1)


def ramp_method(options: SolverOptions) -> str:
    """The method that answers on this path (the ``method`` of its results): "lm" for
    options.method newton or lm (Newton's own steps are predictor.solvers.newton's, without an
    object), "lbfgs" for lbfgs."""
    return "lbfgs" if options.method == "lbfgs" else "lm"


#: The plane stiffness factors of the homotopy a failed step retries through (``homotopy``):
#: from 1/1000 of k_p, whose equilibria lie ~10x deeper across X = 0 (the penalty grows
#: with the cube of a vertex's overlap inside the smoothing width), the basin of each stage
#: holds the next one's root (a 0.15 MPa step pressed on the plane converges through it in
#: 20-50 LM iterations; the stiff plane alone stalls or needs cut-backs).
PLANE_HOMOTOPY = (0.001, 0.01, 0.1)
#: LM iterations of the stiff plane's first try before ``homotopy`` takes over the samples
#: whose finger then crosses X = 0: a step pressed on the plane that converges does so in
#: ~5-10; one that has not by then stalls in the penalty's narrow valley. A sample apart
#: from the plane goes on (the plane adds nothing there).
STIFF_TRY = 10
#: Legs of the KKT's own ramp from zero pressure (predictor.solvers.plane_newton.kkt_path) where
#: its solve at the target from tau = 0 fails (a start far across X = 0).
KKT_LEGS = 4


def softened(problem: GripperProblem, factor: float) -> GripperProblem:
    """``problem`` with the plane X = 0's stiffness k_p times ``factor``."""
    return dataclasses.replace(problem, contact=dataclasses.replace(
        problem.contact, plane_stiffness=problem.contact.plane_stiffness * factor))


def homotopy(prob: GripperProblem, step_of, kkt=None):
    """The step solver run(x, p, p_prev=None, jac=None) -> (x, converged (B,), iterations
    (B,), Jacobians or None) of ``prob`` where the fingers meet at X = 0, from
    step_of(problem, hand_over) -> that problem's step solver (the LM's hand_over,
    predictor.solvers.lm.levenberg_marquardt). The stiff plane's LM runs first; after STIFF_TRY
    iterations its unfinished samples that touch the plane (their start, at p_prev, or
    their iterate crosses X = 0) stop there, and they and the samples that fail touching
    it start again from x by ``kkt`` (a step solver of the same signature:
    predictor.solvers.plane_newton's contact-constrained Newton, ``contact_newton``; None: none),
    and those it does not converge through softer planes (PLANE_HOMOTOPY, then the stiff
    one), each from the previous one's equilibrium: the stiff penalty makes the LM's merit |r|² a
    narrow valley, where from a predictor across X = 0 (the fingers met within the step)
    it can stall short of the root. A sample apart from the plane at its start, after
    STIFF_TRY iterations and at its end solves and fails as without the plane (the ramp
    cuts a failed step back)."""
    stages = [step_of(softened(prob, f), None) for f in PLANE_HOMOTOPY] + [step_of(prob, None)]

    def run(x, p, p_prev=None, jac=None):
        pressed = crosses_plane(prob, x, p if p_prev is None else p_prev)
        test = lambda rows, xi, pi: pressed[rows] | crosses_plane(prob, xi, pi)  # noqa: E731
        x_new, conv, its, jac_new = step_of(prob, (STIFF_TRY, test))(x, p, p_prev, jac)
        bad = ~conv
        if bool(bad.any()):
            bad[bad.clone()] = pressed[bad] | crosses_plane(prob, x_new[bad], p[bad])
        if not bool(bad.any()):
            return x_new, conv, its, jac_new
        if kkt is not None:   # the contact-constrained Newton first (predictor.solvers.plane_newton)
            x_new, conv, its, jac_new = _take_rows((x_new, conv, its, jac_new), bad, kkt(x[bad], p[bad]))
            bad = bad & ~conv
            if not bool(bad.any()):
                return x_new, conv, its, jac_new
        xb, pb = x[bad], p[bad]
        prev = None if p_prev is None else p_prev[bad]
        sub = None if jac is None else tuple(a[bad] for a in jac)
        total = torch.zeros(int(bad.sum()), dtype=torch.long)
        for stage in stages:
            xb, cb, ib, jb = stage(xb, pb, prev, sub)
            prev, sub, total = None, None, total + ib
        return _take_rows((x_new, conv, its, jac_new), bad, (xb, cb, total, jb))

    return run


def _take_rows(step, rows, retried):
    """A step solver's answer (x, converged, iterations, Jacobians) with ``rows`` (bool mask)
    replaced by the retried rows' answer, whose iterations are added to theirs (the
    Jacobians, where both have them, in place)."""
    x_new, conv, its, jac_new = step
    xb, cb, ib, jb = retried
    x_new, conv, its = x_new.clone(), conv.clone(), its.clone()
    x_new[rows], conv[rows], its[rows] = xb, cb, its[rows] + ib
    if jac_new is not None and jb is not None:
        for a, b in zip(jac_new, jb):
            a[rows] = b
    return x_new, conv, its, jac_new


def in_turn(runs):
    """The step solver (``homotopy``'s signature) that runs ``runs`` in turn, each from the
    step's start on the samples that the ones before did not converge (``attempts``' kinds
    of Jacobian)."""

    def run(x, p, p_prev=None, jac=None):
        x_new, conv, its, jac_new = runs[0](x, p, p_prev, jac)
        for nxt in runs[1:]:
            bad = ~conv
            if not bool(bad.any()):
                break
            sub = None if jac is None else tuple(a[bad] for a in jac)
            xb, cb, ib, jb = nxt(x[bad], p[bad], None if p_prev is None else p_prev[bad], sub)
            x_new, conv, its, jac_new = _take_rows((x_new, conv, its, jac_new), bad, (xb, cb, ib, jb))
        return x_new, conv, its, jac_new

    return run


def ramped(problem: GripperProblem) -> bool:
    """Whether a solve of ``problem`` can follow a history (an object or the plane X = 0)."""
    return problem.obstacle is not None or meets(problem)


@graph_cache
def _traced_depth_fn(problem: GripperProblem):
    """c(x (B, 3J), p (B, J)) -> (B, 3) [normal force of the object on the finger N, the
    deepest overlap mm: the object's penetration or the outline's crossing of X = 0, that
    crossing alone mm (0 where the fingers do not meet)], recorded by ``traced``: the ramp
    asks for it after every step (depth check, first contact, the plane's homotopy)."""
    n_joints, weight = problem.n_joints, problem.params.object_weight if problem.gravity else 0.0
    layout = problem.params.layout

    def c(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        pose = problem.pose(p, x.reshape(-1, n_joints, 3), face_points=False)   # the outline is built here
        V = outline_vertices(pose, layout)
        zero = torch.zeros_like(x[:, 0])
        normal, depth, across = zero, zero, zero
        if problem.obstacle is not None:
            st = contact_loads(pose, problem.params, problem.obstacle, problem.contact, weight, V)
            normal, depth = st.normal, st.penetration
        if meets(problem):
            across = plane_overlap(V)
            depth = torch.maximum(depth, across)
        return torch.stack((normal, depth, across), -1)

    return traced(c, 3 * n_joints, n_joints)


def contact_depth(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(normal force N (B,) of the object on the finger, the deepest overlap mm (B,) of the
    object or of the plane X = 0 with the finger) at unknowns x (B, 3J), pressures p (B, J)."""
    c = _depth_columns(problem, x, p)
    return c[:, 0].clone(), c[:, 1].clone()


def _depth_columns(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """``_traced_depth_fn``'s (B, 3) at x, p. The last call's answer is kept: a ramp step's
    depth check, its first-contact record (``solve_path``) and the next step's plane test
    (``homotopy``) ask for the same point."""
    last = _LAST_DEPTH[0]
    if (last is not None and last[0] is problem and last[1].shape == x.shape and last[2].shape == p.shape
            and torch.equal(last[1], x) and torch.equal(last[2], p)):
        return last[3]
    with torch.inference_mode():
        c = _traced_depth_fn(problem)(x, p)
    c = c.clone()
    _LAST_DEPTH[0] = (problem, x.detach().clone(), p.detach().clone(), c)
    return c


#: _depth_columns' last (problem, x, p, columns).
_LAST_DEPTH: list = [None]


def attempts(problem: GripperProblem, options: SolverOptions) -> tuple[str, ...]:
    """The Jacobians a Newton solve tries in turn (``jacobian_fn`` kinds). ``auto`` with
    an object: central differences of the traced residual first (cheaper per call for a
    few samples), then the exact one for the samples that failed (a difference that
    straddles a kink of the contact law can stall LM; docs/decisions.md §11). Both end at the same equilibria (tested on the
    three objects' holds, slips and misses)."""
    if options.method in ("newton", "lm") and options.jacobian == "auto" and ramped(problem):
        return ("differences", "exact")
    return (options.jacobian,)


def advance(run, x, pa, pb, cutbacks, jac=None, snap=None):
    """One ramp step pa -> pb (B, J) from the equilibrium x at pa (with its Jacobians
    ``jac``, or None); samples that fail are retried as two half steps, recursively up to
    ``cutbacks`` times (as the FEM does), and those that fail the shortest step go to
    ``snap`` (``snap_off``) when given. Returns (x, converged, iterations, jac at x; None
    after a snap)."""
    x_new, conv, its, jac_new = run(x, pb, pa, jac)
    if bool(conv.all()) or (cutbacks == 0 and snap is None):
        return x_new, conv, its, jac_new
    bad = ~conv
    if cutbacks == 0:
        retried = snap(x[bad], pb[bad])
    else:
        pm = 0.5 * (pa[bad] + pb[bad])
        sub = None if jac is None else tuple(a[bad] for a in jac)
        x1, c1, i1, j1 = advance(run, x[bad], pa[bad], pm, cutbacks - 1, sub, snap)
        x2, c2, i2, j2 = advance(run, x1, pm, pb[bad], cutbacks - 1, j1, snap)
        retried = (x2, c1 & c2, i1 + i2, j2)
    if retried[3] is None:
        jac_new = None
    return _take_rows((x_new, conv, its, jac_new), bad, retried)


def crosses_plane(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """(B,) bool: the outline at unknowns x (B, 3J), pressures p (B, J) lies across X = 0
    (any vertex at X < 0); False everywhere where the fingers do not meet."""
    return _depth_columns(problem, x, p)[:, 2] > 0


def runner(prob: GripperProblem, opts: SolverOptions, history: bool | None = None, soften: bool = True,
           hand_over=None):
    """The solver of one ramp step: run(x (B, n), p (B, J), p_prev=None, jac=None) ->
    (x, converged (B,), iterations (B,), Jacobians at x or None), by opts.method. On a
    ``history`` (default: with an object) it has the ramp's tangent predictor, the step
    cap, and an equilibrium deeper than opts.max_penetration into the object or across
    X = 0 counts as failed, and where the fingers meet (``soften``) a step that touches
    the plane and stalls goes through softer planes (``homotopy``). hand_over: the LM's
    (levenberg_marquardt)."""
    history = prob.obstacle is not None if history is None else history
    if opts.method in ("newton", "lm"):
        jac_fn = jacobian_fn(prob, history, opts.jacobian)  # dr/dP: the ramp's predictor
        cap = opts.contact_max_step if history else None
        shorten = SHORTENINGS if prob.obstacle is not None else 0
        method = lambda x, p, p_prev=None, jac=None: levenberg_marquardt(  # noqa: E731
            jac_fn, x, p, opts, cap, p_prev, jac, hand_over, shorten)
    else:
        method = lambda x, p, p_prev=None, jac=None: lbfgs(residual_fn(prob), x, p, opts)  # noqa: E731
    if not history:
        return method

    def with_depth_check(x, p, p_prev=None, jac=None):
        # A step so large that the finger passes into (or through) the object or the other
        # finger finds a spurious equilibrium; refuse it so that advance cuts the step back.
        x, conv, its, jac = method(x, p, p_prev, jac)
        return x, conv & (contact_depth(prob, x, p)[1] <= opts.max_penetration), its, jac

    if not (soften and meets(prob)):
        return with_depth_check
    return homotopy(prob, lambda problem, hand_over: runner(problem, opts, True, False, hand_over),
                    None if opts.method == "lbfgs" else contact_newton(prob, opts))


def contact_newton(prob: GripperProblem, opts: SolverOptions):
    """The step solver of predictor.solvers.plane_newton for ``prob`` where the fingers meet: the
    KKT Newton, the penalty's Newton steps, then the stiff plane's LM (POLISH_ITER
    iterations, the depth check). Not for L-BFGS (``opts.method`` lbfgs keeps the paper's
    path)."""
    return plane_newton(prob, opts, runner(prob, dataclasses.replace(opts, max_iter=POLISH_ITER), True, False))


def snap_off(problem: GripperProblem, options: SolverOptions):
    """The snap of a finger off the object where its contact branch ends (a fold in the
    pressure: the ramp's shortest step fails, as when a fingertip pressing on the top of
    a circle slides off it): snap(x (b, n), p (b, J)) -> (x, converged (b,), iterations
    (b,), None), the gesture without the object solved from x, converged only where it
    does not touch the object (an equilibrium of the grasp then too: zero contact force)
    nor cross X = 0 deeper than options.max_penetration. None without an object."""
    if problem.obstacle is None:
        return None
    built = []      # the object-free solver, built at the first snap: most ramps never snap

    def snap(x, p):
        if not built:
            built.append(runner(dataclasses.replace(problem, obstacle=None), options, history=False))
        x, conv, its, _ = built[0](x, p)
        normal, depth = contact_depth(problem, torch.nan_to_num(x), p)
        return x, conv & (normal <= 0) & (depth <= options.max_penetration), its, None
    return snap


def ramp(problem: GripperProblem, x: torch.Tensor, p0: torch.Tensor, pressures: torch.Tensor,
         options: SolverOptions, on_step=None):
    """Ramp the equilibrium x (B, 3J) at p0 (B, J) to ``pressures`` in options.ramp_steps
    equal sub-steps (module docstring); on_step(x, p) after each. Returns (x, converged (B,),
    iterations (B,))."""
    run = runner(problem, options, history=True)
    # Intermediate ramp steps only need to stay on the branch: a 100x looser tolerance
    # saves the last (quadratic) Newton iteration of each; the final step uses the full one.
    loose = dataclasses.replace(options, tol_force=100 * options.tol_force, tol_moment=100 * options.tol_moment)
    run_loose = runner(problem, loose, history=True)
    snap = snap_off(problem, options)
    x = x.clone()
    ok = torch.ones(len(x), dtype=torch.bool)
    iterations = torch.zeros(len(x), dtype=torch.long)
    jac = None
    beat = Heartbeat("solve")   # a hard ramp (cut-backs on every step) can take tens of seconds
    for k in range(1, options.ramp_steps + 1):
        beat(lambda: f"ramp step {k} of {options.ramp_steps}, {int(ok.sum())} of {len(x)} on track")
        pa = p0 + (pressures - p0) * ((k - 1) / options.ramp_steps)
        pb = p0 + (pressures - p0) * (k / options.ramp_steps)
        on = ok.nonzero().flatten()       # a sample that failed a step has failed: it stops there
        if not len(on):
            break
        every = len(on) == len(x)
        sub = jac if jac is None or every else tuple(a[on] for a in jac)
        xs, conv, its, jac_on = advance(run if k == options.ramp_steps else run_loose, x[on], pa[on], pb[on],
                                        options.cutbacks, sub, snap)
        x[on], ok[on], iterations[on] = xs, conv, iterations[on] + its
        if jac_on is None:
            jac = None
        else:
            if jac is None:
                jac = tuple(torch.zeros(len(x), *a.shape[1:], dtype=a.dtype) for a in jac_on)
            for a, b in zip(jac, jac_on):
                a[on] = b
        if on_step is not None:
            on_step(x, pb)
    return x, ok, iterations


def plane_ramp(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions):
    """The object-free gesture at pressures (B, J) MPa where the fingers meet: the
    contact-constrained Newton (``contact_newton``) from tau = 0 at the target, then along
    its own ramp of KKT_LEGS legs from zero pressure (predictor.solvers.plane_newton.kkt_path) for
    the samples that failed; those that fail both by the ramp from zero pressure, where the
    finger hangs clear of X = 0, so that the fingers close until they meet (module
    docstring), each Jacobian of ``attempts`` in turn for the samples the previous failed.
    Returns (x (B, 3J), converged (B,), iterations (B,): every path's that the sample took)."""
    B, n_joints = pressures.shape
    x = torch.zeros(B, 3 * n_joints, dtype=torch.float64)
    ok, iterations = torch.zeros(B, dtype=torch.bool), torch.zeros(B, dtype=torch.long)
    kkt = None if options.method == "lbfgs" else contact_newton(problem, options)   # L-BFGS: the paper's path
    if kkt is not None:
        x, ok, iterations, _ = kkt(x, pressures)
    if kkt is not None and not bool(ok.all()):   # its own ramp from zero pressure, from tau = 0
        bad = ~ok
        zero = torch.zeros(int(bad.sum()), 3 * n_joints, dtype=torch.float64)
        x[bad], ok[bad], its, _ = kkt(zero, pressures[bad], p0=torch.zeros_like(pressures[bad]), legs=KKT_LEGS)
        iterations[bad] += its
    rows = (~ok).nonzero().flatten()
    for kind in attempts(problem, options) if len(rows) else ():
        opts = dataclasses.replace(options, jacobian=kind)
        p = pressures[rows]
        x0, ok0, its, _ = runner(problem, opts)(torch.zeros(len(rows), 3 * n_joints, dtype=torch.float64),
                                                torch.zeros_like(p))
        xr, okr, itr = ramp(problem, x0, torch.zeros_like(p), p, opts)
        x[rows], ok[rows], iterations[rows] = xr, okr & ok0, iterations[rows] + its + itr
        rows = rows[~ok[rows]]
        if not len(rows):
            break
    return x, ok, iterations


def plane_first(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions) -> torch.Tensor:
    """(B,) bool: the pressures (B, J) whose load-free pose (tau = 0) lies across X = 0
    deeper than options.max_penetration: a solve from tau = 0 would start among the
    plane's huge penalty forces, so they go to ``plane_ramp`` at once (none when the
    fingers do not meet)."""
    if not meets(problem):
        return torch.zeros(len(pressures), dtype=torch.bool)
    zero = torch.zeros(len(pressures), 3 * problem.n_joints, dtype=torch.float64)
    return contact_depth(problem, zero, pressures)[1] > options.max_penetration


def plane_rows(problem: GripperProblem, x: torch.Tensor, pressures: torch.Tensor, ok: torch.Tensor,
               options: SolverOptions) -> torch.Tensor:
    """(B,) bool: the object-free answers x (B, 3J) at pressures (B, J) to solve again by
    ``plane_ramp``: those that lie across X = 0 deeper than options.max_penetration, and
    those that failed (ok False) where the fingers cross X = 0 at x or at tau = 0 (other
    failures are not the plane's); none when the fingers do not meet (``meets``)."""
    if not meets(problem):
        return torch.zeros_like(ok)
    depth = contact_depth(problem, torch.nan_to_num(x), pressures)[1]
    free = contact_depth(problem, torch.zeros_like(x), pressures)[1]
    return (~ok & ((depth > 0) | (free > 0))) | (depth > options.max_penetration)


def free_path(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0=None):
    """The object-free gesture (problem without an object): one solve from x0 (default
    tau = 0), then ``plane_ramp`` for the rows ``plane_rows`` names; from tau = 0, the
    rows ``plane_first`` names go to ``plane_ramp`` at once.
    Returns (x (B, 3J), converged (B,), iterations (B,))."""
    B, n_joints = pressures.shape
    x = torch.zeros(B, 3 * n_joints, dtype=torch.float64) if x0 is None else x0.reshape(B, -1).double().clone()
    ok, iterations = torch.zeros(B, dtype=torch.bool), torch.zeros(B, dtype=torch.long)
    direct = ~plane_first(problem, pressures, options) if x0 is None else torch.ones(B, dtype=torch.bool)
    if bool(direct.any()):
        x[direct], ok[direct], iterations[direct], _ = runner(problem, options, history=False)(x[direct],
                                                                                               pressures[direct])
    again = ~direct | plane_rows(problem, x, pressures, ok, options)
    if bool(again.any()):
        xr, okr, itr = plane_ramp(problem, pressures[again], options)
        x[again], ok[again], iterations[again] = xr, okr, iterations[again] + itr
    return x, ok, iterations


def solve_path(problem: GripperProblem, pressures: torch.Tensor, options: SolverOptions, x0):
    """solve's path (approach, ramp, or from x0) with one kind of Jacobian: (x (B, 3J),
    converged (B,), iterations (B,), first contact (B, J) MPa)."""
    B, n_joints = pressures.shape
    first_contact = torch.full((B, n_joints), float("nan"), dtype=torch.float64)
    if problem.obstacle is None:
        return (*free_path(problem, pressures, options, x0), first_contact)

    def record_contact(x, p):
        # One contact evaluation per ramp step (no iterate changes): the first pressures
        # at which the finger touches the object, for grasp planning (predictor.planning.atlas).
        new = (contact_depth(problem, x, p)[0] > 0) & first_contact[:, 0].isnan()
        first_contact[new] = p[new]

    if x0 is not None:
        x, ok, iterations, _ = runner(problem, options)(x0.reshape(B, -1).double().clone(), pressures)
        record_contact(x, pressures)
        return x, ok, iterations, first_contact
    start = problem.approach
    p0 = (torch.zeros_like(pressures) if start is None else
          torch.as_tensor(start, dtype=torch.float64).expand(B, n_joints))
    x = torch.zeros(B, 3 * n_joints, dtype=torch.float64)
    ok, iterations = torch.ones(B, dtype=torch.bool), torch.zeros(B, dtype=torch.long)
    if start is not None:  # approach: open without the object, then bring it in
        x, ok, iterations = free_path(dataclasses.replace(problem, obstacle=None), p0, options)
    record_contact(x, p0)
    x, conv, its = ramp(problem, x, p0, pressures, options, record_contact)
    return x, ok & conv, iterations + its, first_contact
