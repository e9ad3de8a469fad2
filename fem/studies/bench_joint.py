"""Solver timings of one joint: the production discretisation, and the paper's for
comparison -> results/bench/fem.json.

    python -m fem.studies.bench_joint --out results/bench/fem.json [--json]
    python -m fem.studies.bench_joint --mesh hex2 --formulation mixed --out build/bench_hex2.json

(The accuracy checks are ``fem.studies.validation``; the campaign's throughput is
``workflow.bench_campaign``.)

Measures on one rank (the machine is noisy: medians of several solves in one run), for a
discretisation (fem.mesh.discretisation: mesh H or H:W mm, formulation):

* ``solve_from_zero_s``: median wall time of full solves from u = 0 for three mid-box
  load cases, with their Newton iterations (``newton_iterations``: median total);
* ``continuation_sample_s``: median wall time of the next sample when the solve starts
  from a neighbouring converged state (steps of ``--step`` x the box half-width along a
  random walk, as the campaign harvests samples), with the sensitivities included;
  ``continuation_sample_cpu_s`` the same samples' median CPU time of this process (one
  thread: OMP_NUM_THREADS=1), which other jobs on the machine inflate less;
* mesh figures: ``nodes`` (P2, incl. mid-side nodes), ``dofs``, vertices, element size.

The unsuffixed keys are PRODUCTION's (what new data is generated on; ``formulation``,
``mesh``), or a candidate's given by ``--mesh`` / ``--formulation`` (a discretisation the
mesh study weighs before it becomes PRODUCTION); the same figures of PAPER (the committed datasets' 1.8 mm P2 displacement)
carry its mesh as suffix (``continuation_sample_s_1.8``, ``solve_from_zero_s_1.8``,
``nodes_1.8``), and ``ratio_continuation_vs_1.8`` = production / paper continuation time.
When the two are one discretisation it is timed once (ratio 1).

The paper's ANSYS figure is ~7 min per sample at 16,000 nodes (docs/decisions.md §0). ``--json``
prints the headline figures (SUMMARY_KEYS) that the text line shows.
"""

from __future__ import annotations

import logging
import statistics
import sys
import time

import numpy as np
from mpi4py import MPI

from contract import cli
from fem.artefacts import BENCH_JOINT
from fem.mesh.discretisation import FORMULATIONS, PAPER, PRODUCTION, Discretisation, discretisation
from fem.options import mesh_text, one_rank
from fem.solvers.joint import JointSolver, Load
from contract.spec import INPUT_BOX

FROM_ZERO = [Load(0.2, 1.0, -1.0, 20.0), Load(-0.15, -1.0, 1.5, -40.0), Load(0.1, 2.0, 2.0, 60.0)]
PAPER_SECONDS_PER_SAMPLE = 7 * 60
SUMMARY_KEYS = ("mesh", "formulation", "nodes", "dofs", "solve_from_zero_s", "continuation_sample_s",
                "newton_iterations", f"continuation_sample_s_{PAPER.mesh}",
                f"ratio_continuation_vs_{PAPER.mesh}")


def time_discretisation(disc: Discretisation, n_walk: int = 6, step: float = 0.1,
                        seed: int = 0) -> dict:
    """Timings (s) and mesh figures of the joint in discretisation ``disc`` on one rank
    (module docstring): FROM_ZERO solved from zero, then ``n_walk`` continuation samples
    of a random walk of ``step`` x the box from the last of them."""
    geo = disc.geometry()
    t0 = time.perf_counter()
    solver = JointSolver(geo, MPI.COMM_SELF, config=disc.config(), formulation=disc.formulation)
    setup = time.perf_counter() - t0
    zero = [solver.solve(load) for load in FROM_ZERO]
    if not all(r.converged for r in zero):
        raise RuntimeError(f"a from-zero benchmark solve did not converge ({disc.key})")
    rng = np.random.default_rng(seed)
    x = FROM_ZERO[-1].as_array()
    walk = []
    for _ in range(n_walk):
        x = np.clip(x + step * INPUT_BOX * rng.uniform(-1, 1, 4), -INPUT_BOX, INPUT_BOX)
        t, cpu = time.perf_counter(), time.process_time()
        r = solver.solve(Load.from_array(x), continuation=True)
        solver.sensitivities()
        if not r.converged:
            raise RuntimeError(f"a continuation benchmark solve did not converge ({disc.key})")
        walk.append((time.perf_counter() - t, r.iterations, r.factorisations, time.process_time() - cpu))
    return {
        **solver.mesh_info(), "formulation": disc.formulation, "mesh": disc.mesh,
        "wall_mesh_size_mm": None if geo.divisions else geo.wall_mesh_size or geo.mesh_size, "wall_thickness_mm": geo.wall,
        "setup_s": setup,
        "solve_from_zero_s": statistics.median(r.wall_time for r in zero),
        "solve_from_zero_cases": [{"load": r.load.as_array().tolist(), "wall_time_s": r.wall_time,
                                   "newton_iterations": r.newton_iterations,
                                   "factorisations": r.factorisations} for r in zero],
        "newton_iterations": statistics.median(r.iterations for r in zero),
        "continuation_sample_s": statistics.median(t for t, _, _, _ in walk),
        "continuation_sample_cpu_s": statistics.median(c for _, _, _, c in walk),
        "continuation_newton_iterations": statistics.median(n for _, n, _, _ in walk),
        "continuation_factorisations": statistics.median(f for _, _, f, _ in walk),
        "continuation_step_fraction_of_box": step,
    }


def run(n_walk: int = 6, step: float = 0.1, seed: int = 0,
        production: Discretisation = PRODUCTION, paper: Discretisation = PAPER) -> dict:
    """The bench document: ``production``'s figures, ``paper``'s under keys suffixed with
    its mesh, their continuation-time ratio and the speed-ups over the paper's ANSYS."""
    prod = time_discretisation(production, n_walk, step, seed)
    ref = prod if paper == production else time_discretisation(paper, n_walk, step, seed)
    tag = f"_{paper.mesh}"
    return {
        **prod,
        f"solve_from_zero_s{tag}": ref["solve_from_zero_s"],
        f"continuation_sample_s{tag}": ref["continuation_sample_s"],
        f"continuation_sample_cpu_s{tag}": ref["continuation_sample_cpu_s"],
        f"nodes{tag}": ref["nodes"], f"formulation{tag}": paper.formulation,
        f"ratio_continuation_vs{tag}": prod["continuation_sample_s"] / ref["continuation_sample_s"],
        "paper_seconds_per_sample": PAPER_SECONDS_PER_SAMPLE, "paper_nodes": 16000,
        "speedup_vs_paper_from_zero": PAPER_SECONDS_PER_SAMPLE / prod["solve_from_zero_s"],
        "speedup_vs_paper_continuation": PAPER_SECONDS_PER_SAMPLE / prod["continuation_sample_s"],
        "ranks": 1,
    }


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.bench_joint", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/bench/fem.json",
                  help="result file (default results/bench/fem.json)")
    ap.add_argument("--walk", type=cli.number(1, 100, integer=True), default=6,
                    help="continuation samples to time, in [1, 100] (default 6)")
    ap.add_argument("--step", type=cli.number(0, 1, open_lo=True), default=0.1,
                    help="walk step, fraction of the box in (0, 1] (default 0.1)")
    ap.add_argument("--mesh", type=mesh_text, default=PRODUCTION.mesh, metavar="MESH",
                    help=f"the discretisation timed: tetrahedra H[:W] (mm) or hexahedra hexN "
                    f"(default {PRODUCTION.mesh}, the production mesh)")
    ap.add_argument("--formulation", choices=FORMULATIONS, default=PRODUCTION.formulation,
                    help=f"its formulation (default {PRODUCTION.formulation}, the production one)")
    one_rank(ap, MPI.COMM_WORLD)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    out = run(args.walk, args.step, production=discretisation(args.mesh, formulation=args.formulation))
    with ap.errors():
        BENCH_JOINT.write(args.out, out)
    summary = {k: out[k] for k in SUMMARY_KEYS}
    if args.json:
        cli.print_json({**summary, "out": args.out})
    else:
        print(", ".join(f"{k} {v:g}" if isinstance(v, (int, float)) else f"{k} {v}"
                        for k, v in summary.items()) + f" -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
