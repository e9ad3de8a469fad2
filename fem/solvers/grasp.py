"""FEM grasps: the whole finger holding a rigid object, along the predictor's history.

    python -m fem.cli.finger --p1 0.2 --p2 0.25 --object circle [--approach -0.15,0]
                         [--mu 0.3] [--object-weight 0.2] [--no-plane] [--xdmf out.xdmf] --json

(the command line is fem.cli.finger's: a gesture without --object, a grasp with it).

Model: the finger of fem.solvers.finger (gravity on) with the object's contact of
fem.physics.object_contact (the predictor's law: penalty k_c per length spread over the part's
width, one friction ratio lambda that carries W/2, slip when |lambda| > mu; contract.grasp,
docs/fem-grasps.md). History, as the predictor's (docs/gripper.md §9):

1. the approach: from the unloaded finger to (approach pressures, gravity) without the
   object (its term inactive);
2. the object is brought in: refused (ObjectCutsFinger) when a candidate node of the
   finger's surface then lies inside it;
3. the ramp: the pressures go in a straight line to the target (the load path's steps
   and cut-backs, fem.solvers.load_path), with the object.

The mirror finger's contact at X = 0 (fem.physics.plane_contact; fem.solvers.finger's default, the
gripper; ``--no-plane``: one finger alone) acts throughout the history, approach included,
and the record carries ``plane_force_N`` and ``plane_overlap_mm`` beside ``"plane": true``.

Outputs (GraspResult.summary), with the predictor's meanings: ``tip`` [X, Y] mm,
``tip_angle_deg``, ``state`` (no_contact, holds, slips; not_converged), ``contact_force_N``
(the full finger's normal force), ``friction_N``, ``friction_use`` = |lambda|/mu, ``slip``,
``contact_point_mm`` (force-weighted), ``contact_patch`` (the surface nodes inside the
object: count, extent, parts), ``penetration_mm``, ``object_force_N`` (the object's
resultant on the finger, global) and ``base_force_N``: the clamp's reaction, the sum of the
FEM residual over the clamped dofs (x 2: the half-model), which balances the finger's
weight, the object's force and the plane's (the finger's equilibrium, a check of the
coupling).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from mpi4py import MPI

from contract.grasp import FRICTION, OBJECT_WEIGHT, ObjectSpec
from fem.solvers.finger import FingerLoad, FingerResult, FingerSolver
from fem.physics.finger import closed_tags
from fem.mesh.geometry import FingerGeometry
from fem.physics.object_contact import ObjectContact


class ObjectCutsFinger(ValueError):
    """The object, brought in at the approach gesture, intersects the finger."""


@dataclass
class GraspResult:
    """One FEM grasp: the finger's figures (FingerResult of the ramp), the contact's
    (ObjectContact.state), the base reaction (N, global, full finger) and the history."""

    finger: FingerResult
    approach: tuple[float, ...]
    contact: dict = field(default_factory=dict)
    base_force: list | None = None
    clearance: float | None = None          # mm, the object's gap to the approach gesture
    wall_time: float = 0.0

    @property
    def state(self) -> str:
        return self.contact.get("state", "not_converged") if self.finger.converged else "not_converged"

    def summary(self) -> dict:
        out = self.finger.summary()
        keys = ("contact_force_N", "friction_N", "friction_use", "slip", "friction_ratio", "contact_point_mm",
                "penetration_mm")
        c = self.contact if self.finger.converged else {}
        out.update({k: c.get(k) for k in keys})
        out.update(state=self.state, approach_MPa=list(self.approach), contact_patch=c.get("patch"),
                   object_force_N=c.get("force_N"), base_force_N=self.base_force if c else None,
                   approach_clearance_mm=self.clearance, grasp_wall_time_s=self.wall_time)
        return out


class GraspSolver:
    """A finger FEM with an object (module docstring), and with ``plane`` the mirror
    finger's contact at X = 0 (fem.physics.plane_contact) throughout its history. Collective."""

    def __init__(self, geometry: FingerGeometry, obstacle: ObjectSpec, comm: MPI.Comm = MPI.COMM_WORLD,
                 formulation: str | None = None, mu: float = FRICTION, weight: float = OBJECT_WEIGHT,
                 plane: bool = False):
        self.geometry, self.obstacle, self.mu, self.weight = geometry, obstacle, mu, weight
        kwargs = {} if formulation is None else {"formulation": formulation}
        self.fem = FingerSolver(geometry, comm, extra_contact=self._object_term, plane=plane, **kwargs)
        self.comm = comm

    def _object_term(self, problem) -> ObjectContact:
        finger = self.geometry.finger
        self.object = ObjectContact(problem.u, problem.mesh_data, finger, self.geometry.joint.width, self.obstacle,
                                    closed_tags(finger), mu=self.mu, weight=self.weight)
        return self.object

    def base_force(self) -> list[float]:
        """The clamp's reaction (N, global, full finger; FingerSolver.base_force): it
        balances the finger's weight, the object's force and the plane's."""
        return self.fem.base_force()

    def clearance(self) -> float:
        """The least signed distance (mm) of the finger's candidate surface nodes from the
        object at the current state (negative: the object cuts the finger)."""
        pts, _ = self.object.nodes(self.fem.u)
        mine = float(self.obstacle.signed_distance(pts).min()) if len(pts) else math.inf
        return self.comm.allreduce(mine, op=MPI.MIN)

    def solve(self, pressures: tuple[float, ...], approach: tuple[float, ...]) -> GraspResult:
        """The grasp's history (module docstring) from the unloaded finger; raises
        ObjectCutsFinger when the object intersects the approach gesture."""
        t0 = time.perf_counter()
        self.fem.reset()
        self.object.active = False
        first = self.fem.follow(FingerLoad(tuple(approach), True))
        if not first.converged:
            first.reason = f"the approach gesture {list(approach)} MPa did not converge: {first.reason}"
            return GraspResult(first, tuple(approach), wall_time=time.perf_counter() - t0)
        gap = self.clearance()
        if gap < 0:
            raise ObjectCutsFinger(f"the object cuts the finger by {-gap:.3g} mm at the approach gesture "
                                   f"{list(approach)} MPa: place it lower or open the approach")
        self.object.active = True       # no node touches it here: the tangent in hand stays exact
        result = self.fem.follow(FingerLoad(tuple(pressures), True))
        contact = self.object.state(self.fem.u) if result.converged else {}
        base = self.base_force() if result.converged else None
        return GraspResult(result, tuple(approach), contact, base, gap, time.perf_counter() - t0)


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.cli.finger --object SPEC")
