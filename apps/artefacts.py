"""Every JSON artefact under results/: where it lives, its format and the make target that
writes it.

Each format is defined beside the code that writes the file (fem.artefacts,
workflow.artefacts, surrogate.artefacts, predictor.artefacts, apps.demo); dataset manifests
have their own strict loader (workflow.shards.Manifest, docs/formats.md §2). This catalogue
is what the report loads through, and what tests/test_artefacts.py checks every committed
artefact against.
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import Path

from apps import demo
from contract.records import Format
from fem import artefacts as fem
from predictor import artefacts as predictor
from surrogate import artefacts as surrogate
from workflow import artefacts as workflow
from workflow.shards import MANIFEST, Manifest, ShardError


@dataclass(frozen=True)
class Artefact:
    """Files matching ``pattern`` (relative to results/, fnmatch) in ``format`` (None: a
    dataset manifest), written by ``make``."""

    pattern: str
    make: str
    format: Format | None

    def load(self, path: str | Path) -> dict:
        """The checked document of ``path`` (ValueError, one line, if it fails its format)."""
        if self.format is not None:
            return self.format.load(path)
        try:
            return Manifest.load(Path(path).parent).to_json()
        except ShardError as exc:
            raise ValueError(str(exc)) from None


#: The make variables that rebuild the paper-fidelity 1.8 mm reference (docs/decisions.md §9).
REF_SURROGATE = "DATA_TAG=_h1.8 SURROGATE_DIR=results/surrogate/h1.8 SURROGATE_SET="
REF_PREDICTOR = "PRED_JOINT=results/surrogate/h1.8/improved.pt PRED_DIR=results/predictor/h1.8"

ARTEFACTS = (
    Artefact("fem/validation.json", "make validation", fem.VALIDATION),
    Artefact("fem/mesh_study.json", "make mesh-study", fem.MESH_STUDY),
    Artefact("fem/mesh_study_tet.json", "make mesh-study-tet", fem.MESH_STUDY),
    Artefact("fem/joint_cases/*.json", "make mesh-study", fem.JOINT_CASE),
    Artefact("fem/mesh_causes.json", "make mesh-causes", fem.MESH_CAUSES),
    Artefact("fem/self_contact.json", "make self-contact", fem.SELF_CONTACT),
    Artefact("fem/materials.json", "make materials", fem.MATERIALS),
    Artefact("fem/joint_outline.json", "make joint-outline", fem.JOINT_OUTLINE),
    Artefact("joints/*/joint_outline.json", "make pipeline JOINT=results/joints/<name>/joint.toml (its outline stage)",
             fem.JOINT_OUTLINE),
    Artefact("fem/heldout_mesh.json", "make fine-compare", workflow.MESH_COMPARISON),
    Artefact("fem/heldout_production.json", "make production-compare", workflow.MESH_COMPARISON),
    Artefact("bench/fem.json", "make bench-fem", fem.BENCH_JOINT),
    Artefact("bench/finger.json", "make bench-finger", fem.BENCH_FINGER),
    Artefact("bench/campaign.json", "make bench-campaign", workflow.BENCH_CAMPAIGN),
    Artefact("bench/predictor.json", "make bench-predictor", predictor.BENCH),
    Artefact("bench/predictor_h1.8.json", "make bench-predictor PRED_JOINT=results/surrogate/h1.8/improved.pt "
             "PRED_BENCH=results/bench/predictor_h1.8.json", predictor.BENCH),
    Artefact(f"data/*/{MANIFEST}", "make dataset", None),
    Artefact("surrogate/metrics.json", "make train", surrogate.METRICS),
    Artefact("surrogate/learning_curve.json", "make learning-curve", surrogate.LEARNING_CURVE),
    Artefact("surrogate/sweep/*.json", "make sweep", surrogate.SWEEP),
    # the paper-fidelity reference, the surrogate on the 1.8 mm walks (docs/decisions.md §9)
    Artefact("surrogate/h1.8/metrics.json", f"make train {REF_SURROGATE}", surrogate.METRICS),
    Artefact("surrogate/h1.8/learning_curve.json", f"make learning-curve {REF_SURROGATE} LC_REFERENCE=",
             surrogate.LEARNING_CURVE),
    Artefact("surrogate/h1.8/sweep/*.json", f"make sweep {REF_SURROGATE}", surrogate.SWEEP),
    Artefact("surrogate/h1.8/heldout_fine.json", "make fine-compare", surrogate.EVALUATION),
    Artefact("surrogate/h1.8/heldout_production.json", "make production-compare", surrogate.EVALUATION),
    Artefact("surrogate/h1.8/multifidelity.json", "make multifidelity", surrogate.MULTIFIDELITY),
    Artefact("bench/surrogate_cost.json", "make bench-surrogate", surrogate.BENCH_COST),
    Artefact("fem/stability_*.json", "make failed-samples", workflow.STABILITY),
    Artefact("fem/resolved_*.json", "make resolve-samples", workflow.RESOLVED),
    Artefact("predictor/gestures.json", "make gestures", predictor.GESTURES),
    Artefact("predictor/atlas_*.json", "make atlas", predictor.ATLAS),
    Artefact("predictor/ramp/atlas_*.json", "make atlas-reference", predictor.ATLAS),
    Artefact("predictor/ramp_fine/atlas_*.json", "make atlas-reference-fine", predictor.ATLAS),
    Artefact("predictor/inverse.json", "make inverse", predictor.INVERSE),
    Artefact("predictor/track.json", "make track", predictor.TRACK),
    # the same on the 1.8 mm reference surrogate (docs/decisions.md §9)
    Artefact("predictor/h1.8/gestures.json", f"make gestures {REF_PREDICTOR}", predictor.GESTURES),
    Artefact("predictor/h1.8/atlas_*.json", f"make atlas {REF_PREDICTOR}", predictor.ATLAS),
    Artefact("predictor/h1.8/ramp/atlas_*.json", f"make atlas-reference {REF_PREDICTOR}", predictor.ATLAS),
    Artefact("predictor/h1.8/ramp_fine/atlas_*.json", f"make atlas-reference-fine {REF_PREDICTOR}", predictor.ATLAS),
    Artefact("predictor/h1.8/inverse.json", f"make inverse {REF_PREDICTOR}", predictor.INVERSE),
    Artefact("predictor/h1.8/track.json", f"make track {REF_PREDICTOR}", predictor.TRACK),
    Artefact("predictor/h1.8/contact_change.json", "python -m predictor.validation.contact_change --before DIR --label TEXT "
             "--after results/predictor/h1.8 --out results/predictor/h1.8/contact_change.json",
             predictor.CONTACT_CHANGE),
    Artefact("calibration/recovery.json", "make calibrate-recovery", predictor.RECOVERY),
    Artefact("calibration/calibration.json", "make calibrate-demo", predictor.CALIBRATION),
    Artefact("calibration/fem/*.json", "make calibration-fem", fem.FINGER_CASE),
    Artefact("calibration/fem_h1.8/*.json", "make calibration-fem CAL_MESH= CAL_FEM=results/calibration/fem_h1.8",
             fem.FINGER_CASE),
    Artefact("bench/calibrate.json", "make bench-calibrate", predictor.CALIBRATION_BENCH),
    Artefact("validation/finger.json", "make validate-finger", predictor.VALIDATION),
    Artefact("validation/finger_h1.8.json", "make validate-finger-h1.8", predictor.VALIDATION),
    Artefact("validation/finger_fem/*.json", "make finger-fem", fem.FINGER_CASE),
    Artefact("fem/finger_grid.json", "make finger-grid", fem.FINGER_GRID),
    Artefact("validation/grasps_fem/*.json", "make grasp-fem", fem.GRASP_CASE),
    Artefact("validation/grasps.json", "make validate-grasps", predictor.GRASP_VALIDATION),
    Artefact("demo/finger.json", "make demo", predictor.VALIDATION),
    Artefact("demo/gravity.json", "make demo", predictor.VALIDATION),
    Artefact("demo/finger_fem/*.json", "make demo", fem.FINGER_CASE),
    Artefact("demo/summary.json", "make demo", demo.SUMMARY),
)


def find(rel: str) -> Artefact:
    """The artefact a path relative to results/ is (ValueError if none: an unknown file)."""
    rel = Path(rel).as_posix()
    for artefact in ARTEFACTS:
        if fnmatchcase(rel, artefact.pattern) and rel.count("/") == artefact.pattern.count("/"):
            return artefact
    raise ValueError(f"results/{rel}: not an artefact the project writes (apps/artefacts.py)")
