"""Issue 36 §0 and §4: contact on the finger's outline (faces), the symmetry plane X = 0
where the two fingers meet, and the reference ramp through a rounded rectangle corner.

Every test states the exact or expected answer it checks: exact geometry (outline
vertices, a segment's interval inside a circle or a rounded rectangle), the penalty's
integral against an independent quadrature, the plane's force and moment at a known
overlap in closed form, the new terms' Jacobians against central differences, and the
figures of solves on the committed surrogate.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from contract.finger import parse_finger
from predictor.solvers.graphs import residual_fn
from predictor.model.gripper import GripperParams, edge_ends, finger_pose, joint_height, outline_vertices
from predictor.solvers.jacobians import autograd_jacobian
from predictor.solvers.problem import load_problem
from predictor.solvers.solve import SolverOptions, solve
from predictor.model.statics import (ContactParams, GripperProblem, Obstacle, contact_loads, parse_object, plane_contact,
                                     scaled, smooth_penetration)

from test_predictor_common import ROOT, SURROGATE, J, t

torch.set_num_threads(1)
needs_surrogate = pytest.mark.skipif(not SURROGATE.is_file(), reason="no committed surrogate")
PAPER = (ROOT / "contract/fingers/paper.toml").read_text()


def _straight(params: GripperParams):
    """The load-free pose at zero pressure (the analytic joint: every joint straight)."""
    return finger_pose(J, params, t([[0.0, 0.0]]), torch.zeros(1, 2, 3, dtype=torch.float64))


def _finger(base_gap: float):
    return parse_finger(PAPER.replace("base_gap = 50.0", f"base_gap = {base_gap!r}"), "paper.toml")


# ---------------------------------------------------------------- outline geometry
def test_straight_finger_outline_is_two_lines_and_an_end():
    """The straight hanging finger (mounts 50 mm apart, parts 20 mm high): every inner
    vertex at X = 25 - 10 = 15 mm, every outer one at X = 35 mm, the joints' bands at the
    joint file's height (20 mm), and the fingertip's end face from (15, -215.9) to
    (35, -215.9) mm (2 x 45.45 + 60 + 65 below the base)."""
    params = GripperParams()
    V = outline_vertices(_straight(params), params.layout)[0]
    lay = params.layout
    assert joint_height() == 20.0
    inner = torch.cat((lay.edge_start[lay.edge_face == 0], lay.edge_end[lay.edge_face == 0]))
    outer = torch.cat((lay.edge_start[lay.edge_face == 1], lay.edge_end[lay.edge_face == 1]))
    np.testing.assert_allclose(V[inner, 0].numpy(), 15.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(V[outer, 0].numpy(), 35.0, rtol=0, atol=1e-12)
    end = (lay.edge_face == 2).nonzero().flatten()
    a, b = edge_ends(V[None], lay, end)
    np.testing.assert_allclose(torch.cat((a, b), 1)[0].numpy(), [[15.0, -215.9], [35.0, -215.9]], atol=1e-9)


def _joint_finger(folder, counts):
    """The paper's finger with its two joints of joint files of ``counts`` anchors (the
    paper's joint otherwise), written in ``folder``, and loaded."""
    from contract.finger import load_finger

    joint = (ROOT / "contract/joints/paper.toml").read_text()
    joint = joint[:joint.index("[outline]")]     # its bulge table is one value per chord of 10 anchors
    parts = PAPER.split("[[part]]")
    for i, n in zip((1, 3), counts):
        (folder / f"j{n}.toml").write_text(joint.replace('name = "paper"', f'name = "j{n}"').replace(
            "count = 10", f"count = {n}"))
        parts[i] = parts[i].replace("contact = ", f'joint = "j{n}.toml"\ncontact = ')
    path = folder / "finger.toml"
    path.write_text("[[part]]".join(parts))
    return load_finger(path)


def test_outline_of_a_joint_of_twelve_anchors(tmp_path):
    """A joint description of 12 anchors (the joint model poses them; the analytic
    stand-in of that joint): each joint's band has 12 inner and 12 outer chords, each
    45.45 / 12 mm long on the straight hanging finger, inner vertices at X = 15 mm and
    outer ones at 35 mm, the links' faces and the tip's end face where they are with the
    paper's 10 (same lengths); the figures' polygons close each band over its 26 points.
    A finger whose joints differ in their counts is refused (one line)."""
    from predictor.model.gripper import band_size
    from predictor.model.joint import AnalyticJoint
    from predictor.model.plot import part_outlines

    finger = _joint_finger(tmp_path, (12, 12))
    params = GripperParams(finger)
    assert band_size(finger) == 26
    pose = finger_pose(AnalyticJoint.for_joint(finger.parts[0].spec), params, t([[0.0, 0.0]]),
                       torch.zeros(1, 2, 3, dtype=torch.float64))
    lay = params.layout
    V = outline_vertices(pose, lay)[0]
    a, b = edge_ends(V[None], lay)
    length = (b - a)[0].norm(dim=-1)
    for k in (0, 2):
        for face, x in ((0, 15.0), (1, 35.0)):
            sel = (lay.edge_part == k) & (lay.edge_face == face)
            assert int(sel.sum()) == 12
            np.testing.assert_allclose(length[sel].numpy(), 45.45 / 12, rtol=1e-12)
            np.testing.assert_allclose(torch.cat((a[0, sel, 0], b[0, sel, 0])).numpy(), x, rtol=0, atol=1e-12)
    end = (lay.edge_face == 2).nonzero().flatten()
    np.testing.assert_allclose(torch.cat((a[0, end], b[0, end]), 0).numpy(), [[15.0, -215.9], [35.0, -215.9]],
                               atol=1e-9)
    rings = part_outlines(pose, 0)
    assert [len(r) for kind, r in rings if kind == "joint"] == [27, 27]
    (tmp_path / "mixed").mkdir()
    mixed = _joint_finger(tmp_path / "mixed", (10, 12))
    with pytest.raises(ValueError) as err:
        band_size(mixed)
    assert "\n" not in str(err.value) and "[10, 12] anchors" in str(err.value)

def test_bent_outline_is_closed_where_parts_meet():
    """At a bent pose (cap kinematics, loads on both joints) each joint's band ends where
    the next rigid part's faces start and starts where the previous one's end (its end
    normals are those of theta_i and phi_i, the neighbours' directions): the shared
    corners coincide to 1e-12 mm, on both faces; and every rigid face is h = 20 mm from
    its mirror face. The outline ``band``: a ``bulged`` joint's end vertices stand off by
    their end chord's bulge (tests/test_joint_outline.py)."""
    params = GripperParams(outline="band")
    pose = finger_pose(J, params, t([[0.2, -0.15]]), t([[[0.3, 0.2, -20.0], [0.1, -0.1, 8.0]]]))
    V = outline_vertices(pose, params.layout)[0]
    J1, J2 = 0, 22            # joint vertex blocks: inner 0..10, outer 11..21
    link, tip = 44, 48        # rigid corners S-, E-, S+, E+
    pairs = [(J1 + 10, link), (J1 + 21, link + 2), (link + 1, J2), (link + 3, J2 + 11), (J2 + 10, tip),
             (J2 + 21, tip + 2)]
    for a, b in pairs:
        assert float((V[a] - V[b]).norm()) < 1e-12, (a, b)
    for base in (link, tip):
        assert abs(float((V[base] - V[base + 2]).norm()) - 20.0) < 1e-12


# ---------------------------------------------------------------- the object on a face
def test_segment_interval_inside_a_circle_is_exact():
    """The straight finger's inner tip face (X = 15 mm, Y from -150.9 to -215.9) against a
    circle of radius 16 about (0, -180): inside where |Y + 180| < sqrt(16² - 15²) =
    sqrt(31) mm (exact to 1e-12); a circle that misses gives an empty interval."""
    a, b = t([[15.0, -150.9]]), t([[15.0, -215.9]])
    u0, u1 = Obstacle(a=16.0, b=16.0, y=-180.0).segment_interval(a, b)
    y0, y1 = (-150.9 - 65.0 * float(u) for u in (u0[0], u1[0]))
    assert abs(y0 - (-180 + math.sqrt(31))) < 1e-12 and abs(y1 - (-180 - math.sqrt(31))) < 1e-12
    u0, u1 = Obstacle(a=14.0, b=14.0, y=-180.0).segment_interval(a, b)
    assert float(u1[0] - u0[0]) == 0.0


def test_rounded_rectangle_distance_and_interval():
    """The default rectangle (60 x 50 mm, corner radius 1 mm, centre (0, -195)): a point
    3 mm out from the top-right arc's centre (29, -171) along the diagonal is 2 mm from the
    arc, with the radial normal; inside within the radius the normal turns continuously
    (the two sides of the diagonal agree to 1e-6); rc = 0 gives the sharp rectangle's
    distances (sqrt(2) mm from its corner (30, -170) at (31, -169)).
    A horizontal line at Y = -170.5 (0.5 mm below the top) is inside for |X| < 29 +
    sqrt(1 - 0.5²) mm, exactly."""
    r = parse_object("rectangle")
    assert r.corner == 1.0
    c = torch.tensor([29.0, -171.0], dtype=torch.float64)          # the top-right arc's centre
    diag = torch.tensor([1.0, 1.0], dtype=torch.float64) / math.sqrt(2.0)
    d, n = r.distance_normal((c + 3.0 * diag)[None])
    assert abs(float(d[0]) - 2.0) < 1e-12 and torch.allclose(n[0], diag, atol=1e-12)
    eps = torch.tensor([1e-7, -1e-7], dtype=torch.float64)
    _, n2 = r.distance_normal(torch.stack((c + 0.5 * diag + eps, c + 0.5 * diag - eps)))
    assert float((n2[0] - n2[1]).norm()) < 1e-6
    sharp = parse_object("rectangle:rc=0")
    d, _ = sharp.distance_normal(t([[31.0, -169.0], [29.0, -171.0]]))
    np.testing.assert_allclose(d.numpy(), [math.sqrt(2.0), -1.0], atol=1e-12)
    u0, u1 = r.segment_interval(t([[-40.0, -170.5]]), t([[40.0, -170.5]]))
    half = 29.0 + math.sqrt(1.0 - 0.25)
    np.testing.assert_allclose([-40 + 80 * float(u0[0]), -40 + 80 * float(u1[0])], [-half, half], atol=1e-12)


def test_face_penalty_is_the_integral_over_the_face():
    """The circle r = 16 at (0, -180) pressing on the straight finger's inner faces
    (X = 15): the normal force is k_c ∫ s(16 - |(15, Y + 180)|) dY over the tip and joint 2
    faces, as an independent 200,001-point trapezoid rule gives it, to the 6-point Gauss
    rule's accuracy on this root-shaped profile (3.2e-4 relative measured; asserted 1e-3),
    and it acts along +X (by symmetry about Y = -180, Fy = 0 to 1e-12 N); the loaded
    points lie on the face X = 15 mm."""
    params = GripperParams()
    ob = Obstacle(a=16.0, b=16.0, y=-180.0)
    st = contact_loads(_straight(params), params, ob, ContactParams(), 0.0)
    y = np.linspace(-180 - math.sqrt(31), -180 + math.sqrt(31), 200_001)
    pen = 16.0 - np.hypot(15.0, y + 180.0)
    s = smooth_penetration(torch.from_numpy(pen), 0.05).numpy()
    integrand = s * 15.0 / np.hypot(15.0, y + 180.0)        # n_x along the face
    fx = 2.0 * np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(y))
    total = st.forces[0].sum(0)
    assert abs(float(total[0]) - fx) < 1e-3 * fx and abs(float(total[1])) < 1e-12
    assert bool((st.points[0][st.forces[0].norm(dim=-1) > 0, 0] - 15.0).abs().max() < 1e-12)


# ---------------------------------------------------------------- the symmetry plane
def test_plane_force_and_moment_at_a_known_overlap():
    """Mounts 19.92 mm apart: the straight finger's whole inner face lies at X = -0.04 mm
    (delta below the ramp width 0.05 mm, so s(q) = q²/(2·0.05) and Gauss is exact). The
    plane's push is k_p (s(0.04) L + ∫_0^0.04 s) along +X, L = 215.9 mm of inner face, and
    the end face's 0.04 mm across adds the integral; the overlap is 0.04 mm; the change of
    joint 1's moment residual is minus the moment of the loads on the parts after it
    about its end (0, -45.45): k_p s(0.04) 170.45²/2 + the end face's F·170.45 N·mm."""
    params = GripperParams(_finger(19.92))
    k = ContactParams().plane_stiffness
    pc = plane_contact(_straight(params), params, ContactParams())
    s, S = 0.04**2 / 0.1, 0.04**3 / 0.3
    assert abs(float(pc.force[0]) - k * (s * 215.9 + S)) < 1e-9 and abs(float(pc.overlap[0]) - 0.04) < 1e-12
    p, tau = t([[0.0, 0.0]]), torch.zeros(1, 2, 3, dtype=torch.float64)
    on = GripperProblem(J, params, gravity=False).residual(p, tau).residual
    off = GripperProblem(J, params, contact=ContactParams(plane_stiffness=0.0), gravity=False).residual(p, tau).residual
    moment = k * s * 170.45**2 / 2 + k * S * 170.45
    assert abs(float(on[0, 0, 2] - off[0, 0, 2]) + moment) < 1e-8 * moment      # R_M = M - Σ moments
    assert abs(float(on[0, 0, 0] - off[0, 0, 0]) + k * (s * 170.45 + S)) < 1e-9   # R_F = ... - ΣF


@pytest.mark.filterwarnings("ignore::torch.jit.TracerWarning", "ignore:`torch.jit.trace` is deprecated:DeprecationWarning")
def test_plane_broad_phase_is_the_full_quadrature():
    """The eager plane term skips the rows with no vertex at X < 0 (statics.plane_contact);
    a recorded graph evaluates the plane's quadrature on every row. On one batch of load-free
    poses of which some cross X = 0 (P up to 0.3 MPa: the finger bends 130 mm across) and
    some do not, the two give the same residual bit for bit, and the plane pushes (+X, so
    R_F,x drops) exactly on the rows that cross."""
    problem = GripperProblem(J, GripperParams(), gravity=False)
    p = t([[0.3, 0.3], [-0.3, -0.3], [0.25, 0.0], [0.0, -0.2], [0.1, 0.3]])
    x = torch.zeros(len(p), 6, dtype=torch.float64)
    eager = problem.residual(p, x.reshape(-1, 2, 3))
    cross = eager.plane.overlap > 0
    assert 0 < int(cross.sum()) < len(p)
    recorded = torch.jit.trace(residual_fn(problem), (x, p), check_trace=False)(x, p)
    assert torch.equal(recorded[:, :6], scaled(eager.residual))
    alone = GripperProblem(J, GripperParams(), contact=ContactParams(plane_stiffness=0.0), gravity=False)
    pushed = (eager.residual - alone.residual(p, x.reshape(-1, 2, 3)).residual)[:, 0, 0] < 0
    assert torch.equal(pushed, cross)


@needs_surrogate
def test_fingers_meet_at_the_symmetry_plane():
    """Without an object at (0.3, 0.3) MPa (today 132.6 mm across X = 0 without the
    plane) the right finger stops at the plane: converged, plane force > 0.3 N, overlap
    <= 0.1 mm (0.056 mm measured); the gesture reports both. With the circle brought in at
    the closed gesture (--approach 0.3,0.3) the object would cut the fingers: refused."""
    free = load_problem(None, None)
    res = solve(free, t([[0.3, 0.3]]))
    s = res.summary(0)
    assert s["converged"] and s["plane_force_N"] > 0.3 and 0 < s["plane_overlap_mm"] <= 0.1, s
    off = dataclasses.replace(free, contact=ContactParams(plane_stiffness=0.0))
    assert float(solve(off, t([[0.3, 0.3]])).pose.tip_end[0, 0]) < -130.0
    with pytest.raises(ValueError, match="intersects the fingers at the approach gesture"):
        load_problem(None, "circle", approach=(0.3, 0.3))


# ---------------------------------------------------------------- Jacobians
def _central_differences(problem: GripperProblem, x: torch.Tensor, p: torch.Tensor):
    """dr/dx (6, 6) and dr/dP (6, 2) of the equilibrium rows by central differences,
    steps 1e-6 of (1 N, 1 N, 100 N·mm) and 1e-7 of 0.3 MPa (an independent evaluation; the
    stiff plane's dr/dP has an h² truncation of 6.6e-6 relative at 1e-6, 6.6e-8 at 1e-7)."""
    r = residual_fn(problem)
    ex, ep = torch.eye(6, dtype=torch.float64), torch.eye(2, dtype=torch.float64)
    h, hp = 1e-6 * t([1.0, 1.0, 100.0] * 2), 1e-7 * 0.3
    fx = torch.stack([(r(x + h[k] * ex[k], p) - r(x - h[k] * ex[k], p))[0, :6] / (2 * h[k]) for k in range(6)], 1)
    fp = torch.stack([(r(x, p + hp * ep[j]) - r(x, p - hp * ep[j]))[0, :6] / (2 * hp) for j in range(2)], 1)
    return fx, fp


@pytest.mark.parametrize("spec", ["circle", "ellipse", "rectangle", None])
def test_contact_jacobians_match_finite_differences(spec):
    """At a converged gesture where the finger presses on an object with its faces (the
    analytic joint's grasp at (0.1, 0.2) MPa from the approach: the tip's inner face on the
    circle, the ellipse, the rounded rectangle), and where it presses on the plane X = 0
    without an object (0.2, 0.2) MPa, the exact reverse-mode Jacobians dr/dx and dr/dP
    that the ramp and the inverse's implicit-function gradients use equal central
    differences (``_central_differences``) to 1e-6 of their largest entry."""
    obstacle = None if spec is None else parse_object(spec)
    problem = GripperProblem(J, obstacle=obstacle, approach=None if spec is None else (-0.15, 0.0))
    p = t([[0.1, 0.2]]) if spec else t([[0.2, 0.2]])
    res = solve(problem, p)
    assert bool(res.converged[0])
    x = res.tau.reshape(1, 6)
    st = problem.residual(p, res.tau)
    touching = float(st.contact.normal[0]) if spec else float(st.plane.force[0])
    assert touching > 0.05, (spec, touching)
    Jx, _, Jp = autograd_jacobian(residual_fn(problem))(x, p)
    fx, fp = _central_differences(problem, x, p)
    assert float((Jx[0, :6] - fx).abs().max()) < 1e-6 * float(fx.abs().max()), spec
    assert float((Jp[0] - fp).abs().max()) < 1e-6 * float(fp.abs().max()), spec


# ---------------------------------------------------------------- grasps and the ramp
@needs_surrogate
def test_grasp_touches_with_the_tip_face():
    """The circle held at (0.2, 0.3) MPa (the paper's grasp): it holds, the contact is on
    the tip's inner face (the report names the part and face), its point lies on that face
    (on the line of the tip's two inner corners to 1e-9 mm) and on the circle's boundary
    within the penetration, and the fingers stay apart (no plane force)."""
    problem = load_problem(None, "circle")
    res = solve(problem, t([[0.2, 0.3]]))
    s = res.summary(0)
    assert s["state"] == "holds" and (s["contact_part"], s["contact_face"]) == ("tip", "inner"), s
    V = outline_vertices(res.pose, problem.params.layout)[0]
    a, b = V[48], V[49]                                  # the tip's inner corners S-, E-
    q = torch.tensor(s["contact_point_mm"], dtype=torch.float64)
    assert abs(float((b - a)[0] * (q - a)[1] - (b - a)[1] * (q - a)[0]) / float((b - a).norm())) < 1e-9
    assert abs(float((q - t([0.0, -195.0])).norm()) - 30.0) < 0.2
    assert s["plane_force_N"] == 0.0 and s["plane_overlap_mm"] == 0.0


@needs_surrogate
@pytest.mark.parametrize("steps", [12, 48])
def test_former_failing_reference_ramp_point_converges(steps):
    """(0.2, -0.1) MPa on the rectangle, one of the 44 points where the 48-step reference
    ramp failed (results/predictor/ramp_fine/atlas_rectangle.json): the finger's tip slid
    over the rectangle's corner, where the sharp corner's normal jumps and a contact
    narrower than the sample spacing is seen by one sample point. With the rounded corner
    and the contact integrated over each face's part inside the object, the ramp
    converges at 12 and 48 sub-steps to the same gesture (tip within 0.05 mm)."""
    problem = load_problem(None, "rectangle")
    res = solve(problem, t([[0.2, -0.1]]), SolverOptions(ramp_steps=steps))
    assert bool(res.converged[0]) and res.summary(0)["state"] in ("holds", "slips")
    ref = solve(problem, t([[0.2, -0.1]]), SolverOptions(ramp_steps=24))
    assert float((res.pose.tip_end - ref.pose.tip_end).norm()) < 0.05


def test_plane_homotopy_step_lands_on_the_cut_back_root():
    """A continuation step pressed on the plane X = 0 (analytic joint, (0.2, 0.2) ->
    (0.1, 0.3) MPa, no object): the stiff plane's LM alone does not converge within
    STIFF_TRY iterations; the ramp's runner (stiff try, then the planes of PLANE_HOMOTOPY)
    converges in one step, to the root that the stiff LM reaches by halving the step
    (ramp.advance's cut-backs): unknowns within 1e-6 (N, N·mm), tip within 1e-6 mm."""
    from predictor.solvers.jacobians import jacobian_fn
    from predictor.solvers.lm import levenberg_marquardt
    from predictor.solvers.ramp import STIFF_TRY, advance, runner

    problem, opts = GripperProblem(J), SolverOptions()
    pa, pb = t([[0.2, 0.2]]), t([[0.1, 0.3]])
    start = solve(problem, pa)
    assert bool(start.converged[0]) and float(start.plane_overlap_mm[0]) > 0
    x = start.tau.reshape(1, 6)
    jac = jacobian_fn(problem, True)

    def stiff(x, p, p_prev=None, j=None, o=opts):
        return levenberg_marquardt(jac, x, p, o, None, p_prev, j)

    assert not bool(stiff(x, pb, pa, None, dataclasses.replace(opts, max_iter=STIFF_TRY))[1][0])
    ref, ok_ref, _, _ = advance(stiff, x, pa, pb, opts.cutbacks)
    new, ok_new, _, _ = runner(problem, opts, history=True)(x, pb, pa)
    assert bool(ok_ref[0]) and bool(ok_new[0])
    assert float((new - ref).abs().max()) < 1e-6
    tip = lambda y: problem.pose(pb, y.reshape(1, 2, 3)).tip_end[0]  # noqa: E731
    assert float((tip(new) - tip(ref)).norm()) < 1e-6


def test_plane_homotopy_only_where_the_finger_meets_the_plane():
    """Grasps whose finger never reaches X = 0 (analytic joint, circle at (0.15, 0.15) and
    rectangle at (0.05, 0.05) and (0.15, 0.15) MPa from the approach) cost with the plane
    what they cost without it: the same equilibria bit for bit in the same LM iterations
    (the rectangle's (0.15, 0.15) has a step that fails apart from the plane and is cut
    back as without it, 60 iterations, not sent through the softer planes: 180). The LM's
    hand_over stops after k iterations exactly the unfinished samples its test names."""
    from predictor.solvers.jacobians import jacobian_fn
    from predictor.solvers.lm import levenberg_marquardt
    from predictor.solvers.solve import APPROACH
    from predictor.model.statics import apart

    for ob, p in ((Obstacle(), (0.15, 0.15)), (Obstacle(kind="rectangle", a=30, b=25), (0.05, 0.05)),
                  (Obstacle(kind="rectangle", a=30, b=25), (0.15, 0.15))):
        problem = GripperProblem(J, obstacle=ob, approach=APPROACH)
        met, alone = solve(problem, t([p])), solve(apart(problem), t([p]))
        assert bool(met.converged[0]) and float(met.plane_overlap_mm[0]) == 0.0
        assert torch.equal(met.tau, alone.tau) and torch.equal(met.iterations, alone.iterations), (ob.kind, p)
    jac, opts = jacobian_fn(apart(GripperProblem(J)), False), SolverOptions()
    x0, p = torch.zeros(3, 6, dtype=torch.float64), t([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.1]])
    free = levenberg_marquardt(jac, x0, p, opts)
    assert bool(free[1].all()) and int(free[2].min()) > 1
    stop = lambda rows, x, q: q[:, 0] > 0  # noqa: E731   the first sample only
    handed = levenberg_marquardt(jac, x0, p, opts, hand_over=(1, stop))
    assert handed[1].tolist() == [False, True, True] and handed[2].tolist() == [1, *free[2][1:].tolist()]
    assert float((handed[0][1:] - free[0][1:]).abs().max()) <= 1e-12   # other batches: rounding only


def test_plane_test_and_kept_depth_are_the_definitions():
    """ramp.crosses_plane reads the object problem's depth graph (its third column, the
    outline's crossing of X = 0): the same verdicts as the definition, the object-free
    problem's overlap > 0, on poses across and clear of the plane (analytic joint, circle,
    tau = 0 at four pressures: two across, two clear); contact_depth answers a repeated
    question from the kept last answer, equal to a fresh evaluation, and a changed x or
    another problem evaluates anew; without the plane nothing crosses."""
    import predictor.solvers.ramp as ramp

    problem = GripperProblem(J, obstacle=Obstacle(), approach=(-0.15, 0.0))
    free = dataclasses.replace(problem, obstacle=None)
    p = t([[0.3, 0.3], [0.2, 0.0], [-0.2, 0.0], [-0.1, -0.2]])
    x = torch.zeros(4, 6, dtype=torch.float64)
    with torch.inference_mode():
        overlap = ramp._traced_depth_fn(free)(x, p)[:, 1]
        fresh = ramp._traced_depth_fn(problem)(x, p)
    assert (overlap > 0).tolist() == [True, True, False, False]
    assert ramp.crosses_plane(problem, x, p).tolist() == (overlap > 0).tolist()
    assert torch.equal(fresh[:, 2], overlap)
    first = ramp.contact_depth(problem, x, p)
    kept = ramp._LAST_DEPTH[0]
    again = ramp.contact_depth(problem, x.clone(), p.clone())
    assert ramp._LAST_DEPTH[0] is kept                              # answered from the kept one
    assert torch.equal(again[0], fresh[:, 0]) and torch.equal(again[1], fresh[:, 1])
    assert torch.equal(first[1], again[1])
    moved = x.clone()
    moved[0, 0] = 1.0
    ramp.contact_depth(problem, moved, p)
    assert ramp._LAST_DEPTH[0] is not kept
    no_plane = dataclasses.replace(problem, contact=ContactParams(plane_stiffness=0.0))
    assert not bool(ramp.crosses_plane(no_plane, x, p).any())
