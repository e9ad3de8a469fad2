"""Dataset store (docs/formats.md): the campaign's unit layout, the shard scan, the manifest
rebuild, and the info / verify / merge operations behind ``python -m workflow.dataset``.

Shared by ``workflow.campaign`` (scan + manifest on resume and after every unit) and the
``workflow.dataset`` command line. Imports neither dolfinx nor torch; the FEM's mirror check
of a dataset is ``workflow.mirror``, handed to ``verify`` by its caller.

Data flow::

    DIR/shards/unit-*.npz --ShardScanner.scan (read + verify + match the unit spec)--> UnitInfo
        --build_manifest--> Manifest --save (atomic; the caller is the only writer)--> DIR/manifest.json
    DIR --workflow.shards.load_dataset--> (arrays, Manifest) --info / verify--> dict (text or JSON)
    DIR1, DIR2, ... --merge (units of ONE campaign)--> OUT

Campaign layout: unit u holds sample ids [u K, u K + n_u), K = ``config["unit_size"]``,
n_u = min(K, N - u K) for N requested samples. A unit's shard stores the converged ones
as data and the others as failures, so data ids + failure ids = exactly that range.
Units: inputs P MPa, F1 F2 N, M N·mm; anchors mm.

The joint (contract.joint, docs/joints.md). A manifest's config records the joint it was
solved for only when it is not the paper's: ``joint`` (the description's physics and
contract: its format, geometry, material, input box and anchors, i.e. what
contract.joint.joint_digest covers; not its name, not its [mesh], which the config's
geometry and formulation record) and ``joint_sha256`` (its digest). Absent: the paper's
joint, contract/joints/paper.toml, so every manifest written before joint files existed
reads as what it is (``recorded_joint``). The box checks use the config's ``input_box``.
"""

from __future__ import annotations

import argparse
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from contract.files import atomic_path, sha256_file
from contract.joint import (JointSpec, is_paper_joint, joint_digest, joint_from_dict, joint_to_dict, load_joint,
                            mesh_text)
from contract.spec import INPUT_BOX, INPUT_NAMES, N_INPUTS, outside_box
from workflow.shards import (DATA_KEYS, FAILURE_KEYS, Manifest, ShardEntry, ShardError,
                             array_digest, load_dataset, read_shard, split_of)

SHARD_DIR = "shards"
SHARD_RE = re.compile(r"^unit-(\d{5,})\.npz$")
#: Arrays that must be identical between two runs of the same unit (timings excluded).
REPRODUCIBLE_KEYS = tuple(k for k in DATA_KEYS + FAILURE_KEYS if k != "wall_time_s")


#: The tables of a joint description a config records (the digest's: no name, no mesh).
JOINT_TABLES = ("format", "geometry", "material", "input_box", "anchors")


def joint_record(joint: JointSpec) -> dict:
    """The config entries of ``joint`` (module docstring): {} for the paper's joint, else
    ``joint`` (JOINT_TABLES of contract.joint.joint_to_dict) and ``joint_sha256``."""
    if is_paper_joint(joint):
        return {}
    d = joint_to_dict(joint)
    return {"joint": {k: d[k] for k in JOINT_TABLES}, "joint_sha256": joint_digest(joint)}


def recorded_joint(config: dict) -> JointSpec:
    """The joint a manifest's ``config`` was solved for: its ``joint`` entry, with the
    config's mesh sizes and formulation as the [mesh] table, named by its digest; absent,
    the paper's joint. ShardError (one line) for a record that is not a valid joint."""
    if "joint" not in config:
        return load_joint()
    geometry = config.get("geometry", {})
    mesh = ({"divisions": geometry["divisions"]} if geometry.get("divisions") else {"size": geometry.get("mesh_size")})
    if geometry.get("hex_size") is not None:
        mesh["hex_size"] = geometry["hex_size"]
    mesh["formulation"] = config.get("formulation", "displacement")
    if geometry.get("wall_mesh_size") is not None and not geometry.get("divisions"):
        mesh["wall_size"] = geometry["wall_mesh_size"]
    sha = str(config.get("joint_sha256", ""))
    try:
        joint = joint_from_dict({**config["joint"], "name": f"sha256:{sha[:12]}", "mesh": mesh},
                                "manifest joint")
    except ValueError as exc:
        raise ShardError(str(exc)) from None
    if joint_digest(joint) != sha:
        raise ShardError(f"manifest joint: its description's sha256 {joint_digest(joint)[:12]} is not the "
                         f"recorded joint_sha256 {sha[:12]}")
    return joint


def recorded_box(config: dict) -> np.ndarray:
    """The input box half-widths (4,) of a manifest's config (absent: contract.spec.INPUT_BOX)."""
    return np.asarray(config.get("input_box", INPUT_BOX), dtype=float)


def shard_file(unit: int) -> str:
    """Path of unit ``unit``'s shard relative to the dataset root."""
    return f"{SHARD_DIR}/unit-{unit:05d}.npz"


def unit_count(samples: int, unit_size: int) -> int:
    return -(-samples // unit_size)


def unit_ids(unit: int, samples: int, unit_size: int) -> np.ndarray:
    """Sample ids (n_u,) int64 of ``unit`` in a campaign of ``samples`` samples."""
    start = unit * unit_size
    return np.arange(start, min(start + unit_size, samples), dtype=np.int64)


@dataclass(frozen=True)
class UnitInfo:
    """A verified shard of one unit: its manifest entry and figures."""

    unit: int
    file: str
    sha256: str
    n: int
    failures: int
    cpu_s: float
    git_commit: str

    def entry(self) -> ShardEntry:
        return ShardEntry(file=self.file, sha256=self.sha256, n=self.n, unit=self.unit,
                          failures=self.failures)


def check_unit(arrays: dict, meta: dict, unit: int, samples: int, config: dict, seed: int) -> None:
    """Raise ShardError unless a read shard is unit ``unit`` of this exact campaign."""
    if meta.get("config") != config or meta.get("seed") != seed:
        raise ShardError(f"unit {unit}: shard made with another config or seed")
    if meta.get("unit") != unit:
        raise ShardError(f"unit {unit}: shard claims unit {meta.get('unit')}")
    got = np.sort(np.concatenate([arrays["sample_id"], arrays["failed_sample_id"]]))
    if not np.array_equal(got, unit_ids(unit, samples, config["unit_size"])):
        raise ShardError(f"unit {unit}: sample ids do not cover the unit's range exactly")


class ShardScanner:
    """Finds the verified, finished units of a campaign directory (used by one rank only).

    Results are cached by (file size, mtime) so a rescan only reads new or rewritten shards.
    """

    def __init__(self, root: str | Path, samples: int, config: dict, seed: int):
        self.root, self.samples, self.config, self.seed = Path(root), samples, config, seed
        self.units_total = unit_count(samples, config["unit_size"])
        self._cache: dict[str, tuple[tuple, UnitInfo | None]] = {}
        self.problems: dict[int, str] = {}

    def scan(self) -> dict[int, UnitInfo]:
        """{unit: UnitInfo} of every valid shard of units 0..units_total-1."""
        done, self.problems = {}, {}
        for unit in range(self.units_total):
            rel = shard_file(unit)
            path = self.root / rel
            try:
                st = path.stat()
            except FileNotFoundError:
                continue
            key = (st.st_size, st.st_mtime_ns)
            cached = self._cache.get(rel)
            if cached is None or cached[0] != key:
                try:
                    arrays, meta = read_shard(path)
                    check_unit(arrays, meta, unit, self.samples, self.config, self.seed)
                    info = UnitInfo(unit, rel, sha256_file(path), len(arrays["sample_id"]),
                                    len(arrays["failed_sample_id"]), float(meta.get("cpu_s", 0.0)),
                                    str(meta.get("git_commit", "")))
                    cached = (key, info)
                except ShardError as exc:
                    cached = (key, None)
                    self.problems[unit] = str(exc)
                self._cache[rel] = cached
            elif cached[1] is None:
                self.problems[unit] = f"{rel}: invalid (unchanged since last scan)"
            if cached[1] is not None:
                done[unit] = cached[1]
        return done


def build_manifest(root: str | Path, samples: int, config: dict, seed: int,
                   done: dict[int, UnitInfo], previous: Manifest | None = None) -> Manifest:
    """Atomically (re)write DIR/manifest.json listing the ``done`` units; return it.

    Skips the write when nothing changed since ``previous``. Besides seed, config and the
    shard list it records the campaign figures of Manifest.
    """
    units_total = unit_count(samples, config["unit_size"])
    infos = [done[u] for u in sorted(done)]
    manifest = Manifest(
        seed=seed, config=config, shards=tuple(i.entry() for i in infos),
        samples_requested=samples, units_total=units_total, units_done=len(infos),
        complete=len(infos) == units_total,
        samples=sum(i.n for i in infos), failures=sum(i.failures for i in infos),
        cpu_hours=round(sum(i.cpu_s for i in infos) / 3600.0, 4),
        git_commits=tuple(sorted({i.git_commit for i in infos})))
    if manifest != previous:
        manifest.save(root)
    return manifest


def clean_temporaries(root: str | Path) -> int:
    """Remove temp files a killed writer left beside shards/manifest (``.NAME.*.tmp`` and
    contract.files' ``.NAME.*.tmp.SUFFIX``); return how many."""
    n = 0
    for d in (Path(root), Path(root) / SHARD_DIR):
        if d.is_dir():
            for p in d.glob(".*.tmp*"):
                p.unlink(missing_ok=True)
                n += 1
    return n


# ---------------------------------------------------------------------------- info
def coverage(inputs: np.ndarray, bins: int = 4, box=INPUT_BOX) -> dict:
    """Input coverage of (n, 4) inputs over ``box`` (4,): per-input range and the fraction
    of the bins^4 grid cells of the box that hold at least one sample."""
    box = np.asarray(box, dtype=float)
    z = np.clip((inputs / box + 1) / 2, 0, 1 - 1e-12)          # (n, 4) in [0, 1)
    cells = np.unique(np.floor(z * bins).astype(int) @ bins ** np.arange(N_INPUTS))
    per = {name: {"min": float(inputs[:, i].min()), "max": float(inputs[:, i].max()),
                  "box": float(box[i]),
                  "histogram": np.histogram(z[:, i], bins=bins, range=(0, 1))[0].tolist()}
           for i, name in enumerate(INPUT_NAMES)} if len(inputs) else {}
    return {"per_input": per, "grid": f"{bins}^{N_INPUTS}", "cells_occupied": len(cells) / bins ** N_INPUTS}


def walk_misses(arrays: dict, unit_size: int) -> list[tuple[int, int, float]]:
    """The trapezoid miss (mm) of every walk pair: consecutive converged samples i, i + 1
    of one unit (ids u K .. u K + K - 1: one continuation walk) with finite Jacobians,
    as (id_i, id_{i+1}, miss). The anchors a (k, 2) of such a pair obey
    a_{i+1} - a_i = (J_i + J_{i+1}) / 2 (x_{i+1} - x_i) exactly where they are quadratic in
    the inputs x; the miss is the largest anchor distance of the pair from it."""
    ids, x = arrays["sample_id"], arrays["inputs"]
    a = arrays["anchors"].reshape(len(ids), -1)              # rows x_1, y_1, x_2, ... as J's
    J = arrays["jacobian"]
    pair = (np.diff(ids) == 1) & (ids[1:] // unit_size == ids[:-1] // unit_size)
    pair &= np.isfinite(J[1:]).all((1, 2)) & np.isfinite(J[:-1]).all((1, 2))
    i = np.nonzero(pair)[0]
    step = np.einsum("nij,nj->ni", 0.5 * (J[i] + J[i + 1]), x[i + 1] - x[i])
    miss = np.linalg.norm((step - (a[i + 1] - a[i])).reshape(len(i), -1, 2), axis=-1).max(-1)
    return [(int(ids[k]), int(ids[k + 1]), float(m)) for k, m in zip(i, miss)]


def walk_consistency(arrays: dict, unit_size: int) -> dict | None:
    """How well a dataset's Jacobians predict its walks (a data-quality figure, mm): the
    walk pairs' trapezoid misses (``walk_misses``), which measure the data's curvature
    over a walk step and any noise or inconsistency between anchors and Jacobians.
    Returns {"pairs", "median_mm", "p90_mm", "max_mm"}, or None without a walk pair."""
    miss = np.array([m for _, _, m in walk_misses(arrays, unit_size)])
    if not len(miss):
        return None
    return {"pairs": int(len(miss)), "median_mm": float(np.median(miss)), "p90_mm": float(np.quantile(miss, 0.9)),
            "max_mm": float(miss.max())}


def info(root: str | Path) -> dict:
    """Counts, coverage, failure rate, split, checksums, CPU time and the walks' consistency
    (``walk_consistency``) of dataset ``root``."""
    arrays, manifest = load_dataset(root)
    n, m = len(arrays["sample_id"]), len(arrays["failed_sample_id"])
    split = np.bincount(split_of(arrays["sample_id"], manifest.seed), minlength=3)
    reasons: dict[str, int] = {}
    for r in arrays["failed_reason"]:
        reasons[str(r)[:80]] = reasons.get(str(r)[:80], 0) + 1
    return {
        "root": str(root), "seed": manifest.seed, "config": manifest.config,
        "samples": n, "failures": m, "failure_rate": m / (n + m) if n + m else 0.0,
        "failure_reasons": reasons,
        "split": {"train": int(split[0]), "val": int(split[1]), "test": int(split[2])},
        "shards": len(manifest.shards), "complete": manifest.complete,
        "samples_requested": manifest.samples_requested,
        "coverage": coverage(arrays["inputs"], box=recorded_box(manifest.config)),
        "jacobian_finite": bool(np.isfinite(arrays["jacobian"]).all()),
        "walk_consistency": walk_consistency(arrays, manifest.config["unit_size"]),
        "newton_iterations_median": float(np.median(arrays["newton_iterations"])) if n else None,
        "wall_time_s_median": float(np.median(arrays["wall_time_s"])) if n else None,
        "cpu_hours": manifest.cpu_hours,
        "git_commits": None if manifest.git_commits is None else list(manifest.git_commits),
        "checksums": {"data_sha256": array_digest(arrays),
                      "shards": {e.file: e.sha256 for e in manifest.shards}},
    }


def unit_range(text: str) -> tuple[int, int]:
    """argparse type of ``--units A:B``: two integers 0 <= A < B (B is checked against the
    campaign's unit count after parsing)."""
    try:
        a, b = (int(v) for v in text.split(":"))    # not two integers: ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not A:B (two integers, 0 <= A < B)") from None
    if not 0 <= a < b:
        raise argparse.ArgumentTypeError(f"{text} is not a unit range A:B with 0 <= A < B")
    return a, b


# ---------------------------------------------------------------------------- verify
def verify(root: str | Path, mirror_check=None, tol_mm: float = 1e-5, jac_tol: float = 1e-3) -> dict:
    """Check dataset ``root``; returns {"ok", "errors", "warnings", ...}.

    Errors: unreadable or invalid manifest or shard, sha256/checksum mismatch, config or
    seed mismatch, duplicated or misplaced sample ids, non-finite or out-of-box data
    (contract.spec.outside_box), a sample both stored and failed, and (with ``mirror_check``,
    a callable (arrays, manifest) -> figures such as workflow.mirror.mirror_check) a mirror
    relation off by more than ``tol_mm`` (anchors) or ``jac_tol`` (relative, Jacobian). Warnings: an incomplete campaign, shard files the manifest does not list.
    """
    root = Path(root)
    errors, warnings = [], []
    try:
        arrays, manifest = load_dataset(root)
    except ShardError as exc:
        return {"ok": False, "errors": [str(exc)], "warnings": []}
    cfg, seed = manifest.config, manifest.seed
    for e in manifest.shards:
        a, meta = read_shard(root / e.file)
        if meta.get("seed") != seed:
            errors.append(f"{e.file}: seed {meta.get('seed')} != manifest seed {seed}")
        if manifest.is_campaign:
            try:
                check_unit(a, meta, int(meta.get("unit", -1)), manifest.samples_requested, cfg, seed)
            except ShardError as exc:
                errors.append(f"{e.file}: {exc}")
    listed = {e.file for e in manifest.shards}
    extra = sorted(f"{SHARD_DIR}/{p.name}" for p in (root / SHARD_DIR).glob("*.npz")
                   if SHARD_RE.match(p.name) and f"{SHARD_DIR}/{p.name}" not in listed)
    if extra:
        warnings.append(f"{len(extra)} shard file(s) not in the manifest: {extra[:5]}")
    if manifest.complete is False:
        warnings.append(f"incomplete campaign: {manifest.units_done}/{manifest.units_total} units "
                        "(re-run the campaign to resume)")
    box = recorded_box(cfg)
    outside = int(outside_box(arrays["inputs"], box).sum())
    if outside:
        allowed = ", ".join(f"|{n}| <= {b:g}" for n, b in zip(INPUT_NAMES, box))
        errors.append(f"{outside} input(s) non-finite or outside the box {allowed}")
    if not np.isfinite(arrays["anchors"]).all():
        errors.append("non-finite anchors")
    if cfg.get("source") == "fem-campaign" and not np.isfinite(arrays["jacobian"]).all():
        errors.append("non-finite Jacobians")
    if not arrays["converged"].all():
        errors.append("non-converged samples stored as data")
    both = np.intersect1d(arrays["sample_id"], arrays["failed_sample_id"])
    if both.size:
        errors.append(f"{both.size} sample id(s) both stored and failed")
    out = {"n": len(arrays["sample_id"]), "failures": len(arrays["failed_sample_id"])}
    if mirror_check is not None and len(arrays["sample_id"]):
        if cfg.get("source") != "fem-campaign":
            warnings.append(f"mirror check skipped: source {cfg.get('source')!r} is not the FEM")
        else:
            out["mirror"] = mc = mirror_check(arrays, manifest)
            if not all(c["converged"] for c in mc["cases"]):
                errors.append("mirror check: a mirrored case did not converge")
            elif mc["max_anchor_error_mm"] > tol_mm or mc["max_jacobian_rel_error"] > jac_tol:
                errors.append(f"mirror relation violated: anchors {mc['max_anchor_error_mm']:.2e} mm,"
                              f" Jacobian {mc['max_jacobian_rel_error']:.2e} relative")
    return {"ok": not errors, "errors": errors, "warnings": warnings, **out}


# ---------------------------------------------------------------------------- merge
def merge(out: str | Path, sources: list[str | Path]) -> Manifest:
    """Merge datasets of ONE campaign (same seed and config, e.g. pieces run on different
    machines with ``--units``) into ``out``: the union of their units. A unit present in
    several sources must hold the same samples (timings aside). Every check runs before
    anything is written. Returns the manifest of ``out``."""
    out = Path(out)
    manifests = [Manifest.load(s) for s in sources]
    m0 = manifests[0]
    if not m0.is_campaign:
        raise ShardError(f"{sources[0]}: not a workflow.campaign dataset (no unit layout)")
    for s, m in zip(sources[1:], manifests[1:]):
        if m.seed != m0.seed or m.config != m0.config:
            raise ShardError(f"{s}: seed or config differs from {sources[0]}; cannot merge")
    if Manifest.exists(out):
        mo = Manifest.load(out)
        if mo.seed != m0.seed or mo.config != m0.config:
            raise ShardError(f"{out}: existing dataset with another seed or config")
    samples = max(m.samples_requested or 0 for m in manifests)
    chosen: dict[int, Path] = {}
    for src, m in zip(sources, manifests):
        load_dataset(src)                          # verifies every listed shard first
        for e in m.shards:
            path = Path(src) / e.file
            arrays, _ = read_shard(path)
            if e.unit in chosen:
                prev, _ = read_shard(chosen[e.unit])
                if any(not np.array_equal(prev[k], arrays[k]) for k in REPRODUCIBLE_KEYS):
                    raise ShardError(f"unit {e.unit}: {chosen[e.unit]} and {path} disagree")
                continue
            chosen[e.unit] = path
    for unit, path in sorted(chosen.items()):
        dst = out / shard_file(unit)
        if dst.resolve() == path.resolve():
            continue
        with atomic_path(dst) as tmp:
            shutil.copyfile(path, tmp)
    scanner = ShardScanner(out, samples, m0.config, m0.seed)
    return build_manifest(out, samples, m0.config, m0.seed, scanner.scan())


# ---------------------------------------------------------------------------- compare
def _spread(e: np.ndarray) -> dict:
    return {"mean": float(e.mean()), "p95": float(np.percentile(e, 95)), "max": float(e.max())}


def compare(ref: str | Path, other: str | Path) -> dict:
    """Per-sample differences of dataset ``other`` from dataset ``ref`` where both solved the
    same load: two campaigns of one walk (same seed, unit size, step) on different meshes,
    so the figures are the discretisation change between the meshes over the walk's
    distribution. For sample i on both:

        anchor_mm_i = max_k |r_ik(other) - r_ik(ref)|   (mm; tip_mm_i the same for k = 10)
        phi_end_deg_i, cap_rotation_deg_i = |wrap(a_i(other) - a_i(ref))|   (deg)

    each given as mean / p95 / max over the common samples. Raises ShardError if the walks
    differ or a common sample id holds different loads."""
    (a, ma), (b, mb) = load_dataset(ref), load_dataset(other)
    walk = lambda m: {"seed": m.seed, **{k: m.config.get(k) for k in ("unit_size", "walk_step", "walk_turn")}}
    ca, cb = walk(ma), walk(mb)
    if ca != cb:
        raise ShardError(f"{other}: another campaign walk than {ref} ({cb} against {ca}); "
                         "nothing to compare")
    ids, ia, ib = np.intersect1d(a["sample_id"], b["sample_id"], return_indices=True)
    if not len(ids):
        raise ShardError(f"{ref} and {other}: no sample solved in both")
    # the walk is the same to rounding (1e-17 seen between the committed set and a re-run)
    if np.abs(a["inputs"][ia] - b["inputs"][ib]).max() > 1e-12 * recorded_box(ma.config).max():
        raise ShardError(f"{ref} and {other}: the same sample ids hold different loads")
    d = np.linalg.norm(b["anchors"][ib] - a["anchors"][ia], axis=-1)        # (n, 10) mm
    wrap = lambda x: np.degrees(np.abs(np.angle(np.exp(1j * x))))
    worst = int(np.argmax(d.max(axis=1)))
    def mesh(m):
        g = m.config["geometry"]
        return {"mesh": mesh_text(g.get("mesh_size"), g.get("wall_mesh_size"), g.get("divisions", 0),
                                  g.get("hex_size")),
                "mesh_size": g.get("mesh_size"), "wall_mesh_size": g.get("wall_mesh_size"),
                "formulation": m.config.get("formulation", "displacement")}

    return {
        "ref": str(ref), "other": str(other), "ref_mesh": mesh(ma), "other_mesh": mesh(mb),
        "samples": int(len(ids)), "ref_samples": int(len(a["sample_id"])),
        "other_samples": int(len(b["sample_id"])),
        "anchor_mm": _spread(d.max(axis=1)), "tip_mm": _spread(d[:, -1]),
        "phi_end_deg": _spread(wrap(b["phi_end"][ib] - a["phi_end"][ia])),
        "cap_rotation_deg": _spread(wrap(b["cap_rotation"][ib] - a["cap_rotation"][ia])),
        # CPU time per solved sample from the manifests (each with the solver code it ran)
        "cpu_s_per_sample": {"ref": 3600 * ma.cpu_hours / max(len(a["sample_id"]), 1),
                             "other": 3600 * mb.cpu_hours / max(len(b["sample_id"]), 1)},
        "worst": {"sample_id": int(ids[worst]), "inputs": a["inputs"][ia][worst].tolist(),
                  "anchor_mm": float(d[worst].max())},
    }
