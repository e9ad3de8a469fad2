"""The formats of the JSON artefacts the surrogate package writes (contract.records).

Each names the key paths the report reads with their JSON types; the writer in ``owner``
checks its document before writing it and readers load the file through it
(docs/formats.md §6). Errors are in mm and deg (``*_deg``), the Jacobian's relative; times
in s and ms; null where a model has no such figure (a KNN's Jacobian, a model without a
cap head).
"""

from __future__ import annotations

from contract.records import Format, each

NUM, MAYBE = float, float | None

#: The metric keys of one evaluation (surrogate.evaluate.evaluate): null where the model
#: has no such figure; the p95 and cap keys are absent from older files.
_METRICS = {"n": int, **each("", MAYBE, "mean_anchor_error_mm", "p95_anchor_error_mm", "tip_error_mm",
                             "phi_end_error_deg", "jacobian_rel_error"),
            **each("", MAYBE, *(f"{k}?" for k in (
                "cap_rotation_error_deg", "p95_cap_rotation_error_deg", "tangent_error_deg",
                "p95_tangent_error_deg", "p95_phi_end_error_deg")))}


def _model(name: str, optional: bool) -> dict:
    """The key paths of one model's record in metrics.json."""
    at = f"{name}?" if optional else name
    keys = {f"{at}.{split}.{k}": kind for split in ("test", "heldout") for k, kind in _METRICS.items()}
    return keys | {f"{at}.train_time_s?": NUM, f"{at}.timing?.threads?": list,
                   **each(f"{at}.timing?", NUM, "single_ms_float64?", "batched_samples_per_s_float32_all_cores?")}


#: results/surrogate/metrics.json (make train; surrogate.evaluate --report): every model on
#: the test split and the held-out set.
METRICS = Format("surrogate-metrics", 1, "surrogate.evaluate", {
    **_model("improved", False), **_model("paper", True), **_model("knn", True),
    **each("datasets?.train?.n?", int, "train?", "val?")})

#: results/surrogate/h1.8/heldout_fine.json (make fine-compare; surrogate.evaluate --out): one
#: model against one dataset (its split, model and data paths beside the metrics).
EVALUATION = Format("surrogate-evaluation", 1, "surrogate.evaluate", {
    **_METRICS, **each("", str, "split", "model", "data")})

#: results/surrogate/learning_curve.json (make learning-curve): one point per (samples,
#: Jacobian loss, seed), held-out errors.
LEARNING_CURVE = Format("surrogate-learning-curve", 1, "surrogate.learning_curve", {
    "config": str, **each("data.n", int, "train", "val"), "data.heldout_n": int, "min_steps": int,
    "epoch_budget": str, "complete?": bool,
    **each("points[]", int, "samples", "seed", "steps"), "points[].jacobian_loss": bool,
    **each("points[]", MAYBE, "heldout_mean_anchor_error_mm", "heldout_tip_error_mm",
           "heldout_cap_rotation_error_deg", "heldout_phi_end_error_deg", "heldout_jacobian_rel_error",
           "train_anchor_error_mm", "train_time_s")})

#: results/surrogate/sweep/<variant>.json (make sweep): one variant of the improved config.
SWEEP = Format("surrogate-sweep", 1, "surrogate.sweep", {
    "name": str, "overrides": list, "epochs": int, "data_sha256": str, "model_config": dict,
    "train_config": dict, "best_epoch": int, "train_time_s": NUM,
    **{f"{split}.{k}": kind for split in ("val", "heldout") for k, kind in _METRICS.items()}})

#: results/surrogate/h1.8/multifidelity.json (surrogate.multifidelity): the multi-fidelity
#: surrogate against fine-only training at equal FEM cost; one point per (kind, samples),
#: one comparison row per multi-fidelity point.
MULTIFIDELITY = Format("surrogate-multifidelity", 1, "surrogate.multifidelity", {
    **each("coarse", NUM, "cpu_hours", "cpu_s_per_sample"), "coarse.samples": int,
    **each("fine", NUM, "cpu_hours", "cpu_s_per_sample"), **each("fine", int, "samples", "pool", "val"),
    "heldout.n": int, "heldout.split": str, "min_steps": int, "complete": bool, "coarse_only.cpu_hours": NUM,
    "points[].kind": str, **each("points[]", int, "samples", "seed", "steps"), "points[].cpu_hours": NUM,
    **each("points[]", MAYBE, "heldout_phi_end_error_deg", "heldout_jacobian_rel_error"),
    **each("comparison[]", int, "samples", "equal_cost_fine_samples", "fine_only_samples"),
    "comparison[].m_exceeds_data": bool, **each("comparison[]", NUM, "multifidelity_cpu_hours", "fine_only_cpu_hours"),
    **{f"{at}.{k}": MAYBE for at in ("coarse_only", "points[]", "comparison[].multifidelity",
                                     "comparison[].fine_only?", "comparison[].scale_only?",
                                     "comparison[].reference_curve_at_m?")
       for k in ("heldout_mean_anchor_error_mm", "heldout_tip_error_mm", "heldout_cap_rotation_error_deg")}})

#: results/bench/surrogate_cost.json (make bench-surrogate; surrogate.bench_cost): the median
#: ms of one query (anchors, cap rotation, Jacobian; float64, one thread) per model and batch
#: size, timed interleaved, and each model's ratio to the first's.
BENCH_COST = Format("surrogate-bench-cost", 1, "surrogate.bench_cost", {
    "threads": int, "dtype": str, "models[].model": str, "cases[].batch": int, "cases[].models[].model": str,
    **each("cases[].models[]", NUM, "ms", "samples_per_s", "ratio_to_first")})
