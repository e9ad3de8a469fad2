"""Mesh convergence of the joint at four corners of the input box, with Richardson
extrapolation.

    python -m fem.mesh_study --out results/fem/mesh_study.json \\
        [--meshes 1.8 3.394:1.697 2.4:1.2 1.697:0.849 1.2:0.6] [--work build/mesh_study]

A mesh is ``H`` or ``H:W``: tetrahedron size H mm, and W mm on the chamber walls
(JointGeometry.wall_mesh_size; the wall is 1.2 mm thick, so W = 0.6 puts two P2 elements
through it). For every mesh and corner load the anchors r_1..r_10, phi_end and the distal
cap's rotation are solved from zero; each (mesh, corner) result is its own JSON file in
``--work`` (written atomically, rank 0), so a killed study resumes where it stopped.

Richardson extrapolation (Roache's grid convergence index) on the last three meshes that
are refined by one constant ratio r (sizes h1 > h2 > h3, both H and W scaled):
for a scalar or vector result f,

    p     = ln(|f2 - f1| / |f3 - f2|) / ln r        observed order of convergence
    f_ext = f3 + (f3 - f2) / (r^p - 1)              extrapolated (h -> 0) value

computed per corner for the anchors (a vector: one order from the norms), phi_end and the
cap rotation. The family is in the asymptotic range when, for every corner and result, the
changes shrink (|f3 - f2| < |f2 - f1|) and p lies in [0.5, 4] (P2 elements: p = 2 for
smooth fields; contact and the curved walls lower it); otherwise the study says so and the
finest mesh is the reference (the error of a coarser mesh is then bounded below only).
Every mesh's error against the reference is reported: the largest anchor distance (mm and
percent of the largest anchor displacement), and the phi_end and cap-rotation differences
(deg).

The production mesh is the one the datasets were generated on (JointGeometry's default
mesh_size); the study reports its error, it does not choose it.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.files import json_safe, write_json
from fem.artefacts import MESH_STUDY
from fem.geometry import JointGeometry, anchor_points
from fem.options import MESH_SIZE, MESH_SIZE_TEXT, on_root
from fem.solver import JointSolver, Load

log = logging.getLogger("softjoint.fem")

#: Four corners of the box with P > 0, none the y-mirror of another (the mirror flips P):
#: (P MPa, F1 N, F2 N, M N·mm). F2 and M bend with or against the pressure.
CORNERS = [Load(0.3, 3, -3, -100), Load(0.3, -3, 3, 100), Load(0.3, 3, 3, -100),
           Load(0.3, -3, -3, 100)]
#: production mesh, then a family refined by sqrt(2) in H and W, the last with W = wall / 2
DEFAULT_MESHES = [(1.8, None), (3.394, 1.697), (2.4, 1.2), (1.697, 0.849), (1.2, 0.6)]
ORDER_RANGE = (0.5, 4.0)
#: the production mesh's targets, recorded in the JSON for the report: largest anchor error
#: against the reference (percent of the largest anchor displacement; the paper accepted
#: 3 %), and at least the paper's resolution (16,000 nodes)
TOLERANCE_PERCENT = 2.0
MIN_NODES = 16000


# ---------------------------------------------------------------- pure post-processing
def richardson(f1, f2, f3, r: float) -> dict:
    """Richardson extrapolation of a result f (scalar or array) on three meshes refined by
    the constant ratio r > 1 (f1 coarsest). Returns {"order", "extrapolated",
    "asymptotic"}; order is None (and extrapolated the finest value f3) when the changes do
    not shrink or the observed order falls outside ORDER_RANGE."""
    f1, f2, f3 = (np.asarray(f, dtype=float) for f in (f1, f2, f3))
    e21, e32 = float(np.linalg.norm(f2 - f1)), float(np.linalg.norm(f3 - f2))
    if e32 == 0.0:
        return {"order": None, "extrapolated": f3.tolist(), "asymptotic": e21 == 0.0}
    p = math.log(e21 / e32) / math.log(r) if e21 > 0 else -math.inf
    if not ORDER_RANGE[0] <= p <= ORDER_RANGE[1]:
        return {"order": p if math.isfinite(p) else None, "extrapolated": f3.tolist(), "asymptotic": False}
    return {"order": p, "extrapolated": (f3 + (f3 - f2) / (r ** p - 1.0)).tolist(), "asymptotic": True}


def mesh_errors(case: dict, ref: dict, X: np.ndarray) -> dict:
    """Error of one mesh's result ``case`` against the reference ``ref`` (both with
    anchors (10, 2) mm, phi_end_deg, cap_rotation_deg); X (10, 2) the rest anchors."""
    a, b = np.asarray(case["anchors"]), np.asarray(ref["anchors"])
    scale = float(np.linalg.norm(b - X, axis=1).max())
    d = float(np.linalg.norm(a - b, axis=1).max())
    return {"anchor_mm": d, "anchor_percent": 100.0 * d / scale,
            "tip_mm": float(np.linalg.norm(a[-1] - b[-1])),
            "phi_end_deg": abs(case["phi_end_deg"] - ref["phi_end_deg"]),
            "cap_rotation_deg": abs(case["cap_rotation_deg"] - ref["cap_rotation_deg"])}


def family(meshes: list[dict]) -> list[int] | None:
    """Indices of the finest three meshes (coarse to fine) refined by one ratio (H and W
    alike, within 1 %), or None. Other meshes (the production one) may lie between them."""
    def size(m):
        return np.array([m["mesh_size"], m["wall_mesh_size"] or m["mesh_size"]])

    order = sorted(range(len(meshes)), key=lambda i: -size(meshes[i]).prod())
    found = []
    for i, j, l in itertools.combinations(order, 3):
        r1, r2 = size(meshes[i]) / size(meshes[j]), size(meshes[j]) / size(meshes[l])
        if np.allclose(r1, r1[0], rtol=1e-2) and np.allclose(r2, r1[0], rtol=1e-2) and r1[0] > 1.01:
            found.append([i, j, l])
    return min(found, key=lambda f: [size(meshes[k]).prod() for k in (f[2], f[1])]) if found else None


def analyse(meshes: list[dict], production: tuple) -> dict:
    """The study's figures from its solved meshes (mesh_size, wall_mesh_size, nodes, cases)."""
    X = anchor_points(JointGeometry().length)[:, :2]
    fam = family(meshes)
    extrapolation = [None] * len(CORNERS)
    if fam is not None:
        r = meshes[fam[0]]["mesh_size"] / meshes[fam[1]]["mesh_size"]
        extrapolation = [{key: richardson(*(meshes[i]["cases"][c][key] for i in fam), r)
                          for key in ("anchors", "phi_end_deg", "cap_rotation_deg")} for c in range(len(CORNERS))]
    asymptotic = fam is not None and all(e[k]["asymptotic"] for e in extrapolation for k in e)
    # Outside the asymptotic range nothing is extrapolated: every error is a difference from
    # the finest mesh (a lower bound on the true error).
    refs = ([{key: e["extrapolated"] for key, e in ext.items()} for ext in extrapolation] if asymptotic
            else max(meshes, key=lambda m: m["nodes"])["cases"])
    for m in meshes:
        m["error"] = [mesh_errors(case, ref, X) for case, ref in zip(m["cases"], refs)]
        m["max_error"] = {k: max(e[k] for e in m["error"]) for k in m["error"][0]}
    prod = next((m for m in meshes if (m["mesh_size"], m["wall_mesh_size"]) == production), None)
    return {"family": [[meshes[i]["mesh_size"], meshes[i]["wall_mesh_size"]] for i in fam] if fam else None,
            "reference": "richardson" if asymptotic else "finest mesh", "asymptotic": asymptotic,
            "extrapolation": extrapolation,
            "production_mesh": list(production), "production_error": prod["max_error"] if prod else None}


# ---------------------------------------------------------------- solves
def _case_file(work: Path, h: float, w: float | None, load: Load) -> Path:
    x = "_".join(f"{v:g}" for v in load.as_array())
    return work / f"h{h:g}_w{w if w is None else f'{w:g}'}_{x}.json"


def solve_mesh(h: float, w: float | None, work: Path, comm=MPI.COMM_WORLD) -> dict:
    """Every corner on one mesh, reusing the per-case files already in ``work``."""
    geometry = replace(JointGeometry(), mesh_size=h, wall_mesh_size=w)
    settings = json_safe(geometry.as_dict())
    done = {}
    for load in CORNERS:
        path = _case_file(work, h, w, load)
        try:
            record = json.loads(path.read_text())
            if record.get("geometry") == settings:
                done[path] = record
        except (OSError, ValueError):
            pass                            # missing, damaged or foreign: solve it again
    solver = None
    cases = []
    for load in CORNERS:
        path = _case_file(work, h, w, load)
        if path not in done:
            solver = solver or JointSolver(geometry, comm)
            r = solver.solve(load)
            if not r.converged:
                raise RuntimeError(f"mesh {h:g}:{w}: {load} did not converge ({r.reason})")
            done[path] = {"load": load.as_array().tolist(), "anchors": r.anchors.tolist(),
                          "phi_end_deg": math.degrees(r.phi_end),
                          "cap_rotation_deg": math.degrees(r.cap_rotation),
                          "newton_iterations": r.iterations, "wall_time_s": r.wall_time,
                          "mesh": solver.mesh_info(), "ranks": comm.size, "geometry": settings}
            on_root(comm, lambda: write_json(path, done[path]))
            if comm.rank == 0:
                log.info("mesh %g:%s, %s: phi_end %.3f deg, %.0f s", h, w, load, done[path]["phi_end_deg"],
                         r.wall_time)
        cases.append(done[path])
    info = cases[0]["mesh"]
    return {"mesh_size": h, "wall_mesh_size": w, **info,
            "cases": [{k: v for k, v in c.items() if k not in ("mesh", "geometry")} for c in cases]}


def run(meshes: list[tuple], work: Path, comm=MPI.COMM_WORLD) -> dict:
    """Solve CORNERS on every mesh (coarse first) and analyse; a JSON-ready dict."""
    solved = [solve_mesh(h, w, work, comm) for h, w in sorted(meshes, key=lambda m: -m[0] * (m[1] or m[0]))]
    production = (JointGeometry().mesh_size, JointGeometry().wall_mesh_size)
    return {"corners": [c.as_array().tolist() for c in CORNERS], "wall_mm": JointGeometry().wall,
            "tolerance_percent": TOLERANCE_PERCENT, "min_nodes": MIN_NODES,
            "meshes": solved, **analyse(solved, production)}


# ---------------------------------------------------------------- command line
def _mesh(text: str) -> tuple:
    """argparse type: "H" or "H:W" (mm)."""
    h, _, w = text.partition(":")
    return MESH_SIZE(h), (MESH_SIZE(w) if w else None)


class _Distinct(argparse.Action):
    """Store a list, refusing a repeated value while parsing (before any output folder
    is created)."""

    def __call__(self, parser, namespace, values, option_string=None):
        if len(set(values)) != len(values):
            parser.error(f"{option_string}: give each mesh once")
        setattr(namespace, self.dest, values)


def summary(study: dict) -> dict:
    """The figures ``main`` prints: per mesh, nodes and worst errors; the production error."""
    return {"meshes": [{"mesh_size": m["mesh_size"], "wall_mesh_size": m["wall_mesh_size"],
                        "nodes": m["nodes"], **m["max_error"]} for m in study["meshes"]],
            "reference": study["reference"], "asymptotic": study["asymptotic"],
            "production_error": study["production_error"]}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.mesh_study", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/fem/mesh_study.json",
                  help="result file (default results/fem/mesh_study.json)")
    ap.add_argument("--meshes", type=_mesh, nargs="+", default=DEFAULT_MESHES, metavar="H[:W]",
                    action=_Distinct, help=f"distinct meshes: size H and wall size W, {MESH_SIZE_TEXT} "
                    "(default 1.8 3.394:1.697 2.4:1.2 1.697:0.849 1.2:0.6)")
    ap.add_output("--work", folder=True, default="build/mesh_study",
                  help="folder of the per-case results (resumes from it; default build/mesh_study)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    with ap.errors():
        if comm.rank == 0:
            Path(args.work).mkdir(parents=True, exist_ok=True)
        comm.barrier()
        study = run(args.meshes, Path(args.work), comm)
        on_root(comm, lambda: MESH_STUDY.write(args.out, study))
    if comm.rank == 0:
        if args.json:
            cli.print_json({**summary(study), "out": args.out})
        else:
            for m in summary(study)["meshes"]:
                print(f"mesh {m['mesh_size']:g}:{m['wall_mesh_size']}: {m['nodes']} nodes, anchors "
                      f"{m['anchor_mm']:.4f} mm ({m['anchor_percent']:.2f} %), phi_end {m['phi_end_deg']:.3f} deg, "
                      f"cap {m['cap_rotation_deg']:.3f} deg vs {study['reference']}")
            print(f"asymptotic: {study['asymptotic']} -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
