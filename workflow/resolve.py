"""Re-solve a campaign's failed samples along a finer load path; store those that converge.

    python -m workflow.resolve DATASET [--samples ID,...] [--coarse-step 0.1]
        [--fine-from 0.8] [--fine-step 0.005] [--max-it 24] [--min-step 2^-12]
        [--max-hours H] [--out results/fem/resolved_<dataset>.json] [--summary-only] [--json] [--quiet]

Why. A campaign sample is solved by continuation along its walk and, failing that, once
from zero, each by fem.solvers.load_path's cut-back Newton (12 iterations a step, steps halved
down to 1/256 of the path). Where the valley contact front sweeps over many node pairs
at once (the production train walk results/data/train, unit 36: P about -0.22 MPa with opposing end forces) that budget
runs out although the joint is stable there (workflow.stability: no negative eigenvalue
of the stiffness along the path, the lowest one flat). Such a sample is a solver
failure, and a finer path solves it.

Data flow: the dataset's failed samples (workflow.stability.failed_samples) -> for each,
the dataset's own solver (workflow.mirror.recorded_solver: joint, mesh, formulation,
contact penalty, tolerances unchanged) with only the path controls changed (``max_it``,
``min_step``), from zero along a(s) = s a_target in the segments of
workflow.stability.path_points, each by LoadPathSolver.follow -> at s = 1: anchors,
phi_end, cap rotation and the Jacobian (as a campaign sample), the stiffness's negative
eigenvalues and its eigenvalue nearest zero (LoadPathSolver.stiffness_spectrum: 0 and
positive for a stable equilibrium), and the trapezoid miss
of each walk pair it forms with its stored neighbours (workflow.store.walk_misses, mm:
a state on another branch than its neighbours shows as a miss far above the dataset's)
-> the sample moves in its unit's shard from the failure arrays to the data arrays
(sample order kept; ``meta["resolved"]`` records how: path points, path controls, Newton
iterations, wall time, the stiffness figures) -> the shard is rewritten atomically, then the manifest is
rebuilt from the shards (workflow.store.build_manifest), and the summary JSON (``summary``,
format workflow.artefacts.RESOLVED) is written again from every shard's meta. A sample that
does not reach s = 1 stays a failure, unchanged. ``--summary-only`` rewrites the summary
without solving.

Resume: a killed run leaves every shard either as it was or with its resolved samples
(atomic writes); the next run rebuilds the manifest from the shards before it starts,
and solves only what is still failed. The campaign's lock keeps a campaign and this
tool from writing one dataset at once.

Exit 0 when every requested sample is stored, 3 when some stay failed or the time
budget stopped the run (re-run to go on), 1 when a write failed, 2 for bad input.
Units: mm, N, MPa, N·mm; seconds.
"""
from __future__ import annotations

import fcntl
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.spec import phi_end
from fem.options import one_rank
from workflow.campaign import EXIT_INCOMPLETE, git_commit, save_shard
from workflow.artefacts import RESOLVED
from workflow.mirror import recorded_solver
from workflow.shards import DATA_KEYS, FAILURE_KEYS, Manifest, load_dataset, read_shard
from workflow.stability import add_path_options, chosen, failed_samples, path_points
from workflow.store import ShardScanner, build_manifest, shard_file, walk_consistency, walk_misses


def solve_along(solver, target: np.ndarray, points: list[float]) -> dict:
    """Follow s a_target from zero through ``points`` on ``solver`` (a JointSolver):
    {"converged", "reached_s", "newton", "cutbacks", "reason"}; at s = 1 the solver holds
    the converged state."""
    lp = solver.solver
    solver.reset()
    s0, newton, cutbacks = 0.0, [], 0
    for s in points:
        outcome = lp.follow(s0 * target, s * target)
        newton += outcome.newton_iterations
        cutbacks += outcome.cutbacks
        if not outcome.converged:
            j = int(np.argmax(np.abs(target)))
            return {"converged": False, "reached_s": float(outcome.reached[j] / target[j]), "newton": newton,
                    "cutbacks": cutbacks, "reason": outcome.reason}
        s0 = s
    return {"converged": True, "reached_s": 1.0, "newton": newton, "cutbacks": cutbacks, "reason": ""}


def sample_record(solver) -> dict:
    """The data arrays' entries of the solver's converged state (as workflow.campaign)."""
    anchors = solver.positions()
    return {"anchors": anchors, "jacobian": solver.sensitivities(), "phi_end": float(phi_end(anchors)),
            "cap_rotation": float(solver.problem.lagged[0].constant.value)}


def move_to_data(arrays: dict, sid: int, record: dict) -> dict:
    """The shard's arrays with failed sample ``sid`` stored as data (``record``: inputs,
    anchors, jacobian, phi_end, cap_rotation, newton_iterations, wall_time_s) at its place
    in sample order, and removed from the failure arrays."""
    out = {k: v for k, v in arrays.items()}
    keep = arrays["failed_sample_id"] != sid
    if keep.all():
        raise ValueError(f"sample {sid} is not a failure of this shard")
    for k in FAILURE_KEYS:
        out[k] = arrays[k][keep]
    at = int(np.searchsorted(arrays["sample_id"], sid))
    row = {**record, "sample_id": sid, "converged": True}
    for k in DATA_KEYS:
        out[k] = np.insert(arrays[k], at, np.asarray(row[k], dtype=arrays[k].dtype), axis=0)
    return out


def summary(root: Path) -> dict:
    """The RESOLVED document of dataset ``root``, from its manifest and every shard's
    meta["resolved"] (module docstring)."""
    manifest = Manifest.load(root)
    data, _ = load_dataset(root)
    unit_size = manifest.config["unit_size"]
    pairs = walk_misses(data, unit_size)
    samples = []
    for e in manifest.shards:
        for r in read_shard(root / e.file)[1].get("resolved", []):
            sid = r["sample_id"]
            i = int(np.flatnonzero(data["sample_id"] == sid)[0])
            stiffness = r.get("stiffness", {})
            samples.append({
                "sample_id": sid, "inputs": data["inputs"][i].tolist(), "path_segments": len(r["path_points"]),
                "newton_iterations": int(sum(r["newton"])), "cutbacks": r["cutbacks"], "wall_s": r["wall_s"],
                "max_it": r["max_it"], "min_step": r["min_step"],
                "unstable_modes": stiffness.get("unstable_modes", -1),
                "lowest_eigenvalue": stiffness.get("lowest_eigenvalue"),
                "walk_pairs": [{"pair": f"{a}-{b}", "miss_mm": m} for a, b, m in pairs if sid in (a, b)]})
    return {"format": RESOLVED.tag, "dataset": str(root), "samples_requested": manifest.samples_requested,
            "stored": manifest.samples, "failures": manifest.failures,
            "walk_consistency": walk_consistency(data, unit_size), "samples": samples}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m workflow.resolve", description=__doc__.split("\n\n")[0])
    add_path_options(ap, fine_step=0.005)
    ap.add_argument("--max-it", type=cli.number(1, 200, integer=True), default=24,
                    help="Newton iterations a step before it is cut back (default 24; the campaign's 12)")
    ap.add_argument("--min-step", type=cli.number(0.0, 1.0, open_lo=True), default=2.0 ** -12,
                    help="smallest path step, as a fraction of a segment (default 2^-12; the campaign's 2^-8)")
    ap.add_argument("--max-hours", type=cli.number(0.0, None, open_lo=True),
                    help="start no sample after this many hours (re-run to go on)")
    ap.add_output("--out", suffix=".json", help="the summary JSON (default results/fem/resolved_<dataset>.json)")
    ap.add_argument("--summary-only", action="store_true", help="only rewrite the summary JSON from the shards")
    cli.add_quiet(ap)
    comm = MPI.COMM_WORLD
    one_rank(ap, comm)
    args = ap.parse_args(argv)
    root = Path(args.dataset)
    t_start = time.perf_counter()
    with ap.errors():
        manifest = Manifest.load(root)
        if not manifest.is_campaign:
            ap.error(f"{root} is not a campaign dataset (no unit layout)")
        lock = open(root / ".campaign.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"python -m workflow.resolve: error: another campaign is writing {root}", file=sys.stderr)
            return 1
        scanner = ShardScanner(root, manifest.samples_requested, manifest.config, manifest.seed)
        manifest = build_manifest(root, manifest.samples_requested, manifest.config, manifest.seed,
                                  scanner.scan(), manifest)
        failed = failed_samples(root)
    out = Path(args.out or f"results/fem/resolved_{root.name}.json")
    if args.summary_only:
        with ap.errors():
            RESOLVED.write(out, summary(root))
        lock.close()
        return 0
    failed = chosen(ap, failed, args.samples, root)
    cli.setup_logging(args.quiet)
    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    points = path_points(args.coarse_step, args.fine_from, args.fine_step)
    unit_size = manifest.config["unit_size"]
    budget = args.max_hours * 3600 if args.max_hours else math.inf
    results, code, commit = [], 0, git_commit()
    with ap.errors(), cli.heartbeat("workflow.resolve", enabled=not args.quiet):
        solver = recorded_solver(manifest.config, MPI.COMM_SELF)
        controls = {"max_it": args.max_it, "min_step": args.min_step}
        solver.solver.config = replace(solver.solver.config, **controls)
        for f in failed:
            if time.perf_counter() - t_start > budget:
                code = EXIT_INCOMPLETE
                break
            sid, t0 = f["sample_id"], time.perf_counter()
            say(f"sample {sid}: load {f['inputs']} (P MPa, F1 N, F2 N, M N·mm)")
            path = solve_along(solver, np.asarray(f["inputs"]), points)
            entry = {"sample_id": sid, "inputs": f["inputs"], "campaign_reason": f["reason"], **path}
            if path["converged"]:
                shard = root / shard_file(sid // unit_size)
                arrays, meta = read_shard(shard)
                wall = time.perf_counter() - t0
                arrays = move_to_data(arrays, sid, {
                    "inputs": f["inputs"], **sample_record(solver), "newton_iterations": sum(path["newton"]),
                    "wall_time_s": wall})
                entry["stiffness"] = solver.solver.stiffness_spectrum()
                pairs = walk_misses(arrays, unit_size)
                entry["walk_miss_mm"] = {f"{int(a)}-{int(b)}": m for a, b, m in pairs if sid in (a, b)}
                meta = {**meta, "cpu_s": meta.get("cpu_s", 0.0) + wall, "resolved": meta.get("resolved", []) + [{
                    "sample_id": sid, "path_points": points, **controls, "newton": path["newton"],
                    "cutbacks": path["cutbacks"], "wall_s": wall, "stiffness": entry["stiffness"],
                    "git_commit": commit}]}
                error = save_shard(shard, arrays, meta)
                if error:
                    print(f"python -m workflow.resolve: error: {error}", file=sys.stderr)
                    return 1
                manifest = build_manifest(root, manifest.samples_requested, manifest.config, manifest.seed,
                                          scanner.scan(), manifest)
                RESOLVED.write(out, summary(root))
                entry["wall_s"] = wall
                say(f"sample {sid}: solved, {sum(path['newton'])} Newton iterations, {path['cutbacks']} cut-backs, "
                    f"{wall:.0f} s; walk misses {entry['walk_miss_mm']} mm -> {shard}")
            else:
                code = EXIT_INCOMPLETE
                entry["wall_s"] = time.perf_counter() - t0
                say(f"sample {sid}: still failed at s = {path['reached_s']:.4f} ({path['reason']})")
            results.append(entry)
    figures = {"dataset": str(root), "path_points": points, "max_it": args.max_it, "min_step": args.min_step,
               "samples": results, "stored": manifest.samples, "failures": manifest.failures,
               "wall_s": time.perf_counter() - t_start}
    if args.json:
        cli.print_json(figures)
    else:
        print(f"{root}: {sum(r['converged'] for r in results)} of {len(results)} resolved; "
              f"{manifest.samples} stored, {manifest.failures} failed")
    lock.close()
    return code


if __name__ == "__main__":
    sys.exit(main())
