"""``make gestures``: the paper's gesture cases (Figure 5) into results/predictor/.

- gravity.png: (P1, P2) = (-0.1, 0.1) and (0.1, -0.1) MPa under gravity, gravity-free
  shape dashed (Figure 5A);
- free.png: one finger pressurised without gravity at (0.05, 0.05), (0.1, 0.1),
  (0.05, -0.05), (0.1, -0.1) MPa (the paper's free-pressurisation cases);
- grasps.png: two grasps for each of circle, ellipse and rectangle (Figures 5D-F),
  from the approach gesture statics.Obstacle documents;
- nn_training.png: validation residual per epoch of the NN predictors (Figures 5B, C, G, H),
  read from the histories of the checkpoints in ``--nn-dir``;
- gestures.json: the figures' numbers (GestureResult.summary of every case).

Data flow: joint model (--model, default the committed surrogate) -> GripperProblem -> predictor.solvers.solve ->
predictor.model.plot. Every file is written atomically; ``--json`` prints gestures.json.
"""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from contract import cli  # noqa: E402
from contract.files import dumps, json_safe, write_text  # noqa: E402
from predictor.artefacts import GESTURES  # noqa: E402
from predictor.model.gripper import default_finger  # noqa: E402
from predictor.model.joint import load_joint  # noqa: E402
from predictor.nn.checkpoint import DEFAULT_DIR, load_predictor, nn_folder  # noqa: E402
from predictor.model.plot import draw_gesture, save_figure  # noqa: E402
from predictor.solvers.progress import set_quiet  # noqa: E402
from predictor.solvers.solve import APPROACH, solve  # noqa: E402
from predictor.model.statics import STATES, GripperProblem, parse_object  # noqa: E402

GRAVITY_CASES = [(-0.1, 0.1), (0.1, -0.1)]
FREE_CASES = [(0.05, 0.05), (0.1, 0.1), (0.05, -0.05), (0.1, -0.1)]
#: Two grasps per object at its default placement. With the FEM-trained joint (stiffer
#: than the analytic stand-in: 12 against 29 deg at 0.1 MPa) and contact on the finger's
#: faces, at (0.1, 0.2) MPa the circle and the ellipse hold at the limit (friction use
#: 0.97, 0.99) and the rectangle slips (1.46); at (0.2, 0.3) and (0.3, 0.2) all three hold
#: (friction use <= 0.80; gestures.json records it). Check a case with
#: ``python -m predictor.cli.gesture --p1 0.1 --p2 0.2 --object circle --json``.
GRASPS = {kind: [(0.2, 0.3), (0.3, 0.2)] for kind in ("circle", "ellipse", "rectangle")}
#: The NN checkpoints drawn in nn_training.png: file, label, contact kind.
NN_CURVES = (("gravity_nn_paper.pt", "gravity, paper MLP", False), ("gravity_nn.pt", "gravity, improved", False),
             ("contact_nn.pt", "contact (points: classifier, then per state a head and its correction stages)", True))


def _panel_row(path: Path, results: list, problems: list, titles: list, ncols: int) -> None:
    n = len(results)
    nrows = math.ceil(n / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 4.6 * nrows), squeeze=False)
    for ax, (res, i), problem, title in zip(axes.flat, results, problems, titles):
        draw_gesture(ax, res, i, problem, title)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.tight_layout()
    save_figure(fig, path, 120)


def load_curves(nn_dir: Path) -> list:
    """[(label, Predictor)] of the NN_CURVES checkpoints present in ``nn_dir``, each
    integrity-checked on load (ValueError, one line)."""
    return [(label, load_predictor(nn_dir / name, contact=contact)) for name, label, contact in NN_CURVES
            if (nn_dir / name).is_file()]


def nn_curves(curves: list, path: Path) -> None:
    """``path`` (nn_training.png) from the histories of the predictors ``curves`` (load_curves)."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for label, pred in curves:
        h = pred.history
        axes[0].semilogy(h["epoch"], h["val_force_mN"], "o-", ms=3, label=label + " (raw NN)")
        axes[1].semilogy(h["epoch"], h["val_moment_Nmm"], "o-", ms=3, label=label + " (raw NN)")
        polished = pred.metrics.get("val_polished")
        if polished:  # the delivered contact predictor: NN + Newton steps or the capped-LM polish
            axes[0].semilogy([h["epoch"][-1]], [polished["force_mN_mean"]], "*", ms=12,
                             label="contact NN + Newton / LM polish")
            axes[1].semilogy([h["epoch"][-1]], [polished["moment_Nmm_mean"]], "*", ms=12)
    for ax, bound, unit in ((axes[0], 2.0, "mN"), (axes[1], 1.2, "N·mm")):
        ax.axhline(bound, color="k", ls=":", label=f"paper's gravity NN ({bound} {unit})")
        ax.set_xlabel("epoch (last point: after L-BFGS)")
        ax.set_ylabel(f"mean validation residual ({unit})")
        ax.grid(True, which="both", alpha=0.3)
    if curves:
        axes[0].legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, 120)


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.cli.figures", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", folder=True, default="results/predictor", help="output folder")
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: the committed surrogate, "
                    "predictor.defaults)")
    ap.add_argument("--nn-dir", type=nn_folder, default=DEFAULT_DIR,
                    help=f"folder of the NN checkpoints for nn_training.png (default {DEFAULT_DIR})")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = ap.parse_args(argv)
    set_quiet(args.quiet)
    torch.set_num_threads(1)
    out = Path(args.out)
    with ap.errors():  # every input is read before the solves
        joint = load_joint(args.model, default_finger())   # the figures' finger: the paper's
        curves = load_curves(args.nn_dir)
    summary: dict = {"joint": joint.name, "approach_MPa": APPROACH}

    gravity = GripperProblem(joint)
    grav = solve(gravity, torch.tensor(GRAVITY_CASES, dtype=torch.float64))
    summary["gravity"] = [grav.summary(i) for i in range(len(GRAVITY_CASES))]
    _panel_row(out / "gravity.png", [(grav, i) for i in range(2)], [gravity] * 2,
               [f"gravity, P = {p} MPa (dashed: no gravity)" for p in GRAVITY_CASES], 2)

    weightless = GripperProblem(joint, gravity=False)
    free = solve(weightless, torch.tensor(FREE_CASES, dtype=torch.float64))
    summary["free"] = [free.summary(i) for i in range(len(FREE_CASES))]
    _panel_row(out / "free.png", [(free, i) for i in range(4)], [weightless] * 4,
               [f"no gravity, P = {p} MPa" for p in FREE_CASES], 4)

    panels, problems, titles = [], [], []
    summary["grasps"] = {}
    for kind, cases in GRASPS.items():
        obs = parse_object(kind)
        grasp = GripperProblem(joint, obstacle=obs, approach=APPROACH)
        res = solve(grasp, torch.tensor(cases, dtype=torch.float64))
        summary["grasps"][kind] = [res.summary(i) for i in range(len(cases))]
        for i, p in enumerate(cases):
            panels.append((res, i))
            problems.append(grasp)
            state = STATES[int(res.states()[i])]
            titles.append(f"{kind}, P = {p} MPa: N = {float(res.normal_force_N[i]):.2f} N, {state}"
                          if bool(res.converged[i]) else f"{kind}, P = {p} MPa: NOT CONVERGED")
    _panel_row(out / "grasps.png", panels, problems, titles, 2)
    nn_curves(curves, out / "nn_training.png")
    GESTURES.check(json_safe(summary), str(out / "gestures.json"))
    write_text(out / "gestures.json", dumps(summary))  # no trailing newline, as committed
    if args.json:
        cli.print_json(summary)
    else:
        print(f"[gestures] wrote {out}/gravity.png free.png grasps.png nn_training.png gestures.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
