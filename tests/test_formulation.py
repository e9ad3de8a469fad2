"""The formulation (P2 displacement or Taylor-Hood u-p "mixed", fem.physics.problem) through the
FEM tools, on the coarse 4 mm joint, one rank (about 1 min on a shared 2-core machine).

* the ``--formulation`` option: its choices are fem.physics.problem's, a bad value is one line and
  exit 2, and a displacement campaign's config is the committed one, key for key (old
  manifests stay valid); "mixed" adds exactly ``"formulation": "mixed"``;
* a tiny mixed campaign: its manifest records the formulation, ``dataset verify --mirror``
  re-solves the y-mirror of a stored sample with that formulation and finds the mirror
  relation to solver tolerance (a displacement re-solve would be off by the locking
  error: 1.1 mm measured), and a displacement resume is refused naming the flag and both
  values, leaving the dataset as it was;
* the mixed whole finger: a finger of one joint and one rigid part without gravity is the
  mixed single joint under its pressure (nothing loads its end), to the mesh difference
  between the two models; it is softer than the displacement finger (the locking relief)
  with its tip moving the same way, and the base stays clamped.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI  # noqa: E402

from contract.finger import parse_finger  # noqa: E402
from fem.cli import finger as fem_finger  # noqa: E402
from fem.cli import solve as fem_solve  # noqa: E402
from fem.solvers.finger import FingerLoad, FingerSolver  # noqa: E402
from fem.mesh.geometry import FingerGeometry, JointGeometry  # noqa: E402
from contract.joint import FORMULATIONS  # noqa: E402
from fem.solvers.joint import JointSolver, Load  # noqa: E402
from workflow import campaign, dataset  # noqa: E402
from workflow.shards import Manifest  # noqa: E402
from test_finger import ONE_JOINT  # noqa: E402  (one joint + a 65 mm, 0.5 N rigid part)

PY = sys.executable
ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OMPI_ALLOW_RUN_AS_ROOT": "1",
       "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
COARSE = JointGeometry(mesh_size=4.0, divisions=0, hex_size=None)      # coarse tetrahedra
CAMPAIGN = ["--samples", "2", "--seed", "5", "--unit-size", "2", "--mesh-size", "4",
            "--fresh-check-every", "0", "--quiet", "--json"]


def test_formulation_option(capsys, tmp_path):
    """The choices are contract.joint.FORMULATIONS; none given means the production one
    (None, resolved by the tool); a bad value exits 2 with one line naming it (fem.cli.solve,
    fem.solvers.finger, workflow.campaign)."""
    ap = fem_solve.build_parser()
    assert next(a for a in ap._actions if a.dest == "formulation").choices == FORMULATIONS
    assert ap.parse_args([]).formulation is None
    assert ap.parse_args(["--formulation", "mixed"]).formulation == "mixed"
    required = [*CAMPAIGN, "--out", str(tmp_path / "new")]
    for parse in (ap.parse_args, fem_finger.build_parser().parse_args,
                  lambda argv: campaign.parse_args(required + argv)):
        with pytest.raises(SystemExit) as exc:
            parse(["--formulation", "hybrid"])
        err = capsys.readouterr().err
        assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and "'hybrid'" in err
    assert not (tmp_path / "new").exists()


def test_displacement_config_is_the_committed_one():
    """campaign_config of the 1.8 mm reference held-out set's settings (results/data/
    heldout_h1.8), displacement: equal to its manifest's config (so it still resumes and verifies); mixed: that config plus
    "formulation": "mixed" and nothing else."""
    m = Manifest.load(ROOT / "results/data/heldout_h1.8")
    cfg = m.config
    args = (JointGeometry.from_record(cfg["geometry"]), cfg["unit_size"], cfg["walk_step"],
            cfg["fresh_check_every"])
    assert "formulation" not in cfg
    assert campaign.campaign_config(*args, formulation="displacement") == cfg
    assert campaign.campaign_config(*args, formulation="mixed") == {**cfg, "formulation": "mixed"}


def run_campaign(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([PY, "-m", "workflow.campaign", *CAMPAIGN, "--out", str(out), *extra],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def mixed_campaign(tmp_path_factory):
    """A 2-sample mixed campaign (one unit) on the 4 mm mesh."""
    out = tmp_path_factory.mktemp("formulation") / "mixed"
    r = run_campaign(out, "--formulation", "mixed")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout[r.stdout.find("{\n"):])
    assert summary["complete"] and summary["samples"] == 2 and summary["formulation"] == "mixed"
    return out


@pytest.mark.fem
def test_mixed_campaign_records_and_mirrors(mixed_campaign, capsys):
    """The manifest records "formulation": "mixed"; verify --mirror 1 passes, the mirrored
    re-solve matching the stored anchors within 1e-6 mm and the Jacobian within 1e-4
    (relative): it solved with the recorded formulation."""
    assert Manifest.load(mixed_campaign).config["formulation"] == "mixed"
    capsys.readouterr()
    assert dataset.main(["verify", str(mixed_campaign), "--mirror", "1", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] and report["n"] == 2
    assert report["mirror"]["max_anchor_error_mm"] < 1e-6
    assert report["mirror"]["max_jacobian_rel_error"] < 1e-4


@pytest.mark.fem
def test_displacement_resume_of_a_mixed_campaign_is_refused(mixed_campaign):
    """Resuming the mixed campaign in the displacement formulation: exit 2, one line naming
    --formulation with both values, every file as it was and no lock left."""
    before = {p: p.read_bytes() for p in mixed_campaign.rglob("*") if p.is_file()}
    r = run_campaign(mixed_campaign, "--formulation", "displacement")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "--formulation mixed (this run: displacement)" in r.stderr
    assert {p: p.read_bytes() for p in mixed_campaign.rglob("*") if p.is_file()} == before


@pytest.mark.fem
def test_mixed_finger_is_the_mixed_joint_and_softer_than_displacement():
    """One joint + a 65 mm rigid part, P = 0.15 MPa, no gravity (the end is free, so the
    joint is the single joint under P alone). Mixed finger against the mixed JointSolver:
    joint-frame anchors within 0.1 mm and cap rotation within 0.1 deg (measured 0.024 mm,
    0.026 deg; the displacement pair differs from them by ~2.5 deg). Against the
    displacement finger: the cap turns > 1 deg further and the tip moves > 5 % further
    (measured 21.3 against 18.8 deg, 13 %), in a direction within 5 deg (measured 1.2). The
    proximal centre (on the clamped face) stays at the mount (25, 0) mm."""
    geometry = FingerGeometry(parse_finger(ONE_JOINT), COARSE, 6.0)
    load = FingerLoad((0.15,), False)
    mixed = FingerSolver(geometry, MPI.COMM_SELF, formulation="mixed").solve(load)
    plain = FingerSolver(geometry, MPI.COMM_SELF, formulation="displacement").solve(load)
    joint = JointSolver(COARSE, MPI.COMM_SELF, formulation="mixed").solve(Load(P=0.15))
    assert mixed.converged and plain.converged and joint.converged
    cap = lambda r: r.end_angle[0] - r.theta[0]
    assert np.abs(mixed.local_anchors[0] - joint.anchors).max() < 0.1
    assert math.degrees(abs(cap(mixed) - joint.cap_rotation)) < 0.1
    assert math.degrees(abs(cap(mixed)) - abs(cap(plain))) > 1.0
    rest = np.array([25.0, -geometry.finger.length])
    u_m, u_p = mixed.tip - rest, plain.tip - rest
    assert np.linalg.norm(u_m) > 1.05 * np.linalg.norm(u_p)
    cos = u_m @ u_p / (np.linalg.norm(u_m) * np.linalg.norm(u_p))
    assert math.degrees(math.acos(min(cos, 1.0))) < 5.0
    np.testing.assert_allclose(mixed.proximal[0], [25.0, 0.0], atol=1e-12)
