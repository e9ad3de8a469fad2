"""Inverse pressures: which (P1, P2) hold an object, or put the fingertip where asked.

The command line of predictor.planning.inversion, and ``make inverse``'s cases.

    python -m predictor.cli.inverse --goal hold --object SPEC [--min-normal N] [--least-pressure]
        [--atlas ATLAS.json] [--model PATH|analytic] [--mu MU] [--object-weight N]
        [--no-gravity] [--quiet] [--json] [--plot FILE.png]
    python -m predictor.cli.inverse --goal tip:X,Y[,DEG] [--object SPEC] ...
    python -m predictor.cli.inverse --cases [--atlas-dir DIR] [--out FILE.json] [--track-plot FILE.png]
    python -m predictor.cli.inverse --track FILE|demo [--out FILE.json] [--plot FILE.png] [--finger FILE]

Goals, gradients, search and answers: predictor.planning.inversion. Exit 0: the goal is met
(``feasible``); 1: ``infeasible`` (the closest achievable answer and the limit that stops
it); 2: bad input, one line on stderr, before any work. ``--plot`` draws the answer's
gesture (its verifying ramp solve); ``--cases`` (``make inverse``) answers the hold goal
for the paper's three objects (starting from their committed atlases, and cold) and the
tip targets CASE_TIPS, with median timings of REPEATS identical queries (a tip target
and a cold hold each as a process's first question, its coarse start grid solved anew;
the tip targets also ``warm``: the grid kept from the question before,
predictor.planning.inversion.coarse_atlas); each case also
records where its answer touches and how far the fingers cross X = 0 (``where_it_touches``),
and ``--cases`` also tracks the demo path (predictor.planning.track) into the JSON's ``track``.
``--track FILE`` answers a list of fingertip goals in order, each warm-started from the
last answer (predictor.planning.track; exit 1 when a goal is unreachable, all answered). ``--atlas``
is read strictly (``read_atlas``); ``--finger`` as predictor.cli.gesture's.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import torch

from contract import cli
from predictor.artefacts import INVERSE, TRACK
from predictor.planning.atlas import STATES, Atlas, atlas_from_json
from predictor.planning.inversion import (COARSE, HOLD_MARGIN, REGULATOR, TARGET_HOLD_MS, TARGET_TIP_MS, TIP_TOL_MM,
                                          VERIFY_TOL_MM, Goal, InverseProblem, InverseResult, coarse_atlas,
                                          inverse_pressures, parse_goal)
from predictor.solvers.problem import (DEFAULT, FULL_BOX, MIN_NORMAL, add_arguments, add_finger_arguments, add_plane,
                                       approach_arg, box_arg, finger_record, load_problem, object_arg, params_of)
from predictor.solvers.progress import Heartbeat, set_quiet
from predictor.model.gripper import GripperParams
from predictor.model.statics import GripperProblem, meets


def save_inverse_figure(path: str, items: list[tuple[str, InverseResult, GripperProblem]]) -> None:
    """One gesture panel per answer (its verifying ramp solve), titled with the goal
    (items: (goal text or label, result, problem)); tip targets are marked x."""
    import matplotlib.pyplot as plt

    from predictor.model.plot import draw_gesture, save_figure

    fig, axes = plt.subplots(1, len(items), figsize=(4.4 * len(items), 5.2), squeeze=False)
    for ax, (label, r, prob) in zip(axes[0], items):
        i = int(torch.isclose(r.gesture.pressures, torch.tensor(r.pressures, dtype=torch.float64)).all(-1)
                .nonzero()[0])
        p1, p2 = r.pressures
        draw_gesture(ax, r.gesture, i, prob, f"{label}: {r.status}\nP = ({p1:+.3f}, {p2:+.3f}) MPa"
                     + (f", u = {r.friction_use:.2f}" if r.friction_use is not None else ""))
        if label.startswith("tip"):  # the target
            ax.plot(*parse_goal(label).tip, "kx", ms=9, mew=2)
    fig.tight_layout()
    save_figure(fig, path, 110)


#: ``make inverse``: the paper's three objects (hold goal) and fingertip targets under
#: gravity without an object (two reachable ones, one beyond the finger's reach).
CASE_OBJECTS = ("circle", "ellipse", "rectangle")
CASE_TIPS = ("tip:40,-212", "tip:9.04,-214.93,-88.37", "tip:0,-400")
REPEATS = 3  # timings: the median of this many identical queries


def atlas_check(res: InverseResult, atlas: Atlas) -> dict:
    """The answer against the atlas: the state of its nearest grid point, the atlas' best
    holding friction use, and whether the answer is at least as good."""
    row = atlas.index(*res.pressures)
    best = atlas.best_hold()
    best_use = None if best is None else float(atlas.friction_use.ravel()[best])
    good = res.friction_use is not None and (best_use is None or res.friction_use <= best_use + 1e-9)
    return {"nearest_grid_state": STATES[int(atlas.state.ravel()[row])], "atlas_best_friction_use": best_use,
            "answer_friction_use": res.friction_use, "at_least_as_good": bool(good and res.status == "feasible")}


def where_it_touches(res: InverseResult) -> dict:
    """Where the answer's verifying gesture touches the object (contact_part, contact_face,
    contact_point_mm, contacts) and the fingers' meeting at X = 0 (plane_force_N N,
    plane_overlap_mm mm): GestureResult.where_it_touches; nulls without a gesture."""
    if res.gesture is None:
        return {k: None for k in ("contacts", "contact_part", "contact_face", "contact_point_mm", "plane_force_N",
                                  "plane_overlap_mm")}
    return res.gesture.where_it_touches(0)


def _cold(ip: InverseProblem) -> InverseResult:
    """``ip`` answered as a process's first question: its coarse start grid solved anew
    (predictor.planning.inversion.coarse_atlas forgotten)."""
    coarse_atlas.cache_clear()
    return inverse_pressures(ip)


def _timed(query, repeats: int = REPEATS) -> tuple[list, float]:
    """(``repeats`` answers of query(), the median process CPU time of one, ms): the
    query's own cost on a shared machine, beside its wall time (InverseResult.time_ms)."""
    out, cpu = [], []
    for _ in range(repeats):
        c0 = time.process_time()
        out.append(query())
        cpu.append(1e3 * (time.process_time() - c0))
    return out, float(np.median(cpu))


def run_cases(model: str | None, atlas_dir: Path, params: GripperParams | None = None,
              plane: bool = True) -> tuple[dict, list]:
    """``make inverse``: every case REPEATS times (median time) for the finger and options
    ``params`` (None: the defaults) and the problem ``plane``; hold goals start from the
    object's committed atlas ``atlas_dir/atlas_KIND.json`` when present (the planned use),
    and are also timed cold (a COARSE x COARSE atlas solved per query)."""
    cases, figs = [], []
    beat = Heartbeat("inverse --cases")
    for kind in CASE_OBJECTS:
        beat(f"hold {kind}")
        problem = load_problem(model, kind, params=params, plane=plane)
        ip = InverseProblem(problem, Goal("hold"))
        path = atlas_dir / f"atlas_{kind}.json"
        atlas = atlas_from_json(path, problem) if path.is_file() else None
        runs, cpu = _timed(lambda: inverse_pressures(ip, atlas))
        cold, cold_cpu = _timed(lambda: _cold(ip), 1)
        res, cold = runs[0], cold[0]
        cases.append({"goal": "hold", "object": kind, **res.summary(), **where_it_touches(res),
                      "time_ms_median": float(np.median([r.time_ms for r in runs])),
                      "cpu_ms_median": cpu, "cold_cpu_ms": cold_cpu,
                      "starts_from": str(path) if atlas is not None else f"coarse {COARSE}x{COARSE}",
                      "cold_time_ms": cold.time_ms, "cold_status": cold.status, "cold_pressures": cold.pressures,
                      "atlas_check": atlas_check(res, atlas) if atlas is not None else None})
        figs.append((f"hold {kind}", res, problem))
    free = load_problem(model, None, params=params, plane=plane)
    for text in CASE_TIPS:
        beat(text)
        ip = InverseProblem(free, parse_goal(text))
        runs, cpu = _timed(lambda: _cold(ip))
        warm, warm_cpu = _timed(lambda: inverse_pressures(ip))   # the start grid kept from the last
        res = runs[0]
        cases.append({"goal": text, "object": None, **res.summary(), **where_it_touches(res),
                      "time_ms_median": float(np.median([r.time_ms for r in runs])),
                      "cpu_ms_median": cpu, "warm_cpu_ms_median": warm_cpu,
                      "warm_time_ms_median": float(np.median([r.time_ms for r in warm])),
                      "warm_pressures": warm[0].pressures})
        figs.append((text, res, free))
    med = lambda sel: float(np.median([c["time_ms_median"] for c in cases if sel(c)]))  # noqa: E731
    cmed = lambda key, sel: float(np.median([c[key] for c in cases if sel(c)]))  # noqa: E731
    doc = {"joint": free.joint.name, "finger": finger_record(free.params), "plane": plane, "cases": cases,
           "targets": {"inverse_tip_ms": TARGET_TIP_MS, "inverse_hold_ms": TARGET_HOLD_MS},
           "measured": {"inverse_tip_ms": med(lambda c: c["goal"] != "hold"),
                        "inverse_hold_ms": med(lambda c: c["goal"] == "hold"),
                        "inverse_hold_cold_ms": float(np.median([c["cold_time_ms"] for c in cases
                                                                 if c["goal"] == "hold"])),
                        # a planner's later tip questions: the start grid kept (coarse_atlas)
                        "inverse_tip_warm_ms": float(np.median([c["warm_time_ms_median"] for c in cases
                                                                if c["goal"] != "hold"]))},
           # the same medians in process CPU time (one thread): the queries' own cost on a shared machine
           "measured_cpu": {"inverse_tip_ms": cmed("cpu_ms_median", lambda c: c["goal"] != "hold"),
                            "inverse_hold_ms": cmed("cpu_ms_median", lambda c: c["goal"] == "hold"),
                            "inverse_hold_cold_ms": cmed("cold_cpu_ms", lambda c: c["goal"] == "hold"),
                            "inverse_tip_warm_ms": cmed("warm_cpu_ms_median", lambda c: c["goal"] != "hold")},
           "tolerances": {"tip_mm": TIP_TOL_MM, "verify_tip_mm": VERIFY_TOL_MM, "regulator_MPa": REGULATOR,
                          "least_pressure_margin": HOLD_MARGIN}}
    return doc, figs


#: The keys a predictor.cli.atlas --out JSON may carry (Atlas.to_json, the CLI's spec and
#: ramp_steps, and the finger that wrote it); ``read_atlas`` refuses any other.
ATLAS_KEYS = frozenset((
    "grid", "counts", "best_hold", "time_s", "path", "solved_by", "joint", "mu", "object_weight_N", "gravity",
    "max_plane_overlap_mm", "object", "approach_MPa", "states", "p1_MPa", "p2_MPa", "state", "how",
    "normal_force_N", "friction_use", "tip_mm", "first_contact_MPa", "tau", "contact_part", "contact_face",
    "contact_point_mm", "plane_force_N", "plane_overlap_mm", "targets", "measured", "spec", "ramp_steps", "finger",
    "plane"))
ATLAS_OBJECT_KEYS = frozenset(("kind", "a_mm", "b_mm", "x_mm", "y_mm", "angle_rad", "corner_mm"))


def read_atlas(path: str | Path, problem: GripperProblem) -> Atlas:
    """The --atlas file, read as strictly as a measurement file (predictor.calibration.observations):
    valid JSON without NaN or Infinity (nor a number that overflows), no key but
    ATLAS_KEYS (and ATLAS_OBJECT_KEYS in ``object``), then predictor.planning.atlas.atlas_from_json's
    checks (an atlas of this object, joint and settings). ValueError, one line."""
    import math

    from contract.files import read_text, strict_json

    doc = strict_json(read_text(path, "atlas"), path, "atlas")
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a predictor.planning.atlas JSON (an object of keys expected)")
    for key in doc:
        if key not in ATLAS_KEYS:
            raise ValueError(f"{path}: unknown key {key!r} in the atlas (a predictor.cli.atlas --out JSON has "
                             f"{', '.join(sorted(ATLAS_KEYS))})")
    if isinstance(doc.get("object"), dict):
        for key in doc["object"]:
            if key not in ATLAS_OBJECT_KEYS:
                raise ValueError(f"{path}: unknown key object.{key!r} in the atlas (use "
                                 f"{', '.join(sorted(ATLAS_OBJECT_KEYS))})")
    stack = [("", doc)]
    while stack:
        where, v = stack.pop()
        if isinstance(v, dict):
            stack.extend((f"{where}.{k}" if where else k, w) for k, w in v.items())
        elif isinstance(v, list):
            stack.extend((f"{where}[{i}]", w) for i, w in enumerate(v))
        elif isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{path}: {where} = {v}: not a finite number")
    return atlas_from_json(path, problem)


def run_track(problem: GripperProblem, goals: list, label: str) -> tuple[dict, object]:
    """Answer the goals in order (predictor.planning.track.track); (its JSON document, the result)."""
    import os

    from predictor.planning.track import TARGET_ANY_MS, TARGET_RATE_HZ, TARGET_REACHABLE_MS, track

    load_before = list(os.getloadavg())
    res = track(problem, goals)
    doc = {**res.summary(), "label": label, "joint": problem.joint.name,
           "targets": {"reachable_warm_ms": TARGET_REACHABLE_MS, "any_warm_ms": TARGET_ANY_MS,
                       "rate_hz": TARGET_RATE_HZ, "tip_error_mm": TIP_TOL_MM},
           "load_average_before": load_before, "load_average_after": list(os.getloadavg()), "beside": BESIDE,
           "threads": torch.get_num_threads()}
    return doc, res


def _load_text(tdoc: dict) -> str:
    """The track figure's note of the machine: load averages before the run, and beside what."""
    load = ", ".join(f"{v:.1f}" for v in tdoc["load_average_before"])
    return f". Load averages {load} before the run, beside: {tdoc['beside']}"


#: What ran beside the timings (recorded with the load averages; set SOFTJOINT_BESIDE).
BESIDE = __import__("os").environ.get("SOFTJOINT_BESIDE", "not recorded (set SOFTJOINT_BESIDE)")

def track_label(problem: GripperProblem) -> str:
    """What ``make track``'s figure and JSON say produced them: the model and the problem
    the track was run on, read from the problem itself."""
    return (f"closed-loop tracking (predictor.cli.inverse --track demo): joint model {problem.joint.name}, "
            f"finger {problem.params.finger.name!r}, {'gravity' if problem.gravity else 'no gravity'}, no object, "
            + ("the fingers meeting at the plane X = 0" if meets(problem) else "one finger alone"))


def main(argv: list[str] | None = None) -> int:
    def goal_arg(text):
        try:
            parse_goal(text)
        except (ValueError, argparse.ArgumentTypeError) as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    ap = cli.Parser(prog="python -m predictor.cli.inverse", description=__doc__.split("\n\n")[0])
    ap.add_argument("--goal", type=goal_arg, help="hold | tip:X,Y[,DEG] (mm, degrees)")
    ap.add_argument("--cases", action="store_true", help="make inverse: the paper's three objects (hold) and "
                    f"the tip targets {', '.join(CASE_TIPS)}; starts from ATLAS_DIR/atlas_KIND.json")
    ap.add_argument("--atlas-dir", default="results/predictor", help="--cases: folder of the atlases")
    ap.add_output("--out", suffix=".json", help="--cases: write the JSON here")
    ap.add_argument("--object", type=object_arg, help="object spec (required for --goal hold)")
    ap.add_argument("--min-normal", type=MIN_NORMAL.arg, default=0.0, help="hold: least normal force, N")
    ap.add_argument("--least-pressure", action="store_true",
                    help=f"hold: the least pressure holding with margin {HOLD_MARGIN}")
    ap.add_argument("--box", type=box_arg, default=FULL_BOX, help="P1LO,P1HI,P2LO,P2HI MPa (bounds)")
    ap.add_argument("--atlas", help="the object's predictor.cli.atlas --out JSON for the starts (default: "
                    f"a {COARSE}x{COARSE} grid solved now)")
    ap.add_argument("--no-gravity", action="store_true", help="drop all weights")
    add_plane(ap)
    add_finger_arguments(ap)    # predictor.cli.gesture's --finger, --kinematics, --joint-weight; 2 joints
    ap.add_argument("--approach", type=approach_arg, help="hold: P1,P2 (MPa) at which the object is brought in "
                    "(default as predictor.planning.atlas), or 'zero' to ramp from 0 with the object present")
    ap.add_argument("--track", help="a file of fingertip goals X,Y[,DEG] (CSV, or JSON: a list of [X, Y(, DEG)]), "
                    "each answered warm-started from the previous answer (predictor.planning.track); 'demo': make track's "
                    "100-goal path; --out writes the answers, --plot the closed-loop figure")
    ap.add_output("--track-plot", suffix=".png", help="--cases: also write the demo track's figure here")
    ap.add_output("--track-out", suffix=".json", help="--cases: also write the demo track's answers here")
    ap.add_argument("--into", help="--track: also put the track's summary into this make inverse JSON's "
                    "'track' (make track: inverse.json, track.json and track.png from one run)")
    add_arguments(ap)
    ap.add_output("--plot", suffix=".png", help="write the answer's gesture here")
    args = ap.parse_args(argv)
    set_quiet(args.quiet)
    if args.cases:
        torch.set_num_threads(1)
        with ap.errors():
            doc, figs = run_cases(args.model, Path(args.atlas_dir), params_of(args), args.plane)
            free = load_problem(args.model, None, params=params_of(args), plane=args.plane)
            from predictor.planning.track import demo_goals, save_track_figure
            tdoc, tres = run_track(free, demo_goals(free), track_label(free))
            doc["track"] = {k: v for k, v in tdoc.items() if k != "answers"}
            if args.out:
                INVERSE.write(args.out, doc)
            if args.plot:
                save_inverse_figure(args.plot, figs)
            if args.track_plot:
                save_track_figure(args.track_plot, tres, free, tdoc["label"], _load_text(tdoc))
            if args.track_out:
                TRACK.write(args.track_out, tdoc)
        cli.print_fields({**doc["measured"], **{f"track_{k}": doc["track"][k] for k in
                                             ("goals", "median_ms", "p95_ms", "max_tip_error_mm", "verified")}},
                      args.json)
        return 0
    if args.track is not None:
        if args.goal is not None or args.object or args.approach is not None:
            ap.error("--track answers fingertip goals without an object: drop --goal, --object and --approach")
        torch.set_num_threads(1)
        with ap.errors():
            from predictor.planning.track import demo_goals, load_track, save_track_figure
            problem = load_problem(args.model, None, gravity=not args.no_gravity, params=params_of(args),
                                   plane=args.plane)
            goals = demo_goals(problem) if args.track == "demo" else load_track(args.track)
            label = track_label(problem) if args.track == "demo" else f"predictor.cli.inverse --track {args.track}"
            into = INVERSE.load(args.into) if args.into else None    # checked before the run
            tdoc, tres = run_track(problem, goals, label)
            if args.out:
                TRACK.write(args.out, tdoc)
            if args.plot:
                save_track_figure(args.plot, tres, problem, label, _load_text(tdoc))
            if into is not None:
                into["track"] = {k: v for k, v in tdoc.items() if k != "answers"}
                INVERSE.write(args.into, into)
        cli.print_fields(tdoc if args.json else {k: v for k, v in tdoc.items() if k != "answers"}, args.json)
        if tdoc["unreachable"]:
            print(f"{ap.prog}: {tdoc['unreachable']} of {tdoc['goals']} goals unreachable: answered with the "
                  "closest reachable tip (status unreachable)", file=sys.stderr)
            return 1
        return 0
    if args.goal is None:
        ap.error("give --goal (or --cases, --track)")
    goal = dataclasses.replace(parse_goal(args.goal), min_normal=args.min_normal, least_pressure=args.least_pressure)
    if goal.kind == "hold" and not args.object:
        ap.error("--goal hold needs an --object")
    if goal.kind == "tip" and (args.min_normal or args.least_pressure):
        ap.error("--min-normal and --least-pressure apply to --goal hold only")
    if args.approach is not None and goal.kind != "hold":
        ap.error("--approach applies to --goal hold only (the pressures at which the object is brought in)")
    if args.approach not in (None, "zero") and len(args.approach) != 2:
        ap.error(f"--approach: {len(args.approach)} values for the inverse's two joints (P1,P2 MPa, or 'zero')")
    approach = None if args.approach == "zero" else args.approach or DEFAULT
    torch.set_num_threads(1)
    with ap.errors():
        problem = load_problem(args.model, args.object, gravity=not args.no_gravity, params=params_of(args), mu=args.mu,
                               object_weight=args.object_weight, approach=approach, plane=args.plane)
        ip = InverseProblem(problem, goal, args.box)
        atlas = read_atlas(args.atlas, problem) if args.atlas else None
        res = inverse_pressures(ip, atlas)
        if args.plot:
            save_inverse_figure(args.plot, [(args.goal, res, problem)])
    cli.print_fields({**res.summary(), "goal": args.goal, "object": args.object, "finger": finger_record(params_of(args)),
                   "plane": args.plane}, args.json)
    if res.status != "feasible":
        print(f"{ap.prog}: infeasible: {res.reason}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
