"""Artefact formats: the JSON a make target writes, checked by its writer and its readers.

An artefact's format is a ``Format``: a name, a version and the key paths its readers rely
on, each with its JSON type. The module that writes the artefact defines its format
(``fem/artefacts.py``, ``workflow/artefacts.py``, ``surrogate/artefacts.py``,
``predictor/artefacts.py``); the writer calls ``Format.write`` (check, then an atomic
write), and a reader calls ``Format.load`` (read, then check). A renamed or retyped key so
fails the writer's tests instead of a reader's run. Keys beyond those listed are allowed:
a format states what readers rely on, not everything a writer records.

Key paths (docs/formats.md §6):

* ``a.b.c``: key c of the object at key b of the object at key a;
* ``a[]``: every element of the list at a (``a[].b``: key b of each);
* ``a{}``: every value of the object at a (``a{}.b``: key b of each);
* ``a?``: a may be absent or null; then nothing under it is checked.

Types: ``float`` (any JSON number), ``int``, ``str``, ``bool``, ``list``, ``dict`` and
unions with None (``float | None``: a number or null; non-finite floats are written as
null, contract.files). A bool is not a number. Errors are one line: the file, the key path
and what was expected. The documents carry no format tag (the committed artefacts
predate one); ``version`` counts changes of meaning of the listed paths.

``Target`` is a figure's target ``value OP bound`` as artefacts record and the report
judges them. Standard library only.
"""

from __future__ import annotations

import json
import math
import operator
import re
import types
from dataclasses import dataclass, field
from pathlib import Path

from contract.files import json_safe, write_json

_SEGMENT = re.compile(r"(?P<key>[^.\[\]{}?]+)(?P<optional>\?)?(?P<each>(?:\[\]|\{\})*)")
_NAMES = {float: "a number", int: "an integer", str: "a string", bool: "a boolean",
          list: "a list", dict: "an object", type(None): "null"}


def _kinds(kind) -> tuple:
    """The plain types of ``kind`` (a type or a union such as ``float | None``)."""
    if isinstance(kind, types.UnionType):
        return tuple(t for k in kind.__args__ for t in _kinds(k))
    return (type(None),) if kind is None else (kind,)


def _is(value, kind: type) -> bool:
    if isinstance(value, bool):
        return kind is bool
    if kind is float:
        return isinstance(value, (int, float))
    return isinstance(value, kind)


def _found(value) -> str:
    """What a value is, for an error message: its JSON type and a short repr."""
    name = next((n for t, n in _NAMES.items() if _is(value, t)), type(value).__name__)
    text = repr(value)
    return name if isinstance(value, (list, dict)) else f"{name} {text[:40]}{'...' if len(text) > 40 else ''}"


def expected(kind) -> str:
    """The words for a key's type: 'a number or null'."""
    return " or ".join(_NAMES.get(t, t.__name__) for t in _kinds(kind))


def each(prefix: str, kind, *names: str) -> dict:
    """{"prefix.name": kind} for every name: several keys of one object with one type."""
    return {f"{prefix}.{n}" if prefix else n: kind for n in names}


def _walk(node, segments: list[str], trail: str):
    """(trail, value) of every value the key path ``segments`` reaches in ``node``;
    ValueError(trail, message) where the document does not have the path's shape."""
    if not segments:
        yield trail, node
        return
    m = _SEGMENT.fullmatch(segments[0])
    key, optional, marks = m["key"], bool(m["optional"]), re.findall(r"\[\]|\{\}", m["each"])
    if not isinstance(node, dict):
        raise ValueError(trail or "the document", f"expected an object, found {_found(node)}")
    here = f"{trail}.{key}" if trail else key
    if node.get(key) is None:
        if optional:
            return
        if key not in node:
            raise ValueError(here, "missing")
        if marks or segments[1:]:
            raise ValueError(here, "expected a value, found null")
    yield from _spread(node[key], marks, segments[1:], here)


def _spread(value, marks: list[str], rest: list[str], trail: str):
    """Walk on into every element (``[]``) or value (``{}``) the marks ask for."""
    if not marks:
        yield from _walk(value, rest, trail) if rest else [(trail, value)]
        return
    mark, more = marks[0], marks[1:]
    kind = list if mark == "[]" else dict
    if not isinstance(value, kind):
        raise ValueError(trail, f"expected {_NAMES[kind]}, found {_found(value)}")
    items = enumerate(value) if kind is list else value.items()
    for k, v in items:
        yield from _spread(v, more, rest, f"{trail}[{k}]" if kind is list else f"{trail}.{k}")


@dataclass(frozen=True)
class Format:
    """An artefact's JSON format: ``keys`` maps each key path its readers rely on to its
    type (module docstring); ``owner`` is the module that writes it."""

    name: str
    version: int
    owner: str
    keys: dict = field(default_factory=dict)

    def __post_init__(self):
        for path in self.keys:
            if not all(_SEGMENT.fullmatch(s) for s in path.split(".")):
                raise ValueError(f"format {self.name}: bad key path {path!r}")

    @property
    def tag(self) -> str:
        return f"{self.name}/{self.version}"

    def check(self, doc, where: str = "document"):
        """``doc`` (a decoded JSON object) if it has every key path with its type, else
        ValueError, one line: '<where>: <key path>: <what was expected>, found ...'."""
        for path, kind in self.keys.items():
            try:
                for trail, value in _walk(doc, path.split("."), ""):
                    if not any(_is(value, t) for t in _kinds(kind)):
                        raise ValueError(trail, f"expected {expected(kind)}, found {_found(value)}")
            except ValueError as exc:
                trail, message = exc.args if len(exc.args) == 2 else (path, str(exc))
                raise ValueError(f"{where}: {trail}: {message} (format {self.tag}, {self.owner})") from None
        return doc

    def load(self, path: str | Path) -> dict:
        """The checked document of the JSON file ``path`` (ValueError, one line, if it is
        not JSON or fails the format; OSError if it cannot be read)."""
        try:
            doc = json.loads(Path(path).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not JSON ({exc})") from None
        return self.check(doc, str(path))

    def write(self, path: str | Path, doc, indent: int | None = 1) -> None:
        """Check ``doc`` as it will be written (non-finite floats as null), then write it
        atomically (contract.files.write_json); nothing is written if the check fails."""
        self.check(json_safe(doc), str(path))
        write_json(path, doc, indent)


_OPS = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt}


@dataclass(frozen=True)
class Target:
    """A figure's target ``value OP bound``, in the artefact's units. ``scale`` turns them
    into shown units (0.94 -> 94 %); ``shown`` is the bound as the report prints it
    (default ``bound * scale`` with :g); ``key`` names the figure in its artefact where a
    producer looks it up (workflow.bench_campaign)."""

    op: str
    bound: float
    unit: str = ""
    scale: float = 1.0
    shown: str | None = None
    key: str = ""

    def met(self, value) -> bool:
        return value is not None and math.isfinite(value) and _OPS[self.op](value, self.bound)

    def text(self) -> str:
        return f"{self.op} {self.shown or format(self.bound * self.scale, 'g')} {self.unit}".strip()

    def miss(self, value) -> str | None:
        """None if met, else by how much it is missed: 'over by 237 ms' / 'short by 5 %'."""
        if self.met(value):
            return None
        if value is None or not math.isfinite(value):
            return "not measured"
        gap = abs(value - self.bound) * self.scale
        amount = f"{gap:,.0f}" if gap >= 100 else f"{gap:.3g}"
        return f"{'over' if self.op.startswith('<') else 'short'} by {amount} {self.unit}".strip()
