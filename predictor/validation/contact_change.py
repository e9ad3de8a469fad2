"""What a change of the predictor's model changed in its committed artefacts: the atlases'
grasp states, the reference ramps' failures and the paper's gestures, before against after
(issue 36: the contact on the finger's outline and the plane X = 0 where the fingers meet).

    python -m predictor.validation.contact_change --before DIR --label TEXT [--after results/predictor]
        [--out results/predictor/contact_change.json] [--json]

DIR and --after each hold a predictor results folder: atlas_<object>.json (the sweep),
ramp/ and ramp_fine/atlas_<object>.json (the reference ramps) and gestures.json, e.g. the
model before as ``git archive <commit> results/predictor`` unpacked; --label names it (its
commit and model). Compared, for every object whose atlases exist on both sides:

* ``atlas``: the points (same grid, same object kind) whose grasp state differs, with each
  transition counted ('holds -> slips'), and both sides' state counts;
* ``reference`` and ``reference_fine``: the ramp references' not-converged points before and
  after, with their sub-step counts;
* ``gestures``: per gesture of gestures.json (gravity, free, the grasps per object; matched
  by group, object and pressures, MPa) the state before and after and how far the fingertip
  moved (mm; null unless both converged).

Reads JSON only (each file through its format, predictor.artefacts); a missing file leaves
its entry out, two atlases of different grids or objects are a one-line ValueError.
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

from contract import cli
from predictor.artefacts import ATLAS, CONTACT_CHANGE, GESTURES

OBJECTS = ("circle", "ellipse", "rectangle")
REFERENCES = (("reference", "ramp"), ("reference_fine", "ramp_fine"))


def _load(fmt, path: Path) -> dict | None:
    return fmt.load(path) if path.is_file() else None


def _states(atlas: dict) -> list[str]:
    """The atlas' grid of state names, row by row."""
    return [atlas["states"][code] for row in atlas["state"] for code in row]


def atlas_change(before: dict, after: dict) -> dict:
    """Points whose state differs between two atlases of one object and grid, and how
    (``transitions``: 'before -> after' counts), with both sides' state counts."""
    if before["grid"] != after["grid"] or (before.get("object") or {}).get("kind") != (after.get("object") or {}).get(
            "kind") or before["p1_MPa"] != after["p1_MPa"] or before["p2_MPa"] != after["p2_MPa"]:
        raise ValueError("the two atlases are of different grids or objects")
    pairs = [(u, v) for u, v in zip(_states(before), _states(after)) if u != v]
    return {"points": len(before["state"]) * len(before["state"][0]), "changed": len(pairs),
            "transitions": dict(sorted(Counter(f"{u} -> {v}" for u, v in pairs).items())),
            "counts_before": before["counts"], "counts_after": after["counts"]}


def failures(before: dict, after: dict) -> dict:
    """A reference ramp's not-converged points before and after, and its sub-steps (files
    without ``ramp_steps`` used the solver's default, 12)."""
    return {"points": len(after["state"]) * len(after["state"][0]),
            "ramp_steps_before": before.get("ramp_steps", 12), "ramp_steps_after": after.get("ramp_steps", 12),
            "not_converged_before": before["counts"]["not_converged"],
            "not_converged_after": after["counts"]["not_converged"]}


def _gestures(doc: dict) -> list[tuple[str, str | None, dict]]:
    """(group, object or None, gesture summary) of every gesture of a gestures.json."""
    out = [(group, None, g) for group in ("gravity", "free") for g in doc[group]]
    return out + [("grasps", kind, g) for kind, items in doc["grasps"].items() for g in items]


def gesture_shifts(before: dict, after: dict) -> list[dict]:
    """Per gesture on both sides (same group, object and pressures): the state before and
    after (``converged`` when the file has no state: a free gesture) and the tip's shift, mm
    (null unless both converged)."""
    old = {(grp, kind, tuple(g["pressures_MPa"])): g for grp, kind, g in _gestures(before)}
    out = []
    for grp, kind, g in _gestures(after):
        b = old.get((grp, kind, tuple(g["pressures_MPa"])))
        if b is None:
            continue
        shift = math.dist(b["tip"], g["tip"]) if b["tip"] is not None and g["tip"] is not None else None
        state = lambda s: s.get("state", "converged" if s["converged"] else "not_converged")  # noqa: E731
        out.append({"group": grp, "object": kind, "pressures_MPa": g["pressures_MPa"], "state_before": state(b),
                    "state_after": state(g), "tip_before": b["tip"], "tip_after": g["tip"], "tip_shift_mm": shift,
                    "plane_overlap_mm": g.get("plane_overlap_mm")})
    return out


def compare(before: Path, after: Path, label: str) -> dict:
    """The contact_change document (module docstring) of two predictor results folders."""
    doc = {"before": label, "atlas": {}, "reference": {}, "reference_fine": {}, "gestures": []}
    for kind in OBJECTS:
        name = f"atlas_{kind}.json"
        pair = [_load(ATLAS, d / name) for d in (before, after)]
        if all(pair):
            doc["atlas"][kind] = atlas_change(*pair)
        for key, folder in REFERENCES:
            pair = [_load(ATLAS, d / folder / name) for d in (before, after)]
            if all(pair):
                doc[key][kind] = failures(*pair)
    pair = [_load(GESTURES, d / "gestures.json") for d in (before, after)]
    if all(pair):
        doc["gestures"] = gesture_shifts(*pair)
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = cli.Parser(prog="python -m predictor.validation.contact_change", description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", required=True, help="the predictor results folder of the model before")
    ap.add_argument("--label", required=True, help="what the model before is (its commit and model)")
    ap.add_argument("--after", default="results/predictor", help="the predictor results folder of today's model")
    ap.add_output("--out", suffix=".json", help="write the JSON here")
    args = ap.parse_args(argv)
    for folder in (args.before, args.after):
        if not Path(folder, "gestures.json").is_file() and not any(Path(folder).glob("atlas_*.json")):
            ap.error(f"{folder}: no predictor results (atlas_<object>.json or gestures.json) there")
    with ap.errors():
        doc = compare(Path(args.before), Path(args.after), args.label)
        if args.out:
            CONTACT_CHANGE.write(args.out, doc)
    if args.json:
        cli.print_json(doc)
    else:
        for kind, a in doc["atlas"].items():
            print(f"{kind}: {a['changed']} of {a['points']} atlas points changed state")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
