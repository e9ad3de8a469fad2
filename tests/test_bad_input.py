"""Bad input on every command line (issue 13): exit 2, one line on stderr, nothing written.

Each row of CASES runs ``python -m MODULE ARGS`` from the repository root, with every
output pointed into a fresh folder ``{tmp}``. For each row it asserts:

- exit code 2;
- exactly one non-empty line on stderr, which contains the row's ``needle`` (the offending
  value or option, so the user can see what to fix);
- no traceback anywhere, and valid JSON or nothing on stdout;
- nothing written: ``{tmp}`` is still empty, and ``git status`` of the repository is the
  same after the whole table as before it.

The first row of every module runs in a subprocess of its own, as a user runs it. The
other rows of a package run one after another inside one Python process
(tests/data/run_cli_rows.py: runpy with file descriptors 1 and 2 caught), which imports
torch or dolfinx once instead of once per row: 2-3 s of imports against a fraction of a
second of work for most rows (in the full suite the table took 272 s as 149 subprocesses,
49 s this way).

Rows are grouped by package; ``{tmp}`` in an argument is replaced by the row's folder.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from predictor.model.gripper import DEFAULT_OUTLINE

ROOT = Path(__file__).resolve().parents[1]
#: A progress line of predictor.solvers.progress.Heartbeat: "[label N s] text".
HEARTBEAT = re.compile(r"\[[^\]]* \d+ s\] ")
PY = sys.executable
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMP_NUM_THREADS": "1", "PYVISTA_OFF_SCREEN": "true"}

# (module, args, needle): needle must appear in the one stderr line.
CASES_FEM = [
    # fem.cli.solve: loads are finite numbers, checked against the box before any mesh
    ("fem.cli.solve", ["--p", "nan"], "--p: 'nan' is not a finite number"),
    ("fem.cli.solve", ["--p", "inf"], "--p: 'inf' is not a finite number"),
    ("fem.cli.solve", ["--p", "abc"], "--p: 'abc' is not a finite number"),
    ("fem.cli.solve", ["--p", "0.5"], "P = 0.5 is outside the training box"),
    ("fem.cli.solve", ["--p", "0.1", "--p", "0.2"], "--p given twice"),
    ("fem.cli.solve", ["--mesh-size", "nan"], "--mesh-size: 'nan' is not a finite number (allowed [0.3, 10] mm)"),
    ("fem.cli.solve", ["--mesh-size", "inf"], "--mesh-size: 'inf' is not a finite number"),
    ("fem.cli.solve", ["--mesh-size", "0"], "--mesh-size: 0 is outside [0.3, 10] mm"),
    ("fem.cli.solve", ["--divisions", "7"], "--divisions: 7 is outside [1, 6]"),
    ("fem.cli.solve", ["--divisions", "1.5"], "--divisions"),
    ("fem.cli.solve", ["--divisions", "2", "--mesh-size", "2"], "--divisions (hexahedra) excludes --mesh-size"),
    ("fem.cli.solve", ["--hex-size", "2.5"], "--hex-size grades hexahedra: give --divisions too"),
    ("fem.cli.solve", ["--divisions", "2", "--hex-size", "0.1"], "--hex-size: 0.1 is outside [0.3, 10] mm"),
    ("fem.studies.bench_joint", ["--mesh", "hex2:x", "--out", "{tmp}/x.json"], "--mesh"),
    ("workflow.campaign", ["--out", "{tmp}/c", "--samples", "4", "--seed", "1", "--divisions", "2", "--wall-mesh-size", "0.6"],
     "--divisions (hexahedra) excludes"),
    ("fem.studies.mesh_study", ["--meshes", "hex9", "--out", "{tmp}/x.json"], "hexN needs N in [1, 6]"),
    ("fem.studies.mesh_study", ["--meshes", "hex2", "2.4", "--out", "{tmp}/x.json"], "give one kind of mesh"),
    ("fem.cli.solve", ["--bogus"], "unrecognized arguments: --bogus"),
    # fem.cli.finger --object (a grasp): the object spec, the approach, the friction, gravity
    ("fem.cli.finger", ["--object", "bogus"], "unknown object 'bogus' in 'bogus': use circle, ellipse or rectangle"),
    ("fem.cli.finger", ["--object", "circle:r=-3"], "r=-3 in object 'circle:r=-3': sizes must be positive (mm)"),
    ("fem.cli.finger", ["--object", "circle", "--approach", "0.5,0"], "--approach: P1 = 0.5 is outside [-0.3, 0.3] MPa"),
    ("fem.cli.finger", ["--object", "circle", "--approach", "0.1"], "--approach: 1 values for finger 'paper' of 2 joint(s)"),
    ("fem.cli.finger", ["--approach", "0.1,0"], "--approach needs --object"),
    ("fem.cli.finger", ["--object", "circle", "--no-gravity"], "a grasp lifts the object's weight; drop --no-gravity"),
    ("fem.cli.finger", ["--object", "circle", "--mu", "nan"], "--mu: 'nan' is not a finite number (allowed [0, 10])"),
    ("fem.cli.solve", ["--xdmf", "/etc/passwd/u.xdmf"], "cannot create /etc/passwd/u.xdmf"),
    ("fem.studies.self_contact", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("fem.studies.self_contact", ["--loads", "0.1,0,0", "--out", "{tmp}/x.json"], "expected 4 comma-separated"),
    ("fem.studies.self_contact", ["--loads", "0,0,0,0", "0,0,0,120", "--out", "{tmp}/x.json"],
     "M = 120 is outside the training box"),
    ("fem.studies.mesh_study", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("fem.studies.mesh_study", ["--meshes", "2:1", "2:1", "--out", "{tmp}/x.json"], "give each value once"),
    ("fem.studies.mesh_study", ["--meshes", "2:x", "--out", "{tmp}/x.json"], "--meshes"),
    ("fem.studies.mesh_study", ["--loads", "8", "--out", "{tmp}/x.json"], "--loads"),
    ("fem.studies.mesh_study", ["--seed-from", "hex9", "--out", "{tmp}/x.json"], "--seed-from"),
    ("fem.studies.mesh_study", ["--loads", "1", "1", "--out", "{tmp}/x.json"], "give each value once"),
    ("fem.studies.bench_finger", ["--cases", "free_0.1_0.1,nope", "--out", "{tmp}/x.json"], "--cases: 'nope'"),
    ("fem.studies.bench_finger", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("fem.studies.bench_joint", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("fem.studies.bench_joint", ["--walk", "2.5", "--out", "{tmp}/x.json"], "--walk: '2.5' is not an integer"),
    ("fem.studies.bench_joint", ["--mesh", "hex0", "--out", "{tmp}/x.json"], "--mesh: 'hex0': hexN needs N in [1, 6]"),
    ("fem.studies.bench_joint", ["--mesh", "1.8", "--formulation", "plastic", "--out", "{tmp}/x.json"], "--formulation"),
    ("fem.studies.validation", ["table", "--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("fem.studies.validation", ["cantilever", "--alpha", "nan"], "--alpha: 'nan' is not a finite number (allowed [0, 10])"),
    ("fem.studies.validation", ["rollup", "--theta", "7"], "--theta: 7 is outside [0, 6.2832] rad"),
    ("fem.cli.render", ["--out", "{tmp}/x.txt"], "expected a .png file"),
    ("fem.cli.render", ["--out", "/etc/passwd/x.png"], "cannot create /etc/passwd/x.png"),
    ("fem.cli.render", ["--m", "200", "--out", "{tmp}/x.png"], "M = 200 is outside the training box"),
    # fem.cli.finger / fem.studies.finger_cases (issue 14): pressures per joint of the finger file
    ("fem.cli.finger", ["--p1", "0.5"], "--p1: 0.5 is outside [-0.3, 0.3] MPa"),
    ("fem.cli.finger", ["--p1", "nan"], "--p1: 'nan' is not a finite number"),
    ("fem.cli.finger", ["--p3", "0.1"], "--p3 given, but finger 'paper' has 2 joint(s)"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/no_joint.toml"], "a finger needs at least one joint part"),
    ("fem.cli.finger", ["--rigid-mesh-size", "0"], "--rigid-mesh-size: 0 is outside [0.3, 10] mm"),
    ("fem.cli.finger", ["--xdmf", "/etc/passwd/u.xdmf"], "cannot create /etc/passwd/u.xdmf"),
    ("fem.cli.finger", ["--divisions", "7"], "--divisions: 7 is outside [1, 6]"),
    ("fem.cli.finger", ["--divisions", "1.5"], "--divisions: '1.5' is not an integer"),
    ("fem.cli.finger", ["--divisions", "2", "--mesh-size", "2"], "--divisions (hexahedra) excludes --mesh-size"),
    ("fem.cli.finger", ["--divisions", "2", "--wall-mesh-size", "0.6"], "--divisions (hexahedra) excludes"),
    ("fem.studies.finger_cases", ["--divisions", "2", "--mesh-size", "2", "--out", "{tmp}/f"], "--divisions (hexahedra) excludes"),
    ("fem.studies.finger_cases", ["--cases", "nope", "--out", "{tmp}/f"], "unknown case 'nope'"),
    ("fem.studies.finger_cases", ["--part", "3/2", "--out", "{tmp}/f"], "--part '3/2': use K/N with 1 <= K <= N"),
    ("fem.studies.finger_cases", ["--out", "/etc/passwd/f"], "cannot create /etc/passwd/f"),
    # issue 33: negative values in comma lists parse (the form --help shows), so the real
    # check answers; outputs are probed for real (root passes os.access on /proc) and no
    # folder is made above what the user named
    ("fem.studies.self_contact", ["--loads", "-0.1,0,0", "--out", "{tmp}/x.json"], "--loads: '-0.1,0,0': expected 4"),
    ("fem.studies.self_contact", ["--loads", "-0.1,0,0,-120", "--out", "{tmp}/x.json"], "M = -120 is outside the training box"),
    ("fem.cli.finger", ["--pressures", "-0.1,0.5"], "--pressures: 0.5 is outside [-0.3, 0.3] MPa"),
    ("fem.cli.finger", ["--pressures", "-0.1,0.1,0"], "--pressures: 3 values for finger 'paper' of 2 joint(s)"),
    ("fem.cli.finger", ["--p1", "-0.1", "--pressures", "-0.1,0.1"], "give either --p1..--p4 or --pressures"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/five_joints.toml", "--pressures", "0,0,0,-0.1"],
     "--pressures: 4 values for finger 'five' of 5 joint(s)"),
    ("fem.cli.finger", ["--xdmf", "/proc/u.xdmf"], "cannot write /proc/u.xdmf: /proc:"),
    ("fem.cli.finger", ["--xdmf", "{tmp}/none/u.xdmf"], "cannot create {tmp}/none/u.xdmf: folder {tmp}/none does not exist"),
    ("fem.cli.solve", ["--xdmf", "{tmp}/a/b/u.xdmf"], "cannot create {tmp}/a/b/u.xdmf: folder {tmp}/a/b does not exist"),
    ("fem.cli.solve", ["--xdmf", "/proc/u.xdmf", "--json"], "cannot write /proc/u.xdmf"),
    ("fem.studies.finger_cases", ["--out", "{tmp}/a/b"], "cannot create {tmp}/a/b: folder {tmp}/a does not exist"),
    ("fem.studies.finger_cases", ["--out", "/proc/f"], "cannot write /proc/f: /proc:"),
    # issue 33: finger-file values that break meshing, exhaust memory or leave no gesture
    # are refused while parsing; fingers of any joint count solve or are refused up front
    ("fem.cli.finger", ["--finger", "tests/data/fingers/huge_length.toml"],
     "part 2 (rigid): length = 1000000000.0 is outside [1, 500] mm"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/tiny_length.toml"], "part 2 (rigid): length = 1e-09 is outside [1, 500] mm"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/flat.toml"], "part 2 (rigid): height = 1e-09 is outside [1, 100] mm"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/many_contact_points.toml"],
     "part 2 (rigid): contact_points = 100000000 is outside [0, 1000]"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/heavy.toml"], "part 2 (rigid): weight = 1000000000.0 is outside [0, 2] N"),
    ("fem.cli.finger", ["--finger", "tests/data/fingers/too_long.toml"],
     "too_long.toml: the parts add up to 1245.45 mm, at most 1000 mm"),
    ("fem.studies.finger_cases", ["--finger", "tests/data/fingers/three.toml", "--out", "{tmp}/f"],
     "--finger: finger 'three' has 3 joint(s); the validation cases are pressure pairs for a two-joint finger"),
    ("fem.studies.finger_cases", ["--finger", "tests/data/fingers/heavy.toml", "--out", "{tmp}/f"], "weight = 1000000000.0 is outside"),
    # fem.studies.grasp_cases (issue 36 §3): cases, pressures, objects and --out, before any mesh
    ("fem.studies.grasp_cases", ["--cases", "circle_0.2_0.3,nope", "--out", "{tmp}/g"], "unknown case 'nope'"),
    ("fem.studies.grasp_cases", ["--grasps", "circle@0.2,0.35", "--out", "{tmp}/g"],
     "case circle_0.2_0.35: P2 = 0.35 is outside [-0.3, 0.3] MPa"),
    ("fem.studies.grasp_cases", ["--grasps", "circle@0.2,nan", "--out", "{tmp}/g"], "'nan' is not a finite number"),
    ("fem.studies.grasp_cases", ["--grasps", "circle:x=5@0.2,0.3", "--out", "{tmp}/g"], "object centre x = 5 mm"),
    ("fem.studies.grasp_cases", ["--grasps", "circle", "--out", "{tmp}/g"], "'circle': use SPEC@P1,P2"),
    ("fem.studies.grasp_cases", ["--grasps", "ellipse@0.1,0.1;ellipse@0.1,0.1", "--out", "{tmp}/g"],
     "ellipse_0.1_0.1 given twice"),
    ("fem.studies.grasp_cases", ["--part", "2/1", "--out", "{tmp}/g"], "--part '2/1': use K/N with 1 <= K <= N"),
    ("fem.studies.grasp_cases", ["--out", "/proc/g"], "cannot write /proc/g: /proc:"),
    ("fem.studies.grasp_cases", ["--out", "{tmp}/a/b"], "cannot create {tmp}/a/b: folder {tmp}/a does not exist"),
    ("fem.studies.grasp_cases", ["--out", "README.md"], "README.md is a file, not a folder"),
    ("fem.studies.grasp_cases", ["--divisions", "2", "--mesh-size", "4", "--out", "{tmp}/g"], "--divisions (hexahedra) excludes"),
    # --- fem cases (end)
]
CASES_WORKFLOW = [
    # workflow.campaign: every option checked before MPI starts; --out checked, not created
    ("workflow.campaign", ["--samples", "nan", "--seed", "1", "--out", "{tmp}/d"],
     "--samples: 'nan' is not an integer (allowed [1, inf])"),
    ("workflow.campaign", ["--samples", "0", "--seed", "1", "--out", "{tmp}/d"], "--samples: 0 is outside [1, inf]"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--mesh-size", "inf", "--out", "{tmp}/d"],
     "--mesh-size: 'inf' is not a finite number (allowed [0.3, 10] mm)"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--units", "5", "--out", "{tmp}/d"],
     "--units: '5' is not A:B"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--units", "3:2", "--out", "{tmp}/d"],
     "--units: 3:2 is not a unit range A:B with 0 <= A < B"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--units", "0:2", "--out", "{tmp}/d"],
     "--units 0:2 outside 0:1"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--seed", "2", "--out", "{tmp}/d"], "--seed given twice"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--step", "abc", "--out", "{tmp}/d"],
     "--step: 'abc' is not a finite number"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--bogus", "--out", "{tmp}/d"],
     "unrecognized arguments: --bogus"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--out", "/etc/passwd/x"],
     "cannot create /etc/passwd/x: /etc/passwd is not a folder"),
    # issue 33: no folder above the named one; a real write probe (root passes os.access)
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--out", "{tmp}/a/b"],
     "cannot create {tmp}/a/b: folder {tmp}/a does not exist"),
    ("workflow.campaign", ["--samples", "4", "--seed", "1", "--out", "/proc/d"], "cannot write /proc/d: /proc:"),
    # issue 33: a refusal names the option and both values; a campaign never shrinks (the
    # committed held-out set is on the paper-fidelity mesh, `make dataset`'s --mesh-size 1.8
    # --formulation displacement; the production defaults are another config)
    ("workflow.campaign", ["--samples", "256", "--unit-size", "16", "--seed", "2", "--mesh-size", "3",
                           "--formulation", "displacement", "--out", "results/data/heldout_h1.8"],
     "results/data/heldout_h1.8 holds a campaign made with --mesh-size 1.8 mm (this run: 3 mm)"),
    ("workflow.campaign", ["--samples", "256", "--unit-size", "8", "--seed", "2", "--mesh-size", "1.8",
                           "--formulation", "displacement", "--out", "results/data/heldout_h1.8"],
     "made with --unit-size 16 (this run: 8)"),
    ("workflow.campaign", ["--samples", "256", "--unit-size", "16", "--seed", "2", "--out", "results/data/heldout_h1.8"],
     "results/data/heldout_h1.8 holds a campaign made with --formulation displacement (this run: mixed); --divisions "
     "tetrahedra (this run: 2)"),
    ("workflow.campaign", ["--samples", "128", "--unit-size", "16", "--seed", "2", "--mesh-size", "1.8",
                           "--formulation", "displacement", "--out", "results/data/heldout_h1.8"],
     "results/data/heldout_h1.8 holds a campaign of --samples 256; --samples 128 would drop its other shards"),
    # another seed than the committed held-out set's: refused before the lock is taken
    ("workflow.campaign", ["--samples", "256", "--unit-size", "16", "--seed", "3", "--mesh-size", "1.8",
                           "--formulation", "displacement", "--out", "results/data/heldout_h1.8"],
     "results/data/heldout_h1.8 holds a campaign of --seed 2, not --seed 3"),
    # workflow.dataset: a folder that is not a dataset, bad --mirror, merge of a non-dataset
    ("workflow.dataset", ["info", "/etc"], "/etc: no manifest.json (not a softjoint dataset)"),
    ("workflow.dataset", ["verify", "/etc"], "/etc: no manifest.json (not a softjoint dataset)"),
    ("workflow.dataset", ["verify", "--mirror", "-1", "results/data/heldout"], "--mirror: -1 is outside [0, inf]"),
    ("workflow.dataset", ["verify", "--mirror", "nan", "results/data/heldout"], "--mirror: 'nan' is not an integer"),
    ("workflow.dataset", ["merge", "{tmp}/m", "/etc"], "/etc: no manifest.json"),
    ("workflow.dataset", ["merge", "/etc/passwd/m", "results/data/heldout"], "cannot create /etc/passwd/m: /etc/passwd is not a folder"),
    ("workflow.dataset", ["merge", "{tmp}/a/m", "results/data/heldout"], "cannot create {tmp}/a/m: folder {tmp}/a does not exist"),
    ("workflow.dataset", ["info", "results/data/heldout", "--json", "--json"], "--json given twice"),
    # apps.report, workflow.bench_campaign / profile_walk: outputs and numbers checked up front
    ("apps.report", ["--out", "/etc/passwd/x.md"], "cannot create /etc/passwd/x.md"),
    ("apps.report", ["--out", "{tmp}/x.txt"], "expected a .md file"),
    ("apps.report", ["--results", "/nonexistent", "--out", "{tmp}/x.md"], "--results /nonexistent: not a folder"),
    # apps.material_fit: the test file's columns and numbers, the law, the strain range
    ("apps.material_fit", ["--csv", "/nonexistent.csv"], "/nonexistent.csv"),
    ("apps.material_fit", ["--csv", "README.md"], "no header row with columns 'Engineering Strain'"),
    ("apps.material_fit", ["--csv", "results/joints/soft4/dragon_skin_30.csv", "--law", "ogden"], "invalid choice: 'ogden'"),
    ("apps.material_fit", ["--csv", "results/joints/soft4/dragon_skin_30.csv", "--max-strain", "0.05"],
     "1 samples with 0 < strain < 0.05: yeoh needs at least 4"),
    ("apps.material_fit", ["--csv", "results/joints/soft4/dragon_skin_30.csv", "--nu", "nan"], "--nu: 'nan' is not a finite number"),
    ("workflow.bench_campaign", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("workflow.bench_campaign", ["--fresh", "nan", "--out", "{tmp}/x.json"], "--fresh: 'nan' is not an integer"),
    ("workflow.bench_campaign", ["--unit-size", "1", "--out", "{tmp}/x.json"], "--unit-size: 1 is outside [2, inf]"),
    ("workflow.profile_walk", ["--samples", "1"], "--samples: 1 is outside [2, inf]"),
    ("workflow.profile_walk", ["--mesh-size", "nan"], "--mesh-size: 'nan' is not a finite number"),
    # the discretisation options of the tools that took them with the production switch to
    # hexahedra: both kinds at once is one line before any solve or campaign
    ("workflow.profile_walk", ["--mesh-size", "1.8", "--divisions", "2"], "--divisions (hexahedra) excludes --mesh-size"),
    ("workflow.bench_campaign", ["--divisions", "2", "--mesh-size", "1.8", "--out", "{tmp}/x.json"],
     "--divisions (hexahedra) excludes --mesh-size"),
    ("workflow.bench_campaign", ["--formulation", "hybrid", "--out", "{tmp}/x.json"], "invalid choice: 'hybrid'"),
    ("fem.studies.self_contact", ["--hex-size", "3", "--out", "{tmp}/x.json"], "--hex-size grades hexahedra: give --divisions too"),
    ("fem.studies.bench_finger", ["--divisions", "2", "--wall-mesh-size", "0.6", "--out", "{tmp}/x.json"],
     "--divisions (hexahedra) excludes"),
    ("fem.cli.render", ["--formulation", "hybrid", "--out", "{tmp}/x.png"], "invalid choice: 'hybrid'"),
    # --- workflow cases (end)
]
CASES_SURROGATE = [
    # surrogate.predict: finite numbers always; the box unless --allow-extrapolation;
    # checkpoints of the integrity-checked surrogate kind only
    ("surrogate.predict", ["--p", "nan", "--f1", "0", "--f2", "0", "--m", "0"],
     "--p: 'nan' is not a finite number"),
    ("surrogate.predict", ["--p", "nan", "--f1", "0", "--f2", "0", "--m", "0", "--allow-extrapolation"],
     "--p: 'nan' is not a finite number"),
    ("surrogate.predict", ["--p", "0.5", "--f1", "0", "--f2", "0", "--m", "0", "--json"],
     "P = 0.5 is outside the training box"),
    ("surrogate.predict", ["--p", "0", "--f1", "0", "--f2", "0", "--m", "inf"],
     "--m: 'inf' is not a finite number"),
    ("surrogate.predict", ["--p", "0", "--f1", "0", "--f2", "abc", "--m", "0"],
     "--f2: 'abc' is not a finite number"),
    ("surrogate.predict", ["--p", "0", "--f1", "0", "--f2", "0", "--m", "0", "--model", "/etc/hostname"],
     "/etc/hostname: not a softjoint surrogate checkpoint"),
    ("surrogate.predict", ["--p", "0", "--f1", "0", "--f2", "0", "--m", "0", "--model", "{tmp}/missing.pt"],
     "{tmp}/missing.pt: surrogate checkpoint not found"),
    ("surrogate.predict", ["--p", "0", "--p", "0.1", "--f1", "0", "--f2", "0", "--m", "0"], "--p given twice"),
    ("surrogate.evaluate", ["--model", "/etc/hostname", "--data", "results/data/heldout", "--json"],
     "/etc/hostname: not a softjoint surrogate checkpoint"),
    ("surrogate.evaluate", ["--model", "results/surrogate/improved.pt", "--data", "/etc", "--json"],
     "/etc: no manifest.json"),
    ("surrogate.evaluate", ["--report", "--dir", "/etc/passwd/x"], "cannot create /etc/passwd/x"),
    # surrogate.train: output, overrides and data are checked before any training
    ("surrogate.train", ["--config", "paper", "--out", "/etc/passwd/x.pt"], "cannot create /etc/passwd/x.pt"),
    ("surrogate.train", ["--config", "paper", "--out", "{tmp}/x.json"], "expected a .pt file"),
    ("surrogate.train", ["--config", "paper", "--out", "{tmp}/x.pt", "--set", "bogus=1"],
     "--set bogus=1: unknown field 'bogus'"),
    ("surrogate.train", ["--config", "paper", "--out", "{tmp}/x.pt", "--set", "lr=nan"],
     "--set lr=nan: 'nan' is not a finite number"),
    ("surrogate.train", ["--config", "paper", "--out", "{tmp}/x.pt", "--set", "lr=1", "--set", "lr=2"],
     "--set lr given twice"),
    ("surrogate.train", ["--config", "paper", "--out", "{tmp}/x.pt", "--data", "/etc"], "/etc: no manifest.json"),
    ("surrogate.sweep", ["--dir", "/etc/passwd/sweep"], "cannot create /etc/passwd/sweep"),
    ("surrogate.sweep", ["--dir", "{tmp}", "--data", "/etc"], "/etc: no manifest.json"),
    ("surrogate.synthetic", ["--out", "{tmp}/ds", "--n", "0"], "--n: 0 is outside [1, 1e+07]"),
    ("surrogate.synthetic", ["--out", "/etc/passwd/ds"], "cannot create /etc/passwd/ds"),
    ("surrogate.sweep", ["--dir", "{tmp}/a/sweep"], "cannot create {tmp}/a/sweep: folder {tmp}/a does not exist"),
    ("surrogate.sweep", ["--dir", "/proc/sweep"], "cannot write /proc/sweep: /proc:"),
    # --- surrogate cases (end)
]
CASES_PREDICTOR = [
    # predictor.cli.gesture: pressures, approach and object are checked while parsing, the
    # plot's folder before the solve, the models on load
    ("predictor.cli.gesture", ["--p1", "nan", "--p2", "0"], "--p1: 'nan' is not a finite number (allowed [-0.3, 0.3] MPa)"),
    ("predictor.cli.gesture", ["--p1", "0.5", "--p2", "0"], "--p1: 0.5 is outside [-0.3, 0.3] MPa"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "inf"], "--p2: 'inf' is not a finite number"),
    ("predictor.cli.gesture", ["--p1", "abc", "--p2", "0"], "--p1: 'abc' is not a finite number"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--approach", "nan,0", "--json"],
     "--approach: 'nan' is not a finite number"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--approach", "1,2"], "--approach: 1 is outside [-0.3, 0.3] MPa"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle:r=30,r=40"], "'r' given twice"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle:r=nan"], "r=nan in object"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle:r=-5"], "r=-5 in object"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "blob"], "unknown object 'blob'"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--plot", "/etc/passwd/x.png", "--json"],
     "cannot create /etc/passwd/x.png"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--plot", "{tmp}/x.svg"], "expected a .png file"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--model", "/etc/hostname"],
     "/etc/hostname: not a softjoint surrogate checkpoint"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--method", "nn", "--nn", "/etc/hostname", "--plot", "{tmp}/x.png"],
     "/etc/hostname: not a softjoint NN predictor checkpoint"),
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--method", "nn", "--nn", "results/predictor/gravity_nn.pt",
                           "--object", "circle"], "a 'softjoint-gravity-nn/1' file, expected a 'softjoint-contact-nn/1'"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--method", "nn", "--approach", "zero"],
     "--method nn predicts the trained case only"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--method", "nn", "--no-plane"],
     "the gripper with gravity on, its own approach): drop --no-gravity, --approach and --no-plane"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--polish"], "--polish finishes an NN prediction"),
    ("predictor.cli.gesture", ["--p1", "0", "--p1", "0.1", "--p2", "0"], "--p1 given twice"),
    # issue 33: objects the mirrored model cannot represent, refused before any solve
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "circle:x=15,r=20", "--json"],
     "object centre x = 15 mm: the model mirrors the right finger"),
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "circle:x=40,y=-80"], "object centre x = 40 mm"),
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "circle:r=1e9"],
     "outside the model's [0.1, 500] mm half-size range"),
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "ellipse:deg=20"],
     "an ellipse must stay symmetric about X = 0"),
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "circle:y=2000"], "y = 2000 mm is outside"),
    ("predictor.cli.gesture", ["--p1", "0.2", "--p2", "0.2", "--object", "rectangle:w=1000,h=2,y=-195", "--plot",
                           "{tmp}/x.png"], "the object intersects the fingers at the approach gesture"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle", "--mu", "nan"],
     "--mu: 'nan' is not a finite number (allowed (0, 5])"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle", "--object-weight", "-1"],
     "--object-weight: -1 is outside [0, 10] N"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--bogus"], "unrecognized arguments: --bogus"),
    # predictor.validation.finger (issue 14): an empty FEM folder, an unwritable output
    ("predictor.validation.finger", ["--fem", "{tmp}/none", "--out", "{tmp}/x.json", "--figures", "{tmp}/f"],
     "no FEM cases on mesh 1.8 (displacement) in {tmp}/none"),
    ("predictor.validation.finger", ["--mesh", "hex9", "--out", "{tmp}/x.json"], "--mesh: 'hex9': 9 is outside [1, 6]"),
    ("predictor.validation.finger", ["--mesh", "1.8:nan", "--out", "{tmp}/x.json"], "--mesh: '1.8:nan'"),
    ("predictor.validation.finger", ["--mesh", "1.8", "--mesh-size", "2", "--out", "{tmp}/x.json"],
     "not allowed with argument --mesh"),
    ("predictor.validation.finger", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    # predictor.validation.grasps (issue 36 §3): no folder, a file that is not a grasp record,
    # records of another discretisation, unwritable outputs; all before the model is loaded
    ("predictor.validation.grasps", ["--fem", "{tmp}/none", "--out", "{tmp}/x.json", "--figures", "{tmp}/f"],
     "--fem {tmp}/none: no such folder"),
    ("predictor.validation.grasps", ["--fem", "results/validation/finger_fem", "--out", "{tmp}/x.json", "--figures",
                                   "{tmp}/f"], "region: missing (format fem-grasp-case/1, fem.studies.grasp_cases)"),
    ("predictor.validation.grasps", ["--fem", "tests/data/grasps", "--out", "{tmp}/x.json", "--figures", "{tmp}/f"],
     "no FEM grasp records on mesh hex2:3 (mixed) in tests/data/grasps (it holds 4 mixed"),
    ("predictor.validation.grasps", ["--fem", "tests/data/grasps", "--out", "/etc/passwd/x.json"],
     "cannot create /etc/passwd/x.json"),
    ("predictor.validation.grasps", ["--fem", "tests/data/grasps", "--out", "{tmp}/x.json", "--figures", "/proc/g"],
     "cannot write /proc/g: /proc:"),
    ("predictor.validation.grasps", ["--mesh", "hex9", "--out", "{tmp}/x.json"], "--mesh: 'hex9': 9 is outside [1, 6]"),
    # predictor.cli.gesture --finger (issue 14): the finger file is read and checked while
    # parsing (tests/data/fingers/ holds the bad files), the pressures against its joints
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "{tmp}/none.toml"],
     "cannot read finger file {tmp}/none.toml: No such file or directory"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "tests/data/fingers/bad_toml.toml"],
     "tests/data/fingers/bad_toml.toml: not a valid TOML finger file"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "tests/data/fingers/duplicate_key.toml"],
     "tests/data/fingers/duplicate_key.toml: not a valid TOML finger file (Cannot overwrite a value"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "tests/data/fingers/unknown_key.toml", "--json"],
     "part 2 (rigid): unknown key 'colour'"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "tests/data/fingers/negative_length.toml"],
     "part 2 (rigid): length = -60.0 must be > 0.0"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--finger", "tests/data/fingers/no_joint.toml"],
     "a finger needs at least one joint part"),
    ("predictor.cli.gesture", ["--pressures", "0.1,0,0.1"], "--pressures: 3 values for finger 'paper' of 2 joints"),
    ("predictor.cli.gesture", ["--pressures", "0.1,0.5"], "--pressures: 0.5 is outside [-0.3, 0.3] MPa"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--pressures", "0,0"], "give either --p1/--p2 or --pressures"),
    ("predictor.cli.gesture", ["--p1", "0"], "give --p1 and --p2 (MPa), or --pressures P1,P2"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--object", "circle", "--approach", "0,0,0"],
     "--approach: 3 values for finger 'paper' of 2 joints"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--kinematics", "chord"], "invalid choice: 'chord'"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--joint-weight", "half"], "invalid choice: 'half'"),
    ("predictor.cli.gesture", ["--p1", "0", "--p2", "0", "--method", "nn", "--joint-weight", "lumped"],
     f"was trained for finger 'paper', cap kinematics, split joint weights, {DEFAULT_OUTLINE} outline, not finger "
     f"'paper', cap kinematics, lumped joint weights, {DEFAULT_OUTLINE} outline"),
    # issue 57: a finger no gesture can be solved for is refused where the problem is built
    # (predictor.solvers.problem.finger_error), naming the cause, by every tool
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--finger", "tests/data/fingers/heavy_parts.toml", "--json"],
     "finger 'heavy_parts' is too heavy for its joints: hanging at zero pressure under the parts' weights, "
     "joint 1 F1 = 7.00 N, beyond the joint model's box |F1|, |F2| <= 3 N, |M| <= 100 N·mm"),
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--finger", "tests/data/fingers/no_gap.toml",
                           "--plot", "{tmp}/x.png"],
     "finger 'no_gap': base_gap = 0 mm puts the two fingers across each other (the right one crosses X = 0 by "
     "10.0 mm hanging at zero pressure): the fingers meet at X = 0, so base_gap must be at least 20.0 mm"),
    ("predictor.cli.atlas", ["--object", "circle", "--grid", "3", "--finger", "tests/data/fingers/heavy_parts.toml",
                         "--out", "{tmp}/x.json"], "finger 'heavy_parts' is too heavy for its joints"),
    ("predictor.cli.atlas", ["--object", "circle", "--grid", "3", "--finger", "tests/data/fingers/no_gap.toml",
                         "--out", "{tmp}/x.json"], "base_gap must be at least 20.0 mm"),
    # the atlas takes the finger, approach and gravity options of predictor.cli.gesture
    ("predictor.cli.atlas", ["--object", "circle", "--finger", "tests/data/fingers/three.toml", "--out", "{tmp}/x.json"],
     "the grasp atlas spans (P1, P2): finger 'three' has 3 joints"),
    ("predictor.cli.atlas", ["--object", "circle", "--approach", "0.1", "--out", "{tmp}/x.json"],
     "--approach: 1 values for the atlas's two joints"),
    ("predictor.cli.atlas", ["--object", "circle", "--approach", "0.5,0"], "--approach: 0.5 is outside [-0.3, 0.3] MPa"),
    ("predictor.cli.atlas", ["--object", "circle", "--kinematics", "chord"], "invalid choice: 'chord'"),
    ("predictor.validation.finger", ["--cases", "gravity_0.1_-0.1,nope", "--out", "{tmp}/x.json", "--figures", "{tmp}"],
     "--cases: no case nope in results/validation/finger_fem"),
    # the NN predictors answer the problem they were trained for: one object, one finger
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--method", "nn", "--object", "rectangle", "--json"],
     "--method nn: the contact NN (results/predictor/contact_nn.pt) was trained for one object, the circle "
     "r=30 mm at y=-195 mm, not the rectangle w=60, h=50, rc=1 mm at y=-195 mm: use --method newton for it"),
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--method", "nn", "--object", "circle:r=25",
                           "--plot", "{tmp}/x.png"],
     "trained for one object, the circle r=30 mm at y=-195 mm, not the circle r=25 mm at y=-195 mm"),
    ("predictor.cli.gesture", ["--p1", "0.1", "--p2", "0.1", "--method", "nn", "--finger",
                           "tests/data/fingers/long_tip.toml", "--json"],
     f"was trained for finger 'paper', cap kinematics, split joint weights, {DEFAULT_OUTLINE} outline, not finger "
     f"'long_tip', cap kinematics, split joint weights, {DEFAULT_OUTLINE} outline: an NN predictor answers only its "
     "own finger and options"),
    # predictor.cli.nn / bench / figures: outputs and inputs refused before any training or solve
    ("predictor.cli.nn", ["--variant", "contact", "--out", "/etc/passwd/x.pt"], "cannot create /etc/passwd/x.pt"),
    ("predictor.cli.nn", ["--variant", "contact", "--out", "{tmp}/x.pt", "--epochs", "nan"],
     "--epochs: 'nan' is not an integer"),
    ("predictor.cli.nn", ["--variant", "contact", "--out", "{tmp}/x.pt", "--epochs", "0"], "--epochs: 0 is outside [1, inf]"),
    ("predictor.cli.nn", ["--variant", "bogus", "--out", "{tmp}/x.pt"], "invalid choice: 'bogus'"),
    ("predictor.cli.nn", ["--variant", "contact", "--out", "{tmp}/x.pt", "--no-plane"],
     "--no-plane: the contact variant learns a grasp, which the gripper's plane X = 0 is part of"),
    ("predictor.cli.nn", ["--variant", "gravity-paper", "--out", "{tmp}/x.pt", "--plane", "--no-plane"],
     "--plane and --no-plane both given: give one of them"),
    ("predictor.cli.nn", ["--variant", "contact", "--out", "{tmp}/x.pt", "--model", "/etc/hostname"],
     "/etc/hostname: not a softjoint surrogate checkpoint"),
    ("predictor.validation.bench", ["--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("predictor.validation.bench", ["--out", "{tmp}/x.json", "--nn-dir", "/etc"], "/etc/gravity_nn.pt: NN predictor checkpoint not found"),
    ("predictor.validation.bench", ["--out", "{tmp}/x.json", "--nn-dir", "{tmp}/none"], "--nn-dir: {tmp}/none is not a folder"),
    ("predictor.cli.figures", ["--out", "/etc/passwd"], "/etc/passwd is a file, not a folder"),
    ("predictor.cli.figures", ["--out", "/etc/passwd/figs"], "cannot create /etc/passwd/figs"),
    ("predictor.cli.figures", ["--out", "{tmp}", "--model", "/etc/hostname"], "/etc/hostname: not a softjoint surrogate"),
    # predictor.planning.atlas / inverse (issue 16): numbers, box, goal, object and outputs refused
    # while parsing; an object intersecting the fingers where it is brought in, before the grid
    ("predictor.cli.atlas", ["--object", "circle", "--grid", "nan"], "--grid: 'nan' is not an integer"),
    ("predictor.cli.atlas", ["--object", "circle", "--grid", "1"], "--grid: 1 is outside [2, 201]"),
    ("predictor.cli.atlas", ["--object", "circle", "--box", "0.2,0.1,0,0.3"], "expected P1LO < P1HI"),
    ("predictor.cli.atlas", ["--object", "circle", "--box", "0,0.5,0,0.3"], "--box: 0.5 is outside [-0.3, 0.3] MPa"),
    ("predictor.cli.atlas", ["--object", "circle", "--box", "0,inf,0,0.3"], "--box: 'inf' is not a finite number"),
    ("predictor.cli.atlas", ["--object", "blob"], "unknown object 'blob'"),
    ("predictor.cli.atlas", ["--object", "circle", "--path", "zigzag"], "--path: invalid choice: 'zigzag'"),
    ("predictor.cli.atlas", ["--object", "circle", "--ramp-steps", "0"], "--ramp-steps: 0 is outside [1, 1000]"),
    ("predictor.cli.atlas", ["--object", "circle:q=1"], "bad object field 'q=1'"),
    ("predictor.cli.atlas", ["--object", "circle", "--plot", "{tmp}/x.svg"], "expected a .png file"),
    ("predictor.cli.atlas", ["--object", "circle", "--out", "/etc/passwd/x.json"], "cannot create /etc/passwd/x.json"),
    ("predictor.cli.atlas", ["--object", "circle:x=40,y=-80", "--out", "{tmp}/x.json"], "object centre x = 40 mm"),
    ("predictor.cli.atlas", ["--object", "rectangle:w=1000,h=2,y=-195", "--out", "{tmp}/x.json"],
     "the object intersects the fingers at the approach gesture"),
    ("predictor.cli.atlas", ["--object", "circle:x=15,r=20", "--plot", "{tmp}/x.png"], "object centre x = 15 mm"),
    ("predictor.cli.atlas", ["--object", "circle:r=1e9"], "outside the model's [0.1, 500] mm half-size range"),
    ("predictor.cli.atlas", ["--object", "circle", "--mu", "nan"], "--mu: 'nan' is not a finite number"),
    ("predictor.cli.atlas", ["--object", "circle", "--object-weight", "1e9"], "--object-weight: 1e9 is outside [0, 10] N"),
    ("predictor.cli.atlas", ["--object", "circle", "--model", "/etc/hostname"],
     "/etc/hostname: not a softjoint surrogate checkpoint"),
    ("predictor.cli.atlas", ["--grid", "3"], "the following arguments are required: --object"),
    ("predictor.cli.inverse", ["--goal", "grab"], "goal 'grab': use hold or tip:X,Y[,DEG]"),
    ("predictor.cli.inverse", ["--goal", "tip:1"], "goal 'tip:1': use hold or tip:X,Y[,DEG]"),
    ("predictor.cli.inverse", ["--goal", "tip:nan,-200"], "'nan' is not a finite number"),
    ("predictor.cli.inverse", ["--goal", "hold"], "--goal hold needs an --object"),
    ("predictor.cli.inverse", ["--goal", "tip:0,-200", "--least-pressure"], "apply to --goal hold only"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--min-normal", "-1"],
     "--min-normal: -1 is outside [0, 10] N"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle:x=40,y=-80", "--plot", "{tmp}/x.png"],
     "object centre x = 40 mm"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "rectangle:w=1000,h=2,y=-195", "--plot", "{tmp}/x.png"],
     "the object intersects the fingers at the approach gesture"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle:x=15,r=20"], "object centre x = 15 mm"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--min-normal", "nan"],
     "--min-normal: 'nan' is not a finite number"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--mu", "0"], "--mu: 0 is outside (0, 5]"),
    # an object nothing touches: the starts converged, none touches it (not "no converged start");
    # below the fingertips (at Y = -195 mm even r = 1 is pinched where the fingers meet at X = 0);
    # its atlas may print progress lines on a loaded machine (the one-line rule skips them)
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle:r=1,y=-240", "--plot", "{tmp}/x.png", "--json"],
     "nothing touches the object at any pressure of the box"),
    # an atlas records its settings: one computed with gravity is refused for --no-gravity
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--atlas", "results/predictor/atlas_circle.json",
                           "--no-gravity", "--plot", "{tmp}/x.png"],
     "an atlas computed with gravity = True, this question has False (--no-gravity)"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--atlas", "/etc/hostname"],
     "/etc/hostname: not JSON"),
    ("predictor.cli.inverse", ["--goal", "hold", "--object", "circle", "--plot", "/etc/passwd/x.png"],
     "cannot create /etc/passwd/x.png"),
    ("predictor.cli.inverse", ["--goal", "hold", "--goal", "hold", "--object", "circle"], "--goal given twice"),
    # --- predictor cases (end)
]
CASES = CASES_FEM + CASES_WORKFLOW + CASES_SURROGATE + CASES_PREDICTOR


def _git_status() -> str:
    return subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT,
                          capture_output=True, text=True).stdout


def _argv(args: list[str], out: Path) -> list[str]:
    out.mkdir(parents=True)
    return [a.replace("{tmp}", str(out)) for a in args]


def _run(module: str, args: list[str], out: Path) -> dict:
    r = subprocess.run([PY, "-m", module, *_argv(args, out)], cwd=ROOT, env=ENV,
                       capture_output=True, text=True, timeout=300)
    return {"returncode": r.returncode, "stdout": r.stdout, "stderr": r.stderr}


def _run_batch(rows: list, outs: list[Path]) -> list[dict]:
    """Several rows in one process (run_cli_rows.py); their results in order."""
    todo = json.dumps([[m, _argv(a, out)] for (m, a), out in zip(rows, outs)])
    r = subprocess.run([PY, str(ROOT / "tests" / "data" / "run_cli_rows.py")], input=todo,
                       cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Every row run once: each module's first row in a subprocess of its own, the other
    rows of a package in one process per package, two jobs at a time; the repository's git
    status is compared before and after the whole table. (result, folder) per row."""
    root = tmp_path_factory.mktemp("bad-input")
    outs = [root / str(i) for i in range(len(CASES))]
    first, batches = {}, {}
    for i, (module, _, _) in enumerate(CASES):
        if module in first:
            batches.setdefault(module.split(".")[0], []).append(i)
        else:
            first[module] = i
    jobs = sorted([[i] for i in first.values()] + list(batches.values()), key=len, reverse=True)
    results = [None] * len(CASES)

    def do(job):
        rows, folders = [CASES[i][:2] for i in job], [outs[i] for i in job]
        got = _run_batch(rows, folders) if len(job) > 1 else [_run(*rows[0], folders[0])]
        for i, r in zip(job, got):
            results[i] = r

    before = _git_status()
    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(do, jobs))
    assert _git_status() == before, "a bad-input case changed the repository"
    return list(zip(results, outs))


def error_lines(stderr: str) -> list[str]:
    """The non-blank stderr lines that are not progress lines: predictor.solvers.progress's
    heartbeat, ``[label N s] text``, prints one every 10 s of a long run (an atlas on a loaded
    machine), before the run reaches its refusal."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not HEARTBEAT.match(ln)]


def test_error_lines_skip_the_heartbeat_only():
    from predictor.solvers.progress import Heartbeat

    assert error_lines("[atlas 12 s] ring 3 of 30\n[inverse --cases 130 s] case 2\n\nprog: error: x\n") == \
        ["prog: error: x"]
    assert error_lines("[atlas] 12 s\n[x 1.5 s] y\n") == ["[atlas] 12 s", "[x 1.5 s] y"]
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        Heartbeat("atlas", every=0.0)("ring 1")     # the format the rule skips, as printed
    assert buf.getvalue().startswith("[atlas ") and error_lines(buf.getvalue()) == []


@pytest.mark.parametrize("index", range(len(CASES)),
                         ids=[f"{m}:{' '.join(a)}"[:80] for m, a, _ in CASES])
def test_bad_input_exits_2_with_one_line(index, runs):
    (module, args, needle), (r, out) = CASES[index], runs[index]
    stdout, stderr = r["stdout"], r["stderr"]
    lines = error_lines(stderr)
    assert r["returncode"] == 2, f"exit {r['returncode']}; stderr:\n{stderr[-2000:]}"
    assert len(lines) == 1, f"{len(lines)} stderr lines:\n{stderr[-2000:]}"
    assert needle.replace("{tmp}", str(out)) in lines[0], lines[0]
    assert "Traceback" not in stdout + stderr
    assert "NaN" not in stdout and "Infinity" not in stdout
    assert not any(out.iterdir()), f"wrote {sorted(p.name for p in out.rglob('*'))}"


def _help(argv: list[str]):
    return subprocess.run([PY, "-m", *argv, "--help"], cwd=ROOT, env=ENV, capture_output=True,
                          text=True, timeout=120)


def test_every_cli_has_help_and_json():
    """Every ``python -m`` tool of the packages (and the apps) answers --help (exit 0) and offers
    --json (on the tool itself or on each of its subcommands)."""
    tools = sorted({".".join(p.relative_to(ROOT).with_suffix("").parts)
                    for package in ("fem", "workflow", "surrogate", "predictor", "apps")
                    for p in (ROOT / package).rglob("*.py")
                    if not p.stem.startswith("__") and "def main(" in p.read_text()} | {"apps.report"})
    assert len(tools) >= 15, tools
    with ThreadPoolExecutor(max_workers=2) as pool:
        helps = dict(zip(tools, pool.map(lambda t: _help([t]), tools)))
    for tool, r in helps.items():
        assert r.returncode == 0, f"{tool} --help: exit {r.returncode}\n{r.stderr[-1000:]}"
        if "--json" in r.stdout:
            continue
        # a tool with subcommands ({a,b,c} in its usage): each of them has the flag
        subs = [s.strip() for s in r.stdout.split("{", 1)[1].split("}", 1)[0].split(",")] if "{" in r.stdout else []
        assert subs, f"{tool}: no --json and no subcommands"
        for sub in subs:
            rs = _help([tool, sub])
            assert rs.returncode == 0 and "--json" in rs.stdout, f"{tool} {sub}: no --json"


@pytest.mark.parametrize("alias,module", [("fem.finger", "fem.cli.finger"), ("fem.solve", "fem.cli.solve")])
def test_the_old_command_paths_run_the_moved_commands(alias, module):
    """``python -m fem.finger`` and ``fem.solve`` (issue 61's aliases) run fem.cli's commands
    and say where they moved: --help is the new command's, and bad input exits 2 with its
    one error line after the note."""
    r = _help([alias])
    assert r.returncode == 0 and f"python -m {module}" in r.stdout, r.stdout[:500]
    assert r.stderr.strip() == f"note: {alias} moved to {module} (python -m {module})"
    bad = subprocess.run([PY, "-m", alias, "--mesh-size", "0"], cwd=ROOT, env=ENV, capture_output=True,
                         text=True, timeout=300)
    lines = [ln for ln in bad.stderr.splitlines() if ln.strip()]
    assert bad.returncode == 2 and len(lines) == 2, bad.stderr[-2000:]
    assert lines[0].startswith(f"note: {alias} moved") and "--mesh-size: 0 is outside [0.3, 10] mm" in lines[1]


#: predictor's old command paths (issue 61, README changes) and where the commands moved.
PREDICTOR_ALIASES = {"predictor.gesture": "predictor.cli.gesture", "predictor.atlas": "predictor.cli.atlas",
                     "predictor.inverse": "predictor.cli.inverse", "predictor.calibrate": "predictor.cli.calibrate",
                     "predictor.figures": "predictor.cli.figures", "predictor.nn": "predictor.cli.nn",
                     "predictor.validate_finger": "predictor.validation.finger",
                     "predictor.validate_grasps": "predictor.validation.grasps",
                     "predictor.bench": "predictor.validation.bench",
                     "predictor.contact_change": "predictor.validation.contact_change"}


@pytest.mark.parametrize("alias,module", sorted(PREDICTOR_ALIASES.items()))
def test_the_old_predictor_command_paths_run_the_moved_commands(alias, module):
    """Every old ``python -m predictor.<tool>`` runs the moved command: its --help (the
    parser names the new path), after one note on stderr saying where it went."""
    r = _help([alias])
    assert r.returncode == 0 and f"python -m {module}" in r.stdout, r.stdout[:500] + r.stderr[-1000:]
    name = "the command predictor.nn" if alias == "predictor.nn" else alias
    assert r.stderr.strip() == f"note: {name} moved to {module} (python -m {module})", r.stderr


def test_an_old_predictor_command_path_refuses_bad_input_as_the_new_one():
    bad = subprocess.run([PY, "-m", "predictor.gesture", "--p1", "0.5", "--p2", "0"], cwd=ROOT, env=ENV,
                         capture_output=True, text=True, timeout=300)
    lines = error_lines(bad.stderr)
    assert bad.returncode == 2 and len(lines) == 2, bad.stderr[-2000:]
    assert lines[0].startswith("note: predictor.gesture moved") and "--p1: 0.5 is outside [-0.3, 0.3] MPa" in lines[1]


#: library modules whose names invite ``python -m`` (a command's name, an old command path, the
#: library of a command) and the command that does their work (contract.cli.not_a_command).
LIBRARY_COMMANDS = {
    "predictor.planning.atlas": "predictor.cli.atlas", "predictor.planning.inversion": "predictor.cli.inverse",
    "predictor.planning.track": "predictor.cli.inverse --track FILE",
    "predictor.calibration.model": "predictor.cli.calibrate", "predictor.calibration.fit": "predictor.cli.calibrate",
    "predictor.calibration.bench": "predictor.cli.calibrate bench",
    "predictor.calibration.fem": "predictor.cli.calibrate fem",
    "predictor.calibration.recovery": "predictor.cli.calibrate recovery",
    "predictor.nn.train": "predictor.cli.nn", "predictor.solvers.solve": "predictor.cli.gesture",
    "fem.solvers.joint": "fem.cli.solve", "fem.solvers.finger": "fem.cli.finger",
    "fem.solvers.grasp": "fem.cli.finger --object SPEC",
    "fem.studies.joint_cases": "fem.studies.mesh_study", "fem.studies.elastica": "fem.studies.validation",
    "fem.studies.finger_records": "fem.studies.finger_cases", "fem.cli.xdmf": "fem.cli.solve --xdmf OUT.xdmf",
}
NOT_A_COMMAND = re.compile(r'\n    not_a_command\("([^"]+)"\)\n')


def test_library_modules_name_the_command_that_does_their_work():
    """Every library module with the refusal (contract.cli.not_a_command under its __main__
    guard) is one of LIBRARY_COMMANDS and names its command, whose module is a command line
    (a ``main``, run by its own guard), and the module itself has no command line."""
    guarded = {}
    for p in sorted((ROOT / "fem").rglob("*.py")) + sorted((ROOT / "predictor").rglob("*.py")):
        text = p.read_text()
        m = NOT_A_COMMAND.search(text)
        if m:
            assert "def main(" not in text, p
            guarded[".".join(p.relative_to(ROOT).with_suffix("").parts)] = m.group(1)
    assert guarded == LIBRARY_COMMANDS
    for command in set(guarded.values()):
        text = (ROOT / (command.split()[0].replace(".", "/") + ".py")).read_text()
        assert "def main(" in text and 'if __name__ == "__main__":' in text, command


@pytest.mark.parametrize("module", ["predictor.planning.atlas", "predictor.calibration.bench", "fem.solvers.grasp"])
def test_a_library_module_run_as_a_command_refuses_in_one_line(module):
    """``python -m predictor.planning.atlas`` (the library; the command is predictor.cli.atlas)
    exits 2 with one line naming the command, instead of exiting 0 having done nothing."""
    r = subprocess.run([PY, "-m", module, "--help"], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stdout == "", r.stdout + r.stderr[-2000:]
    assert error_lines(r.stderr) == [f"python -m {module}: a library, not a command; "
                                     f"the command is python -m {LIBRARY_COMMANDS[module]}"]
