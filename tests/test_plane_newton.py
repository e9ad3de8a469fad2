"""The contact-constrained Newton of the fingers pressed on each other at X = 0
(predictor.solvers.plane_newton): its loads are the statics' own, its Jacobian the exact one, it
converges from a start far across X = 0 in a handful of steps, and the solve through it
lands on the penalty's root that the ramp and its homotopy reached before it (frozen from
that solve on the committed surrogate: tips within 1e-3 mm, plane force within 1e-4 N).
"""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from predictor.model.gripper import outline_vertices
from predictor.solvers.options import SolverOptions
from predictor.solvers.plane_newton import (constrained_fn, kkt_jacobian, kkt_residual, kkt_solve, penalty_shift,
                                    plane_loads, plane_vertex_layout)
from predictor.solvers.problem import load_problem
from predictor.solvers.ramp import contact_newton
from predictor.solvers.solve import solve
from predictor.model.statics import apart, plane_contact, scaled

ROOT = Path(__file__).resolve().parents[1]
MODEL = str(ROOT / "results/surrogate/improved.pt")

torch.set_num_threads(1)

#: Gravity gestures pressed on X = 0, solved by the ramp and the homotopy of the plane
#: (before predictor.plane_newton; 230, 1,862 and 102 LM iterations): pressures MPa ->
#: (tip mm, plane force N).
FROZEN = {(0.2, 0.2): ((9.673185491360863, -214.73498176569183), 0.2806374282288458),
          (0.3, 0.0): ((10.00029940087509, -215.82462633616143), 0.48895576587657963),
          (0.1, 0.3): ((8.821648850676748, -206.2159312544292), 0.2415612270490229)}


def t(rows):
    return torch.tensor(rows, dtype=torch.float64)


@pytest.fixture(scope="module")
def problem():
    return load_problem(MODEL, None)


def test_vertex_loads_are_the_statics_plane_loads(problem):
    """plane_loads with the plane's own Gauss points, forces and part mask (ChainLayout.
    plane_mask) is the residual's plane term: residual(with the plane) - residual(apart)
    at a pose across X = 0 (tau = 0 at (0.2, 0.2) MPa, the load-free pose ~1.8 mm across
    or more), to 1e-12 relative; and a vertex's mask row is 1 exactly where its part is distal to
    the joint (the tip's end corners load both joints)."""
    p, tau = t([[0.2, 0.2], [0.3, 0.3]]), torch.zeros(2, 2, 3, dtype=torch.float64)
    full, alone = problem.residual(p, tau), apart(problem).residual(p, tau)
    assert float(full.plane.overlap.min()) > 1.0
    layout = problem.params.layout
    term = plane_loads(full.plane.forces[..., 0], full.plane.points[..., 1], full.pose.joints[:, :, -1, 1],
                       layout.plane_mask)
    # the forces are ~1e6 N there (1.8+ mm deep in the stiff penalty): rounding only
    assert float((scaled(full.residual) - scaled(alone.residual) - term).abs().max()) < 1e-12 * float(term.abs().max())
    index, mask = plane_vertex_layout(layout)
    assert mask.shape == (2, len(index)) and bool((mask[1] <= mask[0]).all())   # joint 2's loads also load joint 1
    assert float(mask[1].sum()) >= 3 and float(mask[0].sum()) > float(mask[1].sum())


def test_kkt_jacobian_matches_autograd(problem):
    """kkt_jacobian's central differences of R(x, lam) and X(x) against reverse-mode
    autograd of the eager constrained_fn at a pose across X = 0 with forces on three
    vertices: within 1e-6 relative; dR/dlam (exact) against a difference in lam."""
    g = constrained_fn(problem)
    _, mask = plane_vertex_layout(problem.params.layout)
    p = t([[0.2, 0.2]])
    x = t([[0.2, 0.3, 40.0, 0.05, 0.2, 6.0]])
    lam = torch.zeros(1, mask.shape[1], dtype=torch.float64)
    lam[0, [-1, -3, 5]] = t([0.3, 0.1, 0.05])
    R, X, dR, dlam, dX = kkt_jacobian(g, x, p, lam, mask)

    def f(xx):
        out = g(xx[None], p)
        return torch.cat((kkt_residual(out, lam, mask)[0], out[1][0]))

    exact = torch.autograd.functional.jacobian(f, x[0])
    n = x.shape[1]
    assert torch.allclose(dR[0], exact[:n], rtol=1e-6, atol=1e-8)
    assert torch.allclose(dX[0], exact[n:], rtol=1e-6, atol=1e-8)
    e = 1e-3 * torch.eye(mask.shape[1], dtype=torch.float64)[7]
    fd = (kkt_residual(g(x, p), lam + e, mask) - kkt_residual(g(x, p), lam - e, mask)) / 2e-3
    assert torch.allclose(dlam[0, :, 7], fd[0], atol=1e-12)


def test_kkt_converges_from_across_the_plane_to_the_penalty_force(problem):
    """From tau = 0 at (0.2, 0.2) MPa, whose load-free outline lies more than 1 mm across
    X = 0, the KKT converges in at most 10 Newton steps with one corner held (its force
    0.2806 N within 1e-3 N of the penalty root's plane force) at X = -s, s the
    penalty's overlap for that force: within 5 % of the penalty root's overlap 0.0431 mm;
    every other plane vertex lies at X >= -s."""
    p = t([[0.2, 0.2]])
    x0 = torch.zeros(1, 6, dtype=torch.float64)
    start = problem.residual(p, x0.reshape(1, 2, 3))
    assert float(start.plane.overlap[0]) > 1.0
    x, lam, s, ok, steps = kkt_solve(problem, x0, p)
    assert bool(ok[0]) and int(steps[0]) <= 10
    held = lam[0] > 1e-9
    assert int(held.sum()) == 1
    assert float(lam[0].sum()) == pytest.approx(FROZEN[(0.2, 0.2)][1], abs=1e-3)
    assert float(s[0]) == pytest.approx(0.0431, rel=0.05)
    _, X, _, _ = constrained_fn(problem)(x, p)
    assert float(X[0, held]) == pytest.approx(-float(s[0]), abs=1e-9)
    assert float(X[0].min()) >= -float(s[0]) - 1e-9


def test_penalty_shift_inverts_the_plane_force(problem):
    """penalty_shift: the straight finger's outline moved to touch X = 0 with its tip's
    inner corner only (tilted); the shift it returns for 0.3 N gives the plane's penalty
    force 0.3 N to 1e-8 relative; zero force, zero shift."""
    pose = problem.pose(t([[0.0, 0.0]]), torch.zeros(1, 2, 3, dtype=torch.float64))
    V = outline_vertices(pose, problem.params.layout)
    c, s_ = torch.cos(t(0.02)), torch.sin(t(0.02))
    V = V @ torch.stack((torch.stack((c, s_)), torch.stack((-s_, c))))     # a slight tilt
    V = V - torch.stack((V[..., 0].amin(-1), torch.zeros(1, dtype=torch.float64)), -1)[:, None]
    s = penalty_shift(problem, V, t([0.3, 0.0])[:1])
    shifted = V - s[:, None, None] * t([1.0, 0.0])
    assert float(plane_contact(None, problem.params, problem.contact, shifted).force[0]) == pytest.approx(0.3, rel=1e-8)
    assert float(penalty_shift(problem, V, t([0.0]))[0]) == 0.0


@pytest.mark.parametrize("pair", sorted(FROZEN))
def test_solve_through_the_kkt_lands_on_the_ramps_penalty_root(problem, pair):
    """The gravity gesture pressed on X = 0 (predictor.solve, the plane's path through
    predictor.plane_newton): converged, tip within 1e-3 mm and plane force within 1e-4 N of
    the ramp-and-homotopy solve's (FROZEN), in at most 60 iterations (230, 1,862 and 102
    before; the flat tip edge of (0.3, 0.0) takes ~45 of them, linearly), and so does the
    KKT's step solver alone from tau = 0."""
    res = solve(problem, t([pair]))
    tip, force = FROZEN[pair]
    assert bool(res.converged[0]) and int(res.iterations[0]) <= 60
    assert float((res.pose.tip_end[0] - t(tip)).abs().max()) < 1e-3
    assert float(res.plane_force_N[0]) == pytest.approx(force, abs=1e-4)
    x, ok, its, _ = contact_newton(problem, SolverOptions())(torch.zeros(1, 6, dtype=torch.float64), t([pair]))
    assert bool(ok[0]) and float((x - res.tau.reshape(1, 6)).abs().max()) < 1e-5
