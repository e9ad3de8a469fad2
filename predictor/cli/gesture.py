"""Command line: the gripper's static gesture for pressures (P1, P2).

    python -m predictor.cli.gesture --p1 -0.1 --p2 0.1 [--object circle:r=30,y=-195]
        [--mu MU] [--object-weight N] [--approach -0.15,0|zero] [--method newton|lbfgs|nn
        [--polish]] [--model PATH|analytic] [--nn PATH] [--finger FILE]
        [--kinematics cap|tangent] [--joint-weight split|lumped] [--no-gravity]
        [--no-plane] [--plot out.png] [--json]
    python -m predictor.cli.gesture --finger three.toml --pressures 0.1,0,-0.1 ...

The finger is read from a finger description file (``--finger``, default
contract/fingers/paper.toml, contract.finger): any chain of J joints and rigid parts. A
2-joint finger takes ``--p1 --p2`` (or ``--pressures P1,P2``); another takes ``--pressures
P1,..,PJ`` (MPa, base to tip), and ``--approach`` takes J values too (default: joint 1 at
-0.15 MPa, the others at 0). ``--kinematics``: how a part leaves a joint, along its cap
face (cap, the default; needs a joint model with a cap-rotation head) or along the chord
of its last two anchors (tangent, the paper's). ``--joint-weight``: a joint's weight half
at each end (split, the default) or at the mean of its anchors (lumped, the paper's)
(predictor.model.statics).

The problem (predictor.solvers.problem, issue 56 §1): by default the gripper, the right finger
against the mirror finger's contact at X = 0 (the plane's penalty), the problem
``python -m fem.finger`` solves by default; ``--no-plane`` solves one finger alone, which
may cross X = 0 (the paper's gestures, and fem.finger's ``--no-plane``). The JSON says
which (``plane``: true or false).

Data flow: pressures (MPa) + finger + object spec -> GripperProblem (predictor.solvers.problem:
joint model from ``--model``, a surrogate checkpoint or ``analytic``; default the
committed surrogate found from the package, predictor.defaults, an error when missing)
-> predictor.solvers.solve (or the NN predictor) -> right-finger figures (GestureResult.summary
plus time_ms and the run's settings) as text or as strict JSON: converged, state
(no_contact, holds, slips or not_converged), tau [[F1 N, F2 N, M N·mm] x J],
residual_force_mN, residual_moment_Nmm (per joint), tip [x, y] mm (the end of the last
part), tip_angle_deg (global direction of the last part, -90 at rest),
joint_end_angle_deg (per joint, its global exit angle), contact_force_N, friction_N,
friction_use = |f|/(mu N) and slip (null where nothing touches), iterations, time_ms,
joint (the joint model's name), mu and object_weight_N (null without an object), plane
(true: the gripper, the plane X = 0; false: one finger alone; plane_force_N and
plane_overlap_mm its push, N, and how far the outline crosses X = 0, mm), finger
{name, sha256}, kinematics, joint_weight, outline, method (what produced the answer: newton, lm,
newton+lm, nn, nn+newton, ...) beside requested_method (--method). Every figure of the gesture is null when the
solve did not converge. With ``--method nn`` also the network's own figures before any
solver, raw_residual_force_mN and raw_residual_moment_Nmm (per joint), and whether the
answer is the solver's polish of them (polished: contact, gravity with ``--polish``, or
gravity at the plane, below: one Newton step from the network's tau) or the full ramp's
(fallback; gravity: the LM's); with an object raw_state, the network's own grasp state;
without one at_plane: the network's own gesture is outside the NN bound where it presses on
the plane X = 0, so the answer shown is its polish, never the network's (the raw figures
stay the network's); and nn_problem, the problem the network learned ("finger_alone": a gravity network trained on
one finger alone, the default, whose gestures may cross X = 0; or "gripper": the plane X = 0's
equilibrium, ``predictor.cli.nn --plane``).

The gravity NN's answer (predictor.nn.answer.predict_gesture): the network's own tau where
its residual on the gripper is within the NN bound (2 mN, 1.2 N·mm; method nn), which is
where its finger stays off the plane X = 0; where it is outside it because its gesture
presses on the plane or crosses it (within 1 mm of X = 0, nn_answer.PLANE_REACH_MM), whose
stiff penalty turns any network's tau error into a residual over the bound, its tau
finished by the Newton step (the LM where the step's check fails, the full ramp where the
LM does not converge; method nn+newton, nn+newton+lm, ...); no answer where the network is
off by more than the bound away from the plane. ``--polish`` finishes every gravity answer so.

Objects: the model mirrors the right finger, so an object is centred (x = 0) and
mirror-symmetric; its sizes and height are bounded (contract.grasp.object_error); one cutting
through the fingers at the approach gesture is refused; one beyond the fingers' reach
answers no_contact at once (statics.out_of_reach).

Exit codes: 0 converged; 1 no answer (the JSON says converged false, its figures are null;
the stderr line says why: the solve did not converge, or the raw gravity NN's own answer is
outside its bound away from the plane X = 0, naming --polish, or where its gesture presses on
the plane and the polish did not converge either); 2 bad
input (a pressure that is not a number or beyond ±0.3 MPa, the wrong number of pressures
for the finger, a bad finger file or object spec, an object the model cannot represent
or that intersects the fingers at the approach gesture, a bad --mu or --object-weight,
an unwritable --plot, a missing, damaged or other-kind model, cap kinematics on a joint
model without a cap head, a finger whose weights load a joint beyond the joint model's
box or whose mounts are too close for the fingers to meet at X = 0
(predictor.solvers.problem.finger_error), an NN checkpoint trained for another finger, options or
object: the contact NN knows one object) with a one-line reason on stderr, checked before
the solve; 130 interrupted (Ctrl-C), one line.
"""
from __future__ import annotations

import argparse
import math
import sys

import torch

from contract import cli
from predictor.model.joint import load_joint
from predictor.solvers.problem import (DEFAULT, OBJECT_HELP, PRESSURE, add_arguments, add_finger_arguments, add_plane,
                                       approach_arg, load_problem, object_arg, params_of, pressure_list)
from predictor.solvers.solve import APPROACH, SolverOptions, solve
from predictor.model.statics import STATES, Obstacle, parse_object


def pressures_of(args: argparse.Namespace, n_joints: int) -> tuple[float, ...]:
    """The J target pressures from --p1/--p2 or --pressures; ValueError (one line) when they
    do not fit the finger's joint count."""
    name = args.finger.name
    if args.pressures is not None:
        if args.p1 is not None or args.p2 is not None:
            raise ValueError("give either --p1/--p2 or --pressures, not both")
        if len(args.pressures) != n_joints:
            raise ValueError(f"--pressures: {len(args.pressures)} values for finger {name!r} of {n_joints} joints")
        return args.pressures
    if n_joints != 2:
        raise ValueError(f"finger {name!r} has {n_joints} joints: give --pressures with {n_joints} values (MPa)")
    if args.p1 is None or args.p2 is None:
        raise ValueError("give --p1 and --p2 (MPa), or --pressures P1,P2")
    return (args.p1, args.p2)


def prepare(args: argparse.Namespace):
    """Everything a gesture needs, checked before any solve: (problem, pressures (1, J),
    joint, NN predictor or None). ValueError (one line) for any bad input, a missing
    default model, an object the model cannot represent or that cuts through the fingers
    at the approach gesture (predictor.solvers.problem.load_problem)."""
    params = params_of(args)
    n_joints = params.n_joints
    pressures = torch.tensor([pressures_of(args, n_joints)], dtype=torch.float64)
    if args.approach not in (None, "zero") and len(args.approach) != n_joints:
        raise ValueError(f"--approach: {len(args.approach)} values for finger {args.finger.name!r} of "
                         f"{n_joints} joints")
    joint = load_joint(args.model, args.finger)
    options = dict(params=params, mu=args.mu, object_weight=args.object_weight, joint=joint)
    if args.method == "nn":
        from predictor.nn.checkpoint import load_predictor

        predictor = load_predictor(args.nn, joint, contact=args.object is not None, params=params)
        trained = predictor.config.obstacle
        if args.object is not None and parse_object(args.object) != Obstacle(**trained):
            # The contact NN learned one grasp: any other object is a question it never saw.
            raise ValueError(f"--method nn: the contact NN ({args.nn or 'results/predictor/contact_nn.pt'}) was "
                             f"trained for one object, the {Obstacle(**trained).describe()}, not the "
                             f"{parse_object(args.object).describe()}: use --method newton for it")
        problem = load_problem(None, args.object, approach=predictor.config.approach, **options)
        return problem, pressures, joint, predictor
    approach = None if args.approach == "zero" else args.approach or DEFAULT
    problem = load_problem(None, args.object, gravity=not args.no_gravity, approach=approach, plane=args.plane,
                           **options)
    return problem, pressures, joint, None


def run(args: argparse.Namespace, prepared=None):
    """Solve one gesture from parsed arguments (and ``prepare(args)``, when already done).
    Returns (json dict, result, problem)."""
    problem, pressures, joint, predictor = prepared or prepare(args)
    if predictor is not None:
        from predictor.nn.answer import predict_gesture

        res = predict_gesture(predictor, problem, pressures, polish=True if args.polish else None)
    else:
        res = solve(problem, pressures, SolverOptions(method=args.method))
    ok = bool(res.converged[0])
    out = {**res.summary(0), "time_ms": res.time_ms,
           "method": res.method, "requested_method": args.method, "object": args.object, "gravity": problem.gravity,
           "finger": {"name": problem.params.finger.name, "sha256": problem.params.finger.digest},
           "kinematics": problem.params.kinematics, "joint_weight": problem.params.joint_weight,
           "outline": problem.params.outline,
           "joint_end_angle_deg": [math.degrees(a) for a in res.pose.phi[0].tolist()] if ok else None}
    if args.method == "nn":   # the network's own figures, before any solver (issue 15)
        out.update(raw_residual_force_mN=res.raw_residual_force_mN[0].tolist(),
                   raw_residual_moment_Nmm=res.raw_residual_moment_Nmm[0].tolist(),
                   polished=bool(res.polished[0]), fallback=bool(res.fallback[0]),
                   newton_from_nn=None if res.stepped is None else bool(res.stepped[0]),
                   raw_state=None if res.raw_state is None else STATES[int(res.raw_state[0])],
                   at_plane=None if res.at_plane is None else bool(res.at_plane[0]),
                   nn_problem="gripper" if predictor.config.learns_gripper() else "finger_alone")
    return out, res, problem


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.cli.gesture", description=__doc__.split("\n\n")[0])
    ap.add_argument("--p1", type=PRESSURE, help="joint-1 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--p2", type=PRESSURE, help="joint-2 pressure, MPa (|P| <= 0.3)")
    ap.add_argument("--pressures", type=pressure_list, help="P1,..,PJ MPa, one per joint of the finger, base "
                    "to tip (instead of --p1 --p2)")
    add_finger_arguments(ap)
    ap.add_argument("--object", type=object_arg, help=OBJECT_HELP)
    ap.add_argument("--approach", type=approach_arg, help="P1,P2[,..] (MPa, one per joint) at which the object is "
                    f"brought in (grasp history; default {APPROACH[0]},{APPROACH[1]}), or 'zero' to ramp from 0 with "
                    "the object present")
    ap.add_argument("--method", choices=("newton", "lbfgs", "nn"), default="newton")
    ap.add_argument("--nn", help="NN predictor checkpoint for --method nn (default: results/predictor/"
                    "gravity_nn.pt, or contact_nn.pt with --object)")
    ap.add_argument("--polish", action="store_true", help="--method nn under gravity: finish the network's tau "
                    "with a Newton step to the iterative solver's tolerances (without it only where its gesture "
                    "presses on the plane X = 0 outside the NN bound; the contact NN's answer is always polished)")
    ap.add_argument("--no-gravity", action="store_true", help="drop all weights")
    add_plane(ap)
    add_arguments(ap)
    ap.add_output("--plot", suffix=".png", help="write the gesture PNG here")
    args = ap.parse_args(argv)
    if args.polish and args.method != "nn":
        ap.error("--polish finishes an NN prediction: use it with --method nn")
    if args.method == "nn" and (args.no_gravity or args.approach is not None or not args.plane):
        ap.error("--method nn predicts the trained case only (the gripper with gravity on, its own approach): "
                 "drop --no-gravity, --approach and --no-plane")
    torch.set_num_threads(1)
    with ap.errors():
        prepared = prepare(args)  # every input checked before the solve
        out, res, problem = run(args, prepared)
        if args.plot:
            from predictor.model.plot import save_gesture

            save_gesture(args.plot, res, 0, problem)
    cli.print_fields(out, args.json, 20)
    if not out["converged"]:
        print(f"{ap.prog}: {failure(out, prepared)}; no gesture returned", file=sys.stderr)
        return 1
    return 0


def failure(out: dict, prepared) -> str:
    """Why a gesture has no answer, for the one stderr line (``prepared``: prepare(args)).
    The raw gravity NN answers only within its bound (predictor.nn.answer), which is not a
    solver failing to converge; where its gesture presses on the plane X = 0 the polish
    was tried already (``at_plane``)."""
    problem, pressures, _, predictor = prepared
    if predictor is None or problem.obstacle is not None or (not out["at_plane"] and (out["polished"] or
                                                                                       out["fallback"])):
        return "the equilibrium solve did not converge"
    from predictor.nn.answer import NN_FORCE_TOL_MN, NN_MOMENT_TOL_NMM

    f, m = max(out["raw_residual_force_mN"]), max(out["raw_residual_moment_Nmm"])
    why = (f"the gravity NN's own answer is outside its bound (residual up to {f:.3g} mN and {m:.3g} N·mm; an "
           f"answer needs <= {NN_FORCE_TOL_MN:g} mN and {NN_MOMENT_TOL_NMM:g} N·mm)")
    if out["at_plane"]:
        return why + (": its finger presses on the plane X = 0, where the gripper's fingers meet, and the polish "
                      "of its tau (Newton steps, the LM, then the full ramp) did not converge either")
    return why + "; --polish finishes it with a Newton step"


if __name__ == "__main__":
    sys.exit(main())
