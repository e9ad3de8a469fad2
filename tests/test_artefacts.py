"""Each artefact owns its format (contract.records, */artefacts.py, apps.artefacts).

- Every committed JSON under results/ is an artefact the catalogue knows, and loads
  through its format.
- A writer refuses a document with a renamed key: one line naming the file, the key path
  and the format, and nothing is written (for every committed artefact, the deepest key
  its format requires through objects renamed, e.g. details.contact_nn_vs_solver.
  reference_converged of bench/predictor.json).
- The key paths mean what contract.records says: nested lists and objects, optional keys,
  nullable numbers, a bool is not a number, an int is a number but a float not an int.
"""

from __future__ import annotations

import copy
import json
import re
import subprocess
from pathlib import Path

import pytest

from apps.artefacts import ARTEFACTS, find
from contract.records import Format

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"


def _committed() -> list[str]:
    out = subprocess.run(["git", "ls-files", "results/*.json", "results/**/*.json"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout.split()
    return sorted({str(Path(p).relative_to("results")) for p in out if (ROOT / p).is_file()})


COMMITTED = _committed()


#: Catalogued artefacts of long runs not finished yet: the finger FEM over the pressure box
#: (make finger-grid) and the FEM grasps (make grasp-fem; the first of 16 cases committed),
#: hours each on the production mesh, and the grasp validation that reads them (make
#: validate-grasps). Their formats are checked by tests/test_finger_grid.py,
#: test_grasp_cases.py and test_validate_grasps.py on hand-made or coarse records.
#: Likewise the failed samples' stability probe (make failed-samples) while it runs.
PENDING = {"fem/finger_grid.json", "validation/grasps_fem/*.json", "validation/grasps.json",
           "fem/stability_*.json"}


def test_every_committed_json_is_a_known_artefact():
    assert len(COMMITTED) >= 60, COMMITTED           # 67 at the time of writing
    # every catalogue entry has a committed file (or is pending), so every format is checked below
    committed = {find(rel).pattern for rel in COMMITTED}
    assert committed | PENDING == {a.pattern for a in ARTEFACTS}
    with pytest.raises(ValueError, match="not an artefact the project writes"):
        find("fem/unknown.json")


@pytest.mark.parametrize("rel", COMMITTED)
def test_committed_artefact_loads_through_its_format(rel):
    doc = find(rel).load(RESULTS / rel)
    assert isinstance(doc, dict) and doc


def _required_path(fmt: Format) -> list[str]:
    """The keys of the first path the format requires through objects only (no '?', '[]'
    or '{}'), deepest first listed: e.g. ["required", "cantilever"]."""
    plain = [p.split(".") for p in fmt.keys if all(s.isidentifier() for s in p.split("."))]
    return max(plain, key=len)


@pytest.mark.parametrize("rel", [r for r in COMMITTED if find(r).format is not None])
def test_writer_refuses_a_renamed_key(rel, tmp_path):
    fmt = find(rel).format
    doc = json.loads((RESULTS / rel).read_text())
    *parents, key = _required_path(fmt)
    bad = copy.deepcopy(doc)
    node = bad
    for k in parents:
        node = node[k]
    node[key + "_renamed"] = node.pop(key)
    out = tmp_path / "x.json"
    with pytest.raises(ValueError) as err:
        fmt.write(out, bad)
    message = str(err.value)
    assert "\n" not in message
    assert message == f"{out}: {'.'.join([*parents, key])}: missing (format {fmt.tag}, {fmt.owner})", message
    assert not list(tmp_path.iterdir())              # nothing written, no temporary file left
    fmt.write(out, doc)                              # the committed document itself is accepted
    assert json.loads(out.read_text()) == doc


FMT = Format("t", 2, "tests", {"a.b": float, "c[].d": int | None, "e?{}.f": str, "g": float | None,
                              "h?[].i?": bool})


@pytest.mark.parametrize("doc,error", [
    ({"a": {"b": 1}, "c": [{"d": None}, {"d": 2}], "g": None}, None),
    ({"a": {"b": 1.5}, "c": [], "g": 3, "e": {"x": {"f": "s"}}, "h": [{}, {"i": True}]}, None),
    ({"a": {"b": True}, "c": [], "g": 1}, "a.b: expected a number, found a boolean True"),
    ({"a": {}, "c": [], "g": 1}, "a.b: missing"),
    ({"a": {"b": 1}, "c": [{"d": 1}, {"d": 1.5}], "g": 1}, "c[1].d: expected an integer or null, found a number 1.5"),
    ({"a": {"b": 1}, "c": [], "g": 1, "e": {"k": {"f": 3}}}, "e.k.f: expected a string, found a number 3"),
    ({"a": {"b": 1}, "c": {}, "g": 1}, "c: expected a list, found an object"),
    ({"a": [], "c": [], "g": 1}, "a: expected an object, found a list"),
    ({"a": {"b": 1}, "c": None, "g": 1}, "c: expected a value, found null"),
    ({"a": {"b": 1}, "c": [], "g": "1"}, "g: expected a number or null, found a string '1'"),
])
def test_key_paths(doc, error):
    if error is None:
        assert FMT.check(doc) is doc
    else:
        with pytest.raises(ValueError, match=re.escape(f"f.json: {error} (format t/2, tests)") + "$"):
            FMT.check(doc, "f.json")


def test_a_bad_key_path_is_refused_when_the_format_is_defined():
    with pytest.raises(ValueError, match="bad key path 'a..b'"):
        Format("t", 1, "tests", {"a..b": float})


def test_load_names_a_file_that_is_not_json(tmp_path):
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"x\.json: not JSON"):
        FMT.load(tmp_path / "x.json")


def test_a_writer_command_refuses_a_renamed_key_and_writes_nothing(tmp_path, monkeypatch, capsys):
    """workflow.dataset compare --out, its comparison renamed (tip_mm -> tip) as a writer
    with a stale key would produce it: exit 2, one line naming the output file, the key and
    the format, and no file; the same comparison unrenamed is written and loads back."""
    from workflow import dataset, store

    doc = json.loads((RESULTS / "fem/heldout_mesh.json").read_text())
    renamed = {("tip" if k == "tip_mm" else k): v for k, v in doc.items()}
    out = tmp_path / "cmp.json"
    monkeypatch.setattr(store, "compare", lambda ref, other: renamed)
    with pytest.raises(SystemExit) as exit_:
        dataset.main(["compare", "a", "b", "--out", str(out)])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert exit_.value.code == 2 and len(err) == 1, err
    assert f"{out}: tip_mm: missing (format workflow-mesh-comparison/1, workflow.dataset)" in err[0]
    assert not list(tmp_path.iterdir())
    monkeypatch.setattr(store, "compare", lambda ref, other: doc)
    assert dataset.main(["compare", "a", "b", "--out", str(out), "--json"]) == 0
    assert find("fem/heldout_mesh.json").load(out) == doc


def test_bench_fem_format_takes_a_hexahedral_discretisation():
    """fem.studies.bench_joint --mesh hexN writes mesh_info's keys of a hexahedral mesh (divisions,
    no mesh_size): the format accepts them, and still needs one of the timings."""
    from fem.artefacts import BENCH_JOINT

    doc = json.loads((RESULTS / "bench/fem.json").read_text())
    hexdoc = {k: v for k, v in doc.items() if k != "mesh_size"} | {
        "mesh": "hex2", "divisions": 2, "formulation": "mixed", "continuation_sample_cpu_s": 9.5}
    assert BENCH_JOINT.check(hexdoc) is hexdoc
    with pytest.raises(ValueError, match="continuation_sample_s: missing"):
        BENCH_JOINT.check({k: v for k, v in hexdoc.items() if k != "continuation_sample_s"})
