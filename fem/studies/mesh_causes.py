"""What limits the joint FEM's mesh convergence: the candidate causes, one at a time.

    python -m fem.studies.mesh_causes --work results/fem/joint_cases --out results/fem/mesh_causes.json \\
        [--max-hours 1.5] [--reference results/fem/mesh_study.json]

A discretisation (:class:`fem.mesh.discretisation.Discretisation`) is (H, W, formulation, q,
kappa): mesh sizes, formulation, quadrature degree and contact penalty. Every discretisation of PLAN is
solved from zero at the eight LOADS (the mesh study's four box corners and four interior
loads); each (discretisation, load) is one JSON file in ``--work`` written atomically on
rank 0, so a killed or time-limited run (``--max-hours``: no new solve starts after it)
resumes where it stopped.

Each record: anchors r_1..r_10 (10, 2) mm, phi_end and cap rotation (deg), the solve's
wall time (s), Newton figures, and the contact state (closed pairs, smallest gap, mm).

Effects. BASE is the paper-fidelity discretisation of the committed data (fem.mesh.discretisation.PAPER:
1.8 mm, displacement, q = 2, kappa = 100).
A factor's effect at a load is the change of the answer when only that factor changes
(COMPARISONS: each variant against BASE, or against the variant that differs from it in
that factor alone, e.g. the wall refinement of the mixed form)::

    anchor %  = 100 max_i |r_i - r_i^B| / max_i |r_i^B - X_i|      (X_i rest anchors)
    phi_end, cap rotation: |difference| in deg

and the table keeps its worst and mean over the loads solved in both. Errors against the
reference: the mesh study's reference (``--reference``: its Richardson extrapolation, or
its finest mesh outside the asymptotic range), with the same measures.

Data flow: PLAN x LOADS -> fem.solvers.joint.JointSolver (one per discretisation) -> work JSONs
-> analyse -> ``--out`` JSON and a markdown table beside it (same stem, .md).
"""

from __future__ import annotations

import json
import logging
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.files import write_text
from fem.artefacts import MESH_CAUSES
from fem.mesh.geometry import JointGeometry, anchor_points
from fem.mesh.discretisation import PAPER
from fem.studies.joint_cases import (INTERIOR, LOADS, add_work_arguments, difference, load_key, read_records,
                                     solve_missing, work_folder)
from fem.options import on_root

BASE = PAPER
MIXED = replace(BASE, formulation="mixed")
#: the discretisations solved, in this order: the base, the two suspected main causes
#: (formulation; one element through the wall, W = 1.2 mm: 1.6x BASE's nodes), the others
#: at BASE's cost, then W = 0.6 mm (two elements through the wall: 7.5x BASE's nodes),
#: mixed first (the displacement form there is close to the mesh study's 1.2:0.6)
PLAN = [BASE, MIXED, replace(BASE, W=1.2), replace(BASE, quadrature=4),
        replace(BASE, penalty=25.0), replace(BASE, penalty=400.0), replace(MIXED, W=1.2),
        replace(MIXED, quadrature=4), replace(MIXED, W=0.6), replace(BASE, W=0.6)]
#: the table's rows: (factor, variant, the discretisation it differs from in that factor)
COMPARISONS = [
    ("base", BASE, None),
    ("formulation", MIXED, BASE),
    ("quadrature", replace(BASE, quadrature=4), BASE),
    ("penalty", replace(BASE, penalty=25.0), BASE),
    ("penalty", replace(BASE, penalty=400.0), BASE),
    ("wall", replace(BASE, W=1.2), BASE),
    ("wall (mixed)", replace(MIXED, W=1.2), MIXED),
    ("formulation (W = 1.2)", replace(MIXED, W=1.2), replace(BASE, W=1.2)),
    ("quadrature (mixed)", replace(MIXED, quadrature=4), MIXED),
    ("wall", replace(BASE, W=0.6), BASE),
    ("wall (mixed)", replace(MIXED, W=0.6), MIXED),
    ("formulation (W = 0.6)", replace(MIXED, W=0.6), replace(BASE, W=0.6)),
]


# ---------------------------------------------------------------- pure post-processing
def worst_and_mean(per_load: dict) -> dict:
    """{"worst": {...}, "mean": {...}} of the per-load differences (empty: None)."""
    if not per_load:
        return {"worst": None, "mean": None}
    keys = next(iter(per_load.values())).keys()
    return {"worst": {k: max(v[k] for v in per_load.values()) for k in keys},
            "mean": {k: float(np.mean([v[k] for v in per_load.values()])) for k in keys}}


def compare(cases: dict, refs: dict, X: np.ndarray) -> dict:
    """Per-load differences of ``cases`` against ``refs`` (both {load key: record}) at
    the loads both hold, with their worst and mean."""
    per_load = {k: difference(cases[k], refs[k], X) for k in cases if k in refs}
    return {"loads": len(per_load), "per_load": per_load, **worst_and_mean(per_load)}


def reference_cases(study: dict | None) -> tuple[dict, str | None]:
    """({load key: answer}, what it is) of the mesh study's reference: the extrapolated
    answers in the asymptotic range, else its finest mesh (empty without a study)."""
    if not study or not study.get("meshes"):
        return {}, None
    if study["reference"] == "richardson":
        refs = {load_key(load): {k: e[k]["extrapolated"] for k in e}
                for load, e in zip(study["loads"], study["extrapolation"])}
        family = ", ".join(study["family"])
        return refs, f"mesh study, Richardson extrapolation of the {study['formulation']} family {family}"
    finest = max(study["meshes"], key=lambda m: m["nodes"])
    return {load_key(c["load"]): c for c in finest["cases"]}, f"mesh study, finest mesh ({finest['key']})"


def analyse(records: dict, study: dict | None) -> dict:
    """The table from the solved records ({discretisation key: {load key: record}})."""
    X = anchor_points(JointGeometry().length)[:, :2]
    refs, reference = reference_cases(study)
    rows = []
    for factor, variant, base in COMPARISONS:
        cases = records.get(variant.key, {})
        if not cases:
            continue
        times = [c["wall_time_s"] for c in cases.values()]
        row = {"factor": factor, "discretisation": variant.as_dict(), "key": variant.key,
               "loads_solved": len(cases), "nodes": next(iter(cases.values()))["mesh"]["nodes"],
               "dofs": next(iter(cases.values()))["mesh"]["dofs"],
               "mean_solve_s": float(np.mean(times)), "against_reference": compare(cases, refs, X)}
        if base is not None:
            base_cases = records.get(base.key, {})
            row["base"] = base.key
            row["effect"] = compare(cases, base_cases, X)
            shared = [k for k in cases if k in base_cases]
            if shared:
                row["time_ratio"] = float(np.mean([cases[k]["wall_time_s"] for k in shared])
                                          / np.mean([base_cases[k]["wall_time_s"] for k in shared]))
        rows.append(row)
    effects = [r for r in rows if r.get("effect", {}).get("worst")]
    dominant = max(effects, key=lambda r: r["effect"]["worst"]["anchor_percent"]) if effects else None
    ranking = {}
    for r in effects:           # each factor's largest worst-load effect, over its rows
        ranking[r["factor"]] = max(ranking.get(r["factor"], 0.0), r["effect"]["worst"]["anchor_percent"])
    contact = {load_key(c["load"]): c["contact"] for c in records.get(BASE.key, {}).values()}
    return {"loads": [load.as_array().tolist() for load in LOADS],
            "interior_loads": [load.as_array().tolist() for load in INTERIOR],
            "base": BASE.as_dict(), "reference": reference, "base_contact": contact, "rows": rows,
            "ranking": sorted(([f, v] for f, v in ranking.items()), key=lambda fv: -fv[1]),
            "dominant": {"factor": dominant["factor"], "key": dominant["key"],
                         "worst_anchor_percent": dominant["effect"]["worst"]["anchor_percent"]}
            if dominant else None}


def _fmt(x, spec):
    return "–" if x is None else format(x, spec)


def markdown(table: dict) -> str:
    """The short markdown summary of :func:`analyse`'s table."""
    lines = ["# What limits the joint FEM's mesh convergence (issue 35 §1)", "",
             "Written by `python -m fem.studies.mesh_causes` (fem/studies/mesh_causes.py states the measures). "
             "Effect: change of the answer when only that factor changes from its base, worst "
             "(mean) over the loads solved in both; anchor % of the largest anchor displacement. "
             "Reference: " + (table["reference"] or "none") + ".", "",
             "| factor | discretisation | nodes | loads | effect anchors % worst (mean) | "
             "phi_end deg worst | cap rot. deg worst | vs reference anchors % worst | solve s (x base) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in table["rows"]:
        e = r.get("effect", {})
        w, m = e.get("worst") or {}, e.get("mean") or {}
        ref = (r["against_reference"].get("worst") or {}).get("anchor_percent")
        ratio = f" (x{r['time_ratio']:.2f})" if "time_ratio" in r else ""
        lines.append(f"| {r['factor']} | {r['key']} | {r['nodes']} | {r['loads_solved']} | "
                     f"{_fmt(w.get('anchor_percent'), '.2f')} ({_fmt(m.get('anchor_percent'), '.2f')}) | "
                     f"{_fmt(w.get('phi_end_deg'), '.3f')} | {_fmt(w.get('cap_rotation_deg'), '.3f')} | "
                     f"{_fmt(ref, '.2f')} | {r['mean_solve_s']:.0f}{ratio} |")
    lines += per_load_markdown(table)
    d = table["dominant"]
    lines += ["", f"Largest single effect: **{d['factor']}** ({d['key']}), {d['worst_anchor_percent']:.2f} % "
              "of the largest anchor displacement at the worst load." if d else "No effect measured yet."]
    if len(table["ranking"]) > 1:
        lines += ["", "Factors by their largest effect (anchors %, worst load): " + ", ".join(
            f"{f} {v:.2f}" for f, v in table["ranking"]) + "."]
    return "\n".join(lines) + "\n"


def per_load_markdown(table: dict) -> list[str]:
    """Lines of a second table: each row's effect (anchor %) at each load, with the base's
    contact state there (closed valley pairs)."""
    rows = [r for r in table["rows"] if r.get("effect", {}).get("per_load")]
    if not rows:
        return []
    head = "| load (P, F1, F2, M) | closed pairs | " + " | ".join(
        f"{r['factor']}: {r['key']}" for r in rows) + " |"
    lines = ["", "Effect per load, anchors % (phi_end deg):", "", head,
             "|---|---|" + "---|" * len(rows)]
    for load in table["loads"]:
        k = load_key(load)
        cells = []
        for r in rows:
            e = r["effect"]["per_load"].get(k)
            cells.append("–" if e is None else f"{e['anchor_percent']:.2f} ({e['phi_end_deg']:.2f})")
        closed = (table["base_contact"].get(k) or {}).get("closed_pairs", "–")
        lines.append(f"| {', '.join(f'{v:g}' for v in load)} | {closed} | " + " | ".join(cells) + " |")
    return lines


# ---------------------------------------------------------------- command line
def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.mesh_causes", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/fem/mesh_causes.json",
                  help="table (default results/fem/mesh_causes.json; a .md summary beside it)")
    add_work_arguments(ap)
    ap.add_argument("--reference", default="results/fem/mesh_study.json",
                    help="mesh study JSON whose finest mesh is the reference (default "
                    "results/fem/mesh_study.json)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    with ap.errors():
        try:
            study = json.loads(Path(args.reference).read_text())
        except (OSError, ValueError) as exc:
            ap.error(f"--reference {args.reference}: {exc}")
        complete = solve_missing(work_folder(args.work, comm), PLAN, LOADS, args.max_hours, comm)
        table = {**analyse(read_records(Path(args.work), PLAN), study), "complete": complete}

        def write():
            MESH_CAUSES.write(args.out, table)
            write_text(Path(args.out).with_suffix(".md"), markdown(table))
        on_root(comm, write)
    if comm.rank == 0:
        if args.json:
            cli.print_json({"out": args.out, "complete": complete, "dominant": table["dominant"]})
        else:
            print(markdown(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
