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


ARTEFACTS = (
    Artefact("fem/validation.json", "make validation", fem.VALIDATION),
    Artefact("fem/mesh_study.json", "make mesh-study", fem.MESH_STUDY),
    Artefact("fem/mesh_study_tet.json", "make mesh-study-tet", fem.MESH_STUDY),
    Artefact("fem/joint_cases/*.json", "make mesh-study", fem.JOINT_CASE),
    Artefact("fem/mesh_causes.json", "make mesh-causes", fem.MESH_CAUSES),
    Artefact("fem/self_contact.json", "make self-contact", fem.SELF_CONTACT),
    Artefact("fem/materials.json", "make materials", fem.MATERIALS),
    Artefact("fem/heldout_mesh.json", "make fine-compare", workflow.MESH_COMPARISON),
    Artefact("fem/heldout_production.json", "make production-compare", workflow.MESH_COMPARISON),
    Artefact("bench/fem.json", "make bench-fem", fem.BENCH_JOINT),
    Artefact("bench/finger.json", "make bench-finger", fem.BENCH_FINGER),
    Artefact("bench/campaign.json", "make bench-campaign", workflow.BENCH_CAMPAIGN),
    Artefact("bench/predictor.json", "make bench-predictor", predictor.BENCH),
    Artefact(f"data/*/{MANIFEST}", "make dataset", None),
    Artefact("surrogate/metrics.json", "make train", surrogate.METRICS),
    Artefact("surrogate/heldout_fine.json", "make fine-compare", surrogate.EVALUATION),
    Artefact("surrogate/heldout_production.json", "make production-compare", surrogate.EVALUATION),
    Artefact("surrogate/learning_curve.json", "make learning-curve", surrogate.LEARNING_CURVE),
    Artefact("surrogate/multifidelity.json", "make multifidelity", surrogate.MULTIFIDELITY),
    Artefact("surrogate/sweep/*.json", "make sweep", surrogate.SWEEP),
    Artefact("surrogate/hex2s3/metrics.json", "make train-new", surrogate.METRICS),
    Artefact("surrogate/hex2s3/learning_curve.json", "make learning-curve-new", surrogate.LEARNING_CURVE),
    Artefact("surrogate/hex2s3/sweep/*.json", "make sweep-new", surrogate.SWEEP),
    Artefact("bench/surrogate_cost.json", "make bench-surrogate", surrogate.BENCH_COST),
    Artefact("fem/stability_*.json", "make failed-samples", workflow.STABILITY),
    Artefact("fem/resolved_*.json", "make resolve-samples", workflow.RESOLVED),
    Artefact("predictor/gestures.json", "make gestures", predictor.GESTURES),
    Artefact("predictor/atlas_*.json", "make atlas", predictor.ATLAS),
    Artefact("predictor/ramp/atlas_*.json", "make atlas-reference", predictor.ATLAS),
    Artefact("predictor/ramp_fine/atlas_*.json", "make atlas-reference-fine", predictor.ATLAS),
    Artefact("predictor/inverse.json", "make inverse", predictor.INVERSE),
    Artefact("predictor/track.json", "make track", predictor.TRACK),
    # the same, on the production surrogate beside today's until the switch (issue 55 §3)
    Artefact("bench/predictor_hex2s3.json", "make predictor-new", predictor.BENCH),
    Artefact("predictor/hex2s3/gestures.json", "make predictor-new", predictor.GESTURES),
    Artefact("predictor/hex2s3/atlas_*.json", "make predictor-new", predictor.ATLAS),
    Artefact("predictor/hex2s3/ramp/atlas_*.json", "make predictor-new", predictor.ATLAS),
    Artefact("predictor/hex2s3/ramp_fine/atlas_*.json", "make predictor-new", predictor.ATLAS),
    Artefact("predictor/hex2s3/inverse.json", "make predictor-new", predictor.INVERSE),
    Artefact("predictor/hex2s3/track.json", "make predictor-new", predictor.TRACK),
    Artefact("predictor/contact_change.json", "python -m predictor.contact_change --before DIR --label TEXT "
             "--out results/predictor/contact_change.json", predictor.CONTACT_CHANGE),
    Artefact("calibration/recovery.json", "make calibrate-recovery", predictor.RECOVERY),
    Artefact("calibration/calibration.json", "make calibrate-demo", predictor.CALIBRATION),
    Artefact("calibration/fem/*.json", "make calibration-fem", fem.FINGER_CASE),
    Artefact("calibration/fem_hex2s3/*.json", "make calibration-fem-new", fem.FINGER_CASE),
    Artefact("bench/calibrate.json", "make bench-calibrate", predictor.CALIBRATION_BENCH),
    Artefact("validation/finger.json", "make validate-finger", predictor.VALIDATION),
    Artefact("validation/finger_hex2s3.json", "make validate-finger-new", predictor.VALIDATION),
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
