"""Each material law of fem.physics.materials against its closed form on homogeneous deformations.

A unit cube (2 x 2 x 2 boxes of tetrahedra, mm) carries the affine field u = (F - I) X,
which the FEM space holds exactly (P1 displacement; Taylor-Hood P2-P1 for the mixed u-p
form), so every difference from the closed form is the law's implementation or the
solver, never discretisation. For each deformation F:

1. u = (F - I) X is imposed on the whole boundary; the interior unknowns (and the mixed
   pressure) start from a random perturbation and Newton (dense LU) solves R(w) = 0;
2. the reaction of face x_K = 1 in direction j is the sum of the residual's rows of its
   nodes, R_jK = sum_i R(w; phi_i e_j). For a constant P it is exactly P_jK (face area
   1): sum_i phi_i = 1 on the face and its strips on the opposite lateral faces integrate
   to the same value on this mesh, so they cancel;
3. against fem.physics.materials.stress (numpy, written out, not UFL):
   rel = max |R - P(F)| / max |P(F)|; the mixed pressure against -kappa ln J (relative to
   max |P|); and the two formulations against each other.

Deformations (stretches solved with scipy.optimize.brentq from the closed form, apart
from the FEM): ``uniaxial`` F = diag(1.5, t, t) with P22(F) = 0; ``equibiaxial``
diag(1.3, 1.3, t) with P33 = 0; ``simple_shear`` I + 0.5 e1 (x) e2; ``small_strain``
diag(1 + 1e-6, t, t) with P22 = 0, where the FEM's R_11 / 1e-6 is the small-strain E and
-(t - 1) / 1e-6 the small-strain nu of contract.joint.MaterialLaw (within 1e-4).

    python -m fem.studies.materials_check --out results/fem/materials.json
    python -m fem.studies.materials_check --joint my_joint.toml --json     # that joint's law only

Writes fem.artefacts.MATERIALS: per law its small-strain figures and per test the
deformation, the closed-form P, each formulation's relative difference and Newton
iterations, and ``max_rel_diff``; ``worst_rel_diff`` over all laws and tests.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from contract import cli
from contract.joint import MaterialLaw, joint_arg

log = logging.getLogger("softjoint.materials")

#: The laws checked by default: the paper's NinjaFlex and one of each other law, with
#: parameters of the usual sign pattern of elastomer fits (Yeoh's C20 < 0; Ogden's three
#: terms of exponents 1.3, 5, -2), K given or nu given. Test parameters, not fits.
CHECK_LAWS = {
    "neo-hookean": MaterialLaw("neo-hookean", (12.2,), nu=0.49),
    "mooney-rivlin": MaterialLaw("mooney-rivlin", (0.5, 0.1), K=50.0),
    "yeoh": MaterialLaw("yeoh", (0.1, -0.005, 0.002), nu=0.49),
    "ogden": MaterialLaw("ogden", ((0.41, 0.003, 0.01), (1.3, 5.0, -2.0)), K=100.0),
}
STRETCH, BIAXIAL, SHEAR, SMALL = 1.5, 1.3, 0.5, 1e-6
TARGET_REL = 1e-6           # homogeneous tests, relative to max |P|
SMALL_STRAIN_TARGET = 1e-4  # small-strain E and nu, relative
DEGREES = {"displacement": 1, "mixed": 2}   # formulation -> displacement degree
CELLS = 2
QUADRATURE = 2              # P is constant: any degree integrates it exactly


# ---------------------------------------------------------------------- closed forms
def free_stretch(material: MaterialLaw, build, axis: int) -> float:
    """The stretch t with P_aa(build(t)) = 0 for a = ``axis`` (closed form, brentq to
    1e-15): ``build(t)`` is the diagonal F whose free stretches are t."""
    from scipy.optimize import brentq

    from fem.physics.materials import stress

    def traction(t):
        return stress(material, build(t))[axis, axis]

    lo, hi = 0.05, 2.0
    if not traction(lo) < 0 < traction(hi):
        raise ValueError(f"{material.law}: no stretch in [{lo:g}, {hi:g}] frees the lateral faces of "
                         f"F = {np.diag(build(1.0)).tolist()}: the law is not stable there")
    return brentq(traction, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)


def deformations(material: MaterialLaw) -> dict[str, np.ndarray]:
    """The homogeneous deformation gradients of the module docstring."""
    def uniaxial(stretch):
        t = free_stretch(material, lambda t: np.diag([stretch, t, t]), 1)
        return np.diag([stretch, t, t])

    b = free_stretch(material, lambda t: np.diag([BIAXIAL, BIAXIAL, t]), 2)
    shear = np.eye(3)
    shear[0, 1] = SHEAR
    return {"uniaxial": uniaxial(STRETCH), "equibiaxial": np.diag([BIAXIAL, BIAXIAL, b]),
            "simple_shear": shear, "small_strain": uniaxial(1 + SMALL)}


# ---------------------------------------------------------------------- the FEM cube
@dataclass
class CubeResult:
    """Face reactions R (3, 3) N (R[j, K]: direction j on face x_K = 1), Newton
    iterations, and the mixed pressure's nodal values (MPa; None for displacement)."""

    reactions: np.ndarray
    iterations: int
    pressure: np.ndarray | None


class HomogeneousCube:
    """The unit cube of one law and formulation, compiled once, solved for any F."""

    def __init__(self, material: MaterialLaw, formulation: str, cells: int = CELLS):
        import ufl
        from dolfinx import fem, mesh
        from mpi4py import MPI

        from fem.physics.materials import energy, mixed_energy

        cube = mesh.create_unit_cube(MPI.COMM_SELF, cells, cells, cells, mesh.CellType.tetrahedron)
        degree = DEGREES[formulation]
        vector = ufl.VectorElement("Lagrange", cube.ufl_cell(), degree)
        if formulation == "mixed":
            scalar = ufl.FiniteElement("Lagrange", cube.ufl_cell(), degree - 1)
            W = fem.FunctionSpace(cube, ufl.MixedElement([vector, scalar]))
        else:
            W = fem.FunctionSpace(cube, vector)
        self.w = fem.Function(W)
        test, trial = ufl.TestFunction(W), ufl.TrialFunction(W)
        u, p = ufl.split(self.w) if formulation == "mixed" else (self.w, None)
        F = ufl.variable(ufl.Identity(3) + ufl.grad(u))
        psi = mixed_energy(material, F, p) if p is not None else energy(material, F)
        dx = ufl.dx(domain=cube, metadata={"quadrature_degree": QUADRATURE})
        R = ufl.derivative(psi * dx, self.w, test)
        self.residual, self.jacobian = fem.form(R), fem.form(ufl.derivative(R, self.w, trial))
        self._dofs(W, formulation)

    def _dofs(self, W, formulation: str) -> None:
        """Parent indices of u's components at its nodes (n, 3), their coordinates, the
        pressure's (mixed), and which are free (not on the boundary)."""
        if formulation == "mixed":
            U, to_parent = W.sub(0).collapse()
            Q, q_parent = W.sub(1).collapse()
            self.p_dofs, self.p_coords = np.asarray(q_parent), Q.tabulate_dof_coordinates()
        else:
            U, to_parent = W, np.arange(W.dofmap.index_map.size_local * 3)
            self.p_dofs = self.p_coords = None
        self.coords = U.tabulate_dof_coordinates()
        self.u_dofs = np.asarray(to_parent).reshape(-1, 3)
        on_face = (np.abs(self.coords) < 1e-12) | (np.abs(self.coords - 1) < 1e-12)
        self.boundary = on_face.any(axis=1)
        self.faces = [np.abs(self.coords[:, K] - 1) < 1e-12 for K in range(3)]
        fixed = np.zeros(len(self.w.x.array), dtype=bool)
        fixed[self.u_dofs[self.boundary].ravel()] = True
        self.free = np.flatnonzero(~fixed)

    def assemble(self) -> tuple[np.ndarray, np.ndarray]:
        from dolfinx import fem
        from dolfinx.fem.petsc import assemble_matrix

        b = fem.assemble_vector(self.residual).array.copy()
        A = assemble_matrix(self.jacobian)
        A.assemble()
        dense = A.convert("dense").getDenseArray().copy()
        A.destroy()
        return b, dense

    def solve(self, Fbar: np.ndarray, seed: int = 0, max_it: int = 30) -> CubeResult:
        """Impose u = (Fbar - I) X on the boundary and solve for the rest (Newton from a
        random start, 0.02 mm and 0.01 MPa); RuntimeError if it does not converge."""
        x = self.w.x.array
        rng = np.random.default_rng(seed)
        homogeneous = self.coords @ (Fbar - np.eye(3)).T
        x[:] = 0.0
        x[self.u_dofs.ravel()] = homogeneous.ravel()
        x[self.free] += rng.uniform(-0.02, 0.02, len(self.free))
        if self.p_dofs is not None:
            x[self.p_dofs] = rng.uniform(-0.01, 0.01, len(self.p_dofs))
        free = self.free
        for it in range(1, max_it + 1):
            b, A = self.assemble()
            du = np.linalg.solve(A[np.ix_(free, free)], -b[free])
            x[free] += du
            if np.abs(du).max() < 1e-13 * max(1.0, np.abs(x).max()):
                break
        else:
            raise RuntimeError(f"homogeneous cube: Newton did not converge in {max_it} iterations")
        b, _ = self.assemble()
        reactions = np.array([[b[self.u_dofs[self.faces[K], j]].sum() for K in range(3)] for j in range(3)])
        pressure = x[self.p_dofs].copy() if self.p_dofs is not None else None
        return CubeResult(reactions, it, pressure)


# ---------------------------------------------------------------------- one law
def relative(a: np.ndarray, reference: np.ndarray, scale: float) -> float:
    return float(np.abs(np.asarray(a) - reference).max() / scale)


def check_case(cubes: dict, material: MaterialLaw, F: np.ndarray, seed: int) -> dict:
    """One deformation through every formulation's cube: figures of the module docstring."""
    from fem.physics.materials import stress

    P = stress(material, F)
    scale = float(np.abs(P).max())
    out = {"F": F.tolist(), "P_closed_form": P.tolist()}
    reactions = {}
    for name, cube in cubes.items():
        r = cube.solve(F, seed)
        reactions[name] = r.reactions
        row = {"P_fem": r.reactions.tolist(), "rel_diff": relative(r.reactions, P, scale),
               "newton_iterations": r.iterations}
        if r.pressure is not None:
            exact = -material.kappa * math.log(np.linalg.det(F))
            row["pressure_rel_diff"] = relative(r.pressure, exact, scale)
        out[name] = row
    out["max_rel_diff"] = max(max(out[n]["rel_diff"], out[n].get("pressure_rel_diff", 0.0)) for n in cubes)
    if len(reactions) == 2:
        out["formulations_rel_diff"] = relative(reactions["mixed"], reactions["displacement"], scale)
    return out


def check_law(material: MaterialLaw, formulations=tuple(DEGREES), seed: int = 0) -> dict:
    """Every homogeneous test of one law (module docstring): a JSON-ready dict."""
    t0 = time.perf_counter()
    cubes = {f: HomogeneousCube(material, f) for f in formulations}
    tests = {name: check_case(cubes, material, F, seed + k)
             for k, (name, F) in enumerate(deformations(material).items())}
    small = tests["small_strain"]
    E_fem = small["displacement" if "displacement" in cubes else "mixed"]["P_fem"][0][0] / SMALL
    nu_closed = -(small["F"][1][1] - 1) / SMALL
    small.update({"E_fem": E_fem, "E_rel_diff": abs(E_fem / material.youngs_modulus - 1),
                  "nu_closed_form": nu_closed, "nu_rel_diff": abs(nu_closed / material.poisson - 1)})
    worst = max(t["max_rel_diff"] for t in tests.values())
    return {**material.summary(), "tests": tests, "worst_rel_diff": worst,
            "wall_time_s": time.perf_counter() - t0}


def run(laws: dict[str, MaterialLaw]) -> dict:
    """Every law's check and the worst figures (the artefact's document)."""
    out = {}
    for name, material in laws.items():
        log.info("material %s: homogeneous cube tests (first run compiles its forms)", name)
        with cli.heartbeat(f"material {name}"):
            out[name] = check_law(material)
        log.info("material %s: worst relative difference %.2e", name, out[name]["worst_rel_diff"])
    worst = max(d["worst_rel_diff"] for d in out.values())
    small = max(max(d["tests"]["small_strain"]["E_rel_diff"], d["tests"]["small_strain"]["nu_rel_diff"])
                for d in out.values())
    return {"laws": out, "worst_rel_diff": worst, "target_rel": TARGET_REL,
            "worst_small_strain_rel_diff": small, "small_strain_target_rel": SMALL_STRAIN_TARGET,
            "target_met": worst <= TARGET_REL and small <= SMALL_STRAIN_TARGET,
            "mesh": {"cells_per_edge": CELLS, "degrees": DEGREES, "quadrature_degree": QUADRATURE}}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m fem.studies.materials_check", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", suffix=".json", default=None,
                  help="result file (e.g. results/fem/materials.json; default: none)")
    ap.add_argument("--joint", type=joint_arg, default=None, metavar="FILE",
                    help="check this joint file's material law instead of the default laws")
    cli.add_quiet(ap)
    args = ap.parse_args(argv)
    cli.setup_logging(args.quiet)
    laws = CHECK_LAWS if args.joint is None else {args.joint.material.law: args.joint.material}
    from fem.artefacts import MATERIALS

    with ap.errors():
        doc = run(laws)
        if args.out:
            MATERIALS.write(args.out, doc)
    if args.json:
        cli.print_json({**doc, "out": args.out})
        return 0
    for name, d in doc["laws"].items():
        tests = ", ".join(f"{t} {v['max_rel_diff']:.1e}" for t, v in d["tests"].items())
        print(f"{name}: {tests}; small-strain E {d['tests']['small_strain']['E_rel_diff']:.1e}, "
              f"nu {d['tests']['small_strain']['nu_rel_diff']:.1e}")
    print(f"worst relative difference {doc['worst_rel_diff']:.2e} (target {TARGET_REL:g}); "
          f"small-strain {doc['worst_small_strain_rel_diff']:.2e} (target {SMALL_STRAIN_TARGET:g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
