"""Joint dataset format (docs/formats.md): sharded NPZ plus a JSON manifest.

Everything here is plain numpy + json, so a dataset is readable without this project
and importing this module never imports dolfinx or torch (the surrogate depends on it).
The joint's contract (input names, units, box, mirror) is ``contract.spec``'s.

Layout of a dataset directory ``DIR``::

    DIR/manifest.json            Manifest: {"format", "seed", "config", "shards": [...], ...}
    DIR/shards/unit-00000.npz    one shard per work unit

Arrays of one shard (n stored samples, m failures, k anchors)::

    sample_id          (n,)        int64    global index of the sample in the campaign
    inputs             (n, 4)      float64  [P MPa, F1 N, F2 N, M N·mm]
    anchors            (n, k, 2)   float64  r_1..r_k in mm, joint frame
    jacobian           (n, 2k, 4)  float64  d anchors.reshape(2k) / d inputs
                                            (mm/MPa, mm/N, mm/N, mm/(N·mm)); NaN if absent
    phi_end            (n,)        float64  rad, from r_(k-1) -> r_k
    cap_rotation       (n,)        float64  rad, rotation of the distal cap itself
    newton_iterations  (n,)        int64    Newton iterations spent on the sample
    wall_time_s        (n,)        float64  s
    converged          (n,)        bool     always True: failures are never stored as data
    failed_sample_id   (m,)        int64
    failed_inputs      (m, 4)      float64
    failed_reason      (m,)        str
    meta               ()          str      JSON: config, mesh parameters, git commit, seed, unit
    checksum           ()          str      sha256 over the arrays above (see array_digest)

The anchor count k is the joint's (contract.joint ``[anchors] count``): the one its
config records (``anchor_count``: ``config["joint"]["anchors"]["count"]``; a config without
a joint is the paper's, k = contract.spec.N_ANCHORS = 10). A shard's meta carries its
config, so writing and reading a shard check its arrays against that k, and
``load_dataset`` against the manifest's.

Shards and the manifest are written atomically (``contract.files``: temporary name in the same
directory, fsync, rename), so a killed writer never leaves half a file under its name.
The manifest is validated once, when ``Manifest.load`` reads it; past that point every
field has its type (see Manifest).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from contract.files import atomic_write, sha256_file, write_text
from contract.spec import N_ANCHORS, N_INPUTS

FORMAT = "softjoint-dataset/1"
MANIFEST = "manifest.json"

DATA_KEYS = (
    "sample_id", "inputs", "anchors", "jacobian", "phi_end", "cap_rotation",
    "newton_iterations", "wall_time_s", "converged",
)
FAILURE_KEYS = ("failed_sample_id", "failed_inputs", "failed_reason")


class ShardError(ValueError):
    """A shard or manifest is missing, partial, corrupt, foreign or inconsistent."""


def anchor_count(config: dict | None) -> int:
    """Anchors k per sample of a dataset ``config`` (module docstring): its joint's
    ``anchors.count``; N_ANCHORS without a recorded joint (the paper's). ShardError (one
    line) for a recorded count that is not a whole number >= 2."""
    joint = (config or {}).get("joint")
    if joint is None:
        return N_ANCHORS
    try:
        k = joint["anchors"]["count"]
    except (KeyError, TypeError):
        raise ShardError("config: the recorded joint has no anchors.count") from None
    if isinstance(k, bool) or not isinstance(k, int) or k < 2:
        raise ShardError(f"config: the recorded joint's anchors.count = {k!r} is not a whole number >= 2")
    return k


def empty_arrays(anchors: int = N_ANCHORS) -> dict[str, np.ndarray]:
    """Zero-sample arrays with the right dtypes and trailing shapes (``anchors`` k per sample)."""
    return {
        "sample_id": np.zeros(0, np.int64),
        "inputs": np.zeros((0, N_INPUTS)),
        "anchors": np.zeros((0, anchors, 2)),
        "jacobian": np.zeros((0, 2 * anchors, N_INPUTS)),
        "phi_end": np.zeros(0),
        "cap_rotation": np.zeros(0),
        "newton_iterations": np.zeros(0, np.int64),
        "wall_time_s": np.zeros(0),
        "converged": np.zeros(0, bool),
        "failed_sample_id": np.zeros(0, np.int64),
        "failed_inputs": np.zeros((0, N_INPUTS)),
        "failed_reason": np.zeros(0, dtype="<U1"),
    }


def array_digest(arrays: dict[str, np.ndarray]) -> str:
    """sha256 over dtype, shape and bytes of every data and failure array, in fixed order."""
    h = hashlib.sha256()
    for key in DATA_KEYS + FAILURE_KEYS:
        a = np.ascontiguousarray(arrays[key])
        h.update(key.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _check_shapes(arrays: dict[str, np.ndarray], where: str, anchors: int) -> None:
    """Every array present, of n samples and ``anchors`` k anchors (module docstring)."""
    missing = [k for k in DATA_KEYS + FAILURE_KEYS if k not in arrays]
    if missing:
        raise ShardError(f"{where}: missing arrays {missing}")
    n = len(arrays["sample_id"])
    expect = {"inputs": (n, N_INPUTS), "anchors": (n, anchors, 2),
              "jacobian": (n, 2 * anchors, N_INPUTS)}
    for key in DATA_KEYS:
        shape = expect.get(key, (n,))
        if arrays[key].shape != shape:
            raise ShardError(f"{where}: '{key}' has shape {arrays[key].shape}, expected {shape}")
    m = len(arrays["failed_sample_id"])
    if arrays["failed_inputs"].shape != (m, N_INPUTS) or arrays["failed_reason"].shape != (m,):
        raise ShardError(f"{where}: failure arrays disagree in length")


def write_shard(path: str | Path, arrays: dict[str, np.ndarray], meta: dict) -> str:
    """Atomically write one shard; return the sha256 of the written file.

    ``arrays`` holds every key of DATA_KEYS and FAILURE_KEYS (see module docstring), with
    the anchor count of ``meta["config"]`` (anchor_count).
    """
    path = Path(path)
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    arrays["failed_reason"] = arrays["failed_reason"].astype(str)
    _check_shapes(arrays, str(path), anchor_count(meta.get("config")))
    if not np.all(arrays["converged"]):
        raise ShardError(f"{path}: refusing to store non-converged samples as data")
    payload = {k: arrays[k] for k in DATA_KEYS + FAILURE_KEYS}
    payload["meta"] = np.array(json.dumps(meta, sort_keys=True))
    payload["checksum"] = np.array(array_digest(payload))
    atomic_write(path, lambda f: np.savez(f, **payload))
    return sha256_file(path)


def read_shard(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read and verify one shard; return (arrays, meta). Raises ShardError if bad, also
    when its arrays do not hold the anchor count of its meta's config."""
    path = Path(path)
    if not path.is_file():
        raise ShardError(f"{path}: shard file is missing")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:  # truncated zip, bad header, not an NPZ at all, ...
        raise ShardError(f"{path}: unreadable shard ({type(exc).__name__}: {exc})") from None
    if "checksum" not in arrays or "meta" not in arrays:
        raise ShardError(f"{path}: no checksum/meta record")
    try:
        meta = json.loads(str(arrays["meta"]))
    except json.JSONDecodeError as exc:
        raise ShardError(f"{path}: corrupt meta record ({exc})") from None
    config = meta.get("config") if isinstance(meta, dict) else None
    _check_shapes(arrays, str(path), anchor_count(config if isinstance(config, dict) else None))
    if array_digest(arrays) != str(arrays.pop("checksum")):
        raise ShardError(f"{path}: checksum mismatch (corrupt shard)")
    arrays.pop("meta")
    return arrays, meta


# ---------------------------------------------------------------------------- manifest
_SHA256 = re.compile(r"^[0-9a-f]{64}$")


@dataclass(frozen=True)
class ShardEntry:
    """One shard listed in a manifest: ``file`` relative to the dataset root (POSIX), the
    sha256 of the whole file, its n stored samples; for campaign datasets also its work
    ``unit`` and its number of ``failures`` (None where the writer records none)."""

    file: str
    sha256: str
    n: int
    unit: int | None = None
    failures: int | None = None

    def to_json(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


#: Campaign figures of a manifest (workflow.campaign datasets; None for other writers).
CAMPAIGN_FIELDS = {"samples_requested": int, "units_total": int, "units_done": int,
                   "complete": bool, "samples": int, "failures": int, "cpu_hours": float,
                   "git_commits": tuple}


@dataclass(frozen=True)
class Manifest:
    """DIR/manifest.json: the dataset's seed (fixes the split), the ``config`` every shard
    was produced with, the shard list, and, for campaign datasets, the campaign figures:
    samples requested, units total/done, complete, stored samples, failures, CPU hours (sum
    of unit wall time x ranks), git commits of the writers.

    ``Manifest.load`` validates the file once; ``save`` writes it back byte for byte as
    ``json.dumps(to_json(), indent=1, sort_keys=True)``, so load -> save is the identity.
    """

    seed: int
    config: dict
    shards: tuple[ShardEntry, ...]
    samples_requested: int | None = None
    units_total: int | None = None
    units_done: int | None = None
    complete: bool | None = None
    samples: int | None = None
    failures: int | None = None
    cpu_hours: float | None = None
    git_commits: tuple[str, ...] | None = None
    format: str = FORMAT

    @staticmethod
    def path(root: str | Path) -> Path:
        return Path(root) / MANIFEST

    @classmethod
    def exists(cls, root: str | Path) -> bool:
        return cls.path(root).is_file()

    @classmethod
    def load(cls, root: str | Path) -> "Manifest":
        """The manifest of dataset ``root``. Raises ShardError (one line) if it is missing,
        not JSON, of another format, or has a missing, unknown or ill-typed field."""
        path = cls.path(root)
        if not path.is_file():
            raise ShardError(f"{root}: no {MANIFEST} (not a softjoint dataset)")
        try:
            raw = json.loads(path.read_bytes())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ShardError(f"{path}: corrupt manifest ({exc})") from None
        except OSError as exc:
            raise ShardError(f"{path}: unreadable manifest ({exc.strerror})") from None
        return cls.from_json(raw, str(path))

    @classmethod
    def from_json(cls, raw, where: str = MANIFEST) -> "Manifest":
        """Validate a decoded manifest (see ``load``)."""
        if not isinstance(raw, dict) or "format" not in raw:
            raise ShardError(f"{where}: not a softjoint dataset manifest (no 'format' record)")
        if raw.get("format") != FORMAT:
            raise ShardError(f"{where}: format {raw.get('format')!r}, expected {FORMAT!r}")
        unknown = sorted(set(raw) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise ShardError(f"{where}: unknown manifest field(s) {unknown}")
        for key in ("seed", "config", "shards"):
            if key not in raw:
                raise ShardError(f"{where}: the manifest has no '{key}'")
        _typed(raw["seed"], int, f"{where}: 'seed'")
        if not isinstance(raw["config"], dict):
            raise ShardError(f"{where}: 'config' must be an object, got {_kind(raw['config'])}")
        if not isinstance(raw["shards"], list):
            raise ShardError(f"{where}: 'shards' must be a list, got {_kind(raw['shards'])}")
        entries = tuple(_entry(e, f"{where}: shards[{i}]") for i, e in enumerate(raw["shards"]))
        files = [e.file for e in entries]
        if len(set(files)) != len(files):
            raise ShardError(f"{where}: a shard is listed twice")
        figures = {}
        for key, kind in CAMPAIGN_FIELDS.items():
            if raw.get(key) is not None:
                figures[key] = _typed(raw[key], kind, f"{where}: '{key}'")
        manifest = cls(seed=raw["seed"], config=raw["config"], shards=entries, **figures)
        manifest._check_figures(where)
        return manifest

    def _check_figures(self, where: str) -> None:
        """The stored campaign figures agree with the shard list."""
        if self.samples is not None and self.samples != self.n:
            raise ShardError(f"{where}: 'samples' {self.samples} != {self.n} listed in 'shards'")
        if self.failures is not None and self.failures != sum(e.failures or 0 for e in self.shards):
            raise ShardError(f"{where}: 'failures' disagrees with the shard list")
        if self.units_done is not None and self.units_done != len(self.shards):
            raise ShardError(f"{where}: 'units_done' {self.units_done} != {len(self.shards)} shards")
        if self.complete is not None and self.units_total is not None \
                and self.complete != (len(self.shards) == self.units_total):
            raise ShardError(f"{where}: 'complete' disagrees with units {len(self.shards)}/{self.units_total}")
        if self.is_campaign and any(e.unit is None for e in self.shards):
            raise ShardError(f"{where}: a campaign manifest lists a shard without its 'unit'")

    def to_json(self) -> dict:
        """The manifest as plain JSON types (campaign figures only where recorded)."""
        out = {"format": self.format, "seed": self.seed, "config": self.config,
               "shards": [e.to_json() for e in self.shards]}
        for key in CAMPAIGN_FIELDS:
            value = getattr(self, key)
            if value is not None:
                out[key] = list(value) if isinstance(value, tuple) else value
        return out

    def save(self, root: str | Path) -> None:
        """Atomically (re)write DIR/manifest.json."""
        write_text(self.path(root), json.dumps(self.to_json(), indent=1, sort_keys=True))

    @property
    def n(self) -> int:
        """Stored samples listed in the shard entries."""
        return sum(e.n for e in self.shards)

    @property
    def is_campaign(self) -> bool:
        """Written by workflow.campaign (its config fixes a unit layout)."""
        return "unit_size" in self.config and self.samples_requested is not None


def _kind(value) -> str:
    return "null" if value is None else type(value).__name__


def _typed(value, kind, what: str):
    """``value`` checked to be of JSON kind ``kind`` (int excludes bool; float accepts int;
    tuple accepts a list of strings) and returned as that Python type."""
    if kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
    elif kind is tuple:
        ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
        value = tuple(value) if ok else value
    else:
        ok = isinstance(value, kind)
    if not ok:
        raise ShardError(f"{what} must be {'a list of strings' if kind is tuple else f'a {kind.__name__}'}"
                         f", got {value!r:.40}")
    return value


def _entry(raw, where: str) -> ShardEntry:
    if not isinstance(raw, dict):
        raise ShardError(f"{where} must be an object, got {_kind(raw)}")
    names = {f.name for f in dataclasses.fields(ShardEntry)}
    unknown = sorted(set(raw) - names)
    if unknown:
        raise ShardError(f"{where}: unknown field(s) {unknown}")
    for key in ("file", "sha256", "n"):
        if key not in raw:
            raise ShardError(f"{where}: no '{key}'")
    file = raw["file"]
    if not isinstance(file, str) or PurePosixPath(file).is_absolute() or ".." in PurePosixPath(file).parts \
            or not file:
        raise ShardError(f"{where}: 'file' must be a path inside the dataset, got {file!r:.60}")
    if not isinstance(raw["sha256"], str) or not _SHA256.match(raw["sha256"]):
        raise ShardError(f"{where}: 'sha256' is not a sha256 hex digest")
    counts = {k: _typed(raw[k], int, f"{where}: '{k}'") for k in ("n", "unit", "failures")
              if raw.get(k) is not None}
    if any(v < 0 for v in counts.values()):
        raise ShardError(f"{where}: negative count in {counts}")
    return ShardEntry(file=file, sha256=raw["sha256"], **counts)


def dataset_digest(root: str | Path) -> str:
    """sha256 over the manifest's shard checksums: names the dataset's exact content
    without reading the shards (which load_dataset verifies against the same checksums)."""
    entries = sorted((e.file, e.sha256) for e in Manifest.load(root).shards)
    return hashlib.sha256(json.dumps(entries).encode()).hexdigest()


def load_dataset(root: str | Path) -> tuple[dict[str, np.ndarray], Manifest]:
    """Concatenate every shard listed in the manifest, sorted by sample_id.

    Verifies each file's sha256 against the manifest and each shard's own checksum, and
    that all shards were produced with the manifest's config. Returns (arrays, manifest).
    """
    root = Path(root)
    manifest = Manifest.load(root)
    config_key = json.dumps(manifest.config, sort_keys=True)
    parts = []
    for entry in manifest.shards:
        path = root / entry.file
        if not path.is_file():
            raise ShardError(f"{path}: listed in the manifest but missing")
        if sha256_file(path) != entry.sha256:
            raise ShardError(f"{path}: sha256 differs from the manifest (corrupt shard)")
        arrays, meta = read_shard(path)
        if json.dumps(meta.get("config"), sort_keys=True) != config_key:
            raise ShardError(f"{path}: shard config differs from the manifest's config")
        parts.append(arrays)
    out = empty_arrays(anchor_count(manifest.config))
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

