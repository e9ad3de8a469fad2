"""The bellow joint (and the benchmark beam): a problem handed to the load-path solver.

Units: mm, N, MPa (= N/mm²), N·mm; angles in rad.

The joint's physics is :func:`fem.physics.problem.joint_problem` (hyperelastic body, stiff distal
cap, follower chamber pressure, valley self-contact, end loads F1, F2, M on the rigid cap;
equations there); it is solved by :class:`fem.solvers.load_path.LoadPathSolver` (load path with
cut-back, Newton/MUMPS, sensitivities). This module adds the joint's load vector
(P, F1, F2, M) in MPa, N, N, N·mm (docs/physics.md), its input box, and its result: the
anchors r_1..r_n (n = 10 for the paper's joint), phi_end and the cap rotation.

A joint is described by a joint file (contract.joint, docs/joints.md):
:meth:`JointSolver.for_joint` builds its geometry (JointGeometry(**joint.geometry_kwargs())),
its law (fem.physics.materials), its anchors X_i = (i L / n, 0, 0) and its input box from it. The
defaults of JointSolver are the paper's joint: NinjaFlex as a compressible neo-Hookean
solid, whose small-strain limit is exactly (E, nu) = (12.2 MPa, 0.49), and
contract.spec.INPUT_BOX. P2 displacements avoid the volumetric locking of P1 at nu = 0.49
(mesh convergence: ``make mesh-study``); ``formulation="mixed"`` solves the same energy in
Taylor-Hood u-p form (fem.physics.problem), which does not lock. JointSolver's default
formulation is the production one, fem.mesh.discretisation.FORMULATION ("mixed"; with
JointGeometry's default mesh, hex2:3, and config_for's quadrature 4 it is the PRODUCTION
discretisation; the paper-fidelity PAPER is JointGeometry(divisions=0, hex_size=None) and
"displacement"). The paper used ANSYS linear elasticity with
large deflection (St Venant-Kirchhoff-like); neo-Hookean agrees with it at small strain
and stays stable in compression.

Data flow: joint file -> contract.joint.JointSpec -> JointSolver.for_joint; JointGeometry
-> fem.mesh.build.create_mesh -> fem.physics.problem.joint_problem -> LoadPathSolver;
JointSolver.solve(Load) -> SolveResult (anchors (n, 2) mm, phi_end, cap rotation, u,
Newton figures); JointSolver.sensitivities() -> d anchors / d load (2n, 4).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from mpi4py import MPI

from contract.joint import JointSpec, MaterialLaw
from contract.spec import INPUT_BOX, N_ANCHORS, check_box, outside_box, phi_end
from fem.mesh.discretisation import FORMULATION
from fem.mesh.geometry import BeamGeometry, JointGeometry, anchor_points
from fem.mesh.discretisation import HEX_QUADRATURE, SolverConfig
from fem.solvers.load_path import LoadPathSolver
from fem.mesh.build import create_mesh
from fem.mesh.data import MeshData
from fem.physics.problem import Material, as_law, joint_problem

# Material and SolverConfig are re-exported: the joint's public configuration.
__all__ = ["Load", "Material", "SolverConfig", "SolveResult", "JointSolver", "EndLoadedSolver",
           "beam_solver"]

log = logging.getLogger("softjoint.fem")


@dataclass(frozen=True)
class Load:
    """One load case: P (MPa, signed), F1, F2 (N, dead, joint frame), M (N·mm, about +z)."""

    P: float = 0.0
    F1: float = 0.0
    F2: float = 0.0
    M: float = 0.0

    def as_array(self) -> np.ndarray:
        return np.array([self.P, self.F1, self.F2, self.M], dtype=float)

    @classmethod
    def from_array(cls, a) -> "Load":
        return cls(*(float(x) for x in a))

@dataclass
class SolveResult:
    """Outcome of one load case. anchors (n_probe, 2) mm; angles rad; times s."""

    load: Load
    converged: bool
    anchors: np.ndarray
    phi_end: float
    cap_rotation: float
    newton_iterations: list[int] = field(default_factory=list)
    load_steps: int = 0
    cutbacks: int = 0
    factorisations: int = 0         # factorisations (LDL^T or LU) this solve needed
    krylov_iterations: int = 0      # GMRES iterations over its tangent solves
    wall_time: float = 0.0
    reason: str = ""
    extrapolated: bool = False
    u: object = None                # dolfinx.fem.Function (this rank's part)

    @property
    def iterations(self) -> int:
        return int(sum(self.newton_iterations))

    def summary(self) -> dict:
        """JSON-ready figures (no field data)."""
        return {
            "load": asdict(self.load), "converged": self.converged,
            "anchors_mm": np.round(self.anchors, 6).tolist(),
            "phi_end_rad": self.phi_end, "phi_end_deg": math.degrees(self.phi_end),
            "cap_rotation_rad": self.cap_rotation,
            "cap_rotation_deg": math.degrees(self.cap_rotation),
            "tangent_assumption_error_deg": math.degrees(self.cap_rotation - self.phi_end),
            "newton_iterations": self.newton_iterations, "iterations": self.iterations,
            "load_steps": self.load_steps, "cutbacks": self.cutbacks,
            "factorisations": self.factorisations, "krylov_iterations": self.krylov_iterations,
            "wall_time_s": self.wall_time, "reason": self.reason,
            "extrapolated": self.extrapolated,
        }


class EndLoadedSolver:
    """A joint-like body (the bellow joint, the benchmark beam) clamped at x = 0, with a
    rigid cap loaded at ``ref_point`` (3,) mm: :func:`fem.physics.problem.joint_problem` handed
    to a :class:`LoadPathSolver`. Load vector (P, F1, F2, M); ``probe_points`` (n, 3) are
    material points whose deformed (x, y) are reported (the joint's anchors).
    ``material``: the body's law (a contract.joint.MaterialLaw, or an (E, nu) Material);
    ``input_box`` (4,): the load half-widths (P MPa, F1 N, F2 N, M N·mm) that size the
    solver's first step.

    ``formulation``: "displacement" (the datasets' P2 displacement form) or "mixed"
    (Taylor-Hood u-p, fem.physics.problem). It is an argument rather than a SolverConfig field so
    that every recorded SolverConfig (campaign manifests) stays what it is."""

    def __init__(self, mesh_data: MeshData, ref_point, probe_points,
                 material: MaterialLaw | Material = Material(), config: SolverConfig = SolverConfig(),
                 formulation: str = "displacement", input_box=INPUT_BOX):
        self.mesh_data, self.material, self.config = mesh_data, as_law(material), config
        self.formulation = formulation
        self.input_box = np.asarray(input_box, dtype=float)
        self.problem = joint_problem(mesh_data, ref_point, probe_points, self.input_box, self.material,
                                     formulation=formulation, **config.discretisation())
        self.solver = LoadPathSolver(self.problem, config)
        self.u, self.V, self.comm = self.problem.u, self.problem.V, self.problem.comm
        self.contact, self.probe_points = self.problem.contact, self.problem.probe_points

    # The solver's running totals and state, read through (diagnostics, continuation).
    factorisations = property(lambda self: self.solver.factorisations)
    krylov_iterations = property(lambda self: self.solver.krylov_iterations)
    state = property(lambda self: self.solver.state)

    @property
    def state_load(self) -> Load:
        """Load of the current converged state."""
        return Load.from_array(self.solver.state)

    def reset(self) -> None:
        """Return to the undeformed, unloaded state."""
        self.solver.reset()

    def mesh_info(self) -> dict:
        return self.solver.mesh_info()

    def displacement(self):
        """The displacement u (mm) as a Function of its own vector space (for the mixed
        formulation a copy of w's u block)."""
        return self.problem.displacement()

    def cap_rotation(self) -> float:
        """Volume-averaged rotation of the distal cap about +z (rad)."""
        return self.solver.average("cap_rotation")

    def positions(self) -> np.ndarray:
        """Deformed (x, y) of the probe points (mm), shape (n, 2)."""
        return (self.probe_points + self.solver.probe_displacements())[:, :2]

    def solve(self, load: Load, continuation: bool = False) -> SolveResult:
        """Solve for ``load``; from zero, or (continuation) from the current state.

        The load path is linear from the start load to ``load`` (LoadPathSolver.follow:
        cut-back on failure; a failed solve returns to its last converged state).
        """
        if not np.isfinite(load.as_array()).all():   # would only fail after every cut-back
            raise ValueError(f"{load} is not finite")
        solver = self.solver
        t0, lu0, kr0 = time.perf_counter(), solver.factorisations, solver.krylov_iterations
        if not continuation:
            solver.reset()
        path = solver.follow(solver.state.copy(), load.as_array())
        anchors = self.positions()
        cap = self.problem.lagged[0].constant      # the cap rotation of the converged state
        result = SolveResult(
            load=load, converged=path.converged, anchors=anchors,
            phi_end=float(phi_end(anchors)) if len(anchors) > 1 else math.nan,
            cap_rotation=float(cap.value), newton_iterations=path.newton_iterations,
            load_steps=path.load_steps, cutbacks=path.cutbacks,
            factorisations=solver.factorisations - lu0,
            krylov_iterations=solver.krylov_iterations - kr0,
            wall_time=time.perf_counter() - t0, reason=path.reason, u=self.u)
        if self.comm.rank == 0:
            log.info("solve %s: converged=%s, %d steps, %d iterations, %.2f s",
                     load, path.converged, path.load_steps, result.iterations, result.wall_time)
        return result

    def sensitivities(self) -> np.ndarray:
        """d(probe x, y)/d(P, F1, F2, M) at the current converged state, shape (2n, 4).

        Rows are the probe coordinates flattened as (x_1, y_1, x_2, ...); columns in
        mm/MPa, mm/N, mm/N, mm/(N·mm) (LoadPathSolver.sensitivities). At P = 0 the
        pressure derivative is the one-sided (top chamber) one."""
        return self.solver.sensitivities()[:, :2, :].reshape(-1, len(self.solver.state))


def config_for(geometry, config: SolverConfig = SolverConfig()) -> SolverConfig:
    """``config`` with at least the quadrature degree Q2 hexahedra need
    (fem.mesh.discretisation.HEX_QUADRATURE: fewer points leave hourglass modes) when ``geometry`` is a
    hexahedral joint (JointGeometry.divisions > 0); unchanged otherwise."""
    if getattr(geometry, "divisions", 0) and config.quadrature_degree < HEX_QUADRATURE:
        return replace(config, quadrature_degree=HEX_QUADRATURE)
    return config


class JointSolver(EndLoadedSolver):
    """The bellow joint: ``anchors`` anchor points r_1..r_n (docs/physics.md), loads at r_n;
    loads outside ``input_box`` (4,) are refused unless allowed. Defaults: the paper's
    joint (material, 10 anchors, contract.spec.INPUT_BOX); ``formulation`` defaults to the
    production one (fem.mesh.discretisation.FORMULATION); ``config`` is raised to the
    hexahedra's quadrature on a hexahedral mesh (config_for). A joint file's joint:
    :meth:`for_joint`."""

    def __init__(self, geometry: JointGeometry = JointGeometry(), comm: MPI.Comm = MPI.COMM_WORLD,
                 material: MaterialLaw | Material = Material(), config: SolverConfig = SolverConfig(),
                 formulation: str = FORMULATION, *, anchors: int = N_ANCHORS, input_box=INPUT_BOX):
        X = anchor_points(geometry.length, anchors)
        super().__init__(create_mesh(geometry, comm), ref_point=X[-1], probe_points=X,
                         material=material, config=config_for(geometry, config), formulation=formulation,
                         input_box=input_box)

    @classmethod
    def for_joint(cls, joint: JointSpec, comm: MPI.Comm = MPI.COMM_WORLD,
                  geometry: JointGeometry | None = None, config: SolverConfig = SolverConfig(),
                  formulation: str | None = None) -> "JointSolver":
        """The solver of a joint description: its shape, law, anchors and input box;
        ``geometry`` (default: the joint's shape and [mesh] sizes) and ``formulation``
        (default: the joint's [mesh] formulation) override its discretisation."""
        geometry = geometry or JointGeometry(**joint.geometry_kwargs())
        return cls(geometry, comm, joint.material, config, formulation or joint.formulation,
                   anchors=joint.anchors, input_box=joint.input_box)

    def solve(self, load: Load, continuation: bool = False,
              allow_extrapolation: bool = False) -> SolveResult:
        """Solve one load case. Raises contract.spec.OutOfBoxError, before any work, for a
        load that is not finite, or outside the joint's box unless ``allow_extrapolation``."""
        check_box(load.as_array(), allow_extrapolation, box=self.input_box)
        result = super().solve(load, continuation)
        result.extrapolated = bool(outside_box(load.as_array(), self.input_box))
        return result


def beam_solver(geometry: BeamGeometry = BeamGeometry(), comm: MPI.Comm = MPI.COMM_WORLD,
                E: float = 12.2, config: SolverConfig = SolverConfig()) -> EndLoadedSolver:
    """The slender benchmark cantilever (nu = 0): probes at the beam end (L, 0, 0). P2
    displacements: at nu = 0 there is no volumetric stiffness to lock (and lambda = 0
    leaves the mixed form's pressure undefined)."""
    tip = np.array([geometry.length, 0.0, 0.0])
    return EndLoadedSolver(create_mesh(geometry, comm), ref_point=tip, probe_points=tip[None, :],
                           material=Material(E=E, nu=0.0), config=config, formulation="displacement")


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.cli.solve")
