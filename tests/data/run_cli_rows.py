"""Run many ``python -m MODULE ARGS`` command lines in this one process (tests/test_bad_input.py).

    python tests/data/run_cli_rows.py < rows.json > results.json

rows.json: a list of [module, [args...]]. For each row the module is executed as
``__main__`` (runpy, with sys.argv set) while file descriptors 1 and 2 are redirected to
temporary files, so everything the row prints, Python or C, is caught. The result of a row
is {"returncode", "stdout", "stderr"} with the exit code a process would have had:
SystemExit's code (None -> 0, a message -> 1, printed to stderr), 1 and the traceback for
any other exception, 0 otherwise.

Why: most rows are argument errors that end in a fraction of a second, after 2-3 s of
importing torch or dolfinx. Paying the imports once per package instead of once per row
takes the table from minutes to seconds. The test still runs every module's first row in
a real subprocess, which covers what only a fresh interpreter shows (import errors, output
at interpreter exit).
"""

from __future__ import annotations

import json
import os
import runpy
import sys
import tempfile
import traceback
from pathlib import Path

# The checkout this script belongs to comes first: an installed copy elsewhere must not
# answer for it.
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _read(f) -> str:
    f.seek(0)
    return f.read().decode(errors="replace")


def run_row(module: str, args: list[str]) -> dict:
    """One command line, in-process; its exit code and captured output."""
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        sys.argv = [module, *args]
        sys.modules.pop(module, None)   # an earlier row's import: run the module afresh, as -m does
        try:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as exc:
            code = exc.code
            if code is None:
                code = 0
            elif not isinstance(code, int):
                print(code, file=sys.stderr)
                code = 1
        except BaseException:           # noqa: BLE001 - reported as a process would
            traceback.print_exc()
            code = 1
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
        return {"returncode": code, "stdout": _read(out), "stderr": _read(err)}


def main() -> int:
    rows = json.load(sys.stdin)
    results = [run_row(module, args) for module, args in rows]
    sys.stdout.write(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
