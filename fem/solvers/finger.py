"""The whole finger in DOLFINx: the ground truth for the gesture predictor (issue 14).

Its command line is fem.cli.finger (``python -m fem.cli.finger``). :class:`FingerSolver`
meshes a finger (fem.mesh.build), builds its problem (fem.physics.finger.finger_problem: the
model, its formulation and loads, units mm, N, MPa, N·mm; angles rad in code, degrees in
the JSON), adds the plane X = 0 where the gripper's fingers meet (fem.physics.plane_contact)
and any extra contact (fem.solvers.grasp's object), and solves it along the load path
(fem.solvers.load_path.LoadPathSolver; FINGER_CONFIG's longer Newton budget).

Outputs, in the predictor's global frame (docs/gripper.md; the right finger, base mount at
(base_gap/2, 0), finger frame rotated by base_angle): x_global = B + Rot(base_angle)·(x + u)
for the centre line points (z = 0, y = 0). Per joint: its n_j anchors (its joint
description's count: 10 for the paper's, 8 for soft4), proximal centre,
proximal orientation theta (the rotation of the part it is bonded to), its distal cap's
orientation (``end_angle``, the direction the next part leaves along) and its chord angle
from the last two anchors (the paper's tangent connection), plus the joint-frame anchors,
phi_end and cap rotation comparable with the single-joint FEM. A solve that does not
converge reports no figures (null in the JSON) and exits 1 with its reason on stderr. The fingertip is the centre
of the last part's distal face, ``tip_angle`` the orientation of the last part. Rotations
of the (stiff) parts are volume averages of atan2(F_yx - F_xy, F_xx + F_yy).

The problem (issue 56 §1): by default the gripper, the right finger where it meets the
mirror finger (FingerSolver(plane=True)): the mirror finger's contact at X = 0, the
predictor's frictionless penalty k_p s(max(0, -X)) on the inner and end faces
(fem.physics.plane_contact), the problem ``python -m predictor.cli.gesture`` solves by default.
``--no-plane`` (FingerSolver(plane=False), the class's default) solves one finger alone,
which passes through X = 0 as in the paper (``--plane``, the default now, is accepted for
one release). The record says which (``"plane": true|false``); with the plane it gains
``plane_force_N`` (N, the plane's push along +X on the full finger), ``plane_overlap_mm``
(how far its surface crosses X = 0) and ``base_force_N`` (the clamp's reaction, global, N:
it balances the weights and the plane's push), null without it.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from dolfinx import fem
from dolfinx.fem.petsc import assemble_vector
from mpi4py import MPI
from petsc4py import PETSc

from contract.finger import FingerSpec, same_finger
from contract.joint import MaterialLaw
from contract.spec import check_box
from fem.mesh.build import create_mesh
from fem.mesh.discretisation import FORMULATION, SolverConfig
from fem.mesh.geometry import FingerGeometry, finger_tags, pressure_limits
from fem.physics.contact import ContactTerms
from fem.physics.finger import RigidMaterial, anchor_counts, closed_tags, finger_problem, rotation_matrix
from fem.physics.plane_contact import PlaneContact
from fem.physics.problem import Material, Problem
from fem.solvers.joint import config_for
from fem.solvers.load_path import LoadPathSolver

log = logging.getLogger("softjoint.fem")


@dataclass(frozen=True)
class FingerLoad:
    """Pressures (MPa, signed, one per joint, base to tip) and gravity on/off."""

    pressures: tuple[float, ...]
    gravity: bool = True

    def as_array(self) -> np.ndarray:
        return np.array([*self.pressures, 1.0 if self.gravity else 0.0])


@dataclass
class FingerResult:
    """One finger solve, global frame (module docstring): mm, rad, s."""

    load: FingerLoad
    converged: bool
    tip: np.ndarray                 # (2,)
    tip_angle: float
    anchors: np.ndarray | tuple     # (n_joints, n, 2) global; per joint (n_j, 2): per_joint
    proximal: np.ndarray            # (n_joints, 2) global proximal centres
    theta: np.ndarray               # (n_joints,) proximal orientation
    end_angle: np.ndarray           # (n_joints,) orientation of the distal cap
    chord_angle: np.ndarray         # (n_joints,) atan2 of r_n - r_(n-1)
    local_anchors: np.ndarray | tuple   # as anchors, in each joint's frame
    newton_iterations: list[int] = field(default_factory=list)
    load_steps: int = 0
    cutbacks: int = 0
    factorisations: int = 0
    factorisation_s: float = 0.0    # wall seconds in them (tangent assembly included)
    krylov_iterations: int = 0
    krylov_s: float = 0.0           # wall seconds in GMRES
    wall_time: float = 0.0
    cpu_time: float = 0.0           # this process's CPU time: one core's share under load
    reason: str = ""
    plane: dict | None = None       # with the plane X = 0: PlaneContact.state and base_force_N

    def plane_figures(self) -> dict:
        """plane_force_N (N), plane_overlap_mm (mm) and base_force_N (N, global) of a
        converged solve with the plane X = 0 (fem.physics.plane_contact); each null otherwise."""
        plane = self.plane if self.converged and self.plane is not None else {}
        return {k: plane.get(k) for k in ("plane_force_N", "plane_overlap_mm", "base_force_N")}

    def summary(self) -> dict:
        """JSON-ready figures (degrees for angles); ``tip`` and ``tip_angle_deg`` mean
        what they mean in ``predictor.cli.gesture --json``. A solve that did not converge has
        no figures: tip, angles and joints are null (the state it stopped in is not an
        answer), ``reason`` says why. ``plane_force_N``, ``plane_overlap_mm`` and
        ``base_force_N``: the plane X = 0's figures (plane_figures), null without it."""
        out = {"pressures_MPa": list(self.load.pressures), "gravity": self.load.gravity,
               "converged": self.converged, "tip": None, "tip_angle_deg": None,
               "joint_end_angle_deg": None, "joints": None}
        if self.converged:
            out.update(tip=self.tip.tolist(), tip_angle_deg=math.degrees(self.tip_angle),
                       joint_end_angle_deg=np.degrees(self.end_angle).tolist(), joints=self._joints())
        return {**out, **self.plane_figures(), "newton_iterations": self.newton_iterations,
                "iterations": int(sum(self.newton_iterations)), "load_steps": self.load_steps,
                "cutbacks": self.cutbacks, "factorisations": self.factorisations,
                "factorisation_s": self.factorisation_s, "krylov_iterations": self.krylov_iterations,
                "krylov_s": self.krylov_s, "wall_time_s": self.wall_time, "cpu_time_s": self.cpu_time,
                "reason": self.reason}

    def _joints(self) -> list[dict]:
        """Per joint: anchors, proximal centre and the angles of the module docstring."""
        return [{"anchors_mm": np.round(self.anchors[j], 6).tolist(),
                 "proximal_mm": self.proximal[j].tolist(),
                 "theta_deg": math.degrees(self.theta[j]),
                 "end_angle_deg": math.degrees(self.end_angle[j]),
                 "chord_angle_deg": math.degrees(self.chord_angle[j]),
                 "cap_rotation_deg": math.degrees(self.end_angle[j] - self.theta[j]),
                 "phi_end_deg": math.degrees(self.chord_angle[j] - self.theta[j]),
                 "local_anchors_mm": np.round(self.local_anchors[j], 6).tolist()}
                for j in range(len(self.theta))]


#: The joint's controls with a longer Newton budget and a finer last step: a pressure step
#: swings the 200 mm finger through a large rotation under its weight, so a step often
#: needs 9-12 iterations (the joint's limit was 12), and near full load in the grasp region
#: (0.2, 0.2) MPa with gravity a step of 1/256 of the path still failed at that limit
#: (with these controls it converges).
FINGER_CONFIG = SolverConfig(max_it=25, min_step=1.0 / 1024)


def per_joint(arrays: list[np.ndarray]):
    """Per-joint arrays as one (n_joints, ...) array when their shapes agree (joints of
    one anchor count, every finger before joint files could differ), else a tuple."""
    return np.stack(arrays) if len({a.shape for a in arrays}) == 1 else tuple(arrays)


def _spent(solver, before: dict) -> dict:
    """The linear algebra's work (LoadPathSolver.work) since ``before``."""
    return {k: v - before[k] for k, v in solver.work().items()}


class FingerSolver:
    """Static large-deflection solve of one whole finger (module docstring):
    :func:`finger_problem` handed to a :class:`fem.solvers.load_path.LoadPathSolver`; every joint
    of its own law unless ``material`` is given. ``formulation`` defaults to the
    production one (fem.mesh.discretisation.FORMULATION); ``config`` is raised to the
    hexahedra's quadrature on hexahedral joints (fem.solvers.joint.config_for). ``plane``: the
    mirror finger's contact at X = 0 (fem.physics.plane_contact, ``plane_term``), beside the
    valley contact and ``extra_contact``'s term (e.g. fem.solvers.grasp's object)."""

    def __init__(self, geometry: FingerGeometry, comm: MPI.Comm = MPI.COMM_WORLD,
                 material: MaterialLaw | Material | None = None, rigid: RigidMaterial = RigidMaterial(),
                 config: SolverConfig = FINGER_CONFIG, formulation: str = FORMULATION,
                 extra_contact: Callable[[Problem], object] | None = None, plane: bool = False):
        config = config_for(geometry, config)
        self.finger, self.geometry, self.config = geometry.finger, geometry, config
        self.formulation = formulation
        self.mesh_data = create_mesh(geometry, comm)
        self.problem = finger_problem(geometry, self.mesh_data, material, rigid,
                                      formulation=formulation, **config.discretisation())
        extra = [] if extra_contact is None else [extra_contact(self.problem)]
        self.plane_term = None
        if plane:
            self.plane_term = PlaneContact(self.problem.u, self.mesh_data, self.finger, geometry.joint.width,
                                           closed_tags(self.finger))
            extra.append(self.plane_term)
        if extra:
            self.problem = dataclasses.replace(self.problem, contact=ContactTerms(self.problem.contact, *extra))
        self.solver = LoadPathSolver(self.problem, config)
        self.u, self.V, self.comm = self.problem.u, self.problem.V, self.problem.comm
        self.contact, self.probe_points = self.problem.contact, self.problem.probe_points
        self._reaction = None       # (residual form, clamped dofs): base_force, built on first use

    # The solver's running totals and state, read through (diagnostics).
    factorisations = property(lambda self: self.solver.factorisations)
    krylov_iterations = property(lambda self: self.solver.krylov_iterations)

    def reset(self) -> None:
        """Return to the undeformed, unloaded state."""
        self.solver.reset()

    def mesh_info(self) -> dict:
        """The solver's mesh figures (LoadPathSolver.mesh_info) and ``mesh``, the joints'
        mesh in words (FingerGeometry.mesh: ``hexN``, ``H`` or ``H:W``), so that a record of
        hexahedra never reads as one of tetrahedra."""
        return {**self.solver.mesh_info(), "mesh": self.geometry.mesh}

    def displacement(self) -> fem.Function:
        """The displacement u (mm) in its own vector space (a copy, for the mixed form)."""
        return self.problem.displacement()

    def _clamped_dofs(self) -> tuple[np.ndarray, np.ndarray]:
        """Owned local (x, y) dofs of the clamped base face."""
        problem = self.problem
        W = problem.u.function_space
        U = W.sub(0) if problem.displacement_space is not None else W
        ft, fdim = problem.mesh_data.facet_tags, W.mesh.topology.dim - 1
        owned = W.dofmap.index_map.size_local * W.dofmap.index_map_bs
        out = []
        for c in (0, 1):
            dofs = fem.locate_dofs_topological(U.sub(c), fdim, ft.find(finger_tags(self.finger)["proximal"]))
            out.append(dofs[dofs < owned])
        return tuple(out)

    def base_force(self) -> list[float]:
        """The clamp's reaction (N, global, full finger) at the current state: the residual
        of the finger's internal forces, weights and pressures summed over the clamped
        dofs (x 2: the half-model). The contact terms (valleys, object, plane) act away from
        the clamp, so at equilibrium it balances the weights and the contact forces."""
        if self._reaction is None:
            self._reaction = (fem.form(self.problem.residual()), self._clamped_dofs())
        form, clamped = self._reaction
        b = assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        local = np.array([b.array_r[d].sum() for d in clamped])
        b.destroy()
        total = 2.0 * self.comm.allreduce(local, op=MPI.SUM)
        return (rotation_matrix(self.finger.base_angle) @ total).tolist()

    def rotation(self, k: int) -> float:
        """Rotation (rad) about +z of part k's rigid body: a rigid part, or a joint's cap."""
        return self.solver.average(f"rotation{k}")

    def sensitivities(self) -> np.ndarray:
        """d(probe x, y)/d(P_1 .. P_n, g) in the finger frame at the converged state,
        shape (n_probe, 2, n + 1): mm/MPa and mm per unit g (probes: finger_probes)."""
        return self.solver.sensitivities()[:, :2, :]

    def solve(self, load: FingerLoad) -> FingerResult:
        """Solve one finger gesture from the unloaded state; raises OutOfBoxError
        (before any work) for a pressure that is not finite or beyond its joint's box."""
        joints = self.finger.joints
        if len(load.pressures) != len(joints):
            raise ValueError(f"{len(load.pressures)} pressures for a finger with {len(joints)} joints")
        check_box(np.asarray(load.pressures), names=[f"P{j + 1}" for j in range(len(joints))],
                  box=pressure_limits(self.finger), units=["MPa"] * len(joints))
        solver = self.solver
        t0, c0, w0 = time.perf_counter(), time.process_time(), solver.work()
        solver.reset()
        path = solver.follow(solver.state.copy(), load.as_array())
        result = self._result(load, path, _spent(solver, w0), time.perf_counter() - t0, time.process_time() - c0)
        if self.comm.rank == 0:
            log.info("finger %s: converged=%s, %d steps, %.1f s", load.pressures, path.converged,
                     path.load_steps, result.wall_time)
        return result

    def follow(self, load: FingerLoad) -> FingerResult:
        """Continue from the current converged state to ``load`` along a straight load path
        (a history: fem.solvers.grasp's approach, then its pressure ramp); OutOfBoxError before any
        work for a pressure beyond its joint's box."""
        check_box(np.asarray(load.pressures), names=[f"P{j + 1}" for j in range(len(self.finger.joints))],
                  box=pressure_limits(self.finger), units=["MPa"] * len(self.finger.joints))
        solver = self.solver
        t0, c0, w0 = time.perf_counter(), time.process_time(), solver.work()
        path = solver.follow(solver.state.copy(), load.as_array())
        return self._result(load, path, _spent(solver, w0), time.perf_counter() - t0, time.process_time() - c0)

    def _result(self, load: FingerLoad, path, spent: dict, wall: float, cpu: float) -> FingerResult:
        """Global-frame figures of the current state (module docstring); spent: the linear
        algebra's work since the solve began (LoadPathSolver.work)."""
        finger = self.finger
        base, turn = np.array([0.5 * finger.base_gap, 0.0]), rotation_matrix(finger.base_angle)
        x = (self.probe_points + self.solver.probe_displacements())[:, :2]
        x = base + x @ turn.T
        # each joint's polyline: its proximal centre, then its own anchors
        polylines = np.split(x[:-1], np.cumsum([n + 1 for n in anchor_counts(finger)])[:-1])
        rot = {k: self.rotation(k) for k in range(len(finger.parts))}
        theta, end = [], []
        for k in finger.joints:
            theta.append(finger.base_angle + (rot[k - 1] if k > 0 else 0.0))
            end.append(finger.base_angle + rot[k])
        theta, end = np.array(theta), np.array(end)
        d = np.array([line[-1] - line[-2] for line in polylines])
        chord = np.arctan2(d[:, 1], d[:, 0])
        # joint frame: x_local = Rot(-theta)·(x - proximal centre)
        local = [(line[1:] - line[0]) @ rotation_matrix(t) for line, t in zip(polylines, theta)]
        last = len(finger.parts) - 1
        return FingerResult(
            load=load, converged=path.converged, tip=x[-1], tip_angle=finger.base_angle + rot[last],
            anchors=per_joint([line[1:] for line in polylines]), proximal=np.array([line[0] for line in polylines]),
            theta=theta, end_angle=end, chord_angle=end + np.remainder(chord - end + math.pi, 2 * math.pi) - math.pi,
            local_anchors=per_joint(local),
            newton_iterations=path.newton_iterations, load_steps=path.load_steps,
            cutbacks=path.cutbacks, **spent, wall_time=wall, cpu_time=cpu,
            reason=path.reason, plane=self._plane_state() if path.converged else None)

    def _plane_state(self) -> dict | None:
        """The plane's figures and the clamp's reaction at the current state (None without
        the plane). Collective."""
        if self.plane_term is None:
            return None
        return {**self.plane_term.state(self.u), "base_force_N": self.base_force()}


# ---------------------------------------------------------------------- command line
def same_settings(recorded: dict | None, settings: dict, finger: FingerSpec) -> bool:
    """Whether a case's recorded ``settings`` are ``settings`` (JSON-safe) of ``finger``: the
    same mesh, formulation and joints, and the same finger by its values
    (contract.finger.same_finger), so a finger file whose comments changed, and with them
    its sha256, keeps its solved cases."""
    if not isinstance(recorded, dict) or not isinstance(recorded.get("geometry"), dict):
        return False
    strip = lambda d: {**{k: v for k, v in d.items() if k != "finger_sha256"},   # noqa: E731
                       "geometry": {k: v for k, v in d["geometry"].items() if k != "finger"}}
    return (strip(recorded) == strip(settings) and isinstance(recorded["geometry"].get("finger"), dict)
            and same_finger(recorded["geometry"]["finger"], finger))


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.cli.finger")
