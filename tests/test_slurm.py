"""The FEM campaign on a real Slurm cluster (issue 17): workflow/slurm/campaign.sbatch as committed.

A module fixture starts a throw-away one-node cluster of Debian's slurm-wlm 22.05: munged
with a generated key, slurmctld and slurmd, all with a slurm.conf of its own (generated
from ``hostname`` and ``nproc``; ``MpiDefault=none`` as on a stock site; its own port pair,
state, spool, logs and munge socket under the pytest tmp folder), and stops exactly the
processes it started afterwards. On it, a coarse campaign (6 samples in 3 units of 2, mesh
4 mm, seed 3411, no fresh checks) passed to the script through its environment variables:

- one 2-task job, requeued with ``scontrol requeue`` once a shard exists but the campaign
  is unfinished, ends (one restart, exit 0) with the dataset of a local ``mpirun -n 2`` run
  of the same command: the same sample ids and inputs, anchors, Jacobians and every other
  reproducible array equal to 1e-10, no duplicated sample, no temp file left,
  ``workflow.dataset verify --require-complete`` exit 0; the restart did only the units
  left, and its budget came from the job's time limit (15 min -> --max-hours 0.2250);
- a job array (``--array=0-1``, UNITS_PER_TASK=2: units 0-1 and unit 2) merged with
  ``workflow.dataset merge`` gives the same dataset;
- a spent time budget (MAX_HOURS=1e-9) exits 3 through srun on a PMIx world of 2 ranks;
  SRUN_MPI=none (the old script's srun on a stock site) fails and writes no shard.

Without the cluster: ``workflow.campaign`` inside an srun step of 2 tasks that sees a world
of 1 (no MPI plugin) exits 2 with one line from task 0 only and creates nothing; the script
run by bash refuses inconsistent job-array settings (exit 2, one line) before any srun, and
does not believe an srun stub that exits 0 without running the campaign (it launches the
step again, SRUN_TRIES times, then exits 1).

If slurm-wlm/munge are absent and apt-get cannot install them, or the daemons do not come
up, the cluster tests are skipped with the reason. Seed 3411 keeps the from-zero solves
short. With 3 units on 2 ranks, the rank that writes the first shard goes on to the third
unit, so a whole unit's solve is the window in which the job is requeued (it cannot end
before). 3-6 minutes on the shared 2-core machine, depending on its load (three
campaigns of three from-zero solves each, and the units redone after the requeue).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from workflow import shards

pytestmark = pytest.mark.mpi

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "workflow" / "slurm" / "campaign.sbatch"
PY = sys.executable
CAMPAIGN = {"SAMPLES": "6", "SEED": "3411", "UNIT_SIZE": "2", "MESH_SIZE": "4",
            "FRESH_CHECK_EVERY": "0"}
CAMPAIGN_ARGS = ["--samples", "6", "--seed", "3411", "--unit-size", "2", "--mesh-size", "4",
                 "--fresh-check-every", "0"]
N_UNITS = 3  # on 2 ranks: the third unit keeps the job running after the first shard
DAEMONS = ("munged", "slurmctld", "slurmd")
CLIENTS = ("sbatch", "srun", "scontrol", "squeue", "sinfo", "scancel")
FINISHED = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY",
            "PREEMPTED", "BOOT_FAIL", "DEADLINE"}
JOB_TIMEOUT_S = 900
BASE_ENV = {k: v for k, v in os.environ.items() if not k.startswith("SLURM_")}   # not a job's
BASE_ENV.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
                OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def tail(path: Path, n: int = 30) -> str:
    try:
        lines = Path(path).read_text(errors="replace").splitlines()
    except OSError as exc:
        return f"({exc})"
    return "\n".join(lines[-n:])


def free_ports(n: int) -> list[int]:
    """n distinct TCP ports free right now (held open together so they differ)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


@dataclass
class Cluster:
    """A running one-node cluster: its folder, environment (SLURM_CONF) and daemons."""

    dir: Path
    env: dict
    procs: dict = field(default_factory=dict)      # name -> Popen, for the teardown only

    def cmd(self, *args, timeout: float = 60, check: bool = True) -> subprocess.CompletedProcess:
        r = subprocess.run(args, env=self.env, cwd=ROOT, capture_output=True, text=True,
                           timeout=timeout)
        if check and r.returncode:
            raise AssertionError(f"{' '.join(args)} -> {r.returncode}: {r.stderr.strip()}\n"
                                 + self.logs())
        return r

    def logs(self, *job_logs: Path) -> str:
        """The tails of the daemon logs and of the given job logs (for failure messages)."""
        parts = [(p.name, p) for p in job_logs]
        parts += [("slurmctld.log", self.dir / "slurmctld.log"),
                  ("slurmd.log", self.dir / "slurmd.log"),
                  ("munged.out", self.dir / "munged.out")]
        return "\n".join(f"----- {name}\n{tail(p)}" for name, p in parts)

    def submit(self, ntasks: int, *opts: str, env: dict, log: Path) -> str:
        """sbatch the committed script on ``ntasks`` tasks of our node, with ``env``
        exported on top of ours; the job id. The command line overrides the script's
        #SBATCH shape (2 nodes x 32 tasks, 2 GB per CPU)."""
        export = ",".join(["ALL"] + [f"{k}={v}" for k, v in env.items()])
        r = self.cmd("sbatch", "--parsable", f"--export={export}", "--nodes=1",
                     f"--ntasks={ntasks}", f"--ntasks-per-node={ntasks}", "--mem-per-cpu=1G",
                     "--time=00:15:00", f"--chdir={ROOT}", f"--output={log}", *opts, str(SCRIPT))
        return r.stdout.strip().split(";")[0]

    def jobs(self, job: str) -> list[dict]:
        """scontrol's records of ``job`` (one per array task), as dicts of its fields."""
        r = self.cmd("scontrol", "show", "job", "-o", job, check=False)
        return [dict(kv.split("=", 1) for kv in line.split() if "=" in kv)
                for line in r.stdout.splitlines() if line.startswith("JobId=")]

    def wait(self, job: str, log: Path, on_poll=None) -> list[dict]:
        """Poll (0.3 s) until every task of ``job`` has finished; its final records. Not
        ``sbatch --wait``: it polls at growing intervals (a 12 s job returned after 42 s),
        and the requeue needs to watch the running job anyway."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < JOB_TIMEOUT_S:
            recs = self.jobs(job)
            if recs and all(r.get("JobState") in FINISHED for r in recs):
                return recs
            if on_poll is not None:
                on_poll(recs)
            time.sleep(0.3)
        self.cmd("scancel", job, check=False)
        raise AssertionError(f"job {job} still running after {JOB_TIMEOUT_S} s\n" + self.logs(log))


def install_slurm() -> str | None:
    """None if the Slurm and munge programs are there (installed with apt-get if not and
    we may); else why not."""
    missing = [p for p in DAEMONS + CLIENTS if shutil.which(p) is None]
    if missing and os.geteuid() == 0 and shutil.which("apt-get"):
        # `make setup` installs them (APT_PACKAGES); a venv set up before that did not.
        subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends",
                        "slurm-wlm", "munge"], capture_output=True, timeout=600,
                       env={**BASE_ENV, "DEBIAN_FRONTEND": "noninteractive"})
        missing = [p for p in DAEMONS + CLIENTS if shutil.which(p) is None]
    return f"no {', '.join(missing)} (apt-get install slurm-wlm munge failed)" if missing else None


def slurm_conf(d: Path, munge_socket: Path, ctld_port: int, slurmd_port: int) -> str:
    host = socket.gethostname().split(".")[0]
    mem_mb = next(int(line.split()[1]) for line in open("/proc/meminfo")
                  if line.startswith("MemTotal:")) // 1024
    return f"""\
# Throw-away one-node cluster of tests/test_slurm.py
ClusterName=sj{ctld_port}
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
# Our own munged. cred_expire is also how long a requeued job is held (default 120 s).
AuthInfo=socket={munge_socket},cred_expire=10
# As a stock site: no MPI plugin unless srun asks for one.
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SchedulerType=sched/backfill
# Schedule within a second (defaults: 30 s backfill, 60 s main loop).
SchedulerParameters=bf_interval=1,sched_interval=1
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MailProg=/bin/true
KillWait=5
ReturnToService=2
StateSaveLocation={d / "state"}
SlurmdSpoolDir={d / "spool"}
SlurmctldPidFile={d / "slurmctld.pid"}
SlurmdPidFile={d / "slurmd.pid"}
SlurmctldLogFile={d / "slurmctld.log"}
SlurmdLogFile={d / "slurmd.log"}
NodeName={host} NodeAddr=127.0.0.1 CPUs={os.cpu_count()} RealMemory={int(mem_mb * 0.9)} State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def start(cluster: Cluster, name: str, *args: str) -> None:
    out = open(cluster.dir / f"{name}.out", "wb")
    cluster.procs[name] = subprocess.Popen([name, *args], env=cluster.env, stdout=out,
                                           stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)


def until(predicate, timeout: float, what: str, cluster: Cluster) -> None:
    """Wait for ``predicate``; skip (with the logs' last line) if a daemon dies or time ends."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        dead = [n for n, p in cluster.procs.items() if p.poll() is not None]
        if dead:
            last = tail(cluster.dir / f"{dead[0]}.out", 1)
            pytest.skip(f"Slurm test cluster: {dead[0]} exited ({last.strip()})")
        if predicate():
            return
        time.sleep(0.3)
    pytest.skip(f"Slurm test cluster: {what} within {timeout:.0f} s")


def stop(cluster: Cluster) -> None:
    """Cancel our jobs, then stop the daemons we started (SIGTERM, then SIGKILL)."""
    if "slurmctld" in cluster.procs and cluster.procs["slurmctld"].poll() is None:
        subprocess.run(["scancel", "--user", str(os.getuid())], env=cluster.env,
                       capture_output=True, timeout=30)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 30:
            r = subprocess.run(["squeue", "-h"], env=cluster.env, capture_output=True,
                               text=True, timeout=30)
            if r.returncode or not r.stdout.strip():
                break
            time.sleep(0.5)
    for name in ("slurmd", "slurmctld", "munged"):
        p = cluster.procs.get(name)
        if p is None or p.poll() is not None:
            continue
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=15)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The running one-node cluster (skips if it cannot be had), torn down afterwards."""
    if os.geteuid() != 0:
        pytest.skip("Slurm test cluster: needs root (SlurmUser=root, munged --force)")
    why = install_slurm()
    if why:
        pytest.skip(f"Slurm test cluster: {why}")
    d = tmp_path_factory.mktemp("slurm")
    for sub in ("state", "spool", "munge"):
        (d / sub).mkdir()
    munge = d / "munge"
    if len(str(munge / "munge.socket")) > 100:       # AF_UNIX paths are at most 107 bytes
        import tempfile
        munge = Path(tempfile.mkdtemp(prefix="sj-munge-"))
    key = munge / "munge.key"
    key.write_bytes(os.urandom(1024))
    key.chmod(0o400)
    ctld_port, slurmd_port = free_ports(2)
    conf = d / "slurm.conf"
    conf.write_text(slurm_conf(d, munge / "munge.socket", ctld_port, slurmd_port))
    c = Cluster(d, {**BASE_ENV, "SLURM_CONF": str(conf)})
    try:
        # --force: munged refuses, as root, a socket folder not reachable by all users
        # (pytest's tmp folders are 0700); the key is ours, so that does not matter here.
        start(c, "munged", "--foreground", "--force", f"--socket={munge / 'munge.socket'}",
              f"--key-file={key}", f"--pid-file={munge / 'munged.pid'}",
              f"--log-file={munge / 'munged.log'}", f"--seed-file={munge / 'munged.seed'}")
        until(lambda: (munge / "munge.socket").exists(), 20, "no munge socket", c)
        start(c, "slurmctld", "-D", "-f", str(conf))
        start(c, "slurmd", "-D", "-f", str(conf))

        def idle() -> bool:
            r = subprocess.run(["sinfo", "-h", "-N", "-o", "%T"], env=c.env,
                               capture_output=True, text=True, timeout=30)
            return r.stdout.strip() == "idle"

        until(idle, 90, "node not idle", c)
        plugins = c.cmd("srun", "--mpi=list", check=False)
        if "pmix" not in plugins.stdout + plugins.stderr:
            pytest.skip("Slurm test cluster: srun has no mpi/pmix plugin")
        yield c
    finally:
        stop(c)
        if munge != d / "munge":
            shutil.rmtree(munge, ignore_errors=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The local reference: ``mpirun -n 2`` of the same campaign (exit 0)."""
    out = tmp_path_factory.mktemp("local") / "ref"
    cmd = ["mpirun", "--oversubscribe", "-n", "2", PY, "-m", "workflow.campaign",
           *CAMPAIGN_ARGS, "--out", str(out), "--quiet"]
    r = subprocess.run(cmd, cwd=ROOT, env=BASE_ENV, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return out


def job_env(out: Path, **extra: str) -> dict:
    env = {**CAMPAIGN, "OUT": str(out), "PROGRESS_EVERY": "5", **extra}
    if Path(PY) != ROOT / ".venv" / "bin" / "python":
        env["PY"] = PY                   # else the script's default .venv/bin/python
    return env


def shard_files(out: Path) -> list[Path]:
    return sorted((out / "shards").glob("unit-*.npz")) if (out / "shards").is_dir() else []


def assert_same_dataset(got: Path, ref: Path) -> None:
    """Same samples as the reference: ids and inputs exactly, every other reproducible
    array to 1e-10 (anchors in mm); no duplicates, no temp files; verify exits 0."""
    a, _ = shards.load_dataset(got)
    b, _ = shards.load_dataset(ref)
    assert len(np.unique(a["sample_id"])) == len(a["sample_id"]), "duplicated sample ids"
    assert len(a["sample_id"]) + len(a["failed_sample_id"]) == int(CAMPAIGN["SAMPLES"])
    np.testing.assert_array_equal(a["sample_id"], b["sample_id"])
    np.testing.assert_array_equal(a["inputs"], b["inputs"])
    np.testing.assert_allclose(a["anchors"], b["anchors"], rtol=0, atol=1e-10)
    assert set(a) == set(b)
    for k in sorted(set(a) - {"wall_time_s"}):
        if a[k].dtype.kind == "f":
            np.testing.assert_allclose(a[k], b[k], rtol=1e-10, atol=1e-10, err_msg=k)
        else:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert not [p for p in got.rglob("*") if p.name.endswith(".tmp")], "temp files left"
    r = subprocess.run([PY, "-m", "workflow.dataset", "verify", str(got), "--require-complete"],
                       cwd=ROOT, env=BASE_ENV, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr


# ---------------------------------------------------------------------------- no cluster
def test_singleton_tasks_are_refused(tmp_path):
    """Inside an srun step of 2 tasks (SLURM_STEP_*) a world of 1 means srun started
    singletons: exit 2, one line from task 0, nothing from task 1, no OUT created."""
    for procid, lines in (("0", 1), ("1", 0)):
        out = tmp_path / f"out{procid}"
        env = {**BASE_ENV, "SLURM_STEP_ID": "0", "SLURM_STEP_NUM_TASKS": "2",
               "SLURM_NTASKS": "2", "SLURM_PROCID": procid}
        r = subprocess.run([PY, "-m", "workflow.campaign", *CAMPAIGN_ARGS, "--out", str(out)],
                           cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 2, r.stderr
        assert len(r.stderr.splitlines()) == lines, r.stderr
        if lines:
            assert "Slurm started 2 tasks but MPI sees a world of 1" in r.stderr
            assert "--mpi=pmix" in r.stderr
        assert not out.exists()


def test_script_refuses_bad_array_settings(tmp_path):
    """The script's own checks, before any srun (run with bash, outside Slurm): one line and
    exit 2 for UNITS_PER_TASK outside an array, an array without UNITS_PER_TASK, both UNITS
    and UNITS_PER_TASK; exit 0 and no OUT for an array task past the campaign's last unit."""
    array = {"SLURM_ARRAY_TASK_ID": "0", "SLURM_ARRAY_TASK_COUNT": "2"}
    cases = [({"UNITS_PER_TASK": "1"}, 2, "UNITS_PER_TASK needs a job array"),
             (array, 2, "a job array needs UNITS_PER_TASK"),
             ({**array, "UNITS_PER_TASK": "1", "UNITS": "0:1"}, 2, "not both"),
             ({**array, "UNITS_PER_TASK": "0"}, 2, "positive integer"),
             ({**array, "SLURM_ARRAY_TASK_ID": "5", "UNITS_PER_TASK": "1"}, 0, "nothing to do")]
    for extra, code, text in cases:
        r = subprocess.run(["bash", str(SCRIPT)], cwd=ROOT, capture_output=True, text=True,
                           env={**BASE_ENV, **job_env(tmp_path / "out", **extra)}, timeout=120)
        assert r.returncode == code and text in r.stdout + r.stderr, (extra, r.stdout, r.stderr)
        assert len((r.stderr if code else r.stdout).splitlines()) == 1, (extra, r.stderr)
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob("out.part*"))


def test_a_step_that_srun_calls_done_but_never_ran_is_launched_again(tmp_path):
    """An srun that prints "task 0 launch failed" and exits 0 without running the campaign
    (seen on the CI cluster with two array tasks launching at once): the script does not
    believe the 0, launches the step SRUN_TRIES = 2 times, then fails with one line (exit 1,
    not 2: the settings were fine) and leaves no OUT; the settings reach the campaign's
    command line (UNITS, WALL_MESH_SIZE). Outside Slurm, srun is a stub on PATH."""
    bin_dir, calls = tmp_path / "bin", tmp_path / "calls"
    bin_dir.mkdir()
    (bin_dir / "srun").write_text("#!/bin/bash\necho \"$*\" >> " + str(calls) + "\n"
                                  "echo 'srun: error: task 0 launch failed: Unspecified error' >&2\n")
    (bin_dir / "srun").chmod(0o755)
    env = {**BASE_ENV, **job_env(tmp_path / "out", SRUN_TRIES="2", UNITS="0:1", WALL_MESH_SIZE="2"),
           "PATH": f"{bin_dir}:{BASE_ENV['PATH']}"}
    r = subprocess.run(["bash", str(SCRIPT)], cwd=ROOT, capture_output=True, text=True, env=env,
                       timeout=120)
    launches = calls.read_text().splitlines()
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert len(launches) == 2 and all("-m workflow.campaign" in c and "--units 0:1" in c
                                      and "--wall-mesh-size 2" in c for c in launches), launches
    assert "try 2 of 2" in r.stdout, r.stdout
    errors = [line for line in r.stderr.splitlines() if line.startswith("campaign.sbatch: error")]
    assert errors == [f"campaign.sbatch: error: srun exited 0 2 time(s) but {tmp_path / 'out'} is not done"], r.stderr
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- on the cluster
def test_spent_budget_exits_3_on_two_pmix_ranks(cluster, tmp_path):
    """MAX_HOURS=1e-9: the campaign starts on a PMIx world of 2 ranks, solves nothing and
    the job ends with exit code 3 (time budget reached, unfinished) and no shard. With
    SRUN_MPI=none (a stock site's srun without --mpi) the job fails and writes no shard."""
    log = tmp_path / "budget.log"
    job = cluster.submit(2, env=job_env(tmp_path / "budget", MAX_HOURS="1e-9"), log=log)
    (rec,) = cluster.wait(job, log)
    text = log.read_text()
    assert rec["JobState"] == "FAILED" and rec["ExitCode"] == "3:0", f"{rec}\n{cluster.logs(log)}"
    assert re.search(r"units to do on 2 rank\(s\)", text), cluster.logs(log)
    assert "time budget reached" in text and not shard_files(tmp_path / "budget")

    log = tmp_path / "nompi.log"
    job = cluster.submit(2, env=job_env(tmp_path / "nompi", SRUN_MPI="none"), log=log)
    (rec,) = cluster.wait(job, log)
    assert rec["JobState"] == "FAILED" and rec["ExitCode"] != "0:0", f"{rec}\n{cluster.logs(log)}"
    assert not shard_files(tmp_path / "nompi")


def test_requeued_job_resumes_to_the_local_dataset(cluster, reference, tmp_path):
    """A 2-task job of the committed script, requeued mid-run, ends (exit 0, one restart)
    with the local mpirun dataset; the restart redid only the unfinished unit."""
    out, log = tmp_path / "job", tmp_path / "job.log"
    job = cluster.submit(2, env=job_env(out), log=log)
    requeued = []

    def requeue_mid_run(recs):
        done = shard_files(out)
        if not requeued and recs and recs[0].get("JobState") == "RUNNING" and done:
            assert len(done) < N_UNITS, "the campaign ended before it could be requeued"
            cluster.cmd("scontrol", "requeue", job)
            requeued.append(len(done))

    (rec,) = cluster.wait(job, log, requeue_mid_run)
    text = log.read_text()
    msg = f"{rec}\n{cluster.logs(log)}"
    assert len(requeued) == 1 and 1 <= requeued[0] < N_UNITS, msg
    assert rec["JobState"] == "COMPLETED" and rec["ExitCode"] == "0:0", msg
    assert rec["Restarts"] == "1", msg
    # Both runs in the one log (--open-mode=append): all units to do, then only the one left.
    first, _, second = text.partition("(restart 1)")
    assert "(restart 0)" in first and second, msg
    assert re.search(rf" {N_UNITS} of {N_UNITS} units to do on 2 rank\(s\)", first), msg
    left = re.search(rf" (\d+) of {N_UNITS} units to do on 2 rank\(s\)", second)
    assert left and 1 <= int(left.group(1)) <= N_UNITS - requeued[0], msg   # only what was left
    assert "--max-hours 0.2250" in second, msg            # 15 min limit less 10 %
    assert_same_dataset(out, reference)


def test_job_array_merged_is_the_local_dataset(cluster, reference, tmp_path):
    """--array=0-1 with UNITS_PER_TASK=2: task i writes units 2i, 2i+1 into OUT.part<i>; merged
    with workflow.dataset merge they give the local mpirun dataset."""
    out, log = tmp_path / "arr", tmp_path / "arr-%a.log"
    job = cluster.submit(1, "--array=0-1", env=job_env(out, UNITS_PER_TASK="2"),
                         log=log)
    logs = [tmp_path / f"arr-{i}.log" for i in range(2)]
    recs = cluster.wait(job, logs[0])
    msg = f"{recs}\n{cluster.logs(*logs)}"
    assert sorted(r.get("ArrayTaskId") for r in recs) == ["0", "1"], msg
    assert all(r["JobState"] == "COMPLETED" and r["ExitCode"] == "0:0" for r in recs), msg
    parts = [Path(f"{out}.part{i}") for i in range(2)]
    assert [len(shard_files(p)) for p in parts] == [2, 1], msg
    merged = tmp_path / "merged"
    r = subprocess.run([PY, "-m", "workflow.dataset", "merge", str(merged), *map(str, parts)],
                       cwd=ROOT, env=BASE_ENV, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert_same_dataset(merged, reference)
