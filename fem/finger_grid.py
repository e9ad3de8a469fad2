"""The whole-finger FEM over the pressure box: an N x N grid of gravity gestures (issue 36 §1).

    python -m fem.finger_grid --out results/fem/finger_grid.json [--points 7]
                              [--mesh-size H | --divisions N] [--formulation mixed]

Every pair (P1, P2) of the grid p_i = -P_max + 2 P_max i / (N - 1), i = 0 .. N-1, over each
joint's box [-P_max, P_max] MPa (the paper's finger: [-0.3, 0.3]^2, 7 x 7 = 49 pairs), with
gravity, is one ``FingerSolver.solve`` from the unloaded state (fem.finger: load path,
cut-back, Newton) on one mesh built once. The JSON (format
fem.artefacts.FINGER_GRID) holds the run's settings (finger file digest, geometry, formulation,
solver controls), the mesh, and a list ``cases``, each with ``p1``, ``p2`` (MPa), ``converged``,
``wall_s`` and ``cpu_s`` (s, this process; one core's share under load), the Newton figures
(``newton_iterations`` in total and ``newton_per_step``, ``load_steps``, ``cutbacks``,
``factorisations``), the fingertip (``tip`` mm, ``tip_angle_deg``; null unless converged),
``reason`` (why it stopped, if it did) and the load average at its start. The file is
rewritten (atomically) after every case and a run resumes from it: a case of the same
settings that converged stands, a failed one is solved again once the solver's controls
change; other settings start the grid afresh. ``complete`` says whether all N² pairs are in.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.files import json_safe
from contract.finger import FingerSpec, finger_arg, load_finger
from fem.artefacts import FINGER_GRID
from fem.finger import (FINGER_CONFIG, FingerLoad, FingerSolver, add_finger_mesh, finger_discretisation,
                        pressure_limits, same_settings)
from fem.geometry import FingerGeometry
from fem.options import one_rank
from fem.solver import config_for


def grid_pairs(limits: np.ndarray, points: int) -> list[tuple[float, float]]:
    """The (P1, P2) pairs (MPa) of the points x points grid over [-l1, l1] x [-l2, l2],
    P1 varying fastest; values rounded to 1e-12 so that 0 is 0."""
    axes = [np.round(np.linspace(-limit, limit, points), 12) + 0.0 for limit in limits]
    return [(float(p1), float(p2)) for p2 in axes[1] for p1 in axes[0]]


def solver_settings(geometry: FingerGeometry) -> dict:
    """The controls FingerSolver solves with (fem.finger.FINGER_CONFIG on this mesh), as recorded."""
    return json_safe(asdict(config_for(geometry, FINGER_CONFIG)))


def case_record(p1: float, p2: float, result) -> dict:
    """One grid case from a FingerResult (fem.finger)."""
    return {"p1": p1, "p2": p2, "converged": bool(result.converged), "wall_s": result.wall_time,
            "cpu_s": result.cpu_time, "newton_iterations": int(sum(result.newton_iterations)),
            "newton_per_step": list(result.newton_iterations), "load_steps": result.load_steps,
            "cutbacks": result.cutbacks, "factorisations": result.factorisations,
            "tip": result.tip.tolist() if result.converged else None,
            "tip_angle_deg": math.degrees(result.tip_angle) if result.converged else None,
            "reason": result.reason, "load_average": os.getloadavg()[0]}


def kept_cases(path: Path, settings: dict, solver: dict, finger: FingerSpec) -> dict:
    """{(p1, p2): case} of an earlier run of the same settings (the same finger by its
    values, fem.finger.same_settings) that stand (module docstring)."""
    if not path.is_file():
        return {}
    try:
        done = json.loads(path.read_text())
    except ValueError:
        return {}           # a damaged file: the grid starts afresh
    if not same_settings(done.get("settings"), settings, finger):
        return {}
    same_solver = done.get("solver") == solver
    return {(c["p1"], c["p2"]): c for c in done.get("cases", []) if c.get("converged") or same_solver}


def summary(cases: list[dict], n_pairs: int) -> dict:
    """The grid's headline figures: converged count, slowest and median solve (s)."""
    walls = [c["wall_s"] for c in cases]
    return {"pairs": n_pairs, "solved": len(cases), "converged": sum(c["converged"] for c in cases),
            "complete": len(cases) == n_pairs,
            "max_wall_s": max(walls) if walls else None,
            "median_wall_s": float(np.median(walls)) if walls else None}


def build_parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m fem.finger_grid", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/fem/finger_grid.json",
                  help="the grid's JSON (default results/fem/finger_grid.json); resumed if present")
    ap.add_argument("--points", type=cli.number(2, 21, integer=True), default=7,
                    help="grid points per pressure axis (default 7: 49 pairs)")
    ap.add_argument("--finger", type=finger_arg, default=None, help="finger file (default: the paper's)")
    add_finger_mesh(ap)
    cli.add_quiet(ap)
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    comm = MPI.COMM_WORLD
    one_rank(ap, comm)
    args = ap.parse_args(argv)
    finger = args.finger or load_finger()
    if finger.n_joints != 2:
        ap.error(f"--finger: finger {finger.name!r} has {finger.n_joints} joint(s); the grid is over "
                 "pressure pairs of a two-joint finger")
    cli.setup_logging(args.quiet)
    geometry, formulation = finger_discretisation(ap, args, finger)
    settings = json_safe({"finger_sha256": finger.digest, "geometry": geometry.as_dict(),
                          "formulation": formulation, "points": args.points, "gravity": True})
    solver = solver_settings(geometry)
    pairs = grid_pairs(pressure_limits(finger), args.points)
    out = Path(args.out)
    kept = kept_cases(out, settings, solver, finger)
    todo = [p for p in pairs if p not in kept]
    doc = {"finger": finger.summary(), "settings": settings, "solver": solver, "cases": []}
    if not todo:
        print(f"{ap.prog}: all {len(pairs)} pairs are up to date in {out}")
        return 0
    with ap.errors(), cli.heartbeat("finger grid"):
        t0 = time.perf_counter()
        fem_solver = FingerSolver(geometry, comm, formulation=formulation)
        doc.update(setup_s=time.perf_counter() - t0, mesh=fem_solver.mesh_info())
        for p1, p2 in todo:
            res = fem_solver.solve(FingerLoad((p1, p2), True))
            kept[(p1, p2)] = case_record(p1, p2, res)
            doc["cases"] = [kept[p] for p in pairs if p in kept]
            doc.update(summary(doc["cases"], len(pairs)))
            cli.make_output_folder(out.parent)
            FINGER_GRID.write(out, doc)
            print(f"({p1:g}, {p2:g}) MPa: " + ("converged" if res.converged else f"did not converge ({res.reason})")
                  + f", {res.wall_time:.0f} s, Newton {sum(res.newton_iterations)} in {res.load_steps} steps, "
                  f"{res.cutbacks} cut-backs", flush=True)
    print(f"{ap.prog}: {doc['converged']} of {doc['solved']} solved pairs converged "
          f"({len(pairs)} in the grid) -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
