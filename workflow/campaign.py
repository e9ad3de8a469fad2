"""MPI data campaign: random load cases of the joint -> FEM -> sharded dataset (issue 3).

``python -m workflow.campaign --samples N --seed S --out DIR [--joint FILE] [options]``, on
1 rank or under ``mpirun -n K`` / ``srun``. Running the same command again resumes.

Data flow::

    (seed, unit u) --unit_walk--> inputs (n_u, 4) [P MPa, F1 N, F2 N, M N·mm]
      --JointSolver on a group of ranks: continuation along the walk--> anchors (n_u, 10, 2) mm,
        Jacobian (n_u, 20, 4) = d anchors / d inputs, per-sample Newton figures
      --group rank 0: workflow.shards.write_shard (atomic)--> DIR/shards/unit-uuuuu.npz
      --world rank 0: workflow.store.build_manifest (scan + verify, atomic)--> DIR/manifest.json

Work units. Sample ids [u K, u K + n_u) form unit u (K = ``--unit-size``). Its inputs are a
persistent walk drawn from its own stream ``np.random.default_rng([seed, u])``: a uniform
start y_0 in the box and a uniform direction d_0 on the unit sphere, then

    y_k = y_{k-1} + h d_{k-1},   d_k = (d_{k-1} + s xi_k) / |d_{k-1} + s xi_k|,   xi_k ~ N(0, I)
    x_k = fold(y_k)   (mirror reflection into [-1, 1]^4, box-normalised coordinates;
                       inputs x_k * B, B the joint's input box)

with h = ``--step`` and s = ``WALK_TURN``. The cost of a continuation sample depends on h
only; the gently turning direction makes a unit sweep the box like a billiard ball where a
plain random walk of the same h would stay near its start (RMS distance h sqrt(n)). The
uniform distribution is stationary: y mod 4 stays uniform under a translation, and d stays
uniform under a rotation-equivariant kick. The inputs never depend on solver outcomes, so
the samples are the same whatever the number of ranks or groups.

Speed. The first sample of a unit is solved from zero (the solver's load path with
cut-back); every further sample continues from the previous converged state along the
short walk step (Euler predictor from the previous sample's sensitivities, then Newton).
The assembled sparsity, forms and MUMPS symbolic factorisation are reused throughout. The
Jacobian comes from ``solver.sensitivities()``: one block GMRES solve for the four inputs,
preconditioned with the sample's factorisation (fem.solvers.load_path).

Failures. A sample whose continuation fails is retried once from zero; if that fails too
it goes to the shard's failure arrays with its inputs and both reasons (never as data),
and the walk continues from the solver's last converged state.

Joint. ``--joint FILE`` (contract.joint, docs/joints.md; default the paper's joint,
contract/joints/paper.toml) gives the joint's shape, law, input box B and anchors, and its
default mesh ([mesh]: sizes and formulation). The manifest's config records the joint
(workflow.store.joint_record: its description and sha256) only when it is not the
paper's, so every manifest written before joint files existed is unchanged and resumes;
resuming with another joint is refused with one line naming --joint and both joints.
Its shards hold the joint's anchor count (workflow.shards.anchor_count reads it back
from the config).

Formulation. ``--formulation`` (default the joint file's, for the paper's joint the
production one, fem.mesh.discretisation.FORMULATION) chooses the joint's elements
(fem.physics.problem: P2 displacement or Taylor-Hood u-p "mixed"). The manifest's config records
it only when it is not "displacement", so that every manifest written before the mixed
formulation existed reads as what it is (fem.mesh.discretisation.recorded_formulation);
resuming with another formulation is refused like any other config change. Without
``--mesh-size``, ``--wall-mesh-size`` or ``--divisions`` the mesh is the joint file's (the
paper's: the production hex2:3, JointGeometry's default mesh, in the mixed formulation).
The committed datasets results/data/{train,heldout} are on the production discretisation
(``make dataset``); the paper-fidelity 1.8 mm displacement reference walks
results/data/{train,heldout}_h1.8 (fem.mesh.discretisation.PAPER) resume with ``--mesh-size 1.8
--formulation displacement``, and the production defaults are refused there (another
config).

Path check. Every ``--fresh-check-every``-th unit also re-solves its last sample from zero
and records the largest anchor difference in the shard's meta (``fresh_checks``). If the
two differ by more than ``FRESH_TOL_MM`` (a second equilibrium branch), the from-zero
solution is stored instead: it is the one a user's single solve returns.

Ranks. ``comm.Split`` forms groups of ``--ranks-per-group`` ranks; the units still to do
are dealt round-robin to the groups. Only world rank 0 prints and writes the manifest;
each group's rank 0 writes its shards. Start and resume: world rank 0 first checks that
DIR holds no dataset of another seed or config, nor of more samples (check_compatible: the
refusal names the option and both values; a refused run creates nothing in DIR, not even
the lock; DIR's parent must exist), then takes DIR/.campaign.lock, removes left-over temp
files, scans DIR/shards (checksum + unit layout + config) and rebuilds the manifest; units
with a missing or invalid shard are (re)done. A ``kill -9`` at any moment loses at most
the units in progress: shards and manifest only ever appear complete (temp file + rename).

Exit codes: 0 the dataset is complete, 3 stopped by ``--max-hours`` (re-run to resume),
1 error (e.g. another campaign holds the lock), 2 bad command line or an ``--out`` that
holds another campaign (one line on stderr). ``--json`` prints the summary as JSON on
rank 0.
"""

from __future__ import annotations

import argparse
import fcntl
import math
import os
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.joint import JointSpec, is_paper_joint, joint_digest, load_joint, material_dict
from contract.spec import INPUT_BOX, N_ANCHORS, N_INPUTS
from fem.mesh.discretisation import FORMULATION
from fem.options import (add_divisions, add_formulation, add_joint, add_mesh_size, add_wall_mesh_size, formulation_of,
                         joint_geometry, joint_of)
from fem.solvers.joint import JointSolver, Load, Material, config_for
from workflow import shards
from workflow.shards import Manifest, ShardError
from workflow.store import (ShardScanner, build_manifest, clean_temporaries, joint_record, shard_file,
                            unit_count, unit_ids, unit_range)

EXIT_INCOMPLETE = 3
#: A harvested sample farther than this (mm) from the from-zero solve is another branch.
FRESH_TOL_MM = 1e-5
DEFAULT_UNIT_SIZE = 64
#: Walk step (box-normalised). At the 1.8 mm P2 mesh, with 2 ranks busy, a 16-sample unit
#: took a mean 13.4 s per harvested sample at 0.1 against 27.2 s at 0.2: the longer step
#: leaves contact and rotation far enough from the predictor to need cut-backs. Coverage
#: comes from the walk's persistence instead (WALK_TURN).
DEFAULT_STEP = 0.1
#: Direction kick s of the persistent walk: directions decorrelate over ~1/(1.5 s^2) = 17
#: steps, about one box width at h = 0.1. Over 40 units of 64 samples this occupies about
#: 90 % of the 4^4 grid cells, against about 60 % for a random walk of the same step
#: (tests/test_campaign.py::test_walk_sweeps_the_box).
WALK_TURN = 0.2


def reflect(x: np.ndarray) -> np.ndarray:
    """Fold coordinates into [-1, 1] by mirror reflection at the faces. Shape kept."""
    y = np.mod(x + 1.0, 4.0)
    return np.where(y > 2.0, 4.0 - y, y) - 1.0


def unit_walk(seed: int, unit: int, n: int, step: float, turn: float = WALK_TURN,
              box=INPUT_BOX) -> np.ndarray:
    """Inputs (n, 4) [P MPa, F1 N, F2 N, M N·mm] of unit ``unit``: the persistent walk of the
    module docstring (step ``step``, direction kick ``turn``) from the stream
    default_rng([seed, unit]), scaled by the input box ``box`` (4,). The first k rows do
    not depend on n (a longer unit extends a shorter one)."""
    rng = np.random.default_rng([seed, unit])
    z = np.empty((n, N_INPUTS))
    y = rng.uniform(-1.0, 1.0, N_INPUTS)
    d = rng.normal(size=N_INPUTS)
    d /= np.linalg.norm(d)
    for j in range(n):
        if j:
            y = y + step * d
            d = d + turn * rng.normal(size=N_INPUTS)
            d /= np.linalg.norm(d)
        z[j] = reflect(y)
    return z * np.asarray(box, dtype=float)


def git_commit() -> str:
    """HEAD commit of the source tree, with '+dirty' if it has uncommitted changes outside
    results/ (datasets being written are not source changes)."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                ":/", ":(top,exclude)results"],
                               cwd=here, capture_output=True, text=True).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def campaign_config(geometry, unit_size: int, step: float, fresh_check_every: int,
                    formulation: str = FORMULATION, joint: JointSpec | None = None) -> dict:
    """The manifest's ``config``: everything that determines the samples (not N, not ranks);
    ``geometry`` a fem.mesh.geometry.JointGeometry (its mesh and wall mesh sizes included);
    ``formulation`` recorded only when it is not "displacement", ``joint`` (default the
    paper's) only when it is not the paper's (module docstring)."""
    joint = joint or load_joint()
    paper = is_paper_joint(joint)
    config = {"source": "fem-campaign", "geometry": geometry.as_dict(),
              "material": asdict(Material()) if paper else material_dict(joint.material),
              "solver": asdict(config_for(geometry)),
              "unit_size": unit_size, "walk_step": step, "walk_turn": WALK_TURN,
              "fresh_check_every": fresh_check_every,
              "input_box": joint.input_box.tolist(), **joint_record(joint)}
    if formulation != "displacement":
        config["formulation"] = formulation
    return config


# ---------------------------------------------------------------------------- one unit
def solve_unit(solver, ids: np.ndarray, inputs: np.ndarray, fresh_check: bool,
               on_sample=None, anchors: int = N_ANCHORS) -> tuple[dict, dict]:
    """Solve the walk ``inputs`` (n, 4) of one unit by continuation (collective over the
    solver's communicator), ``anchors`` per sample (the joint's count). Returns (arrays for
    write_shard, meta figures)."""
    data = {k: [] for k in ("sample_id", "inputs", "anchors", "jacobian", "phi_end",
                            "cap_rotation", "newton_iterations", "wall_time_s")}
    fail = {"failed_sample_id": [], "failed_inputs": [], "failed_reason": []}
    checks, t_unit = [], time.perf_counter()
    solver.reset()
    for j, (sid, x) in enumerate(zip(ids, inputs)):
        t0 = time.perf_counter()
        load = Load.from_array(x)
        res = solver.solve(load, continuation=j > 0)
        its = res.iterations
        if not res.converged and j > 0:
            first_reason = res.reason
            res = solver.solve(load, continuation=False)
            its += res.iterations
            if not res.converged:
                res.reason = f"continuation: {first_reason}; from zero: {res.reason}"
        if res.converged:
            jac = solver.sensitivities()
            if fresh_check and j == len(ids) - 1 and j > 0:
                # Last sample of the unit, so re-solving from zero costs the walk nothing.
                fresh = solver.solve(load, continuation=False)
                its += fresh.iterations
                diff = float(np.abs(fresh.anchors - res.anchors).max()) if fresh.converged else None
                other = diff is not None and diff > FRESH_TOL_MM
                checks.append({"sample_id": int(sid), "max_anchor_diff_mm": diff,
                               "stored": "from-zero" if other else "harvested",
                               "note": "" if fresh.converged else f"from zero: {fresh.reason}"})
                if other:
                    res, jac = fresh, solver.sensitivities()
            data["sample_id"].append(sid)
            data["inputs"].append(x)
            data["anchors"].append(res.anchors)
            data["jacobian"].append(jac)
            data["phi_end"].append(res.phi_end)
            data["cap_rotation"].append(res.cap_rotation)
            data["newton_iterations"].append(its)
            data["wall_time_s"].append(time.perf_counter() - t0)
        else:
            fail["failed_sample_id"].append(sid)
            fail["failed_inputs"].append(x)
            fail["failed_reason"].append(res.reason or "no convergence")
        if on_sample is not None:
            on_sample(res.converged)
    arrays = shards.empty_arrays(anchors)
    for k, v in {**data, **fail}.items():
        if v:
            arrays[k] = np.asarray(v, dtype=arrays[k].dtype if k != "failed_reason" else str)
    arrays["converged"] = np.ones(len(arrays["sample_id"]), bool)
    return arrays, {"wall_s": time.perf_counter() - t_unit, "fresh_checks": checks}


# ---------------------------------------------------------------------------- CLI
def parse_args(argv=None) -> argparse.Namespace:
    ap = cli.Parser(prog="python -m workflow.campaign",
                    description="Resumable MPI FEM data campaign of the bellow joint "
                                "(run the same command again to resume).")
    count = cli.number(1, None, integer=True)
    ap.add_argument("--samples", type=count, required=True, help="number of load cases N")
    ap.add_argument("--seed", type=cli.number(0, None, integer=True), required=True,
                    help="campaign seed >= 0 (fixes all inputs)")
    ap.add_argument("--out", required=True,
                    help="dataset directory (manifest.json + shards/); created only once the "
                         "run is known to be compatible with what it holds")
    ap.add_argument("--max-hours", type=cli.number(0, None, "h", open_lo=True), default=None,
                    help="time budget: start no unit that would end past it (exit 3 if unfinished)")
    ap.add_argument("--ranks-per-group", type=count, default=1,
                    help="MPI ranks per FEM solve (default 1; must divide the rank count)")
    add_joint(ap)
    add_mesh_size(ap, None, "tetrahedron size", shown="the joint file's [mesh] size")
    add_wall_mesh_size(ap)
    add_divisions(ap)
    add_formulation(ap, "the joint file's [mesh] formulation (the paper's: the production one)")
    ap.add_argument("--unit-size", type=count, default=DEFAULT_UNIT_SIZE,
                    help=f"samples per work unit / shard (default {DEFAULT_UNIT_SIZE})")
    ap.add_argument("--step", type=cli.number(0, 2, open_lo=True), default=DEFAULT_STEP,
                    help=f"random-walk step, box-normalised, in (0, 2] (default {DEFAULT_STEP})")
    ap.add_argument("--fresh-check-every", type=cli.number(0, None, integer=True), default=8,
                    metavar="U", help="re-solve the last sample of every U-th unit from zero (0: never)")
    ap.add_argument("--units", type=unit_range, default=None, metavar="A:B",
                    help="only units A..B-1 (split one campaign over independent jobs; "
                         "merge with python -m workflow.dataset merge)")
    ap.add_argument("--progress-every", type=cli.number(0, None, "s", open_lo=True), default=60.0,
                    help="seconds between progress lines (default 60)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    why = cli.check_output(args.out, folder=True)   # checked now, created in run()
    if why:
        ap.error(why)
    args.joint = joint_of(args)
    with ap.errors():
        args.geometry = joint_geometry(args, args.joint)
    n_units = unit_count(args.samples, args.unit_size)
    args.unit_range = args.units or (0, n_units)
    if args.unit_range[1] > n_units:
        ap.error(f"--units {args.units[0]}:{args.units[1]} outside 0:{n_units} "
                 f"({args.samples} samples in units of {args.unit_size})")
    return args


class Progress:
    """Rank-0 progress line: samples done, rate, ETA, failures."""

    def __init__(self, total: int, done0: int, quiet: bool, every: float):
        self.total, self.done0, self.quiet, self.every = total, done0, quiet, every
        self.t0 = self.last = time.perf_counter()
        self.shown = None

    def line(self, done: int, failures: int, force: bool = False) -> None:
        now = time.perf_counter()
        if self.quiet or (done, failures) == self.shown or (not force and now - self.last < self.every):
            return
        self.last, self.shown = now, (done, failures)
        rate = (done - self.done0) / max(now - self.t0, 1e-9) * 3600
        eta = (self.total - done) / rate if rate > 0 else math.inf
        print(f"[campaign] {done}/{self.total} samples ({100 * done / self.total:.1f}%), "
              f"{rate:.0f} samples/h, ETA {eta:.2f} h, failures {failures}", flush=True)


#: The manifest's config entries that a command-line option sets: key -> (flag, unit).
CONFIG_FLAGS = {("geometry", "mesh_size"): ("--mesh-size", " mm"),
                ("geometry", "wall_mesh_size"): ("--wall-mesh-size", " mm"),
                ("geometry", "divisions"): ("--divisions", ""),
                ("geometry", "hex_size"): ("--hex-size", " mm"),
                ("formulation",): ("--formulation", ""),
                ("unit_size",): ("--unit-size", ""), ("walk_step",): ("--step", ""),
                ("fresh_check_every",): ("--fresh-check-every", "")}
#: What an absent config entry means (shown instead of "unset"): a manifest without a
#: formulation was made with P2 displacements.
CONFIG_ABSENT = {("formulation",): "displacement", ("geometry", "divisions"): "tetrahedra",
                 ("geometry", "hex_size"): "uniform"}


def _differences(old: dict, new: dict, prefix: tuple = ()) -> list[tuple[tuple, object, object]]:
    """(key path, old value, new value) of every leaf where two configs differ."""
    out = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, prefix + (key,))
        elif a != b:
            out.append((prefix + (key,), a, b))
    return out


def describe_difference(path: tuple, old, new) -> str:
    """One config difference in the user's words: the option and both values, or the
    code setting (the FEM code or its defaults changed) and both values."""
    if path in CONFIG_FLAGS:
        flag, unit = CONFIG_FLAGS[path]
        absent = CONFIG_ABSENT.get(path, "unset")
        show = lambda v: absent if v is None else f"{v:g}{unit}" if isinstance(v, (int, float)) else str(v)
        return f"{flag} {show(old)} (this run: {show(new)})"
    return f"{'.'.join(path)} = {old!r} (this run, from the code: {new!r})"


def joint_label(config: dict) -> str:
    """The joint of a campaign config in a message: the paper's, or its sha256 prefix."""
    sha = config.get("joint_sha256")
    return "the paper's joint" if sha is None else f"joint sha256 {sha[:12]}"


def check_joint(out: Path, old: dict, new: dict, joint: JointSpec | None) -> None:
    """ShardError (one line naming --joint and both joints) if ``out``'s campaign (config
    ``old``) was made for another joint than this run's (config ``new``, joint ``joint``)."""
    if old.get("joint_sha256") == new.get("joint_sha256"):
        return
    this = joint_label(new) if joint is None else f"--joint {joint.name!r} ({joint_label(new)})"
    raise ShardError(f"{out} holds a campaign of {joint_label(old)}, not of {this}; rerun with the "
                     "--joint it was made with, or use another --out")


def check_compatible(out: Path, config: dict, seed: int, samples: int | None = None,
                     joint: JointSpec | None = None) -> Manifest | None:
    """The manifest already in ``out`` (None if there is none). Raises ShardError (one
    line naming the option or setting and both values) if ``out`` holds a dataset this
    run must not touch: an unreadable manifest, a campaign of another joint (check_joint;
    ``joint`` this run's, for its name), seed or config, or more samples than ``samples``
    (a smaller run would drop its shards from the manifest)."""
    if not Manifest.exists(out):
        return None
    old = Manifest.load(out)
    check_joint(out, old.config, config, joint)
    differ = _differences(old.config, config)
    if differ:
        shown = "; ".join(describe_difference(*d) for d in differ[:3])
        more = f" and {len(differ) - 3} more" if len(differ) > 3 else ""
        raise ShardError(f"{out} holds a campaign made with {shown}{more}; rerun with its settings "
                         "or use another --out")
    if old.seed != seed:
        raise ShardError(f"{out} holds a campaign of --seed {old.seed}, not --seed {seed}; "
                         "use another --out or its seed")
    if samples is not None and old.samples_requested is not None and samples < old.samples_requested:
        raise ShardError(f"{out} holds a campaign of --samples {old.samples_requested}; --samples {samples} "
                         "would drop its other shards: rerun with --samples "
                         f"{old.samples_requested} (or more) or use another --out")
    return old


def run(args) -> int:
    world = MPI.COMM_WORLD
    rank, size = world.rank, world.size
    # srun without an MPI plugin that this MPI understands (a stock MpiDefault=none, no
    # --mpi) can start N singletons, each rank 0 of a world of 1: all would write the same
    # units. SLURM_STEP_NUM_TASKS exists inside srun steps only (not in the batch script);
    # under mpirun (OMPI_COMM_WORLD_SIZE set) the world is the one mpirun was asked for.
    tasks = os.environ.get("SLURM_STEP_NUM_TASKS", "") if "SLURM_STEP_ID" in os.environ else ""
    if size == 1 and tasks.isdigit() and int(tasks) > 1 and "OMPI_COMM_WORLD_SIZE" not in os.environ:
        if os.environ.get("SLURM_PROCID", "0") == "0":      # every task thinks it is rank 0
            print(f"python -m workflow.campaign: error: Slurm started {tasks} tasks but MPI sees "
                  "a world of 1: srun needs --mpi=pmix (set SRUN_MPI)", file=sys.stderr)
        return 2
    G = args.ranks_per_group
    if size % G:
        if rank == 0:
            print(f"python -m workflow.campaign: error: --ranks-per-group {G} does not divide "
                  f"{size} ranks", file=sys.stderr)
        return 2
    joint = args.joint
    geometry = args.geometry
    mesh_size, formulation = geometry.mesh_size, formulation_of(args, joint)
    config = campaign_config(geometry, args.unit_size, args.step, args.fresh_check_every, formulation, joint)
    out, t_start = Path(args.out), time.perf_counter()

    # --- world rank 0: check, lock, clean, scan, manifest; everyone learns the units to do.
    # Nothing is created in ``out`` (not even the lock) for a run it refuses.
    status, lock, scanner, manifest, todo = None, None, None, None, None
    if rank == 0:
        try:
            check_compatible(out, config, args.seed, args.samples, joint)
            (cli.make_output_folder(out) / "shards").mkdir(exist_ok=True)
            lock = open(out / ".campaign.lock", "w")
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            old = check_compatible(out, config, args.seed, args.samples, joint)   # again: a writer may have raced us
            clean_temporaries(out)
            scanner = ShardScanner(out, args.samples, config, args.seed)
            done = scanner.scan()
            manifest = build_manifest(out, args.samples, config, args.seed, done, old)
            todo = [u for u in range(*args.unit_range) if u not in done]
        except ShardError as exc:
            status = (str(exc), cli.EXIT_USAGE)
        except BlockingIOError:
            status = (f"another campaign is writing {out}", 1)
        except OSError as exc:
            status = (str(exc), 1)
    status, todo, commit = world.bcast((status, todo, git_commit() if rank == 0 else None), root=0)
    if status:
        if rank == 0:
            print(f"python -m workflow.campaign: error: {' '.join(status[0].split())}", file=sys.stderr)
        return status[1]

    n_groups = size // G
    group = world.Split(color=rank // G, key=rank)
    mine = todo[rank // G::n_groups]
    progress = None
    if rank == 0:
        progress = Progress(args.samples, manifest.samples + manifest.failures, args.quiet,
                            args.progress_every)
        if not args.quiet:
            print(f"[campaign] {out}: joint {joint.name!r}, {len(todo)} of {manifest.units_total} units to do on "
                  f"{size} rank(s) in {n_groups} group(s) of {G}; mesh {geometry.mesh}, "
                  f"{formulation} formulation, unit size {args.unit_size}, step {args.step}",
                  flush=True)

    state = {"in_unit": 0, "fail_in_unit": 0}

    def on_sample(converged: bool) -> None:
        state["in_unit"] += 1
        state["fail_in_unit"] += not converged
        if rank == 0:
            progress.line(manifest.samples + manifest.failures + state["in_unit"],
                          manifest.failures + state["fail_in_unit"])

    units_run, stopped, failed, solver, unit_times = 0, False, False, None, []
    budget = args.max_hours * 3600 if args.max_hours else math.inf
    for unit in mine:
        # All ranks of a group must agree to start a unit (its solves are collective).
        elapsed = time.perf_counter() - t_start
        expected = np.mean(unit_times) if unit_times else 0.0
        go = group.bcast(elapsed + expected <= budget, root=0)
        if not go:
            stopped = True
            break
        if solver is None:
            solver = JointSolver.for_joint(joint, group, geometry, formulation=formulation)
        ids = unit_ids(unit, args.samples, args.unit_size)
        inputs = unit_walk(args.seed, unit, len(ids), args.step, box=joint.input_box)
        check = args.fresh_check_every > 0 and unit % args.fresh_check_every == 0
        state["in_unit"] = state["fail_in_unit"] = 0
        arrays, figures = solve_unit(solver, ids, inputs, check, on_sample, joint.anchors)
        unit_times.append(figures["wall_s"])
        if group.rank == 0:
            meta = {"config": config, "seed": args.seed, "unit": unit, "git_commit": commit,
                    "mesh": solver.mesh_info(), "ranks": G, "cpu_s": figures["wall_s"] * G,
                    **figures}
            write_error = save_shard(out / shard_file(unit), arrays, meta)
        write_error = group.bcast(write_error if group.rank == 0 else None, root=0)
        if write_error:
            if group.rank == 0:
                _error_line(write_error)
            failed = True
            break
        units_run += 1
        if rank == 0:
            manifest = build_manifest(out, args.samples, config, args.seed, scanner.scan(), manifest)
            state["in_unit"] = state["fail_in_unit"] = 0
            progress.line(manifest.samples + manifest.failures, manifest.failures, force=True)

    # --- wait for every group without spinning a core (MPI barriers busy-poll)
    req = world.Ibarrier()
    while not req.Test():
        time.sleep(0.2)
        if rank == 0:
            fresh = scanner.scan()
            if len(fresh) != manifest.units_done:
                manifest = build_manifest(out, args.samples, config, args.seed, fresh, manifest)
                progress.line(manifest.samples + manifest.failures, manifest.failures)
    stopped = world.allreduce(stopped, op=MPI.LOR)
    failed = world.allreduce(failed, op=MPI.LOR)
    units_run = world.allreduce(units_run, op=MPI.SUM)
    code = 0
    if rank == 0:
        manifest = build_manifest(out, args.samples, config, args.seed, scanner.scan(), manifest)
        wall = time.perf_counter() - t_start
        solved = manifest.samples + manifest.failures - progress.done0
        listed = {e.unit for e in manifest.shards}
        range_done = all(u in listed for u in range(*args.unit_range))
        summary = {
            "out": str(out), "seed": args.seed, "samples_requested": args.samples,
            "samples": manifest.samples, "failures": manifest.failures,
            "failure_rate": manifest.failures / max(manifest.samples + manifest.failures, 1),
            "units_total": manifest.units_total, "units_done": manifest.units_done,
            "units_run": units_run, "complete": manifest.complete,
            "range_complete": range_done, "stopped_by_budget": stopped,
            "ranks": size, "ranks_per_group": G, "mesh": geometry.mesh, "mesh_size": mesh_size,
            "wall_mesh_size": geometry.wall_mesh_size, "formulation": formulation,
            "joint": {"name": joint.name, "sha256": joint_digest(joint)},
            "wall_s": wall, "samples_per_hour": solved / wall * 3600 if solved else 0.0,
            "cpu_hours_dataset": manifest.cpu_hours, "git_commit": commit,
        }
        if args.json:
            cli.print_json(summary)
        elif not args.quiet:
            print(f"[campaign] {'complete' if summary['complete'] else 'incomplete'}: "
                  f"{summary['samples']} samples, {summary['failures']} failures "
                  f"({100 * summary['failure_rate']:.2f}%), {units_run} units this run in "
                  f"{wall / 3600:.2f} h ({summary['samples_per_hour']:.0f} samples/h)"
                  + ("; time budget reached, re-run to resume" if stopped else ""), flush=True)
        code = 1 if failed else 0 if summary["range_complete"] else EXIT_INCOMPLETE
        lock.close()
    return world.bcast(code, root=0)


def _error_line(text: str) -> None:
    print(f"python -m workflow.campaign: error: {' '.join(text.split())}", file=sys.stderr, flush=True)


def save_shard(path: Path, arrays: dict, meta: dict) -> str | None:
    """Write one shard (atomically: what was there stays on failure); why it could not
    be written (full disk, a folder in its place), or None."""
    try:
        shards.write_shard(path, arrays, meta)
    except OSError as exc:
        return (f"cannot write {path}: {exc.strerror or exc}; the dataset keeps its other shards "
                "(free the space or the path, then rerun to resume)")
    return None


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        return run(args)
    except OSError as exc:      # the manifest or the lock on a full disk: one line, data kept
        _error_line(f"{args.out}: {exc.strerror or exc}" + (f" ({exc.filename})" if exc.filename else "")
                    + "; what was written stays (rerun to resume)")
        if MPI.COMM_WORLD.size > 1:
            MPI.COMM_WORLD.Abort(1)
        return 1


if __name__ == "__main__":
    sys.exit(main())
