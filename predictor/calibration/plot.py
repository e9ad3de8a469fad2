"""The before/after figure of the calibration against the finger FEM (predictor.calibration.fem).

One panel per held-out gesture, global frame (mm): the FEM's centre line (each joint's
proximal centre and anchors, then the fingertip; orange) over its render when the case
has one (fem.studies.finger_cases' PNG, coloured by |u|), the uncalibrated predictor's parts
(red, dashed) and the calibrated one's (black), the FEM fingertip circled; the title gives
both fingertip errors (mm). matplotlib (Agg), written atomically.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from contract.files import atomic_path
from predictor.calibration.fem import FemCase, FemStudy


def fem_centre_line(record: dict) -> np.ndarray:
    """(n, 2) mm: every joint's proximal centre and anchors, base to tip, then the
    fingertip (the rigid parts between them are straight)."""
    pts = [p for j in record["joints"] for p in [j["proximal_mm"], *j["anchors_mm"]]]
    return np.array(pts + [record["tip"]])


def _panel(ax, case: FemCase, lines_before, lines_after, e0: float, e1: float) -> None:
    import matplotlib.pyplot as plt

    r = case.record
    png = case.path.with_suffix(".png")
    render = r.get("render")
    if render and png.is_file():
        x0, x1, y0, y1 = render["extent_mm"]
        ax.imshow(plt.imread(png), extent=(x0, x1, y0, y1), zorder=0, alpha=0.6)
    fem = fem_centre_line(r)
    ax.plot(fem[:, 0], fem[:, 1], color="tab:orange", lw=4, alpha=0.8, zorder=1)
    for lines, style in ((lines_before, dict(color="tab:red", ls="--")), (lines_after, dict(color="black", ls="-"))):
        for poly in lines:
            ax.plot(poly[:, 0], poly[:, 1], lw=1.4, zorder=2, **style)
    ax.plot(*r["tip"], "o", mfc="none", mec="tab:orange", mew=2, ms=10, zorder=3)
    every = np.vstack([fem] + list(lines_before) + list(lines_after))
    lo, hi = every.min(0) - 15.0, every.max(0) + 15.0
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo).max()
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal")
    p1, p2 = r["pressures_MPa"]
    ax.set_title(f"P = ({p1:g}, {p2:g}) MPa: tip error {e0:.2f} -> {e1:.2f} mm", fontsize=9)
    ax.set_xlabel("X (mm)", fontsize=8)
    ax.set_ylabel("Y (mm)", fontsize=8)
    ax.tick_params(labelsize=7)


def heldout_figure(path: str | Path, study: FemStudy, cases: list[FemCase]) -> None:
    """The held-out gestures before and after the calibration (module docstring) to
    ``path`` (PNG); ``cases`` are the held-out FEM cases in the study's order."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(cases)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 4.6 * rows + 0.6), dpi=100, squeeze=False)
    rec = study.record
    for b, case in enumerate(cases):
        before = [lines[b] for lines in study.before.polylines]
        after = [lines[b] for lines in study.after.polylines]
        h = rec["heldout"][b]
        _panel(axes.flat[b], case, before, after, h["uncalibrated_error_mm"], h["calibrated_error_mm"])
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color="tab:orange", lw=4, alpha=0.8, label="FEM (the true finger)"),
               plt.Line2D([], [], color="tab:red", ls="--", label="predictor, uncalibrated"),
               plt.Line2D([], [], color="black", label="predictor, calibrated")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    u, c = rec["heldout_tip_error_uncalibrated_mm"], rec["heldout_tip_error_calibrated_mm"]
    fig.suptitle(f"held-out gestures, calibrated on {rec['observations_used']} FEM gestures: fingertip error "
                 f"mean {u['mean']:.2f} -> {c['mean']:.2f} mm\njoint model {rec['joint_model']}, FEM mesh "
                 f"{rec['fem']['mesh']}", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
