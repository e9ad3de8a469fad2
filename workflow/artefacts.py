"""The formats of the JSON artefacts the workflow package writes (contract.records), and
issue 3's campaign throughput targets.

Dataset manifests have their own strict format (``workflow.shards.Manifest``,
docs/formats.md §2). Each format names the key paths the report reads with their JSON
types; the writer in ``owner`` checks its document before writing it and readers load the
file through it. Units as in the key names: s, h, mm, deg.
"""

from __future__ import annotations

from contract.records import Format, Target, each

NUM, MAYBE = float, float | None

#: Issue 3's throughput targets (bench_campaign records whether they are met).
CAMPAIGN_TARGETS = (Target(">=", 400, key="samples_per_hour_2ranks"),
                    Target(">=", 0.85, "%", 100, key="parallel_efficiency"))

#: results/bench/campaign.json (make bench-campaign): campaign throughput on 1 and 2 ranks.
BENCH_CAMPAIGN = Format("workflow-bench-campaign", 1, "workflow.bench_campaign", {
    **each("", NUM, "samples_per_hour_1rank", "samples_per_hour_2ranks", "parallel_efficiency",
           "per_unit_efficiency", "harvested_sample_s", "fresh_sample_s", "paper_cpu_hours"),
    "dataset_cpu_hours": MAYBE, "targets{}": bool})

_MESH = ("mesh_size", "wall_mesh_size")

#: results/fem/heldout_mesh.json (make fine-compare; workflow.dataset compare --out): one
#: walk solved on two meshes, the differences' mean, p95 and max.
MESH_COMPARISON = Format("workflow-mesh-comparison", 1, "workflow.dataset", {
    "ref_mesh.mesh_size": NUM, "ref_mesh.wall_mesh_size": MAYBE, "ref_mesh.mesh?": str,
    "other_mesh.mesh_size": NUM, "other_mesh.wall_mesh_size": MAYBE, "other_mesh.mesh?": str,
    "samples": int, "ref_samples": int,
    **each("tip_mm", NUM, "mean", "p95", "max"), "phi_end_deg.mean": NUM,
    **each("cap_rotation_deg", NUM, "mean", "p95"), "cpu_s_per_sample.other": NUM})

#: results/fem/stability_<dataset>.json (make failed-samples; workflow.stability): each failed
#: sample's load path from zero, probed for stability (negative eigenvalues, lowest eigenvalue
#: N/mm) and contact state (closed valley pairs) at every converged path parameter s.
STABILITY = Format("workflow-stability", 1, "workflow.stability", {
    "dataset": str, "path_points[]": NUM,
    "samples[].sample_id": int, "samples[].inputs[]": NUM, "samples[].verdict": str,
    "samples[].points[].s": NUM, "samples[].points[].unstable_modes": int,
    "samples[].points[].lowest_eigenvalue": MAYBE, "samples[].points[].closed_pairs": int})

#: results/fem/resolved_<dataset>.json (make resolve-samples; workflow.resolve): the campaign's
#: failed samples that a finer load path solved and stored (from the shards' meta["resolved"]):
#: how (path segments, Newton iterations, cut-backs, s), the stored state's stiffness
#: (negative eigenvalues, eigenvalue nearest zero N/mm), the trapezoid miss of its walk pairs
#: (mm) beside the whole walk's; and the dataset's stored and failed counts.
RESOLVED = Format("workflow-resolved", 1, "workflow.resolve", {
    "dataset": str, "samples_requested": int, "stored": int, "failures": int,
    **each("walk_consistency", NUM, "median_mm", "p90_mm", "max_mm"),
    "samples[].sample_id": int, "samples[].inputs[]": NUM, "samples[].path_segments": int,
    "samples[].newton_iterations": int, "samples[].cutbacks": int, "samples[].wall_s": NUM,
    "samples[].unstable_modes": int, "samples[].lowest_eigenvalue": MAYBE,
    "samples[].walk_pairs[].pair": str, "samples[].walk_pairs[].miss_mm": NUM})
