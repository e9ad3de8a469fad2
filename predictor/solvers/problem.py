"""One validation of a gripper question, shared by every tool and the Python API.

Each input has one check (a ``Check``: bounds and units), used as the argparse type of
its flag (``Check.arg``: "--mu: 'nan' is not a finite number (allowed (0, 5])") and by
the API (``Check.value``: "mu: ..."), so a value refused by one is refused by the other
with the same reason. ``load_problem`` builds the GripperProblem of predictor.cli.gesture's
defaults (joint from predictor.defaults, object from a spec, approach gesture APPROACH)
and refuses an object the model cannot represent (contract.grasp.object_error) or that cuts
through the fingers where it is brought in (``placement_error``), and a finger that no
gesture can be solved for (``finger_error``: its weights load a joint beyond the joint
model's box in the hanging pose, or its mounts are so close that the two fingers overlap
at X = 0), so that every tool says why instead of "not converged". The gripper settles
at the approach gesture without the object, so an object overlapping that gesture
would start the grasp inside the fingers.

One problem, said (issue 56 §1): every tool and the API solve the gripper by default, the
right finger with the mirror finger's contact at X = 0 (``plane=True``, the penalty of
predictor.model.statics.ContactParams.plane_stiffness), as fem.finger does; ``--no-plane``
(``add_plane``; the API's ``plane=False``) solves one finger alone, which may cross X = 0
as the paper's do (predictor.model.statics.apart). Every result names its problem (``"plane":
true|false``, ``problem_words``), and a comparison of two results refuses two problems
(``same_problem``).

The flags every gesture tool shares are defined here once: ``add_finger_arguments``
(--finger, --kinematics, --joint-weight), ``approach_arg``, ``OBJECT_HELP`` and
``add_arguments`` (--model, --mu, --object-weight, --quiet).

Data flow: model, object spec, options -> load_problem -> GripperProblem (checked).
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass

import torch

from contract import cli
from contract.finger import DEFAULT_FINGER, finger_arg
from contract.spec import INPUT_BOX, PRESSURE_LIMIT
from predictor.model.gripper import (DEFAULT_JOINT_WEIGHT, DEFAULT_KINEMATICS, DEFAULT_OUTLINE, JOINT_WEIGHTS, KINEMATICS,
                                     OUTLINES, GripperParams,
                                     check_pressures, outline_vertices, rot)
from predictor.model.joint import check_finger, load_joint
from predictor.solvers.solve import APPROACH, approach_for, solve
from predictor.model.statics import ContactParams, GripperProblem, apart, meets, parse_object, plane_overlap

FULL_BOX = (-PRESSURE_LIMIT, PRESSURE_LIMIT, -PRESSURE_LIMIT, PRESSURE_LIMIT)


@dataclass(frozen=True)
class Check:
    """A number's bounds: [lo, hi] (open at lo with open_lo), unit, integer."""

    lo: float | None
    hi: float | None
    unit: str = ""
    integer: bool = False
    open_lo: bool = False

    @property
    def arg(self):
        """The argparse type of the flag."""
        return cli.number(self.lo, self.hi, self.unit, self.integer, self.open_lo)

    def value(self, name: str, v) -> float:
        """The API's check of value v of parameter ``name``: ValueError (one line) with the
        flag's reason, prefixed by the name."""
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (self.integer and float(v) != int(v)):
            raise ValueError(f"{name}: {v!r} is not {'an integer' if self.integer else 'a finite number'}")
        try:
            return self.arg(repr(int(v)) if self.integer else repr(float(v)))
        except argparse.ArgumentTypeError as exc:
            why = str(exc)
        try:   # the reason as the CLI words it for the same value typed short (0, not 0.0)
            self.arg(f"{v:g}")
        except argparse.ArgumentTypeError as exc:
            why = str(exc)
        raise ValueError(f"{name}: {why}")


MU = Check(0.0, 5.0, open_lo=True)                 # friction coefficient of the contact law
OBJECT_WEIGHT = Check(0.0, 10.0, "N")              # the object's weight
GRID = Check(2, 201, integer=True)                 # atlas grid points per axis
MIN_NORMAL = Check(0.0, 10.0, "N")                 # inverse --min-normal


def check_box(box) -> tuple[float, float, float, float]:
    """A pressure box (P1LO, P1HI, P2LO, P2HI) MPa: four finite numbers within |P| <= 0.3,
    P1LO < P1HI and P2LO < P2HI; ValueError (one line) otherwise."""
    try:
        box = tuple(float(v) for v in box)
    except (TypeError, ValueError):
        raise ValueError(f"box {box!r}: expected 4 numbers P1LO,P1HI,P2LO,P2HI (MPa)") from None
    if len(box) != 4:
        raise ValueError(f"box {box!r}: expected 4 numbers P1LO,P1HI,P2LO,P2HI (MPa)")
    one = Check(-PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa")
    box = tuple(one.value("box", v) for v in box)
    if not (box[0] < box[1] and box[2] < box[3]):
        raise ValueError(f"box {box}: expected P1LO < P1HI and P2LO < P2HI")
    return box


def box_arg(text: str) -> tuple[float, float, float, float]:
    """--box P1LO,P1HI,P2LO,P2HI MPa (``check_box``)."""
    box = cli.numbers(4, -PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa")(text)
    if not (box[0] < box[1] and box[2] < box[3]):
        raise argparse.ArgumentTypeError(f"{text!r}: expected P1LO < P1HI and P2LO < P2HI")
    return box


def object_arg(text: str) -> str:
    """--object: the spec, checked while parsing (contract.grasp.parse_object), so a bad one is
    refused before any model is loaded."""
    try:
        parse_object(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def placement_error(problem: GripperProblem) -> str | None:
    """Why the object is badly placed, or None: it intersects the fingers where it is
    brought in, i.e. at the approach gesture (or at zero pressure without one), a
    gravity-loaded equilibrium without the object. (The default objects do intersect the
    zero-pressure gesture, by design: statics.Obstacle.)"""
    if problem.obstacle is None:
        return None
    free = GripperProblem(problem.joint, problem.params, None, problem.contact, problem.gravity)
    p = (0.0,) * problem.n_joints if problem.approach is None else tuple(problem.approach)
    res = solve(free, torch.tensor([p], dtype=torch.float64))
    if not bool(res.converged[0]):  # no gesture to check against: never guess one
        return f"the gesture without the object at ({', '.join(f'{v:g}' for v in p)}) MPa did not converge"
    with torch.no_grad():
        pen = float(problem.residual(res.pressures, res.tau).contact.penetration[0])
    if pen > 0:
        where = ("zero pressure" if problem.approach is None else
                 f"the approach gesture ({', '.join(f'{v:g}' for v in p)}) MPa")
        return (f"the object intersects the fingers at {where} by {pen:.2f} mm: place it lower or "
                "farther from the fingers")
    return None


def hanging_loads(problem: GripperProblem) -> torch.Tensor:
    """(J, 3) [F1 N, F2 N, M N·mm]: the loads each joint carries in the finger's unloaded
    hanging pose (zero pressure, every joint at its load-free shape), from the parts'
    weights alone (no object, no plane X = 0). A static estimate: Equation 1's residual at
    tau = 0 is minus the distal loads, turned into each joint's frame."""
    free = apart(GripperProblem(problem.joint, problem.params, None, problem.contact, problem.gravity))
    J = problem.n_joints
    with torch.no_grad():
        st = free.residual(torch.zeros(1, J, dtype=torch.float64), torch.zeros(1, J, 3, dtype=torch.float64))
    force = rot(-st.pose.theta, -st.residual[..., :2])
    return torch.cat((force, -st.residual[..., 2:]), -1)[0]


def finger_error(problem: GripperProblem) -> str | None:
    """Why no gesture of ``problem``'s finger can be trusted, or None (one line):

    - with gravity, a joint whose load in the hanging pose (``hanging_loads``) leaves the
      joint model's box |F1|, |F2| <= 3 N, |M| <= 100 N·mm: the solvers keep tau in that
      box, so they fail at every pressure (a finger of 1 N parts, 3.5 N on joint 1: none
      of 15 pressures over the box converged, after about a minute of ramping; of 0.8 N
      parts, 2.8 N: all 15 did);
    - where the fingers meet at X = 0, a finger whose outline already crosses X = 0 in
      that pose (base_gap too small): the plane cannot push the mounted base back, so the
      two fingers would overlap at every pressure."""
    finger = problem.params.finger
    if problem.gravity:
        box = INPUT_BOX[1:]
        out = [f"joint {j + 1} {name} = {v:.2f} {unit}" for j, load in enumerate(hanging_loads(problem).tolist())
               for name, v, lim, unit in zip(("F1", "F2", "M"), load, box, ("N", "N", "N·mm")) if abs(v) > lim]
        if out:
            return (f"finger {finger.name!r} is too heavy for its joints: hanging at zero pressure under the "
                    f"parts' weights, {', '.join(out)}, beyond the joint model's box |F1|, |F2| <= {box[0]:g} N, "
                    f"|M| <= {box[2]:g} N·mm, so no gesture can be solved (lighten the parts, or solve without "
                    "gravity)")
    if meets(problem):
        J = problem.n_joints
        with torch.no_grad():
            pose = problem.pose(torch.zeros(1, J, dtype=torch.float64), torch.zeros(1, J, 3, dtype=torch.float64))
            overlap = float(plane_overlap(outline_vertices(pose, problem.params.layout))[0])
        if overlap > 0:
            return (f"finger {finger.name!r}: base_gap = {finger.base_gap:g} mm puts the two fingers across each "
                    f"other (the right one crosses X = 0 by {overlap:.1f} mm hanging at zero pressure): the "
                    f"fingers meet at X = 0, so base_gap must be at least {finger.base_gap + 2 * overlap:.1f} mm")
    return None


#: --object's help: the keys a user can change (``x`` exists only as x=0: the model mirrors
#: one finger, contract.grasp.object_error, so it is not advertised).
OBJECT_HELP = ("circle[:r=,y=] | ellipse[:a=,b=,y=,deg=] | rectangle[:w=,h=,y=,deg=,rc=] (mm, deg; centred on the "
               "gripper's axis X = 0)")
PRESSURE = cli.number(-PRESSURE_LIMIT, PRESSURE_LIMIT, "MPa")


def pressure_list(text: str) -> tuple[float, ...]:
    """P1,P2[,..] MPa, each a finite number within ±0.3 (the count is checked against the finger)."""
    return tuple(PRESSURE(p.strip()) for p in text.split(","))


def approach_arg(text: str):
    """--approach: ``zero`` or P1,..,PJ in MPa."""
    return "zero" if text.strip().lower() == "zero" else pressure_list(text)


def add_finger_arguments(ap) -> None:
    """The finger's flags, the same on every tool that solves gestures: --finger,
    --kinematics, --joint-weight, --outline (predictor.model.gripper.GripperParams)."""
    ap.add_argument("--finger", type=finger_arg, default=str(DEFAULT_FINGER),
                    help="finger description file (TOML, contract.finger; default contract/fingers/paper.toml)")
    ap.add_argument("--kinematics", choices=KINEMATICS, default=DEFAULT_KINEMATICS,
                    help="a part leaves a joint along its last anchors' chord (tangent, the paper's) "
                    "or its cap face (cap)")
    ap.add_argument("--joint-weight", choices=JOINT_WEIGHTS, default=DEFAULT_JOINT_WEIGHT,
                    help="a joint's weight at its anchors' mean (lumped) or half at each end (split)")
    ap.add_argument("--outline", choices=OUTLINES, default=DEFAULT_OUTLINE,
                    help="a joint's outline: a band of its height (band) or with its pressurised cells' "
                    "bulge, its joint file's [outline] (bulged)")


def params_of(args) -> GripperParams:
    """The GripperParams of add_finger_arguments' flags."""
    return GripperParams(args.finger, kinematics=args.kinematics, joint_weight=args.joint_weight,
                         outline=args.outline)


def add_arguments(ap, model_help: str = "") -> None:
    """The flags of every planning tool: --model, --mu, --object-weight, --quiet."""
    ap.add_argument("--model", help="joint surrogate checkpoint, or 'analytic' (default: the committed surrogate, "
                    "results/surrogate/improved.pt of this package or of $SOFTJOINT_RESULTS)" + model_help)
    ap.add_argument("--mu", type=MU.arg, help=f"friction coefficient of the contact law (default {ContactParams.mu})")
    ap.add_argument("--object-weight", type=OBJECT_WEIGHT.arg,
                    help=f"the object's weight, N (default {GripperParams.object_weight})")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def finger_record(params: GripperParams) -> dict:
    """The finger a tool answered for, as its JSON records it (name, file digest, chain
    options): predictor.planning.atlas's and predictor.cli.inverse's "finger"."""
    return {"name": params.finger.name, "sha256": params.finger.digest, "kinematics": params.kinematics,
            "joint_weight": params.joint_weight, "outline": params.outline}


def add_plane(ap) -> None:
    """--no-plane (``args.plane``, default True): one finger alone instead of the gripper
    (module docstring); the same flag as fem.finger's."""
    ap.add_argument("--no-plane", dest="plane", action="store_false",
                    help="one finger alone, which may cross X = 0 (default: the gripper, the right finger "
                         "against the mirror finger's contact at X = 0, as fem.finger)")


def problem_words(plane: bool) -> str:
    """The problem in words, for one-line messages."""
    return "the gripper (the plane X = 0)" if plane else "one finger alone (--no-plane)"


def same_problem(first: bool, second: bool, where: str = "",
                 names: tuple[str, str] = ("the FEM", "the predictor")) -> None:
    """Refuse to compare two results of different problems: ValueError (one line) when
    ``first`` and ``second`` (each: solved with the plane X = 0) differ, naming both
    (``names``) after ``where`` (e.g. a case's file)."""
    if bool(first) != bool(second):
        raise ValueError(f"{where + ': ' if where else ''}{names[0]} solved {problem_words(first)}, "
                         f"{names[1]} {problem_words(second)}: different problems, not compared")


DEFAULT = "default"


def load_problem(model: str | None, spec: str | None, gravity: bool = True, params: GripperParams | None = None,
                 mu: float | None = None, object_weight: float | None = None,
                 approach=DEFAULT, joint=None, plane: bool = True) -> GripperProblem:
    """The GripperProblem of ``predictor.cli.gesture``'s defaults. model: a checkpoint path,
    "analytic", or None (the committed surrogate, predictor.defaults); joint: an already
    loaded JointModel instead; spec: an object spec (None: no object); params: finger and
    chain options (None: the paper's finger, default options); mu, object_weight (N):
    the contact law's friction coefficient and the object's weight (None: the defaults,
    0.3 and GripperParams.object_weight); approach: DEFAULT (APPROACH, or approach_for(J),
    with an object; none without), None (ramp from zero) or J pressures MPa; plane: the
    gripper, the right finger against the mirror finger's contact at X = 0 (True, the
    default), or one finger alone (False: predictor.model.statics.apart). ValueError
    (one line) for any bad value, for a model of another joint than the finger's joint
    parts name (predictor.model.joint.check_finger), for a finger no gesture can be solved for
    (``finger_error``: joints loaded beyond the model's box by the parts' weights, fingers
    overlapping at their mounts) and for an object badly placed (``placement_error``)."""
    params = params or GripperParams()
    if object_weight is not None:
        params = dataclasses.replace(params, object_weight=OBJECT_WEIGHT.value("object_weight", object_weight))
    contact = ContactParams() if mu is None else ContactParams(mu=MU.value("mu", mu))
    obstacle = parse_object(spec) if spec else None
    if approach == DEFAULT:
        approach = (APPROACH if params.n_joints == 2 else approach_for(params.n_joints)) if spec else None
    elif approach is not None:
        check_pressures(torch.as_tensor(approach, dtype=torch.float64).reshape(1, -1))
    if joint is None:
        joint = load_joint(model, params.finger)
    else:
        check_finger(joint, params.finger)   # the model must be of the finger's joints
    if not isinstance(plane, bool):
        raise ValueError(f"plane: {plane!r} is not True or False")
    problem = GripperProblem(joint, params, obstacle=obstacle, contact=contact, gravity=gravity,
                             approach=None if approach is None else tuple(approach))
    if not plane:
        problem = apart(problem)
    why = finger_error(problem) or placement_error(problem)
    if why:
        raise ValueError(why)
    return problem
