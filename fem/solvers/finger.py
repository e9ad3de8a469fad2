"""The whole finger in DOLFINx: the ground truth for the gesture predictor (issue 14).

Its command line is fem.cli.finger (``python -m fem.cli.finger``).

Model (units mm, N, MPa, N·mm; angles rad in code, degrees in the JSON): one half-model
(z >= 0, u_z = 0 on z = 0) of the finger described by a finger file
(contract.finger; default the paper's, contract/fingers/paper.toml), built by
fem.mesh.geometry.build_finger in the finger frame (x along the straight rest finger from the
base mount, y in the bending plane). Every joint is the bellow joint of fem.physics.problem built
from its own joint description (the finger file's optional ``joint`` key per joint part,
contract.joint; absent: the paper's joint, NinjaFlex as a neo-Hookean solid): its law
(fem.physics.materials), stiff distal cap, input box (the pressure limit of its P_j), anchor count
and default mesh ([mesh]: sizes and formulation, of the first joint, unless given), with
P2 elements and the valley self-contact of fem.physics.contact. ``--divisions`` N (or a first
joint file whose [mesh] gives divisions) meshes the whole finger with swept Q2 hexahedra
instead (fem.mesh.hexahedra: N elements through every joint wall, the same grid as the joint
alone when the joints share their section), integrated with the hexahedra's quadrature
(fem.solvers.joint.config_for). The record's ``mesh.mesh`` names the joints' mesh in words (``1.8``, ``1.697:0.849``, ``hex2``;
contract.joint.mesh_text). Each joint is meshed in its own shape (its joint description's
[geometry]: length, cells, walls, section; fem.mesh.geometry.FingerGeometry.joint_at) with the
finger's one set of mesh settings, so the joints of one finger may differ in shape, law,
box and anchor count (results/joints/soft4/finger_mixed.toml: the paper's joint at the
base, soft4 at the tip); on hexahedra the finger's one swept (y, z) grid holds every
joint's section lines (fem.mesh.hexahedra). Every rigid part is a neo-Hookean PLA-like solid
(E = 3.5 GPa, nu = 0.35), bonded to its neighbours' end faces (one conforming mesh). The
base face x = 0 is clamped. Each joint's probes (proximal centre and anchors), valley
contact pairs (fem.physics.contact, on its own cells) and contact penalty
(fem.physics.problem.contact_penalty_for of its law) are its own.

Formulation (the joint's discretisation, fem.mesh.discretisation; default the first joint's
[mesh] formulation, for the paper's joint the production FORMULATION): "displacement", P2
displacements u; or "mixed", one Taylor-Hood space (P2 u, continuous P1 pressure p, MPa)
over the whole finger, whose internal work is the variation of the perturbed Lagrangian
of fem.physics.problem with each region's own law,

    Pi(u, p) = sum_regions ∫ psi_dev,r - p ln J - p² / (2 kappa_r) dX,

(each joint's body, its stiff cap, PLA parts), one pressure continuous across them as in
the joint's body and cap. It removes the volumetric locking of P2 at nu = 0.49 in the joints
(results/fem/mesh_causes.md; the stiff parts move rigidly in either formulation).

Loads, all ramped together along one load path (load vector a = (P_1 .. P_n, g)):

* chamber pressure of joint j, a follower load on its deformed chamber walls
  (t0 = -p J F^-T N; P_j > 0 inflates its top chamber, P_j < 0 its bottom one);
* gravity as a dead body force b_k = g W_k / (2 V_k) e_g on part k (weight W_k from the
  finger file, V_k its half-model volume: the half-model carries half the weight), with
  e_g = Rot(-base_angle)·(0, -1) the global -Y in the finger frame, g in [0, 1].

The physics is declared once as a problem (:func:`finger_problem`, from the pieces of
fem.physics.problem that the joint uses) and handed to the joint's load-path solver
(fem.solvers.load_path.LoadPathSolver: stepping, cut-back, Newton/MUMPS, sensitivities).

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
(fem.physics.plane_contact), the problem ``python -m predictor.gesture`` solves by default.
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
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_vector
from mpi4py import MPI
from petsc4py import PETSc

from contract.finger import FingerSpec, same_finger
from contract.joint import FORMULATIONS, MaterialLaw
from fem.physics.contact import ContactTerms
from fem.mesh.discretisation import FORMULATION, SolverConfig
from fem.mesh.geometry import FingerGeometry, finger_joints, finger_tags, pressure_limits
from fem.solvers.load_path import LoadPathSolver
from fem.mesh.build import create_mesh
from fem.mesh.data import MeshData
from fem.physics.plane_contact import PlaneContact
from fem.physics.problem import (Average, LoadTerm, Material, Problem, as_law, bellow_work,
                                 chamber_pressures, clamp_and_symmetry, contact_penalty_for, deformation_gradient,
                                 displacement_space, elastic_work, facet_tags_present, mixed_bellow_work,
                                 mixed_clamp_and_symmetry, mixed_elastic_work, mixed_space, region_volume,
                                 rotation_about_z, valley_contact)
from contract.spec import check_box
from fem.solvers.joint import config_for

log = logging.getLogger("softjoint.fem")
def joint_laws(finger: FingerSpec, material: MaterialLaw | Material | None = None) -> dict:
    """{part index k: the body's law of joint part k}: each joint's own (None), or
    ``material`` for every joint."""
    return {k: as_law(material) if material is not None else finger.parts[k].spec.material
            for k in finger.joints}


@dataclass(frozen=True)
class RigidMaterial:
    """The rigid parts: PLA-like, E (MPa), nu. 290x NinjaFlex, so they bend by
    ~1e-4 rad under the finger's loads (a 65 mm tip under 20 N·mm)."""

    E: float = 3500.0
    nu: float = 0.35


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
        what they mean in ``predictor.gesture --json``. A solve that did not converge has
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


def rotation_matrix(angle: float) -> np.ndarray:
    """(2, 2) counter-clockwise rotation by angle (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


#: The joint's controls with a longer Newton budget and a finer last step: a pressure step
#: swings the 200 mm finger through a large rotation under its weight, so a step often
#: needs 9-12 iterations (the joint's limit was 12), and near full load in the grasp region
#: (0.2, 0.2) MPa with gravity a step of 1/256 of the path still failed at that limit
#: (with these controls it converges).
FINGER_CONFIG = SolverConfig(max_it=25, min_step=1.0 / 1024)


@dataclass(frozen=True, eq=False)
class FingerUnknown:
    """The finger's unknown in one formulation: ``w`` the Function solved for (u, or the
    mixed pair (u, p)), F = I + grad u (UFL variable), ``v`` the displacement test function,
    the measures, the internal virtual work of a joint (``joint_work(body, cap, law)``) and
    of a rigid part (``rigid_work(region)``), the clamp and symmetry conditions, and the
    displacement space ``U`` the contact acts on (with ``parent`` = (W, to_parent) when it
    is collapsed out of the mixed space W)."""

    w: fem.Function
    F: object
    v: object
    dx: object
    ds: object
    joint_work: Callable
    rigid_work: Callable
    bcs: tuple
    U: object
    parent: tuple | None = None
    formulation: str = "displacement"


def displacement_unknown(mesh_data: MeshData, rigid: RigidMaterial,
                         degree: int, quadrature_degree: int) -> FingerUnknown:
    """P``degree`` displacements u (mm) over the whole finger."""
    u, v, dx, ds = displacement_space(mesh_data, degree, quadrature_degree)
    F = deformation_gradient(u)
    return FingerUnknown(u, F, v, dx, ds,
                         lambda body, cap, law: bellow_work(F, v, law, body, cap),
                         lambda region: elastic_work(F, v, rigid.E, rigid.nu, region),
                         tuple(clamp_and_symmetry(u.function_space, mesh_data.facet_tags)),
                         u.function_space)


def mixed_unknown(mesh_data: MeshData, rigid: RigidMaterial,
                  degree: int, quadrature_degree: int) -> FingerUnknown:
    """One Taylor-Hood space (P``degree`` u mm, continuous P``degree - 1`` p MPa) over the
    whole finger; every region's work the variation of its perturbed Lagrangian."""
    fields, dx, ds = mixed_space(mesh_data, degree, quadrature_degree)
    W = fields.w.function_space
    F = deformation_gradient(fields.u)
    return FingerUnknown(fields.w, F, fields.v, dx, ds,
                         lambda body, cap, law: mixed_bellow_work(fields, F, law, body, cap),
                         lambda region: mixed_elastic_work(fields, F, rigid.E, rigid.nu, region),
                         tuple(mixed_clamp_and_symmetry(W, mesh_data.facet_tags)), fields.U,
                         parent=(W, fields.to_parent), formulation="mixed")


def finger_problem(geometry: FingerGeometry, mesh_data: MeshData,
                   material: MaterialLaw | Material | None = None,
                   rigid: RigidMaterial = RigidMaterial(), *, degree: int = 2,
                   quadrature_degree: int = 2, contact_penalty: float = 100.0,
                   formulation: str = "displacement") -> Problem:
    """The whole finger as a :class:`fem.physics.problem.Problem` (module docstring): every joint
    the bellow joint's body (its own law, or ``material`` for every joint), stiff cap,
    chamber pressures and valley contact, every rigid part a PLA-like solid, gravity a dead
    body force. Load vector a = (P_1 .. P_n, g) in MPa and [0, 1]; probes: each joint's
    proximal centre and anchors, then the fingertip; averages ``rotation{k}`` (rad): part
    k's rigid body (a rigid part, or a joint's cap). ``formulation``: "displacement" or
    "mixed" (module docstring). Every per-joint quantity (probes, valley contact pairs and
    their penalty) is that joint's own (FingerGeometry.joint_at, its law). Collective."""
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {FORMULATIONS}, not {formulation!r}")
    build = mixed_unknown if formulation == "mixed" else displacement_unknown
    unknown = build(mesh_data, rigid, degree, quadrature_degree)
    finger, comm = geometry.finger, mesh_data.mesh.comm
    laws = joint_laws(finger, material)
    F, v, dx, ds = unknown.F, unknown.v, unknown.dx, unknown.ds
    ft, mesh = mesh_data.facet_tags, mesh_data.mesh
    tags = finger_tags(finger)
    present = facet_tags_present(ft)
    internal, weights, pressures, averages = 0, [], (), {}
    for k, part in enumerate(finger.parts):
        own = dx(tags[f"part{k}"])
        if part.kind == "joint":
            rigid_body = dx(tags[f"cap{k}"])
            internal = internal + unknown.joint_work(own, rigid_body, laws[k])
            whole = own + rigid_body
            pressures += chamber_pressures(F, v, ds, tags[f"top{k}"], tags[f"bottom{k}"], present,
                                           finger.joints.index(k))
        else:
            internal = internal + unknown.rigid_work(own)
            whole = rigid_body = own
        if part.weight > 0:
            weights.append(gravity_work(v, finger, part.weight, whole, region_volume(mesh, whole, comm)))
        averages[f"rotation{k}"] = Average(fem.form(rotation_about_z(F) * rigid_body),
                                           region_volume(mesh, rigid_body, comm))
    n = len(finger.joints)
    loads = pressures
    if weights:
        loads += (LoadTerm(fem.Constant(mesh, PETSc.ScalarType(0)), sum(weights[1:], weights[0]), n),)
    contact = joints_contact(unknown.U, ft, present, geometry,
                             tuple(contact_penalty_for(contact_penalty, laws[k]) for k in finger.joints),
                             parent=unknown.parent)
    return Problem(mesh_data, unknown.w, internal, loads, np.append(pressure_limits(finger), 1.0),
                   unknown.bcs, finger_probes(geometry), contact, averages=averages,
                   formulation=unknown.formulation,
                   displacement_space=None if unknown.parent is None else unknown.U)


def gravity_work(v, finger: FingerSpec, weight: float, region, volume: float):
    """Virtual work per unit g of a part's weight (N) as a dead body force over ``region``
    of half-model volume ``volume`` (mm³): b = W / (2 V) e_g, e_g = Rot(-base_angle)·(0, -1)
    the global -Y in the finger frame. Returned as the residual term -∫ b·v dX."""
    e_g = rotation_matrix(-finger.base_angle) @ np.array([0.0, -1.0])
    gravity = ufl.as_vector([float(e_g[0]), float(e_g[1]), 0.0])
    mesh = ufl.domain.extract_unique_domain(v)     # v may be a block of a mixed test function
    rho = fem.Constant(mesh, PETSc.ScalarType(weight / (2 * volume)))
    return -rho * ufl.inner(gravity, v) * region


def finger_probes(geometry: FingerGeometry) -> np.ndarray:
    """Every joint's proximal centre and its own anchors (n_j of them at i L_j / n_j, its
    joint description's count and length: 10 at 4.545 mm for the paper's), then the
    fingertip: (sum_j (n_j + 1) + 1, 3) mm, finger frame."""
    finger = geometry.finger
    points = [[finger.rest_start(k) + i * geometry.joint_at(k).length / n, 0.0, 0.0]
              for k, n in zip(finger.joints, anchor_counts(finger)) for i in range(n + 1)]
    points.append([finger.length, 0.0, 0.0])
    return np.array(points)


def anchor_counts(finger: FingerSpec) -> list[int]:
    """Every joint's anchor count n_j (its joint description's), base to tip."""
    return [spec.anchors for spec in finger_joints(finger)]


def per_joint(arrays: list[np.ndarray]):
    """Per-joint arrays as one (n_joints, ...) array when their shapes agree (joints of
    one anchor count, every finger before joint files could differ), else a tuple."""
    return np.stack(arrays) if len({a.shape for a in arrays}) == 1 else tuple(arrays)


class JointsContact(ContactTerms):
    """The valley self-contact of a finger whose joints differ in shape: one
    fem.physics.contact.ValleyContact per joint (its own cells, valley size and penalty) summed as
    ContactTerms. ``first[i]``: the number of valleys before the i-th term's joint, so that
    :meth:`gaps` numbers valleys along x across the joints, as one ValleyContact does."""

    def __init__(self, parts: list, first: list[int]):
        super().__init__(*parts)
        self.first, self.comm = first, parts[0].comm

    def gaps(self, u: fem.Function) -> dict:
        """Signed gap g (mm) of every pair, per (valley, side), valleys along x."""
        return {(first + k, side): g for part, first in zip(self.terms, self.first)
                for (k, side), g in part.gaps(u).items()}


def joints_contact(V, facet_tags, present: set, geometry: FingerGeometry, penalties: tuple[float, ...],
                   parent=None):
    """The finger's valley contact (fem.physics.problem.valley_contact; ``penalties`` MPa/mm, one
    per joint): one ValleyContact over every joint when they share one shape, else a
    :class:`JointsContact` of one per joint of its own geometry; None without valleys or
    with every penalty 0."""
    finger = geometry.finger
    offsets = tuple(finger.rest_start(k) for k in finger.joints)
    if geometry.same_shape:
        return valley_contact(V, facet_tags, present, geometry.joint, penalties, offsets=offsets, parent=parent)
    parts, first, valleys = [], [], 0
    for jg, kappa, x0 in zip(geometry.joints, penalties, offsets):
        part = valley_contact(V, facet_tags, present, jg, kappa, offsets=(x0,), parent=parent)
        if part is not None:
            parts.append(part)
            first.append(valleys)
        valleys += jg.n_cells - 1
    return JointsContact(parts, first) if parts else None


def closed_tags(finger: FingerSpec) -> list[int]:
    """Facet tags of the finger's surfaces that touch nothing outside it: every joint's
    chamber walls, the half-model's plane z = 0 and the clamped base face."""
    tags = finger_tags(finger)
    return [tags[f"{side}{k}"] for k in finger.joints for side in ("top", "bottom")] + [
        tags["symmetry"], tags["proximal"]]


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

