"""The predictor's command lines (predictor.cli.gesture) and joint loading: JSON keys, one-line
errors with exit 2, the real surrogate, the surrogate wrapper, finger options on the
command line, and that importing the predictor imports no dolfinx.

Every test states the exact or expected answer it checks.
"""
from __future__ import annotations

import json
import ast
import subprocess
import sys

import numpy as np
import pytest
import torch

from contract.spec import INPUT_BOX
from predictor.model.gripper import DEFAULT_OUTLINE, GripperParams
from predictor.model.joint import load_joint
from predictor.solvers.solve import solve
from predictor.model.statics import GripperProblem

from test_predictor_common import DT, PAPER_CHAIN, ROOT, SURROGATE, THREE, THREE_FINGER, THREE_P, J, run_gesture_cli, t

torch.set_num_threads(1)


def test_cli_json_and_errors():
    """--json prints the issue's keys (converged true, tau 2x3, per-joint residuals, tip)
    and exits 0; |P| > 0.3, an unknown object and a missing model exit 2 with one
    'error:' line on stderr."""
    ok = run_gesture_cli("--p1", "-0.1", "--p2", "0.1", "--model", "analytic", "--json")
    assert ok.returncode == 0, ok.stderr
    out = json.loads(ok.stdout)
    for key in ("converged", "tau", "residual_force_mN", "residual_moment_Nmm", "tip", "tip_angle_deg",
                "contact_force_N", "slip", "iterations", "time_ms"):
        assert key in out
    assert out["converged"] and np.array(out["tau"]).shape == (2, 3) and len(out["residual_force_mN"]) == 2
    for args in (("--p1", "0.5", "--p2", "0"), ("--p1", "0", "--p2", "0", "--object", "blob"),
                 ("--p1", "0", "--p2", "0", "--model", "/nonexistent.pt")):
        bad = run_gesture_cli(*args)
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1, bad.stderr
        assert bad.stderr.startswith("python -m predictor.cli.gesture: error:"), bad.stderr


def test_cli_text_is_the_json_one_key_a_line(capsys):
    """Without --json the gesture prints the --json answer's keys one a line, right-aligned
    in 20 characters, ``key: value`` (contract.cli.print_fields, the table bench and
    surrogate.evaluate print too)."""
    from predictor.cli.gesture import main

    argv = ["--p1", "-0.1", "--p2", "0.1", "--model", "analytic", "--quiet"]
    assert main(argv + ["--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split(": ", 1)[0] for ln in lines] == [f"{k:>20}" for k in doc]
    assert lines[list(doc).index("converged")] == f"{'converged':>20}: True"
    assert lines[list(doc).index("state")] == f"{'state':>20}: {doc['state']}"
    from contract.cli import print_fields

    print_fields({"a": 1.5, "long_key": None}, False)                  # width: the longest key's
    print_fields({"x": 0.123456}, False, 4, lambda v: f"{v:.2f}", sep="  ")
    print_fields({"y": float("nan")}, True)                            # strict JSON: NaN is null
    text, _, strict = capsys.readouterr().out.partition("{")
    assert text == "       a: 1.5\nlong_key: None\n   x  0.12\n" and json.loads("{" + strict) == {"y": None}


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
    from predictor.model.joint import SurrogateJoint

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
    module (each file of predictor/ and its sub-packages) leaves 'dolfinx' out of sys.modules."""
    modules = sorted(".".join(f.relative_to(ROOT).with_suffix("").parts) for f in (ROOT / "predictor").rglob("*.py")
                     if not f.stem.startswith("__"))
    assert {"predictor.solvers.solve", "predictor.solvers.newton", "predictor.cli.nn", "predictor.nn.answer"} <= set(modules)
    code = f"import sys, {', '.join(modules)}; print('dolfinx' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr


def test_cli_finger_kinematics_and_joint_weight(tmp_path):
    """predictor.cli.gesture --finger FILE --pressures P1,P2,P3 on the three-joint finger (and
    --kinematics cap --joint-weight split) exits 0; its JSON names the finger (name, sha256
    of the file), the kinematics and the joint weight, has tau 3x3, three
    joint_end_angle_deg whose last is tip_angle_deg, and the tip equals the Python solve's;
    --p1/--p2 with that finger exits 2 with one line asking for --pressures; --plot draws
    the three-joint gripper."""
    import hashlib

    path = tmp_path / "three.toml"
    path.write_text(THREE)
    png = tmp_path / "three.png"
    out = run_gesture_cli("--finger", str(path), "--pressures", "0.1,-0.05,0.2", "--model", "analytic",
                          "--kinematics", "cap", "--joint-weight", "split", "--json", "--plot", str(png))
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
    paper = json.loads(run_gesture_cli("--p1", "-0.1", "--p2", "0.1", "--model", "analytic", "--json").stdout)
    assert paper["finger"]["name"] == "paper" and (paper["kinematics"], paper["joint_weight"]) == ("cap", "split")
    assert paper["tip_angle_deg"] == paper["joint_end_angle_deg"][1]
    bad = run_gesture_cli("--finger", str(path), "--p1", "0", "--p2", "0", "--model", "analytic")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "finger 'three' has 3 joints: give --pressures with 3 values" in bad.stderr


def _predictor_imports():
    """(importer, imported module, name) of every ``from predictor.x import name`` in
    predictor/ and its sub-packages (top level and inside functions; not the old command
    paths' ``if __name__ == "__main__":`` blocks, aliases that run a command), and the set of
    command-line modules (a ``main`` function)."""
    found, clis = [], set()
    for path in sorted((ROOT / "predictor").rglob("*.py")):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        tree = ast.parse(path.read_text())
        if any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body):
            clis.add(name)
        runs = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
        skipped = {id(m) for n in runs for m in ast.walk(n)}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("predictor") and id(node) not in skipped:
                for alias in node.names:
                    sub = ROOT.joinpath(*node.module.split("."), f"{alias.name}.py")
                    module = f"{node.module}.{alias.name}" if sub.exists() else node.module
                    found.append((name, module, alias.name))
    return found, clis


def test_no_private_imports_and_no_library_imports_a_command_line():
    """Issue 34: no predictor module imports another's private (``_name``) names, and no
    library module (one without ``main``) imports a command-line module (one with ``main``:
    predictor.cli's, predictor.validation's; issue 61 split predictor.planning.atlas's
    command line off to predictor.cli.atlas). The check finds what it looks for: gesture,
    atlas and nn are command-line modules, and the solver's parts are imported by name
    (predictor.solvers.ramp's advance by atlas)."""
    found, clis = _predictor_imports()
    assert {"predictor.cli.gesture", "predictor.cli.nn", "predictor.cli.atlas", "predictor.cli.inverse"} <= clis
    assert "predictor.planning.atlas" not in clis
    assert ("predictor.planning.atlas", "predictor.solvers.ramp", "advance") in found
    assert ("predictor.cli.nn", "predictor.solvers.progress", "progress") in found     # a module by name
    private = [f for f in found if f[2].startswith("_")]
    assert private == []
    upward = [f for f in found if f[0] not in clis and f[1] in clis]
    assert upward == []


# ---------------------------------------------------------------------- a finger of another joint
J30 = (ROOT / "contract/joints/paper.toml").read_text().replace('name = "paper"', 'name = "j30"').replace(
    "length = 45.45 ", "length = 30.0 ")
FINGER_J30 = """format = "softjoint-finger/1"
name = "j30_finger"
base_gap = 50.0
base_angle_deg = -90.0
{parts}"""
JOINT_PART = '[[part]]\nkind = "joint"\nweight = 0.09\ncontact = true\njoint = "j30.toml"\n'
RIGID_PART = '[[part]]\nkind = "rigid"\nlength = {length}\nweight = {weight}\ncontact_points = 6\n'


def j30_finger(folder):
    """A 3-joint finger of a 30 mm joint file: joint, 60 mm link, joint, 60 mm link, joint,
    65 mm tip (the paper's rigid parts; joint weight 0.09 N, links 0.04 N, tip 0.06 N)."""
    from contract.finger import load_finger

    (folder / "j30.toml").write_text(J30)
    parts = [JOINT_PART, RIGID_PART.format(length=60.0, weight=0.04), JOINT_PART,
             RIGID_PART.format(length=60.0, weight=0.04), JOINT_PART, RIGID_PART.format(length=65.0, weight=0.06)]
    path = folder / "j30_finger.toml"
    path.write_text(FINGER_J30.format(parts="\n".join(parts)))
    return path, load_finger(path)


def test_finger_of_a_30mm_joint_has_its_own_chain(tmp_path):
    """Issue 37 §2: a finger of three joints of a 30 mm joint file, with the analytic
    stand-in of that joint (AnalyticJoint.for_joint: L = 30 mm, h = 3 mm). Without
    gravity at zero pressure the tip sits at the summed lengths, 3 x 30 + 60 + 60 + 65 =
    275 mm below the mount, exactly (to 1e-12 mm); under gravity each joint stretches
    axially by L F1 / EA (EA = 300 N) with F1 the weight hanging below its middle: half its
    own and everything distal (0.365, 0.235, 0.105 N), so the tip is 275 + 30 (0.705)/300
    mm down (to 1e-6 mm). Each contact anchor of a joint carries 30/10 = 3 mm of length,
    not the paper joint's 4.545 mm. The paper's joint model is refused for this finger
    (one line naming both joints)."""
    from predictor.model.gripper import chain_layout
    from predictor.model.joint import AnalyticJoint
    from predictor.solvers.problem import load_problem

    _, finger = j30_finger(tmp_path)
    assert [round(p.length, 12) for p in finger.parts] == [30.0, 60.0, 30.0, 60.0, 30.0, 65.0]
    model = AnalyticJoint.for_joint(finger.parts[0].spec)
    params = GripperParams(finger)
    free = solve(load_problem(None, None, gravity=False, params=params, joint=model), t([[0.0, 0.0, 0.0]]))
    assert bool(free.converged[0])
    np.testing.assert_allclose(free.pose.tip_end[0].numpy(), [25.0, -275.0], rtol=0, atol=1e-12)
    hanging = solve(load_problem(None, None, params=params, joint=model), t([[0.0, 0.0, 0.0]]))
    loads = [0.09 / 2 + 0.04 + 0.09 + 0.04 + 0.09 + 0.06, 0.09 / 2 + 0.04 + 0.09 + 0.06, 0.09 / 2 + 0.06]
    np.testing.assert_allclose(hanging.tau[0, :, 0].numpy(), loads, rtol=0, atol=1e-9)
    stretch = sum(30.0 * f / 300.0 for f in loads)
    np.testing.assert_allclose(hanging.pose.tip_end[0].numpy(), [25.0, -275.0 - stretch], rtol=0, atol=1e-6)
    layout = chain_layout(finger, "split", "centre_line")   # the anchors of the paper's centre-line contact
    for k in finger.joints:
        np.testing.assert_array_equal(layout.contact_length[layout.contact_part == k].numpy(), [3.0] * 10)
    with pytest.raises(ValueError) as err:
        load_problem("analytic", None, params=params)
    assert "\n" not in str(err.value) and "'paper'" in str(err.value) and "'j30'" in str(err.value)


def test_commands_refuse_a_model_of_another_joint_than_the_fingers(tmp_path):
    """Every command with a model and a finger checks them together (predictor.model.joint.
    load_joint(model, finger)): predictor.cli.gesture and predictor.cli.nn with the paper's
    analytic joint and the 30 mm joint's finger exit 2 with one line naming the finger's
    joint, before any solve or training; predictor.api.load_gripper refuses the pair too."""
    from predictor import api

    path, _ = j30_finger(tmp_path)
    gesture = run_gesture_cli("--finger", str(path), "--pressures", "0,0,0", "--model", "analytic")
    nn = subprocess.run([sys.executable, "-m", "predictor.cli.nn", "--variant", "gravity-improved", "--model", "analytic",
                         "--finger", str(path), "--epochs", "1", "--out", str(tmp_path / "nn.pt")],
                        cwd=ROOT, capture_output=True, text=True, timeout=60)
    for bad in (gesture, nn):
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1, bad.stderr
        assert "joint 1 of finger 'j30_finger' is 'j30'" in bad.stderr
    assert not (tmp_path / "nn.pt").exists()
    with pytest.raises(ValueError, match="joint 1 of finger 'j30_finger' is 'j30'"):
        api.load_gripper("analytic", finger=path)


# ---------------------------------------------------------------- issue 57: every tool takes every finger

FINGERS = ROOT / "tests" / "data" / "fingers"


def test_atlas_takes_the_finger_approach_and_gravity_options(tmp_path):
    """predictor.cli.atlas --finger --kinematics --approach zero --no-gravity (the options of
    predictor.cli.gesture) exits 0 and its JSON records them: the finger's name and sha256 of
    the file, its kinematics, approach_MPa null (ramped from zero with the object present),
    gravity false and the object's weight 0 N; the help advertises no ``x=`` for the object
    (an object is centred on X = 0)."""
    import hashlib

    out = tmp_path / "atlas.json"
    paper = ROOT / "contract" / "fingers" / "paper.toml"
    r = subprocess.run([sys.executable, "-m", "predictor.cli.atlas", "--object", "circle:y=-260", "--grid", "2",
                        "--finger", str(paper), "--kinematics", "tangent", "--approach", "zero", "--no-gravity",
                        "--out", str(out), "--quiet", "--json"], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["finger"] == {"name": "paper", "sha256": hashlib.sha256(paper.read_bytes()).hexdigest(),
                             "kinematics": "tangent", "joint_weight": "split", "outline": DEFAULT_OUTLINE}
    assert doc["approach_MPa"] is None and doc["gravity"] is False and doc["object_weight_N"] == 0.0
    assert json.loads(r.stdout)["finger"] == doc["finger"]
    helps = [subprocess.run([sys.executable, "-m", m, "--help"], cwd=ROOT, capture_output=True, text=True).stdout
             for m in ("predictor.cli.atlas", "predictor.cli.gesture")]
    for text in helps:
        assert "--finger" in text and "--approach" in text and "--no-gravity" in text
        assert "x=" not in text.replace("\n", " "), text


def test_atlas_solves_the_finger_approach_and_gravity_it_is_given(tmp_path):
    """predictor.cli.atlas --finger tests/data/fingers/long_tip.toml (a 5 mm longer tip)
    --no-gravity --approach -0.1,0.05 --path ramp on a 2 x 2 grid: each point's tip is
    predictor.solvers.solve's for that finger without gravity ramped from that approach (the
    problem predictor.cli.gesture builds from the same options) to 1e-6 mm (measured: 0),
    where the same finger with gravity is 0.02-0.06 mm away and the default problem (the
    paper's finger, gravity) 4.94-5.00 mm: more than 4 mm at every point. The object is
    not touched on this grid, so the approach is checked as recorded, not by its path."""
    from contract.finger import load_finger
    from predictor.solvers.problem import load_problem

    out, spec = tmp_path / "atlas.json", "circle:y=-260"
    finger = ROOT / "tests/data/fingers/long_tip.toml"
    r = subprocess.run([sys.executable, "-m", "predictor.cli.atlas", "--object", spec, "--grid", "2", "--box",
                        "0,0.1,0,0.1", "--path", "ramp", "--finger", str(finger), "--no-gravity", "--approach",
                        "-0.1,0.05", "--out", str(out), "--quiet"], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["finger"]["name"] == "long_tip" and doc["approach_MPa"] == [-0.1, 0.05] and doc["gravity"] is False
    p = torch.tensor([[a, b] for a in doc["p1_MPa"] for b in doc["p2_MPa"]], dtype=torch.float64)
    tips = torch.tensor(doc["tip_mm"], dtype=torch.float64).reshape(-1, 2)
    asked = load_problem(str(SURROGATE), spec, gravity=False, params=GripperParams(load_finger(finger)),
                         approach=(-0.1, 0.05))
    ref = solve(asked, p)
    assert bool(ref.converged.all())
    assert float((ref.pose.tip_end - tips).norm(dim=-1).max()) <= 1e-6
    assert doc["counts"]["no_contact"] == 4
    heavy = solve(load_problem(str(SURROGATE), spec, params=GripperParams(load_finger(finger)),
                               approach=(-0.1, 0.05)), p)
    assert float((heavy.pose.tip_end - tips).norm(dim=-1).min()) > 0.01     # --no-gravity reached the solve
    default = solve(load_problem(str(SURROGATE), spec), p)
    assert float((default.pose.tip_end - tips).norm(dim=-1).min()) > 4.0


def test_ctrl_c_during_the_atlas_ends_with_one_line_and_exit_130(tmp_path):
    """SIGINT while the atlas's grid is solved: exit 130 (128 + SIGINT), the last stderr
    line 'python -m predictor.cli.atlas: interrupted (Ctrl-C)', no traceback, nothing on
    stdout and no atlas written. The signal is sent once the grid solve has printed its
    first progress line (before that, the imports are running)."""
    import signal
    import time

    out = tmp_path / "atlas.json"
    p = subprocess.Popen([sys.executable, "-m", "predictor.cli.atlas", "--object", "circle", "--grid", "61",
                          "--path", "ramp", "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    first = ""
    while not first.startswith("[solve"):   # the grid solve's first progress line ("[solve 11 s] ramp step ...")
        line = p.stderr.readline()
        assert line, f"the atlas ended before any progress line: {first}"
        first = line
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    stdout, rest = p.communicate(timeout=120)
    lines = (first + rest).splitlines()
    assert p.returncode == 130, rest
    assert lines[-1] == "python -m predictor.cli.atlas: interrupted (Ctrl-C)"
    assert "Traceback" not in rest and "KeyboardInterrupt" not in rest
    assert stdout == "" and not out.exists()


def test_nn_predictor_message_names_the_problem_it_was_trained_for():
    """predict_gesture on another problem than the network's: one line naming the object
    in the spec's own words (no Obstacle(...) repr)."""
    from predictor.nn.answer import predict_gesture
    from predictor.nn.checkpoint import load_predictor
    from predictor.solvers.problem import load_problem

    joint = load_joint(None)
    pred = load_predictor(None, joint, contact=True, params=GripperParams())
    problem = load_problem(None, "circle:r=25", approach=pred.config.approach, joint=joint)
    with pytest.raises(ValueError) as exc:
        predict_gesture(pred, problem, torch.tensor([[0.1, 0.1]], dtype=torch.float64))
    assert str(exc.value) == ("an NN predictor answers only the problem it was trained for: object circle r=30 mm "
                              "at y=-195 mm (given circle r=25 mm at y=-195 mm)")


@pytest.mark.skipif(not SURROGATE.is_file(), reason="no committed surrogate checkpoint yet")
def test_gravity_nn_at_the_plane_answers_polished_and_says_so():
    """--method nn at (0.1, 0.1) MPa: the committed gravity NN learned one finger alone, and
    its gesture crosses X = 0, where the gripper's fingers meet, so its own answer is far
    outside the NN bound (raw residual over 2 mN); the answer is its tau polished on the
    gripper (at_plane, polished, exit 0), the raw residual beside the answer's (within the
    solver's 1e-4 mN), and it is the one --polish gives (tau within 1e-8). The stderr line
    of a raw answer outside the bound away from the plane: test_predictor_nn's
    test_gravity_nn_cli_answers_at_the_plane_polished."""
    def gesture(*args):   # run_gesture_cli's 60 s is too short for a polish beside other jobs
        return subprocess.run([sys.executable, "-m", "predictor.cli.gesture", "--p1", "0.1", "--p2", "0.1", "--method",
                               "nn", "--json", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)

    out = gesture()
    got = json.loads(out.stdout)
    assert out.returncode == 0 and got["converged"] and got["polished"] and got["at_plane"], out.stderr
    assert got["nn_problem"] == "finger_alone" and got["method"].startswith("nn+newton")
    assert max(got["raw_residual_force_mN"]) > 2.0 and max(got["residual_force_mN"]) <= 1e-4
    good = json.loads(gesture("--polish").stdout)
    assert good["converged"] and np.allclose(good["tau"], got["tau"], rtol=0, atol=1e-8)
