"""The FEM records the validations compare against, read alike by each of them
(predictor.validation.finger: fem.studies.finger_cases records; predictor.validation.grasps:
fem.studies.grasp_cases records): which problem a record was solved for (the plane X = 0
where the mirror fingers meet, or one finger alone) and on which discretisation (its mesh
text, "H" or "H:W" tetrahedra in mm, "hexN" or "hexN:S" hexahedra, and its formulation).

Data flow: records (dicts, fem.artefacts' formats) -> ``split_cases`` (the validated
discretisation's and the others) -> ``one_problem`` (the cases of the problem asked for,
or a one-line ValueError when none is) -> the validation's comparison.
"""
from __future__ import annotations

import argparse
from typing import Callable

from contract import cli
from contract.joint import MAX_DIVISIONS, mesh_text
from fem.artefacts import finger_case_formulation, finger_case_mesh
from predictor.solvers.problem import problem_words


def case_plane(case: dict) -> bool:
    """Whether a fem.studies.finger_cases record was solved with the plane X = 0 where the mirror
    fingers meet (its settings' ``plane``; absent: a single finger without it)."""
    return bool(case.get("settings", {}).get("plane", False))


def mesh_arg(text: str) -> str:
    """argparse type of ``--mesh``: "H" or "H:W" (tetrahedra, mm), "hexN" or "hexN:S"
    (hexahedra), returned in contract.joint.mesh_text's spelling (the records')."""
    size, count = cli.number(0.05, 50, "mm", open_lo=True), cli.number(1, MAX_DIVISIONS, integer=True)
    text = text.strip()
    a, _, b = text[3:].partition(":") if text.startswith("hex") else text.partition(":")
    try:
        if text.startswith("hex"):
            return mesh_text(None, None, count(a), size(b) if b else None)
        return mesh_text(size(a), size(b) if b else None)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc} (a mesh is H or H:W in mm, or hexN or hexN:S)") from None


def split_cases(cases: list[dict], validated: tuple[str, str]) -> tuple[list[dict], list[dict]]:
    """(the fem.studies.finger_cases records on the discretisation ``validated``, (mesh text,
    formulation); the others, for the mesh check)."""
    on = [(finger_case_mesh(c), finger_case_formulation(c)) == tuple(validated) for c in cases]
    return [c for c, o in zip(cases, on) if o], [c for c, o in zip(cases, on) if not o]


def one_problem(cases: list[dict], plane: bool | None, where: str,
                plane_of: Callable[[dict], bool] | None = None) -> tuple[list[dict], bool | None]:
    """(the cases validated, their problem) among ``cases`` (fem.studies.finger_cases or
    fem.studies.grasp_cases records): with ``plane`` None all of them, each against the predictor
    of its own problem, and their problem (True: the plane X = 0; None when they mix both);
    else those of ``plane``. ValueError (one line) when none is of the ``plane`` asked for
    (the comparison asked for would be of different problems); ``where``: the cases in
    words; ``plane_of``: a case's problem (default ``case_plane``; fem.studies.grasp_cases
    records: their ``plane``)."""
    plane_of = plane_of or case_plane
    kinds = {bool(plane_of(c)) for c in cases}
    if plane is None:
        return cases, kinds.pop() if len(kinds) == 1 else None
    chosen = [c for c in cases if plane_of(c) == plane]
    if cases and not chosen:
        raise ValueError(f"{where} were all solved for {problem_words(not plane)}, the predictor was asked for "
                         f"{problem_words(plane)}: different problems, not compared")
    return chosen, plane
