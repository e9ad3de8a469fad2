"""Self-contact check: the outer bellow walls facing each other across each valley.

    python -m fem.self_contact --out results/fem/self_contact.json

When one chamber is pressurised (or M, F2 bend the joint) the other side's bellows close
up: the two outer cell walls across a valley (gap ``valley_width`` = 2.5 mm undeformed)
approach. For each corner load of fem.mesh_study.CORNERS (and their mirrors) this solves
the joint and measures, for every valley on each side, the signed gap

    g = min_i  (p_right(i) - p_left(i)) · n_left

between the deformed nodes of the left face and their nearest deformed nodes on the
right face, with n_left the deformed unit normal of the left face (best-fit plane).
g < 0 means the walls interpenetrate (then penalty contact would be needed).
Units: mm. One rank.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import replace

import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from fem.geometry import TAGS, JointGeometry
from fem.mesh_study import CORNERS
from fem.solver import JointSolver, Load


def _face_nodes(solver, geo: JointGeometry) -> dict:
    """Map (valley index, side 'top'|'bottom', 'left'|'right') -> dof-node indices."""
    from dolfinx import fem

    ft = solver.mesh_data.facet_tags
    dofs = fem.locate_dofs_topological(solver.V, 2, ft.find(TAGS["valley_faces"]))
    X = solver.V.tabulate_dof_coordinates()[dofs]
    cells = geo.cells()
    groups = {}
    for k, ((_, x1), (x2, _)) in enumerate(zip(cells[:-1], cells[1:])):
        for side, sign in (("top", 1), ("bottom", -1)):
            for face, xf in (("left", x1), ("right", x2)):
                mask = (np.abs(X[:, 0] - xf) < 1e-6) & (sign * X[:, 1] > 0)
                groups[(k, side, face)] = dofs[mask]
    return groups


def valley_gaps(solver, geo: JointGeometry) -> dict:
    """Signed minimum gap (mm) per valley and side at the solver's current state."""
    x = solver.V.tabulate_dof_coordinates() + solver.u.x.array.reshape(-1, 3)
    groups = _face_nodes(solver, geo)
    gaps = {}
    for k in range(geo.n_cells - 1):
        for side in ("top", "bottom"):
            left, right = x[groups[(k, side, "left")]], x[groups[(k, side, "right")]]
            centred = left - left.mean(axis=0)
            n = np.linalg.svd(centred, full_matrices=False)[2][-1]
            n = n if n[0] > 0 else -n
            _, j = cKDTree(right).query(left)
            gaps[f"{side}_{k}"] = float(np.min((right[j] - left) @ n))
    return gaps


def run(mesh_size: float | None = None, loads: list[Load] | None = None) -> dict:
    """Gaps for ``loads`` (default: CORNERS and their mirrors) on the given mesh."""
    geo = JointGeometry() if mesh_size is None else replace(JointGeometry(), mesh_size=mesh_size)
    solver = JointSolver(geo, MPI.COMM_SELF)
    cases = []
    if loads is None:
        loads = CORNERS + [Load.from_array(c.as_array() * [-1, 1, -1, -1]) for c in CORNERS]
    for load in loads:
        r = solver.solve(load)
        entry = {"load": load.as_array().tolist(), "converged": r.converged,
                 "phi_end_deg": float(np.degrees(r.phi_end))}
        if r.converged:
            gaps = valley_gaps(solver, geo)
            entry.update(gaps=gaps, min_gap_mm=min(gaps.values()))
        cases.append(entry)
    solved = [c for c in cases if c["converged"]]
    min_gap = min(c["min_gap_mm"] for c in solved) if solved else None
    return {"undeformed_gap_mm": geo.valley_width, "mesh_size": geo.mesh_size, "cases": cases,
            "min_gap_mm": min_gap, "interpenetration": bool(min_gap is not None and min_gap < 0),
            "unsolved_cases": len(cases) - len(solved)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fem.self_contact", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="results/fem/self_contact.json")
    ap.add_argument("--mesh-size", type=float, default=None)
    ap.add_argument("--loads", nargs="+", metavar="P,F1,F2,M",
                    help="solve these loads instead of the box corners (diagnostics)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    loads = None
    if args.loads:
        try:
            loads = [Load(*(float(x) for x in spec.split(","))) for spec in args.loads]
        except (TypeError, ValueError):
            print(f"error: --loads takes P,F1,F2,M groups, got {args.loads}", file=sys.stderr)
            return 2
    out = run(args.mesh_size, loads)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    for c in out["cases"]:
        print(f"  load {c['load']}: phi_end {c['phi_end_deg']:.1f} deg, min gap "
              f"{c.get('min_gap_mm', float('nan')):.3f} mm")
    print(f"minimum valley gap over these loads: {out['min_gap_mm']} mm "
          f"(undeformed {out['undeformed_gap_mm']} mm); interpenetration: {out['interpenetration']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
