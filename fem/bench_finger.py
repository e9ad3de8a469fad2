"""Whole-finger FEM timings at the production joint mesh -> results/bench/finger.json.

    python -m fem.bench_finger --out results/bench/finger.json [--cases free_0.1_0.1,...]

Solves a few of fem.finger_cases.CASES from the unloaded state on one rank, one after the
other on one mesh (the paper's finger, joint mesh 1.8 mm): per gesture the wall and CPU
time and the load average, the mesh build and form compilation apart (``setup_s``).
Run it on an otherwise idle machine: the issue's target is <= 10 min per gesture on one
core (the paper's ANSYS: 20-30 min). Each answer is checked against the committed
validation result of the same case (results/validation/finger_fem/<case>.json) to 1e-4
mm (the Newton tolerance's scale; the load path may differ), so the figure times the computation the validation used.
"""
from __future__ import annotations

import json
import logging
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from fem.artefacts import BENCH_FINGER
from fem.finger import FingerLoad, FingerSolver
from fem.finger_cases import CASES
from contract.finger import load_finger
from fem.geometry import FingerGeometry
from fem.options import one_rank

#: the paper's gravity case, a free case and one in the grasp region
#: a free case, the paper's gravity case, the grasp region, and the slowest validated case
DEFAULT_CASES = ("free_0.1_0.1", "gravity_-0.1_0.1", "gravity_0.2_0.2", "gravity_-0.25_0.2")
TARGET_S = 600.0
PAPER_S = (20 * 60, 30 * 60)


def run(names, committed: Path) -> dict:
    cases = {c[0]: c for c in CASES}
    t0 = time.perf_counter()
    solver = FingerSolver(FingerGeometry(load_finger()), MPI.COMM_SELF)
    setup = time.perf_counter() - t0
    rows = []
    for name in names:
        _, p1, p2, gravity = cases[name]
        load_before = os.getloadavg()[0]
        r = solver.solve(FingerLoad((p1, p2), gravity))
        if not r.converged:
            raise RuntimeError(f"{name} did not converge ({r.reason})")
        row = {"case": name, "wall_time_s": r.wall_time, "cpu_time_s": r.cpu_time,
               "load_average_before": load_before, "load_average_after": os.getloadavg()[0],
               "newton_iterations": r.newton_iterations, "factorisations": r.factorisations,
               "tip": r.tip.tolist()}
        ref = committed / f"{name}.json"
        if ref.is_file():
            row["tip_vs_committed_mm"] = float(np.linalg.norm(r.tip - np.array(json.loads(ref.read_text())["tip"])))
            if row["tip_vs_committed_mm"] > 1e-4:
                raise RuntimeError(f"{name}: tip differs from {ref} by {row['tip_vs_committed_mm']:.2e} mm")
        rows.append(row)
    median = statistics.median(r["wall_time_s"] for r in rows)
    return {**solver.mesh_info(), "setup_s": setup, "cases": rows,
            "finger_fem_median_s": median, "finger_fem_max_s": max(r["wall_time_s"] for r in rows),
            "target_s": TARGET_S, "met": max(r["wall_time_s"] for r in rows) <= TARGET_S,
            "paper_s": list(PAPER_S), "speedup_vs_paper": PAPER_S[0] / median, "ranks": 1}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.bench_finger", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/bench/finger.json",
                  help="result file (default results/bench/finger.json)")
    ap.add_argument("--cases", default=",".join(DEFAULT_CASES),
                    help=f"comma-separated fem.finger_cases names (default {','.join(DEFAULT_CASES)})")
    ap.add_argument("--committed", default="results/validation/finger_fem",
                    help="folder of the validation results to check the answers against")
    one_rank(ap, MPI.COMM_WORLD)
    args = ap.parse_args(argv)
    names = args.cases.split(",")
    known = {c[0] for c in CASES}
    for name in names:
        if name not in known or names.count(name) > 1:
            ap.error(f"--cases: {name!r} is unknown or repeated (see fem.finger_cases)")
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    with ap.errors():
        out = run(names, Path(args.committed))
        BENCH_FINGER.write(args.out, out)
    line = {"finger_fem_median_s": out["finger_fem_median_s"], "finger_fem_max_s": out["finger_fem_max_s"],
            "met": out["met"], "nodes": out["nodes"]}
    if args.json:
        cli.print_json({**line, "out": args.out})
    else:
        print(", ".join(f"{k} {v}" for k, v in line.items()) + f" -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
