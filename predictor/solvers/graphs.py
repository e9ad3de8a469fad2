"""Recorded graphs of the gesture residual: one evaluation of Equation 1 is ~150 small
tensor operations whose Python dispatch costs more than their arithmetic, so the solvers
call them through a graph recorded once per problem (``traced``): the residual r(x; P)
(``traced_residual_fn``), the contact figures (``touch``) and the answer's statics
(``statics_at``). Where the two fingers meet at X = 0, the residual's and the statics'
graphs are two, without and with the plane's penalty, and the first decides per row
whether the second is needed (``gated``: the plane's broad phase).

How graphs are recorded is a process-wide choice, visible as ``graph_mode()`` and set by
``use_graphs`` (which empties every ``graph_cache``, so that the next call records anew):
"trace" (torch.jit.trace, the default) or "compile" (torch.compile). Either is checked
against the eager function before it is used; results are bit for bit the eager ones
(trace) or within 1e-6 relative (compile).

Unknowns x (B, 3J) = (F1 N, F2 N, M N·mm) per joint; pressures p (B, J) MPa.
"""
from __future__ import annotations

import functools
import warnings

import torch

from contract.spec import INPUT_BOX
from predictor.model.gripper import FingerPose, outline_vertices
from predictor.model.statics import (ContactState, GripperProblem, PlaneContact, Statics, apart, box_scale, contact_loads,
                                     meets, plane_overlap, range_penalty, scaled)


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


def graph_mode() -> str:
    """How graphs are recorded now: one of GRAPHS (``use_graphs``)."""
    return _graphs


def residual_fn(problem: GripperProblem, overlap: bool = False):
    """Batched r(x; P): x (B, 3J), P (B, J) -> (B, 6J) [scaled equilibrium, penalties];
    with ``overlap`` the pair (r, how far (B,) mm the outline crosses X = 0)."""
    n_joints = problem.n_joints

    def r(x: torch.Tensor, p: torch.Tensor):
        tau = x.reshape(-1, n_joints, 3)
        st = problem.residual(p, tau)
        out = torch.cat((scaled(st.residual), range_penalty(tau)), -1)
        return (out, _overlap(problem, st)) if overlap else out

    return r


def _overlap(problem: GripperProblem, st: Statics) -> torch.Tensor:
    """How far (B,) mm the outline of st's pose crosses X = 0 (its plane contact's, when on)."""
    if st.plane is not None:
        return st.plane.overlap
    return plane_overlap(outline_vertices(st.pose, problem.params.layout) if st.vertices is None else st.vertices)


@graph_cache
def traced_residual_fn(problem: GripperProblem):
    """``residual_fn(problem)`` recorded by ``traced``: one per problem (0.3 s), valid
    for any batch size; where the fingers meet, ``gated`` by the plane's overlap."""
    n, J = 3 * problem.n_joints, problem.n_joints
    if not meets(problem):
        return traced(residual_fn(problem), n, J)
    return gated(traced(residual_fn(apart(problem), overlap=True), n, J),
                 traced(residual_fn(problem, overlap=True), n, J))


def gated(apart_fn, full_fn):
    """The broad phase of the symmetry plane X = 0: f(x, p) = full_fn(x, p) without its
    last output, full_fn a graph with the plane's penalty and apart_fn the same without it,
    each with the outline's overlap across X = 0 (B,) mm last. Where no vertex of the
    outline lies at X < 0 the plane's penalty is exactly zero (its Gauss points lie on the
    edges' parts at X < 0), so there the two agree to the order of a sum (~1e-16) and the
    plane's terms cost one min over the vertices: f calls apart_fn and full_fn only for
    the rows that cross. A call where most rows crossed makes the next ones call full_fn
    alone (a ramp where the fingers meet stays on it), until one where most do not."""
    mostly = [False]   # most rows of the last call crossed X = 0

    def f(x: torch.Tensor, p: torch.Tensor):
        if mostly[0]:
            *out, overlap = full_fn(x, p)
            mostly[0] = 2 * int((overlap > 0).sum()) > len(overlap)
        else:
            *out, overlap = apart_fn(x, p)
            cross = (overlap > 0).nonzero().flatten()
            mostly[0] = 2 * len(cross) > len(overlap)
            if len(cross):
                sub = full_fn(x.index_select(0, cross), p.index_select(0, cross))
                out = [o.index_copy(0, cross, s) for o, s in zip(out, sub)]
        return out[0] if len(out) == 1 else tuple(out)

    return f


@graph_cache
def _traced_contact_fn(problem: GripperProblem):
    """c(x (B, 3J), p (B, J)) -> (B, 2) [total normal force N, penetration mm] of the
    object on the finger, recorded by ``traced``: the ramp asks for it after every step
    (the depth check, the first contact), where the whole eager residual (pose, weights,
    Equation 1) costs several times more."""
    n_joints, weight = problem.n_joints, problem.params.object_weight if problem.gravity else 0.0

    def c(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        pose = problem.pose(p, x.reshape(-1, n_joints, 3), face_points=False)   # the outline once, here
        V = outline_vertices(pose, problem.params.layout) if problem.params.surface == "faces" else None
        st = contact_loads(pose, problem.params, problem.obstacle, problem.contact, weight, V)
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
    x = (2 * torch.rand(4, n, generator=gen, dtype=torch.float64) - 1) * box_scale(n)[0]
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


#: torch.compile's graphs per code object (torch._dynamo.config.recompile_limit, 8 by
#: default). Every problem's residual is a closure of the same function, so each problem
#: (a grasp: without and with the plane, and the plane homotopy's three softer planes)
#: is a recompile of it, two with the size-one batch that ``traced`` checks first; past the
#: limit dynamo runs the function eagerly, several times slower than the trace.
RECOMPILE_LIMIT = 64


def _compiled(fn):
    """torch.compile of fn(x, p) with a dynamic batch size, its inputs passed as inference
    tensors: a compiled graph is specialised to its inputs' dispatch keys, and callers
    pass both kinds (a clone of a few rows is cheaper than a second compile)."""
    torch._dynamo.config.recompile_limit = max(torch._dynamo.config.recompile_limit, RECOMPILE_LIMIT)
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


def statics_fn(problem: GripperProblem):
    """s(x (B, 3J), p (B, J)) -> (residual (B, J, 3), then the FingerPose's tensor fields
    joints, segments, theta, phi, points (and band, with outline ``bulged``), then with an object the ContactState's forces,
    normal, friction, ratio, slip, penetration, then the plane X = 0's force (B,) N (0 when
    its penalty is off) and the outline's overlap across it (B,) mm)."""
    n_joints, contact = problem.n_joints, problem.obstacle is not None

    def s(x: torch.Tensor, p: torch.Tensor):
        st = problem.residual(p, x.reshape(-1, n_joints, 3))
        q, c = st.pose, st.contact
        out = (st.residual, q.joints, q.segments, q.theta, q.phi, q.points) + (() if q.band is None else (q.band,))
        out = out + (c.forces, c.normal, c.friction, c.ratio, c.slip, c.penetration) if contact else out
        overlap = _overlap(problem, st)
        return out + (torch.zeros_like(overlap) if st.plane is None else st.plane.force, overlap)

    return s


@graph_cache
def _traced_statics_fn(problem: GripperProblem):
    """``statics_fn`` recorded by ``traced``: the answer's statics (``gesture_result``),
    faster than eager (docs/decisions.md §11) and bit for bit the same; where the fingers meet, ``gated`` by the plane's overlap."""
    n, J = 3 * problem.n_joints, problem.n_joints
    if not meets(problem):
        return traced(statics_fn(problem), n, J)
    return gated(traced(_keyed(statics_fn(apart(problem))), n, J), traced(_keyed(statics_fn(problem)), n, J))


def _keyed(s):
    """``statics_fn``'s s with its last output (the overlap across X = 0) once more: ``gated``'s key."""

    def keyed(x: torch.Tensor, p: torch.Tensor):
        out = s(x, p)
        return out + (out[-1],)

    return keyed


def as_statics(problem: GripperProblem, out) -> Statics:
    """The Statics of ``statics_fn``'s tuple (cloned: out of inference mode)."""
    res, joints, segments, theta, phi, points, *contact, force, overlap = (v.clone() for v in out)
    band = None if problem.params.bulge is None else contact.pop(0)
    pose = FingerPose(joints=joints, segments=segments, theta=theta, phi=phi, points=points,
                      finger=problem.params.finger, band=band)
    plane = PlaneContact(None, None, force, overlap)   # the figures only (its loads are in res)
    if not contact:
        return Statics(res, pose, ContactState.none(len(res), res.dtype), plane)
    return Statics(res, pose, ContactState(points, contact[0], problem.params.layout.contact_part, *contact[1:]),
                   plane)


def statics_at(problem: GripperProblem, pressures: torch.Tensor, tau: torch.Tensor) -> Statics:
    """problem.residual(pressures (B, J), tau (B, J, 3)) by its recorded graph in float64
    (``_traced_statics_fn``, recorded in float64; float32 is the throughput mode's,
    eager)."""
    if tau.dtype != torch.float64:
        return problem.residual(pressures, tau)
    with torch.inference_mode():
        return as_statics(problem, _traced_statics_fn(problem)(tau.reshape(len(tau), -1), pressures))
