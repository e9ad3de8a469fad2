"""Integrity-checked checkpoint files (docs/formats.md), for the surrogate and the NN predictors.

A checkpoint file is one header line followed by a standard ``torch.save`` archive::

    {"bytes":N,"format":"softjoint-surrogate/2","sha256":"<64 hex>"}\\n  <N bytes: torch.save(payload)>

- ``format`` names the kind of payload (surrogate, gravity or contact NN predictor), so a
  foreign file, or a checkpoint of another kind, is refused by name;
- ``sha256`` and ``bytes`` cover the archive byte for byte, and the header must re-serialise
  to exactly itself, so a flipped, missing or added byte anywhere in the file is refused:
  nothing damaged loads, not even a byte the archive reader would ignore;
- the payload is a dict of tensors and plain types, loaded with ``weights_only=True``
  (no pickled code runs);
- files are written atomically (contract.files.atomic_path).

Outside this project: ``torch.load(io.BytesIO(data.split(b"\\n", 1)[1]), weights_only=True)``.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import torch

from contract.files import atomic_write

MAX_HEADER = 512  # bytes; a header is ~120


class CheckpointError(ValueError):
    """A checkpoint file is missing, damaged, foreign, or of another kind (one-line message)."""


def _header(fmt: str, body: bytes) -> bytes:
    return json.dumps({"bytes": len(body), "format": fmt, "sha256": hashlib.sha256(body).hexdigest()},
                      sort_keys=True, separators=(",", ":")).encode() + b"\n"


def save(path: str | Path, fmt: str, payload: dict) -> None:
    """Write ``payload`` (tensors and plain types only) as a checkpoint of kind ``fmt``."""
    buf = io.BytesIO()
    torch.save(payload, buf)
    body = buf.getvalue()
    atomic_write(path, lambda f: f.write(_header(fmt, body) + body))


def load(path: str | Path, fmt: str, what: str = "checkpoint") -> dict:
    """The payload dict of checkpoint ``path`` of kind ``fmt``; raises CheckpointError.

    ``what`` names the file's role in the messages ("surrogate checkpoint", ...).
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: {what} not found")
    data = path.read_bytes()
    line, sep, body = data[:MAX_HEADER].partition(b"\n")
    body = data[len(line) + 1:] if sep else b""
    try:
        header = json.loads(line.decode("ascii"))
        found = header.get("format") if isinstance(header, dict) else None
    except (UnicodeDecodeError, json.JSONDecodeError):
        header = found = None
    if not sep or not isinstance(header, dict) or not str(found).startswith("softjoint-"):
        raise CheckpointError(f"{path}: not a softjoint {what} (no valid checkpoint header; "
                              f"an old-format or foreign file?)")
    if found != fmt:
        raise CheckpointError(f"{path}: a {found!r} file, expected a {fmt!r} {what}")
    if line + b"\n" != _header(fmt, body):
        raise CheckpointError(f"{path}: damaged {what} (checksum or length mismatch)")
    try:
        payload = torch.load(io.BytesIO(body), map_location="cpu", weights_only=True)
    except Exception as exc:  # unreachable for intact files; a failing torch is still one line
        raise CheckpointError(f"{path}: unreadable {what} ({type(exc).__name__})") from None
    if not isinstance(payload, dict):
        raise CheckpointError(f"{path}: {what} payload is a {type(payload).__name__}, not a dict")
    return payload
