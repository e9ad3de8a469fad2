"""Joint solves, one JSON record per (discretisation, load), shared by the mesh studies
(fem.studies.mesh_study, fem.studies.mesh_causes).

    LOADS = INTERIOR + CORNERS        (P MPa, F1 N, F2 N, M N·mm)

CORNERS are four corners of the input box with P > 0, none the y-mirror of another (the
mirror flips P), F2 and M bending with or against the pressure; INTERIOR four loads away
from the corners, with and without valley contact.

A record: the load, the discretisation (fem.mesh.discretisation.Discretisation as a dict), the
anchors r_1..r_10 (10, 2) mm, phi_end and the cap's rotation (deg), the solve's wall time
(s) and rank count, the Newton figures, the contact state (closed valley pairs, smallest
gap, mm) and the mesh's size. Records live in one folder (results/fem/joint_cases), named
``<discretisation key>_<load key>.json`` and written atomically on rank 0, so a study that
is killed or time-limited resumes where it stopped, and studies share what they solved.

A solve starts from zero (the load path of fem.solvers.load_path), or, given a seed discretisation
(``solve_missing(..., seed_from=...)``), a discretisation with more nodes starts from the
seed's answer at the same load (fem.solvers.transfer: a few Newton iterations instead of the load
path; the same equilibrium to the Newton tolerance). A seeded record adds ``seeded_from``
(the seed's key) and ``seed_wall_time_s`` (the seed's own solve from zero, s); its
``wall_time_s`` is the seeding and Newton on its own mesh only. A seeded Newton that fails
falls back to the solve from zero.
"""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from contract import cli
from contract.files import json_safe
from fem.artefacts import JOINT_CASE
from fem.mesh.discretisation import Discretisation
from fem.mesh.hexahedra import q2_nodes
from fem.options import on_root
from fem.solvers.joint import JointSolver, Load
from fem.solvers.transfer import solve_seeded

log = logging.getLogger("softjoint.fem")

CORNERS = [Load(0.3, 3, -3, -100), Load(0.3, -3, 3, 100), Load(0.3, 3, 3, -100),
           Load(0.3, -3, -3, 100)]
INTERIOR = [Load(0.15, 1, -1, 30), Load(0.1, -1.5, 1.5, 60), Load(-0.1, 1, -1, -20),
            Load(0.05, 0.5, 0.5, 0)]
LOADS = INTERIOR + CORNERS


def load_key(load) -> str:
    """File-name key of a load (4,), e.g. ``0.3_3_-3_-100``."""
    return "_".join(f"{v:g}" for v in np.asarray(load, dtype=float))


def difference(case: dict, ref: dict, X: np.ndarray) -> dict:
    """How far one answer ``case`` is from ``ref`` (both with anchors (10, 2) mm,
    phi_end_deg, cap_rotation_deg); X (10, 2) the rest anchors: the largest anchor distance
    (mm, and % of ref's largest anchor displacement), the tip anchor's distance (mm), and
    the phi_end and cap-rotation differences (deg)."""
    a, b = np.asarray(case["anchors"]), np.asarray(ref["anchors"])
    d = float(np.linalg.norm(a - b, axis=1).max())
    scale = float(np.linalg.norm(b - X, axis=1).max())
    return {"anchor_mm": d, "anchor_percent": 100.0 * d / scale, "tip_mm": float(np.linalg.norm(a[-1] - b[-1])),
            "phi_end_deg": abs(case["phi_end_deg"] - ref["phi_end_deg"]),
            "cap_rotation_deg": abs(case["cap_rotation_deg"] - ref["cap_rotation_deg"])}


def case_file(work: Path, disc: Discretisation, load: Load) -> Path:
    return Path(work) / f"{disc.key}_{load_key(load.as_array())}.json"


def read_records(work: Path, discs, loads=LOADS) -> dict:
    """{discretisation key: {load key: record}} of the valid records in ``work`` (a
    missing, damaged or foreign file is left out: it is solved again)."""
    out = {}
    for disc in discs:
        for load in loads:
            try:
                record = json.loads(case_file(work, disc, load).read_text())
            except (OSError, ValueError):
                continue
            if record.get("discretisation") == json_safe(disc.as_dict()):
                out.setdefault(disc.key, {})[load_key(load.as_array())] = record
    return out


def contact_state(solver: JointSolver) -> dict:
    """Closed valley pairs and the smallest gap (mm) at the solver's state."""
    if solver.contact is None:
        return {"closed_pairs": 0, "min_gap_mm": None}
    gaps = np.concatenate(list(solver.contact.gaps(solver.u).values()))
    return {"closed_pairs": int((gaps < 0).sum()), "min_gap_mm": float(gaps.min())}


def result_record(solver: JointSolver, disc: Discretisation, r, comm) -> dict:
    """The record of a converged fem.solvers.joint.SolveResult ``r`` of ``solver``."""
    return {"load": r.load.as_array().tolist(), "discretisation": json_safe(disc.as_dict()),
            "anchors": r.anchors.tolist(), "phi_end_deg": math.degrees(r.phi_end),
            "cap_rotation_deg": math.degrees(r.cap_rotation), "wall_time_s": r.wall_time,
            "newton_iterations": r.iterations, "load_steps": r.load_steps,
            "factorisations": r.factorisations, "contact": contact_state(solver),
            "mesh": solver.mesh_info(), "ranks": comm.size}


def solve_record(solver: JointSolver, disc: Discretisation, load: Load, comm) -> dict:
    """One solve from zero as a record; a solve that does not converge is an error."""
    r = solver.solve(load)
    if not r.converged:
        raise RuntimeError(f"{disc.key}: {load} did not converge ({r.reason})")
    return result_record(solver, disc, r, comm)


def node_estimate(disc: Discretisation) -> float:
    """P2 / Q2 node count of a discretisation's joint (orders work by cost): swept
    hexahedra (fem.mesh.hexahedra) exactly, tetrahedra roughly, ~ 2.6e4 at 1.8 mm scaling as
    1 / (H W)."""
    if disc.divisions:
        return float(q2_nodes(disc.geometry()))
    return 2.6e4 * 1.8 ** 2 / float(np.prod(disc.sizes))


class Seeder:
    """Solves of the ``seed`` discretisation from zero, as starting guesses for the
    discretisations with more nodes (node_estimate) at the same load (fem.solvers.transfer). Its
    solver is built at the first use and kept for every later load (one rank)."""

    def __init__(self, seed: Discretisation, comm):
        if comm.size > 1:
            raise ValueError(f"seeding from {seed.mesh} runs on one rank (fem.solvers.transfer), not {comm.size}")
        self.disc, self.comm, self.solver = seed, comm, None

    def seeds(self, disc: Discretisation) -> bool:
        """Is ``disc`` solved from this seed (it has more nodes)?"""
        return disc.key != self.disc.key and node_estimate(disc) > node_estimate(self.disc)

    def record(self, solver: JointSolver, disc: Discretisation, load: Load) -> dict | None:
        """``solver`` (of ``disc``) at ``load`` from the seed's answer there, as a record
        with ``seeded_from`` (the seed's key) and ``seed_wall_time_s`` (its solve from
        zero, s; ``wall_time_s`` is the seeding and Newton of ``solver`` only); None
        when the seed or the seeded Newton does not converge (solve from zero then)."""
        self.solver = self.solver or JointSolver(self.disc.geometry(), self.comm, config=self.disc.config(),
                                                 formulation=self.disc.formulation)
        rs = self.solver.solve(load)
        if not rs.converged:
            log.info("seed %s %s did not converge (%s): from zero", self.disc.key, load, rs.reason)
            return None
        r = solve_seeded(solver, self.solver)
        if not r.converged:
            log.info("%s %s from seed %s did not converge (%s): from zero", disc.key, load, self.disc.key, r.reason)
            return None
        return {**result_record(solver, disc, r, self.comm), "seeded_from": self.disc.key,
                "seed_wall_time_s": rs.wall_time}


def add_work_arguments(ap: cli.Parser) -> None:
    """The options of a study that solves its missing records here (fem.studies.mesh_study,
    mesh_causes): ``--work``, the records' folder it resumes from, and ``--max-hours``,
    solve_missing's budget."""
    ap.add_output("--work", folder=True, default="results/fem/joint_cases",
                  help="folder of the per-(discretisation, load) records (resumes from it; "
                  "default results/fem/joint_cases)")
    ap.add_argument("--max-hours", type=cli.number(0, 1000, "h"), default=1000.0,
                    help="start no new solve after this many hours (default 1000)")


def work_folder(work: str, comm=MPI.COMM_WORLD) -> Path:
    """The records' folder ``work``, made by rank 0 while the others wait (collective)."""
    if comm.rank == 0:
        Path(work).mkdir(parents=True, exist_ok=True)
    comm.barrier()
    return Path(work)


def solve_missing(work: Path, plan, loads=LOADS, max_hours: float = 1000.0,
                  comm=MPI.COMM_WORLD, seed_from: Discretisation | None = None) -> bool:
    """Solve the missing (discretisation, load) records of ``plan`` in order until done or
    ``max_hours`` have passed (no new solve starts then). True when all are done.

    ``seed_from``: every discretisation with more nodes than it starts from its answer at
    the same load (Seeder; one rank), and from zero when that fails."""
    t_end = time.monotonic() + 3600.0 * max_hours
    seeder = Seeder(seed_from, comm) if seed_from is not None else None
    done = read_records(work, plan, loads)
    for disc in plan:
        missing = [load for load in loads if load_key(load.as_array()) not in done.get(disc.key, {})]
        solver = None
        for load in missing:
            if time.monotonic() > t_end:
                return False
            solver = solver or JointSolver(disc.geometry(), comm, config=disc.config(),
                                           formulation=disc.formulation)
            record = seeder.record(solver, disc, load) if seeder and seeder.seeds(disc) else None
            record = record or solve_record(solver, disc, load, comm)
            on_root(comm, lambda: JOINT_CASE.write(case_file(work, disc, load), record))
            if comm.rank == 0:
                log.info("%s %s: phi_end %.3f deg, %.0f s%s", disc.key, load, record["phi_end_deg"],
                         record["wall_time_s"], f" (seeded from {seed_from.key})" if "seeded_from" in record else "")
        del solver
    return True


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("fem.studies.mesh_study")
