"""Dataset tools (docs/formats.md): inspect, verify and merge FEM campaign datasets.

    python -m workflow.dataset info ROOT [--json]
    python -m workflow.dataset verify ROOT [--mirror N] [--require-complete | --require-units A:B] [--json]
    python -m workflow.dataset merge OUT SOURCE [SOURCE ...] [--json]
    python -m workflow.dataset compare REF OTHER [--out FILE] [--json]

``compare``: how far OTHER's samples lie from REF's where both solved the same load (two
campaigns of one walk on different meshes: the discretisation change over the walk).

The command line only: the work is ``workflow.store`` (info, verify, merge, compare), on datasets
in the format of ``workflow.shards``. Imports neither dolfinx nor torch; only
``verify --mirror N`` builds a FEM solver (N solves on one rank).

Exit codes: 0 ok; 1 ``verify`` found problems in the dataset (listed on stdout, or in
the JSON's "errors"); 2 bad command line, or an input that is not a usable dataset
(``verify`` of a folder without manifest.json; ``info`` or ``merge`` of any dataset
they cannot use), with one line on stderr.
"""

from __future__ import annotations

import sys

from contract import cli
from workflow import store
from workflow.artefacts import MESH_COMPARISON
from workflow.store import unit_range
from workflow.mirror import mirror_check
from workflow.shards import MANIFEST, Manifest

EXIT_PROBLEMS = 1


def _print_info(d: dict) -> None:
    print(f"{d['root']}: {d['samples']} samples, {d['failures']} failures "
          f"({100 * d['failure_rate']:.2f}%), {d['shards']} shards, complete={d['complete']}")
    print(f"  seed {d['seed']}; split train/val/test = {d['split']['train']}/"
          f"{d['split']['val']}/{d['split']['test']}; CPU hours {d['cpu_hours']}")
    cov = d["coverage"]
    for name, c in cov["per_input"].items():
        print(f"  {name:>2}: [{c['min']:+.4g}, {c['max']:+.4g}] of ±{c['box']:g}, "
              f"histogram {c['histogram']}")
    print(f"  grid cells occupied ({cov['grid']}): {100 * cov['cells_occupied']:.1f}%")
    w = d["walk_consistency"]
    if w:
        print(f"  walk consistency (trapezoid rule on the Jacobians, {w['pairs']} pairs): anchors missed by "
              f"{w['median_mm']:.2e} mm median, {w['p90_mm']:.2e} p90, {w['max_mm']:.2e} max")
    if d["failure_reasons"]:
        print("  failure reasons: " + "; ".join(f"{k} x{v}" for k, v in d["failure_reasons"].items()))
    print(f"  data sha256 {d['checksums']['data_sha256']}; commits {d['git_commits']}")


def _print_verify(root: str, d: dict) -> None:
    for e in d["errors"]:
        print(f"ERROR: {e}")
    for w in d["warnings"]:
        print(f"warning: {w}")
    if "mirror" in d:
        print(f"mirror check: anchors {d['mirror']['max_anchor_error_mm']:.2e} mm, "
              f"Jacobian {d['mirror']['max_jacobian_rel_error']:.2e} relative")
    print(f"{root}: {'OK' if d['ok'] else 'FAILED'} "
          f"({d.get('n', 0)} samples, {d.get('failures', 0)} failures)")


def parser() -> cli.Parser:
    ap = cli.Parser(prog="python -m workflow.dataset", description=__doc__.split("\n\n")[0],
                    json=False)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p_info = sub.add_parser("info", help="counts, coverage, failure rate, split, checksums")
    p_info.add_argument("root", help="dataset directory")
    p_ver = sub.add_parser("verify", help="check checksums, layout, data; exit 1 on problems")
    p_ver.add_argument("root", help="dataset directory")
    p_ver.add_argument("--mirror", type=cli.number(0, None, "samples", integer=True), default=0,
                       metavar="N", help="also solve the y-mirror of N stored samples with the FEM "
                                         "and check the mirror relation (docs/physics.md); default 0")
    need = p_ver.add_mutually_exclusive_group()
    need.add_argument("--require-complete", action="store_true",
                      help="treat an unfinished campaign as an error")
    need.add_argument("--require-units", type=unit_range, default=None, metavar="A:B",
                      help="treat a missing unit among A..B-1 as an error (one slice of a "
                           "campaign, e.g. a job-array task's --units)")
    p_mrg = sub.add_parser("merge", help="merge pieces of one campaign into OUT")
    p_mrg.add_argument("out", help="output dataset directory")
    p_mrg.add_argument("sources", nargs="+", help="dataset directories of the same campaign")
    p_cmp = sub.add_parser("compare", help="per-sample differences of two campaigns of one walk "
                                           "(e.g. two meshes)")
    p_cmp.add_argument("ref", help="reference dataset directory")
    p_cmp.add_argument("other", help="dataset directory of the same walk")
    p_cmp.add_output("--out", suffix=".json", help="also write the figures as JSON (atomically)")
    return ap


def _print_compare(d: dict) -> None:
    print(f"{d['other']} against {d['ref']}: {d['samples']} common samples "
          f"(of {d['other_samples']} and {d['ref_samples']})")
    for key, unit in (("anchor_mm", "mm"), ("tip_mm", "mm"), ("phi_end_deg", "deg"),
                      ("cap_rotation_deg", "deg")):
        s = d[key]
        print(f"  {key:>16}: mean {s['mean']:.4f}, p95 {s['p95']:.4f}, max {s['max']:.4f} {unit}")


def main(argv=None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    if args.cmd == "info":
        with ap.errors():
            d = store.info(args.root)
        cli.print_json(d) if args.json else _print_info(d)
        return 0
    if args.cmd == "verify":
        if not Manifest.exists(args.root):
            ap.error(f"{args.root}: no {MANIFEST} (not a softjoint dataset)")
        with ap.errors():
            check = (lambda arrays, manifest: mirror_check(arrays, manifest, args.mirror)) if args.mirror else None
            d = store.verify(args.root, mirror_check=check)
        if args.require_complete and any(w.startswith("incomplete") for w in d["warnings"]):
            d["ok"], d["errors"] = False, d["errors"] + ["incomplete campaign"]
        if args.require_units and d["ok"]:
            done = {e.unit for e in Manifest.load(args.root).shards}
            missing = [u for u in range(*args.require_units) if u not in done]
            if missing:
                d["ok"] = False
                d["errors"] = d["errors"] + [f"units missing from the slice "
                                             f"{args.require_units[0]}:{args.require_units[1]}: {missing}"]
        cli.print_json(d) if args.json else _print_verify(args.root, d)
        return 0 if d["ok"] else EXIT_PROBLEMS
    if args.cmd == "compare":
        with ap.errors():
            d = store.compare(args.ref, args.other)
            if args.out:
                MESH_COMPARISON.write(args.out, d)
        cli.print_json(d) if args.json else _print_compare(d)
        return 0
    why = cli.check_output(args.out, folder=True)   # not created: the sources are checked first
    if why:
        ap.error(why)
    with ap.errors():
        m = store.merge(args.out, args.sources)
    cli.print_json(m.to_json()) if args.json else print(
        f"{args.out}: {m.samples} samples in {m.units_done}/{m.units_total} units, "
        f"complete={m.complete}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
