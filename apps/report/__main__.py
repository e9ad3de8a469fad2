"""``python -m apps.report``: results/REPORT.md from the committed JSON artefacts (apps.report)."""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path

from apps.report import build
from contract import cli
from contract.files import write_text


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m apps.report",
                    description="Assemble results/REPORT.md from the committed JSON artefacts.")
    ap.add_argument("--results", default="results", help="artefact folder (default results)")
    ap.add_output("--out", suffix=".md", default="results/REPORT.md",
                  help="report file (default results/REPORT.md)")
    args = ap.parse_args(argv)
    if not Path(args.results).is_dir():
        ap.error(f"--results {args.results}: not a folder")
    with ap.errors():
        text, sections, checks = build(Path(args.results))
        write_text(args.out, text)
    if args.json:
        cli.print_json({"out": args.out, "sections": sections,
                        "targets": [asdict(c) for c in checks],
                        "met": sum(c.met for c in checks), "missed": sum(not c.met for c in checks)})
    else:
        missed = [c for c in checks if not c.met]
        print(f"wrote {args.out}: {len(sections)} sections, {len(checks) - len(missed)} of "
              f"{len(checks)} targets met" + "".join(f"; {c.figure}: {c.verdict}" for c in missed))
    return 0


if __name__ == "__main__":
    sys.exit(main())

