"""The joint's discretisations: what the FEM data is generated on, named once.

A discretisation is (H, W, formulation, q, kappa): tetrahedron size H mm and W mm on the
1.2 mm chamber walls (JointGeometry.mesh_size, wall_mesh_size; W = None: H), the
formulation ("displacement": P2 displacement; "mixed": Taylor-Hood P2-P1 u-p, see
fem.problem), the quadrature degree q and the valley-contact penalty kappa (MPa/mm).

* PAPER: the discretisation of the paper-fidelity datasets (1.8 mm P2 displacement), kept
  as the reference that REPORT compares against;
* PRODUCTION: what new data is generated on (chosen by ``make mesh-study``, issue 35);
  JointGeometry's default sizes and FORMULATION are PRODUCTION's.

A dataset's manifest records its geometry and solver settings, and its formulation only
when it is not "displacement" (so manifests written before the mixed formulation existed
read as what they are).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from fem.geometry import JointGeometry
from fem.load_path import SolverConfig
from fem.problem import FORMULATIONS

#: the formulation new data is generated on (PRODUCTION's)
FORMULATION = "displacement"


@dataclass(frozen=True)
class Discretisation:
    """One discretisation of the joint: sizes in mm, penalty in MPa/mm."""

    H: float = JointGeometry.mesh_size
    W: float | None = JointGeometry.wall_mesh_size
    formulation: str = FORMULATION
    quadrature: int = SolverConfig.quadrature_degree
    penalty: float = SolverConfig.contact_penalty

    def __post_init__(self):
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, not {self.formulation!r}")

    @property
    def key(self) -> str:
        """File-name key, e.g. ``h2.4_w1.2_mixed_q2_k100``."""
        w = "none" if self.W is None else f"{self.W:g}"
        return f"h{self.H:g}_w{w}_{self.formulation}_q{self.quadrature}_k{self.penalty:g}"

    @property
    def mesh(self) -> str:
        """``H`` or ``H:W`` (mm)."""
        return f"{self.H:g}" if self.W is None else f"{self.H:g}:{self.W:g}"

    def geometry(self, base: JointGeometry = JointGeometry()) -> JointGeometry:
        return replace(base, mesh_size=self.H, wall_mesh_size=self.W)

    def config(self, base: SolverConfig = SolverConfig()) -> SolverConfig:
        return replace(base, quadrature_degree=self.quadrature, contact_penalty=self.penalty)


PAPER = Discretisation(H=1.8, W=None, formulation="displacement", quadrature=2, penalty=100.0)
PRODUCTION = Discretisation()


def recorded_formulation(config: dict) -> str:
    """The formulation a dataset manifest's ``config`` records (absent: displacement)."""
    return config.get("formulation", "displacement")
