"""Atomic result files: a reader sees the old file or the new one, never half of one.

Every result (JSON, PNG, NPZ, XDMF, checkpoints) is written to a temporary name in the
target's own folder (so the rename cannot cross filesystems), flushed, fsynced and then
renamed over the target with os.replace. A killed writer leaves at most a hidden
``.NAME.*.tmp`` file, which no reader looks at. Plain Python: no dolfinx, no torch.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import tempfile
from pathlib import Path

_UMASK = os.umask(0o022)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside ``path`` (same suffix, so writers that choose the
    format by extension still work); on a clean exit it is renamed over ``path``, on an
    exception it is removed. Creates the parent folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; a result file is as open as any other
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write(path: str | Path, write) -> None:
    """Call ``write(fileobj)`` on a binary temporary file, then rename it over ``path``."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        write(f)


def write_bytes(path: str | Path, data: bytes) -> None:
    atomic_write(path, lambda f: f.write(data))


def write_text(path: str | Path, text: str) -> None:
    write_bytes(path, text.encode())


def json_safe(obj):
    """``obj`` with every non-finite float replaced by None, so that json.dumps with
    allow_nan=False writes strict JSON (NaN and Infinity are not JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy / torch scalars and arrays
        return json_safe(obj.tolist())
    return obj


def dumps(obj, indent: int | None = 1) -> str:
    """Strict JSON text of ``obj`` (non-finite floats as null)."""
    return json.dumps(json_safe(obj), indent=indent, allow_nan=False)


def write_json(path: str | Path, obj, indent: int | None = 1) -> None:
    write_text(path, dumps(obj, indent) + "\n")


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_text(path: str | Path, what: str) -> str:
    """The text of the ``what`` file at ``path`` (ValueError, one line, if it cannot be read)."""
    try:
        return Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"cannot read the {what} {path}: {getattr(exc, 'strerror', None) or exc}") from None


def strict_json(text: str, path: str | Path, what: str):
    """``text`` parsed as JSON without NaN or Infinity, which Python's json accepts and JSON
    has not (ValueError, one line, naming ``path``, the ``what`` file)."""
    def constant(c):
        raise ValueError(f"{path}: {c} in the {what}: not a number (JSON has no NaN or Infinity)")

    try:
        return json.loads(text, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None
