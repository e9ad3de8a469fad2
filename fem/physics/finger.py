"""The whole finger's physics: its problem, as the joint's (fem.physics.problem) is the joint's.

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
fem.physics.problem that the joint uses); fem.solvers.finger.FingerSolver hands it to the
joint's load-path solver (fem.solvers.load_path.LoadPathSolver: stepping, cut-back,
Newton/MUMPS, sensitivities), and fem.solvers.grasp adds an object's contact to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from contract.finger import FingerSpec
from contract.joint import FORMULATIONS, MaterialLaw
from fem.mesh.data import MeshData
from fem.mesh.geometry import FingerGeometry, finger_joints, finger_tags, pressure_limits
from fem.physics.contact import ContactTerms
from fem.physics.problem import (Average, LoadTerm, Material, Problem, as_law, bellow_work, chamber_pressures,
                                 clamp_and_symmetry, contact_penalty_for, deformation_gradient, displacement_space,
                                 elastic_work, facet_tags_present, mixed_bellow_work, mixed_clamp_and_symmetry,
                                 mixed_elastic_work, mixed_space, region_volume, rotation_about_z, valley_contact)


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


def rotation_matrix(angle: float) -> np.ndarray:
    """(2, 2) counter-clockwise rotation by angle (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


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
