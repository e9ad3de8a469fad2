"""Freeze the pre-issue-14 predictor's answers into tests/data/predictor_reference.json.

Run with the predictor of commit bbc0df4 (its hard-wired joint-link-joint-tip chain) on
the path, from the repository root:

    git worktree add /tmp/bbc0df4 bbc0df4
    PYTHONPATH=/tmp/bbc0df4 .venv/bin/python tests/data/freeze_predictor_reference.py --model results/surrogate/h1.8/paper.pt

It adds (or replaces) the entry of ``--model`` ("analytic" or a surrogate checkpoint
unchanged since that commit). The cases and their off-equilibrium tau offsets are those of
the analytic entry: gravity at (-0.1, 0.1) and (0.1, -0.1) MPa, no gravity at (0.1, 0.1),
and the circle grasp at (0.1, 0.2) from the approach gesture.
tests/test_predictor_finger.py::test_paper_finger_reproduces_the_frozen_predictor checks today's
generic chain against every entry.
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
from pathlib import Path

import torch

import predictor
from predictor.joint import load_joint
from predictor.solve import APPROACH, solve
from predictor.statics import GripperProblem, Obstacle

HERE = Path(__file__).resolve().parent
REFERENCE = HERE / "predictor_reference.json"
COMMIT = "bbc0df4"
POSE = ("joint1", "joint2", "link", "tip", "theta", "phi", "link_points", "tip_points")
#: tau_off - tau per joint [F1 N, F2 N, M N·mm]: a fixed step off the equilibrium
OFFSET = (0.05, -0.02, 0.8)


def problem(joint, case: str) -> GripperProblem:
    return {"gravity": GripperProblem(joint), "free": GripperProblem(joint, gravity=False),
            "circle": GripperProblem(joint, obstacle=Obstacle(), approach=APPROACH)}[case]


def freeze(model: str, cases: list[dict]) -> dict:
    joint = load_joint(model)
    rows = []
    for case in cases:
        prob = problem(joint, case["case"])
        p = torch.tensor([case["pressures_MPa"]], dtype=torch.float64)
        res = solve(prob, p)
        assert bool(res.converged[0]), case["case"]
        tau_off = res.tau + torch.tensor(OFFSET, dtype=torch.float64)
        st = prob.residual(res.pressures, tau_off)
        d = res.pose.tip[0, 1] - res.pose.tip[0, 0]   # the tip part's direction
        rows.append({
            "case": case["case"], "pressures_MPa": case["pressures_MPa"], "tau": res.tau[0].tolist(),
            "tip": res.pose.tip_end[0].tolist(), "tip_angle_rad": math.atan2(float(d[1]), float(d[0])),
            "iterations": int(res.iterations[0]), "normal_force_N": float(res.normal_force_N[0]),
            "friction_ratio": float(res.friction_ratio[0]),
            "pose": {k: getattr(res.pose, k)[0].tolist() for k in POSE},
            "tau_off": tau_off[0].tolist(), "residual_off": st.residual[0].tolist(),
            "contact_forces_off": st.contact.forces[0].tolist() if prob.obstacle is not None else None})
    return {"joint": joint.name, "cases": rows}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", required=True, help="'analytic' or a surrogate checkpoint")
    args = ap.parse_args()
    root = Path(predictor.__file__).resolve().parents[1]
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=7", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    if head != COMMIT:
        raise SystemExit(f"predictor imported from {root} at {head}, not {COMMIT}: see the docstring")
    doc = json.loads(REFERENCE.read_text())
    doc["models"][args.model] = freeze(args.model, doc["models"]["analytic"]["cases"])
    REFERENCE.write_text(json.dumps(doc) + "\n")
    print(f"{REFERENCE}: {args.model} ({doc['models'][args.model]['joint']}) frozen with the predictor of {COMMIT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
