"""Dataset tools (DESIGN.md §5): inspect, verify and merge FEM campaign datasets.

``python -m workflow.dataset info|verify|merge``. The library part (the unit layout of a
campaign, the shard scan and the manifest rebuild) is shared with ``workflow.campaign``
and imports neither dolfinx nor torch; only ``verify --mirror N`` builds a FEM solver.

Data flow::

    DIR/shards/unit-*.npz --scan_units (read + verify + match the unit spec)--> UnitInfo
        --build_manifest--> DIR/manifest.json (atomic; the only writer is the caller)
    DIR --workflow.shards.load_dataset--> arrays --info / verify--> report (text or --json)

Campaign layout: unit u holds sample ids [u K, u K + n_u), K = ``config["unit_size"]``,
n_u = min(K, N - u K) for N requested samples. A unit's shard stores the converged ones
as data and the others as failures, so data ids + failure ids = exactly that range.
Units: inputs P MPa, F1 F2 N, M N·mm; anchors mm.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workflow import shards
from workflow.shards import (DATA_KEYS, FAILURE_KEYS, INPUT_BOX, ShardError, file_sha256,
                             load_dataset, load_manifest, read_shard, split_of, write_manifest)

SHARD_DIR = "shards"
SHARD_RE = re.compile(r"^unit-(\d{5,})\.npz$")
#: Arrays that must be identical between two runs of the same unit (timings excluded).
REPRODUCIBLE_KEYS = tuple(k for k in DATA_KEYS + FAILURE_KEYS if k != "wall_time_s")
#: Exit codes of the CLIs: 0 ok, 1 problems found, 2 bad command line.
EXIT_PROBLEMS, EXIT_USAGE = 1, 2


def shard_file(unit: int) -> str:
    """Path of unit ``unit``'s shard relative to the dataset root."""
    return f"{SHARD_DIR}/unit-{unit:05d}.npz"


def unit_count(samples: int, unit_size: int) -> int:
    return -(-samples // unit_size)


def unit_ids(unit: int, samples: int, unit_size: int) -> np.ndarray:
    """Sample ids (n_u,) int64 of ``unit`` in a campaign of ``samples`` samples."""
    start = unit * unit_size
    return np.arange(start, min(start + unit_size, samples), dtype=np.int64)


@dataclass
class UnitInfo:
    """A verified shard of one unit: its manifest entry and figures."""

    unit: int
    file: str
    sha256: str
    n: int
    failures: int
    cpu_s: float
    git_commit: str

    def entry(self) -> dict:
        return {"file": self.file, "sha256": self.sha256, "n": self.n, "unit": self.unit,
                "failures": self.failures}


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
                    info = UnitInfo(unit, rel, file_sha256(path), len(arrays["sample_id"]),
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
                   done: dict[int, UnitInfo], previous: dict | None = None) -> dict:
    """Atomically (re)write DIR/manifest.json listing the ``done`` units; return it.

    Skips the write when nothing changed. Extra keys (besides format/seed/config/shards)
    are campaign figures: requested samples, completeness, failures, CPU hours, commits.
    """
    units_total = unit_count(samples, config["unit_size"])
    infos = [done[u] for u in sorted(done)]
    manifest = {
        "seed": seed, "config": config, "shards": [i.entry() for i in infos],
        "samples_requested": samples, "units_total": units_total, "units_done": len(infos),
        "complete": len(infos) == units_total,
        "samples": sum(i.n for i in infos), "failures": sum(i.failures for i in infos),
        "cpu_hours": round(sum(i.cpu_s for i in infos) / 3600.0, 4),
        "git_commits": sorted({i.git_commit for i in infos}),
        "format": shards.FORMAT,
    }
    if manifest != previous:
        write_manifest(root, manifest)
    return manifest


def clean_temporaries(root: str | Path) -> int:
    """Remove temp files a killed writer left beside shards/manifest; return how many."""
    n = 0
    for d in (Path(root), Path(root) / SHARD_DIR):
        if d.is_dir():
            for p in d.glob(".*.tmp"):
                p.unlink(missing_ok=True)
                n += 1
    return n


# ---------------------------------------------------------------------------- info
def coverage(inputs: np.ndarray, bins: int = 4) -> dict:
    """Input coverage of (n, 4) inputs over the box: per-input range and the fraction of
    the bins^4 grid cells of the box that hold at least one sample."""
    z = np.clip((inputs / INPUT_BOX + 1) / 2, 0, 1 - 1e-12)          # (n, 4) in [0, 1)
    cells = np.unique(np.floor(z * bins).astype(int) @ bins ** np.arange(4))
    per = {name: {"min": float(inputs[:, i].min()), "max": float(inputs[:, i].max()),
                  "box": float(INPUT_BOX[i]),
                  "histogram": np.histogram(z[:, i], bins=bins, range=(0, 1))[0].tolist()}
           for i, name in enumerate(shards.INPUT_NAMES)} if len(inputs) else {}
    return {"per_input": per, "grid": f"{bins}^4", "cells_occupied": len(cells) / bins ** 4}


def info(root: str | Path) -> dict:
    """Counts, coverage, failure rate, split, checksums and CPU time of dataset ``root``."""
    arrays, manifest = load_dataset(root)
    n, m = len(arrays["sample_id"]), len(arrays["failed_sample_id"])
    seed = manifest.get("seed")
    split = np.bincount(split_of(arrays["sample_id"], seed), minlength=3) if seed is not None \
        else np.zeros(3, int)
    digest = shards._array_digest({k: arrays[k] for k in DATA_KEYS + FAILURE_KEYS})
    reasons: dict[str, int] = {}
    for r in arrays["failed_reason"]:
        reasons[str(r)[:80]] = reasons.get(str(r)[:80], 0) + 1
    return {
        "root": str(root), "seed": seed, "config": manifest.get("config"),
        "samples": n, "failures": m, "failure_rate": m / (n + m) if n + m else 0.0,
        "failure_reasons": reasons,
        "split": {"train": int(split[0]), "val": int(split[1]), "test": int(split[2])},
        "shards": len(manifest["shards"]), "complete": manifest.get("complete"),
        "samples_requested": manifest.get("samples_requested"),
        "coverage": coverage(arrays["inputs"]),
        "jacobian_finite": bool(np.isfinite(arrays["jacobian"]).all()),
        "newton_iterations_median": float(np.median(arrays["newton_iterations"])) if n else None,
        "wall_time_s_median": float(np.median(arrays["wall_time_s"])) if n else None,
        "cpu_hours": manifest.get("cpu_hours"), "git_commits": manifest.get("git_commits"),
        "checksums": {"data_sha256": digest,
                      "shards": {e["file"]: e["sha256"] for e in manifest["shards"]}},
    }


# ---------------------------------------------------------------------------- verify
def mirror_check(arrays: dict, manifest: dict, n: int) -> dict:
    """Solve the y-mirror of ``n`` stored samples with the FEM (fresh from zero) and compare
    with the mirrored stored anchors and Jacobian (DESIGN.md §3). The mesh is mirror
    symmetric, so the relation holds to solver tolerance. Needs dolfinx; runs on one rank."""
    from mpi4py import MPI

    from fem.geometry import JointGeometry
    from fem.solver import JointSolver, Load, Material, SolverConfig

    cfg = manifest["config"]
    solver = JointSolver(JointGeometry(**cfg["geometry"]), MPI.COMM_SELF,
                         Material(**cfg["material"]), SolverConfig(**cfg["solver"]))
    rng = np.random.default_rng([int(manifest["seed"]), 7])
    pick = np.sort(rng.choice(len(arrays["sample_id"]), size=min(n, len(arrays["sample_id"])),
                              replace=False))
    cases = []
    for i in pick:
        x_m, r_m, j_m = shards.mirror(arrays["inputs"][i:i + 1], arrays["anchors"][i:i + 1],
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


def verify(root: str | Path, mirror: int = 0, tol_mm: float = 1e-5, jac_tol: float = 1e-3) -> dict:
    """Check dataset ``root``; returns {"ok", "errors", "warnings", ...}.

    Errors: unreadable manifest or shard, sha256/checksum mismatch, config or seed
    mismatch, duplicated or misplaced sample ids, non-finite or out-of-box data, a sample
    both stored and failed, and (with ``mirror`` > 0) a mirror relation off by more than
    ``tol_mm`` (anchors) or ``jac_tol`` (relative, Jacobian). Warnings: an incomplete
    campaign, shard files the manifest does not list.
    """
    root = Path(root)
    errors, warnings = [], []
    try:
        arrays, manifest = load_dataset(root)
    except ShardError as exc:
        return {"ok": False, "errors": [str(exc)], "warnings": []}
    cfg, seed = manifest.get("config") or {}, manifest.get("seed")
    if seed is None:
        errors.append("manifest has no seed (the split is undefined)")
    listed = {e["file"] for e in manifest["shards"]}
    for e in manifest["shards"]:
        _, meta = read_shard(root / e["file"])
        if meta.get("seed") != seed:
            errors.append(f"{e['file']}: seed {meta.get('seed')} != manifest seed {seed}")
        if "unit_size" in cfg and "samples_requested" in manifest:
            a, _ = read_shard(root / e["file"])
            try:
                check_unit(a, meta, int(meta.get("unit", -1)), manifest["samples_requested"], cfg,
                           seed)
            except ShardError as exc:
                errors.append(f"{e['file']}: {exc}")
    extra = sorted(str(p.relative_to(root)) for p in (root / SHARD_DIR).glob("*.npz")
                   if str(p.relative_to(root)) not in listed) if (root / SHARD_DIR).is_dir() else []
    if extra:
        warnings.append(f"{len(extra)} shard file(s) not in the manifest: {extra[:5]}")
    if manifest.get("complete") is False:
        warnings.append(f"incomplete campaign: {manifest.get('units_done')}/"
                        f"{manifest.get('units_total')} units (re-run the campaign to resume)")
    x = arrays["inputs"]
    if not np.isfinite(x).all() or (np.abs(x) > INPUT_BOX * (1 + 1e-12)).any():
        errors.append("inputs non-finite or outside the box |P|<=0.3, |F1|,|F2|<=3, |M|<=100")
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
    if mirror > 0 and len(arrays["sample_id"]):
        if cfg.get("source") != "fem-campaign":
            warnings.append(f"mirror check skipped: source {cfg.get('source')!r} is not the FEM")
        else:
            out["mirror"] = mc = mirror_check(arrays, manifest, mirror)
            if not all(c["converged"] for c in mc["cases"]):
                errors.append("mirror check: a mirrored case did not converge")
            elif mc["max_anchor_error_mm"] > tol_mm or mc["max_jacobian_rel_error"] > jac_tol:
                errors.append(f"mirror relation violated: anchors {mc['max_anchor_error_mm']:.2e} mm,"
                              f" Jacobian {mc['max_jacobian_rel_error']:.2e} relative")
    return {"ok": not errors, "errors": errors, "warnings": warnings, **out}


# ---------------------------------------------------------------------------- merge
def merge(out: str | Path, sources: list[str | Path]) -> dict:
    """Merge datasets of ONE campaign (same seed and config, e.g. pieces run on different
    machines with ``--units``) into ``out``: the union of their units. A unit present in
    several sources must hold the same samples (timings aside). Returns the manifest."""
    out = Path(out)
    manifests = [load_manifest(s) for s in sources]
    m0 = manifests[0]
    if "unit_size" not in (m0.get("config") or {}):
        raise ShardError(f"{sources[0]}: not a workflow.campaign dataset (no unit layout)")
    for s, m in zip(sources[1:], manifests[1:]):
        if m.get("seed") != m0.get("seed") or m.get("config") != m0.get("config"):
            raise ShardError(f"{s}: seed or config differs from {sources[0]}; cannot merge")
    if shards.manifest_path(out).is_file():
        mo = load_manifest(out)
        if mo.get("seed") != m0.get("seed") or mo.get("config") != m0.get("config"):
            raise ShardError(f"{out}: existing dataset with another seed or config")
    samples = max(int(m.get("samples_requested", 0)) for m in manifests)
    chosen: dict[int, tuple[Path, dict]] = {}
    for src in sources:
        load_dataset(src)                          # verifies every listed shard first
        for e in load_manifest(src)["shards"]:
            unit, path = int(e["unit"]), Path(src) / e["file"]
            arrays, _ = read_shard(path)
            if unit in chosen:
                prev, _ = read_shard(chosen[unit][0])
                if any(not np.array_equal(prev[k], arrays[k]) for k in REPRODUCIBLE_KEYS):
                    raise ShardError(f"unit {unit}: {chosen[unit][0]} and {path} disagree")
                continue
            chosen[unit] = (path, e)
    (out / SHARD_DIR).mkdir(parents=True, exist_ok=True)
    for unit, (path, e) in sorted(chosen.items()):
        dst = out / e["file"]
        if dst.resolve() == path.resolve():
            continue
        fd, tmp = tempfile.mkstemp(prefix=f".{dst.name}.", suffix=".tmp", dir=dst.parent)
        os.close(fd)
        shutil.copyfile(path, tmp)
        os.replace(tmp, dst)
    scanner = ShardScanner(out, samples, m0["config"], int(m0["seed"]))
    return build_manifest(out, samples, m0["config"], int(m0["seed"]), scanner.scan())


# ---------------------------------------------------------------------------- CLI
class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line on stderr with exit code 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _print_info(d: dict) -> None:
    print(f"{d['root']}: {d['samples']} samples, {d['failures']} failures "
          f"({100 * d['failure_rate']:.2f}%), {d['shards']} shards, complete={d['complete']}")
    print(f"  seed {d['seed']}; split train/val/test = {d['split']['train']}/"
          f"{d['split']['val']}/{d['split']['test']}; CPU hours {d['cpu_hours']}")
    cov = d["coverage"]
    for name, c in cov["per_input"].items():
        print(f"  {name:>2}: [{c['min']:+.4g}, {c['max']:+.4g}] of ±{c['box']:g}, "
              f"histogram {c['histogram']}")
    print(f"  grid cells occupied ({cov['grid']}): {100 * cov['cells_occupied']:.1f}%")
    if d["failure_reasons"]:
        print("  failure reasons: " + "; ".join(f"{k} x{v}" for k, v in d["failure_reasons"].items()))
    print(f"  data sha256 {d['checksums']['data_sha256']}; commits {d['git_commits']}")


def main(argv=None) -> int:
    ap = OneLineParser(prog="python -m workflow.dataset", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=OneLineParser)
    p_info = sub.add_parser("info", help="counts, coverage, failure rate, split, checksums")
    p_info.add_argument("root", help="dataset directory")
    p_ver = sub.add_parser("verify", help="check checksums, layout, data; exit 1 on problems")
    p_ver.add_argument("root", help="dataset directory")
    p_ver.add_argument("--mirror", type=int, default=0, metavar="N",
                       help="also solve the y-mirror of N stored samples with the FEM and "
                            "check the mirror relation (DESIGN.md §3); default 0")
    p_ver.add_argument("--require-complete", action="store_true",
                       help="treat an unfinished campaign as an error")
    p_mrg = sub.add_parser("merge", help="merge pieces of one campaign into OUT")
    p_mrg.add_argument("out", help="output dataset directory")
    p_mrg.add_argument("sources", nargs="+", help="dataset directories of the same campaign")
    for p in (p_info, p_ver, p_mrg):
        p.add_argument("--json", action="store_true", help="print a JSON summary")
    args = ap.parse_args(argv)
    if getattr(args, "mirror", 0) < 0:
        ap.error("--mirror must be >= 0")
    try:
        if args.cmd == "info":
            d = info(args.root)
            print(json.dumps(d, indent=1)) if args.json else _print_info(d)
            return 0
        if args.cmd == "verify":
            d = verify(args.root, mirror=args.mirror)
            if args.require_complete and any(w.startswith("incomplete") for w in d["warnings"]):
                d["ok"], d["errors"] = False, d["errors"] + ["incomplete campaign"]
            if args.json:
                print(json.dumps(d, indent=1))
            else:
                for e in d["errors"]:
                    print(f"ERROR: {e}")
                for w in d["warnings"]:
                    print(f"warning: {w}")
                if "mirror" in d:
                    print(f"mirror check: anchors {d['mirror']['max_anchor_error_mm']:.2e} mm, "
                          f"Jacobian {d['mirror']['max_jacobian_rel_error']:.2e} relative")
                print(f"{args.root}: {'OK' if d['ok'] else 'FAILED'} "
                      f"({d.get('n', 0)} samples, {d.get('failures', 0)} failures)")
            return 0 if d["ok"] else EXIT_PROBLEMS
        m = merge(args.out, args.sources)
        print(json.dumps(m, indent=1) if args.json else
              f"{args.out}: {m['samples']} samples in {m['units_done']}/{m['units_total']} units, "
              f"complete={m['complete']}")
        return 0
    except ShardError as exc:
        print(f"python -m workflow.dataset: error: {exc}", file=sys.stderr)
        return EXIT_PROBLEMS


if __name__ == "__main__":
    sys.exit(main())
