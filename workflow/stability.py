"""Why a campaign sample failed: its load path probed for stability and contact changes.

    python -m workflow.stability DATASET [--samples ID,...] [--load P,F1,F2,M ...]
        [--fine-from 0.8] [--fine-step 0.01] [--out results/fem/stability_<dataset>.json] [--json]

Data flow: the dataset's failed samples (their ids and inputs from the shards, or the
loads given) -> for each, the dataset's own joint solver (workflow.mirror.recorded_solver:
joint, mesh, formulation, solver settings) from zero along the linear load path
a(s) = s a_target, in segments s_0 < s_1 < ... (coarse steps of ``--coarse-step`` up to
``--fine-from``, then ``--fine-step``), each segment solved by fem.solvers.load_path's cut-back
Newton -> at every converged s:

* ``unstable_modes``: the negative eigenvalues of the stiffness there
  (fem.solvers.load_path.LoadPathSolver.unstable_modes, Sylvester's inertia of an exact LDL^T): 0
  while the equilibrium is stable under these loads; it turns 1 where an eigenvalue
  passes through zero, a limit point under load control (past it no nearby equilibrium
  exists, and Newton fails however small the step) or a bifurcation;
* ``closed_pairs``: the closed valley contact pairs (node-to-node, fem.physics.contact), the
  contact state; a jump between segments is a change of contact state;
* the tip (mm), phi_end and the cap rotation (deg);

-> the first segment that does not converge and its reason, and a verdict per sample:
``limit point`` (unstable_modes > 0 before the failure, or the inertia changes across
the last converged segment), ``contact change`` (the closed pairs jump at the failure
with the inertia unchanged), or ``solver failure`` (neither). The JSON (atomic) holds
every probe point; units mm, N, MPa, N·mm, degrees, seconds. One rank (the
factorisation's inertia is counted on one process).

Exit 0 when the probe ran (whatever it found), 2 for bad input.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from workflow.artefacts import STABILITY
from fem.options import one_rank
from workflow.mirror import recorded_solver
from workflow.shards import Manifest, read_shard


def failed_samples(root: str | Path) -> list[dict]:
    """Every failed sample of a dataset: {"sample_id", "inputs" (4,), "reason"}, from its shards."""
    root = Path(root)
    manifest = Manifest.load(root)
    out = []
    for entry in manifest.shards:
        if not entry.failures:
            continue
        arrays, _ = read_shard(root / entry.file)
        for sid, x, why in zip(arrays["failed_sample_id"], arrays["failed_inputs"], arrays["failed_reason"]):
            out.append({"sample_id": int(sid), "inputs": [float(v) for v in x], "reason": str(why)})
    return out


def path_points(coarse_step: float, fine_from: float, fine_step: float) -> list[float]:
    """The path parameters s (0, 1] probed: coarse steps to ``fine_from``, then fine ones to 1."""
    coarse = np.arange(coarse_step, fine_from + 1e-12, coarse_step)
    fine = np.arange(fine_from + fine_step, 1.0 + 1e-12, fine_step)
    s = np.unique(np.round(np.concatenate([coarse, fine, [1.0]]), 10))
    return [float(v) for v in s if v <= 1.0]


def probe_path(solver, target: np.ndarray, points: list[float], say=print) -> dict:
    """Follow s a_target from zero through ``points`` (module docstring) on ``solver`` (a
    fem.solvers.joint.JointSolver); the probe's record: its points, the failure (None if it
    reached s = 1) and the verdict."""
    lp = solver.solver
    solver.reset()
    record, failure, s0 = [], None, 0.0
    t0 = time.perf_counter()
    for s in points:
        outcome = lp.follow(s0 * target, s * target)
        if not outcome.converged:
            failure = {"s_from": s0, "s_to": s, "reached_s": reached(outcome.state, target),
                       "reason": outcome.reason, "cutbacks": outcome.cutbacks}
            break
        s0 = s
        anchors = solver.positions()
        point = {"s": s, "newton": outcome.newton_iterations, "cutbacks": outcome.cutbacks,
                 **lp.stiffness_spectrum(),
                 "closed_pairs": int(sum(int((g < 0).sum()) for g in solver.contact.gaps(solver.u).values())),
                 "tip_mm": anchors[-1].tolist(), "cap_rotation_deg": math.degrees(solver.cap_rotation()),
                 "wall_s": time.perf_counter() - t0}
        record.append(point)
        say(f"  s = {s:.4f}: Newton {sum(outcome.newton_iterations)}, unstable modes {point['unstable_modes']}, "
            f"lowest eigenvalue {point['lowest_eigenvalue']:.3e} N/mm, closed pairs {point['closed_pairs']}, "
            f"tip ({point['tip_mm'][0]:.3f}, {point['tip_mm'][1]:.3f}) mm")
    return {"points": record, "failure": failure, "verdict": verdict(record, failure),
            "wall_s": time.perf_counter() - t0}


def reached(state: np.ndarray, target: np.ndarray) -> float:
    """The path parameter s of the load ``state`` = s ``target``."""
    j = int(np.argmax(np.abs(target)))
    return float(state[j] / target[j])


def verdict(points: list[dict], failure: dict | None) -> str:
    """solved / limit point / contact change / solver failure (module docstring)."""
    if failure is None:
        return "solved"
    if any(p["unstable_modes"] > 0 for p in points) or (
            len(points) >= 3 and limit_ahead([p["s"] for p in points], [p["lowest_eigenvalue"] for p in points],
                                             failure["s_to"])):
        return "limit point"
    if len(points) >= 2 and points[-1]["closed_pairs"] != points[-2]["closed_pairs"]:
        return "contact change"
    return "solver failure"


def limit_ahead(s: list[float], lam: list[float], s_fail: float) -> bool:
    """Whether the lowest eigenvalue, extrapolated from its last three values as a
    quadratic in s (lambda^2 is linear in s near a fold: lambda ~ sqrt(s_c - s)), reaches
    zero before ``s_fail``, the first path parameter that did not converge."""
    x, y = np.asarray(s[-3:]), np.asarray(lam[-3:]) ** 2
    slope, icept = np.polyfit(x, y, 1)
    return bool(slope < 0 and -icept / slope <= s_fail + 1e-12)


def add_path_options(ap, fine_step: float) -> None:
    """The dataset, --samples and the path's segments (path_points), shared with
    workflow.resolve."""
    ap.add_argument("dataset", help="campaign dataset folder (its manifest names the joint and discretisation)")
    ap.add_argument("--samples", type=cli.number_list(0, None), metavar="ID,...",
                    help="these failed sample ids only (default: every failed sample)")
    ap.add_argument("--coarse-step", type=cli.number(0.0, 1.0, open_lo=True), default=0.1,
                    help="path step up to --fine-from (default 0.1)")
    ap.add_argument("--fine-from", type=cli.number(0.0, 1.0), default=0.8,
                    help="path parameter from which the fine steps start (default 0.8)")
    ap.add_argument("--fine-step", type=cli.number(0.0, 1.0, open_lo=True), default=fine_step,
                    help=f"path step from --fine-from on (default {fine_step:g})")


def chosen(ap, failed: list[dict], samples, dataset) -> list[dict]:
    """The failed samples ``samples`` asks for (all for None); an id that is not a failure
    is a usage error (one line, exit 2)."""
    if samples is None:
        return failed
    wanted = {int(i) for i in samples}
    unknown = sorted(wanted - {f["sample_id"] for f in failed})
    if unknown:
        ap.error(f"--samples: {unknown} are not failed samples of {dataset}")
    return [f for f in failed if f["sample_id"] in wanted]


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m workflow.stability", description=__doc__.split("\n\n")[0])
    add_path_options(ap, fine_step=0.01)
    ap.add_output("--out", suffix=".json", help="the probe's JSON (default results/fem/stability_<dataset>.json)")
    cli.add_quiet(ap)
    comm = MPI.COMM_WORLD
    one_rank(ap, comm)
    args = ap.parse_args(argv)
    with ap.errors():
        manifest = Manifest.load(args.dataset)
        failed = failed_samples(args.dataset)
    failed = chosen(ap, failed, args.samples, args.dataset)
    out = Path(args.out or f"results/fem/stability_{Path(args.dataset).name}.json")
    cli.setup_logging(args.quiet)
    points = path_points(args.coarse_step, args.fine_from, args.fine_step)
    say = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else (lambda s: print(s, flush=True))
    with ap.errors(), cli.heartbeat("workflow.stability"):
        solver = recorded_solver(manifest.config, MPI.COMM_SELF)
        doc = {"dataset": args.dataset, "discretisation": manifest.config.get("formulation"),
               "mesh": solver.mesh_info(), "path_points": points, "samples": []}
        for f in failed:
            say(f"sample {f['sample_id']}: load {f['inputs']} (P MPa, F1 N, F2 N, M N·mm)")
            probe = probe_path(solver, np.asarray(f["inputs"]), points, say)
            doc["samples"].append({**f, **probe})
            say(f"sample {f['sample_id']}: {probe['verdict']}" + (
                f", path stops at s = {probe['failure']['reached_s']:.4f}" if probe["failure"] else ""))
            STABILITY.write(out, doc)
    if args.json:
        cli.print_json(doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
