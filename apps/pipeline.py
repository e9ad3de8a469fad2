"""One command from a joint description file to a validated gripper predictor (issue 37 §3).

    python -m apps.pipeline --joint FILE [--budget small|full] [--out DIR] [--ranks N]
        [--launcher CMD] [--max-hours H] [--mesh-size MM | --divisions N] [--samples N]
        [--heldout-samples N] [--epochs N] [--json]
    make pipeline JOINT=FILE [BUDGET=small|full]

Stages, each run as its own command line (``python -m ...``: every stage keeps its
checks, one-line errors and resume), in DIR (default results/joints/<joint name>/):

    1 render    fem.cli.render --joint           -> render.png, render.json (mesh and one solve)
    2 outline   fem.studies.joint_outline        -> joint_outline.json: how far the pressurised
                cells bulge beyond the predictor's outline band; a joint file without an
                [outline] table gets the measured one in DIR/joint.toml (not in the digest:
                nothing before or after it is redone), so the gesture draws it
    3 train-data   workflow.campaign, seed 1, units of 64 -> data/train/ (resumable)
    4 heldout-data workflow.campaign, seed 2, units of 16 -> data/heldout/ (resumable)
    5 train     surrogate.train --config improved -> surrogate.pt (+ surrogate_curve.png)
    6 evaluate  surrogate.evaluate on the held-out walk -> heldout.json, and on the
                training split -> train_fit.json
    7 gesture   predictor.cli.gesture with finger.toml (three joints of the joint, the paper
                finger's 60 mm link between them and its 65 mm tip) at pressures (-p, p, p),
                p = 0.5 min(P_max, 0.3 MPa): the base joint opens, the other two close (a
                grasp-like pose that keeps the two fingers apart), gravity -> gesture.png,
                gesture.json
    8 summary   metrics.json (``heldout`` -> mean_anchor_error_mm, cap_rotation_error_deg,
                samples), summary.json and summary.txt: errors, sample counts, wall time
                per stage

Budgets (docs/pipeline.md; the learning curve results/surrogate/h1.8/learning_curve.json of
the paper's joint): ``full`` is the paper joint's campaign, 2,560 training and 256
held-out samples and the improved surrogate's 800 epochs. ``small`` is 256 training
(a 7:2:1 split, so 192 to train on) and 64 held-out samples, trained for the
learning curve's step budget, at least S = 22,400 Adam steps:

    epochs = max(E0, ceil(S / ceil(n_train / batch))),   lr_decay = d0^(E0 / epochs)

(E0 = 800 epochs, d0 = 0.995 per epoch, batch 64: the improved config). Both mesh the
joint with its file's [mesh] unless ``--mesh-size`` (tetrahedra) or ``--divisions``
(hexahedra) is given; ``--samples``,
``--heldout-samples`` and ``--epochs`` override a budget's numbers (tests, trials).

Resume. ``DIR/pipeline.json`` records, per finished stage, the key of what made it (the
joint's sha256, contract.joint.joint_digest; the stage's settings; the sha256 of what it
read) and the sha256 of every file it wrote. A stage is skipped when its record has the
same key and its files are unchanged; a campaign stage also needs its manifest complete,
of the requested samples and of this joint (workflow.store.recorded_joint). So a killed
pipeline, run again, redoes only the stage it was in (a campaign resumes from its
shards), and a changed input redoes what depends on it. DIR holding another joint's
pipeline (its joint.toml, record or datasets) is refused.

Progress: one line per stage on stdout (its log, the stage's own output, goes to
DIR/logs/<stage>.log). Exit codes: 0 done; 2 bad input (one line on stderr, before any
stage); 3 a campaign stopped at --max-hours (run the same command again to resume);
1 a stage failed (the line names its log).

The surrogate takes the joint's anchor count and input box from its dataset
(surrogate.model.ModelConfig), so any joint file runs.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from contract import cli
from contract.files import sha256_file, write_json, write_text
from contract.finger import load_finger, parse_finger
from contract.joint import MAX_DIVISIONS, JointSpec, joint_digest, load_joint, outline_table
from contract.spec import PRESSURE_LIMIT
from fem.artefacts import outline_of
from workflow.shards import Manifest, ShardError, dataset_digest, load_dataset, split_of
from workflow.store import recorded_joint

ROOT = Path(__file__).resolve().parents[1]
FORMAT = "softjoint-pipeline/1"
RECORD = "pipeline.json"
EXIT_INCOMPLETE = 3


@dataclass(frozen=True)
class Budget:
    """Samples of the two campaigns, and whether the training takes the step budget of the
    module docstring (``small``) or the config's own 800 epochs (``full``)."""

    train_samples: int
    heldout_samples: int
    step_budget: bool


BUDGETS = {"small": Budget(256, 64, True), "full": Budget(2560, 256, False)}
#: The learning curve's minimum Adam steps (surrogate.learning_curve, its committed run).
MIN_STEPS = 22_400
#: The training campaign's seed (the held-out walk's: + 1), as make dataset's.
TRAIN_SEED = 1
TRAIN_UNIT, HELDOUT_UNIT = 64, 16
CONFIG = "improved"
#: Gesture pressures (-p, p, p): p is this fraction of the joint's pressure limit (capped
#: at the predictor's 0.3 MPa); P > 0 closes the right finger, P < 0 opens it.
GESTURE_FRACTION = 0.5
GESTURE_SIGNS = (-1.0, 1.0, 1.0)


# ---------------------------------------------------------------------- settings
@dataclass
class Settings:
    """Everything the stages are run with (parsed and checked command line)."""

    joint: JointSpec
    joint_file: Path
    out: Path
    budget: str
    train_samples: int
    heldout_samples: int
    epochs: int | None
    mesh_size: float | None
    divisions: int | None
    ranks: int
    launcher: str
    max_hours: float | None
    seed: int = TRAIN_SEED
    json: bool = False
    digest: str = field(init=False)

    def __post_init__(self):
        self.digest = joint_digest(self.joint)

    def mesh_args(self) -> list[str]:
        """The render's and the campaigns' mesh options (none: the joint file's [mesh])."""
        if self.divisions is not None:
            return ["--divisions", str(self.divisions)]
        return [] if self.mesh_size is None else ["--mesh-size", f"{self.mesh_size!r}"]


def parse_args(argv=None) -> Settings:
    ap = cli.Parser(prog="python -m apps.pipeline", description=__doc__.split("\n\n")[0])
    ap.add_argument("--joint", required=True, metavar="FILE", help="joint description file (docs/joints.md)")
    ap.add_argument("--budget", choices=sorted(BUDGETS), default="small",
                    help="small: 256 + 64 samples (a laptop, well under an hour on 4 cores); "
                         "full: 2,560 + 256 samples (the paper joint's campaign)")
    ap.add_output("--out", folder=True, help="results folder (default results/joints/<joint name>)")
    ap.add_argument("--ranks", type=cli.number(1, 4096, integer=True), default=1,
                    help="MPI ranks of the campaigns (default 1: no launcher)")
    ap.add_argument("--launcher", default="mpirun -q --oversubscribe -n {ranks}",
                    help="command that starts the campaigns' ranks when --ranks > 1 ({ranks} is "
                         "replaced; default 'mpirun -q --oversubscribe -n {ranks}', under Slurm "
                         "'srun --mpi=pmix')")
    ap.add_argument("--max-hours", type=cli.number(0, None, "h", open_lo=True),
                    help="time budget of each campaign (exit 3 when it stops: run again to resume)")
    mesh = ap.add_mutually_exclusive_group()
    mesh.add_argument("--mesh-size", type=cli.number(0.3, 10, "mm"),
                      help="tetrahedron size of the render and the campaigns (default: the joint file's [mesh])")
    mesh.add_argument("--divisions", type=cli.number(1, MAX_DIVISIONS, integer=True),
                      help="swept Q2 hexahedra of N divisions instead (fem.mesh.hexahedra; default: the joint file's [mesh])")
    count = cli.number(1, 1_000_000, integer=True)
    ap.add_argument("--samples", type=count, help="training campaign samples (default: the budget's)")
    ap.add_argument("--heldout-samples", type=count, help="held-out campaign samples (default: the budget's)")
    ap.add_argument("--epochs", type=cli.number(1, 100_000, integer=True),
                    help="training epochs (default: the budget's)")
    ap.add_argument("--seed", type=cli.number(0, 2**31 - 2, integer=True), default=TRAIN_SEED,
                    help=f"seed of the training campaign; the held-out walk's is SEED + 1 (default {TRAIN_SEED})")
    args = ap.parse_args(argv)
    with ap.errors():
        joint = load_joint(args.joint)
    if args.ranks > 1 and not args.launcher.strip():
        ap.error("--launcher is empty: give the command that starts --ranks ranks")
    budget = BUDGETS[args.budget]
    out = Path(args.out) if args.out else ROOT / "results" / "joints" / joint.name
    if args.out is None and (why := cli.check_output(out.parent.parent, folder=True)):
        ap.error(why)
    settings = Settings(joint, Path(args.joint).resolve(), out.resolve(), args.budget,
                        args.samples or budget.train_samples, args.heldout_samples or budget.heldout_samples,
                        args.epochs, args.mesh_size, args.divisions, args.ranks, args.launcher, args.max_hours, args.seed, args.json)
    with ap.errors():
        check_folder(settings)
    return settings


def check_folder(s: Settings) -> None:
    """ValueError (one line) when DIR holds another joint's pipeline: its joint.toml, its
    record or one of its datasets is of another joint, or a dataset holds more samples
    than asked (a campaign never shrinks)."""
    held = s.out / "joint.toml"
    if held.is_file():
        other = joint_digest(load_joint(held))
        if other != s.digest:
            raise ValueError(f"{s.out} holds the pipeline of another joint (sha256 {other[:12]}), not of "
                             f"--joint {s.joint.name!r} (sha256 {s.digest[:12]}): use another --out")
    record = read_record(s.out)
    if record and record.get("joint_sha256") != s.digest:
        raise ValueError(f"{s.out}/{RECORD} is of another joint (sha256 {str(record.get('joint_sha256'))[:12]}): "
                         f"use another --out")
    for name, samples in (("train", s.train_samples), ("heldout", s.heldout_samples)):
        root = s.out / "data" / name
        if not Manifest.exists(root):
            continue
        try:
            manifest = Manifest.load(root)
            digest = joint_digest(recorded_joint(manifest.config))
        except ShardError as exc:
            raise ValueError(f"{root}: {exc}") from None
        if digest != s.digest:
            raise ValueError(f"{root} holds a campaign of another joint (sha256 {digest[:12]}): use another --out")
        if (manifest.samples_requested or 0) > samples:
            raise ValueError(f"{root} holds a campaign of {manifest.samples_requested} samples; this run asks "
                             f"for {samples} (a campaign never shrinks): use its budget or another --out")


# ---------------------------------------------------------------------- record
def read_record(out: Path) -> dict:
    """DIR/pipeline.json ({} when absent or unreadable: every stage then runs again)."""
    try:
        record = json.loads((out / RECORD).read_text())
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) and record.get("format") == FORMAT else {}


def key_of(**parts) -> str:
    """sha256 of the canonical JSON of what determines a stage's outputs."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()


def file_digests(out: Path, files: list[str]) -> dict[str, str] | None:
    """{file: sha256} of ``files`` under DIR, or None when one is missing."""
    if not all((out / f).is_file() for f in files):
        return None
    return {f: sha256_file(out / f) for f in files}


@dataclass
class Stage:
    """One stage: its command (argv after ``python``, run with the ``launcher`` prefix),
    the files it writes (relative to DIR), the key of what makes them, and an extra
    completeness check (None when complete, else why not)."""

    name: str
    argv: list[str]
    outputs: list[str]
    key: str
    incomplete: Callable[[], str | None] | None = None
    stdout_to: str | None = None       # save the stage's stdout (its --json) as this file
    launcher: list[str] = field(default_factory=list)


class Pipeline:
    """Runs the stages in order, skipping those whose record matches (module docstring)."""

    def __init__(self, s: Settings, total: int):
        self.s, self.total, self.done = s, total, 0
        self.record = read_record(s.out) or {"format": FORMAT, "stages": {}}
        self.record.update(joint=s.joint.name, joint_sha256=s.digest)
        self.ran: dict[str, bool] = {}

    def up_to_date(self, st: Stage) -> str | None:
        """Why ``st`` may be skipped (its record and files match), or None."""
        entry = self.record["stages"].get(st.name)
        if not entry or entry.get("key") != st.key:
            return None
        if file_digests(self.s.out, st.outputs) != entry.get("outputs"):
            return None
        if st.incomplete is not None and st.incomplete() is not None:
            return None
        return "up to date"

    def run(self, st: Stage) -> None:
        """Run (or skip) ``st``; raise StageFailed when its command fails."""
        self.done += 1
        head = f"[pipeline] {self.done}/{self.total} {st.name}"
        if self.up_to_date(st):
            entry = self.record["stages"][st.name]
            self.say(f"{head}: skipped, up to date ({entry['wall_s']:.0f} s when it ran)")
            self.ran[st.name] = False
            return
        self.record["stages"].pop(st.name, None)
        self.save()
        log = self.s.out / "logs" / f"{st.name}.log"
        self.say(f"{head}: running (log {log}) ...", end="")
        t0 = time.perf_counter()
        code, stdout = self._execute(st, log)
        wall = time.perf_counter() - t0
        if code != 0:
            self.say(f" failed after {wall:.0f} s (exit {code})")
            raise StageFailed(st.name, code, log)
        if st.stdout_to:
            write_text(self.s.out / st.stdout_to, stdout)
        digests = file_digests(self.s.out, st.outputs)
        missing = [f for f in st.outputs if not (self.s.out / f).is_file()]
        if digests is None or (st.incomplete is not None and st.incomplete() is not None):
            self.say(f" incomplete after {wall:.0f} s")
            raise StageFailed(st.name, 1, log, f"missing {missing}" if missing else st.incomplete())
        self.record["stages"][st.name] = {"key": st.key, "outputs": digests, "wall_s": wall,
                                          "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        self.save()
        self.ran[st.name] = True
        self.say(f" done in {wall:.0f} s")

    def _execute(self, st: Stage, log: Path) -> tuple[int, str]:
        log.parent.mkdir(parents=True, exist_ok=True)
        cmd = [*st.launcher, sys.executable, *st.argv]
        env = {**os.environ, "PYVISTA_OFF_SCREEN": "true"}
        env.setdefault("OMP_NUM_THREADS", "1")
        with open(log, "w") as err:
            err.write("$ " + shlex.join(cmd) + "\n")
            err.flush()
            proc = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=err, text=True)
        with open(log, "a") as f:
            f.write(proc.stdout)
        return proc.returncode, proc.stdout

    def save(self) -> None:
        write_json(self.s.out / RECORD, self.record)

    def say(self, text: str, end: str = "\n") -> None:
        """A progress line: stdout, or stderr with --json (stdout is then the JSON alone)."""
        print(text, end=end, file=sys.stderr if self.s.json else sys.stdout, flush=True)


class StageFailed(Exception):
    def __init__(self, name: str, code: int, log: Path, why: str | None = None):
        super().__init__(name)
        self.name, self.code, self.log, self.why = name, code, log, why

    def line(self) -> str:
        last = ""
        try:
            lines = [x for x in self.log.read_text().splitlines() if x.strip()]
            last = lines[-1] if lines else ""
        except OSError:
            pass
        why = self.why or last
        return f"stage {self.name} failed (exit {self.code}): {why} (log {self.log})"


# ---------------------------------------------------------------------- stages
def render_stage(s: Settings) -> Stage:
    """fem.cli.render at the paper's render load scaled to the joint's box: P = 2/3 P_max,
    F2 = -1/3 F_max, M = 0.2 M_max (the paper's 0.2 MPa, -1 N, 20 N·mm)."""
    p, f, m = s.joint.pressure_mpa, s.joint.force_n, s.joint.moment_nmm
    load = ["--p", f"{2 * p / 3!r}", "--f2", f"{-f / 3!r}", "--m", f"{0.2 * m!r}"]
    argv = ["-m", "fem.cli.render", "--joint", str(s.out / "joint.toml"), "--out", str(s.out / "render.png"),
            *load, *s.mesh_args(), "--json"]
    return Stage("render", argv, ["render.png", "render.json"], key_of(joint=s.digest, argv=argv[2:]),
                 stdout_to="render.json")


def outline_stage(s: Settings) -> Stage:
    """fem.studies.joint_outline on the pipeline's mesh, the joint's default pressures."""
    argv = ["-m", "fem.studies.joint_outline", "--joint", str(s.out / "joint.toml"),
            "--out", str(s.out / "joint_outline.json"), *s.mesh_args(), "--json"]
    return Stage("outline", argv, ["joint_outline.json"], key_of(joint=s.digest, mesh=s.mesh_args()))


def joint_text(s: Settings) -> str:
    """DIR/joint.toml: the joint file as given, and, when it has no [outline] table and the
    outline stage has measured one (DIR/joint_outline.json), that table appended."""
    text = s.joint_file.read_text()
    measured = s.out / "joint_outline.json"
    if s.joint.outline is not None or not measured.is_file():
        return text
    table = outline_table(*outline_of(json.loads(measured.read_text())))
    return (text.rstrip("\n") + "\n\n# Measured by python -m apps.pipeline's outline stage "
            "(fem.studies.joint_outline, joint_outline.json).\n" + table)


def campaign_stage(s: Settings, name: str, samples: int, seed: int, unit: int) -> Stage:
    root = s.out / "data" / name
    argv = ["-m", "workflow.campaign", "--joint", str(s.out / "joint.toml"), "--samples", str(samples),
            "--seed", str(seed), "--unit-size", str(min(unit, samples)), "--out", str(root), *s.mesh_args(),
            "--progress-every", "300"]
    if s.max_hours is not None:
        argv += ["--max-hours", f"{s.max_hours!r}"]
    launcher = shlex.split(s.launcher.replace("{ranks}", str(s.ranks))) if s.ranks > 1 else []

    def incomplete() -> str | None:
        try:
            m = Manifest.load(root)
        except ShardError as exc:
            return str(exc)
        if not m.complete or m.samples_requested != samples:
            return f"{root}: {m.units_done}/{m.units_total} units of {m.samples_requested} samples"
        if joint_digest(recorded_joint(m.config)) != s.digest:
            return f"{root}: a campaign of another joint"
        return None

    key = key_of(joint=s.digest, samples=samples, seed=seed, unit=unit, mesh=s.mesh_args())
    return Stage(f"{name}-data", argv, [f"data/{name}/manifest.json"], key, incomplete, launcher=launcher)


def train_epochs(s: Settings) -> tuple[int, float] | None:
    """(epochs, lr_decay) of the small budget's step rule (module docstring) for the
    training split of DIR/data/train, or None: the config's own (full budget)."""
    from surrogate.train import CONFIGS     # the improved config's E0, d0 and batch

    cfg = CONFIGS[CONFIG][1]
    if s.epochs is not None:
        return s.epochs, cfg.lr_decay ** (cfg.epochs / s.epochs)
    if not BUDGETS[s.budget].step_budget:
        return None
    arrays, manifest = load_dataset(s.out / "data" / "train")
    n_train = int((split_of(arrays["sample_id"], manifest.seed) == 0).sum())
    epochs = max(cfg.epochs, math.ceil(MIN_STEPS / max(1, math.ceil(n_train / cfg.batch_size))))
    return epochs, cfg.lr_decay ** (cfg.epochs / epochs)


def train_stage(s: Settings) -> Stage:
    overrides = []
    if (budget := train_epochs(s)) is not None:
        overrides = ["--set", f"epochs={budget[0]}", "--set", f"lr_decay={budget[1]!r}"]
    argv = ["-m", "surrogate.train", "--config", CONFIG, "--data", str(s.out / "data" / "train"),
            "--out", str(s.out / "surrogate.pt"), *overrides, "--quiet"]
    key = key_of(joint=s.digest, data=dataset_digest(s.out / "data" / "train"), argv=argv[2:4] + overrides)
    return Stage("train", argv, ["surrogate.pt", "surrogate_curve.png"], key,
                 lambda: checkpoint_mismatch(s))


def checkpoint_mismatch(s: Settings) -> str | None:
    """Why DIR/surrogate.pt is not a surrogate of this joint, or None."""
    from surrogate.model import checkpoint_joint, load_checkpoint

    path = s.out / "surrogate.pt"
    try:
        digest = joint_digest(checkpoint_joint(load_checkpoint(path), str(path)))
    except ValueError as exc:
        return str(exc)
    return None if digest == s.digest else f"{path} is a surrogate of joint sha256 {digest[:12]}"


def evaluate_stages(s: Settings) -> list[Stage]:
    ckpt = sha256_file(s.out / "surrogate.pt")
    stages = []
    for name, data, split, out in (("evaluate", "heldout", "all", "heldout.json"),
                                   ("train-fit", "train", "train", "train_fit.json")):
        argv = ["-m", "surrogate.evaluate", "--model", str(s.out / "surrogate.pt"),
                "--data", str(s.out / "data" / data), "--split", split, "--out", str(s.out / out),
                "--json"]
        key = key_of(joint=s.digest, model=ckpt, data=dataset_digest(s.out / "data" / data), split=split)
        stages.append(Stage(name, argv, [out], key))
    return stages


def finger_text(s: Settings) -> str:
    """finger.toml: three joints of joint.toml, the paper finger's link between them and
    its tip last; its joint weight and base mounts (contract/fingers/paper.toml)."""
    paper = load_finger()
    joint = next(p for p in paper.parts if p.kind == "joint")
    link, tip = [p for p in paper.parts if p.kind == "rigid"][:2]

    def rigid(p) -> str:
        return (f'[[part]]\nkind = "rigid"\nlength = {p.length!r}\nheight = {p.height!r}\nwidth = {p.width!r}\n'
                f"weight = {p.weight!r}\ncontact_points = {p.contact_points}\n")

    def bellow(contact: bool) -> str:
        return (f'[[part]]\nkind = "joint"\nweight = {joint.weight!r}\ncontact = {str(contact).lower()}\n'
                f'joint = "joint.toml"\n')

    head = (f"# Written by python -m apps.pipeline: three joints of joint.toml ({s.joint.name!r}) with the\n"
            f"# paper finger's link between them and its tip (contract/fingers/paper.toml).\n"
            f'format = "softjoint-finger/1"\nname = "{s.joint.name}-three"\n'
            f"base_gap = {paper.base_gap!r}\nbase_angle_deg = {math.degrees(paper.base_angle)!r}\n\n")
    return head + "\n".join([bellow(False), rigid(link), bellow(True), rigid(link), bellow(True), rigid(tip)])


def gesture_pressures(s: Settings) -> list[float]:
    """The gesture's pressures (MPa), base to tip: GESTURE_SIGNS x GESTURE_FRACTION of the
    joint's limit."""
    p = GESTURE_FRACTION * min(s.joint.pressure_mpa, PRESSURE_LIMIT)
    return [sign * p for sign in GESTURE_SIGNS]


def gesture_stage(s: Settings) -> Stage:
    pressures = ",".join(f"{p!r}" for p in gesture_pressures(s))
    argv = ["-m", "predictor.cli.gesture", "--finger", str(s.out / "finger.toml"), "--model", str(s.out / "surrogate.pt"),
            f"--pressures={pressures}", "--plot", str(s.out / "gesture.png"), "--json", "--quiet"]
    key = key_of(joint=s.digest, model=sha256_file(s.out / "surrogate.pt"), finger=sha256_file(s.out / "finger.toml"),
                 outline=sha256_file(s.out / "joint.toml"), argv=argv[6:7])
    return Stage("gesture", argv, ["gesture.png", "gesture.json"], key, stdout_to="gesture.json")


# ---------------------------------------------------------------------- summary
def dataset_figures(root: Path) -> dict:
    m = Manifest.load(root)
    return {"samples": m.samples, "failures": m.failures, "samples_requested": m.samples_requested,
            "cpu_hours": m.cpu_hours, "complete": m.complete}


ERROR_KEYS = ("mean_anchor_error_mm", "p95_anchor_error_mm", "tip_error_mm", "max_anchor_error_mm",
              "phi_end_error_deg", "cap_rotation_error_deg", "jacobian_rel_error", "n")


def summary(s: Settings, pipe: Pipeline, wall_s: float) -> dict:
    """The run's figures (module docstring), from the stages' files."""
    load = lambda name: json.loads((s.out / name).read_text())   # noqa: E731
    heldout, fit, gesture = load("heldout.json"), load("train_fit.json"), load("gesture.json")
    top = load("joint_outline.json")["bulge_mm"][-1]
    data = {name: dataset_figures(s.out / "data" / name) for name in ("train", "heldout")}
    stages = [{"stage": name, "wall_s": entry["wall_s"], "ran": pipe.ran.get(name, False),
               "finished": entry["finished"]} for name, entry in pipe.record["stages"].items()]
    return {
        "joint": {"name": s.joint.name, "sha256": s.digest, "file": str(s.joint_file)},
        "budget": s.budget, "out": str(s.out),
        "settings": {"train_samples": s.train_samples, "heldout_samples": s.heldout_samples,
                     "mesh_size_mm": s.mesh_size, "divisions": s.divisions, "epochs": train_epochs(s), "ranks": s.ranks},
        "samples": data,
        "outline": {"P_MPa": top["P_MPa"], "bulge_max_mm": max(top["pressurised_mm"]),
                    "other_min_mm": min(top["other_mm"]),
                    "table": "the joint file's" if s.joint.outline is not None else "measured (joint.toml)"},
        "heldout": {k: heldout.get(k) for k in ERROR_KEYS} | {"samples": heldout.get("n")},
        "train_fit": {k: fit.get(k) for k in ERROR_KEYS} | {"samples": fit.get("n")},
        "gesture": {k: gesture.get(k) for k in ("converged", "state", "tip", "tip_angle_deg",
                                                "joint_end_angle_deg", "iterations", "time_ms")}
                   | {"pressures_mpa": gesture_pressures(s), "finger": "finger.toml"},
        "stages": stages,
        "stage_wall_s_total": sum(x["wall_s"] for x in stages),
        "this_run_wall_s": wall_s,
    }


def summary_text(d: dict) -> str:
    h, t, g = d["heldout"], d["train_fit"], d["gesture"]
    lines = [f"pipeline of joint {d['joint']['name']!r} (sha256 {d['joint']['sha256'][:12]}), budget {d['budget']}: "
             f"{d['out']}", "stage            wall time  this run"]
    lines += [f"{x['stage']:<16} {x['wall_s']:>8.0f} s  {'ran' if x['ran'] else 'skipped (up to date)'}"
              for x in d["stages"]]
    lines.append(f"{'total':<16} {d['stage_wall_s_total']:>8.0f} s")
    for name, f in d["samples"].items():
        lines.append(f"{name} campaign: {f['samples']} samples, {f['failures']} failures, "
                     f"{f['cpu_hours']:.3f} CPU h of FEM")
    o = d["outline"]
    lines.append(f"outline at {o['P_MPa']:g} MPa: the pressurised cells up to {o['bulge_max_mm']:.2f} mm beyond "
                 f"the band, the other side {o['other_min_mm']:.2f} mm; the predictor draws {o['table']} table")
    for what, e in (("held-out", h), ("training split", t)):
        lines.append(f"surrogate on its {what} ({e['samples']} samples): mean anchor error "
                     f"{e['mean_anchor_error_mm']:.4f} mm, tip {e['tip_error_mm']:.4f} mm, p95 "
                     f"{e['p95_anchor_error_mm']:.4f} mm, cap rotation {_deg(e['cap_rotation_error_deg'])}")
    tip = "not converged" if not g["converged"] else \
        f"tip ({g['tip'][0]:.2f}, {g['tip'][1]:.2f}) mm, tip angle {g['tip_angle_deg']:.2f} deg"
    pressures = ", ".join(f"{p:g}" for p in g["pressures_mpa"])
    lines.append(f"gesture (finger.toml at ({pressures}) MPa, gravity): {tip}")
    return "\n".join(lines) + "\n"


def _deg(v) -> str:
    return "n/a" if v is None else f"{v:.3f} deg"


# ---------------------------------------------------------------------- main
def prepare(s: Settings) -> None:
    """DIR, its copy of the joint file (joint_text) and its finger file (rewritten only
    when changed)."""
    s.out.mkdir(parents=True, exist_ok=True)   # its parent exists (--out) or is results/joints
    (s.out / "data").mkdir(exist_ok=True)
    for name, text in (("joint.toml", joint_text(s)), ("finger.toml", finger_text(s))):
        path = s.out / name
        if not path.is_file() or path.read_text() != text:
            write_text(path, text)
    parse_finger(finger_text(s), str(s.out / "finger.toml"))   # a generated finger must load


def run(s: Settings) -> dict:
    """Every stage in order; the summary's dict. Raises StageFailed."""
    t0 = time.perf_counter()
    prepare(s)
    pipe = Pipeline(s, total=9)
    pipe.run(render_stage(s))
    pipe.run(outline_stage(s))
    prepare(s)                                  # joint.toml with the measured [outline], if it lacked one
    pipe.run(campaign_stage(s, "train", s.train_samples, s.seed, TRAIN_UNIT))
    pipe.run(campaign_stage(s, "heldout", s.heldout_samples, s.seed + 1, HELDOUT_UNIT))
    pipe.run(train_stage(s))
    for stage in evaluate_stages(s):
        pipe.run(stage)
    pipe.run(gesture_stage(s))
    pipe.done += 1
    result = summary(s, pipe, time.perf_counter() - t0)
    write_json(s.out / "metrics.json", {"joint": result["joint"], "budget": s.budget,
                                        "heldout": result["heldout"], "train_fit": result["train_fit"],
                                        "samples": result["samples"]})
    write_json(s.out / "summary.json", result)
    write_text(s.out / "summary.txt", summary_text(result))
    pipe.say(f"[pipeline] {pipe.done}/{pipe.total} summary: {s.out / 'summary.txt'}: held-out mean anchor error "
             f"{result['heldout']['mean_anchor_error_mm']:.4f} mm ({result['heldout']['samples']} samples)")
    return result


def main(argv=None) -> int:
    s = parse_args(argv)
    try:
        result = run(s)
    except StageFailed as exc:
        print(f"python -m apps.pipeline: {exc.line()}", file=sys.stderr)
        incomplete = exc.name.endswith("-data") and exc.code == EXIT_INCOMPLETE
        return EXIT_INCOMPLETE if incomplete else 1
    if s.json:
        cli.print_json(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
