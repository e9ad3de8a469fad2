"""Shared definitions of the predictor tests (test_predictor_*.py): the analytic joint and
its problems, the committed checkpoints' paths, a three-joint finger, the mirrored
(left-finger) joint and the gesture command line. No tests here."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import torch

from contract.finger import parse_finger
from predictor.model.gripper import GripperParams
from predictor.model.joint import AnalyticJoint, JointModel
from predictor.solvers.solve import APPROACH
from predictor.model.statics import GripperProblem, Obstacle

ROOT = Path(__file__).resolve().parents[1]
J = AnalyticJoint()
DT = torch.float64
GRAVITY = GripperProblem(J)
#: the paper's chain (tangent kinematics, lumped joint weights): the predictor before issue 14
PAPER_CHAIN = GripperParams(kinematics="tangent", joint_weight="lumped")
GRASP = GripperProblem(J, obstacle=Obstacle(), approach=APPROACH)


def t(x):
    return torch.tensor(x, dtype=DT)


SURROGATE = ROOT / "results/surrogate/improved.pt"
GRAVITY_NN = ROOT / "results/predictor/gravity_nn.pt"
CONTACT_NN = ROOT / "results/predictor/contact_nn.pt"
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


class LeftJoint(JointModel):
    """The physical left-finger joint seen in a chain frame whose +y is global +X (its
    top chamber is then on -y): R_L(P, F1, F2, M) = diag(1,-1)·R(P, F1, -F2, -M)."""

    name = "left"
    has_cap_rotation = True

    def __call__(self, inputs):
        return J(inputs * t([1.0, 1.0, -1.0, -1.0])) * t([1.0, -1.0])

    def anchors_and_cap(self, inputs):
        anchors, cap = J.anchors_and_cap(inputs * t([1.0, 1.0, -1.0, -1.0]))
        return anchors * t([1.0, -1.0]), -cap


def run_gesture_cli(*args):
    return subprocess.run([sys.executable, "-m", "predictor.cli.gesture", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
