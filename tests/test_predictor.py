"""Gripper gesture predictor (issues 5 and 14) on the analytic stand-in joint.

Every test states the exact or expected answer it checks. The whole file runs in about a
minute on one core; the real-surrogate tests run only when the committed checkpoint
exists. Issue 14's generic finger chain: the paper's finger reproduces the predictor as it
was before the change (tests/data/predictor_reference.json), a three-joint finger works
with the same joint models, cap kinematics and split joint weights are checked against
hand computations.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.optimize import fsolve

from fem.spec import INPUT_BOX, OutOfBoxError, phi_end
from fem.finger_spec import parse_finger
from predictor.gripper import FingerPose, GripperParams, default_finger, finger_pose
from predictor.joint import AnalyticJoint, JointModel, load_joint
from predictor.graphs import residual_fn
from predictor.jacobians import jacobian_fn
from predictor.solve import APPROACH, GestureResult, SolverOptions, solve
from predictor.statics import ContactParams, GripperProblem, Obstacle, parse_object, range_penalty

torch.set_num_threads(1)
ROOT = Path(__file__).resolve().parents[1]
J = AnalyticJoint()
DT = torch.float64
GRAVITY = GripperProblem(J)
#: the paper's chain (tangent kinematics, lumped joint weights): the predictor before issue 14
PAPER_CHAIN = GripperParams(kinematics="tangent", joint_weight="lumped")
GRASP = GripperProblem(J, obstacle=Obstacle(), approach=APPROACH)


def t(x):
    return torch.tensor(x, dtype=DT)


# ---------------------------------------------------------------- joint
def test_analytic_joint_pure_moment_is_circular_arc():
    """M = 60 N·mm, P = 0.1 MPa, F = 0: uniform curvature k = (60 - 333·0.1)/3000 1/mm, so
    the anchors are r_i = (sin(k s_i)/k, (1 - cos(k s_i))/k), s_i = i·L/10 (exact)."""
    k = (60.0 - 33.3) / 3000.0
    s = np.arange(1, 11) * 45.45 / 10
    exact = np.stack((np.sin(k * s) / k, (1 - np.cos(k * s)) / k), -1)
    got = J(t([0.1, 0.0, 0.0, 60.0])).numpy()
    np.testing.assert_allclose(got, exact, atol=1e-12)
    assert float(phi_end(J(t([0.0, 0.0, 0.0, 0.0])))) == 0.0


def test_analytic_joint_axial_stretch_and_pressure_sign():
    """F1 = 3 N alone stretches the straight joint to L(1 + 3/300) = 45.9045 mm; P > 0
    (top chamber) bends towards -y, so y_10 < 0 (DESIGN.md §3 sign of the stand-in)."""
    r = J(t([0.0, 3.0, 0.0, 0.0]))
    assert abs(float(r[-1, 0]) - 45.9045) < 1e-12 and float(r[-1, 1].abs()) == 0.0
    assert float(J(t([0.2, 0.0, 0.0, 0.0]))[-1, 1]) < -10.0


def test_analytic_joint_mirror_symmetry():
    """DESIGN.md §3: (R·diag(1,-1), -P, F1, -F2, -M) is a solution; equal to 1e-12 mm."""
    x = t([[0.13, 1.1, -0.7, 35.0], [-0.25, -2.0, 2.5, -80.0]])
    mirrored = J(x * t([-1.0, 1.0, -1.0, -1.0]))
    np.testing.assert_allclose(mirrored.numpy(), (J(x) * t([1.0, -1.0])).numpy(), atol=1e-12)


def test_load_joint_errors_are_one_line_value_errors(tmp_path):
    """A missing checkpoint raises ValueError('...: surrogate checkpoint not found')."""
    with pytest.raises(ValueError, match="not found"):
        load_joint(str(tmp_path / "none.pt"))
    assert isinstance(load_joint("analytic"), AnalyticJoint)


# ---------------------------------------------------------------- statics
def test_straight_hanging_finger_closed_form():
    """P = (0, 0) under gravity, the paper's chain: the finger hangs straight, so tau_1 = (0.19, 0, 0) and
    tau_2 = (0.06, 0, 0) (distal weights along each joint's +x = down) exactly, and the
    tip is at (25, -(45.45(1 + 0.19/300) + 60 + 45.45(1 + 0.06/300) + 65)) mm."""
    res = solve(GripperProblem(J, PAPER_CHAIN), t([0.0, 0.0]))
    assert bool(res.converged[0])
    np.testing.assert_allclose(res.tau[0].numpy(), [[0.19, 0, 0], [0.06, 0, 0]], atol=1e-9)
    tip_y = -(45.45 * (1 + 0.19 / 300) + 60 + 45.45 * (1 + 0.06 / 300) + 65)
    np.testing.assert_allclose(res.pose.tip_end[0].numpy(), [25.0, tip_y], atol=1e-8)


def test_residual_zero_at_returned_solution():
    """For 64 random (P1, P2) in [-0.3, 0.3]², recomputing Equation 1 at the returned tau
    gives |R_F| <= 1e-4 mN and |R_M| <= 1e-5 N·mm (the solver's tolerance, 1000x below the
    issue's 0.1 mN / 0.01 N·mm), in at most 6 Newton iterations."""
    p = torch.rand(64, 2, generator=torch.Generator().manual_seed(3), dtype=DT) * 0.6 - 0.3
    res = solve(GRAVITY, p)
    assert bool(res.converged.all()) and int(res.iterations.max()) <= 6
    r = GRAVITY.residual(p, res.tau).residual
    assert float(r[..., :2].abs().max()) * 1e3 <= 1e-4
    assert float(r[..., 2].abs().max()) <= 1e-5


def test_newton_polish_finishes_a_near_start_in_one_step(monkeypatch):
    """Warm starts 1e-4 N (and 0.01 N·mm) off the Newton equilibria of 32 random pressures,
    the setting of a network's tau: one Newton step (solve.newton_polish) lands within the
    solver's 1e-4 mN / 1e-5 N·mm on every sample (quadratic convergence: 1e-4 -> ~1e-8 N),
    on the cold solve's tau to 1e-6 N and 1e-4 N·mm (that solve's own accuracy at its
    1e-4 mN / 1e-5 N·mm), and the start's residual it returns is Equation 1
    recomputed at the start; the answer's residual and pose, from the same recorded graph
    as the step (predictor.newton.traced_warm_fn), are Equation 1 and the kinematics recomputed at
    its tau. Allowed one step only (NEWTON_STEPS = 1), from tau = 0 at (0.3, -0.3) the
    check refuses it and the LM goes on (iterations > 1) to the same equilibrium. With an
    object it refuses to run (the contact law is not smooth)."""
    from predictor.solve import newton_polish

    p = torch.rand(32, 2, generator=torch.Generator().manual_seed(8), dtype=DT) * 0.6 - 0.3
    cold = solve(GRAVITY, p)
    start = cold.tau + t([1e-4, -1e-4, 0.01])
    res, r0 = newton_polish(GRAVITY, p, start)
    assert bool(res.converged.all()) and int(res.iterations.max()) == 1
    assert float(res.residual_force_mN.max()) <= 1e-4 and float(res.residual_moment_Nmm.max()) <= 1e-5
    assert float((res.tau - cold.tau)[..., :2].abs().max()) <= 1e-6
    assert float((res.tau - cold.tau)[..., 2].abs().max()) <= 1e-4
    torch.testing.assert_close(r0, GRAVITY.residual(p, start).residual, rtol=0, atol=1e-12)
    again = GRAVITY.residual(p, res.tau)
    torch.testing.assert_close(res.residual_force_mN, 1e3 * again.residual[..., :2].norm(dim=-1), rtol=0, atol=1e-12)
    torch.testing.assert_close(res.residual_moment_Nmm, again.residual[..., 2].abs(), rtol=0, atol=1e-12)
    torch.testing.assert_close(res.pose.points, again.pose.points, rtol=0, atol=1e-12)
    monkeypatch.setattr("predictor.solve.NEWTON_STEPS", 1)
    far, _ = newton_polish(GRAVITY, t([[0.3, -0.3]]), torch.zeros(1, 2, 3, dtype=DT))
    assert bool(far.converged[0]) and int(far.iterations[0]) > 1
    assert float((far.tau - solve(GRAVITY, t([0.3, -0.3])).tau).abs().max()) <= 1e-4
    with pytest.raises(ValueError, match="without an object"):
        newton_polish(GRASP, p[:1], start[:1])


def test_newton_steps_reach_the_lm_equilibria():
    """Without an object the default solve from tau = 0 is a Picard step and Newton steps
    (predictor.solve's cold path): on 64 random pressures of the paper's finger it converges in at
    most 3 iterations (Picard and two Newton steps, the one-graph path), on 16 of a
    three-joint finger in at most 4 (a third Newton step by newton_polish where the check
    refused), to the LM's equilibria (method="lm") within the two solves' accuracy at the
    tolerances (1e-6 N, 1e-4 N·mm), its own residual within 1e-4 mN / 1e-5 N·mm. At
    tolerances 1e6x tighter (1e-10 mN, 1e-11 N·mm) the check refuses the two-step answer
    and the fallback finishes every sample to them."""
    gen = torch.Generator().manual_seed(21)
    for problem, n, most in ((GRAVITY, 64, 3), (GripperProblem(J, GripperParams(THREE_FINGER)), 16, 4)):
        p = torch.rand(n, problem.n_joints, generator=gen, dtype=DT) * 0.6 - 0.3
        new, lm = solve(problem, p), solve(problem, p, SolverOptions(method="lm"))
        assert bool(new.converged.all()) and bool(lm.converged.all()) and new.method == "newton"
        assert int(new.iterations.max()) <= most
        assert float((new.tau - lm.tau)[..., :2].abs().max()) <= 1e-6
        assert float((new.tau - lm.tau)[..., 2].abs().max()) <= 1e-4
        r = problem.residual(p, new.tau).residual
        assert float(r[..., :2].norm(dim=-1).max()) * 1e3 <= 1e-4 and float(r[..., 2].abs().max()) <= 1e-5
    tight = solve(GRAVITY, p[:, :2], SolverOptions(tol_force=1e-13, tol_moment=1e-11))
    assert bool(tight.converged.all()) and int(tight.iterations.max()) > 3
    assert float(tight.residual_force_mN.max()) <= 1e-10 and float(tight.residual_moment_Nmm.max()) <= 1e-11


def test_traced_statics_is_the_eager_statics_bit_for_bit():
    """solve.statics_at, the traced statics of an answer, gives exactly problem.residual's
    residual and pose on 50 random (P, tau) in the box (the record was checked on 3), for
    the paper's finger and a three-joint one, and with an object its contact state too;
    float32 takes the eager path."""
    from predictor.solve import statics_at

    gen = torch.Generator().manual_seed(12)
    for problem in (GRAVITY, GripperProblem(J, GripperParams(THREE_FINGER))):
        nj = problem.n_joints
        p = torch.rand(50, nj, generator=gen, dtype=DT) * 0.6 - 0.3
        tau = (2 * torch.rand(50, nj, 3, generator=gen, dtype=DT) - 1) * t([3.0, 3.0, 100.0])
        got, ref = statics_at(problem, p, tau), problem.residual(p, tau)
        assert torch.equal(got.residual, ref.residual)
        for name in ("joints", "segments", "theta", "phi", "points"):
            assert torch.equal(getattr(got.pose, name), getattr(ref.pose, name)), name
    got, ref = statics_at(GRASP, p[:, :2], tau[:, :2]), GRASP.residual(p[:, :2], tau[:, :2])
    assert torch.equal(got.residual, ref.residual) and torch.equal(got.contact.part, ref.contact.part)
    for name in ("points", "forces", "normal", "friction", "ratio", "slip", "penetration"):
        assert torch.equal(getattr(got.contact, name), getattr(ref.contact, name)), name
    assert bool((ref.contact.normal > 0).any())   # some of the 50 touch the object


COMPILED_VS_TRACED = """
import json, torch
from predictor import newton, solve as S
from predictor.joint import AnalyticJoint
from predictor.statics import GripperProblem, Obstacle
gravity = GripperProblem(AnalyticJoint())
grasp = GripperProblem(AnalyticJoint(), obstacle=Obstacle(), approach=S.APPROACH)
p = torch.tensor([[0.1, -0.1]], dtype=torch.float64)
tau = torch.tensor([[[0.1, -0.2, 5.0], [0.05, 0.3, -3.0]]], dtype=torch.float64)
try:
    S.use_graphs("jit")
    refused = ""
except ValueError as exc:
    refused = str(exc)
out = {"refused": refused}
for mode in ("trace", "compile"):
    S.use_graphs(mode)
    res, st = S.solve(gravity, p), S.statics_at(grasp, p, tau)
    graph = newton.traced_cold_fn(gravity, *newton.bounds(S.SolverOptions()))
    out[mode] = {"converged": bool(res.converged[0]), "tau": res.tau.flatten().tolist(),
                 "force_mN": float(res.residual_force_mN.max()), "residual": st.residual.flatten().tolist(),
                 "slip": bool(st.contact.slip[0]),
                 "compiled": hasattr(getattr(graph, "__wrapped__", None), "_torchdynamo_orig_callable")}
print(json.dumps(out))
"""


def test_compiled_graphs_give_the_traced_answers():
    """use_graphs("compile") records the solver's graphs by torch.compile: the cold gravity
    solve (Picard and Newton steps in one graph) and an object's statics then give the
    same converged tau as the traced graphs to 1e-9 N / N·mm (both meet 1e-4 mN; compiled
    sums are only reordered), the graph is the compiled one (no silent fall-back to the
    trace), and an unknown mode is refused with a one-line ValueError. In a process of
    its own, as a batch job would run it: inductor's compile workers must not be forked
    from a test process that has loaded MPI (dolfinx) for the FEM tests."""
    run = subprocess.run([sys.executable, "-c", COMPILED_VS_TRACED], cwd=ROOT, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    out = json.loads(run.stdout.splitlines()[-1])
    assert "use one of trace, compile" in out["refused"] and "\n" not in out["refused"]
    traced, compiled = out["trace"], out["compile"]
    assert compiled["compiled"] and not traced["compiled"]
    assert traced["converged"] and compiled["converged"] and compiled["force_mN"] <= 1e-4
    np.testing.assert_allclose(compiled["tau"], traced["tau"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(compiled["residual"], traced["residual"], rtol=1e-12, atol=1e-12)
    assert compiled["slip"] == traced["slip"]


def test_newton_and_lbfgs_agree():
    """The paper's validation pressures (-0.1, 0.1) and (0.1, -0.1): L-BFGS (paper) and
    Newton-LM give the same tau to 1e-6 N / N·mm and the same tip to 1e-5 mm."""
    p = t([[-0.1, 0.1], [0.1, -0.1]])
    a = solve(GRAVITY, p)
    b = solve(GRAVITY, p, SolverOptions(method="lbfgs"))
    assert bool(a.converged.all()) and bool(b.converged.all())
    np.testing.assert_allclose(a.tau.numpy(), b.tau.numpy(), atol=1e-6)
    np.testing.assert_allclose(a.pose.tip_end.numpy(), b.pose.tip_end.numpy(), atol=1e-5)


def _numpy_equilibrium(p1: float, p2: float, kinematics: str = "tangent",
                       joint_weight: str = "lumped") -> tuple[np.ndarray, np.ndarray]:
    """Independent numpy/scipy implementation of the stand-in joint (arc-integrated, not
    the sinc-chord form), the chain and Equation 1 under gravity. A part leaves a joint
    along the chord of its last two anchors (tangent) or along the arc's end tangent, the
    analytic joint's cap face (cap); a joint's 0.09 N acts at its anchors' mean (lumped)
    or half at its proximal centre and half at its distal end (split)."""
    L, EI, cp, EA, h = 45.45, 3000.0, 333.0, 300.0, 4.545

    def anchors(P, F1, F2, M):
        """(10, 2) anchors and the end tangent angle of the joint's arcs."""
        pts, a, pos = [], 0.0, np.zeros(2)
        for k in range(10):
            kap = (M - cp * P + F2 * (L - (k + 0.5) * h)) / EI
            b = a + kap * h
            d = np.array([math.sin(b) - math.sin(a), math.cos(a) - math.cos(b)]) / kap if abs(kap) > 1e-14 \
                else h * np.array([math.cos(a), math.sin(a)])
            pos = pos + (1 + F1 / EA) * d
            pts.append(pos)
            a = b
        return np.array(pts), a

    def R(a):
        return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def exit_angle(A, cap):
        return cap if kinematics == "cap" else math.atan2(*(A[-1] - A[-2])[::-1])

    def chain(x):
        t1, t2 = x[:3], x[3:]
        (A1, c1), (A2, c2) = anchors(p1, *t1), anchors(p2, *t2)
        th1 = -math.pi / 2
        j1 = np.array([25.0, 0.0]) + A1 @ R(th1).T
        ph1 = th1 + exit_angle(A1, c1)
        link_end = j1[-1] + 60 * np.array([math.cos(ph1), math.sin(ph1)])
        j2 = link_end + A2 @ R(ph1).T
        ph2 = ph1 + exit_angle(A2, c2)
        tip_end = j2[-1] + 65 * np.array([math.cos(ph2), math.sin(ph2)])
        return j1, link_end, j2, tip_end, th1, ph1

    def eq(x):
        j1, link_end, j2, tip_end, th1, th2 = chain(x)
        # (point, weight N, reach: the load enters the balance of joints i < reach)
        loads = [((j1[-1] + link_end) / 2, 0.04, 1), ((j2[-1] + tip_end) / 2, 0.06, 2)]
        if joint_weight == "lumped":
            loads.append((j2.mean(0), 0.09, 1))
        else:   # joint 1's proximal half sits on the base; its distal half, zero arm
            loads += [(j1[-1], 0.045, 1), (link_end, 0.045, 1), (j2[-1], 0.045, 2)]
        out = []
        for i, (end, th) in enumerate(((j1[-1], th1), (j2[-1], th2))):
            F = R(th) @ x[3 * i:3 * i + 2]
            Fd = np.zeros(2)
            Md = 0.0
            for pt, w, reach in loads:
                if reach > i:
                    Fd += [0.0, -w]
                    Md += (pt - end)[0] * -w
            out += [*(F - Fd), x[3 * i + 2] - Md]
        return out

    x = fsolve(eq, np.zeros(6), xtol=1e-12)
    assert np.abs(eq(x)).max() < 1e-10
    return x.reshape(2, 3), chain(x)[3]


@pytest.mark.parametrize("chain", [("tangent", "lumped"), ("cap", "split")], ids=["paper", "default"])
@pytest.mark.parametrize("p1,p2", [(-0.1, 0.1), (0.1, -0.1), (0.25, 0.2), (-0.3, -0.05)])
def test_matches_independent_scipy_solution(p1, p2, chain):
    """tau and the fingertip from an independent numpy re-implementation solved by
    scipy.optimize.fsolve equal the torch Newton solution to 1e-7 (N, N·mm) and 1e-6 mm,
    for the paper's chain and for the default one (cap kinematics, split joint weights)."""
    tau, tip = _numpy_equilibrium(p1, p2, *chain)
    res = solve(GripperProblem(J, GripperParams(kinematics=chain[0], joint_weight=chain[1])), t([p1, p2]))
    np.testing.assert_allclose(res.tau[0].numpy(), tau, atol=1e-7)
    np.testing.assert_allclose(res.pose.tip_end[0].numpy(), tip, atol=1e-6)


class _LeftJoint(JointModel):
    """The physical left-finger joint seen in a chain frame whose +y is global +X (its
    top chamber is then on -y): R_L(P, F1, F2, M) = diag(1,-1)·R(P, F1, -F2, -M)."""

    name = "left"
    has_cap_rotation = True

    def __call__(self, inputs):
        return J(inputs * t([1.0, 1.0, -1.0, -1.0])) * t([1.0, -1.0])

    def anchors_and_cap(self, inputs):
        anchors, cap = J.anchors_and_cap(inputs * t([1.0, 1.0, -1.0, -1.0]))
        return anchors * t([1.0, -1.0]), -cap


def test_two_finger_mirror_symmetry():
    """Solving the LEFT finger directly (base at X = -25 mm, mirrored joint) gives the
    mirror of the right finger: tau_L = (F1, -F2, -M)_R and every point (-X, Y), to 1e-8."""
    p = t([[-0.1, 0.1], [0.2, 0.05]])
    right = solve(GRAVITY, p)
    left_finger = dataclasses.replace(default_finger(), base_gap=-50.0)
    left = solve(GripperProblem(_LeftJoint(), params=GripperParams(left_finger)), p)
    np.testing.assert_allclose(left.tau.numpy(), (right.tau * t([1.0, -1.0, -1.0])).numpy(), atol=1e-8)
    mirror = right.pose.mirrored()
    for name in ("joint1", "link", "joint2", "tip"):
        np.testing.assert_allclose(getattr(left.pose, name).numpy(), getattr(mirror, name).numpy(), atol=1e-8)


def test_gradcheck_residual_and_jacobian():
    """torch.autograd.gradcheck: d(residual)/d(tau, P) equals central finite differences
    (gravity, and contact with penetration); the solver's batched Jacobian equals
    torch.autograd.functional.jacobian of the eager residual to 1e-7 relative (it is central
    differences of the traced residual), and the traced residual equals the eager one."""
    p = t([[0.1, 0.2]])
    grasp = solve(GRASP, p)
    for problem, tau0 in ((GRAVITY, t([[[0.2, 0.01, -3.0], [0.05, -0.02, 0.4]]])), (GRASP, grasp.tau)):
        assert problem.obstacle is None or float(problem.residual(p, tau0).contact.normal[0]) > 0.1

        def f(tau, pp):
            return problem.residual(pp, tau).residual

        assert torch.autograd.gradcheck(f, (tau0.clone().requires_grad_(True), p.clone().requires_grad_(True)),
                                        eps=1e-7, atol=1e-5, rtol=1e-4)
        r_fn = residual_fn(problem)
        x0 = tau0.reshape(1, 6)
        Jmat, r0, Jp = jacobian_fn(problem)(x0, p)
        ref = torch.autograd.functional.jacobian(lambda x: r_fn(x, p)[0, :6], x0)[:, 0]
        ref_p = torch.autograd.functional.jacobian(lambda q: r_fn(x0, q)[0, :6], p)[:, 0]
        np.testing.assert_allclose(r0[0].numpy(), r_fn(x0, p)[0].numpy(), rtol=0, atol=1e-14)
        np.testing.assert_allclose(Jmat[0, :6].numpy(), ref.numpy(), atol=1e-7 * float(ref.abs().max()))
        np.testing.assert_allclose(Jp[0].numpy(), ref_p.numpy(), atol=1e-7 * float(ref_p.abs().max()))


def test_range_penalty_zero_inside_box():
    """Inside |F| <= 3 N, |M| <= 100 N·mm the penalty is exactly 0; at F1 = 3.5 N it is
    10·0.5 = 5 and at M = -150 N·mm it is 10·50/100 = 5."""
    inside = t([[[3.0, -3.0, 100.0], [0.0, 0.0, -100.0]]])
    assert float(range_penalty(inside).abs().max()) == 0.0
    out = range_penalty(t([[[3.5, 0.0, -150.0], [0.0, 0.0, 0.0]]]))
    np.testing.assert_allclose(out[0].numpy(), [5, 0, 5, 0, 0, 0], atol=1e-12)


# ---------------------------------------------------------------- contact
def test_signed_distances():
    """Exact values: circle r=30 at (0,-195): (40,-195) -> 10 mm, normal (1,0);
    rectangle 60x50 rotated 90°: (0,-195+40) -> 10 mm (its half width 30 now lies along
    Y); ellipse 35x25 boundary point (35, -195) -> 0 with normal (1, 0)."""
    c = Obstacle()
    d, n = c.signed_distance(t([[40.0, -195.0]]))
    assert abs(float(d[0]) - 10) < 1e-12 and np.allclose(n[0].numpy(), [1, 0])
    r = parse_object("rectangle:w=60,h=50,deg=90")
    d, _ = r.signed_distance(t([[0.0, -155.0], [0.0, -195.0]]))
    assert abs(float(d[0]) - 10) < 1e-9 and abs(float(d[1]) + 25) < 1e-9
    e = parse_object("ellipse")
    d, n = e.signed_distance(t([[35.0, -195.0], [0.0, -170.0]]))
    assert float(d.abs().max()) < 1e-12 and np.allclose(n.numpy(), [[1, 0], [0, 1]], atol=1e-12)


def test_object_spec_errors():
    """Unknown kinds and keys, a key given twice, a value that is not a finite number, a
    size <= 0 and an object the mirrored model cannot represent (off the axis X = 0, an
    asymmetric rotation, sizes or height beyond the bounds) are one-line ValueErrors naming
    the offending item; w/h are full sizes, a circle may turn (it stays symmetric)."""
    for bad, needle in (("blob", "'blob'"), ("circle:q=3", "'q=3'"), ("circle:r=abc", "r=abc"),
                        ("ellipse:a=-1", "a=-1"), ("circle:r=30,r=40", "'r' given twice"),
                        ("ellipse:a=35,b=25,a=30", "'a' given twice"), ("circle:r=nan", "r=nan"),
                        ("circle:y=inf", "y=inf"), ("rectangle:w=0", "w=0"), ("circle:r", "'r'"),
                        ("circle:x=15,r=20", "object centre x = 15 mm"), ("circle:x=-0.5", "x = -0.5 mm"),
                        ("ellipse:deg=20", "turned by 20 deg"), ("rectangle:deg=-45", "turned by -45 deg"),
                        ("circle:r=1e9", "half size 1e+09 mm"), ("rectangle:w=0.1", "half size 0.05 mm"),
                        ("ellipse:b=501", "half size 501 mm"), ("circle:y=-1001", "y = -1001 mm")):
        with pytest.raises(ValueError) as info:
            parse_object(bad)
        assert needle in str(info.value) and "\n" not in str(info.value), (bad, str(info.value))
    r = parse_object("rectangle:w=60,h=50,y=-200")
    assert (r.a, r.b, r.y) == (30.0, 25.0, -200.0)
    c = parse_object("circle:r=40, x=0,deg=33")
    assert (c.a, c.b, c.x, c.angle) == (40.0, 40.0, 0.0, math.radians(33))
    assert parse_object("ellipse:deg=-270").angle == math.radians(-270)   # symmetric about X = 0
    assert parse_object("rectangle:w=1000,h=1000,y=1000").radius == math.hypot(500, 500)
    with pytest.raises(ValueError, match="object centre x = 3 mm"):
        Obstacle(x=3.0)


def test_zero_contact_force_without_penetration():
    """An object that the finger does not reach (and one that exactly touches the straight
    finger's tip, d = 0) adds exactly zero force: the residual equals the object-free one."""
    p = t([[0.05, -0.1]])
    tau = t([[[0.2, 0.01, -3.0], [0.05, -0.02, 0.4]]])
    free = GRAVITY.residual(p, tau)
    for obs in (Obstacle(y=-400.0), Obstacle(kind="rectangle", a=30, b=25, y=-500.0)):
        st = GripperProblem(J, obstacle=obs).residual(p, tau)
        assert float(st.contact.normal[0]) == 0.0 and float(st.contact.forces.abs().max()) == 0.0
        assert torch.equal(st.residual, free.residual)
    straight = t([[0.0, 0.0]])
    tau0 = solve(GRAVITY, straight).tau
    tip_y = float(finger_pose(J, GripperParams(), straight, tau0).tip_end[0, 1])
    touching = Obstacle(kind="rectangle", a=40.0, b=10.0, y=tip_y - 10.0)
    assert float(GripperProblem(J, obstacle=touching).residual(straight, tau0).contact.normal[0]) == 0.0


def test_grasp_friction_cone_and_hold():
    """Grasp of the default circle at (0.1, 0.2) MPa from the approach gesture: converged,
    in contact (normal force 0.2-0.5 N), every contact point's friction |f_t| <= mu·f_n
    (mu = 0.3), the demanded ratio |λ| < 0.3, so no slip; residual <= 1e-4 mN."""
    res = solve(GRASP, t([0.1, 0.2]))
    assert bool(res.converged[0]) and 0.2 < float(res.normal_force_N[0]) < 0.5
    assert not bool(res.slip[0]) and abs(float(res.friction_ratio[0])) < 0.3
    assert float(res.residual_force_mN.max()) <= 1e-4
    st = GRASP.residual(res.pressures, res.tau).contact
    _, n = Obstacle().signed_distance(st.points)
    fn = (st.forces * n).sum(-1)
    ft = (st.forces - fn[..., None] * n).norm(dim=-1)
    assert bool((ft <= 0.3 * fn + 1e-12).all()) and float(fn.min()) >= 0.0


@pytest.mark.parametrize("kind", ["circle", "ellipse", "rectangle"])
def test_default_jacobian_gives_the_exact_jacobians_grasps(kind):
    """A contact solve's default Jacobian (central differences, the exact one only for
    samples that fail with them: solve.attempts) ends at the same equilibria as the exact
    Jacobian alone, on the committed surrogate: three pressure pairs that hold, slip and
    miss, the same grasp state and tau to 1e-6 N / N·mm (the solver's 1e-7 N tolerance)."""
    from predictor.atlas import classify, load_problem

    problem = load_problem(str(ROOT / "results/surrogate/improved.pt"), kind)
    p = t([[0.25, 0.14], [0.12, -0.04], [-0.1, 0.0]])
    auto, exact = solve(problem, p), solve(problem, p, SolverOptions(jacobian="exact"))
    assert bool(auto.converged.all()) and bool(exact.converged.all())
    assert classify(auto, 0.3)[0].tolist() == classify(exact, 0.3)[0].tolist() == [1, 2, 0]
    assert torch.allclose(auto.tau, exact.tau, rtol=0, atol=1e-6)


def test_slip_flagged_when_mu_too_small():
    """The (0.2, 0.1) MPa grasp demands |λ| ≈ 0.2: it holds at mu = 0.3 and is flagged as
    slipping at mu = 0.1, with friction clipped to exactly mu·N = 0.1·N."""
    p = t([0.2, 0.1])
    hold = solve(GRASP, p)
    slip = solve(GripperProblem(J, obstacle=Obstacle(), contact=ContactParams(mu=0.1), approach=APPROACH), p)
    assert bool(hold.converged[0]) and bool(slip.converged[0])
    assert 0.1 < abs(float(hold.friction_ratio[0])) < 0.3 and not bool(hold.slip[0])
    assert bool(slip.slip[0])
    assert abs(float(slip.friction_N[0]) - 0.1 * float(slip.normal_force_N[0])) < 1e-12


def test_object_below_tips_slips():
    """The paper-like placement (circle centre 235 mm below the base, ramp from 0 with the
    object present): zero pressure is contact-free, and closing (0.1, 0.1) MPa touches only
    the object's upper shoulder, where mu = 0.3 cannot carry 0.1 N: slip is reported."""
    below = GripperProblem(J, obstacle=parse_object("circle:y=-235"))
    assert float(solve(below, t([0.0, 0.0])).normal_force_N[0]) == 0.0
    res = solve(below, t([0.1, 0.1]))
    assert bool(res.converged[0]) and float(res.normal_force_N[0]) > 0 and bool(res.slip[0])


def test_nonconverged_is_not_an_answer():
    """With a 1-iteration budget the gravity solve at (0.3, -0.3) cannot reach 1e-4 mN:
    converged is False and tau and the gesture are NaN, never a number."""
    res = solve(GRAVITY, t([0.3, -0.3]), SolverOptions(max_iter=1))
    assert not bool(res.converged[0])
    assert bool(torch.isnan(res.tau).all()) and bool(torch.isnan(res.pose.tip).all())


def test_pressure_out_of_range_refused():
    """|P| > 0.3 MPa is outside the surrogate's box, and NaN or inf is not a number:
    fem.spec.OutOfBoxError (a ValueError) naming the value and the allowed 0.3 MPa, for the
    target pressures and for the approach pressures alike."""
    for p, needle in (([0.31, 0.0], "P1 = 0.31 is outside"), ([0.0, float("nan")], "P2 = nan is not a finite"),
                      ([float("-inf"), 0.0], "P1 = -inf is not a finite")):
        with pytest.raises(OutOfBoxError, match=needle) as info:
            solve(GRAVITY, t(p))
        assert "|P1| <= 0.3 MPa" in str(info.value)
    with pytest.raises(OutOfBoxError, match="P2 = -0.4 is outside"):
        GripperProblem(J, obstacle=Obstacle(), approach=(0.0, -0.4))


# ---------------------------------------------------------------- result objects
def _hand_mirrored(pose):
    """A hand-written mirror of every FingerPose field (the reference for the generic one)."""
    flip = torch.tensor([-1.0, 1.0], dtype=pose.joints.dtype)
    return FingerPose(pose.joints * flip, pose.segments * flip, math.pi - pose.theta, math.pi - pose.phi,
                      pose.points * flip, pose.finger)


def test_finger_pose_mirrored_and_masked():
    """mirrored() equals the hand-written mirror bit for bit (X -> -X for points, a -> pi - a
    for theta and phi) in every tensor field, and so do the paper layout's views (joint1,
    link, joint2, tip, link_points, tip_points); mirrored twice is the identity (to 1 ulp of
    pi for angles, exactly for points); masked(ok) is NaN in every tensor field exactly on
    the rows where ok is False and unchanged on the others; with_rows takes exactly the
    given rows; the finger (static) is carried along unchanged."""
    p = t([[-0.1, 0.1], [0.2, 0.05], [0.05, -0.2]])
    pose = solve(GRAVITY, p).pose
    names = [f.name for f in dataclasses.fields(FingerPose) if not f.metadata.get("static")]
    assert names == ["joints", "segments", "theta", "phi", "points"]
    assert pose.joints.shape == (3, 2, 11, 2) and pose.segments.shape == (3, 2, 2, 2)
    assert pose.points.shape == (3, 87, 2)
    mirror, hand = pose.mirrored(), _hand_mirrored(pose)
    assert mirror.finger is pose.finger
    for name in names:
        assert torch.equal(getattr(mirror, name), getattr(hand, name)), name
        assert not torch.equal(getattr(mirror, name), getattr(pose, name)), name
        np.testing.assert_allclose(getattr(mirror.mirrored(), name).numpy(), getattr(pose, name).numpy(),
                                   rtol=0, atol=1e-15 if name in ("theta", "phi") else 0)
    flip = t([-1.0, 1.0])
    for view in ("joint1", "link", "joint2", "tip", "link_points", "tip_points", "tip_end"):
        assert torch.equal(getattr(mirror, view), getattr(pose, view) * flip), view
    assert pose.link_points.shape == (3, 12, 2) and pose.tip_points.shape == (3, 65, 2)
    ok = torch.tensor([True, False, True])
    masked = pose.masked(ok)
    for name in names:
        v, m = getattr(pose, name), getattr(masked, name)
        assert m.shape == v.shape and bool(torch.isnan(m[1]).all()), name
        assert torch.equal(m[ok], v[ok]), name
    rows = torch.tensor([False, True, False])
    other = pose.mirrored()
    swapped = pose.with_rows(rows, other.rows(rows))
    for name in names:
        assert torch.equal(getattr(swapped, name)[1], getattr(other, name)[1]), name
        assert torch.equal(getattr(swapped, name)[~rows], getattr(pose, name)[~rows]), name


def test_gesture_result_summary_and_rows():
    """summary(i) is plain JSON with the figures of sample i (tau 2x3 and the tip only when
    converged, degrees for the tip angle); with_rows takes every solved field of the
    replaced rows from the other result and keeps the pressures, the time
    and the method."""
    p = t([[-0.1, 0.1], [0.3, -0.3]])
    good = solve(GRAVITY, p)
    bad = solve(GRAVITY, p, SolverOptions(max_iter=1))
    assert bool(good.converged.all()) and not bool(bad.converged[1])
    s0 = good.summary(0)
    assert json.loads(json.dumps(s0)) == s0
    assert list(s0) == ["pressures_MPa", "converged", "state", "tau", "residual_force_mN", "residual_moment_Nmm",
                        "tip", "tip_angle_deg", "contact_force_N", "friction_N", "friction_use", "slip", "iterations",
                        "joint", "mu", "object_weight_N"]
    assert s0["pressures_MPa"] == [-0.1, 0.1] and s0["converged"] is True and s0["state"] == "no_contact"
    assert s0["slip"] is None and s0["friction_use"] is None and s0["joint"] == J.name and s0["mu"] is None
    assert s0["tau"] == good.tau[0].tolist() and s0["tip"] == good.pose.tip_end[0].tolist()
    assert s0["tip_angle_deg"] == math.degrees(float(good.pose.phi[0, 1])) and s0["iterations"] == good.iterations[0]
    s1 = bad.summary(1)
    assert s1["converged"] is False and s1["tau"] is None and s1["tip"] is None and s1["tip_angle_deg"] is None
    assert s1["state"] == "not_converged" and s1["contact_force_N"] is None and s1["friction_N"] is None
    rows = torch.tensor([False, True])
    sub = solve(GRAVITY, p[rows])
    mixed = bad.with_rows(rows, sub)
    assert mixed.converged.tolist() == [bool(bad.converged[0]), True] and torch.equal(mixed.tau[1], sub.tau[0])
    assert torch.equal(mixed.pose.tip[1], sub.pose.tip[0]) and torch.equal(mixed.iterations[1], sub.iterations[0])
    np.testing.assert_array_equal(mixed.pose.tip[0].numpy(), bad.pose.tip[0].numpy())  # NaN == NaN here
    assert mixed.pressures is bad.pressures
    assert (mixed.time_ms, mixed.method) == (bad.time_ms, bad.method)
    for f in dataclasses.fields(GestureResult):
        if isinstance(getattr(bad, f.name), torch.Tensor) and not f.metadata.get("given"):
            assert torch.equal(getattr(mixed, f.name)[1], getattr(sub, f.name)[0]), f.name


# ---------------------------------------------------------------- NN and CLI
def test_nn_training_reduces_equilibrium_residual():
    """Two epochs of the paper's gravity NN on 400 pairs (equilibrium loss, no labels) cut
    the mean validation force residual below 1/3 of the untrained network's."""
    from predictor.networks import GestureNet, NNConfig
    from predictor.nn_eval import evaluate
    from predictor.nn_train import train

    cfg = NNConfig(n_train=400, n_val=100, epochs=2, lr=3e-3)
    torch.manual_seed(cfg.seed)
    before = evaluate(GestureNet(cfg.widths, cfg.activation), GRAVITY, torch.rand(100, 2, dtype=DT) * 0.6 - 0.3)
    pred = train(cfg, J)
    assert pred.metrics["val"]["force_mN_mean"] < before["force_mN_mean"] / 3


def test_correction_stage_cuts_a_fitted_heads_error_fourfold():
    """Multi-stage training (predictor.nn_train.fit_stage) on labels with an exact solution,
    tau(P) = (sin 3P1 cos 2P2, P1 P2, 20 tanh(P1 - P2)) per joint (the second joint's
    halved): a small head fitted by Adam and L-BFGS leaves an error e; the correction
    stage's tau_scale is e's RMS per output, and head + stage leave less than a quarter
    of e's RMS in every output, on the training pressures and on 300 others (0.11-0.17
    on the others when written)."""
    from predictor.networks import VARIANTS, network
    from predictor.nn_train import fit, fit_stage

    def exact(p):
        one = torch.stack((torch.sin(3 * p[:, 0] / 0.3) * torch.cos(2 * p[:, 1] / 0.3), p[:, 0] * p[:, 1] / 0.09,
                           20 * torch.tanh((p[:, 0] - p[:, 1]) / 0.3)), -1)
        return torch.stack((one, 0.5 * one), 1)

    cfg = dataclasses.replace(VARIANTS["contact"], widths=(2, 24, 24, 6), refine_hidden=(24, 24), refine_stages=1,
                              abs_pressure=False,
                              epochs=40, batch=50, lbfgs_iters=400, refine_epochs=40, refine_lbfgs_iters=400)
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    net = network(cfg)
    p, q = ((2 * torch.rand(n, 2, generator=gen, dtype=DT) - 1) * 0.3 for n in (600, 300))
    scale = torch.tensor([1.0, 1.0, 30.0], dtype=DT)
    fit(net.heads[1], lambda i: ((net.heads[1](p if i is None else p[i]) - exact(p if i is None else p[i]))
                                  / scale).pow(2).sum((-1, -2)).mean(), len(p), cfg, gen)
    rms = lambda x, stages: (net.head_tau(1, x, stages) - exact(x)).pow(2).mean(0).sqrt()  # noqa: E731
    with torch.no_grad():
        before_p, before_q = rms(p, 0), rms(q, 0)
    fit_stage(net, 1, 0, p, exact(p), cfg, gen)
    with torch.no_grad():
        assert torch.allclose(net.refine[1][0].tau_scale, before_p.flatten(), rtol=1e-12, atol=0)
        assert bool((rms(p, None) < before_p / 4).all()) and bool((rms(q, None) < before_q / 4).all())


def test_nn_checkpoint_round_trip_and_refusals(tmp_path):
    """save_predictor/load_predictor return the same network bit for bit (outputs on 500
    pressures torch.equal); the file is the gravity kind (no object), so loading it as a
    contact predictor is refused by name, as are a flipped byte, a plain torch.save file,
    a joint other than the one it was trained on, and a query with an object: each a
    one-line ValueError."""
    from predictor.networks import NNConfig
    from predictor.nn_answer import predict_gesture
    from predictor.nn_checkpoint import GRAVITY_FORMAT, load_predictor, save_predictor
    from predictor.nn_train import train

    pred = train(NNConfig(n_train=100, n_val=20, epochs=1), J)
    path = tmp_path / "g.pt"
    save_predictor(pred, path)
    assert path.read_bytes().startswith(b'{"bytes":') and GRAVITY_FORMAT.encode() in path.read_bytes()[:200]
    back = load_predictor(path, J)
    p = torch.rand(500, 2, dtype=DT) * 0.6 - 0.3
    with torch.no_grad():
        assert torch.equal(back.net(p), pred.net(p))
    assert back.config == pred.config and back.joint_name == "analytic" and back.history == pred.history
    data = path.read_bytes()
    bad = tmp_path / "bad.pt"
    for damaged, needle in ((data[:100] + bytes([data[100] ^ 1]) + data[101:], "damaged"),
                            (data[:-1], "damaged")):
        bad.write_bytes(damaged)
        with pytest.raises(ValueError, match=needle):
            load_predictor(bad, J)
    torch.save({"config": {}}, bad)
    for call, needle in ((lambda: load_predictor(path, J, contact=True), "softjoint-gravity-nn/1"),
                         (lambda: load_predictor(bad, J), "no valid checkpoint header"),
                         (lambda: load_predictor(path, _LeftJoint()), "trained with joint"),
                         (lambda: predict_gesture(back, GRASP, p), "trained for obstacle None")):
        with pytest.raises(ValueError, match=needle) as info:
            call()
        assert "\n" not in str(info.value)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "predictor.gesture", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)


def test_cli_json_and_errors():
    """--json prints the issue's keys (converged true, tau 2x3, per-joint residuals, tip)
    and exits 0; |P| > 0.3, an unknown object and a missing model exit 2 with one
    'error:' line on stderr."""
    ok = _cli("--p1", "-0.1", "--p2", "0.1", "--model", "analytic", "--json")
    assert ok.returncode == 0, ok.stderr
    out = json.loads(ok.stdout)
    for key in ("converged", "tau", "residual_force_mN", "residual_moment_Nmm", "tip", "tip_angle_deg",
                "contact_force_N", "slip", "iterations", "time_ms"):
        assert key in out
    assert out["converged"] and np.array(out["tau"]).shape == (2, 3) and len(out["residual_force_mN"]) == 2
    for args in (("--p1", "0.5", "--p2", "0"), ("--p1", "0", "--p2", "0", "--object", "blob"),
                 ("--p1", "0", "--p2", "0", "--model", "/nonexistent.pt")):
        bad = _cli(*args)
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1, bad.stderr
        assert bad.stderr.startswith("python -m predictor.gesture: error:"), bad.stderr


SURROGATE = ROOT / "results/surrogate/improved.pt"


@pytest.mark.skipif(not SURROGATE.is_file(), reason="no committed surrogate checkpoint yet")
def test_real_surrogate_gravity_gesture():
    """With the trained surrogate the gravity gesture at (-0.1, 0.1) converges to the same
    tolerance (|R_F| <= 1e-4 mN, |R_M| <= 1e-5 N·mm) and tau is inside the box."""
    joint = load_joint(str(SURROGATE))
    res = solve(GripperProblem(joint), t([[-0.1, 0.1], [0.1, -0.1]]))
    assert bool(res.converged.all())
    assert float(res.residual_force_mN.max()) <= 1e-4 and float(res.residual_moment_Nmm.max()) <= 1e-5
    assert float(res.tau[..., :2].abs().max()) <= 3 and float(res.tau[..., 2].abs().max()) <= 100


def test_surrogate_joint_wrapper_with_a_fitted_surrogate(tmp_path):
    """A small surrogate (issue 4's JointSurrogate) fitted for a few seconds to the analytic
    joint, saved and loaded through SurrogateJoint: the gravity gesture at (-0.1, 0.1)
    converges to the solver tolerance and its tip lies within 3 mm of the analytic one;
    a corrupt file is a one-line ValueError."""
    model_mod = pytest.importorskip("surrogate.model")
    from predictor.joint import SurrogateJoint

    torch.manual_seed(0)
    box = t(INPUT_BOX)
    x = (torch.rand(1000, 4, dtype=DT) * 2 - 1) * box * t([1.0, 0.3, 0.3, 0.3])
    y = J(x).reshape(-1, 20)
    norm = {"input_scale": box.tolist(), "output_mean": y.mean(0).tolist(), "output_scale": y.std(0).tolist()}
    net = model_mod.JointSurrogate(model_mod.ModelConfig(hidden=(32, 32), activation="tanh"), norm).double()
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    for _ in range(400):
        opt.zero_grad()
        lossv = (net(x).reshape(-1, 20) - y).pow(2).mean()
        lossv.backward()
        opt.step()
    path = tmp_path / "fit.pt"
    model_mod.save_checkpoint(path, net, {}, {}, {})
    res = solve(GripperProblem(SurrogateJoint(path), PAPER_CHAIN), t([-0.1, 0.1]))   # no cap head: tangent
    ref = solve(GripperProblem(J, PAPER_CHAIN), t([-0.1, 0.1]))
    assert bool(res.converged[0]) and float(res.residual_force_mN.max()) <= 1e-4
    assert float((res.pose.tip_end - ref.pose.tip_end).norm()) < 3.0
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError):
        SurrogateJoint(bad)


def test_import_predictor_does_not_import_dolfinx():
    """Dependencies run downward and the predictor is FEM-free: importing every predictor
    module leaves 'dolfinx' out of sys.modules."""
    code = ("import sys, predictor.joint, predictor.gripper, predictor.statics, predictor.solve, predictor.nn, "
            "predictor.gesture, predictor.figures, predictor.bench; print('dolfinx' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr


GRAVITY_NN = ROOT / "results/predictor/gravity_nn.pt"


@pytest.mark.skipif(not GRAVITY_NN.is_file(), reason="no trained NN predictor (make gestures)")
def test_nn_predictor_cli_matches_solver():
    """--method nn with the committed gravity NN at (-0.1, 0.1), on the joint model it was
    trained on (analytic or the committed surrogate): converged (residual within 2 mN /
    1.2 N·mm), tau within 0.01 N / 1 N·mm of the Newton solution and its raw residual is
    its residual (no solver); with the contact NN at (0.1, 0.2) on the circle the answer is
    the solver's polish (or the ramp's) within 1e-4 mN, and the raw network's larger
    residual is reported beside it."""
    from predictor.nn_checkpoint import load_predictor

    trained_on = load_predictor(GRAVITY_NN).joint_name
    model = "analytic" if trained_on == "analytic" else str(SURROGATE)
    if model != "analytic" and not (SURROGATE.is_file() and load_joint(model).name == trained_on):
        pytest.skip(f"NN trained on joint model {trained_on!r}, not the committed one")
    out = _cli("--p1", "-0.1", "--p2", "0.1", "--model", model, "--method", "nn", "--json")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    ref = solve(GripperProblem(load_joint(model)), t([-0.1, 0.1])).tau[0].numpy()
    assert got["converged"] and max(got["residual_force_mN"]) <= 2.0
    np.testing.assert_allclose(np.array(got["tau"])[:, :2], ref[:, :2], atol=0.01)
    np.testing.assert_allclose(np.array(got["tau"])[:, 2], ref[:, 2], atol=1.0)
    # gravity: the answer is the network's own, so its raw residual is the residual
    assert (got["raw_residual_force_mN"], got["raw_residual_moment_Nmm"]) == \
        (got["residual_force_mN"], got["residual_moment_Nmm"])
    assert not got["polished"] and not got["fallback"]
    # gravity, --polish: one Newton step from the same tau reaches the solver's tolerance
    # and the cold solve's tau; the raw figures are the network's, as above
    out = _cli("--p1", "-0.1", "--p2", "0.1", "--model", model, "--method", "nn", "--polish", "--json")
    assert out.returncode == 0, out.stderr
    pol = json.loads(out.stdout)
    assert pol["converged"] and pol["polished"] and max(pol["residual_force_mN"]) <= 1e-4
    np.testing.assert_allclose(np.array(pol["tau"]), ref, atol=1e-6)
    assert pol["raw_residual_force_mN"] == pytest.approx(got["raw_residual_force_mN"], rel=1e-9, abs=1e-12)
    # contact: the raw network's residual is reported beside the polished answer's
    out = _cli("--p1", "0.1", "--p2", "0.2", "--object", "circle", "--model", model, "--method", "nn", "--json")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["polished"] != got["fallback"] and max(got["residual_force_mN"]) <= 1e-4
    assert len(got["raw_residual_force_mN"]) == 2 and max(got["raw_residual_force_mN"]) > max(got["residual_force_mN"])


@pytest.mark.skipif(not (SURROGATE.is_file() and GRAVITY_NN.is_file()), reason="no committed surrogate and NN")
def test_float32_batched_gravity_nn_agrees_with_float64():
    """The float32 throughput mode (Predictor.astype, GripperProblem.astype) on 2,000
    pressures of the committed gravity NN's domain: computed in float32 throughout, and
    against float64 the same samples pass the NN bound, tau agrees to 1e-4 N / N·mm, the
    fingertip to 1e-3 mm and the residuals to 1e-3 mN / N·mm (float32's 6e-8 relative
    rounding on ~200 mm and ~1 N is 1e-5 of those)."""
    from predictor.networks import sample_pressures
    from predictor.nn_answer import predict_gesture
    from predictor.nn_checkpoint import load_predictor

    pred = load_predictor(GRAVITY_NN, load_joint(SURROGATE))
    if pred.joint_name != load_joint(SURROGATE).name:
        pytest.skip("the gravity NN was trained on another joint model")
    problem = pred.config.problem(load_joint(SURROGATE))
    p = sample_pressures(2000, pred.config, torch.Generator().manual_seed(11))
    a = predict_gesture(pred, problem, p)
    b = predict_gesture(pred.astype(torch.float32), problem.astype(torch.float32), p.float())
    assert b.tau.dtype == b.pose.tip_end.dtype == b.residual_force_mN.dtype == torch.float32
    assert torch.equal(a.converged, b.converged) and int(a.converged.sum()) >= 1990
    ok = a.converged
    assert float((a.tau[ok] - b.tau[ok].double()).abs().max()) <= 1e-4
    assert float((a.pose.tip_end[ok] - b.pose.tip_end[ok].double()).abs().max()) <= 1e-3
    assert float((a.residual_force_mN - b.residual_force_mN.double()).abs().max()) <= 1e-3
    assert float((a.residual_moment_Nmm - b.residual_moment_Nmm.double()).abs().max()) <= 1e-3
    # the analytic joint follows its inputs' dtype: its float32 anchors are float64's to 1e-4 mm
    inputs = t([[0.2, 1.0, -2.0, 50.0], [-0.3, -3.0, 3.0, -100.0]])
    a32 = AnalyticJoint().astype(torch.float32)(inputs.float())
    assert a32.dtype == torch.float32 and float((a32.double() - J(inputs)).abs().max()) <= 1e-4


# ---------------------------------------------------------------- issue 14: the generic finger chain
REFERENCE = ROOT / "tests/data/predictor_reference.json"
THREE = """
format = "softjoint-finger/1"
name = "three"
base_gap = 50.0
base_angle_deg = -90.0

[[part]]
kind = "joint"
weight = 0.09
contact = false

[[part]]
kind = "rigid"
length = 40.0
weight = 0.03
contact_points = 8

[[part]]
kind = "joint"
weight = 0.08
contact = true

[[part]]
kind = "rigid"
length = 35.0
weight = 0.025
contact_points = 7

[[part]]
kind = "joint"
weight = 0.07
contact = true

[[part]]
kind = "rigid"
length = 45.0
weight = 0.04
contact_points = 45
"""
THREE_FINGER = parse_finger(THREE, "three.toml")
THREE_P = t([[0.1, -0.05, 0.2], [-0.2, 0.15, 0.05], [0.05, 0.1, -0.1]])


def _reference_problem(joint, case: str) -> GripperProblem:
    return {"gravity": GripperProblem(joint, PAPER_CHAIN), "free": GripperProblem(joint, PAPER_CHAIN, gravity=False),
            "circle": GripperProblem(joint, PAPER_CHAIN, obstacle=Obstacle(), approach=APPROACH)}[case]


@pytest.mark.parametrize("model", ["analytic", "results/surrogate/paper.pt"])
def test_paper_finger_reproduces_the_frozen_predictor(model):
    """The paper's finger (fem/fingers/paper.toml) through the generic chain, with tangent
    kinematics and lumped weights, reproduces the predictor as it was before issue 14 (its
    hard-wired joint-link-joint-tip chain, frozen at commit bbc0df4 into
    tests/data/predictor_reference.json by tests/data/freeze_predictor_reference.py), on
    the analytic joint and on the committed paper surrogate: gravity at (-0.1, 0.1) and (0.1, -0.1) MPa, no gravity at (0.1, 0.1) and one
    circle grasp from the approach gesture. tau to 1e-9 N / N·mm, the tip and every pose
    point (both joints, link, tip, contact sample points) to 1e-9 mm, the angles to
    1e-10 rad (the last Newton iterate moves by ~1e-12 with the solver's Jacobian, which
    is now central differences), the same iteration count of the LM (the solver it was
    frozen with; without an object ``newton`` is now Newton steps, checked against the LM
    in test_newton_steps_reach_the_lm_equilibria), and at a fixed off-equilibrium tau the
    Equation-1 residual and the contact forces to 1e-9 N / N·mm."""
    ref = json.loads(REFERENCE.read_text())["models"][model]
    if model != "analytic" and not (ROOT / model).is_file():
        pytest.skip("no committed surrogate checkpoint")
    joint = load_joint(model if model == "analytic" else str(ROOT / model))
    assert joint.name == ref["joint"], "the paper surrogate changed: freeze the reference again"
    for case in ref["cases"]:
        problem = _reference_problem(joint, case["case"])
        res = solve(problem, t([case["pressures_MPa"]]), SolverOptions(method="lm"))
        assert bool(res.converged[0]) and int(res.iterations[0]) == case["iterations"], case["case"]
        np.testing.assert_allclose(res.tau[0].numpy(), case["tau"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.pose.tip_end[0].numpy(), case["tip"], rtol=0, atol=1e-9)
        assert abs(float(res.pose.tip_angle[0]) - case["tip_angle_rad"]) <= 1e-10
        for name, value in case["pose"].items():
            atol = 1e-10 if name in ("theta", "phi") else 1e-9
            np.testing.assert_allclose(getattr(res.pose, name)[0].numpy(), np.array(value), rtol=0, atol=atol,
                                       err_msg=f"{case['case']} {name}")
        st = problem.residual(res.pressures, t([case["tau_off"]]))
        np.testing.assert_allclose(st.residual[0].numpy(), case["residual_off"], rtol=0, atol=1e-9)
        if case["contact_forces_off"] is not None:
            np.testing.assert_allclose(st.contact.forces[0].numpy(), case["contact_forces_off"], rtol=0, atol=1e-9)
            assert st.contact.part.tolist() == [1] * 12 + [2] * 10 + [3] * 65


GESTURES = ROOT / "results/predictor/gestures.json"


@pytest.mark.skipif(not (GESTURES.is_file() and SURROGATE.is_file()), reason="no committed gestures / surrogate")
def test_committed_gestures_unchanged():
    """Every case of the committed results/predictor/gestures.json (make gestures: gravity,
    free and the six grasps), recomputed by today's predictor on the joint it names, has
    the same convergence, iterations and slip flag, and tau, tip (mm) and tip angle (deg)
    within 1e-9 of the committed figures."""
    from predictor.figures import GRASPS

    doc = json.loads(GESTURES.read_text())
    joint = load_joint(str(SURROGATE))
    if joint.name != doc["joint"]:
        pytest.skip(f"gestures.json is of joint {doc['joint']}, the committed surrogate is {joint.name}")
    groups = [(GripperProblem(joint), doc["gravity"]), (GripperProblem(joint, gravity=False), doc["free"])]
    groups += [(GripperProblem(joint, obstacle=parse_object(kind), approach=APPROACH), doc["grasps"][kind])
               for kind in GRASPS]
    for problem, rows in groups:
        res = solve(problem, t([r["pressures_MPa"] for r in rows]))
        for i, row in enumerate(rows):
            now, row = res.summary(i), _current_keys(row)
            for key in ("converged", "iterations", "slip", "state"):
                assert now[key] == row[key], (row["pressures_MPa"], key)
            for key in ("tau", "tip", "tip_angle_deg", "contact_force_N", "friction_use"):
                np.testing.assert_allclose(np.array(now[key], dtype=float), np.array(row[key], dtype=float),
                                           rtol=0, atol=1e-9, err_msg=f"{row['pressures_MPa']} {key}")


def _current_keys(row: dict, mu: float = 0.3) -> dict:
    """A gestures.json case in today's keys: files written before issue 33 carry the
    signed friction_ratio lambda and slip even where nothing touches (state, friction_use
    = |lambda|/mu and slip are then derived; mu was always 0.3); newer ones pass through."""
    if "state" in row:
        return row
    touching = row["converged"] and row["contact_force_N"] > 0
    state = ("not_converged" if not row["converged"] else "no_contact" if not touching
             else "slips" if row["slip"] else "holds")
    return {**row, "state": state, "slip": row["slip"] if touching else None,
            "friction_use": abs(row["friction_ratio"]) / mu if touching else None}


def _closed_form_tip(finger, pressures, cap: bool):
    """Independent chain of the analytic joint without loads (numpy): each joint is a
    circular arc of curvature k = -c_p P / EI and length L, its end at (sin kL, 1 - cos kL)/k
    in its frame; a part leaves it at theta + k·9.5·L/10 (tangent: the chord of anchors 9
    and 10, whose arc angles are k·9L/10 and k·L) or theta + k·L (cap: the end section).
    Returns (tip (2,), tip angle) mm, rad."""
    EI, cp, L = 3000.0, 333.0, 45.45
    pos, a, j = np.array([0.5 * finger.base_gap, 0.0]), finger.base_angle, 0
    for part in finger.parts:
        if part.kind == "joint":
            k = -cp * pressures[j] / EI
            j += 1
            local = np.array([math.sin(k * L) / k, (1 - math.cos(k * L)) / k]) if k else np.array([L, 0.0])
            pos = pos + np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]) @ local
            a = a + k * (L if cap else 0.95 * L)
        else:
            pos = pos + part.length * np.array([math.cos(a), math.sin(a)])
    return pos, a


@pytest.mark.parametrize("kinematics", ["tangent", "cap"])
def test_three_joint_finger_free_matches_closed_form_chain(kinematics):
    """A joint-rigid-joint-rigid-joint-rigid finger (TOML above) on the analytic joint,
    without gravity and object: the solve returns tau = 0 exactly (0 iterations) and the
    fingertip and tip angle equal the independent closed-form chain (_closed_form_tip) to
    1e-9 mm / 1e-12 rad, for tangent and cap kinematics; the per-joint exit angles are
    theta_i + the closed-form joint turn."""
    params = GripperParams(THREE_FINGER, kinematics=kinematics)
    res = solve(GripperProblem(J, params, gravity=False), THREE_P)
    assert bool(res.converged.all()) and res.tau.shape == (3, 3, 3)
    assert float(res.tau.abs().max()) == 0.0 and int(res.iterations.max()) == 0
    for i, p in enumerate(THREE_P.tolist()):
        tip, angle = _closed_form_tip(THREE_FINGER, p, kinematics == "cap")
        np.testing.assert_allclose(res.pose.tip_end[i].numpy(), tip, rtol=0, atol=1e-9)
        assert abs(float(res.pose.tip_angle[i]) - angle) <= 1e-12
        turn = -333.0 * np.array(p) / 3000.0 * 45.45 * (1.0 if kinematics == "cap" else 0.95)
        np.testing.assert_allclose((res.pose.phi[i] - res.pose.theta[i]).numpy(), turn, rtol=0, atol=1e-12)
    assert res.pose.joints.shape == (3, 3, 11, 2) and res.pose.segments.shape == (3, 3, 2, 2)
    assert res.pose.points.shape == (3, 8 + 10 + 7 + 10 + 45, 2)
    with pytest.raises(ValueError, match="another chain"):
        res.pose.link  # noqa: B018 (the paper's names do not apply to this chain)


def _three_joint_checks(joint, kinematics="tangent"):
    params = GripperParams(THREE_FINGER, kinematics=kinematics)
    grav = solve(GripperProblem(joint, params), THREE_P)
    assert bool(grav.converged.all())
    assert float(grav.residual_force_mN.max()) <= 1e-4 and float(grav.residual_moment_Nmm.max()) <= 1e-5
    assert float(grav.tau[..., :2].abs().max()) <= 3 and float(grav.tau[..., 2].abs().max()) <= 100
    r = GripperProblem(joint, params).residual(THREE_P, grav.tau).residual  # recomputed, not the solver's figure
    assert float(r[..., :2].norm(dim=-1).max()) * 1e3 <= 1e-4 and float(r[..., 2].abs().max()) <= 1e-5
    # mirror: P -> -P mirrors the finger about its own axis X = base_gap/2 (angles a -> -pi - a)
    axis = 0.5 * THREE_FINGER.base_gap
    for gravity, tol in ((False, 1e-9), (True, 1e-6)):
        prob = GripperProblem(joint, params, gravity=gravity)
        a, b = solve(prob, THREE_P), solve(prob, -THREE_P)
        assert bool(a.converged.all()) and bool(b.converged.all())
        if not gravity:
            assert float(a.tau.abs().max()) == 0.0
        np.testing.assert_allclose(b.tau.numpy(), (a.tau * t([1.0, -1.0, -1.0])).numpy(), rtol=0, atol=tol)
        for name in ("joints", "segments", "points"):
            va, vb = getattr(a.pose, name), getattr(b.pose, name)
            np.testing.assert_allclose(vb[..., 0].numpy(), (2 * axis - va[..., 0]).numpy(), rtol=0, atol=tol)
            np.testing.assert_allclose(vb[..., 1].numpy(), va[..., 1].numpy(), rtol=0, atol=tol)
        for name in ("theta", "phi"):
            np.testing.assert_allclose(getattr(b.pose, name).numpy(), (-math.pi - getattr(a.pose, name)).numpy(),
                                       rtol=0, atol=tol)
    return grav


def test_three_joint_finger_on_the_analytic_joint():
    """The three-joint finger under gravity on the analytic joint, tangent and cap
    kinematics: converged for the three pressure triples, residual recomputed from
    Equation 1 <= 1e-4 mN and 1e-5 N·mm, tau inside the box; P -> -P gives the finger
    mirrored about its own axis X = 25 mm (tau -> (F1, -F2, -M)), to 1e-9 without gravity
    and to 1e-6 (the solver tolerance) with it."""
    for kinematics in ("tangent", "cap"):
        _three_joint_checks(J, kinematics)


@pytest.mark.skipif(not SURROGATE.is_file(), reason="no committed surrogate checkpoint yet")
def test_three_joint_finger_with_the_surrogate():
    """The same surrogate serves a three-joint finger with no retraining: the gravity solve
    of the three pressure triples converges with the recomputed residual <= 1e-4 mN and
    1e-5 N·mm and tau inside the box; without gravity tau = 0; P -> -P mirrors the finger
    about its own axis (the equivariant surrogate is exactly symmetric): to 1e-9 mm without
    gravity and 1e-6 with it. A grasp of the default circle by the three-joint gripper from
    its approach gesture converges too."""
    joint = load_joint(str(SURROGATE))
    _three_joint_checks(joint)
    grasp = GripperProblem(joint, GripperParams(THREE_FINGER), obstacle=Obstacle(), approach=(-0.15, 0.0, 0.0))
    res = solve(grasp, t([0.2, 0.1, 0.2]))
    assert bool(res.converged[0]) and float(res.normal_force_N[0]) > 0
    assert float(res.residual_force_mN.max()) <= 1e-4


def _analytic_end_angle(inputs: np.ndarray) -> np.ndarray:
    """End-section angle of the analytic beam (numpy): sum_k kappa_k·h, kappa_k =
    (M - c_p P + F2 (L - s_k)) / EI at the segment midpoints s_k = (k + 1/2) h."""
    P, F1, F2, M = np.moveaxis(inputs, -1, 0)
    h = 45.45 / 10
    s = (np.arange(10) + 0.5) * h
    return ((M - 333.0 * P)[..., None] + F2[..., None] * (45.45 - s)).sum(-1) * h / 3000.0


def test_cap_kinematics_exit_angle_is_the_analytic_end_angle():
    """Cap kinematics on the analytic joint, paper finger, random pressures and loads: each
    joint's exit angle phi_i - theta_i equals the beam's end-section angle (numpy, 1e-13
    rad); the link starts at joint 1's r_10 and points along phi_1 (1e-12), joint 2's
    theta_2 = phi_1 exactly; anchors_and_cap returns the same anchors as the plain call,
    bit for bit; tangent kinematics turns by phi_end instead, which lags the end section by
    about half the last segment's turn, kappa_10·h/2 (2 %)."""
    gen = torch.Generator().manual_seed(5)
    p = torch.rand(8, 2, generator=gen, dtype=DT) * 0.6 - 0.3
    tau = (torch.rand(8, 2, 3, generator=gen, dtype=DT) * 2 - 1) * t([1.0, 1.0, 30.0])
    pose = finger_pose(J, GripperParams(kinematics="cap"), p, tau)
    inputs = torch.cat((p[..., None], tau), -1)
    np.testing.assert_allclose((pose.phi - pose.theta).numpy(), _analytic_end_angle(inputs.numpy()), rtol=0, atol=1e-13)
    assert torch.equal(pose.segments[:, 0, 0], pose.joints[:, 0, -1]) and torch.equal(pose.theta[:, 1], pose.phi[:, 0])
    d = pose.segments[:, 0, 1] - pose.segments[:, 0, 0]
    np.testing.assert_allclose(torch.atan2(d[:, 1], d[:, 0]).numpy(), pose.phi[:, 0].numpy(), rtol=0, atol=1e-12)
    anchors, cap = J.anchors_and_cap(inputs)
    assert torch.equal(anchors, J(inputs)) and cap.shape == (8, 2)
    tangent = finger_pose(J, PAPER_CHAIN, p, tau)
    assert float((tangent.phi - tangent.theta - phi_end(anchors)).abs().max()) <= 1e-15
    # the chord of anchors 9-10 lags the end section by about half the last segment's turn
    lag = cap - phi_end(anchors)
    h = 45.45 / 10
    kappa_10 = ((inputs[..., 3] - 333.0 * inputs[..., 0]) + inputs[..., 2] * 0.5 * h) / 3000.0
    np.testing.assert_allclose(lag.numpy(), (0.5 * kappa_10 * h).numpy(), rtol=0.02, atol=1e-4)
    assert float(lag.abs().max()) > 1e-2


def test_cap_kinematics_tip_gradient_matches_finite_differences():
    """torch.autograd.gradcheck through anchors_and_cap: d tip/d tau and d tip/d P of the
    cap-kinematics chain (paper finger and the three-joint one) equal central finite
    differences; so does d(residual)/d tau, which the Newton solver uses."""
    for finger, n in ((default_finger(), 2), (THREE_FINGER, 3)):
        params = GripperParams(finger, kinematics="cap")
        p = t([[0.1, -0.2, 0.05][:n]])
        tau = t([[[0.2, 0.1, -5.0], [0.05, -0.02, 3.0], [0.1, 0.03, 1.0]][:n]])

        def tip(tau_, p_, params=params):
            return finger_pose(J, params, p_, tau_).tip_end

        assert torch.autograd.gradcheck(tip, (tau.clone().requires_grad_(True), p.clone().requires_grad_(True)),
                                        eps=1e-6, atol=1e-5, rtol=1e-4)
        problem = GripperProblem(J, params)
        assert torch.autograd.gradcheck(lambda x: problem.residual(p, x).residual, (tau.clone().requires_grad_(True),),
                                        eps=1e-6, atol=1e-5, rtol=1e-4)
    res = solve(GripperProblem(J, GripperParams(kinematics="cap")), t([[-0.1, 0.1], [0.1, -0.1]]))
    assert bool(res.converged.all()) and float(res.residual_force_mN.max()) <= 1e-4


def test_cap_kinematics_needs_a_cap_head():
    """A joint model without a cap-rotation head (the base JointModel, a SurrogateJoint whose
    module has no ``has_cap_rotation``) refuses cap kinematics with one line naming the
    option to use, when the problem is built (before any solve); a SurrogateJoint whose
    module has the head returns ``module.with_cap(inputs)``."""
    from predictor.joint import SurrogateJoint

    class NoHead(JointModel):
        name = "nohead"

        def __call__(self, inputs):
            return J(inputs)

    with pytest.raises(ValueError, match="joint model nohead has no cap-rotation head: use --kinematics tangent"):
        GripperProblem(NoHead(), GripperParams(kinematics="cap"))
    GripperProblem(NoHead(), PAPER_CHAIN)  # tangent needs no head

    class Head(torch.nn.Module):
        has_cap_rotation = True

        def forward(self, inputs):
            return J(inputs)

        def with_cap(self, inputs):
            return J.anchors_and_cap(inputs)

    sur = object.__new__(SurrogateJoint)
    sur.name, sur.module = "stub", torch.nn.Identity()
    assert not sur.has_cap_rotation
    with pytest.raises(ValueError, match="has no cap-rotation head"):
        sur.anchors_and_cap(t([[0.1, 0.0, 0.0, 0.0]]))
    sur.module = Head()
    x = t([[0.1, 0.2, -0.1, 5.0]])
    assert sur.has_cap_rotation and torch.equal(sur.anchors_and_cap(x)[1], J.anchors_and_cap(x)[1])
    res = solve(GripperProblem(sur, GripperParams(kinematics="cap")), t([-0.1, 0.1]))
    ref = solve(GripperProblem(J, GripperParams(kinematics="cap")), t([-0.1, 0.1]))
    assert torch.equal(res.pose.tip_end, ref.pose.tip_end)


@pytest.mark.parametrize("finger", [default_finger(), THREE_FINGER], ids=["paper", "three"])
def test_split_joint_weight_moves_exactly_half(finger):
    """Straight finger at P = 0 under gravity (analytic joint): every weight hangs on the
    finger's axis, so tau_i = (F1_i, 0, 0), axial with zero moments, and by hand
    F1_i = sum of the weights of the parts after joint i (lumped), plus half of joint i's own
    weight (split: its distal half sits at r_10, in its own balance). The paper finger:
    (0.19, 0.06) N lumped, (0.235, 0.105) N split. All to 1e-10 N (the solve's own
    accuracy: its last Newton step lands ~1e-11 N off; the split moves F1 by 0.045 N)."""
    zero = t([[0.0] * finger.n_joints])
    taus = {}
    for jw in ("lumped", "split"):
        res = solve(GripperProblem(J, GripperParams(finger, joint_weight=jw)), zero)
        assert bool(res.converged[0])
        taus[jw] = res.tau[0].numpy()
        np.testing.assert_allclose(taus[jw][:, 1:], 0.0, rtol=0, atol=1e-10)
    distal = np.array([sum(p.weight for p in finger.parts[k + 1:]) for k in finger.joints])
    own = np.array([finger.parts[k].weight for k in finger.joints])
    np.testing.assert_allclose(taus["lumped"][:, 0], distal, rtol=0, atol=1e-10)
    np.testing.assert_allclose(taus["split"][:, 0], distal + 0.5 * own, rtol=0, atol=1e-10)
    if finger.n_joints == 2:
        np.testing.assert_allclose(taus["lumped"][:, 0], [0.19, 0.06], rtol=0, atol=1e-10)
        np.testing.assert_allclose(taus["split"][:, 0], [0.235, 0.105], rtol=0, atol=1e-10)


def test_split_joint_weight_moment_arms():
    """Off the straight pose the split weights act where stated: for the paper finger at a
    fixed bent (P, tau), the split residual minus the lumped one equals, per joint i, the
    force and moment about r_10,i of -0.045 N (down) at each joint's anchor mean, moved to
    +0.045 N at its proximal centre and at its distal end (zero arm about its own end),
    computed by hand from the pose, to 1e-12; joint 1's own distal half moves joint 1's
    force balance only (zero arm)."""
    p = t([[0.15, -0.1]])
    tau = t([[[0.2, 0.05, -10.0], [0.06, -0.02, 2.0]]])
    lumped = GripperProblem(J, GripperParams(joint_weight="lumped")).residual(p, tau)
    split = GripperProblem(J, GripperParams(joint_weight="split")).residual(p, tau)
    pose = lumped.pose
    ends = pose.joints[0, :, -1].numpy()
    expect = np.zeros((2, 3))
    for i in range(2):
        for j in range(2):  # joint j's weight, as seen by joint i's balance (R = applied - loads)
            w = 0.09
            loads = []
            if j > i:  # the lumped load removed (an upward w), the two halves added
                loads += [(pose.joints[0, j, 1:].mean(0).numpy(), -w)]
                loads += [(pose.joints[0, j, 0].numpy(), w / 2), (pose.joints[0, j, -1].numpy(), w / 2)]
            elif j == i:  # only the distal half enters the joint's own balance
                loads += [(pose.joints[0, j, -1].numpy(), w / 2)]
            for pt, weight in loads:  # a load F = (0, -weight) at pt adds -F to R_F, -(pt - end) x F to R_M
                F = np.array([0.0, -weight])
                expect[i, :2] -= F
                expect[i, 2] -= (pt - ends[i])[0] * F[1] - (pt - ends[i])[1] * F[0]
    np.testing.assert_allclose((split.residual - lumped.residual)[0].numpy(), expect, rtol=0, atol=1e-12)


def test_gripper_options_are_checked():
    """Unknown kinematics or joint-weight options are one-line ValueErrors, as are an
    approach of the wrong length and a pressure count other than the finger's joints."""
    with pytest.raises(ValueError, match="kinematics 'chord': use tangent or cap"):
        GripperParams(kinematics="chord")
    with pytest.raises(ValueError, match="joint weight 'half': use lumped or split"):
        GripperParams(joint_weight="half")
    with pytest.raises(ValueError, match=r"approach \(-0.15, 0.0\) MPa: give 3 pressures"):
        GripperProblem(J, GripperParams(THREE_FINGER), obstacle=Obstacle(), approach=(-0.15, 0.0))
    with pytest.raises(ValueError, match="2 pressures given for finger 'three' of 3 joints"):
        solve(GripperProblem(J, GripperParams(THREE_FINGER)), t([0.1, 0.1]))


def test_cli_finger_kinematics_and_joint_weight(tmp_path):
    """predictor.gesture --finger FILE --pressures P1,P2,P3 on the three-joint finger (and
    --kinematics cap --joint-weight split) exits 0; its JSON names the finger (name, sha256
    of the file), the kinematics and the joint weight, has tau 3x3, three
    joint_end_angle_deg whose last is tip_angle_deg, and the tip equals the Python solve's;
    --p1/--p2 with that finger exits 2 with one line asking for --pressures; --plot draws
    the three-joint gripper."""
    import hashlib

    path = tmp_path / "three.toml"
    path.write_text(THREE)
    png = tmp_path / "three.png"
    out = _cli("--finger", str(path), "--pressures", "0.1,-0.05,0.2", "--model", "analytic", "--kinematics", "cap",
               "--joint-weight", "split", "--json", "--plot", str(png))
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["finger"] == {"name": "three", "sha256": hashlib.sha256(THREE.encode()).hexdigest()}
    assert (got["kinematics"], got["joint_weight"]) == ("cap", "split")
    assert np.array(got["tau"]).shape == (3, 3) and len(got["joint_end_angle_deg"]) == 3
    assert got["joint_end_angle_deg"][-1] == got["tip_angle_deg"]
    ref = solve(GripperProblem(J, GripperParams(THREE_FINGER, kinematics="cap", joint_weight="split")),
                THREE_P[:1])
    np.testing.assert_allclose(got["tip"], ref.pose.tip_end[0].numpy(), rtol=0, atol=1e-9)
    assert png.stat().st_size > 10_000
    paper = json.loads(_cli("--p1", "-0.1", "--p2", "0.1", "--model", "analytic", "--json").stdout)
    assert paper["finger"]["name"] == "paper" and (paper["kinematics"], paper["joint_weight"]) == ("cap", "split")
    assert paper["tip_angle_deg"] == paper["joint_end_angle_deg"][1]
    bad = _cli("--finger", str(path), "--p1", "0", "--p2", "0", "--model", "analytic")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "finger 'three' has 3 joints: give --pressures with 3 values" in bad.stderr


def test_nn_for_another_finger(tmp_path):
    """An NN config moved to the three-joint finger (NNConfig.for_params) trains a 3 -> 9
    network; its checkpoint records the finger and options and loads back with them, and
    loading it for the paper finger (or other options) is refused with one line; an old
    checkpoint without the fields means the paper finger and chain (tangent, lumped)."""
    from predictor.networks import NNConfig
    from predictor.nn_checkpoint import load_predictor, save_predictor
    from predictor.nn_train import train

    params = GripperParams(THREE_FINGER, kinematics="tangent", joint_weight="split")
    cfg = NNConfig(n_train=60, n_val=20, epochs=1).for_params(params)
    assert cfg.widths[0] == 3 and cfg.widths[-1] == 9 and cfg.params() == params
    pred = train(cfg, J)
    assert pred.net(THREE_P).shape == (3, 3, 3)
    path = tmp_path / "three.pt"
    save_predictor(pred, path)
    back = load_predictor(path, J, params=params)
    assert back.config.params() == params
    with pytest.raises(ValueError, match="was trained for finger 'three', tangent kinematics, split joint weights, "
                                         "not finger 'paper', cap kinematics, split joint weights"):
        load_predictor(path, J, params=GripperParams())
    assert NNConfig().params() == GripperParams()
    # a checkpoint written before the chain options were recorded: the paper's chain
    from dataclasses import asdict

    from predictor.nn_checkpoint import checkpoint_kind
    from surrogate import checkpoint

    old = train(NNConfig(n_train=60, n_val=20, epochs=1), J)
    old_path = tmp_path / "old.pt"
    payload = {"config": {k: v for k, v in asdict(old.config).items() if k not in ("kinematics", "joint_weight")},
               "state_dict": old.net.state_dict(), "joint": old.joint_name, "metrics": old.metrics,
               "history": old.history}
    checkpoint.save(old_path, checkpoint_kind(False), payload)
    with pytest.raises(ValueError, match="not finger 'paper', cap kinematics"):
        load_predictor(old_path, J, params=GripperParams())
    assert load_predictor(old_path, J, params=PAPER_CHAIN).config.params() == PAPER_CHAIN


def test_surrogate_cap_head_drives_cap_kinematics(tmp_path):
    """A JointSurrogate built with a cap-rotation head (surrogate.model, issue 14; skipped
    while the option does not exist), saved and loaded through SurrogateJoint: cap
    kinematics accepted, and each joint's exit angle phi_i - theta_i equals the module's
    own with_cap rotation for the same inputs (1e-15 rad), one joint-model pass for both
    joints; without the head the same checkpoint kind refuses cap kinematics by name."""
    model_mod = pytest.importorskip("surrogate.model")
    if "cap_rotation" not in {f.name for f in dataclasses.fields(model_mod.ModelConfig)}:
        pytest.skip("surrogate.model has no cap-rotation head yet")
    from predictor.joint import SurrogateJoint

    torch.manual_seed(1)
    box = t(INPUT_BOX)
    y = J(torch.zeros(1, 4, dtype=DT)).reshape(-1, 20)
    norm = {"input_scale": box.tolist(), "output_mean": y[0].tolist(), "output_scale": [1.0] * 20, "cap_scale": [0.05]}
    paths = {}
    for head in (True, False):
        cfg = model_mod.ModelConfig(hidden=(16, 16), activation="tanh", equivariant=True, cap_rotation=head)
        net = model_mod.JointSurrogate(cfg, norm).double()
        paths[head] = tmp_path / f"cap_{head}.pt"
        model_mod.save_checkpoint(paths[head], net, {}, {}, {})
    joint = SurrogateJoint(paths[True])
    assert joint.has_cap_rotation
    p, tau = t([[0.1, -0.2]]), t([[[0.2, 0.1, -5.0], [0.05, -0.02, 3.0]]])
    pose = GripperProblem(joint, GripperParams(kinematics="cap")).pose(p, tau)
    _, cap = joint.module.with_cap(torch.cat((p[..., None], tau), -1))
    np.testing.assert_allclose((pose.phi - pose.theta).numpy(), cap.numpy(), rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="has no cap-rotation head: use --kinematics tangent"):
        GripperProblem(SurrogateJoint(paths[False]), GripperParams(kinematics="cap"))


@pytest.mark.skipif(not (SURROGATE.is_file() and (ROOT / "results/predictor/contact_nn.pt").is_file()),
                    reason="no committed surrogate or NN checkpoints")
def test_bench_writes_every_required_key(tmp_path):
    """``python -m predictor.bench --quick`` (a few samples per figure, the committed models)
    writes every top-level figure issues 5 and 15 require as a finite number, and figures
    that agree with their details: the batched rates are converged gestures over measured seconds, and
    the fast contact path's misses and times add up to its cases. Physics: every gravity
    Newton solve converged to the solver's 1e-4 mN / 1e-5 N·mm, the polished contact NN (a
    solver result) to the issue's 0.1 mN / 0.01 N·mm, and no answer of the Newton steps
    from the contact NN that the branch check kept is another equilibrium than the ramp's."""
    from predictor import bench

    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "predictor.bench", "--quick", "--model", str(SURROGATE),
                          "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    b = json.loads(out.read_text())
    for key in bench.REQUIRED_KEYS:
        assert isinstance(b[key], (int, float)) and math.isfinite(b[key]), key
    cb = b["details"]["contact_batched"]
    assert cb["converged"] <= cb["n"] and abs(b["contact_ramp_batched_per_s"] - cb["converged"] / cb["s"]) < 1e-9
    through = b["details"]["contact_throughput"]   # the delivered path's batch, to two tolerances
    assert through["n"] == bench.QUICK["contact_throughput"] and through["threads"] == os.cpu_count()
    assert b["contact_batched_per_s"] == through["issue_bound"]["per_s"] and b["graphs"] == "trace"
    for key, (force, moment) in (("issue_bound", (0.1, 0.01)), ("solver_tolerance", (1e-4, 1e-5))):
        r = through[key]
        assert r["converged"] == through["n"] and abs(r["per_s"] - r["converged"] / (r["ms"] / 1e3)) < 1e-6
        assert r["max_residual_force_mN"] <= force and r["max_residual_moment_Nmm"] <= moment
    fast = b["details"]["contact_fast"]
    assert fast["n"] == bench.QUICK["contact"] and 0 <= fast["misses"] < fast["n"]
    assert 0.0 <= b["contact_nn_state_agreement"] <= 1.0
    assert b["contact_nn_raw_p95_force_mN"] >= 0.0 and b["gravity_batched_per_s"] > 0.0
    assert (b["batched_dtype"], b["batched_threads"]) == ("float32", os.cpu_count())
    thr = b["details"]["gravity_nn_throughput"]
    assert thr["one_thread"]["dtype"] == "float64" and thr["one_thread"]["threads"] == 1
    assert b["gravity_batched_per_s"] == thr["every_core"]["delivered_per_s"]
    gf = b["details"]["gravity_fast"]
    assert gf["n"] == bench.QUICK["gravity"] and gf["misses"] == 0 and gf["max_residual_force_mN"] <= 1e-4
    g = b["details"]["gravity_newton"]
    assert g["converged"] == g["n"] == bench.QUICK["gravity"]
    assert g["max_residual_force_mN"] <= 1e-4 and g["max_residual_moment_Nmm"] <= 1e-5
    assert b["contact_nn_residual_force_mN"] <= 0.1 and b["contact_nn_residual_moment_Nmm"] <= 0.01
    steps = b["details"]["contact_nn_vs_solver"]["newton_from_raw"]   # no kept answer off the ramp's branch
    assert steps["kept_elsewhere"] == 0 and steps["kept"] <= steps["converged_to_ramp_equilibrium"]
    assert 0.0 <= b["contact_nn_newton_rate"] <= 1.0 and fast["newton_from_nn"] + fast["fallbacks"] <= fast["n"]


def test_contact_net_answers_from_the_head_of_its_state(tmp_path):
    """ContactNet's tau for each pressure is exactly the output of the head its classifier
    picks plus that head's correction stages (random weights, so every state occurs on 200
    pressures and every stage adds something), and its checkpoint round-trips bit for bit."""
    from predictor.networks import VARIANTS, ContactNet, features, network, Predictor
    from predictor.nn_checkpoint import load_predictor, save_predictor

    cfg = VARIANTS["contact"]
    torch.manual_seed(5)   # a seed whose random classifier picks all three states
    net = network(cfg)
    assert isinstance(net, ContactNet)
    p = (2 * torch.rand(200, 2, dtype=torch.float64) - 1) * 0.3
    # every network sees P / 0.3 and |P| / 0.3 (the joint model's kink at P = 0)
    assert cfg.abs_pressure and torch.equal(features(p, True), torch.cat((p / 0.3, (p / 0.3).abs()), 1))
    assert {m.mlp[0].in_features for m in [*net.heads, *(s for r in net.refine for s in r)]} == {4}
    assert net.classifier[0].in_features == 4
    with torch.no_grad():
        net.classifier[-1].weight.mul_(100.0)  # an untrained classifier's logits barely vary
        state, tau = net.state(p), net(p)
        assert set(state.tolist()) == {0, 1, 2}
        for k, head in enumerate(net.heads):
            rows = p[state == k]
            assert torch.equal(tau[state == k], net.head_tau(k, rows))
            stages = [stage(rows) for stage in net.refine[k]]
            assert len(stages) == cfg.refine_stages and all(bool(c.abs().min() > 0) for c in stages)
            assert torch.allclose(tau[state == k], head(rows) + sum(stages), rtol=0, atol=1e-12)
    save_predictor(Predictor(net, cfg, J.name), tmp_path / "c.pt")
    back = load_predictor(tmp_path / "c.pt", J, contact=True)
    with torch.no_grad():
        assert isinstance(back.net, ContactNet) and torch.equal(back.net(p), tau)


CONTACT_NN = ROOT / "results/predictor/contact_nn.pt"


@pytest.mark.skipif(not (SURROGATE.is_file() and CONTACT_NN.is_file()), reason="no committed contact NN")
def test_contact_nn_raw_residual_and_state_on_a_fixed_set():
    """The committed contact NN on 60 fixed pressures of its domain (seed 5; 50 end in
    contact), against the ramp solver (the reference): its classifier's grasp state is the
    solver's on at least 57 (the bench's 400 give the >= 99 % figure); with no solver its
    raw tau meets the issue's bounds over every equilibrium, contact or not (mean <= 2 mN,
    1.2 N·mm; p95 <= 10 mN, 5 N·mm; 0.96 mN, 0.13 N·mm mean when written), is within
    1e-3 mN at every contact-free one, and its fingertip is within 2 µm of the solver's on
    average. One closed-form Gauss-Newton step (exact Jacobian, no iteration or check)
    from it cuts the mean force residual at least tenfold."""
    from predictor.networks import sample_pressures
    from predictor.nn_checkpoint import load_predictor
    from predictor.nn_eval import evaluate_contact

    joint = load_joint(SURROGATE)
    pred = load_predictor(CONTACT_NN, joint, contact=True)
    p = sample_pressures(60, pred.config, torch.Generator().manual_seed(5))
    ev = evaluate_contact(pred, joint, p)
    assert ev["reference_converged"] == 60 and ev["state_by"] == "classifier"
    assert ev["state_agreement"] >= 57 / 60
    raw, free, step = ev["raw"], ev["raw_contact_free"], ev["newton_step_from_raw"]
    assert raw["force_mN_mean"] <= 2.0 and raw["moment_Nmm_mean"] <= 1.2
    assert raw["force_mN_p95"] <= 10.0 and raw["moment_Nmm_p95"] <= 5.0
    assert free is not None and free["force_mN_max"] <= 1e-3
    assert ev["raw_tip_error_mm"]["mean"] <= 0.002
    assert step["force_mN_mean"] <= raw["force_mN_mean"] / 10


@pytest.mark.skipif(not (SURROGATE.is_file() and CONTACT_NN.is_file()), reason="no committed contact NN")
def test_contact_nn_newton_answers_are_the_ramps_equilibria(monkeypatch):
    """The delivered contact NN path on 24 fixed pressures of its domain (seed 11): every
    answer converges to the solver's tolerances; the answers of the Newton steps from the
    network's tau (``stepped``: most of them; 95 % on the 400 validation pressures) are
    the ramp solver's equilibria (tau within 1e-4 N, 1e-4 N·mm), not another branch's.
    With the branch check made impossible (BRANCH_TIP_MM = -1) nothing is stepped and
    the capped LM answers the same equilibria."""
    import predictor.nn_answer as answer
    from predictor.nn_checkpoint import load_predictor
    from predictor.networks import sample_pressures

    joint = load_joint(SURROGATE)
    pred = load_predictor(CONTACT_NN, joint, contact=True)
    problem = pred.config.problem(joint)
    p = sample_pressures(24, pred.config, torch.Generator().manual_seed(11))
    ref = solve(problem, p)
    res = answer.predict_gesture(pred, problem, p)
    assert bool(ref.converged.all()) and bool(res.converged.all())
    # method: "nn+newton", joined with "lm" where the capped LM answered rows
    assert int(res.stepped.sum()) >= 12 and res.method == ("nn+newton" if bool(res.stepped.all()) else "nn+newton+lm")
    assert torch.allclose(res.tau, ref.tau, rtol=0, atol=1e-4)
    # a stepped answer took Newton steps, or the network's own tau met the tolerances already
    # (contact-free raw residuals reach 1e-4 mN)
    raw_done = (res.raw_residual_force_mN.amax(-1) <= 1e-4) & (res.raw_residual_moment_Nmm.amax(-1) <= 1e-5)
    assert bool(((res.iterations >= 1) | raw_done)[res.stepped].all())
    monkeypatch.setattr(answer, "BRANCH_TIP_MM", -1.0)
    lm = answer.predict_gesture(pred, problem, p[:6])
    assert not bool(lm.stepped.any()) and bool(lm.converged.all()) and lm.method == "nn+lm"
    assert torch.allclose(lm.tau, ref.tau[:6], rtol=0, atol=1e-4)
