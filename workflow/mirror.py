"""The FEM's own check of a dataset: the y-mirror of stored samples solved afresh.

Mirroring y -> -y maps a solution (R, P, F1, F2, M) to (R diag(1, -1), -P, F1, -F2, -M)
(docs/physics.md); the joint mesh is mirror symmetric, so a dataset's mirrored samples,
solved from zero on one rank with the dataset's own joint and discretisation (its joint,
workflow.store.recorded_joint, absent: the paper's; its geometry, solver settings and
formulation, fem.mesh.discretisation.recorded_formulation), must give the mirrored stored
anchors and Jacobians to solver tolerance. ``workflow.dataset verify --mirror N`` hands ``mirror_check`` to
``workflow.store.verify``. Needs dolfinx (the data layer sits on the FEM layer).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from contract.spec import mirror
from fem.mesh.discretisation import recorded_formulation
from fem.mesh.geometry import JointGeometry
from fem.physics.problem import Material
from fem.solvers.joint import JointSolver, Load, SolverConfig
from workflow.shards import Manifest
from workflow.store import recorded_joint


def recorded_solver(cfg: dict, comm=MPI.COMM_SELF) -> JointSolver:
    """The joint solver a campaign manifest's ``config`` was made with: its joint, geometry
    (JointGeometry.from_record: a geometry recorded without ``divisions`` is tetrahedra,
    whatever JointGeometry's defaults are), solver settings and formulation."""
    joint = recorded_joint(cfg)
    # A manifest without a joint has the (E, nu) record of the paper's Material; with one,
    # the law is the joint's.
    material = joint.material if "joint" in cfg else Material(**cfg["material"])
    return JointSolver(JointGeometry.from_record(cfg["geometry"]), comm, material,
                       SolverConfig(**cfg["solver"]), formulation=recorded_formulation(cfg),
                       anchors=joint.anchors, input_box=joint.input_box)


def mirror_check(arrays: dict, manifest: Manifest, n: int) -> dict:
    """Solve the y-mirror of ``n`` stored samples with the FEM (fresh from zero) and compare
    with the mirrored stored anchors and Jacobian (docs/physics.md). The mesh is mirror
    symmetric, so the relation holds to solver tolerance. Runs on one rank."""
    solver = recorded_solver(manifest.config)
    rng = np.random.default_rng([manifest.seed, 7])
    pick = np.sort(rng.choice(len(arrays["sample_id"]), size=min(n, len(arrays["sample_id"])),
                              replace=False))
    cases = []
    for i in pick:
        x_m, r_m, j_m = mirror(arrays["inputs"][i:i + 1], arrays["anchors"][i:i + 1],
                                    arrays["jacobian"][i:i + 1])
        res = solver.solve(Load.from_array(x_m[0]))
        case = {"sample_id": int(arrays["sample_id"][i]), "converged": res.converged}
        if res.converged:
            jac = solver.sensitivities()
            case["anchor_error_mm"] = float(np.abs(res.anchors - r_m[0]).max())
            case["jacobian_rel_error"] = float(np.abs(jac - j_m[0]).max() / np.abs(j_m[0]).max())
        cases.append(case)
    return {"cases": cases,
            "max_anchor_error_mm": max((c.get("anchor_error_mm", np.inf) for c in cases), default=0.0),
            "max_jacobian_rel_error": max((c.get("jacobian_rel_error", np.inf) for c in cases),
                                          default=0.0)}
