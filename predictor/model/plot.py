"""Matplotlib drawing of gestures in the paper's colours (Figure 5).

Rigid parts red, joints blue, object green, the unloaded (tau = 0) shape dashed, each
named in the panel's legend; the title names the pressures, the grasp state and the joint
model. Both fingers are drawn: the right one solved, the left one its mirror. Each part is
drawn as its outline (predictor.model.gripper.outline_vertices: a rigid part's rectangle of its
height, a joint's band of the joint's outer height about its centre line), the surfaces
that touch, over its centre line (FingerPose.part_polylines); where the object presses
on the finger a black dot marks each part face's contact point (GestureResult.sites), and
the symmetry plane X = 0 where the fingers meet is a dotted line. Any finger chain. A
gesture that did not converge is not drawn (only its unloaded shape), and its title says
NOT CONVERGED without figures. Units mm.
"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from contract.files import atomic_path  # noqa: E402
from predictor.model.gripper import FingerPose, band_size, chain_layout, outline_vertices  # noqa: E402
from predictor.model.statics import STATES, GripperProblem  # noqa: E402


COLOURS = {"joint": "tab:blue", "rigid": "tab:red"}


def draw_fem_render(fig, ax, render: dict, png, label: str) -> None:
    """The whole-finger FEM's off-screen render (fem.studies.finger_records.render: coloured by |u|;
    ``render["extent_mm"]`` its global extent [X0, X1, Y0, Y1] mm) as the background of
    ``ax`` in equal global axes (mm), with its colour bar labelled ``label``."""
    x0, x1, y0, y1 = render["extent_mm"]
    ax.imshow(plt.imread(png), extent=(x0, x1, y0, y1), zorder=0)
    sm = plt.cm.ScalarMappable(cmap=render["cmap"], norm=plt.Normalize(0.0, render["u_max_mm"]))
    fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02, label=label)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")


def part_outlines(pose: FingerPose, index: int) -> list[tuple[str, np.ndarray]]:
    """[(kind, closed polygon (n, 2) mm)] of every part of sample ``index``, chain order:
    a joint's band (inner vertices base to tip, then the outer ones back), a rigid part's
    rectangle (predictor.model.gripper.outline_vertices' order)."""
    V = outline_vertices(pose.rows(slice(index, index + 1)), chain_layout(pose.finger))[0].detach().numpy()
    out, j, r, J, size = [], 0, 0, pose.finger.n_joints, band_size(pose.finger)
    for part in pose.finger.parts:
        if part.kind == "joint":
            band = V[size * j:size * (j + 1)]
            ring = np.concatenate((band[:size // 2], band[size // 2:][::-1]))
            j += 1
        else:
            base = size * J + 4 * r
            ring = V[[base, base + 1, base + 3, base + 2]]
            r += 1
        out.append((part.kind, np.concatenate((ring, ring[:1]))))
    return out


def draw_finger(ax, pose: FingerPose, index: int, dashed: bool = False) -> None:
    """Draw sample ``index`` of a FingerPose and its mirror on axes ``ax``: the outline of
    every part (filled, unless ``dashed``: the unloaded shape) over its centre line."""
    ls, lw = ("--", 1.0) if dashed else ("-", 1.2)
    flip = np.array([-1.0, 1.0])
    for kind, ring in part_outlines(pose, index):
        for xy in (ring, ring * flip):
            if not dashed:
                ax.fill(xy[:, 0], xy[:, 1], color=COLOURS[kind], alpha=0.25, lw=0)
            ax.plot(xy[:, 0], xy[:, 1], ls, color=COLOURS[kind], lw=lw, alpha=0.6 if dashed else 1.0)
    if not dashed:
        for p in (pose, pose.mirrored()):
            for kind, part in p.part_polylines():
                xy = part[index].detach().numpy()
                ax.plot(xy[:, 0], xy[:, 1], "-", color=COLOURS[kind], lw=0.6, alpha=0.8)


def draw_contacts(ax, result, index: int) -> None:
    """Mark the contact points of gesture ``index`` (GestureResult.sites, both fingers)."""
    sites = getattr(result, "sites", None)
    if sites is None:
        return
    site = sites[index].reshape(-1, 3).numpy()
    xy = site[site[:, 0] > 0, 1:]
    for pts in (xy, xy * np.array([-1.0, 1.0])):
        ax.plot(pts[:, 0], pts[:, 1], "o", color="k", ms=3.5, zorder=5)


def legend_handles(obstacle: bool) -> list:
    """Legend entries: joints, rigid parts, the unloaded shape (and the object)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    out = [Patch(facecolor="tab:blue", edgecolor="tab:blue", alpha=0.5, label="joints (outer band)"),
           Patch(facecolor="tab:red", edgecolor="tab:red", alpha=0.5, label="rigid parts"),
           Line2D([], [], color="0.4", ls="--", lw=1.0, label="unloaded (tau = 0)"),
           Line2D([], [], color="0.3", ls=":", lw=0.8, label="X = 0 (fingers meet)")]
    return out + ([Patch(color="tab:green", alpha=0.35, label="object"),
                   Line2D([], [], color="k", marker="o", ls="", ms=3.5, label="contact")] if obstacle else [])


def gesture_title(result, index: int, problem: GripperProblem) -> str:
    """Pressures, the grasp state (and normal force) and the joint model of gesture ``index``."""
    pressures = ", ".join(f"P{i + 1}={v:+.2f}" for i, v in enumerate(result.pressures[index].tolist()))
    if not bool(result.converged[index]):
        state = "  NOT CONVERGED"
    elif problem.obstacle is not None:
        state = f"  N={result.normal_force_N[index]:.2f} N  {STATES[int(result.states()[index])]}"
    else:
        state = ""
    plane = getattr(result, "plane_force_N", None)
    if plane is not None and bool(result.converged[index]) and float(plane[index]) > 0:
        state += f"  fingers meet ({float(plane[index]):.2f} N)"
    return f"{pressures} MPa{state}\n{problem.joint.name}"


def draw_gesture(ax, result, index: int, problem: GripperProblem, title: str | None = None) -> None:
    """Draw solve result ``index`` of ``problem``: gesture, the gravity- and load-free
    shape (tau = 0, dashed), the object and the legend; ``title`` replaces the first line
    of the default title (the joint model stays named)."""
    p = result.pressures[index:index + 1]
    with torch.no_grad():
        draw_finger(ax, problem.pose(p, torch.zeros(*p.shape, 3, dtype=p.dtype)), 0, dashed=True)
    obstacle = problem.obstacle
    if obstacle is not None:
        xy = obstacle.outline(200)
        xy = np.vstack([xy, xy[:1]])            # closed
        ax.fill(xy[:, 0], xy[:, 1], color="tab:green", alpha=0.35)
        ax.plot(xy[:, 0], xy[:, 1], color="tab:green")
    if bool(result.converged[index]):
        draw_finger(ax, result.pose, index)
        draw_contacts(ax, result, index)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axvline(0.0, color="0.3", ls=":", lw=0.8)
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
