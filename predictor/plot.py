"""Matplotlib drawing of gestures in the paper's colours (Figure 5).

Rigid parts red, joints blue, object green, the unloaded (tau = 0) shape dashed, each
named in the panel's legend; the title names the pressures, the grasp state and the joint
model. Both fingers are drawn: the right one solved, the left one its mirror. Any finger
chain (FingerPose.part_polylines: every joint's centre line through its anchors, every
rigid part's segment, in chain order). A gesture that did not converge is not drawn
(only its unloaded shape), and its title says NOT CONVERGED without figures. Units mm.
"""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from contract.files import atomic_path  # noqa: E402
from predictor.gripper import FingerPose  # noqa: E402
from predictor.statics import STATES, GripperProblem, Obstacle  # noqa: E402


def object_outline(obstacle: Obstacle, n: int = 200) -> np.ndarray:
    """Closed outline (n+1, 2) mm of the object in the global plane."""
    t = np.linspace(0.0, 2.0 * math.pi, n + 1)
    if obstacle.kind == "rectangle":
        a, b = obstacle.a, obstacle.b
        pts = np.array([[a, b], [-a, b], [-a, -b], [a, -b], [a, b]])
    else:
        pts = np.stack((obstacle.a * np.cos(t), obstacle.b * np.sin(t)), -1)
    c, s = math.cos(obstacle.angle), math.sin(obstacle.angle)
    return pts @ np.array([[c, s], [-s, c]]) + np.array([obstacle.x, obstacle.y])


def draw_finger(ax, pose: FingerPose, index: int, dashed: bool = False) -> None:
    """Draw sample ``index`` of a FingerPose and its mirror on axes ``ax``."""
    ls, lw = ("--", 1.2) if dashed else ("-", 3.0)
    colours = {"joint": "tab:blue", "rigid": "tab:red"}
    for p in (pose, pose.mirrored()):
        for kind, part in p.part_polylines():
            colour = colours[kind]
            xy = part[index].detach().numpy()
            ax.plot(xy[:, 0], xy[:, 1], ls, color=colour, lw=lw, alpha=0.6 if dashed else 1.0,
                    solid_capstyle="round")


def legend_handles(obstacle: bool) -> list:
    """Legend entries: joints, rigid parts, the unloaded shape (and the object)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    out = [Line2D([], [], color="tab:blue", lw=3, label="joints"),
           Line2D([], [], color="tab:red", lw=3, label="rigid parts"),
           Line2D([], [], color="0.4", ls="--", lw=1.2, label="unloaded (tau = 0)")]
    return out + ([Patch(color="tab:green", alpha=0.35, label="object")] if obstacle else [])


def gesture_title(result, index: int, problem: GripperProblem) -> str:
    """Pressures, the grasp state (and normal force) and the joint model of gesture ``index``."""
    pressures = ", ".join(f"P{i + 1}={v:+.2f}" for i, v in enumerate(result.pressures[index].tolist()))
    if not bool(result.converged[index]):
        state = "  NOT CONVERGED"
    elif problem.obstacle is not None:
        state = f"  N={result.normal_force_N[index]:.2f} N  {STATES[int(result.states()[index])]}"
    else:
        state = ""
    return f"{pressures} MPa{state}\n{problem.joint.name}"


def draw_gesture(ax, result, index: int, problem: GripperProblem, title: str | None = None) -> None:
    """Draw solve result ``index`` of ``problem``: gesture, the gravity- and load-free
    shape (tau = 0, dashed), the object and the legend; ``title`` replaces the first line
    of the default title (the joint model stays named)."""
    p = result.pressures[index:index + 1]
    with torch.no_grad():
        draw_finger(ax, problem.pose(p, torch.zeros(*p.shape, 3, dtype=p.dtype)), 0, dashed=True)
    obstacle = problem.obstacle
    if bool(result.converged[index]):
        draw_finger(ax, result.pose, index)
    if obstacle is not None:
        xy = object_outline(obstacle)
        ax.fill(xy[:, 0], xy[:, 1], color="tab:green", alpha=0.35)
        ax.plot(xy[:, 0], xy[:, 1], color="tab:green")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    ax.legend(handles=legend_handles(obstacle is not None), fontsize=6, loc="upper right")
    default = gesture_title(result, index, problem)
    ax.set_title(default if title is None else f"{title}\n{problem.joint.name}", fontsize=9)


def save_figure(fig, path, dpi: int) -> None:
    """Write ``fig`` to ``path`` atomically (contract.files.atomic_path) and close it."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)


def save_gesture(path: str, result, index: int, problem: GripperProblem) -> None:
    """One-panel PNG of gesture ``index`` of a result of ``problem``."""
    fig, ax = plt.subplots(figsize=(5, 5.5))
    draw_gesture(ax, result, index, problem)
    fig.tight_layout()
    save_figure(fig, path, 130)
