"""Physics tests of the whole-finger FEM (fem.solvers.finger) on a coarse mesh, one rank.

Exact references:
* a finger of one joint and one rigid part is the single joint (fem.solvers.joint.JointSolver)
  loaded at its end by the rigid part's weight: a dead axial force W along the finger and
  the couple of that force about r_10, M = -l/2 W sin(phi_c) (the part's centre of mass
  sits l/2 along the cap direction phi_c). Solved by fixed-point iteration on M;
* the y-mirror: the finger is symmetric about its own axis and gravity acts along that
  axis at rest, so (P, gravity) and (-P, gravity) give mirror-image fingers about the
  mount's vertical line X = base_gap / 2;
* zero pressure, no gravity: nothing moves.
"""
import math

import numpy as np
import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI  # noqa: E402

from fem.solvers.finger import FingerLoad, FingerSolver  # noqa: E402
from contract.finger import parse_finger  # noqa: E402
from fem.mesh.geometry import FingerGeometry, JointGeometry  # noqa: E402
from fem.solvers.joint import JointSolver, Load  # noqa: E402
from contract.spec import JOINT_LENGTH  # noqa: E402

pytestmark = pytest.mark.fem
#: a coarse tetrahedral joint, solved in P2 displacement (the defaults are the production hex2:3 mixed)
COARSE = JointGeometry(mesh_size=4.0, divisions=0, hex_size=None)
W, TIP = 0.5, 65.0          # N, mm: the rigid part's weight and length
ONE_JOINT = f"""
format = "softjoint-finger/1"
name = "one-joint"
base_gap = 50.0
[[part]]
kind = "joint"
weight = 0.0
[[part]]
kind = "rigid"
length = {TIP}
weight = {W}
"""


@pytest.fixture(scope="module")
def finger():
    return FingerSolver(FingerGeometry(parse_finger(ONE_JOINT), COARSE, 6.0), MPI.COMM_SELF, formulation="displacement")


@pytest.fixture(scope="module")
def bent(finger):
    """The one-joint finger at P = 0.15 MPa under gravity, and at P = -0.15 MPa."""
    plus = finger.solve(FingerLoad((0.15,), True))
    minus = finger.solve(FingerLoad((-0.15,), True))
    assert plus.converged and minus.converged
    return plus, minus


def test_zero_load_moves_nothing(finger):
    """No pressure, no gravity: u = 0 and the tip sits at (25, -JOINT_LENGTH - TIP)."""
    res = finger.solve(FingerLoad((0.0,), False))
    assert res.converged
    assert np.abs(finger.u.x.array).max() == 0.0
    np.testing.assert_allclose(res.tip, [25.0, -JOINT_LENGTH - TIP], atol=1e-12)
    assert math.degrees(res.tip_angle) == pytest.approx(-90.0, abs=1e-12)


def test_finger_of_one_joint_is_the_joint_under_the_weight_of_its_tip(bent):
    """The finger FEM against the single-joint FEM on the same coarse mesh size, loaded
    by the resultant of the distal weight (module docstring). Tolerances: the two meshes
    of the joint differ (the finger's is graded into its rigid part), which at h = 4 mm
    moves the anchors by up to ~0.1 mm and the cap by ~0.1 deg."""
    plus, _ = bent
    joint = JointSolver(COARSE, MPI.COMM_SELF, formulation="displacement")
    M = 0.0
    for _ in range(4):              # fixed point on the couple of the tip weight
        res = joint.solve(Load(0.15, W, 0.0, M))
        M = -0.5 * TIP * W * math.sin(res.cap_rotation)
    assert res.converged and abs(M) > 3.0          # the couple matters: > 3 N·mm
    assert abs(-0.5 * TIP * W * math.sin(res.cap_rotation) - M) < 1e-3
    local = plus.local_anchors[0]
    assert np.abs(local - res.anchors).max() < 0.15
    cap = plus.end_angle[0] - plus.theta[0]
    assert math.degrees(abs(cap - res.cap_rotation)) < 0.15
    # The rigid tip leaves along the cap: tip = r_10 + TIP (cos, sin)(end angle), global.
    end = plus.end_angle[0]
    np.testing.assert_allclose(plus.tip, plus.anchors[0, -1] + TIP * np.array([math.cos(end), math.sin(end)]),
                               atol=0.02)


def test_mirror_pressure_gives_the_mirror_finger(bent):
    """(P, g) and (-P, g): X - 25 flips sign, Y and the angles about -90 deg mirror, to
    solver tolerance (the mesh is mirrored node by node)."""
    plus, minus = bent
    assert 25.0 - plus.tip[0] > 20.0                 # P > 0 closes the right finger (towards -X)
    np.testing.assert_allclose(plus.tip[0] - 25.0, -(minus.tip[0] - 25.0), atol=1e-6)
    np.testing.assert_allclose(plus.tip[1], minus.tip[1], atol=1e-6)
    np.testing.assert_allclose(plus.tip_angle + math.pi / 2, -(minus.tip_angle + math.pi / 2), atol=1e-8)


def test_finger_sensitivities_match_finite_differences(finger):
    """The load-path solver's sensitivities of the finger problem (pressure: one-sided
    follower load; gravity: the weight body force summed over the parts) against central
    differences of continuation solves, h = 1e-3 MPa and 1e-3 g, at (0.15 MPa, gravity):
    the finger-frame probe displacements (anchors, fingertip) agree to 1e-3 of the largest
    derivative (the difference quotient's error is O(h^2))."""
    assert finger.solve(FingerLoad((0.15,), True)).converged
    S = finger.sensitivities()                         # (n_probe, 2, 2): mm/MPa, mm/g
    assert S.shape == (len(finger.probe_points), 2, 2)
    state, h = finger.solver.state.copy(), 1e-3
    for j in range(2):
        x = []
        for sign in (1, -1):
            step = np.zeros(2)
            step[j] = sign * h
            assert finger.solver.follow(finger.solver.state.copy(), state + step).converged
            x.append(finger.solver.probe_displacements()[:, :2])
        fd = (x[0] - x[1]) / (2 * h)
        scale = np.abs(S[:, :, j]).max()
        assert scale > 1.0                             # the tip moves by mm per MPa or per g
        np.testing.assert_allclose(S[:, :, j], fd, atol=1e-3 * scale)


def test_committed_finger_cases_are_recognised_by_their_finger_values():
    """fem.studies.finger_cases skips a case solved for the same finger, mesh and formulation. The
    committed cases (1.8 mm, displacement) were written when the paper's finger file had
    other comments, so another sha256: they are still its cases (by values), while a finger
    of another tip weight, or another joint mesh, is not."""
    import dataclasses
    import json
    from pathlib import Path

    from contract.finger import load_finger
    from contract.files import json_safe
    from fem.solvers.finger import same_settings

    case = json.loads((Path(__file__).resolve().parents[1] / "results/validation/finger_fem/"
                       "gravity_0.2_0.2.json").read_text())
    finger = load_finger()
    assert case["settings"]["finger_sha256"] != finger.digest

    def settings(f, joint=JointGeometry(mesh_size=1.8, divisions=0, hex_size=None)):
        return json_safe({"finger_sha256": f.digest, "geometry": FingerGeometry(f, joint).as_dict()})

    heavier = dataclasses.replace(finger, parts=finger.parts[:-1] + (
        dataclasses.replace(finger.parts[-1], weight=finger.parts[-1].weight * 1.2),))
    assert same_settings(case["settings"], settings(finger), finger)
    assert not same_settings(case["settings"], settings(heavier), heavier)
    assert not same_settings(case["settings"], settings(finger, COARSE), finger)
