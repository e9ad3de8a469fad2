"""What every section of the report shares: loading an artefact through its format, the
target rows (Target, Check, judge, cells), pictures and their captions, the joint model an
artefact names, and number formatting.

``load(root, rel)`` returns the artefact ``root/rel`` checked against its format
(apps.artefacts names each file's format and make target), None when the file is not
there; a file that fails its format raises ``Malformed``, whose one line names the file,
the key path, what was expected and the make target that regenerates it (the report
shows that line in place of the section).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

from apps.artefacts import find
from contract.files import sha256_file
from contract.records import Target
from contract.joint import mesh_text

__all__ = ["Check", "MESH_REFERENCE", "Malformed", "NOT_JUDGED", "PAPER", "Target", "cells", "figure",
           "figure_grid", "joint_model", "judge", "load", "mesh_label", "missing", "num"]


class Malformed(ValueError):
    """An artefact that fails its format: the message is one line."""


def load(root: Path, rel: str) -> dict | None:
    """The artefact ``root/rel`` (a path under results/, as apps.artefacts lists it),
    checked against its format; None if there is no such file."""
    path = root / rel
    if not path.is_file():
        return None
    artefact = find(rel)
    try:
        return artefact.load(path)
    except ValueError as exc:
        raise Malformed(f"{exc}; regenerate it with `{artefact.make}`") from None


def missing(what: str, target: str) -> list[str]:
    """The line of an artefact not produced yet: what it holds and the make target."""
    return [f"_Not produced yet: run `{target}` ({what})._", ""]


#: The paper's figures that no artefact records (docs/decisions.md §0); the others are read from
#: the bench JSON (fem.json paper_*, campaign.json paper_cpu_hours, predictor.json "paper").
PAPER = {"fem_mesh_mm": 1.2, "mesh_change_percent": 3, "surrogate_nn_mm": 0.19, "surrogate_knn_mm": 1.04,
         "finger_fem": "20-30 min (ANSYS)", "predictor_speedup": "~100x"}

#: The met cell of a row that is shown beside judged ones but has no target.
NOT_JUDGED = "shown, not judged"


def figure(root: Path, rel: str, alt: str, caption: str, make: str) -> list[str]:
    """The picture ``root/rel`` linked as ``rel`` (REPORT.md sits in the results folder)
    with its one-line caption, or a line naming the make target that draws it."""
    if (root / rel).is_file():
        return [f"![{alt}]({rel})", "", f"*{caption}*", ""]
    return [f"*{alt}: (not generated yet: `{make}`)*", ""]


def figure_grid(root: Path, pictures: list[tuple[str, str]], caption: str, make: str) -> list[str]:
    """Pictures side by side in one table row, [(rel, heading), ...] (only those on disk),
    with one caption below; a line for the missing ones."""
    there = [(rel, head) for rel, head in pictures if (root / rel).is_file()]
    absent = [head for rel, head in pictures if not (root / rel).is_file()]
    out = []
    if there:
        out += ["| " + " | ".join(head for _, head in there) + " |", "|---" * len(there) + "|",
                "| " + " | ".join(f"![{head}]({rel})" for rel, head in there) + " |", "", f"*{caption}*", ""]
    if absent:
        out += [f"*{', '.join(absent)}: (not generated yet: `{make}`)*", ""]
    return out


@functools.lru_cache(maxsize=None)
def _digest(path: Path) -> str | None:
    return sha256_file(path)[:12] if path.is_file() else None


def joint_model(root: Path, name: str | None, make: str | None = None) -> str:
    """An artefact's joint model, flagged (unless ``make`` is None: a caption under a text
    that flags it) when it names a surrogate checkpoint whose file under results/surrogate/
    is now another one (the artefact predates it)."""
    if not name:
        return "unrecorded"
    if make is None:
        return f"`{name}`"
    m = re.fullmatch(r"surrogate:(.+\.pt)@([0-9a-f]{12})", name)
    now = _digest((root / "surrogate" / m[1]).resolve()) if m else None
    if now is None or now == m[2]:
        return f"`{name}`"
    return (f"`{name}` (**not** the current results/surrogate/{m[1]}, `@{now}`: "
            f"regenerate with `{make}`)")


@dataclass(frozen=True)
class Check:
    """One target row of the report: the figure, its target(s) and the verdict."""

    section: str
    figure: str
    target: str
    values: tuple
    met: bool
    verdict: str


def judge(section: str, figure: str, pairs) -> Check:
    """The Check of a row whose ``pairs`` [(Target, value), ...] must all be met."""
    misses = [m for t, v in pairs if (m := t.miss(v))]
    return Check(section, figure, ", ".join(t.text() for t, _ in pairs),
                 tuple(v for _, v in pairs), not misses, "yes" if not misses else "no, " + "; ".join(misses))


def cells(check: Check | None) -> str:
    """The target and met cells of a table row ("shown, not judged" without a target)."""
    return f" {check.target} | {check.verdict} |" if check else f" | {NOT_JUDGED} |"


MESH_REFERENCE = {"richardson": "the Richardson extrapolation", "finest mesh": "the finest mesh"}


def mesh_label(h: float, w: float | None) -> str:
    """A tetrahedral mesh as fem.studies.mesh_study names it: "H" or "H:W" (mm)."""
    return mesh_text(h, w)


def num(v, spec: str = ".4g") -> str:
    return "n/a" if v is None else format(v, spec)
