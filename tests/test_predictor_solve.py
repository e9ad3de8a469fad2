"""Gesture predictor, joint models and the solvers without an object (predictor.model.joint,
statics, solve and its parts: graphs, jacobians, newton, lm): closed forms, an independent
scipy solution, symmetry, finite differences, and the solvers against each other.

Every test states the exact or expected answer it checks.
"""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import torch
from scipy.optimize import fsolve

from contract.spec import phi_end
from predictor.model.gripper import GripperParams, default_finger
from predictor.model.joint import AnalyticJoint, load_joint
from predictor.solvers.graphs import residual_fn
from predictor.solvers.jacobians import jacobian_fn
from predictor.solvers.solve import APPROACH, SolverOptions, solve
from predictor.model.statics import ContactParams, GripperProblem, Obstacle, range_penalty

from test_predictor_common import DT, PAPER_CHAIN, ROOT, THREE_FINGER, J, LeftJoint, t

torch.set_num_threads(1)
#: These tests check the chain and the solvers on the smooth residual, the paper's model
#: in which the two fingers pass through each other: the analytic stand-in (2.5x softer
#: than the surrogate) meets the symmetry plane X = 0 from 0.02 MPa. The plane contact is
#: tested in test_predictor_faces.py.
NO_PLANE = ContactParams(plane_stiffness=0.0)
GRAVITY = GripperProblem(J, contact=NO_PLANE)
GRASP = GripperProblem(J, obstacle=Obstacle(), approach=APPROACH, contact=NO_PLANE)


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
    (top chamber) bends towards -y, so y_10 < 0 (docs/physics.md sign of the stand-in)."""
    r = J(t([0.0, 3.0, 0.0, 0.0]))
    assert abs(float(r[-1, 0]) - 45.9045) < 1e-12 and float(r[-1, 1].abs()) == 0.0
    assert float(J(t([0.2, 0.0, 0.0, 0.0]))[-1, 1]) < -10.0


def test_analytic_joint_mirror_symmetry():
    """docs/physics.md: (R·diag(1,-1), -P, F1, -F2, -M) is a solution; equal to 1e-12 mm."""
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
    res = solve(GripperProblem(J, PAPER_CHAIN, contact=NO_PLANE), t([0.0, 0.0]))
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
    as the step (predictor.solvers.newton.traced_warm_fn), are Equation 1 and the kinematics recomputed at
    its tau. Allowed one step only (NEWTON_STEPS = 1), from tau = 0 at (0.3, -0.3) the
    check refuses it and the LM goes on (iterations > 1) to the same equilibrium. With an
    object it refuses to run (the contact law is not smooth)."""
    from predictor.solvers.solve import newton_polish

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
    monkeypatch.setattr("predictor.solvers.solve.NEWTON_STEPS", 1)
    far, _ = newton_polish(GRAVITY, t([[0.3, -0.3]]), torch.zeros(1, 2, 3, dtype=DT))
    assert bool(far.converged[0]) and int(far.iterations[0]) > 1 and far.method == "newton+lm"   # the LM answered
    assert float((far.tau - solve(GRAVITY, t([0.3, -0.3])).tau).abs().max()) <= 1e-4
    with pytest.raises(ValueError, match="without an object"):
        newton_polish(GRASP, p[:1], start[:1])


def test_newton_steps_reach_the_lm_equilibria():
    """Without an object the default solve from tau = 0 is a Picard step and Newton steps
    (predictor.solvers.solve's cold path): on 64 random pressures of the paper's finger it converges in at
    most 3 iterations (Picard and two Newton steps, the one-graph path), on 16 of a
    three-joint finger in at most 4 (a third Newton step by newton_polish where the check
    refused), to the LM's equilibria (method="lm") within the two solves' accuracy at the
    tolerances (1e-6 N, 1e-4 N·mm), its own residual within 1e-4 mN / 1e-5 N·mm. At
    tolerances 1e6x tighter (1e-10 mN, 1e-11 N·mm) the check refuses the two-step answer
    and the fallback finishes every sample to them."""
    gen = torch.Generator().manual_seed(21)
    three = GripperProblem(J, GripperParams(THREE_FINGER), contact=NO_PLANE)
    for problem, n, most in ((GRAVITY, 64, 3), (three, 16, 4)):
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
    from predictor.solvers.solve import statics_at

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
from predictor.solvers import newton, solve as S
from predictor.model.joint import AnalyticJoint
from predictor.model.statics import GripperProblem, Obstacle
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
    res = solve(GripperProblem(J, GripperParams(kinematics=chain[0], joint_weight=chain[1]), contact=NO_PLANE),
                t([p1, p2]))
    np.testing.assert_allclose(res.tau[0].numpy(), tau, atol=1e-7)
    np.testing.assert_allclose(res.pose.tip_end[0].numpy(), tip, atol=1e-6)


def test_two_finger_mirror_symmetry():
    """Solving the LEFT finger directly (base at X = -25 mm, mirrored joint) gives the
    mirror of the right finger: tau_L = (F1, -F2, -M)_R and every point (-X, Y), to 1e-8."""
    p = t([[-0.1, 0.1], [0.2, 0.05]])
    right = solve(GRAVITY, p)
    left_finger = dataclasses.replace(default_finger(), base_gap=-50.0)
    left = solve(GripperProblem(LeftJoint(), params=GripperParams(left_finger), contact=NO_PLANE), p)
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
