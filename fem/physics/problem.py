"""Physics of the FEM models as problem objects: what is solved, apart from how.

Units: mm, N, MPa (= N/mm²), N·mm; angles in rad.

A :class:`Problem` holds one static boundary-value problem in the unknown displacement u
(P``degree`` vector field, mm) of a half-model (z >= 0):

    R(u; v; a) = R_int(u; v) + sum_i c_i(a) G_i(u; v) = 0      for all v,  u = 0 on Dirichlet faces

* R_int, the internal virtual work of a hyperelastic energy psi, P = d psi / d F::

      F = I + grad u,   J = det F,   psi(F) = psi_dev(F) + kappa/2 (ln J)^2

  where the law (psi_dev, kappa) is a contract.joint.MaterialLaw written as a UFL energy
  by fem.physics.materials (neo-Hookean, Mooney-Rivlin, Yeoh, Ogden). The paper's NinjaFlex is the
  compressible neo-Hookean law

      psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,   I1 = tr(F^T F)
      mu = E / (2 (1 + nu)),   lambda = E nu / ((1 + nu)(1 - 2 nu))

  (:func:`neo_hookean_psi`; fem.physics.materials builds the same UFL expression, so its forms,
  and the committed data, are unchanged). With ``formulation="mixed"`` the same energy
  is split by a pressure p (MPa, positive in compression; Taylor-Hood: P``degree`` u,
  continuous P``degree - 1`` p) as the stationary point of the perturbed Lagrangian

      Pi(u, p) = ∫ psi_dev - p ln J - p² / (2 kappa) dX

  whose p-equation ∫ q (ln J + p / kappa) dX = 0 makes p the projection of
  -kappa ln J, i.e. J = exp(-p / kappa) ≈ 1 - p / kappa: at the solution Pi is the
  displacement energy above, so both formulations converge to one answer, but the
  near-incompressible kappa ~ 50 mu no longer enters the displacement stiffness
  directly (no volumetric locking). The unknown is then w = (u, p); its first three
  components are u;

* the loads: each :class:`LoadTerm` is a constant c_i (a ``fem.Constant``) times its form
  G_i = dR/dc_i, and c_i follows one entry of the load vector a, either linearly
  (c = a_j) or one-sided (c = max(±a_j, 0): a signed pressure P inflates the top chamber
  when P > 0 and the bottom one when P < 0);
* an optional contact term (:class:`fem.physics.contact.ValleyContact`) assembled apart;
* lagged constants (:class:`Lagged`): values recomputed from each converged state (the
  cap's rotation that the end loads are written relative to);
* probe points (material points whose displacement is reported) and named volume
  averages (:class:`Average`, e.g. the rotation of a rigid part).

The problem is declared here, solved by :class:`fem.solvers.load_path.LoadPathSolver` (load path,
Newton, MUMPS, sensitivities), which knows nothing of the physics.

The physics pieces, written once and shared by the joint, the beam and the finger:

* :func:`law_work`: internal virtual work of one region of a MaterialLaw (mixed:
  :func:`mixed_law_work`); :func:`elastic_work` the same for a neo-Hookean (E, nu) region
  (the beam, the finger's rigid parts);
* :func:`bellow_work`: a joint's body of its law and its stiff distal cap (neo-Hookean,
  modulus ``cap_stiffness`` x the body's small-strain E, MaterialLaw.cap(), so it moves
  rigidly to solver precision);
* :func:`chamber_pressures`: follower pressure on the deformed chamber walls (Nanson)::

      t0 = -p J F^-T N = -p cofac(F) N,   p_top = max(P, 0),  p_bottom = max(-P, 0)

* :func:`end_loads`: F1, F2 (dead, joint frame) at the reference point X_ref and the pure
  couple M about +z, through the rigid cap's rotation theta (:func:`rotation_about_z`)::

      Pi_ext = -1/(2 V_cap) ∫_cap [ f·(u + (R(theta) - I)(X_ref - X)) + M theta ] dX

  whose variation is f·δu_ref + M δtheta: the couple is M at any end rotation. theta is
  measured relative to the last converged rotation (a lagged constant), so it has no
  branch cut; the half-model carries half of each resultant;
* :func:`valley_contact`: penalty self-contact of the valley walls (:mod:`fem.physics.contact`).

Data flow: MeshData (fem.mesh.data, built by fem.mesh.build), MaterialLaw (contract.joint, a joint file's [material])
-> joint_problem / fem.physics.finger.finger_problem -> Problem -> fem.solvers.load_path.LoadPathSolver.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from contract.joint import FORMULATIONS, MaterialLaw
from fem.physics.contact import ValleyContact
from fem.mesh.geometry import TAGS, JointGeometry
from fem.physics.materials import energy, mixed_energy
from fem.mesh.data import MeshData


@dataclass(frozen=True)
class Material:
    """Neo-Hookean material (MPa) by (E, nu). Defaults: NinjaFlex, the paper's joint
    (contract/joints/paper.toml). :meth:`law` is the same material as a MaterialLaw."""

    E: float = 12.2
    nu: float = 0.49
    # Distal cap modulus = cap_stiffness * E: the 3 mm solid cap then bends by < 3e-5 rad
    # under M = 100 N·mm, rigid for every reported figure. Much stiffer caps slow Newton:
    # a linearised rotation step strains a stiff block by ~theta^2/2.
    cap_stiffness: float = 100.0
    # The connector need not be nearly incompressible; nu = 0.3 keeps lambda_cap small,
    # since lambda * theta^2/2 is the spurious stress a linearised rotation step creates.
    cap_nu: float = 0.3

    def law(self) -> MaterialLaw:
        """This material as a contract.joint.MaterialLaw ("neo-hookean", E, nu, cap)."""
        return MaterialLaw("neo-hookean", (self.E,), nu=self.nu, cap_stiffness=self.cap_stiffness,
                           cap_nu=self.cap_nu)


def as_law(material: MaterialLaw | Material) -> MaterialLaw:
    """A MaterialLaw, given one or an (E, nu) Material."""
    return material.law() if isinstance(material, Material) else material


# ---------------------------------------------------------------------- problem types
@dataclass(frozen=True, eq=False)
class LoadTerm:
    """One load of the residual: ``constant`` c times ``form`` G = dR/dc.

    c follows entry ``index`` of the load vector a: c = a_j (``side`` 0), max(a_j, 0)
    (side +1) or max(-a_j, 0) (side -1)."""

    constant: fem.Constant
    form: ufl.Form
    index: int
    side: int = 0

    def value(self, a: np.ndarray) -> float:
        x = a[self.index]
        return x if self.side == 0 else max(self.side * x, 0.0)

    def slope(self, a: np.ndarray) -> float:
        """dc/da_j; at a_j = 0 the one-sided derivative of the + side (side +1 active)."""
        x = a[self.index]
        if self.side == 0:
            return 1.0
        active = x >= 0 if self.side > 0 else x < 0
        return float(self.side) if active else 0.0


@dataclass(frozen=True, eq=False)
class Average:
    """Volume average of a scalar field f over a region: ∫ f dX / volume."""

    form: object                    # compiled dolfinx form of ∫ f dX
    volume: float                   # mm³ (of the half-model)

    def value(self, comm: MPI.Comm) -> float:
        """The average over all ranks (collective)."""
        return comm.allreduce(fem.assemble_scalar(self.form), op=MPI.SUM) / self.volume


@dataclass(frozen=True, eq=False)
class Lagged:
    """A constant of the forms set to ``average`` at every converged state (0 at rest)."""

    constant: fem.Constant
    average: Average


@dataclass(frozen=True, eq=False)
class Problem:
    """A static problem R(u; v; a) = 0 (module docstring), ready for a solver.

    ``load_scale`` (len(a),): the full-range magnitude of each load entry, which sizes the
    solver's first step. ``probe_points`` (n, 3) mm: material points whose displacement
    the solver reports. ``averages``: named outputs (e.g. part rotations, rad).

    ``u`` is the unknown: the displacement (mm), or for ``formulation`` "mixed" the pair
    w = (u, p) whose first three components are u; ``displacement_space`` is then u's
    own (collapsed) space, for counting nodes."""

    mesh_data: MeshData
    u: fem.Function
    internal: ufl.Form
    loads: tuple[LoadTerm, ...]
    load_scale: np.ndarray
    bcs: tuple
    probe_points: np.ndarray
    contact: ValleyContact | None = None
    lagged: tuple[Lagged, ...] = ()
    averages: dict = field(default_factory=dict)
    formulation: str = "displacement"
    displacement_space: object = None

    @property
    def V(self):
        return self.u.function_space

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh_data.mesh.comm

    def residual(self) -> ufl.Form:
        """R(u; v) with the loads as constants."""
        R = self.internal
        for term in self.loads:
            R = R + term.constant * term.form
        return R

    def set_load(self, a: np.ndarray) -> None:
        """Set every load constant for the load vector ``a``."""
        for term in self.loads:
            term.constant.value = term.value(a)

    def displacement(self) -> fem.Function:
        """u (mm) as a Function of its own vector space: ``u`` itself, or for "mixed" a
        copy of w's displacement block (for writers and plots, which take no mixed field)."""
        return self.u if self.displacement_space is None else self.u.sub(0).collapse()


# ---------------------------------------------------------------------- physics pieces
def lame(E: float, nu: float) -> tuple[float, float]:
    """(mu, lambda) in MPa of Young's modulus E (MPa) and Poisson's ratio nu."""
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def neo_hookean_psi(F, mu, lmbda):
    """Strain energy density psi(F) (MPa = N·mm/mm³), compressible neo-Hookean: the
    reference expression that fem.physics.materials.energy reproduces for the law "neo-hookean"."""
    J = ufl.det(F)
    I1 = ufl.tr(F.T * F)
    return mu / 2 * (I1 - 3) - mu * ufl.ln(J) + lmbda / 2 * ufl.ln(J) ** 2


def deformation_gradient(u):
    """F = I + grad u as a UFL variable (so that P = ufl.diff(psi, F))."""
    return ufl.variable(ufl.Identity(len(u)) + ufl.grad(u))


def law_work(F, v, law: MaterialLaw, dx):
    """Internal virtual work ∫ P : grad v dX (N·mm per mm of v) of a region of ``law``,
    P = d psi / d F of fem.physics.materials.energy."""
    P = ufl.diff(energy(law, F), F)
    return ufl.inner(P, ufl.grad(v)) * dx


def neo_hookean(E: float, nu: float) -> MaterialLaw:
    """The compressible neo-Hookean law of Young's modulus E (MPa) and Poisson's ratio nu."""
    return MaterialLaw("neo-hookean", (E,), nu=nu)


def elastic_work(F, v, E: float, nu: float, dx):
    """Internal virtual work of a neo-Hookean (E MPa, nu) region (:func:`law_work`)."""
    return law_work(F, v, neo_hookean(E, nu), dx)


def bellow_work(F, v, material: MaterialLaw | Material, body, cap):
    """A joint's internal virtual work: ``body`` of its law and its stiff distal ``cap``
    (MaterialLaw.cap(): neo-Hookean, cap_stiffness x the body's small-strain E)."""
    law = as_law(material)
    return law_work(F, v, law, body) + law_work(F, v, law.cap(), cap)


def rotation_about_z(F, theta_ref=0.0):
    """Rotation (rad) about +z of the material at a point, theta = atan2(F_yx - F_xy,
    F_xx + F_yy): exact for any rigid motion, and the polar rotation's angle for a planar
    F. Taken relative to ``theta_ref`` (UFL scalar), so it has no branch cut near it."""
    c, s = ufl.cos(theta_ref), ufl.sin(theta_ref)
    a, b = F[0, 0] + F[1, 1], F[1, 0] - F[0, 1]
    return theta_ref + ufl.atan_2(b * c - a * s, a * c + b * s)


def follower_pressure(F, v, ds):
    """Virtual work per unit pressure of a follower load on the deformed surface ``ds``
    (Nanson: t0 = -p cofac(F) N; this is the residual term divided by p)."""
    N = ufl.FacetNormal(ufl.domain.extract_unique_domain(v))
    return ufl.inner(ufl.cofac(F) * N, v) * ds


def chamber_pressures(F, v, ds, top: int, bottom: int, present: set, index: int) -> tuple:
    """Load terms of one joint's signed pressure a[index] (MPa): P > 0 on the ``top``
    chamber's walls, -P on the ``bottom`` one's (facet tags; absent ones are skipped)."""
    mesh = ufl.domain.extract_unique_domain(v)
    return tuple(LoadTerm(fem.Constant(mesh, PETSc.ScalarType(0)),
                          follower_pressure(F, v, ds(tag)), index, side)
                 for tag, side in ((top, 1), (bottom, -1)) if tag in present)


def region_volume(mesh, dx, comm: MPI.Comm) -> float:
    """Volume (mm³) of the region of measure ``dx`` (collective)."""
    one = fem.Constant(mesh, PETSc.ScalarType(1))
    return comm.allreduce(fem.assemble_scalar(fem.form(one * dx)), op=MPI.SUM)


def end_loads(F, u, v, dx_cap, ref_point, first: int, unknown=None,
              test=None) -> tuple[tuple, Lagged]:
    """F1, F2 (N) at ``ref_point`` carried by the rigid cap and the couple M (N·mm) about
    +z (module docstring), on load entries first .. first + 2; and the cap rotation they
    are measured from (lagged, rad). The potentials are varied in ``unknown`` along
    ``test`` (default u and v; the mixed pair w and its test function)."""
    unknown, test = (u, v) if unknown is None else (unknown, test)
    mesh = unknown.function_space.mesh
    theta_ref = fem.Constant(mesh, PETSc.ScalarType(0))
    theta = rotation_about_z(F, theta_ref)
    volume = region_volume(mesh, dx_cap, mesh.comm)
    # Mesh-dependent numbers are Constants, so one compiled form serves every mesh.
    X = ufl.SpatialCoordinate(mesh)
    Xref = fem.Constant(mesh, np.asarray(ref_point[:2], dtype=PETSc.ScalarType))
    Rth = ufl.as_matrix([[ufl.cos(theta), -ufl.sin(theta)], [ufl.sin(theta), ufl.cos(theta)]])
    arm = Xref - ufl.as_vector([X[0], X[1]])
    u_ref = ufl.as_vector([u[0], u[1]]) + (Rth - ufl.Identity(2)) * arm
    w = fem.Constant(mesh, PETSc.ScalarType(-0.5 / volume))   # the half-model carries half
    potentials = [w * u_ref[0] * dx_cap, w * u_ref[1] * dx_cap, w * theta * dx_cap]
    terms = tuple(LoadTerm(fem.Constant(mesh, PETSc.ScalarType(0)), ufl.derivative(pi, unknown, test),
                           first + i) for i, pi in enumerate(potentials))
    return terms, Lagged(theta_ref, Average(fem.form(theta * dx_cap), volume))


def facet_tags_present(facet_tags) -> set:
    """The facet tag values present on any rank (collective)."""
    comm = facet_tags.mesh.comm
    tags = set(np.unique(facet_tags.values)) if facet_tags.values.size else set()
    return comm.allreduce(tags, op=MPI.BOR) if comm.size > 1 else tags


def contact_penalty_for(penalty: float, material: MaterialLaw | Material) -> float:
    """The valley-contact penalty (MPa/mm) of a joint of ``material``: ``penalty`` (the
    solver's, SolverConfig.contact_penalty) holds for the paper's E = 12.2 MPa and scales
    with the law's small-strain modulus E0, so that an overlap costs the same strain in any
    elastomer. (A fixed 100 MPa/mm on a 0.5 MPa silicone is a spring 23x too stiff for
    its walls: Newton stalls where the valleys close.) The paper's joint keeps ``penalty``
    exactly."""
    return penalty * (as_law(material).youngs_modulus / Material().E)


def valley_contact(V, facet_tags, present: set, joint: JointGeometry, penalty: float | tuple[float, ...],
                   offsets: tuple[float, ...] = (0.0,), parent=None) -> ValleyContact | None:
    """The valley self-contact of the joints at x = ``offsets`` (mm), or None when the
    mesh has no valley faces or the penalty (MPa/mm; one, or one per joint) is 0.
    ``parent``: see ValleyContact (V a displacement space collapsed out of the mixed space)."""
    if TAGS["valley_faces"] not in present or np.max(penalty) <= 0:
        return None
    return ValleyContact(V, facet_tags, joint, penalty, offsets=offsets, parent=parent)


def clamp_and_symmetry(V, facet_tags) -> list:
    """u = 0 on the ``proximal`` facets and u_z = 0 on the ``symmetry`` plane z = 0."""
    tdim = V.mesh.topology.dim
    zero = np.zeros(3, dtype=PETSc.ScalarType)
    clamp = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(TAGS["proximal"]))
    Vz = V.sub(2)
    sym = fem.locate_dofs_topological(Vz, tdim - 1, facet_tags.find(TAGS["symmetry"]))
    return [fem.dirichletbc(zero, clamp, V), fem.dirichletbc(PETSc.ScalarType(0), sym, Vz)]


def displacement_space(mesh_data: MeshData, degree: int, quadrature_degree: int):
    """(u, v, dx, ds) of a half-model: the unknown displacement u (mm) in a P``degree``
    vector space, its test function and the tagged measures at ``quadrature_degree``."""
    mesh, ct, ft = mesh_data.mesh, mesh_data.cell_tags, mesh_data.facet_tags
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    V = fem.VectorFunctionSpace(mesh, ("CG", degree))
    md = {"quadrature_degree": quadrature_degree}
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=ct, metadata=md)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=ft, metadata=md)
    return fem.Function(V, name="u"), ufl.TestFunction(V), dx, ds


# ---------------------------------------------------------------------- mixed u-p


@dataclass(frozen=True, eq=False)
class MixedFields:
    """The mixed unknown w = (u, p) of a Taylor-Hood space W and its pieces: UFL u (mm) and
    p (MPa) with their test functions; ``U`` the collapsed displacement space and
    ``to_parent[i]`` the local dof of W of U's unrolled local dof i."""

    w: fem.Function
    u: object
    p: object
    test: object
    v: object
    q: object
    U: object
    to_parent: np.ndarray


def mixed_space(mesh_data: MeshData, degree: int, quadrature_degree: int):
    """(MixedFields, dx, ds) of a half-model: P``degree`` u with a continuous
    P``degree - 1`` pressure (Taylor-Hood, inf-sup stable for degree >= 2)."""
    if degree < 2:
        raise ValueError(f"the mixed formulation needs degree >= 2 (Taylor-Hood), not {degree}")
    mesh, ct, ft = mesh_data.mesh, mesh_data.cell_tags, mesh_data.facet_tags
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    cell = mesh.ufl_cell()
    W = fem.FunctionSpace(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, degree),
                                                   ufl.FiniteElement("Lagrange", cell, degree - 1)]))
    w = fem.Function(W, name="u_p")
    test = ufl.TestFunction(W)
    (u, p), (v, q) = ufl.split(w), ufl.split(test)
    U, to_parent = W.sub(0).collapse()
    md = {"quadrature_degree": quadrature_degree}
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=ct, metadata=md)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=ft, metadata=md)
    return MixedFields(w, u, p, test, v, q, U, np.asarray(to_parent)), dx, ds


def mixed_energy_density(F, p, E: float, nu: float):
    """The perturbed-Lagrangian density (MPa) of the module docstring,
    mu/2 (I1 - 3) - mu ln J - p ln J - p²/(2 lambda); stationary in p at p = -lambda ln J,
    where it equals neo_hookean_psi (the reference of fem.physics.materials.mixed_energy for the
    law "neo-hookean"). Needs lambda > 0 (nu > 0)."""
    mu, lmbda = lame(E, nu)
    if lmbda <= 0:
        raise ValueError(f"the mixed formulation needs nu > 0 (lambda > 0), not nu = {nu}")
    J = ufl.det(F)
    return mu / 2 * (ufl.tr(F.T * F) - 3) - mu * ufl.ln(J) - p * ufl.ln(J) - p ** 2 / (2 * lmbda)


def mixed_bellow_work(fields: MixedFields, F, material: MaterialLaw | Material, body, cap):
    """A joint's internal virtual work in w = (u, p): the variation of Pi(u, p) over the
    ``body`` of its law and the stiff ``cap`` (MaterialLaw.cap(); one continuous pressure
    across both)."""
    law = as_law(material)
    Pi = mixed_energy(law, F, fields.p) * body + mixed_energy(law.cap(), F, fields.p) * cap
    return ufl.derivative(Pi, fields.w, fields.test)


def mixed_law_work(fields: MixedFields, F, law: MaterialLaw, dx):
    """Internal virtual work in w = (u, p) of one region of ``law`` (kappa > 0): the
    variation of ∫ fem.physics.materials.mixed_energy dX, the mixed counterpart of law_work."""
    return ufl.derivative(mixed_energy(law, F, fields.p) * dx, fields.w, fields.test)


def mixed_elastic_work(fields: MixedFields, F, E: float, nu: float, dx):
    """Internal virtual work in w = (u, p) of one neo-Hookean region (E MPa, nu > 0)."""
    return mixed_law_work(fields, F, neo_hookean(E, nu), dx)


def mixed_clamp_and_symmetry(W, facet_tags) -> list:
    """u = 0 on the ``proximal`` facets and u_z = 0 on ``symmetry``, on the displacement
    block of the mixed space W (one scalar condition per component)."""
    fdim = W.mesh.topology.dim - 1
    U = W.sub(0)
    clamp, sym = facet_tags.find(TAGS["proximal"]), facet_tags.find(TAGS["symmetry"])
    bcs = [fem.dirichletbc(PETSc.ScalarType(0), fem.locate_dofs_topological(U.sub(c), fdim, clamp),
                           U.sub(c)) for c in range(3)]
    bcs.append(fem.dirichletbc(PETSc.ScalarType(0), fem.locate_dofs_topological(U.sub(2), fdim, sym),
                               U.sub(2)))
    return bcs


# ---------------------------------------------------------------------- the joint
def joint_problem(mesh_data: MeshData, ref_point, probe_points, load_scale,
                  material: MaterialLaw | Material = Material(), *, degree: int = 2,
                  quadrature_degree: int = 2, contact_penalty: float = 100.0,
                  formulation: str = "displacement") -> Problem:
    """One joint-like body clamped at x = 0 (the bellow joint, or the benchmark beam):
    body and stiff cap, chamber pressure, valley contact where the mesh has them, and the
    end loads at ``ref_point`` (3,) mm. ``material``: the body's law (a contract.joint
    MaterialLaw, or an (E, nu) Material). Load vector a = (P, F1, F2, M) in MPa, N, N, N·mm,
    with full-range magnitudes ``load_scale`` (4,). ``formulation``: "displacement"
    (P``degree`` u) or "mixed" (Taylor-Hood u-p, module docstring). Collective."""
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {FORMULATIONS}, not {formulation!r}")
    if formulation == "mixed":
        return mixed_joint_problem(mesh_data, ref_point, probe_points, load_scale, material,
                                   degree=degree, quadrature_degree=quadrature_degree,
                                   contact_penalty=contact_penalty)
    u, v, dx, ds = displacement_space(mesh_data, degree, quadrature_degree)
    V, ft = u.function_space, mesh_data.facet_tags
    F = deformation_gradient(u)
    internal = bellow_work(F, v, material, dx(TAGS["solid"]), dx(TAGS["distal_cap"]))
    present = facet_tags_present(ft)
    pressure = chamber_pressures(F, v, ds, TAGS["top_chamber"], TAGS["bottom_chamber"], present, 0)
    forces, cap = end_loads(F, u, v, dx(TAGS["distal_cap"]), ref_point, first=1)
    return Problem(mesh_data, u, internal, pressure + forces, np.asarray(load_scale, dtype=float),
                   tuple(clamp_and_symmetry(V, ft)), np.asarray(probe_points, dtype=float).reshape(-1, 3),
                   valley_contact(V, ft, present, mesh_data.geometry,
                                  contact_penalty_for(contact_penalty, material)),
                   lagged=(cap,), averages={"cap_rotation": cap.average})


def mixed_joint_problem(mesh_data: MeshData, ref_point, probe_points, load_scale,
                        material: MaterialLaw | Material = Material(), *, degree: int = 2,
                        quadrature_degree: int = 2, contact_penalty: float = 100.0) -> Problem:
    """:func:`joint_problem` in the mixed u-p formulation: the same loads, contact, cap
    rotation and probes, with the internal work of Pi(u, p). Collective."""
    fields, dx, ds = mixed_space(mesh_data, degree, quadrature_degree)
    W, ft = fields.w.function_space, mesh_data.facet_tags
    F = deformation_gradient(fields.u)
    internal = mixed_bellow_work(fields, F, material, dx(TAGS["solid"]), dx(TAGS["distal_cap"]))
    present = facet_tags_present(ft)
    pressure = chamber_pressures(F, fields.v, ds, TAGS["top_chamber"], TAGS["bottom_chamber"],
                                 present, 0)
    forces, cap = end_loads(F, fields.u, fields.v, dx(TAGS["distal_cap"]), ref_point, first=1,
                            unknown=fields.w, test=fields.test)
    contact = valley_contact(fields.U, ft, present, mesh_data.geometry,
                             contact_penalty_for(contact_penalty, material), parent=(W, fields.to_parent))
    return Problem(mesh_data, fields.w, internal, pressure + forces,
                   np.asarray(load_scale, dtype=float), tuple(mixed_clamp_and_symmetry(W, ft)),
                   np.asarray(probe_points, dtype=float).reshape(-1, 3), contact,
                   lagged=(cap,), averages={"cap_rotation": cap.average},
                   formulation="mixed", displacement_space=fields.U)
