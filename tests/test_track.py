"""Fingertip goals along a trajectory (issue 60) and the inverse's inputs and errors (issue 57).

Physical assertions on a short trajectory of the committed surrogate without an object (the
fingers meeting at X = 0): each verified answer's forward fingertip (predictor.solvers.solve, the
gesture's own history) within the tolerance of its goal where it is reached, and an
unreachable goal's answer no farther than the best point of the inverse's coarse grid.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from predictor import load_gripper
from predictor.planning.inversion import (FAR_GOAL_MM, TIP_TOL_MM, VERIFY_TOL_MM, Goal, coarse_atlas, search_tip, tip_errors,
                                          unreachable_reason, wrap_deg)
from predictor.solvers.options import SolverOptions
from predictor.solvers.problem import FULL_BOX
from predictor.model.gripper import DEFAULT_OUTLINE
from predictor.solvers.solve import solve
from predictor.planning.track import Tracker, load_track, tip_goal, track

ROOT = Path(__file__).resolve().parents[1]
MODEL = str(ROOT / "results/surrogate/improved.pt")
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def free():
    return load_gripper(MODEL, None)


def _cli(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "predictor.cli.inverse", *args], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=timeout)


def test_errors_are_split_and_the_angle_wrapped():
    """Position (mm) and angle (deg) errors apart: a tip at (3, 4) mm against the goal
    (0, 0) is 5 mm off; its angle 170 deg against -170 deg is -20 deg off (wrapped, not
    340); the reason names both."""
    pos, ang = tip_errors((3.0, 4.0), 170.0, Goal("tip", (0.0, 0.0), -170.0))
    assert pos == 5.0 and ang == pytest.approx(-20.0, abs=1e-12)
    assert tip_errors((3.0, 4.0), 170.0, Goal("tip", (0.0, 0.0))) == (5.0, None)
    assert tip_errors((1.0, 0.0), -179.0, tip_goal(0.0, 0.0, 900.0))[1] == pytest.approx(1.0, abs=1e-12)
    assert unreachable_reason(5.0, -20.0) == ("unreachable: the closest achievable tip is 5.00 mm away, its tip "
                                              "angle -20.00 deg off (tolerance 0.1 mm)")
    # a goal far beyond reach is searched for FAR_GOAL_MM away in its own direction
    far = search_tip(Goal("tip", (1e308, -212.0)))
    assert math.hypot(*far) == pytest.approx(FAR_GOAL_MM) and far[0] > 0


def test_short_trajectory_reaches_and_flags(free):
    """Four reachable goals (forward fingertips of four pressures, one pressed on X = 0)
    and two unreachable ones (behind the other finger, far below): every answer verified;
    a reached goal's forward fingertip (a new solve at its pressures) within TIP_TOL_MM
    of the goal; an unreachable one's answer no farther than the coarse 5 x 5 grid's best
    point, its reported tip the forward solve's (VERIFY_TOL_MM)."""
    prob = free.problem
    P = torch.tensor([[-0.10, -0.15], [-0.08, -0.14], [0.0, -0.1], [0.3, 0.2]], dtype=torch.float64)
    tips = solve(prob, P).pose.tip_end.tolist()
    goals = [tip_goal(*t) for t in tips[:3]] + [tip_goal(-10.0, -225.0), tip_goal(0.0, -400.0), tip_goal(*tips[3])]
    res = track(prob, goals)
    assert [a.status for a in res.answers] == ["reached"] * 3 + ["unreachable"] * 2 + ["reached"]
    assert all(a.verified for a in res.answers)
    grid = coarse_atlas(prob, FULL_BOX, SolverOptions())
    for g, a in zip(goals, res.answers):
        fwd = solve(prob, torch.tensor([a.pressures], dtype=torch.float64))
        assert bool(fwd.converged[0])
        tip = fwd.pose.tip_end[0]
        assert float((tip - torch.tensor(a.tip)).norm()) <= VERIFY_TOL_MM
        err = float((tip - torch.tensor(g.tip)).norm())
        if a.status == "reached":
            assert err <= TIP_TOL_MM and a.position_error_mm <= TIP_TOL_MM
        else:
            best = float((grid.result.pose.tip_end - torch.tensor(g.tip)).norm(dim=-1).min())
            assert err <= best + 1e-9, (err, best)
            assert a.position_error_mm > TIP_TOL_MM
    assert res.answers[3].plane_force_N > 0          # behind the other finger: pressed on X = 0
    s = res.summary()
    assert s["goals"] == 6 and s["verified"] and s["reached"] == 4 and s["max_tip_error_mm"] <= TIP_TOL_MM
    json.dumps(s, allow_nan=False)


def test_pressed_goals_by_newton_match_the_forward_pressures(free):
    """Goals along a pressure path pressed on X = 0 (the fingers meet: plane force > 0),
    their fingertips the gripper's own forward solves (predictor.solvers.solve, the ramp from zero
    pressure): each answered reached and verified, its forward tip (a new solve at the
    answer's pressures) within TIP_TOL_MM of the goal, and the pressures those of the path
    (the tip map is one to one there: 1e-3 MPa), the square Newton of the track answering
    pressed goals (not the continuation's softer planes: no restarts)."""
    prob = free.problem
    P = torch.tensor([[0.10 + 0.01 * k, 0.20 - 0.005 * k] for k in range(5)], dtype=torch.float64)
    fwd = solve(prob, P)
    assert bool(fwd.converged.all()) and bool((fwd.plane_force_N > 0).all())
    res = track(prob, [tip_goal(*t) for t in fwd.pose.tip_end.tolist()])
    assert all(a.status == "reached" and a.verified and a.plane_force_N > 0 for a in res.answers)
    assert not any(a.restarted for a in res.answers[1:])
    got = torch.tensor([a.pressures for a in res.answers], dtype=torch.float64)
    assert float((got - P).abs().max()) <= 1e-3
    again = solve(prob, got)
    err = (again.pose.tip_end - fwd.pose.tip_end).norm(dim=-1)
    assert bool(again.converged.all()) and float(err.max()) <= TIP_TOL_MM


def test_near_pressed_rows_match_the_continuation(free):
    """The stencil's rows pressed on X = 0 by Newton from the last answers' kept pressed
    gestures (``Tracker._near``: the tangent predictor of the nearest within NEAR_MPA, then
    the solver's Newton steps checked by its rule) are the forward equilibria the plane's
    continuation (``Tracker._continue``: the stiff LM, then the homotopy's softer planes)
    finds from the verified centre: the same joint loads (1e-6 N, N·mm) and fingertips
    (1e-6 mm). Every row of the next goal's stencil ((+0.005, -0.0025) MPa along the
    path, every row pressed) converges from a kept row of the first answer's 9, and a row
    farther than NEAR_MPA from every kept one is left to the continuation (not
    converged)."""
    from predictor.planning.inversion import REGULATOR, InverseProblem, traced_tip_fn
    from predictor.planning.track import NEAR_MPA

    prob = free.problem
    P = torch.tensor([[0.15, 0.20], [0.155, 0.1975]], dtype=torch.float64)
    fwd = solve(prob, P)
    assert bool(fwd.converged.all()) and bool((fwd.plane_force_N > 0).all())
    tracker = Tracker(prob)
    first = tracker.answer(tip_goal(*fwd.pose.tip_end[0].tolist()))
    assert first.status == "reached" and first.robust and len(tracker.pressed[0]) == 9
    d = REGULATOR * torch.tensor([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)],
                                 dtype=torch.float64)
    ps = P[1:] + d
    x, ok = tracker._near(ps)
    assert bool(ok.all())
    ip = InverseProblem(prob, tip_goal(*fwd.pose.tip_end[1].tolist()))
    xc, okc = tracker._continue(ip, (P[1:], fwd.tau.reshape(-1, 6)[1:]), ps)
    assert bool(okc.all())
    assert float((x - xc).abs().max()) <= 1e-6
    with torch.no_grad():
        t, tc = traced_tip_fn(prob)(x, ps)[:, :2], traced_tip_fn(prob)(xc, ps)[:, :2]
    assert float((t - tc).norm(dim=-1).max()) <= 1e-6
    far = P[1:] + torch.tensor([[3 * NEAR_MPA, 0.0]], dtype=torch.float64)
    assert not bool(tracker._near(far)[1].any())


def test_stencil_row_the_continuation_leaves_is_the_forward_equilibrium(free):
    """Goal 41 of the demo track after goal 40 (a fresh tracker: the same answer, (0.1834,
    0.0143) MPa pressed on X = 0): the continuation from the verified centre leaves the
    stencil's row (+0.01, -0.01) MPa (an edge of the outline nearly flat on X = 0: the
    LM creeps through its iterations, Newton converges linearly), which the forward solve
    from zero pressure converges. The answer was flagged not robust; now every stencil
    row is the forward solve's equilibrium (each row's kept verified x against ``solve``:
    joint loads within 1e-4 N, N·mm, fingertip within 1e-4 mm, all 9 pressed)."""
    from predictor.planning.inversion import REGULATOR, traced_tip_fn
    from predictor.planning.track import demo_goals

    prob = free.problem
    goals = demo_goals(prob)
    tracker = Tracker(prob, keep_coarse=True)
    tracker.answer(goals[40])
    a = tracker.answer(goals[41])
    assert a.status == "reached" and a.verified and a.plane_force_N > 0
    assert a.pressures == pytest.approx((0.18344, 0.01433), abs=1e-4)
    d = REGULATOR * torch.tensor([(x, y) for x in (-1, 0, 1) for y in (-1, 0, 1) if (x, y) != (0, 0)],
                                 dtype=torch.float64)
    ps = torch.tensor([a.pressures], dtype=torch.float64) + d
    fwd = solve(prob, ps)
    assert bool(fwd.converged.all()) and bool((fwd.plane_force_N > 0).all())
    assert a.robust
    kp, kx = tracker.pressed
    got = torch.stack([kx[int((kp - p).abs().amax(-1).argmin())] for p in ps])
    assert float(torch.stack([(kp - p).abs().amax(-1).min() for p in ps]).max()) == 0.0
    assert float((got - fwd.tau.reshape(-1, 6)).abs().max()) <= 1e-4
    with torch.no_grad():
        t = traced_tip_fn(prob)(got, ps)[:, :2]
    assert float((t - fwd.pose.tip_end).norm(dim=-1).max()) <= 1e-4


def test_kkt_stencil_rows_match_the_continuation(free):
    """The stencil's rows pressed on X = 0 by the contact-constrained Newton from the
    verified centre (``Tracker._kkt``) are the equilibria the plane's continuation from the
    same centre finds (``Tracker._continue``): a centre apart from the plane (goal 31 of
    the demo track, (0.0663, -0.0799) MPa) whose +0.01 MPa rows along P1 cross X = 0, and
    a pressed centre (0.2, 0.05) MPa: every row converged, pressed, the same joint loads
    (1e-5 N, N·mm: both roots within the solver's tolerances, measured 2.2e-6 N·mm) and
    fingertips (1e-5 mm, measured 1.5e-6)."""
    from predictor.model.statics import apart
    from predictor.planning.inversion import REGULATOR, InverseProblem, traced_tip_fn

    prob = free.problem
    tracker = Tracker(prob)
    d = REGULATOR * torch.tensor([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)],
                                 dtype=torch.float64)
    for centre, plane_free in (((0.06633, -0.07993), True), ((0.2, 0.05), False)):
        pc = torch.tensor([centre], dtype=torch.float64)
        fc = solve(prob, pc)
        assert bool(fc.converged[0]) and (float(fc.plane_force_N[0]) == 0.0) == plane_free
        xc = fc.tau.reshape(1, 6)
        ps = pc + d
        fwd = solve(apart(prob), ps)
        pressed = ~fwd.converged | (fwd.plane_overlap_mm > 0)
        assert int(pressed.sum()) >= 3
        ps = ps[pressed]
        xk, ok = tracker._kkt((pc, xc), ps)
        assert bool(ok.all())
        xl, okl = tracker._continue(InverseProblem(prob, tip_goal(0.0, 0.0)), (pc, xc), ps)
        assert bool(okl.all())
        assert float((xk - xl).abs().max()) <= 1e-5     # the roots within the solver's tolerances
        with torch.no_grad():
            t, tl = traced_tip_fn(prob)(xk, ps)[:, :2], traced_tip_fn(prob)(xl, ps)[:, :2]
        assert float((t - tl).norm(dim=-1).max()) <= 1e-5
        g = solve(prob, ps[:1], x0=xk[:1].reshape(1, 2, 3))
        assert float(g.plane_force_N[0]) > 0


def test_least_squares_newton_ends_where_the_continuation_does(free):
    """A goal beyond the reach next to a verified answer (as on the demo's return leg: the
    closest tip held at P2 = -0.3 MPa): the least-squares Newton in (x, P) (one Jacobian per
    step, no continuation) ends at an equilibrium within the solver's tolerances (a new
    forward solve at its pressures puts the tip within VERIFY_TOL_MM of its tip) and as
    close to the goal as the single inverse's Gauss-Newton by continuation from the same
    point (0.01 mm), and no closer than the reach allows (farther than TIP_TOL_MM)."""
    from predictor.planning.inversion import Branch, InverseProblem, gauss_newton, traced_tip_fn

    prob = free.problem
    tracker = Tracker(prob)
    P = torch.tensor([[0.0, -0.3]], dtype=torch.float64)
    tip = solve(prob, P).pose.tip_end[0].tolist()
    assert tracker.answer(tip_goal(*tip)).status == "reached"
    goal = tip_goal(tip[0], tip[1] + 15.0)      # 15 mm above: beyond the reach (held at P2 = -0.3 MPa)
    ip = InverseProblem(prob, goal)
    other = Branch(ip, tracker.branch.p.clone(), tracker.branch.x.clone())
    f = tracker._least_squares(ip, tracker.branch)
    assert f is not None
    gauss_newton(ip, other)
    with torch.no_grad():
        t_gn = traced_tip_fn(prob)(other.x, other.p)[0, :2]
        t_ls = traced_tip_fn(prob)(tracker.branch.x, tracker.branch.p)[0, :2]
    g = torch.tensor(goal.tip, dtype=torch.float64)
    assert math.sqrt(f) == pytest.approx(float((t_ls - g).norm()), abs=1e-9)
    assert abs(float((t_ls - g).norm()) - float((t_gn - g).norm())) <= 0.01
    assert math.sqrt(f) > TIP_TOL_MM and float(tracker.branch.p[0, 1]) == -0.3
    fwd = solve(prob, tracker.branch.p)
    assert bool(fwd.converged[0]) and float((fwd.pose.tip_end[0] - t_ls).norm()) <= VERIFY_TOL_MM


def test_api_track_tip(free):
    """The API's track_tip takes goal strings and tuples; a goal that is not a tip is refused."""
    from predictor import track_tip

    res = track_tip(free, ["tip:40,-212", (40.2, -212.1)])
    assert [a.status for a in res.answers] == ["reached", "reached"]
    assert all(a.verified and a.position_error_mm <= TIP_TOL_MM and a.cpu_ms > 0 for a in res.answers)
    with pytest.raises(ValueError, match="fingertip goals"):
        track_tip(free, ["hold"])


def test_track_files(tmp_path):
    """CSV (header, comments) and JSON tracks; NaN, unknown keys and wrong counts refused
    in one line."""
    f = tmp_path / "t.csv"
    f.write_text("x,y,deg\n# a comment\n40,-212\n\n41,-212.5,-70\n")
    goals = load_track(f)
    assert [g.tip for g in goals] == [(40.0, -212.0), (41.0, -212.5)] and goals[1].angle_deg == -70.0
    j = tmp_path / "t.json"
    j.write_text(json.dumps({"goals": [[40, -212], {"x": 41, "y": -212.5, "deg": 290}]}))
    assert load_track(j)[1].angle_deg == -70.0
    for text, why in (("[[40, NaN]]", "NaN in the track: not a number"), ('[{"x": 1, "y": 2, "z": 3}]', "keys x, y"),
                      ("[[1]]", "X,Y or X,Y,DEG"), ("[]", "0 goals")):
        j.write_text(text)
        with pytest.raises(ValueError, match=why):
            load_track(j)
    f.write_text("40,abc\n")
    with pytest.raises(ValueError, match="is not a number"):
        load_track(f)


def test_atlas_reader_is_strict(tmp_path):
    """--atlas refuses an unknown key and a NaN like the observation reader: exit 2, one
    line on stderr, before any search."""
    doc = json.loads((ROOT / "results/predictor/atlas_circle.json").read_text())
    bad = tmp_path / "unknown.json"
    bad.write_text(json.dumps({**doc, "surprise": 1}))
    r = _cli("--goal", "hold", "--object", "circle", "--atlas", str(bad), "--quiet", timeout=300)
    assert r.returncode == 2 and "unknown key 'surprise'" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    nan = tmp_path / "nan.json"
    nan.write_text(json.dumps(doc).replace('"mu": 0.3', '"mu": NaN', 1))
    r = _cli("--goal", "hold", "--object", "circle", "--atlas", str(nan), "--quiet", timeout=300)
    assert r.returncode == 2 and "NaN" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_tip_goal_at_900_deg_reports_its_errors_apart():
    """Issue 57's case predictor.cli.inverse --goal tip:40,-212,900 (900 deg is 180): exit 1
    and one stderr line naming the closest tip's position error (mm, its distance to
    (40, -212), not the 256.89 mm that added tip length x unwrapped angle) and its angle
    error (deg, achieved minus 180 wrapped to (-180, 180]), the JSON's figures. Frozen
    (the committed production surrogate, since the switch): 25.66 mm and +58.77 deg at
    (-0.1532, 0.3) MPa (the 1.8 mm surrogate's were 25.34 mm, +61.24 deg at (-0.1484, 0.3))."""
    r = _cli("--goal", "tip:40,-212,900", "--json", "--quiet")
    assert r.returncode == 1, r.stderr
    out = json.loads(r.stdout)
    assert out["status"] == "infeasible" and out["verified"]
    pos, ang = out["tip_error_mm"], out["angle_error_deg"]
    assert pos == pytest.approx(math.hypot(out["tip"][0] - 40.0, out["tip"][1] + 212.0), rel=1e-12)
    assert ang == pytest.approx(wrap_deg(out["tip_angle_deg"] - 180.0), abs=1e-9) and -180.0 < ang <= 180.0
    assert r.stderr == f"python -m predictor.cli.inverse: infeasible: {unreachable_reason(pos, ang)}\n"
    assert (pos, ang) == (pytest.approx(25.66, abs=0.01), pytest.approx(58.77, abs=0.01))
    assert out["pressures"] == pytest.approx([-0.1532, 0.3], abs=1e-3)


def test_far_goal_is_unreachable_with_finger_flag():
    """tip:1e308,-212 is an unreachable goal: exit 1 with the closest answer (not exit 2);
    --finger is accepted (the paper's file, as predictor.cli.gesture)."""
    r = _cli("--goal", "tip:1e308,-212", "--finger", str(ROOT / "contract/fingers/paper.toml"), "--json", "--quiet")
    assert r.returncode == 1, r.stderr
    out = json.loads(r.stdout)
    assert out["status"] == "infeasible" and out["verified"] and out["angle_error_deg"] is None
    assert out["tip"][0] > 150.0          # the farthest reach toward +X
    assert "unreachable" in r.stderr


def test_inverse_answers_for_the_finger_it_is_given():
    """predictor.cli.inverse --finger tests/data/fingers/long_tip.toml (the paper's finger with a
    70 mm tip, 5 mm longer): the goal is that finger's forward fingertip at (0.1, 0.05) MPa;
    the answer meets it (exit 0, verified, within TIP_TOL_MM), and a new forward solve of
    that finger at the answer's pressures puts its tip there, where the paper's finger at
    the same pressures is more than 4 mm away (5.02 mm): the file reached the search."""
    from contract.finger import load_finger
    from predictor.model.gripper import GripperParams
    from predictor.solvers.problem import load_problem

    finger = ROOT / "tests/data/fingers/long_tip.toml"
    long_tip = load_problem(MODEL, None, params=GripperParams(load_finger(finger)))
    paper = load_problem(MODEL, None)
    goal = solve(long_tip, torch.tensor([[0.1, 0.05]], dtype=torch.float64)).pose.tip_end[0].tolist()
    r = _cli("--goal", f"tip:{goal[0]!r},{goal[1]!r}", "--finger", str(finger), "--json", "--quiet")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["status"] == "feasible" and out["verified"] and out["tip_error_mm"] <= TIP_TOL_MM
    assert out["finger"]["name"] == "long_tip" and out["finger"]["sha256"] == load_finger(finger).digest
    p = torch.tensor([out["pressures"]], dtype=torch.float64)
    for prob, near in ((long_tip, True), (paper, False)):
        fwd = solve(prob, p)
        err = float((fwd.pose.tip_end[0] - torch.tensor(goal)).norm())
        assert bool(fwd.converged[0]) and (err <= TIP_TOL_MM if near else err > 4.0), (near, err)


def test_inverse_takes_the_plane_chain_and_approach_options():
    """predictor.cli.inverse takes predictor.cli.gesture's --no-plane, --kinematics, --joint-weight
    (issue 57: every tool every finger option). The goal is the forward fingertip of one
    finger alone, tangent kinematics, lumped joint weights, at (0.1, 0.05) MPa: (-14.9,
    -212.1) mm, across X = 0, where the default gripper's tip is at X = +9.9 mm. The
    answer meets it (exit 0, verified) and a forward solve of that problem at the answer's
    pressures puts the tip there, while the default problem's tip there is > 4 mm away.
    --approach is for hold goals only, and needs two values: exit 2, one line, before a solve."""
    from contract.finger import DEFAULT_FINGER, load_finger
    from predictor.model.gripper import GripperParams
    from predictor.solvers.problem import load_problem

    params = GripperParams(load_finger(DEFAULT_FINGER), kinematics="tangent", joint_weight="lumped")
    alone = load_problem(MODEL, None, params=params, plane=False)
    default = load_problem(MODEL, None)
    goal = solve(alone, torch.tensor([[0.1, 0.05]], dtype=torch.float64)).pose.tip_end[0].tolist()
    assert goal[0] < -10.0     # across X = 0: the gripper's fingers could not put it there
    r = _cli("--goal", f"tip:{goal[0]!r},{goal[1]!r}", "--no-plane", "--kinematics", "tangent",
             "--joint-weight", "lumped", "--json", "--quiet")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["status"] == "feasible" and out["verified"] and out["tip_error_mm"] <= TIP_TOL_MM
    assert out["finger"] == {"name": "paper", "sha256": params.finger.digest, "kinematics": "tangent",
                             "joint_weight": "lumped", "outline": DEFAULT_OUTLINE} and out["plane"] is False    # what it answered for
    p = torch.tensor([out["pressures"]], dtype=torch.float64)
    for prob, near in ((alone, True), (default, False)):
        fwd = solve(prob, p)
        err = float((fwd.pose.tip_end[0] - torch.tensor(goal)).norm())
        assert bool(fwd.converged[0]) and (err <= TIP_TOL_MM if near else err > 4.0), (near, err)
    for args, why in ((("--goal", "tip:40,-212", "--approach", "0,0"), "--approach applies to --goal hold only"),
                      (("--goal", "hold", "--object", "circle", "--approach", "0.1,0,0"), "3 values for the inverse's two joints"),
                      (("--track", "demo", "--approach", "0,0"), "drop --goal, --object and --approach")):
        r = _cli(*args, timeout=120)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and why in r.stderr, r.stderr


def test_track_cli(tmp_path):
    """--track FILE answers each goal; an unreachable one makes exit 1, the answers all
    written (--out) and verified."""
    f = tmp_path / "t.csv"
    f.write_text("40,-212\n40.5,-212.2\n0,-400\n")
    out, inv = tmp_path / "track.json", tmp_path / "inverse.json"
    inv.write_text((ROOT / "results/predictor/inverse.json").read_text())
    r = _cli("--track", str(f), "--out", str(out), "--into", str(inv), "--quiet")
    assert r.returncode == 1, r.stderr
    doc = json.loads(out.read_text())
    assert doc["goals"] == 3 and doc["verified"] and doc["reached"] == 2 and doc["unreachable"] == 1
    assert [a["status"] for a in doc["answers"]] == ["reached", "reached", "unreachable"]
    assert all(a["position_error_mm"] <= TIP_TOL_MM for a in doc["answers"][:2])
    # --into: make inverse's JSON carries this run's summary as its track (answers apart)
    from predictor.artefacts import INVERSE

    track = INVERSE.load(inv)["track"]
    assert track["median_ms"] == doc["median_ms"] and "answers" not in track
    # a bad track file: exit 2, one line
    bad = tmp_path / "bad.csv"
    bad.write_text("40,-212\n40,nan\n")
    r = _cli("--track", str(bad), "--quiet")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "bad.csv:2: Y = nan: must be a finite number" in r.stderr
