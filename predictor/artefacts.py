"""The formats of the JSON artefacts the predictor package writes (contract.records).

Each names the key paths the report and the demo read with their JSON types; the writer
in ``owner`` checks its document before writing it (predictor.validation.bench, atlas, inverse,
validate_finger, validate_grasps; predictor.cli.figures checks gestures.json, which it writes
without a final newline) and readers load the file through it (docs/formats.md §6). Units as in the key names: MPa, mm, N, mN, N·mm, deg, ms, s.
Optional paths (``?``) are figures a writer records only in some runs (a path it did not
bench, a file from before a figure was added).
"""

from __future__ import annotations

from contract.records import Format, each

NUM, MAYBE = float, float | None

_RESIDUALS = ("force_mN_mean", "moment_Nmm_mean", "force_mN_p95", "moment_Nmm_p95",
              "force_mN_max", "moment_Nmm_max")
_THROUGHPUT = {"per_s": NUM, "newton_from_nn": int, "ramp_fallback": int}

#: results/bench/predictor.json (make bench-predictor): timings, residuals and throughputs.
BENCH = Format("predictor-bench", 1, "predictor.validation.bench", {
    **each("", NUM, "gravity_newton_median_ms", "gravity_lbfgs_median_ms", "contact_median_ms",
           "gravity_nn_residual_force_mN", "gravity_nn_residual_moment_Nmm",
           "contact_nn_raw_residual_force_mN", "contact_nn_raw_residual_moment_Nmm",
           "contact_nn_raw_p95_force_mN", "contact_nn_raw_p95_moment_Nmm", "contact_nn_state_agreement",
           "contact_nn_raw_tip_error_mm", "contact_nn_residual_force_mN", "contact_nn_residual_moment_Nmm",
           "contact_nn_polished_fallback_rate", "nn_single_query_ms", "nn_batched_per_s"),
    **each("", NUM, "gravity_lm_median_ms?", "gravity_fast_median_ms?", "contact_fast_median_ms?",
           "contact_batched_per_s?", "contact_ramp_batched_per_s?", "contact_nn_newton_rate?",
           "gravity_batched_per_s?"),
    "batched_threads?": int, "batched_dtype?": str, "threads?": int, "graphs?": str, "joint?": str,
    "targets?{}": NUM, "paper?": dict,
    "details.nn_domain_MPa?{}.p1": list, "details.nn_domain_MPa?{}.p2": list,
    **each("details.gravity_nn_improved?", NUM, *_RESIDUALS),
    **each("details.gravity_nn_paper_mlp?", NUM, *_RESIDUALS),
    **each("details.gravity_nn_throughput?.one_thread?", NUM, "nn_and_kinematics_per_s?", "delivered_per_s?"),
    "details.gravity_fast?.method": str, **each("details.gravity_fast?", int, "misses", "n", "fallbacks"),
    "details.contact_fast?.method": str, **each("details.contact_fast?", int, "misses", "n"),
    **each("details.contact_fast?", int, "newton_from_nn?", "fallbacks?"),
    **each("details.contact_throughput?", int, "n", "threads"), "details.contact_throughput?.dtype": str,
    **{f"details.contact_throughput?.{k}.{f}": t for k in ("issue_bound", "solver_tolerance")
       for f, t in _THROUGHPUT.items()},
    "details.contact_nn_vs_solver.raw_contact_free": dict | None,
    "details.contact_nn_vs_solver.raw_contact_free?.force_mN_mean": MAYBE,
    "details.contact_nn_vs_solver.reference_converged": int,
    "details.contact_nn_vs_solver.state_by?": str,
    "details.contact_nn_vs_solver.state_agreement_of_tau?": NUM,
    **each("details.contact_nn_vs_solver.reference_penetration_mm?", NUM, "mean", "p95"),
    **each("details.contact_nn_vs_solver.newton_step_from_raw?", NUM, "force_mN_mean", "moment_Nmm_mean",
           "force_mN_p95", "moment_Nmm_p95", "tip_error_mm_mean"),
    **each("details.contact_nn_vs_solver.newton_from_raw?", int, "converged", "converged_to_ramp_equilibrium",
           "converged_elsewhere", "kept", "kept_elsewhere"),
    **each("details.contact_nn_vs_solver.newton_from_raw?", MAYBE, "tip_shift_mm_max_at_ramp_equilibrium",
           "tip_shift_mm_min_elsewhere"),
    "details.contact_nn_vs_solver.newton_from_raw?.branch_tip_mm": NUM})

#: Where a converged gesture touches (GestureResult.where_it_touches; null unless converged;
#: absent in files from before the face contact): the part and face carrying the most
#: normal force, its mean contact point, and the fingers' meeting at X = 0.
_WHERE = {"contact_part?": str | None, "contact_face?": str | None, "contact_point_mm?": list | None,
          "plane_force_N?": MAYBE, "plane_overlap_mm?": MAYBE}

#: One gesture summary (predictor.cli.gesture --json, and each case of gestures.json): the
#: fingertip and angles are null unless converged; files from before the gesture said its
#: state carry ``slip`` and a signed ``friction_ratio`` instead of ``state``, ``friction_use``.
_GESTURE = {"pressures_MPa": list, "converged": bool, "tip": list | None, "tip_angle_deg": MAYBE,
            "contact_force_N": NUM, "state?": str, "friction_use?": MAYBE, "slip?": bool,
            "friction_ratio?": MAYBE, **_WHERE}

#: results/predictor/gestures.json (make gestures): the paper's gesture cases and grasps.
GESTURES = Format("predictor-gestures", 1, "predictor.cli.figures", {
    "joint": str, "approach_MPa": list, "mu?": NUM,
    **{f"{group}.{k}": kind for group in ("gravity[]", "free[]", "grasps{}[]") for k, kind in _GESTURE.items()}})

#: results/predictor/atlas_<object>.json and its ramp/, ramp_fine/ references (make atlas):
#: the grasp state over a (P1, P2) grid; ``state`` holds codes into ``states``.
ATLAS = Format("predictor-atlas", 1, "predictor.cli.atlas", {
    "grid": int, "approach_MPa": list | None, "mu": NUM, "joint?": str, "states": list, "state[]": list,
    **each("counts", int, "no_contact", "holds", "slips", "not_converged"),
    "best_hold?.pressures_MPa": list, "best_hold?.friction_use": MAYBE,
    "targets.atlas_s_per_object": NUM, "measured.atlas_s_per_object": NUM, "measured.grid_points": int,
    "solved_by?{}": int, "ramp_steps?": int, "max_plane_overlap_mm?": MAYBE, "plane_overlap_mm?[]": list,
    "object?.corner_mm?": NUM, "finger?.name": str, "finger?.sha256": str})

#: results/predictor/inverse.json (make inverse): each goal's pressures, verified forward.
INVERSE = Format("predictor-inverse", 1, "predictor.cli.inverse", {
    "joint?": str, **each("targets", NUM, "inverse_tip_ms", "inverse_hold_ms"),
    **each("measured", NUM, "inverse_tip_ms", "inverse_hold_ms", "inverse_hold_cold_ms"),
    "tolerances.regulator_MPa": NUM,
    **each("cases[]", str, "goal", "status"), "cases[].object": str | None, "cases[].pressures": list,
    "cases[].friction_use": MAYBE, "cases[].tip_error_mm?": MAYBE, "cases[].verified": bool | None,
    "cases[].robust": bool | None, "cases[].time_ms_median": NUM, "cases[].angle_error_deg?": MAYBE,
    **{f"cases[].{k}": kind for k, kind in _WHERE.items()},
    # issue 60: the demo track (predictor.planning.track), timed beside what the load averages say
    "track?.goals": int, **each("track?", NUM, "median_ms", "p95_ms", "rate_hz", "setup_ms", "first_ms"),
    "track?.max_tip_error_mm": MAYBE, "track?.verified": bool, **each("track?", int, "reached", "unreachable"),
    "track?.reached_warm_median_ms": MAYBE, "track?.unreachable_median_ms": MAYBE,
    "track?.load_average_before": list, "track?.beside": str, "track?.cpu_median_ms?": NUM})

_SUMMARY = ("tip_error_mm_max", "tip_error_mm_mean", "tip_angle_error_deg_max",
            "joint_end_angle_error_deg_max", "speedup_min")

#: results/validation/finger.json, results/demo/finger.json (make validate-finger): the
#: predictor's variants against the finger FEM, per case and summarised per variant.
VALIDATION = Format("predictor-finger-validation", 1, "predictor.validation.finger", {
    **each("targets", NUM, "tip_error_mm", "tip_angle_error_deg", "speedup", "fem_s", "fem_cases"),
    "targets.refinement_tip_change_mm?": NUM,
    "summary{}.cases": int, **each("summary{}", NUM, *_SUMMARY), "judged_variant": str,
    "joint": str, "repeats": int, "finger.name": str, "finger.base_angle_deg?": NUM, "figures?": list,
    "discretisation?.mesh": str, "discretisation?.formulation": str, "plane?": bool | None,
    "fem[].case": str, "fem[].converged": bool, "fem[].gravity": bool, "fem[].pressures_MPa": list,
    "fem[].fem_s": NUM, "fem[].tip": list | None, "fem[].tip_angle_deg": MAYBE,
    "fem[].load_average?": NUM, "fem[].reason?": str, "fem[].mesh.nodes": int, "fem[].mesh.mesh_size?": NUM,
    "fem[].mesh.mesh?": str,
    **each("cases[]", str, "case", "variant", "method", "kinematics"), "cases[].joint_weight": str | None,
    **each("cases[]", MAYBE, "tip_error_mm", "tip_angle_error_deg", "predictor_s", "tip_angle_deg"),
    "cases[].tip_mm": list | None,
    "mesh_check?[].case": str, **each("mesh_check?[]", NUM, "tip_change_mm", "tip_angle_change_deg"),
    "mesh_check?[].production_mesh_size?": NUM, "mesh_check?[].mesh_size": MAYBE,
    "mesh_check?[].mesh?": str, "mesh_check?[].production_mesh?": str,
    "mesh_check?[].formulation?": str, "mesh_check?[].production_formulation?": str,
    **each("mesh_check?[]", int, "production_nodes", "nodes"), "mesh_check?[].wall_mesh_size?": NUM})

_GRASP_MET = ("tip", "tip_angle", "normal_force", "contact_location", "state", "fem_time", "speedup")

#: results/validation/grasps.json (make validate-grasps; predictor.validation.grasps): the
#: predictor against the FEM grasps of fem.studies.grasp_cases on one discretisation, per case (the
#: issue's keys; figures null where a side did not solve) and summarised; ``met`` per target:
#: true, false, or null where not judged (the state where the FEM's friction use is near 1).
GRASP_VALIDATION = Format("predictor-grasp-validation", 1, "predictor.validation.grasps", {
    "joint": str, "finger.name": str, "fem_folder": str, "repeats": int, "figures": list, "judged": list,
    "plane?": bool | None,
    **each("discretisation", str, "mesh", "formulation"),
    **each("targets", NUM, "tip_error_mm", "tip_angle_error_deg", "normal_force_rel", "normal_force_N",
           "contact_location_error_mm", "friction_use_band", "fem_s", "speedup"),
    **each("cases[]", str, "case", "region", "object", "fem_state", "predictor_state", "mesh", "formulation"),
    **each("cases[]", NUM, "p1", "p2", "fem_s", "predictor_s", "speedup"), "cases[].nodes": int,
    **each("cases[]", bool, "plane", "fem_converged", "predictor_converged"),
    **each("cases[]", MAYBE, "fem_friction_use", "predictor_friction_use", "tip_error_mm", "tip_angle_error_deg",
           "normal_force_fem_N", "normal_force_predictor_N", "normal_force_error_N", "normal_force_error_rel",
           "contact_location_error_mm", "tip_angle_fem_deg", "tip_angle_predictor_deg", "plane_force_fem_N",
           "plane_force_predictor_N"),
    **each("cases[]", list | None, "tip_fem_mm", "tip_predictor_mm", "contact_point_fem_mm",
           "contact_point_predictor_mm", "object_force_fem_N", "object_force_predictor_N"),
    "cases[].figure": str | None, **each("cases[].met", bool | None, *_GRASP_MET),
    **each("summary", int, "cases", "fem_converged", "predictor_converged", "compared", "state_agreement"),
    **each("summary", MAYBE, "tip_error_mm_max", "tip_angle_error_deg_max", "normal_force_error_N_max",
           "normal_force_error_rel_max", "contact_location_error_mm_max", "fem_s_max", "speedup_min",
           "predictor_s_median"),
    **{f"summary.met.{k}.{f}": int for k in _GRASP_MET for f in ("met", "judged")}, "summary.all_met": bool})

#: results/calibration/recovery.json (make calibrate-recovery; predictor.cli.calibrate recovery):
#: the calibration fit on observations made from a known truth, noise-free and noisy seeds.
RECOVERY = Format("predictor-calibration-recovery", 1, "predictor.cli.calibrate", {
    "truth{}": NUM, "pressures_MPa": list, "joint_model": str, **each("noise", NUM, "mm", "deg"),
    "seeds": int, "starts": int, "targets": dict, "time_s": NUM,
    **each("noise_free", list, "parameters", "identifiable", "unidentifiable"),
    "noise_free.all_identifiable_within_2pct": bool, "noise_free.observations": int,
    **each("noise_free", NUM, "rms_before_mm", "rms_after_mm", "time_s"),
    "noisy.coverage_95": NUM, "noisy.coverage_95_per_parameter{}": MAYBE,
    "noisy.runs[].seed": int, "noisy.runs[].rms_after_mm": NUM, "noisy.runs[].parameters": dict})

#: results/predictor/h1.8/contact_change.json (python -m predictor.validation.contact_change): what the
#: contact on the finger's outline and the plane X = 0 changed, before against after.
CONTACT_CHANGE = Format("predictor-contact-change", 1, "predictor.validation.contact_change", {
    "before": str,
    **each("atlas{}", int, "points", "changed"), "atlas{}.transitions{}": int,
    **{f"{key}{{}}.{k}": int for key in ("reference", "reference_fine")
       for k in ("points", "ramp_steps_before", "ramp_steps_after", "not_converged_before", "not_converged_after")},
    "gestures[].group": str, "gestures[].object": str | None, "gestures[].pressures_MPa": list,
    **each("gestures[]", str, "state_before", "state_after"), "gestures[].tip_shift_mm": MAYBE,
    "gestures[].plane_overlap_mm": MAYBE})

#: results/calibration/calibration.json (make calibrate-demo; predictor.cli.calibrate fem): the
#: predictor calibrated on four whole-finger FEM gestures of a deliberately different finger
#: and its fingertip errors on the held-out ones, uncalibrated and calibrated; the recovery
#: study's figures copied beside them.
CALIBRATION = Format("predictor-calibration-fem", 1, "predictor.cli.calibrate", {
    "joint_model": str, "truth_finger.name": str, "model_finger.name": str,
    "fem.mesh": str, "fem.nodes": int, "fem.cases[].sha256": str, "fem.cases[].role": str,
    "fit.parameters": list, "fit.why": str, "fit.trusted?": bool, **each("parameters{}", NUM, "value", "std", "nominal", "true"),
    "observations_used": int, "heldout_observations": int, "calibrate_on_MPa": list, "heldout_MPa": list,
    **each("heldout_tip_error_uncalibrated_mm", NUM, "mean", "max"),
    **each("heldout_tip_error_calibrated_mm", NUM, "mean", "max"), "improvement": NUM,
    "heldout[].pressures_MPa": list, **each("heldout[]", NUM, "uncalibrated_error_mm", "calibrated_error_mm"),
    "time_s": NUM, **each("targets", NUM, "improvement_at_least", "calibrated_tip_error_mm_at_most"),
    **each("recovery.parameters{}", NUM, "true", "fitted"), "recovery.parameters{}.interval_95": list,
    "recovery.coverage_95": NUM, "recovery.all_identifiable_within_2pct": bool,
    "recovery.time_s_8_observations": NUM, "figure?": str})

#: results/bench/calibrate.json (make bench-calibrate; predictor.cli.calibrate bench): wall times
#: of the 8-observation calibration, with the machine's load and what ran beside it.
CALIBRATION_BENCH = Format("predictor-calibration-bench", 1, "predictor.cli.calibrate", {
    "observations": int, "observations_sha256": str, "observations_file": str, "parameters": list, "trusted": bool,
    "starts": int, "repeats": int, "joint": str,
    **each("", NUM, "fit_median_s", "fit_cpu_median_s", "with_loo_median_s", "with_loo_cpu_median_s", "target_s"),
    "fit_s": list, "with_loo_s": list, "load_average_before": list, "load_average_after": list, "beside": str})

#: results/predictor/track.json (make track, make inverse; predictor.cli.inverse --track): every
#: goal of a trajectory answered warm from the previous answer, verified; times in ms.
TRACK = Format("predictor-track", 1, "predictor.cli.inverse", {
    "goals": int, **each("", NUM, "median_ms", "p95_ms", "rate_hz"), "max_tip_error_mm": MAYBE,
    "verified": bool, **each("", int, "reached", "unreachable"), "answers": list, "label": str})
