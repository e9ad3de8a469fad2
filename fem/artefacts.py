"""The formats of the JSON artefacts the fem package writes (contract.records).

Each names the key paths the report and the demo read, with their JSON types; the writer
named in ``owner`` checks its document against the format before writing it, and every
reader loads the file through it (docs/formats.md §6). Units as in the key names: mm, s,
MPa, deg; ``*_over_L`` are fractions of the beam length.
"""

from __future__ import annotations

from contract.joint import mesh_text
from contract.records import Format, each

NUM, MAYBE = float, float | None

#: results/fem/validation.json (make validation): the elastica sweeps against exact solutions.
VALIDATION = Format("fem-validation", 1, "fem.studies.validation", {
    **each("required", float, "cantilever", "rollup"),
    **each("cantilever[]", NUM, "alpha", "error_over_L", "u_over_L", "w_over_L", "theta"),
    **each("cantilever[].exact", NUM, "u_over_L", "w_over_L", "theta"),
    **each("rollup[]", NUM, "theta_load", "error_over_L", "x_over_L", "y_over_L", "theta"),
    **each("rollup[].exact", NUM, "x_over_L", "y_over_L", "theta"),
    **each("", NUM, "max_cantilever_error_over_L", "max_rollup_error_over_L")})

_ERRORS = ("anchor_mm", "anchor_percent", "tip_mm", "phi_end_deg", "cap_rotation_deg")

#: results/fem/mesh_study.json (make mesh-study): every discretisation's worst error over the
#: eight loads against the reference (Richardson extrapolation of the family, or its finest
#: mesh), the production discretisation's judged against the tolerances.
MESH_STUDY = Format("fem-mesh-study", 3, "fem.studies.mesh_study", {
    "loads": list, "formulation": str, "element": str, "complete": bool, "asymptotic": bool,
    "reference": str | None, **each("", NUM, "tolerance_percent", "tolerance_deg", "wall_mm"), "min_nodes": int,
    "family": list | None, "production": str, "production_mesh": str, "production_met": bool,
    "meshes[].key": str, "meshes[].mesh": str, "meshes[].element": str, "meshes[].sizes": list,
    "meshes[].formulation": str, "meshes[].nodes": int, "meshes[].mean_solve_s": NUM, "meshes[].ranks": int,
    **each("meshes[].max_error?", NUM, *_ERRORS), "orders": list, "extrapolation?[].anchors.order": MAYBE,
    **each("production_error?", NUM, *_ERRORS), **each("paper_error?", NUM, *_ERRORS)})

#: results/fem/self_contact.json (make self-contact): valley gaps over the load cases.
SELF_CONTACT = Format("fem-self-contact", 1, "fem.studies.self_contact", {
    **each("", NUM, "contact_penalty_MPa_per_mm", "min_gap_mm", "undeformed_gap_mm"),
    "unsolved_cases": int, "cases[].load": list, "cases[].phi_end_deg": NUM,
    "cases[].min_gap_mm": MAYBE, "cases[].converged?": bool})

#: results/fem/joint_outline.json (make joint-outline): how far the pressurised cells bulge
#: beyond the outline's band, per |P| and anchor chord (fem.studies.joint_outline).
JOINT_OUTLINE = Format("fem-joint-outline", 1, "fem.studies.joint_outline", {
    "joint": str, "half_height_mm": NUM, "bulge_mm[].P_MPa": NUM, "bulge_mm[].pressurised_mm": list,
    "bulge_mm[].other_mm": list, "mirror.pressurised_mm": list, "mirror.other_mm": list, "wall_time_s": NUM})


def outline_of(record: dict) -> tuple:
    """(pressures, bulge, other) of a JOINT_OUTLINE record, in contract.joint's [outline]
    order (contract.joint.outline_table prints them)."""
    rows = record["bulge_mm"]
    return (tuple(r["P_MPa"] for r in rows), tuple(tuple(r["pressurised_mm"]) for r in rows),
            tuple(tuple(r["other_mm"]) for r in rows))

#: results/bench/fem.json (make bench-fem): joint FEM timings on one core, the production
#: discretisation's under plain keys and the paper's 1.8 mm mesh's, from the same run, under
#: keys ending in ``_1.8`` (``continuation_sample_s_1.8``; not listed here: a key path cannot
#: hold a dot, so the report reads them as optional).
BENCH_JOINT = Format("fem-bench-joint", 1, "fem.studies.bench_joint", {
    **each("", int, "paper_nodes", "nodes", "dofs"), "formulation?": str, "mesh?": str,
    "mesh_size?": NUM, "divisions?": int, "continuation_sample_cpu_s?": NUM,   # tetrahedra: mesh_size
    **each("", NUM, "solve_from_zero_s", "continuation_sample_s", "newton_iterations",
           "continuation_step_fraction_of_box", "paper_seconds_per_sample",
           "speedup_vs_paper_from_zero", "speedup_vs_paper_continuation"),
    "solve_from_zero_cases": list})

#: results/bench/finger.json (make bench-finger): the finger FEM's time per gesture.
BENCH_FINGER = Format("fem-bench-finger", 1, "fem.studies.bench_finger", {
    "cases[].case": str, "cases[].load_average_before": NUM,
    **each("", NUM, "finger_fem_max_s", "finger_fem_median_s", "target_s")})

#: results/validation/finger_fem/<case>.json (make finger-fem): one finger FEM case
#: (FingerResult.summary); tip and angles are null unless converged. ``mesh.mesh`` names the
#: joints' mesh (contract.joint.mesh_text: "1.8", "1.697:0.849", "hex2"); records written
#: before hexahedra have only ``mesh.mesh_size``, hexahedral ones ``mesh.divisions`` instead.
FINGER_CASE = Format("fem-finger-case", 1, "fem.studies.finger_cases", {
    "case": str, "pressures_MPa": list, "gravity": bool, "converged": bool, "tip": list | None,
    "tip_angle_deg": MAYBE, "fem_s": NUM, "mesh.mesh?": str, "mesh.mesh_size?": NUM, "mesh.divisions?": int,
    "mesh.nodes": int})

#: results/validation/grasps_fem/<case>.json (make grasp-fem; fem.studies.grasp_cases): one FEM grasp
#: along the predictor's history (GraspResult.summary and the case); the figures are null
#: unless converged, ``friction_use`` and ``contact_point_mm`` also when nothing touches;
#: ``render`` (the PNG's extent) only when converged.
GRASP_CASE = Format("fem-grasp-case", 1, "fem.studies.grasp_cases", {
    **each("", str, "case", "region", "object", "state", "formulation"), "object_geometry.kind": str,
    **each("", NUM, "p1", "p2", "mu", "object_weight_N", "fem_s", "fem_cpu_s", "setup_s"),
    **each("", list, "pressures_MPa", "approach_MPa"), **each("", bool, "gravity", "plane", "converged"),
    **each("", list | None, "tip", "contact_point_mm", "object_force_N", "base_force_N"),
    **each("", MAYBE, "tip_angle_deg", "contact_force_N", "friction_use", "penetration_mm", "plane_force_N"),
    "contact_patch": dict | None, "mesh.mesh": str, "mesh.nodes": int, "ranks": int,
    "render?.extent_mm": list, "render?.u_max_mm": NUM})

#: results/fem/finger_grid.json (make finger-grid; fem.studies.finger_grid): the summary of the finger
#: FEM over an N x N grid of gravity pressure pairs, one fem.studies.finger_cases record each (FINGER_CASE,
#: ``cases[].file``): each case's problem (``plane``), convergence, time, Newton figures and tip.
FINGER_GRID = Format("fem-finger-grid", 1, "fem.studies.finger_grid", {
    "settings.points": int, "settings.plane": bool, **each("", int, "pairs", "solved", "converged"),
    "complete": bool, "max_wall_s": MAYBE, "mesh.nodes": int, "cases[].p1": NUM, "cases[].p2": NUM,
    "cases[].converged": bool, "cases[].plane": bool, "cases[].tip": list | None,
    "cases[].wall_s": NUM, **each("cases[]", int, "newton_iterations", "load_steps", "cutbacks"),
    "cases[].reason": str})


def finger_case_wall(case: dict) -> float | None:
    """The chamber-wall tetrahedron size (mm) of a FINGER_CASE record (None: its size)."""
    return case.get("settings", {}).get("geometry", {}).get("joint", {}).get("wall_mesh_size")


def finger_case_mesh(case: dict) -> str:
    """The joints' mesh of a FINGER_CASE record in words: its ``mesh.mesh``, or, in a record
    written before hexahedra, mesh_text of its size and chamber-wall size (mm)."""
    return case["mesh"].get("mesh") or mesh_text(case["mesh"]["mesh_size"], finger_case_wall(case))


def finger_case_formulation(case: dict) -> str:
    """The formulation of a FINGER_CASE record (absent: "displacement", which it predates)."""
    return case.get("formulation") or "displacement"

#: results/fem/joint_cases/<discretisation>_<load>.json (make mesh-study, make mesh-causes;
#: fem.studies.joint_cases): one joint solve of one load under one discretisation (mesh H:W,
#: formulation, quadrature degree, penalty factor), kept so that the studies resume; a solve
#: seeded from another discretisation's answer names it (``seeded_from``, its key) and the
#: seed's own solve time (``seed_wall_time_s``).
JOINT_CASE = Format("fem-joint-case", 1, "fem.studies.joint_cases", {
    "load": list, "discretisation.H": MAYBE, "discretisation.W": MAYBE, "discretisation.divisions?": int,
    "discretisation.formulation": str,
    "discretisation.quadrature": int, "discretisation.penalty": NUM, "anchors": list,
    **each("", NUM, "phi_end_deg", "cap_rotation_deg", "wall_time_s"), "newton_iterations": int,
    "contact.closed_pairs": int, "contact.min_gap_mm": MAYBE, "mesh.nodes": int, "ranks": int,
    "seeded_from?": str, "seed_wall_time_s?": NUM})

#: results/fem/mesh_causes.json (make mesh-causes; fem.studies.mesh_causes): each factor's effect on
#: the answer against the production discretisation, its time, and the error against the
#: mesh study's finest mesh where that exists.
MESH_CAUSES = Format("fem-mesh-causes", 1, "fem.studies.mesh_causes", {
    "loads": list, "base.H": NUM, "base.formulation": str, "reference": str, "complete": bool,
    "rows[].factor": str, "rows[].key": str, "rows[].loads_solved": int, "rows[].nodes": int,
    "rows[].mean_solve_s": MAYBE, "rows[].effect?.worst?.anchor_percent": MAYBE,
    "rows[].effect?.worst?.phi_end_deg": MAYBE, "rows[].effect?.worst?.cap_rotation_deg": MAYBE,
    "rows[].against_reference?.worst?.anchor_percent": MAYBE, "ranking": list,
    "dominant?.factor": str, "dominant?.worst_anchor_percent": NUM})

#: results/fem/materials.json (fem.studies.materials_check): each material law against its closed
#: form on homogeneous deformations of a cube: per law and test the largest relative
#: difference, and the small-strain E and nu.
MATERIALS = Format("fem-materials", 1, "fem.studies.materials_check", {
    **each("", NUM, "worst_rel_diff", "target_rel", "worst_small_strain_rel_diff", "small_strain_target_rel"),
    "target_met": bool, "laws{}.law": str,
    **each("laws{}", NUM, "E_small_strain", "nu_small_strain", "mu0", "K", "worst_rel_diff"),
    "laws{}.tests{}.max_rel_diff": NUM, "laws{}.tests{}.P_closed_form": list,
    **each("laws{}.tests.small_strain", NUM, "E_fem", "E_rel_diff", "nu_closed_form", "nu_rel_diff")})
