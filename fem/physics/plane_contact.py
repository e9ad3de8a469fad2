"""The finger FEM's contact with the plane X = 0 where the two mirror fingers meet.

The gripper's two fingers are mirror images about the global X = 0, so where they touch
they touch on that plane, and each pushes the other along X only (frictionless by
symmetry). A point X of the right finger's half-model (finger frame, fem.solvers.finger) sits at
x = B + Rot(base_angle)·(X + u)_xy globally. On every candidate facet (below) the plane
presses with the predictor's law (contract.grasp, docs/gripper.md §7), per area of the
reference surface:

    N(X) = k_a s(max(0, -x_X))   [N/mm²],   k_a = k_p / width   (the part's full width)
    f(X) = N e_X                  on the finger, global

with s the C1 ramp of width delta of the object's law (fem.physics.object_contact) and k_p
(contract.grasp.PLANE_STIFFNESS, N/mm²) per mm of outline spread over the part's width,
as the object's k_c is. The residual term and its tangent are

    R_p = -∫ N e_X·v_g dA,      dR_p = UFL's derivative of R_p

(v_g the test function's global (x, y) components): a local facet form, assembled into
the tangent's matrix, no low-rank part. Where no candidate point lies at x_X < 0 both are
exactly zero, so a finger that stays apart solves as without the plane.

Candidate facets, the predictor's "inner and end edges" on the FEM's surface: the
exterior facets whose normal lies in the bending plane (|n_z| < 1/2; chamber walls, the
clamped base face and the half-model's plane z = 0 excluded: fem.physics.object_contact's
bending_facets) on every part (the predictor's plane acts on every part, whether or not
it takes the object), less the outer faces (|n_y| > 1/2 at y > 0 in the finger frame; the
section is symmetric about y = 0 and its outer side, +y, faces away from the plane as the
outline's +nu side does). A facet on the boundary between two parts (the last part's end
face) belongs to the distal one.

Figures (``state``, the full finger: x 2 for the half-model z >= 0): ``plane_force_N``,
the plane's resultant on the finger (N, global X component, >= 0), and
``plane_overlap_mm``, how far the finger crosses X = 0: max(0, -min x_X) over every node of
the half-model's surface (the predictor's: over every vertex of its outline).

Data flow: fem.solvers.finger.FingerSolver(plane=True) builds the term on the problem's unknown
and adds it to the contact terms (fem.physics.contact.ContactTerms) that the load path
(fem.solvers.load_path) assembles in every Newton iteration; the solver's result reads ``state``
at a converged state.
"""
from __future__ import annotations

import math

import numpy as np
from dolfinx import fem
from dolfinx.mesh import exterior_facet_indices
from mpi4py import MPI

from contract.finger import FingerSpec
from contract.grasp import CONTACT_SMOOTHING, PLANE_STIFFNESS
from fem.physics.object_contact import FacetTerm, bending_facets, owned_xy_dofs, part_width, smooth_penetration


def plane_facets(mesh, facet_tags, finger: FingerSpec, excluded: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(facets, part index) of the plane's candidate facets (module docstring), local to
    this rank: bending_facets on any part (by the midpoint x along the rest finger; the
    distal part at a boundary), less the outer faces (|n_y| > 1/2, midpoint y > 0)."""
    facets, mid, normal = bending_facets(mesh, facet_tags, excluded)
    part = np.full(len(facets), -1)
    eps = 1e-6       # mm: a face on a part's end plane belongs to it (a later part wins)
    for k, p in enumerate(finger.parts):
        x0 = finger.rest_start(k)
        part[(mid[:, 0] > x0 - eps) & (mid[:, 0] < x0 + p.length + eps)] = k
    outer = (np.abs(normal[:, 1]) > 0.5) & (mid[:, 1] > 0.0)
    keep = (part >= 0) & ~outer
    return facets[keep], part[keep]


class PlaneContact(FacetTerm):
    """The plane X = 0's frictionless penalty on the finger (module docstring): a FacetTerm
    of residual R_p, with nothing lagged.

    w: the unknown (displacement, or the mixed (u, p)); finger, joint_width (mm): the
    finger description and its joints' full width; excluded_tags: facet tags that never
    touch (chamber walls, base, symmetry plane). stiffness k_p (N/mm²), smoothing delta
    (mm): contract.grasp's. ``active`` False makes the term add nothing (the finger then
    passes through X = 0). Collective."""

    def __init__(self, w: fem.Function, mesh_data, finger: FingerSpec, joint_width: float,
                 excluded_tags: list[int], *, stiffness: float = PLANE_STIFFNESS,
                 smoothing: float = CONTACT_SMOOTHING):
        mesh = mesh_data.mesh
        facets, parts = plane_facets(mesh, mesh_data.facet_tags, finger, excluded_tags)
        super().__init__(w, mesh_data, finger, facets, parts)
        ds, xg, vg = self.ds, self.xg, self.vg
        s = smooth_penetration(-xg[0], smoothing)
        # N per part: k_p / width of that part, over its own facet tag
        normal = sum((stiffness / part_width(finger, k, joint_width)) * s * ds(k + 1)
                     for k in range(len(finger.parts)))
        residual = sum(-(stiffness / part_width(finger, k, joint_width)) * s * vg[0] * ds(k + 1)
                       for k in range(len(finger.parts)))
        self.set_residual(residual)
        self._normal = fem.form(normal)
        self.n_facets = self.comm.allreduce(len(facets), op=MPI.SUM)
        self._surface_dofs(mesh)

    def _surface_dofs(self, mesh) -> None:
        """``surface_dofs``: the owned surface nodes' x and y dofs (local indices of the
        unknown, two arrays in node order), and their reference points (mm): the overlap."""
        mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
        xd, yd, ref = owned_xy_dofs(self.w, self.U, exterior_facet_indices(mesh.topology))
        self.surface_dofs, self._ref = (xd, yd), ref

    def surface_x(self, u: fem.Function) -> np.ndarray:
        """Global X (n,) mm of the surface nodes this rank owns at the state u."""
        xd, yd = self.surface_dofs
        angle, base = self.finger.base_angle, 0.5 * self.finger.base_gap
        return (base + math.cos(angle) * (self._ref[:, 0] + u.x.array[xd])
                - math.sin(angle) * (self._ref[:, 1] + u.x.array[yd]))

    def state(self, u: fem.Function) -> dict:
        """The full finger's figures (module docstring): plane_force_N (N, along +X; 0 while
        the term is inactive) and plane_overlap_mm (mm, >= 0). Collective."""
        force = 0.0
        if self.active:
            force = 2.0 * self.comm.allreduce(fem.assemble_scalar(self._normal), op=MPI.SUM)
        x = self.surface_x(u)
        lowest = self.comm.allreduce(float(x.min()) if len(x) else math.inf, op=MPI.MIN)
        return {"plane_force_N": force, "plane_overlap_mm": max(0.0, -lowest)}
