"""Joint dataset format (DESIGN.md §5): sharded NPZ plus a JSON manifest.

Everything here is plain numpy + json, so a dataset is readable without this project
and importing this module never imports dolfinx (the surrogate depends on it).

Layout of a dataset directory ``DIR``::

    DIR/manifest.json            {"format", "seed", "config", "shards": [...]}
    DIR/shards/unit-00000.npz    one shard per work unit

Arrays of one shard (n stored samples, m failures)::

    sample_id          (n,)        int64    global index of the sample in the campaign
    inputs             (n, 4)      float64  [P MPa, F1 N, F2 N, M N·mm]
    anchors            (n, 10, 2)  float64  r_1..r_10 in mm, joint frame
    jacobian           (n, 20, 4)  float64  d anchors.reshape(20) / d inputs
                                            (mm/MPa, mm/N, mm/N, mm/(N·mm)); NaN if absent
    phi_end            (n,)        float64  rad, from r_9 -> r_10
    cap_rotation       (n,)        float64  rad, rotation of the distal cap itself
    newton_iterations  (n,)        int64    Newton iterations spent on the sample
    wall_time_s        (n,)        float64  s
    converged          (n,)        bool     always True: failures are never stored as data
    failed_sample_id   (m,)        int64
    failed_inputs      (m, 4)      float64
    failed_reason      (m,)        str
    meta               ()          str      JSON: config, mesh parameters, git commit, seed, unit
    checksum           ()          str      sha256 over the arrays above (see _array_digest)

Shards are written to a temporary name in the same directory, fsynced and renamed, so a
killed writer never leaves half a shard under the final name.

Mirror symmetry y -> -y (DESIGN.md §3): (R, P, F1, F2, M) -> (R·diag(1,-1), -P, F1, -F2, -M).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

FORMAT = "softjoint-dataset/1"
N_ANCHORS = 10
N_INPUTS = 4
INPUT_NAMES = ("P", "F1", "F2", "M")
INPUT_UNITS = ("MPa", "N", "N", "N*mm")
#: Half-widths of the training box (DESIGN.md §3): |P|<=0.3, |F1|,|F2|<=3, |M|<=100.
INPUT_BOX = np.array([0.3, 3.0, 3.0, 100.0])

DATA_KEYS = (
    "sample_id", "inputs", "anchors", "jacobian", "phi_end", "cap_rotation",
    "newton_iterations", "wall_time_s", "converged",
)
FAILURE_KEYS = ("failed_sample_id", "failed_inputs", "failed_reason")
#: Input sign flips and anchor sign flips of the y-mirror.
INPUT_MIRROR = np.array([-1.0, 1.0, -1.0, -1.0])
ANCHOR_MIRROR = np.array([1.0, -1.0])


class ShardError(ValueError):
    """A shard or manifest is missing, partial, corrupt or inconsistent."""


def empty_arrays() -> dict[str, np.ndarray]:
    """Zero-sample arrays with the right dtypes and trailing shapes."""
    return {
        "sample_id": np.zeros(0, np.int64),
        "inputs": np.zeros((0, N_INPUTS)),
        "anchors": np.zeros((0, N_ANCHORS, 2)),
        "jacobian": np.zeros((0, 2 * N_ANCHORS, N_INPUTS)),
        "phi_end": np.zeros(0),
        "cap_rotation": np.zeros(0),
        "newton_iterations": np.zeros(0, np.int64),
        "wall_time_s": np.zeros(0),
        "converged": np.zeros(0, bool),
        "failed_sample_id": np.zeros(0, np.int64),
        "failed_inputs": np.zeros((0, N_INPUTS)),
        "failed_reason": np.zeros(0, dtype="<U1"),
    }


def _array_digest(arrays: dict[str, np.ndarray]) -> str:
    """sha256 over dtype, shape and bytes of every data and failure array, in fixed order."""
    h = hashlib.sha256()
    for key in DATA_KEYS + FAILURE_KEYS:
        a = np.ascontiguousarray(arrays[key])
        h.update(key.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _check_shapes(arrays: dict[str, np.ndarray], where: str) -> None:
    missing = [k for k in DATA_KEYS + FAILURE_KEYS if k not in arrays]
    if missing:
        raise ShardError(f"{where}: missing arrays {missing}")
    n = len(arrays["sample_id"])
    expect = {"inputs": (n, N_INPUTS), "anchors": (n, N_ANCHORS, 2),
              "jacobian": (n, 2 * N_ANCHORS, N_INPUTS)}
    for key in DATA_KEYS:
        shape = expect.get(key, (n,))
        if arrays[key].shape != shape:
            raise ShardError(f"{where}: '{key}' has shape {arrays[key].shape}, expected {shape}")
    m = len(arrays["failed_sample_id"])
    if arrays["failed_inputs"].shape != (m, N_INPUTS) or arrays["failed_reason"].shape != (m,):
        raise ShardError(f"{where}: failure arrays disagree in length")


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _atomic_write(path: Path, write) -> None:
    """Call write(fileobj) on a temp file beside ``path``, fsync, then rename over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_shard(path: str | Path, arrays: dict[str, np.ndarray], meta: dict) -> str:
    """Atomically write one shard; return the sha256 of the written file.

    ``arrays`` holds every key of DATA_KEYS and FAILURE_KEYS (see module docstring).
    """
    path = Path(path)
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    arrays["failed_reason"] = arrays["failed_reason"].astype(str)
    _check_shapes(arrays, str(path))
    if not np.all(arrays["converged"]):
        raise ShardError(f"{path}: refusing to store non-converged samples as data")
    payload = {k: arrays[k] for k in DATA_KEYS + FAILURE_KEYS}
    payload["meta"] = np.array(json.dumps(meta, sort_keys=True))
    payload["checksum"] = np.array(_array_digest(payload))
    _atomic_write(path, lambda f: np.savez(f, **payload))
    return file_sha256(path)


def read_shard(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read and verify one shard; return (arrays, meta). Raises ShardError if bad."""
    path = Path(path)
    if not path.is_file():
        raise ShardError(f"{path}: shard file is missing")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:  # truncated zip, bad header, ...
        raise ShardError(f"{path}: unreadable shard ({type(exc).__name__}: {exc})") from None
    _check_shapes(arrays, str(path))
    if "checksum" not in arrays or "meta" not in arrays:
        raise ShardError(f"{path}: no checksum/meta record")
    if _array_digest(arrays) != str(arrays.pop("checksum")):
        raise ShardError(f"{path}: checksum mismatch (corrupt shard)")
    meta = json.loads(str(arrays.pop("meta")))
    return arrays, meta


def manifest_path(root: str | Path) -> Path:
    return Path(root) / "manifest.json"


def load_manifest(root: str | Path) -> dict:
    """The manifest of dataset ``root``; raises ShardError if absent or unreadable."""
    path = manifest_path(root)
    if not path.is_file():
        raise ShardError(f"{root}: no manifest.json (not a softjoint dataset)")
    try:
        manifest = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ShardError(f"{path}: corrupt manifest ({exc})") from None
    if manifest.get("format") != FORMAT:
        raise ShardError(f"{path}: format {manifest.get('format')!r}, expected {FORMAT!r}")
    return manifest


def write_manifest(root: str | Path, manifest: dict) -> None:
    """Atomically (re)write the manifest of dataset ``root``."""
    manifest = {**manifest, "format": FORMAT}
    text = json.dumps(manifest, indent=1, sort_keys=True).encode()
    _atomic_write(manifest_path(root), lambda f: f.write(text))


def dataset_digest(root: str | Path) -> str:
    """sha256 over the manifest's shard checksums: names the dataset's exact content
    without reading the shards (which load_dataset verifies against the same checksums)."""
    entries = sorted((e["file"], e["sha256"]) for e in load_manifest(root)["shards"])
    return hashlib.sha256(json.dumps(entries).encode()).hexdigest()


def load_dataset(root: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Concatenate every shard listed in the manifest, sorted by sample_id.

    Verifies each file's sha256 against the manifest and each shard's own checksum, and
    that all shards were produced with the manifest's config. Returns (arrays, manifest).
    """
    root = Path(root)
    manifest = load_manifest(root)
    config_key = json.dumps(manifest.get("config"), sort_keys=True)
    parts = []
    for entry in manifest["shards"]:
        path = root / entry["file"]
        if not path.is_file():
            raise ShardError(f"{path}: listed in the manifest but missing")
        if file_sha256(path) != entry["sha256"]:
            raise ShardError(f"{path}: sha256 differs from the manifest (corrupt shard)")
        arrays, meta = read_shard(path)
        if json.dumps(meta.get("config"), sort_keys=True) != config_key:
            raise ShardError(f"{path}: shard config differs from the manifest's config")
        parts.append(arrays)
    out = empty_arrays()
    if parts:
        out = {k: np.concatenate([p[k] for p in parts]) for k in out}
    order = np.argsort(out["sample_id"], kind="stable")
    for k in DATA_KEYS:
        out[k] = out[k][order]
    if len(np.unique(out["sample_id"])) != len(out["sample_id"]):
        raise ShardError(f"{root}: duplicated sample ids across shards")
    return out, manifest


#: Samples per split block. Consecutive ids are consecutive points of one continuation walk,
#: 0.1 of the box apart, so a split per sample would put nearly every validation and test
#: sample next to a training neighbour: validation would reward memorising (a KNN chose
#: k = 2 and looked 5x better on it than on the held-out walks). A block of 16 spans 1.6
#: box half-widths of walk; 16 divides the units of both datasets (64 and 16 samples).
SPLIT_BLOCK = 16


def split_of(sample_id: np.ndarray, seed: int, counts=(7, 2, 1),
             block: int = SPLIT_BLOCK) -> np.ndarray:
    """Split label 0 (train), 1 (validation), 2 (test) for each sample id, fixed by seed.

    Ids go in blocks of ``block`` consecutive ids (id // block), so whole stretches of a
    walk fall in one split, and blocks in groups of sum(counts) = 10: in each group a
    permutation drawn from default_rng([seed, group]) deals counts[k] blocks to split k.
    So every complete group splits exactly 7:2:1 (2,560 samples: 1792/512/256), and a
    sample's split never changes when the dataset grows. Shapes: (n,) -> (n,) int.
    """
    blocks = np.asarray(sample_id, np.int64) // block
    per_group = sum(counts)
    deal = np.repeat(np.arange(len(counts)), counts)
    groups, inverse = np.unique(blocks // per_group, return_inverse=True)
    table = np.array([np.random.default_rng([seed, int(g)]).permutation(deal) for g in groups],
                     np.int64).reshape(-1, per_group)
    return table[inverse, blocks % per_group].astype(np.int64)


def mirror(inputs: np.ndarray, anchors: np.ndarray, jacobian: np.ndarray | None = None):
    """Apply the y-mirror (DESIGN.md §3) to a batch.

    inputs (n, 4), anchors (n, 10, 2), jacobian (n, 20, 4) or None -> same shapes.
    The Jacobian transforms as S·J·B with S = diag(1,-1,...) on the 20 anchor coordinates
    and B = diag(-1, 1, -1, -1) on the inputs (B is its own inverse).
    """
    inputs_m = inputs * INPUT_MIRROR
    anchors_m = anchors * ANCHOR_MIRROR
    if jacobian is None:
        return inputs_m, anchors_m, None
    s = np.tile(ANCHOR_MIRROR, N_ANCHORS)
    return inputs_m, anchors_m, jacobian * s[:, None] * INPUT_MIRROR[None, :]
