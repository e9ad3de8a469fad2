"""The joint's discretisations: what the FEM data is generated on, named once.

A discretisation is (mesh, formulation, q, kappa). The mesh is either tetrahedra of size H
mm and W mm on the 1.2 mm chamber walls (JointGeometry.mesh_size, wall_mesh_size; W = None:
H; written "H" or "H:W"), or the swept hexahedra of n divisions (JointGeometry.divisions,
fem.mesh.hexahedra: n elements through every wall; written "hexN"), optionally graded by S mm
(JointGeometry.hex_size: long intervals cut into elements of at most S / n; "hexN:S"). Then the formulation
("displacement": P2 / Q2 displacement; "mixed": Taylor-Hood P2-P1 / Q2-Q1 u-p, see
fem.physics.problem), the quadrature degree q (at least HEX_QUADRATURE on hexahedra) and
the valley-contact penalty kappa (MPa/mm).

* PAPER: the paper-fidelity 1.8 mm P2 displacement discretisation (H = PAPER_MESH_SIZE),
  the reference artefacts' (results/data/{train,heldout}_h1.8, results/*/h1.8, the lone-finger cases of
  results/validation/finger_fem); the tools that resume or check them pass it explicitly
  (the Makefile's PAPER_MESH);
* PRODUCTION: what new data is generated on, "hex2:3" mixed with quadrature 4 (key
  ``hex2s3_mixed_q4_k100``; chosen by ``make mesh-study``, issue 35, docs/decisions.md §9):
  Discretisation's defaults, JointGeometry's default mesh, FORMULATION and the paper joint
  file's [mesh] are PRODUCTION's.

A dataset's manifest records its geometry and solver settings (SolverConfig: the
discretisation's keywords and the Newton / load-stepping controls of fem.solvers.load_path), and its
formulation only when it is not "displacement" (a manifest without it is a displacement one).

Value objects only: this module imports no dolfinx, so the command-line pieces
(fem.options) and the dolfinx modules (fem.mesh.hexahedra, fem.physics.problem,
fem.solvers.load_path) all build on it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from contract import cli
from contract.joint import FORMULATIONS
from fem.mesh.geometry import MAX_DIVISIONS, PAPER_MESH_SIZE, JointGeometry, mesh_record

#: the formulation new data is generated on (PRODUCTION's)
FORMULATION = "mixed"
#: Quadrature degree of Q2 hexahedra (fem.mesh.hexahedra): dolfinx's default for Q2 is 2 x 2 x 2,
#: which under-integrates the Q2 stiffness (hourglass modes).
HEX_QUADRATURE = 4
#: Tetrahedron and hexahedron sizes, mm: finer meshes than 0.3 mm do not fit in memory (the
#: paper-fidelity 1.8 mm mesh has 17,359 P2 nodes, nodes ~ h^-3), coarser ones than 10 mm no
#: longer resolve the 2.5 mm valleys of the joint or the 2 mm beam.
MESH_SIZE_RANGE = (0.3, 10.0)
MESH_SIZE = cli.number(*MESH_SIZE_RANGE, "mm")   # argparse type, and parse_mesh's check


@dataclass(frozen=True)
class SolverConfig:
    """Discretisation and Newton / load-stepping controls."""

    degree: int = 2                 # Lagrange degree of u
    quadrature_degree: int = 2      # exact for the linearised P2 stiffness; see mesh study
    atol: float = 1e-8              # Newton: absolute residual 2-norm (N)
    stol: float = 1e-9              # Newton: |du| <= stol |u|, just above round-off
    max_it: int = 12
    chord_steps: int = 3            # extra back-substitutions per factorisation (see newton)
    krylov_rtol: float = 1e-9       # Newton corrections: GMRES on the current tangent with
                                    # a recent tangent's factorisation as preconditioner
    sensitivity_rtol: float = 1e-10 # GMRES for d u / d inputs
    krylov_max_it: int = 30         # more: refactorise (the preconditioner went stale)
    mumps_blr: float | None = 1e-8  # MUMPS block low-rank dropping threshold (None: exact)
    box_step: float = 0.25          # first step: at most this fraction of the box per input
    first_step: float | None = None # or a fixed first path fraction (e.g. for the beam)
    max_step: float = 1.0
    min_step: float = 1.0 / 256     # give up below this path fraction
    grow: float = 1.5               # step growth after an easy step (<= 6 iterations)
    contact_penalty: float = 100.0  # valley self-contact, MPa/mm of overlap (0: off), at
                                    # E = 12.2 MPa: fem.physics.problem.contact_penalty_for

    def discretisation(self) -> dict:
        """The keyword arguments of the problem builders (fem.physics.problem.joint_problem)."""
        return {"degree": self.degree, "quadrature_degree": self.quadrature_degree,
                "contact_penalty": self.contact_penalty}



@dataclass(frozen=True)
class Discretisation:
    """One discretisation of the joint: sizes in mm (None on hexahedra), penalty in MPa/mm.
    The defaults are PRODUCTION (JointGeometry's default hexahedra, FORMULATION, the
    hexahedra's quadrature). Build one from its mesh text with :func:`discretisation`."""

    H: float | None = None
    W: float | None = None
    formulation: str = FORMULATION
    quadrature: int = HEX_QUADRATURE
    penalty: float = SolverConfig.contact_penalty
    divisions: int = JointGeometry.divisions
    hex_size: float | None = JointGeometry.hex_size

    def __post_init__(self):
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, not {self.formulation!r}")
        if not (isinstance(self.divisions, int) and 0 <= self.divisions <= MAX_DIVISIONS):
            raise ValueError(f"divisions must be a whole number in [0, {MAX_DIVISIONS}], not {self.divisions!r}")
        if self.divisions and (self.H, self.W) != (None, None):
            raise ValueError("a hexahedral discretisation has no tetrahedron sizes (H = W = None)")
        if self.divisions and self.quadrature < HEX_QUADRATURE:
            raise ValueError(f"Q2 hexahedra need quadrature degree >= {HEX_QUADRATURE} "
                             f"(fewer points leave hourglass modes), not {self.quadrature}")
        if not self.divisions and self.H is None:
            raise ValueError("a tetrahedral discretisation needs its size H (mm)")
        if self.hex_size is not None and not (self.divisions and self.hex_size > 0):
            raise ValueError(f"hex_size = {self.hex_size!r}: a positive size (mm), for hexahedra only")

    @property
    def key(self) -> str:
        """File-name key, e.g. ``h2.4_w1.2_mixed_q2_k100``, ``hex2_mixed_q4_k100`` or
        ``hex2s2.5_mixed_q4_k100``."""
        if self.divisions:
            graded = f"s{self.hex_size:g}" if self.hex_size else ""
            return f"hex{self.divisions}{graded}_{self.formulation}_q{self.quadrature}_k{self.penalty:g}"
        w = "none" if self.W is None else f"{self.W:g}"
        return f"h{self.H:g}_w{w}_{self.formulation}_q{self.quadrature}_k{self.penalty:g}"

    @property
    def mesh(self) -> str:
        """``H``, ``H:W`` (mm) or ``hexN`` (JointGeometry.mesh)."""
        return self.geometry().mesh

    @property
    def sizes(self) -> tuple[float, float]:
        """Element sizes (in-plane, wall) up to one factor per mesh kind: (H, W) mm on
        tetrahedra, (1/n, 1/n) on hexahedra; two meshes of one kind whose sizes share one
        ratio are refinements of each other (fem.studies.mesh_study's families; a graded hexahedral
        mesh is its own kind, ``element``)."""
        if self.divisions:
            return (1.0 / self.divisions,) * 2
        return self.H, self.W or self.H

    def as_dict(self) -> dict:
        """The fields; ``divisions`` only on hexahedra and ``hex_size`` only when set, so
        records written before them read as what they are."""
        return mesh_record(self)

    @property
    def element(self) -> str:
        """The mesh kind: "tet", "hex", or "hex:S" (graded by S mm: refinements in n of one
        S are nested, and no uniform hexN is one of them)."""
        if not self.divisions:
            return "tet"
        return "hex" if self.hex_size is None else f"hex:{self.hex_size:g}"

    def geometry(self, base: JointGeometry = JointGeometry()) -> JointGeometry:
        if self.divisions:
            return replace(base, divisions=self.divisions, hex_size=self.hex_size)
        return replace(base, mesh_size=self.H, wall_mesh_size=self.W, divisions=0, hex_size=None)

    def config(self, base: SolverConfig = SolverConfig()) -> SolverConfig:
        return replace(base, quadrature_degree=self.quadrature, contact_penalty=self.penalty)


PAPER = Discretisation(H=PAPER_MESH_SIZE, W=None, formulation="displacement", quadrature=2, penalty=100.0,
                       divisions=0, hex_size=None)
PRODUCTION = Discretisation()


def parse_mesh(text: str) -> dict:
    """The mesh fields of a Discretisation from its text: "H" or "H:W" (mm, each in
    MESH_SIZE's range), "hexN" (N divisions, with the hexahedra's quadrature
    degree) or "hexN:S" (graded by S mm, in MESH_SIZE's range). Raises ValueError with a
    one-line reason."""
    text = text.strip()
    if text.startswith("hex"):
        n, _, s = text[3:].partition(":")
        if not (n.isdigit() and 1 <= int(n) <= MAX_DIVISIONS):
            raise ValueError(f"{text!r}: hexN needs N in [1, {MAX_DIVISIONS}]")
        return {"H": None, "W": None, "divisions": int(n), "quadrature": HEX_QUADRATURE,
                "hex_size": MESH_SIZE(s) if s else None}
    h, _, w = text.partition(":")
    return {"H": MESH_SIZE(h), "W": MESH_SIZE(w) if w else None, "divisions": 0, "hex_size": None}


def discretisation(mesh: str, base: Discretisation = PRODUCTION, **fields) -> Discretisation:
    """``base`` on the mesh ``mesh`` (parse_mesh's text), with ``fields`` replaced; a
    tetrahedral mesh keeps base's quadrature unless base is hexahedral."""
    kw = parse_mesh(mesh)
    if not kw["divisions"] and base.divisions:
        kw["quadrature"] = SolverConfig.quadrature_degree
    return replace(base, **{**kw, **fields})


def recorded_formulation(config: dict) -> str:
    """The formulation a dataset manifest's ``config`` records (absent: displacement)."""
    return config.get("formulation", "displacement")
