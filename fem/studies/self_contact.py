"""Self-contact check: the outer bellow walls facing each other across each valley.

    python -m fem.studies.self_contact --out results/fem/self_contact.json [--penalty 0]
        [--mesh-size H [--wall-mesh-size W] | --divisions N [--hex-size S]] [--formulation F]

When one chamber is pressurised (or M, F2 bend the joint) the other side's bellows close
up: the two outer cell walls across a valley (gap ``valley_width`` = 2.5 mm undeformed)
approach. For each corner load of fem.studies.joint_cases.CORNERS (and their mirrors) this solves
the joint and reports, for every valley on each side, the smallest signed gap

    g = min_pairs (x_b - x_a) · n

over the node pairs of the two periodic faces (:mod:`fem.physics.contact`; n the best-fit
normal of the valley). g < 0 is overlap. The production solver carries penalty contact
(SolverConfig.contact_penalty), so g stays near 0; ``--penalty 0`` switches it off and
shows how far the walls would interpenetrate without it. The mesh options
(fem.options.joint_geometry) and ``--formulation`` default to the production
discretisation (fem.mesh.discretisation.PRODUCTION, hex2:3 mixed); ``make self-contact`` passes
the committed result's paper-fidelity 1.8 mm displacement. The JSON records the mesh
(``mesh``, contract.joint.mesh_text; ``mesh_size`` on tetrahedra) and the formulation.
Units: mm. One rank.
``--json`` prints the minimum gap and the figures of every case.
"""

from __future__ import annotations

import logging
import sys

import numpy as np
from mpi4py import MPI

from contract import cli
from fem.physics.contact import ValleyContact
from fem.artefacts import SELF_CONTACT
from fem.mesh.discretisation import FORMULATION
from fem.mesh.geometry import JointGeometry
from fem.studies.joint_cases import CORNERS
from fem.options import (add_divisions, add_extrapolation, add_formulation, add_mesh_size, add_wall_mesh_size,
                         checked_loads, joint_geometry, one_rank)
from fem.solvers.joint import JointSolver, Load, SolverConfig
from contract.spec import INPUT_MIRROR

PENALTY_MAX = 1e5  # MPa/mm: 1000 x the production penalty


def valley_gaps(solver: JointSolver, geo: JointGeometry) -> dict:
    """Signed gaps g (mm) of every valley's node pairs at the solver's state, per (valley,
    side) (fem.physics.contact). Without contact (penalty 0) they are measured on u in its own
    space: the solver's u, or for the mixed formulation a copy of w's u block."""
    if solver.contact is not None:
        return solver.contact.gaps(solver.u)
    u = solver.displacement()
    return ValleyContact(u.function_space, solver.mesh_data.facet_tags, geo, 0.0).gaps(u)


def run(geo: JointGeometry = JointGeometry(), loads: list[Load] | None = None,
        penalty: float | None = None, allow_extrapolation: bool = False,
        formulation: str = FORMULATION) -> dict:
    """Gaps (mm) for ``loads`` (default: CORNERS and their mirrors) on the joint ``geo``
    (default the production mesh) and formulation, with the contact penalty (MPa/mm; None:
    the solver's)."""
    config = SolverConfig() if penalty is None else SolverConfig(contact_penalty=penalty)
    solver = JointSolver(geo, MPI.COMM_SELF, config=config, formulation=formulation)
    cases = []
    if loads is None:
        loads = CORNERS + [Load.from_array(c.as_array() * INPUT_MIRROR) for c in CORNERS]
    for load in loads:
        r = solver.solve(load, allow_extrapolation=allow_extrapolation)
        entry = {"load": load.as_array().tolist(), "converged": r.converged,
                 "phi_end_deg": float(np.degrees(r.phi_end)),
                 "newton_iterations": r.iterations, "wall_time_s": r.wall_time}
        if r.converged:
            gaps = {f"{side}_{k}": float(g.min()) for (k, side), g in valley_gaps(solver, geo).items()}
            entry.update(gaps=gaps, min_gap_mm=min(gaps.values()))
        cases.append(entry)
    solved = [c for c in cases if c["converged"]]
    min_gap = min(c["min_gap_mm"] for c in solved) if solved else None
    return {"undeformed_gap_mm": geo.valley_width, "mesh": geo.mesh,
            **({} if geo.divisions else {"mesh_size": geo.mesh_size}), "formulation": formulation,
            "contact_penalty_MPa_per_mm": config.contact_penalty, "cases": cases,
            "min_gap_mm": min_gap, "unsolved_cases": len(cases) - len(solved)}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.self_contact", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default="results/fem/self_contact.json",
                  help="result file (default results/fem/self_contact.json)")
    add_mesh_size(ap, None)
    add_wall_mesh_size(ap)
    add_divisions(ap)
    ap.add_argument("--penalty", type=cli.number(0, PENALTY_MAX, "MPa/mm"), default=None,
                    help=f"contact penalty, MPa/mm in [0, {PENALTY_MAX:g}] (default: the "
                         "solver's; 0 = no contact)")
    ap.add_argument("--loads", type=cli.numbers(4), nargs="+", metavar="P,F1,F2,M",
                    help="solve these loads (MPa, N, N, N*mm) instead of the box corners")
    add_extrapolation(ap)
    add_formulation(ap)
    one_rank(ap, MPI.COMM_WORLD)
    args = ap.parse_args(argv)
    loads = None
    if args.loads:
        loads = [Load.from_array(x) for x in checked_loads(ap, args.loads, args.allow_extrapolation)]
    with ap.errors():
        geo = joint_geometry(args)
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    out = run(geo, loads, args.penalty, args.allow_extrapolation,
              args.formulation or FORMULATION)
    with ap.errors():
        SELF_CONTACT.write(args.out, out)
    if args.json:
        cli.print_json({**out, "out": args.out})
        return 0
    for c in out["cases"]:
        print(f"  load {c['load']}: phi_end {c['phi_end_deg']:.1f} deg, min gap "
              f"{c.get('min_gap_mm', float('nan')):.3f} mm")
    print(f"minimum valley gap over these loads: {out['min_gap_mm']} mm "
          f"(undeformed {out['undeformed_gap_mm']} mm, penalty "
          f"{out['contact_penalty_MPa_per_mm']} MPa/mm, {out['formulation']} formulation)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
