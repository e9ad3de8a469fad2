"""Issue 33 (no silent wrong answers) and issue 34 item 6, predictor side: the default
joint model does not depend on the working directory, every object the model cannot
represent is refused in the CLI and the API alike, non-converged results carry no
figures, every result says its state, friction use, mu, object weight and joint model,
the planning messages name the real cause, and long runs report progress.

The command-line rows (exit 2, one line, nothing written) are in tests/test_bad_input.py;
here the same inputs go through the Python API (``API_ROWS``), plus what a table row
cannot check: numbers, timings, the environment and figures.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor import grasp_atlas, inverse_pressures, load_gripper, solve_gesture
from predictor.solvers import progress
from predictor.defaults import RESULTS_ENV
from predictor.planning.atlas import atlas_from_json
from predictor.planning.inversion import parse_goal
from predictor.model.joint import AnalyticJoint, load_joint
from predictor.solvers.problem import load_problem
from predictor.solvers.solve import APPROACH, SolverOptions, solve
from predictor.model.statics import ContactParams, GripperProblem, Obstacle, finger_reach, out_of_reach

ROOT = Path(__file__).resolve().parents[1]
SURROGATE = ROOT / "results/surrogate/improved.pt"
ATLAS = ROOT / "results/predictor/atlas_circle.json"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMP_NUM_THREADS": "1", "PYVISTA_OFF_SCREEN": "true"}
needs_surrogate = pytest.mark.skipif(not SURROGATE.is_file(), reason="no committed surrogate checkpoint")


def t(x):
    return torch.tensor(x, dtype=torch.float64)


# ------------------------------------------------------------ default model, any cwd
def _outside(tmp_path: Path, *args: str, env: dict | None = None, code: str | None = None):
    """Run ``python -m predictor.cli.gesture ARGS`` (or ``python -c code``) from tmp_path, a
    folder outside the repository, with this worktree on PYTHONPATH."""
    env = {**ENV, "PYTHONPATH": str(ROOT), **(env or {})}
    argv = [sys.executable, "-c", code] if code else [sys.executable, "-m", "predictor.cli.gesture", *args]
    return subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


@needs_surrogate
def test_default_model_from_outside_the_repository(tmp_path):
    """From a folder outside the repository, predictor.cli.gesture and the API use the
    committed surrogate: the tip at (-0.1, 0.1) MPa is the in-process answer of
    results/surrogate/improved.pt, (43.80, -214.42) mm since the switch to the production
    surrogate ((42.6, -214.7) on the 1.8 mm one; the analytic joint's is (61.6, -207.7)),
    and both name that joint."""
    joint = load_joint(str(SURROGATE))
    ref = solve(GripperProblem(joint), t([[-0.1, 0.1]]))
    tip = ref.pose.tip_end[0].numpy()
    assert np.allclose(tip, [43.80, -214.42], atol=0.05), tip
    r = _outside(tmp_path, "--p1", "-0.1", "--p2", "0.1", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["joint"] == joint.name and np.allclose(out["tip"], tip, rtol=0, atol=1e-9)
    code = ("import json; from predictor import load_gripper, solve_gesture; "
            "print(json.dumps(solve_gesture(load_gripper(), -0.1, 0.1).summary()))")
    r = _outside(tmp_path, code=code)
    assert r.returncode == 0, r.stderr
    api = json.loads(r.stdout)
    assert api["joint"] == joint.name and np.allclose(api["tip"], tip, rtol=0, atol=1e-9)
    assert list(tmp_path.iterdir()) == []


def test_missing_default_model_is_an_error(tmp_path, monkeypatch):
    """A results folder without the surrogate ($SOFTJOINT_RESULTS): the CLI exits 2 with one
    line naming the missing file, the API raises the same ValueError; the analytic joint
    is used only when named."""
    missing = tmp_path / "nowhere"
    r = _outside(tmp_path, "--p1", "0", "--p2", "0", env={RESULTS_ENV: str(missing)})
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert f"default joint model {missing}/surrogate/improved.pt not found" in lines[0]
    monkeypatch.setenv(RESULTS_ENV, str(missing))
    with pytest.raises(ValueError, match="default joint model .* not found"):
        load_gripper()
    g = load_gripper("analytic")
    assert isinstance(g.problem.joint, AnalyticJoint)
    assert solve_gesture(g, -0.1, 0.1).summary()["joint"] == "analytic"


# ------------------------------------------------------------ objects, one validation
#: The bad-input table's object rows, through the API: (load_gripper kwargs, needle).
API_ROWS = [
    (dict(object="circle:x=15,r=20"), "object centre x = 15 mm"),
    (dict(object="circle:x=40,y=-80"), "object centre x = 40 mm"),
    (dict(object="circle:r=1e9"), "outside the model's [0.1, 500] mm half-size range"),
    (dict(object="ellipse:deg=20"), "must stay symmetric about X = 0"),
    (dict(object="rectangle:w=1000,h=2,y=-100"), "intersects the fingers at the approach gesture"),
    (dict(object="circle", mu=float("nan")), "mu: 'nan' is not a finite number"),
    (dict(object="circle", mu=0.0), "mu: 0 is outside (0, 5]"),
    (dict(object="circle", object_weight=-1.0), "object_weight: -1 is outside [0, 10] N"),
    (dict(object="circle", object_weight=1e9), "object_weight: 1e+09 is outside [0, 10] N"),
]


@pytest.mark.parametrize("kwargs, needle", API_ROWS, ids=[str(k) for k, _ in API_ROWS])
def test_api_refuses_what_the_cli_refuses(kwargs, needle):
    with pytest.raises(ValueError) as info:
        load_gripper("analytic", **kwargs)
    assert needle in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_finger_reach_bounds_every_point():
    """finger_reach is an upper bound: over the pressure box under gravity no pose point
    (joints' anchors, parts, contact samples, tip) lies farther from the base mount. The
    fingers pass through each other (plane_stiffness = 0), so that the most curled poses
    are in the box too: with the plane X = 0, the analytic joint's joint 1 reaches 99.8 of
    the input box's 100 N·mm at (0.3, 0.29) MPa, and at (0.3, 0.3) no equilibrium is found."""
    problem = GripperProblem(AnalyticJoint(), contact=ContactParams(plane_stiffness=0.0))
    p = torch.cartesian_prod(t([-0.3, -0.1, 0.1, 0.3]), t([-0.3, 0.0, 0.3]))
    res = solve(problem, p)
    assert bool(res.converged.all())
    pose = res.pose
    pts = torch.cat((pose.points, pose.joints.reshape(len(p), -1, 2), pose.tip_end[:, None]), 1)
    mount = t([0.5 * problem.params.finger.base_gap, 0.0])
    far = float((pts - mount).norm(dim=-1).max())
    assert far < finger_reach(problem.params), (far, finger_reach(problem.params))
    assert finger_reach(problem.params) == pytest.approx(60 + 65 + 2 * 1.5 * 45.45, abs=0.01)


def test_unreachable_object_answers_no_contact_at_once():
    """An object beyond the fingers' reach: every result says no_contact, with the
    object-free gesture's tau (bit for bit: it is that solve), NaN first contact, null
    friction figures, and no ramp (as fast as the object-free solve)."""
    joint = AnalyticJoint()
    far = GripperProblem(joint, obstacle=Obstacle(a=10.0, b=10.0, y=-900.0), approach=APPROACH)
    near = GripperProblem(joint, obstacle=Obstacle(a=10.0, b=10.0, y=-240.0), approach=APPROACH)
    assert out_of_reach(far) and not out_of_reach(near)
    p = t([[0.2, 0.2], [-0.1, 0.1]])
    res = solve(far, p)
    free = solve(GripperProblem(joint), p)
    assert torch.equal(res.tau, free.tau) and bool(res.first_contact.isnan().all())
    s = res.summary(0)
    assert (s["state"], s["contact_force_N"], s["friction_use"], s["slip"]) == ("no_contact", 0.0, None, None)
    assert (s["mu"], s["object_weight_N"]) == (0.3, 0.2)
    assert res.iterations.tolist() == free.iterations.tolist()   # no ramp steps


# ------------------------------------------------------------ states and figures
def test_not_converged_result_has_null_figures():
    """A grasp stopped after one iteration: state not_converged, and tip, angles, tau,
    contact and friction figures all null in the summary."""
    problem = GripperProblem(AnalyticJoint(), obstacle=Obstacle(), approach=APPROACH)
    res = solve(problem, t([[0.3, 0.3]]), SolverOptions(max_iter=1, cutbacks=0))
    assert not bool(res.converged[0])
    s = res.summary(0)
    assert s["state"] == "not_converged" and s["converged"] is False
    for key in ("tau", "tip", "tip_angle_deg", "contact_force_N", "friction_N", "friction_use", "slip"):
        assert s[key] is None, key


def test_state_and_friction_use_follow_the_contact_law():
    """friction_use = |f|/(mu N) = |lambda|/mu, recomputed from the forces on the finger:
    the tangential share of the contact forces over mu times their normal share; a grasp
    that holds at mu = 0.3 slips at mu = 0.1 (its use then > 1: 0.55 and 1.66 at (0.1, 0.15) MPa
    on the analytic joint, the tip's inner face on the circle), and mu and the object's
    weight are the ones asked for (API kwargs), the weight scaled out without gravity."""
    joint = AnalyticJoint()
    hold = load_problem("analytic", "circle", joint=joint)
    p = t([[0.1, 0.15]])
    res = solve(hold, p)
    s = res.summary(0)
    assert s["state"] == "holds" and s["slip"] is False and 0 < s["friction_use"] <= 1
    st = hold.residual(res.pressures, res.tau)
    d, n = hold.obstacle.distance_normal(st.contact.points)
    f = st.contact.forces[0]
    normal = (f * n[0]).sum(-1)                       # N_k >= 0 along the outward normal
    tangent = f - normal[:, None] * n[0]
    use = float(tangent.norm(dim=-1).sum() / (0.3 * normal.sum()))
    assert use == pytest.approx(s["friction_use"], rel=1e-9)
    assert s["mu"] == 0.3 and s["object_weight_N"] == 0.2
    slips = solve(load_problem("analytic", "circle", joint=joint, mu=0.1), p).summary(0)
    assert slips["state"] == "slips" and slips["friction_use"] > 1 and slips["mu"] == 0.1
    light = load_problem("analytic", "circle", joint=joint, object_weight=0.05, gravity=False)
    assert solve(light, p).summary(0)["object_weight_N"] == 0.0


def test_no_contact_gesture_has_no_friction_sentinel():
    """predictor.cli.gesture --p1 -0.02 --p2 -0.02 --object circle: nothing touches, so state
    no_contact with friction_use and slip null (it printed slip true and 1000.0). (At
    (-0.02, 0) MPa the tip's inner face, 10 mm nearer the circle than its centre line,
    touches it.)"""
    g = solve_gesture(load_gripper("analytic", "circle"), -0.02, -0.02)
    s = g.summary()
    assert g.state == "no_contact" and s["state"] == "no_contact" and s["contact_force_N"] == 0.0
    assert s["friction_use"] is None and s["slip"] is None and s["first_contact_MPa"] is None


# ------------------------------------------------------------ planning inputs and messages
def test_planning_inputs_refused_in_the_api():
    """grid=1, an inverted or out-of-range box and min_normal=nan, which the CLI refuses,
    are one-line ValueErrors in the API too (before any solve)."""
    g = load_gripper("analytic", "circle")
    for kwargs, needle in ((dict(grid=1), "grid: 1 is outside [2, 201]"),
                           (dict(grid=2.5), "grid: 2.5 is not an integer"),
                           (dict(box=(0.2, 0.1, 0.0, 0.3)), "expected P1LO < P1HI"),
                           (dict(box=(0.0, 0.5, 0.0, 0.3)), "box: 0.5 is outside [-0.3, 0.3] MPa"),
                           (dict(box=(0.0, 0.1)), "expected 4 numbers")):
        with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace("[", r"\[")):
            grasp_atlas(g, **kwargs)
    for kwargs, needle in ((dict(min_normal=float("nan")), "min_normal: 'nan' is not a finite number"),
                           (dict(min_normal=11.0), "min_normal: 11 is outside [0, 10] N"),
                           (dict(box=(0.3, -0.3, 0.0, 0.1)), "expected P1LO < P1HI")):
        with pytest.raises(ValueError) as info:
            inverse_pressures(g, **kwargs)
        assert needle in str(info.value)


def test_tip_angle_goal_is_wrapped():
    """tip:X,Y,631.63 is the goal -88.37 deg (631.63 - 720), as tip_angle_deg reports it."""
    assert parse_goal("tip:9.04,-214.93,631.63").angle_deg == pytest.approx(-88.37, abs=1e-9)
    assert parse_goal("tip:0,-200,-190").angle_deg == pytest.approx(170.0, abs=1e-9)
    assert parse_goal("tip:0,-200,180").angle_deg == 180.0


def test_hold_of_an_object_nothing_touches_says_so():
    """A 1 mm circle 24 mm below the straight finger's reach (about 216 mm): every start
    converged and nothing touches it, which is what the answer says. (Between the fingers,
    at the default Y = -195 mm, the inner faces meet at X = 0 and squeeze it: it holds.)"""
    g = load_gripper("analytic", "circle:r=1,y=-240")
    with pytest.raises(ValueError, match="nothing touches the object at any pressure of the box"):
        inverse_pressures(g, goal="hold")


@needs_surrogate
@pytest.mark.skipif(not ATLAS.is_file(), reason="no committed circle atlas")
def test_min_normal_beyond_reach_names_the_normal_force_limit():
    """--min-normal 10 on the circle: infeasible, goal_met false, and the reason gives the
    most normal force a hold reaches (the committed atlas' best, within the search's)
    instead of a friction figure; an atlas computed with gravity is refused for a
    question without it."""
    g = load_gripper(object="circle")
    atlas = atlas_from_json(ATLAS, g.problem)
    ans = inverse_pressures(g, goal="hold", min_normal=10.0, atlas=atlas)
    s = ans.summary()
    assert s["status"] == "infeasible" and s["goal_met"] is False and "state" not in s
    limit = float(atlas.normal_N[atlas.state == 1].max())
    assert "the normal force of a hold reaches at most" in ans.reason and "10 N" in ans.reason
    said = float(ans.reason.split("at most ")[1].split(" N")[0])
    assert limit - 1e-3 <= said < 10.0
    free = load_gripper(object="circle", gravity=False)
    with pytest.raises(ValueError, match="gravity = True, this question has False"):
        atlas_from_json(ATLAS, free.problem)
    with pytest.raises(ValueError, match="the atlas was solved with gravity = True"):
        inverse_pressures(free, goal="hold", atlas=atlas)


# ------------------------------------------------------------ heartbeat and figures
def test_heartbeat_on_stderr_and_quiet(capsys, monkeypatch):
    """A heartbeat prints on stderr once its interval has passed (never on stdout);
    set_quiet silences it; the atlas sweep beats once per ring."""
    beat = progress.Heartbeat("x", every=0.0)
    beat("one")
    progress.set_quiet(True)
    beat("two")
    progress.set_quiet(False)
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and out.err.startswith("[x ") and "one" in out.err
    monkeypatch.setattr(progress, "EVERY", 0.0)
    grasp_atlas(load_gripper("analytic", "circle"), grid=3, box=(0.1, 0.3, 0.1, 0.3))
    err = capsys.readouterr().err
    assert err.count("[atlas") >= 2 and "points converged" in err
    monkeypatch.setattr(progress, "EVERY", 10.0)
    start = time.monotonic()
    grasp_atlas(load_gripper("analytic", "circle"), grid=3, box=(0.1, 0.3, 0.1, 0.3))
    assert capsys.readouterr().err == "" or time.monotonic() - start >= 10.0


def test_gesture_figure_has_legend_and_joint_title():
    """A gesture panel has a legend naming the joints' outer bands, rigid parts, the
    unloaded shape, the plane X = 0 where the fingers meet, the object and its contact
    points, and its title names the joint model and the state; a non-converged panel
    says so without figures."""
    import matplotlib.pyplot as plt

    from predictor.model.plot import draw_gesture

    problem = load_problem("analytic", "circle")
    res = solve(problem, t([[0.2, 0.3], [0.3, 0.3]]))
    bad = solve(problem, t([[0.3, 0.3]]), SolverOptions(max_iter=1, cutbacks=0))
    fig, axes = plt.subplots(1, 2)
    draw_gesture(axes[0], res, 0, problem)
    draw_gesture(axes[1], bad, 0, problem)
    labels = [x.get_text() for x in axes[0].get_legend().get_texts()]
    assert labels == ["joints (outer band)", "rigid parts", "unloaded (tau = 0)", "X = 0 (fingers meet)", "object",
                      "contact"]
    title = axes[0].get_title()
    assert "analytic" in title and "holds" in title and "N=" in title
    assert "NOT CONVERGED" in axes[1].get_title() and "N=" not in axes[1].get_title()
    assert len(axes[1].lines) < len(axes[0].lines)   # the non-converged gesture is not drawn
    plt.close(fig)


# ------------------------------------------------------------ rows pending contract.cli (another agent)
#: Refused by contract.cli.Parser's write probe and negative comma lists once that change
#: merges (contract/cli.py is not this branch's): these fail until then.
PENDING_ROWS = [
    (["predictor.cli.gesture", "--p1", "0", "--p2", "0", "--plot", "/proc/x.png"], "/proc/x.png"),
    (["predictor.cli.gesture", "--p1", "0", "--p2", "0", "--plot", "{tmp}/missing/dir/x.png"], "{tmp}/missing/dir/x.png"),
    (["predictor.cli.atlas", "--object", "circle", "--grid", "2", "--out", "/proc/x.json"], "/proc/x.json"),
    (["predictor.cli.inverse", "--cases", "--out", "/proc/x.json"], "/proc/x.json"),
]


@pytest.mark.parametrize("argv, needle", PENDING_ROWS, ids=[" ".join(a) for a, _ in PENDING_ROWS])
def test_unwritable_outputs_refused_before_work(argv, needle, tmp_path):
    """A /proc path and a folder that does not exist are refused before any solve: exit 2,
    one line naming the path, no folder created."""
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    r = subprocess.run([sys.executable, "-m", *argv, "--quiet"], cwd=ROOT, env=ENV, capture_output=True,
                       text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and needle.replace("{tmp}", str(tmp_path)) in lines[0], \
        r.stderr[-1000:]
    assert list(tmp_path.iterdir()) == []


@needs_surrogate
def test_negative_values_in_comma_lists():
    """--pressures -0.1,0.1 and --approach -0.15,0, as --help shows them: the committed
    surrogate's gesture (pending contract.cli's negative comma lists)."""
    r = subprocess.run([sys.executable, "-m", "predictor.cli.gesture", "--pressures", "-0.1,0.1", "--approach",
                        "-0.15,0", "--json"], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert np.allclose(json.loads(r.stdout)["tip"], [43.80, -214.42], atol=0.05)
