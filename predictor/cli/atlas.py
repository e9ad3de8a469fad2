"""Command line: the grasp atlas of predictor.planning.atlas (where the gripper holds, slips
or misses an object over its pressure plane).

    python -m predictor.cli.atlas --object SPEC --grid N [--box P1LO,P1HI,P2LO,P2HI]
        [--path sweep|ramp] [--model PATH|analytic] [--mu MU] [--object-weight N]
        [--finger FILE] [--kinematics cap|tangent] [--joint-weight split|lumped]
        [--approach P1,P2|zero] [--no-gravity] [--no-plane] [--quiet] [--json] [--plot FILE.png] [--out FILE.json]

The options, what is solved and what the JSON records: predictor.planning.atlas.

Exit codes: 0 atlas written; 2 bad input (a bad number, grid, box, object spec, an
object the model cannot represent, unwritable output, a missing default model, an object
that intersects the fingers at the approach gesture, a finger of other than two joints or
one no gesture can be solved for, predictor.solvers.problem.finger_error), one line on stderr,
before the grid solve; 130 interrupted (Ctrl-C): one line, no traceback, no file. The API (``grasp_atlas``) applies the same checks (predictor.solvers.problem).
"""
from __future__ import annotations

import sys

import torch

from contract import cli
from predictor.artefacts import ATLAS
from predictor.planning import atlas as library
from predictor.planning.atlas import PATHS, grasp_atlas, save_atlas_figure
from predictor.solvers.options import SolverOptions
from predictor.solvers.problem import (DEFAULT, FULL_BOX, GRID, OBJECT_HELP, add_arguments, add_finger_arguments, add_plane,
                                       approach_arg, box_arg, finger_record, load_problem, object_arg, params_of)
from predictor.solvers.progress import set_quiet
from predictor.solvers.solve import APPROACH


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.cli.atlas", description=library.__doc__.split("\n\n")[0])
    ap.add_argument("--object", type=object_arg, required=True, help=OBJECT_HELP)
    ap.add_argument("--grid", type=GRID.arg, default=61, help="N: N x N grid (default 61)")
    ap.add_argument("--box", type=box_arg, default=FULL_BOX, help="P1LO,P1HI,P2LO,P2HI MPa (default the full box)")
    ap.add_argument("--path", choices=PATHS, default="sweep",
                    help="sweep: continuation outward from the approach (default); ramp: every point "
                    "ramped on its own (the reference)")
    ap.add_argument("--ramp-steps", type=cli.number(1, 1000, integer=True), default=SolverOptions.ramp_steps,
                    help=f"pressure sub-steps of a ramped point (default {SolverOptions.ramp_steps}; --path ramp "
                    "with more steps checks the reference's own path resolution)")
    add_plane(ap)
    add_finger_arguments(ap)
    ap.add_argument("--approach", type=approach_arg, help="P1,P2 (MPa) at which the object is brought in (default "
                    f"{APPROACH[0]},{APPROACH[1]}), or 'zero' to ramp from 0 with the object present")
    ap.add_argument("--no-gravity", action="store_true", help="drop all weights")
    add_arguments(ap)
    ap.add_output("--plot", suffix=".png", help="write the atlas figure here")
    ap.add_output("--out", suffix=".json", help="write the full atlas JSON here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    set_quiet(args.quiet)
    params = params_of(args)
    if params.n_joints != 2:   # before any model is loaded
        ap.error(f"the grasp atlas spans (P1, P2): finger {params.finger.name!r} has {params.n_joints} joints")
    if args.approach not in (None, "zero") and len(args.approach) != 2:
        ap.error(f"--approach: {len(args.approach)} values for the atlas's two joints (P1,P2 MPa, or 'zero')")
    approach = None if args.approach == "zero" else args.approach or DEFAULT
    with ap.errors():
        problem = load_problem(args.model, args.object, gravity=not args.no_gravity, params=params, mu=args.mu,
                               object_weight=args.object_weight, approach=approach, plane=args.plane)
        atlas = grasp_atlas(problem, args.grid, args.box, SolverOptions(ramp_steps=args.ramp_steps), args.path)
        finger = finger_record(params)
        doc = {**atlas.to_json(), "spec": args.object, "ramp_steps": args.ramp_steps, "finger": finger}
        if args.out:
            ATLAS.write(args.out, doc)
        if args.plot:
            save_atlas_figure(args.plot, atlas, problem)
    cli.print_fields({**atlas.summary(), "spec": args.object, "finger": finger}, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
