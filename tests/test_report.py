"""apps.report (results/REPORT.md): pictures, tables and sources, on JSON only (no solve,
no training; a second or two).

- On the committed results/: every linked picture or file exists, every table row has its
  header's number of cells and no empty met cell, no heading repeats within its section,
  and nothing is read from the retired results/surrogate/cap/.
- On an empty or partial results folder the report still builds, naming the make target
  of every missing picture instead of linking it.
- The finger section takes the judged variant from finger.json, and the surrogate's cap
  rotation (mean, p95, held-out) and the tangent assumption's error from metrics.json.
- An artefact that fails its format is named in one line (file, key, make target) in
  place of its section; the other sections are unchanged.
- ``python -m apps.report`` reproduces the committed REPORT.md byte for byte.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from apps import report as report_app
from apps.report.__main__ import main as report_main

RESULTS = Path(__file__).resolve().parents[1] / "results"
LINK = re.compile(r"\]\(([^)#\s][^)\s]*)\)")   # a file link (not an anchor in the report)
committed = pytest.mark.skipif(not (RESULTS / "validation/finger.json").is_file()
                               or not (RESULTS / "surrogate/metrics.json").is_file(),
                               reason="no committed finger validation / surrogate metrics")


def _cells(line: str) -> list[str]:
    """The cells of a Markdown table row (escaped pipes stay inside their cell)."""
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]


def _tables(text: str):
    """(header cells, [row cells, ...]) of every table in ``text``."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("|") and i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            if i > 0 and lines[i - 1].strip():
                raise AssertionError(f"table without a blank line before it: {line[:60]}")
            rows = []
            for row in lines[i + 2:]:
                if not row.startswith("|"):
                    break
                rows.append(_cells(row))
            yield _cells(line), rows


@committed
def test_committed_report_links_tables_and_sources():
    text, sections, checks = report_app.build(RESULTS)
    assert len(sections) == len(set(sections)) == len(report_app.SECTIONS)
    for part in text.split("\n## ")[1:]:
        subs = [ln for ln in part.splitlines() if ln.startswith("### ")]
        assert len(subs) == len(set(subs)), subs
    links = LINK.findall(text)
    headings = {report_app.anchor(ln.lstrip("#").strip()) for ln in text.splitlines() if ln.startswith("#")}
    assert set(re.findall(r"\]\((#[^)\s]+)\)", text)) <= headings   # each anchor link lands on a heading
    missing = [p for p in links if not (RESULTS / p).is_file()]
    assert not missing, missing
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    for must in ("fem/joint.png", "surrogate/comparison.png", "predictor/nn_training.png",
                 "predictor/grasps.png", "predictor/gravity.png"):
        assert must in images or not (RESULTS / must).is_file(), must
    # the production validation's paper gravity case and its most bent free case (more as
    # make finger-grid's cases are validated)
    assert sum(p.startswith("validation/finger_") for p in images) >= 2
    for header, rows in _tables(text):
        for row in rows:
            assert len(row) == len(header), (header, row)
            if header[-1] == "met":
                assert row[-1], (header, row)   # judged, or "shown, not judged"
    assert "surrogate/cap/" not in text and "cap/metrics.json" not in text
    assert checks and all(c.verdict for c in checks)


@committed
def test_finger_judged_variant_and_cap_figures_come_from_the_json(tmp_path):
    for rel in ("validation/finger.json", "surrogate/metrics.json"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(RESULTS / rel, tmp_path / rel)
    v = json.loads((tmp_path / "validation/finger.json").read_text())
    other = next(k for k in v["summary"] if k != v["judged_variant"] and k.startswith("predictor_"))
    v["judged_variant"] = other
    (tmp_path / "validation/finger.json").write_text(json.dumps(v))
    text = report_app.report(tmp_path)
    s = v["summary"][other]
    assert f"| fingertip error, {other} (max over {s['cases']} cases) | {s['tip_error_mm_max']:.2f} mm |" in text
    assert f"(`{other}`)**" in text
    held = json.loads((tmp_path / "surrogate/metrics.json").read_text())["improved"]["heldout"]
    row = (f"| improved | {held['n']} | {held['phi_end_error_deg']:.3f}° / {held['p95_phi_end_error_deg']:.3f}° | "
           f"{held['cap_rotation_error_deg']:.3f}° / {held['p95_cap_rotation_error_deg']:.3f}° | "
           f"{held['tangent_error_deg']:.3f}° / {held['p95_tangent_error_deg']:.3f}° |")
    assert row in text
    # the overlays are not in tmp_path: named with their make target, not linked
    assert "(not generated yet: `make validate-finger`)" in text
    assert not [p for p in LINK.findall(text) if not (tmp_path / p).is_file()]


def test_report_builds_without_artefacts(tmp_path):
    text, sections, checks = report_app.build(tmp_path)
    assert len(sections) == len(report_app.SECTIONS) and not checks
    assert not LINK.findall(text)
    for target in ("make joint-render", "make gestures", "make atlas", "make inverse"):
        assert f"(not generated yet: `{target}`)" in text, target


@committed
def test_the_committed_report_regenerates_identically(tmp_path, capsys):
    """make report on the committed artefacts writes the committed REPORT.md, byte for byte."""
    assert report_main(["--results", str(RESULTS), "--out", str(tmp_path / "R.md")]) == 0
    assert (tmp_path / "R.md").read_bytes() == (RESULTS / "REPORT.md").read_bytes()


@committed
def test_a_malformed_artefact_is_named_in_one_line(tmp_path):
    """bench/fem.json with a renamed key (solve_from_zero_s -> solve_s): the FEM section is
    one line naming the file, the key path and the make target; the campaign section, which
    reads bench/fem.json only for the paper's seconds per sample, is named the same way;
    every other section renders as from the committed file."""
    shutil.copytree(RESULTS, tmp_path / "results", ignore=shutil.ignore_patterns("*.npz"))
    root = tmp_path / "results"
    bench = json.loads((root / "bench/fem.json").read_text())
    bench["solve_s"] = bench.pop("solve_from_zero_s")
    (root / "bench/fem.json").write_text(json.dumps(bench))
    text, sections, _ = report_app.build(root)
    good, _, _ = report_app.build(RESULTS)
    lines = [ln for ln in text.splitlines() if ln.startswith("_Malformed artefact:")]
    assert len(lines) == 2, lines
    for line in lines:
        assert f"{root}/bench/fem.json: solve_from_zero_s: missing" in line and "`make bench-fem`" in line
    by_section = lambda t: dict(zip(sections, t.split("\n## ")[1:]))
    same = [s for s in sections if by_section(text)[s] == by_section(good)[s]]
    assert same == sections[2:], same


def test_mesh_study_judges_the_production_mesh_only(tmp_path):
    """A mesh_study.json as fem.studies.mesh_study writes it (figures made up): the production
    discretisation 2.4:1.2 mixed, 1.5 % anchors and 0.4 deg cap rotation against the
    Richardson extrapolation, is judged against the recorded 1 %, 0.3 deg and 16,000 nodes
    ("no, over by 0.5 %; over by 0.1 °"); the family's other meshes and the paper's 1.8 mm
    displacement mesh are shown, not judged. Out of the asymptotic range (reference: the
    finest mesh) the error is a lower bound: a miss when it already exceeds the tolerance,
    no verdict below it."""
    def mesh(h, w, nodes, percent, formulation="mixed"):
        err = {"anchor_mm": percent / 10, "anchor_percent": percent, "tip_mm": percent / 20,
               "phi_end_deg": percent / 5, "cap_rotation_deg": percent / 3.75}
        key = f"h{h:g}_w{w if w is None else f'{w:g}'}_{formulation}_q2_k100"
        return {"key": key, "mesh": f"{h:g}" + (f":{w:g}" if w else ""), "element": "tet", "sizes": [h, w or h],
                "formulation": formulation, "nodes": nodes, "mean_solve_s": 10.0, "ranks": 2, "max_error": err}

    meshes = [mesh(3.394, 1.697, 16195, 3.0), mesh(2.4, 1.2, 27908, 1.5), mesh(1.697, 0.849, 53179, 0.75),
              mesh(1.2, 0.6, 136875, 0.3), mesh(1.8, None, 17351, 6.0, "displacement")]
    study = {"loads": [[0.3, 3, -3, -100]] * 8, "formulation": "mixed", "element": "tet", "complete": True,
             "wall_mm": 1.2,
             "tolerance_percent": 1.0, "tolerance_deg": 0.3, "min_nodes": 16000, "meshes": meshes,
             "family": ["3.394:1.697", "2.4:1.2", "1.697:0.849", "1.2:0.6"], "reference": "richardson",
             "asymptotic": True, "extrapolation": [{"anchors": {"order": 2.0}}] * 8,
             "orders": [{"meshes": ["2.4:1.2", "1.697:0.849", "1.2:0.6"], "anchors": [2.0] * 8,
                         "phi_end_deg": [1.5] * 8, "cap_rotation_deg": [None] * 8}],
             "production": meshes[1]["key"], "production_mesh": "2.4:1.2", "production_met": False,
             "production_error": meshes[1]["max_error"], "paper": meshes[4]["key"],
             "paper_error": meshes[4]["max_error"]}
    (tmp_path / "fem").mkdir()
    (tmp_path / "fem/mesh_study.json").write_text(json.dumps(study))
    text, _, checks = report_app.build(tmp_path)
    (check,) = [c for c in checks if "production discretisation" in c.figure]
    assert check.figure == "production discretisation 2.4:1.2 mixed against the Richardson extrapolation"
    assert check.verdict == "no, over by 0.5 %; over by 0.1 °"
    rows = {r[0]: r for h, rows in _tables(text) if h[0] == "discretisation" for r in rows}
    assert rows["2.4:1.2 mixed"][-1] == check.verdict and rows["2.4:1.2 mixed"][3] == "1.50"
    assert all(rows[m][-1] == report_app.NOT_JUDGED
               for m in ("3.394:1.697 mixed", "1.697:0.849 mixed", "1.2:0.6 mixed", "1.8 displacement (paper-fidelity data)"))
    assert "mixed family 3.394:1.697, 2.4:1.2, 1.697:0.849, 1.2:0.6, in the asymptotic range" in text
    assert "per load (anchors; phi_end; cap rotation): " + ", ".join(["2.00"] * 8) in text
    study.update(asymptotic=False, reference="finest mesh")
    for percent, verdict in ((3.5, "no, over by at least 2.50 % (3.50 % is a lower bound)"),
                             (0.5, "not established: 0.50 % is a lower bound (no extrapolation in the asymptotic range)")):
        study["meshes"][1] = mesh(2.4, 1.2, 27908, percent)
        (tmp_path / "fem/mesh_study.json").write_text(json.dumps(study))
        text, _, checks = report_app.build(tmp_path)
        (check,) = [c for c in checks if "production discretisation" in c.figure]
        assert check.figure == "production discretisation 2.4:1.2 mixed against the finest mesh" and not check.met
        assert check.verdict == verdict
    assert "mixed family 3.394:1.697, 2.4:1.2, 1.697:0.849, 1.2:0.6 is NOT in the asymptotic range" in text


def test_finger_fem_time_is_judged_on_the_bench(tmp_path):
    """With results/bench/finger.json (made-up times 200 and 700 s against the 600 s target)
    the finger FEM row judges the bench's slowest case ("no, over by 100 s"), and the
    validation run's slowest FEM time is shown beside it, not judged."""
    (tmp_path / "validation").mkdir()
    shutil.copy(RESULTS / "validation/finger.json", tmp_path / "validation/finger.json")
    (tmp_path / "bench").mkdir()
    cases = [{"case": "free_0.1_0.1", "wall_time_s": 200.0, "load_average_before": 0.1},
             {"case": "gravity_0.2_0.2", "wall_time_s": 700.0, "load_average_before": 1.0}]
    (tmp_path / "bench/finger.json").write_text(json.dumps(
        {"cases": cases, "finger_fem_median_s": 450.0, "finger_fem_max_s": 700.0, "target_s": 600.0}))
    text, _, checks = report_app.build(tmp_path)
    (check,) = [c for c in checks if "finger FEM per gesture" in c.figure]
    assert "`make bench-finger`, max over free_0.1_0.1, gravity_0.2_0.2" in check.figure
    assert check.verdict == "no, over by 100 s"
    validation_max = max(c["fem_s"] for c in json.loads((RESULTS / "validation/finger.json").read_text())["fem"]
                         if c["converged"])
    row = next(r for h, rows in _tables(text) for r in rows if r[0].startswith("finger FEM per gesture in the validation"))
    assert row[1] == f"{validation_max:.0f} s" and row[-1] == report_app.NOT_JUDGED


def test_multifidelity_verdict_compares_equal_cost_figures(tmp_path):
    """The committed multifidelity.json with its best point's learning-curve proxy set
    below and then above the multi-fidelity error: the verdict says fine-only wins by the
    ratio (0.100 / 0.020 = 5.0x), then that the correction wins."""
    m = json.loads((Path(report_app.__file__).parents[2] / "results/surrogate/h1.8/multifidelity.json").read_text())
    best = min(m["comparison"], key=lambda r: r["multifidelity"]["heldout_mean_anchor_error_mm"])
    (tmp_path / "surrogate/h1.8").mkdir(parents=True)
    for proxy, words in ((0.2 * best["multifidelity"]["heldout_mean_anchor_error_mm"], "is 5.0× more accurate"),
                         (2.0 * best["multifidelity"]["heldout_mean_anchor_error_mm"], "better than the learning curve")):
        best["reference_curve_at_m"]["heldout_mean_anchor_error_mm"] = proxy
        (tmp_path / "surrogate/h1.8/multifidelity.json").write_text(json.dumps(m))
        text = "\n".join(report_app.learning.multifidelity_lines(tmp_path))
        assert words in text and f"n = {best['samples']}" in text


def test_each_figure_is_labelled_with_the_discretisation_that_made_it(tmp_path):
    """A hexahedral production run beside the committed 1.8 mm artefacts: bench/fem.json of
    hex2:3 mixed reads "Q2 nodes ... hex2:3 mixed"; a finger.json validating hex2:3 mixed
    names it, its mesh-check row against 1.8 mm displacement names both and the command
    that reproduces the other (--mesh-size 1.8 --formulation displacement, now that the
    default is mixed); bench/finger.json of hex2:3 mixed names its mesh; a committed dataset
    manifest names its own (the production hex2:3 mixed; the mesh check is the 1.8 mm
    reference validation's, finger_h1.8.json, relabelled)."""
    for folder in ("bench", "validation", "data/heldout"):
        (tmp_path / folder).mkdir(parents=True)
    bench = json.loads((RESULTS / "bench/fem.json").read_text())
    bench = {k: v for k, v in bench.items() if not k.endswith("_1.8") and k != "mesh_size"} | {
        "mesh": "hex2:3", "divisions": 2, "hex_size": 3.0, "formulation": "mixed"}
    (tmp_path / "bench/fem.json").write_text(json.dumps(bench))
    v = json.loads((RESULTS / "validation/finger_h1.8.json").read_text())
    base = v["mesh_check"][0]
    v["discretisation"] = {"mesh": "hex2:3", "formulation": "mixed"}
    v["mesh_check"] = [{k: x for k, x in base.items() if k not in ("production_mesh_size", "wall_mesh_size")}
                       | {"production_mesh": "hex2:3", "production_formulation": "mixed", "mesh": "1.8",
                          "mesh_size": 1.8, "formulation": "displacement"}]
    (tmp_path / "validation/finger.json").write_text(json.dumps(v))
    (tmp_path / "bench/finger.json").write_text(json.dumps(
        {"cases": [{"case": "free_0.1_0.1", "wall_time_s": 500.0, "load_average_before": 0.1}],
         "finger_fem_median_s": 500.0, "finger_fem_max_s": 500.0, "target_s": 600.0, "mesh": "hex2:3",
         "formulation": "mixed"}))
    shutil.copy(RESULTS / "data/heldout/manifest.json", tmp_path / "data/heldout/manifest.json")
    text, _, checks = report_app.build(tmp_path)
    assert f"| mesh | {bench['nodes']} Q2 nodes, {bench['dofs']} dofs, hex2:3 mixed |" in text
    assert "joint mesh hex2:3 mixed, one rank, one finger alone) against the predictor" in text
    assert (f"| discretisation: finger FEM, joint mesh hex2:3 mixed -> 1.8 mm displacement "
            f"({base['production_nodes']:,} -> {base['nodes']:,} nodes), {base['case']} |") in text
    assert "`python -m fem.studies.finger_cases --mesh-size 1.8 --formulation displacement` |" in text
    assert any("finger FEM per gesture, joint mesh hex2:3 mixed, one core (`make bench-finger`" in c.figure
               for c in checks)
    assert "| heldout | hex2:3 mixed | 2 |" in text


def test_production_surrogate_targets_are_judged_from_its_metrics(tmp_path):
    """Issue 55's held-out targets (mean anchor <= 0.03 mm, tip <= 0.05 mm, cap rotation
    <= 0.1 deg) judged on results/surrogate/metrics.json (the production models' since the
    switch), the 1.8 mm reference's (surrogate/h1.8/metrics.json) not judged; each figure
    shown is the file's."""
    from apps.report.learning import production_surrogate_section
    from surrogate.artefacts import METRICS

    held = {"n": 256, "mean_anchor_error_mm": 0.0204, "p95_anchor_error_mm": 0.07, "tip_error_mm": 0.0612,
            "phi_end_error_deg": 0.1, "jacobian_rel_error": 0.03, "cap_rotation_error_deg": 0.0931,
            "p95_cap_rotation_error_deg": 0.41}
    (tmp_path / "surrogate").mkdir(parents=True)
    METRICS.write(tmp_path / "surrogate/metrics.json", {"improved": {"test": held, "heldout": held}})
    lines, checks = production_surrogate_section(tmp_path)
    assert [c.met for c in checks] == [True, False, True]
    assert checks[1].verdict.startswith("no") and "0.0612" in "\n".join(lines)
    assert "0.410 deg" in "\n".join(lines)                 # the p95 shown, not judged


def test_dataset_table_lists_every_committed_walk():
    """REPORT's dataset table has a row per committed manifest under results/data: the
    surrogate's train and held-out sets first (the production hex2:3 walks), then the others
    (the 1.8 mm reference walks and the finer held-out walk), each with its discretisation in
    words."""
    from apps.report.joint_fem import campaign_section

    lines, _ = campaign_section(RESULTS)
    lines = lines[:lines.index("### Campaign throughput (`make bench-campaign`)")]   # the dataset table only
    rows = [ln.split(" | ")[0].lstrip("| ") for ln in lines if ln.startswith("| ") and not ln.startswith("| set ")]
    names = sorted(p.parent.name for p in (RESULTS / "data").glob("*/manifest.json"))
    assert rows[:2] == ["train", "heldout"] and sorted(rows) == names
    for name in ("train", "heldout"):
        assert any(ln.startswith(f"| {name} | hex2:3 mixed |") for ln in lines)
        assert any(ln.startswith(f"| {name}_h1.8 | 1.8 mm displacement |") for ln in lines)


def test_targets_at_a_glance_count_each_sections_misses_and_link_it():
    """The glance before the sections: per section the targets met, and each missed one's
    verdict; the link is the anchor GitHub gives the section's heading."""
    a = report_app.Check("Finger FEM over the pressure box (issue 36)", "pairs converged", ">= 49", (7,), False,
                         "no, short by 42 pairs")
    b = report_app.Check("Finger FEM over the pressure box (issue 36)", "slowest", "<= 600 s", (500.0,), True, "yes")
    c = report_app.Check("Calibration (issue 38)", "gain", "<= 1 %", (0.5,), True, "yes")
    rows = [ln for ln in report_app.glance([a, b, c]) if ln.startswith("| [")]
    assert rows == ["| [Finger FEM over the pressure box (issue 36)](#finger-fem-over-the-pressure-box-issue-36) | "
                    "1 of 2 | pairs converged: short by 42 pairs |",
                    "| [Calibration (issue 38)](#calibration-issue-38) | 1 of 1 | none |"]
    assert "2 of 3 met" in report_app.glance([a, b, c])[0] and report_app.glance([]) == []
    assert report_app.anchor("Contact on the finger's outline, fingers that meet (issue 36)") == \
        "#contact-on-the-fingers-outline-fingers-that-meet-issue-36"
