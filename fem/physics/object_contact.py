"""The finger FEM's contact with a rigid object: the predictor's law on the finger's surface.

The object (contract.grasp.ObjectSpec: circle, ellipse or rounded rectangle, an infinite
prism along z) is fixed in the gripper's global plane. A point X of the finger's
half-model (finger frame, fem.solvers.finger) sits at x = B + Rot(base_angle)·(X + u)_xy
globally (B the right finger's base mount). On every candidate facet (the outer surfaces
of the parts that take contact: a facet of the mesh's boundary whose normal lies in the
bending plane, |n_z| < 1/2, not a chamber wall, on a joint with ``contact = true`` or a
rigid part with ``contact_points > 0``) the object presses with the predictor's law
(contract.grasp, docs/gripper.md §7), per area of the reference surface:

    N(X) = k_a s(max(0, -d(x)))    [N/mm²],   k_a = k_c / width   (the part's full width)
    f(X) = N (n - lambda_c t)      on the finger, global
    lambda = (W/2 + 2 ∫ N n_y dA) / (2 ∫ N t_y dA),   lambda_c = clip(lambda, -mu, mu)

with d, n the object's exact signed distance and outward normal (the ellipse: its first
order distance), t the object's tangent turned upwards, s the C1 ramp of width delta, and
the integrals over the half-model (z >= 0, hence the 2: one finger carries W/2). The
residual term and its consistent tangent are

    R_o = -∫ f·v dA = -∫ N n·v dA + lambda_c G·v,     G = ∫ N t·v dA
    dR_o = dR_o|lambda fixed + G ⊗ dlambda,           dlambda = (d num - lambda d den) / den

dR_o|lambda fixed is UFL's derivative of the facet form, assembled into the tangent's matrix
(its entries couple dofs of one cell, already in the pattern). The second term couples
every candidate dof to every other (lambda is one number for the whole contact): assembled
it would be a dense block over the m candidate (x, y) dofs, m² entries (2,788² = 7.8
million on the 4 mm mesh, 3.4 times the rest of the tangent). It stays out of the matrix:
``low_rank`` hands the pair (G, dlambda) to the solver (fem.solvers.load_path), whose Krylov
operator is the matrix plus G dlambdaᵀ while the LU preconditioner factorises the matrix
alone, so Newton keeps the exact tangent. It is zero where the friction is clipped (slip)
or nothing touches.

A penalty holds whatever lies inside the object, however deep: a Newton iterate that
carries part of the finger through the surface can converge there (a coarse mixed grasp
did, 20 mm deep under 2,500 N). ``refuses`` makes the solver reject a converged state with
a candidate node deeper than MAX_PENETRATION inside the object, so the load step is cut
back instead.

fem.physics.contact.ContactTerms sums this term and the joints' valley contact behind the one
interface the solver calls (add_residual, add_tangent, coupled_dofs, low_rank, refuses).
"""
from __future__ import annotations

import math

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.cpp.mesh import entities_to_geometry
from dolfinx.fem.petsc import assemble_matrix, assemble_vector
from dolfinx.mesh import exterior_facet_indices, meshtags
from mpi4py import MPI
from petsc4py import PETSc

from contract.finger import FingerSpec
from contract.grasp import (CONTACT_SMOOTHING, CONTACT_STIFFNESS, FRICTION, OBJECT_WEIGHT, ObjectSpec,
                            friction_ratio)

#: Facet quadrature degree of the contact integrals (6 points per triangle).
CONTACT_QUADRATURE = 4
#: mm: the deepest a candidate node may lie inside the object in a converged state
#: (``refuses``): 40 times the law's ramp width delta, 20 times the coarse grasp's 0.09 mm.
MAX_PENETRATION = 2.0


def smooth_penetration(pen, delta: float):
    """UFL C1 ramp s(pen) (mm): 0 for pen <= 0, pen²/(2 delta) below delta, pen - delta/2."""
    return ufl.conditional(ufl.le(pen, 0.0), 0.0,
                           ufl.conditional(ufl.lt(pen, delta), pen * pen / (2.0 * delta), pen - 0.5 * delta))


def turn(angle: float, v):
    """UFL 2-vector v turned counter-clockwise by angle (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return ufl.as_vector([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def signed_distance(ob: ObjectSpec, x):
    """UFL (d mm, n unit 2-vector) of the global point x (2-vector): contract.grasp's
    ObjectSpec.signed_distance, with the outward normal (a rectangle: the rounded corner's
    radial direction where both offsets are positive, else the nearest face's)."""
    q = turn(-ob.angle, ufl.as_vector([x[0] - ob.x, x[1] - ob.y]))
    if ob.kind == "circle":
        r = ufl.max_value(ufl.sqrt(ufl.dot(q, q)), 1e-12)
        d, n = r - ob.a, q / r
    elif ob.kind == "ellipse":
        grad = ufl.as_vector([2.0 * q[0] / ob.a ** 2, 2.0 * q[1] / ob.b ** 2])
        gn = ufl.max_value(ufl.sqrt(ufl.dot(grad, grad)), 1e-12)
        d, n = (q[0] ** 2 / ob.a ** 2 + q[1] ** 2 / ob.b ** 2 - 1.0) / gn, grad / gn
    else:
        sx = ufl.conditional(ufl.lt(q[0], 0.0), -1.0, 1.0)
        sy = ufl.conditional(ufl.lt(q[1], 0.0), -1.0, 1.0)
        e0, e1 = abs(q[0]) - ob.a + ob.corner, abs(q[1]) - ob.b + ob.corner
        arc = ufl.And(ufl.gt(e0, 0.0), ufl.gt(e1, 0.0))
        r = ufl.sqrt(ufl.max_value(e0 * e0 + e1 * e1, 1e-24))
        d = ufl.conditional(arc, r, ufl.max_value(e0, e1)) - ob.corner
        face = ufl.conditional(ufl.ge(e0, e1), ufl.as_vector([sx, 0.0]), ufl.as_vector([0.0, sy]))
        n = ufl.conditional(arc, ufl.as_vector([sx * e0 / r, sy * e1 / r]), face)
    return d, (turn(ob.angle, n) if ob.angle else n)


def upward_tangent(n):
    """The object's tangent (-n_y, n_x) turned so that its y component is >= 0 (UFL)."""
    sign = ufl.conditional(ufl.lt(n[0], 0.0), -1.0, 1.0)
    return ufl.as_vector([-n[1] * sign, n[0] * sign])


def contact_parts(finger: FingerSpec) -> list[int]:
    """Indices of the parts that take contact: joints with ``contact``, rigid parts with
    ``contact_points`` > 0 (the predictor's rule)."""
    return [k for k, p in enumerate(finger.parts)
            if (p.contact if p.kind == "joint" else p.contact_points > 0)]


def part_width(finger: FingerSpec, k: int, joint_width: float) -> float:
    """Full width (mm, normal to the bending plane) of part k: a rigid part's own, a joint's
    the joint geometry's."""
    part = finger.parts[k]
    return part.width if part.kind == "rigid" else joint_width


def bending_facets(mesh, facet_tags, excluded: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(facets, midpoints (f, 3) mm, unit normals (f, 3), sign arbitrary) of the exterior
    facets local to this rank whose normal lies in the bending plane (|n_z| < 1/2) and that
    carry none of the tags ``excluded`` (the chamber walls), in the reference finger frame."""
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, fdim + 1)
    facets = exterior_facet_indices(mesh.topology)
    skip = np.concatenate([facet_tags.find(t) for t in excluded] or [np.zeros(0, np.int32)])
    facets = np.setdiff1d(facets, skip).astype(np.int32)
    nodes = entities_to_geometry(getattr(mesh, "_mesh", mesh), fdim, facets, False)
    x = mesh.geometry.x[nodes]                       # (f, vertices, 3)
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    keep = np.abs(normal[:, 2]) < 0.5
    return facets[keep], x.mean(axis=1)[keep], normal[keep]


def candidate_facets(mesh, facet_tags, finger: FingerSpec, excluded: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(facets, part index) of the candidate facets (module docstring), local to this rank:
    bending_facets on a part that takes contact (by the facet's midpoint x along the rest
    finger, strictly inside the part)."""
    facets, mid, _ = bending_facets(mesh, facet_tags, excluded)
    part = np.full(len(facets), -1)
    for k in contact_parts(finger):
        x0 = finger.rest_start(k)
        part[(mid[:, 0] > x0) & (mid[:, 0] < x0 + finger.parts[k].length)] = k
    keep = part >= 0
    return facets[keep], part[keep]


def part_measure(mesh, facets: np.ndarray, parts: np.ndarray) -> ufl.Measure:
    """The facet measure of the candidate facets, ``ds(k + 1)`` over part k's (parts: the
    part index of each facet), at the contact quadrature."""
    order = np.argsort(facets)
    tags = meshtags(mesh, mesh.topology.dim - 1, facets[order], (parts[order] + 1).astype(np.int32))
    return ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata={"quadrature_degree": CONTACT_QUADRATURE})


def split_unknown(w: fem.Function):
    """(U, u, v, test) of the unknown w: the displacement space U (W.sub(0) of a mixed
    (u, p)), the displacement u and its test function v (UFL), and W's test function."""
    W = w.function_space
    mixed = type(W.ufl_element()) is ufl.MixedElement
    test = ufl.TestFunction(W)
    u, v = (ufl.split(w)[0], ufl.split(test)[0]) if mixed else (w, test)
    return (W.sub(0) if mixed else W), u, v, test


def global_frame(finger: FingerSpec, mesh, u, v):
    """UFL (x_g, v_g): the deformed point x_g = B + Rot(base_angle)·(X + u)_xy (mm, the
    gripper's global plane, B the right finger's base mount) and the test function's global
    (x, y) components v_g = Rot(base_angle)·v_xy."""
    base, angle = np.array([0.5 * finger.base_gap, 0.0]), finger.base_angle
    X = ufl.SpatialCoordinate(mesh)
    xg = ufl.as_vector(base.tolist()) + turn(angle, ufl.as_vector([X[0] + u[0], X[1] + u[1]]))
    return xg, turn(angle, ufl.as_vector([v[0], v[1]]))


def owned_xy_dofs(w: fem.Function, U, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x dofs, y dofs, reference points (n, 3) mm) of the nodes of ``facets`` that this
    rank owns: local indices of the unknown w, in node order; through the displacement
    space U, collapsed out of a mixed unknown (dolfinx tabulates no mixed space's
    coordinates)."""
    W = w.function_space
    fdim = W.mesh.topology.dim - 1
    if U is W:
        imap = W.dofmap.index_map
        U, to_parent = W, np.arange((imap.size_local + imap.num_ghosts) * W.dofmap.index_map_bs)
    else:
        U, to_parent = U.collapse()
        to_parent = np.asarray(to_parent)
    bs = U.dofmap.index_map_bs
    nodes = np.asarray(fem.locate_dofs_topological(U, fdim, facets))
    nodes = nodes[nodes < U.dofmap.index_map.size_local]
    return to_parent[bs * nodes], to_parent[bs * nodes + 1], U.tabulate_dof_coordinates()[nodes]


def assembled(form) -> PETSc.Vec:
    """The vector of a linear form, ghost contributions summed into their owners (collective)."""
    vec = assemble_vector(form)
    vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return vec


class FacetTerm:
    """A contact term whose residual R is one UFL facet form of the unknown w, and whose
    tangent is its derivative dR/dw assembled into the tangent's matrix (the object's,
    ObjectContact, and the plane's, fem.physics.plane_contact.PlaneContact): the part of the
    interface fem.physics.contact.ContactTerms calls that both share. A subclass passes its
    candidate facets to ``__init__`` and its form to ``set_residual``; ``refresh`` updates
    what the form holds fixed (nothing here) before either is assembled."""

    def __init__(self, w: fem.Function, mesh_data, finger: FingerSpec, facets: np.ndarray, parts: np.ndarray):
        """The set-up both terms share: ``finger``, ``w``, ``active`` (True), ``comm``, the
        displacement space ``U`` and W's test function ``test`` (split_unknown), the
        candidate facets' measure ``ds`` (``ds(k + 1)`` over part k's: part_measure), and the
        deformed point and test function in the global plane ``xg``, ``vg`` (global_frame)."""
        self.finger, self.w, self.active = finger, w, True
        mesh = mesh_data.mesh
        self.comm = mesh.comm
        self.U, u, v, self.test = split_unknown(w)
        self.ds = part_measure(mesh, facets, parts)
        self.xg, self.vg = global_frame(finger, mesh, u, v)

    def set_residual(self, residual) -> None:
        """Compile R (``residual``, a UFL form linear in w's test function) and dR/dw."""
        self._residual = residual
        self._R = fem.form(residual)
        self._K = fem.form(ufl.derivative(residual, self.w, ufl.TrialFunction(self.w.function_space)))

    def refresh(self) -> None:
        """Update the form's lagged values from the current state (none here)."""

    def linearise(self, u: fem.Function) -> None:
        """Fix the lagged values at the current state, as add_tangent does (nothing when
        inactive)."""
        if self.active:
            self.refresh()

    def coupled_dofs(self) -> list[np.ndarray]:
        """None: the facet form couples only dofs that share a cell (already in the tangent's
        pattern)."""
        return []

    def add_residual(self, b: PETSc.Vec, u: fem.Function) -> None:
        """b += R(u) (collective; nothing when inactive)."""
        if not self.active:
            return
        self.refresh()
        vec = assembled(self._R)
        b.axpy(1.0, vec)
        vec.destroy()

    def add_tangent(self, A: PETSc.Mat, u: fem.Function) -> None:
        """A += dR/du (collective; A is left flush-assembled, call A.assemble() after;
        nothing when inactive)."""
        if not self.active:
            return
        self.refresh()
        A.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)
        A.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)
        assemble_matrix(A, self._K)
        A.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)
        A.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)

    def action_form(self, x: fem.Function) -> fem.FormMetaClass:
        """The linear form (dR/du) x, for a tangent applied matrix-free
        (fem.solvers.load_path.TangentAction): the form add_tangent assembles, along x."""
        return fem.form(ufl.derivative(self._residual, self.w, x))


class ObjectContact(FacetTerm):
    """The object's penalty and friction on the finger (module docstring): a FacetTerm
    whose residual R_o is assembled at the current lambda_c (``refresh``), and whose tangent
    add_tangent assembles at fixed lambda_c, the friction's rank-one part staying out of
    the matrix (``low_rank``).

    w: the unknown (displacement, or the mixed (u, p)); finger, joint_width (mm): the
    finger description and its joints' full width; obstacle: the object. stiffness k_c
    (N/mm²), smoothing delta (mm), mu, weight W (N): contract.grasp's law. ``active``
    False makes the term add nothing (the approach gesture before the object is brought
    in). Collective."""

    def __init__(self, w: fem.Function, mesh_data, finger: FingerSpec, joint_width: float, obstacle: ObjectSpec,
                 excluded_tags: list[int], *, stiffness: float = CONTACT_STIFFNESS,
                 smoothing: float = CONTACT_SMOOTHING, mu: float = FRICTION, weight: float = OBJECT_WEIGHT):
        self.obstacle, self.mu, self.weight = obstacle, mu, weight
        mesh = mesh_data.mesh
        facets, parts = candidate_facets(mesh, mesh_data.facet_tags, finger, excluded_tags)
        super().__init__(w, mesh_data, finger, facets, parts)
        ds, xg, vg, test = self.ds, self.xg, self.vg, self.test
        d, n = signed_distance(obstacle, xg)
        t = upward_tangent(n)
        s = smooth_penetration(-d, smoothing)
        # N per part: k_c / width of that part, over its own facet tag
        N_parts = [((stiffness / part_width(finger, k, joint_width)) * s, ds(k + 1)) for k in contact_parts(finger)]

        def over(expr_of):
            return sum(expr_of(N) * dA for N, dA in N_parts)
        self.lam = fem.Constant(mesh, PETSc.ScalarType(0.0))
        residual = over(lambda N: -N * ufl.dot(n, vg) + self.lam * N * ufl.dot(t, vg))
        num, den = over(lambda N: N * n[1]), over(lambda N: N * t[1])
        self.set_residual(residual)
        self._G = fem.form(over(lambda N: N * ufl.dot(t, vg)))
        self._dnum = fem.form(ufl.derivative(num, w, test))
        self._dden = fem.form(ufl.derivative(den, w, test))
        self._sums = {name: fem.form(form) for name, form in dict(
            num=num, den=den, normal=over(lambda N: N), fx=over(lambda N: N * n[0]), ft=over(lambda N: N * t[0]),
            mx=over(lambda N: N * xg[0]), my=over(lambda N: N * xg[1])).items()}
        self._dofs(facets)

    # ------------------------------------------------------------------ dofs
    def _dofs(self, facets: np.ndarray) -> None:
        """The candidate (x, y) dofs this rank owns (``candidate_dofs``, local indices of the
        unknown), the owned candidate nodes' x and y dofs (``xy_dofs``, two arrays in node
        order) and their reference points (mm), for ``nodes`` (owned_xy_dofs)."""
        xdofs, ydofs, self._ref = owned_xy_dofs(self.w, self.U, facets)
        self.candidate_dofs = np.sort(np.concatenate([xdofs, ydofs])).astype(np.int32)
        self.xy_dofs = (xdofs, ydofs)

    # ------------------------------------------------------------------ law
    def _sum(self, name: str) -> float:
        return self.comm.allreduce(fem.assemble_scalar(self._sums[name]), op=MPI.SUM)

    def ratio(self) -> float:
        """lambda at the current state (contract.grasp.friction_ratio; half-model sums x 2)."""
        return friction_ratio(self.weight, 2.0 * self._sum("num"), 2.0 * self._sum("den"))

    def _update(self) -> tuple[float, bool]:
        """Set lambda_c from the current state; (lambda, whether it is unclipped)."""
        lam = self.ratio()
        self.lam.value = float(np.clip(lam, -self.mu, self.mu))
        return lam, abs(lam) <= self.mu

    def refresh(self) -> None:
        """Set lambda_c from the current state before the residual or tangent is assembled
        (FacetTerm: add_residual, add_tangent at fixed lambda_c; the rest: low_rank)."""
        self._update()

    def low_rank(self, u: fem.Function) -> list[tuple[PETSc.Vec, PETSc.Vec]]:
        """The tangent's part that add_tangent leaves out: [(G, dlambda)], dR_o += G dlambdaᵀ
        (module docstring), two vectors of the unknown's layout (N per mm, N/mm per mm);
        [] when inactive, when the friction is clipped (|lambda| > mu) or when nothing
        touches (Σ N t_y <= 1e-9 N). The caller owns (and destroys) the vectors. Collective."""
        if not self.active:
            return []
        lam, free = self._update()
        den = 2.0 * self._sum("den")
        if not (free and den > 1e-9):
            return []
        G, dlam, dden = (assembled(f) for f in (self._G, self._dnum, self._dden))
        dlam.axpy(-lam, dden)               # dlambda = (2 d num - lambda 2 d den) / den
        dlam.scale(2.0 / den)
        dden.destroy()
        return [(G, dlam)]

    def refuses(self, u: fem.Function) -> str:
        """Why the solver must not accept u as a converged state (one line), or "": a
        candidate node more than MAX_PENETRATION inside the object (module docstring).
        Collective."""
        if not self.active:
            return ""
        pts, _ = self.nodes(u)
        mine = float(-self.obstacle.signed_distance(pts).min()) if len(pts) else -math.inf
        depth = self.comm.allreduce(mine, op=MPI.MAX)
        if depth > MAX_PENETRATION:
            return (f"the finger went {depth:.3g} mm into the object (more than {MAX_PENETRATION:g} mm: "
                    "a Newton iterate carried it through the surface)")
        return ""

    # ------------------------------------------------------------------ figures
    def nodes(self, u: fem.Function) -> tuple[np.ndarray, np.ndarray]:
        """Global deformed positions (n, 2) mm of the candidate nodes this rank owns, and
        their reference x (n,) mm along the rest finger."""
        xd, yd = self.xy_dofs
        ref = self._ref
        local = np.column_stack([ref[:, 0] + u.x.array[xd], ref[:, 1] + u.x.array[yd]])
        turn = np.array([[math.cos(self.finger.base_angle), -math.sin(self.finger.base_angle)],
                         [math.sin(self.finger.base_angle), math.cos(self.finger.base_angle)]])
        return np.array([0.5 * self.finger.base_gap, 0.0]) + local @ turn.T, ref[:, 0]

    def state(self, u: fem.Function) -> dict:
        """The contact's figures for one finger (full width): normal force N (N), friction
        ratio lambda, friction use |lambda|/mu, slip, friction (N), the resultant force on
        the finger (global, N), the force-weighted contact point (mm), the penetration
        (mm) and the contact patch (the candidate nodes inside the object: count, global
        extent, the parts they lie on)."""
        normal = 2.0 * self._sum("normal")
        lam = self.ratio()
        lam_c = float(np.clip(lam, -self.mu, self.mu))
        pts, xref = self.nodes(u)
        d = self.obstacle.signed_distance(pts)
        inside = d < 0
        gathered = self.comm.allgather((pts[inside], xref[inside], float(-d.min()) if len(d) else 0.0))
        patch = np.concatenate([g[0] for g in gathered]) if gathered else np.zeros((0, 2))
        xs = np.concatenate([g[1] for g in gathered])
        parts = sorted({self._part_of(x) for x in xs})
        touching = normal > 0
        out = {"contact_force_N": normal, "friction_ratio": lam,
               "friction_use": abs(lam) / self.mu if touching else None,
               "slip": bool(abs(lam) > self.mu) if touching else None,
               "friction_N": abs(lam_c) * normal,
               "force_N": [2.0 * (self._sum("fx") - lam_c * self._sum("ft")),
                           2.0 * (self._sum("num") - lam_c * self._sum("den"))],
               "contact_point_mm": ([2.0 * self._sum("mx") / normal, 2.0 * self._sum("my") / normal]
                                    if touching else None),
               "penetration_mm": max(0.0, max(g[2] for g in gathered)),
               "patch": {"nodes": int(len(patch)), "parts": parts,
                         "min_mm": patch.min(0).tolist() if len(patch) else None,
                         "max_mm": patch.max(0).tolist() if len(patch) else None}}
        out["state"] = "no_contact" if not touching else ("slips" if out["slip"] else "holds")
        return out

    def _part_of(self, x: float) -> str:
        """The name of the part at rest-finger x (mm): joint1, link, joint2, tip for the
        paper's finger (joint{j} / rigid{k} otherwise)."""
        finger = self.finger
        for k, p in enumerate(finger.parts):
            if finger.rest_start(k) - 1e-6 <= x <= finger.rest_start(k) + p.length + 1e-6:
                return part_name(finger, k)
        return "?"


def part_name(finger: FingerSpec, k: int) -> str:
    """The predictor's name of part k: joint{j} for the j-th joint; for the paper's finger
    link and tip for its rigid parts (rigid{k} otherwise)."""
    part = finger.parts[k]
    if part.kind == "joint":
        return f"joint{finger.joints.index(k) + 1}"
    rigid = [i for i, p in enumerate(finger.parts) if p.kind == "rigid"]
    if len(rigid) == 2:
        return ("link", "tip")[rigid.index(k)]
    return f"rigid{k}"
