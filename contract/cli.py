"""The command-line contract shared by every ``python -m <package>.<tool>``.

- ``--help`` on every tool, and ``--json`` (strict JSON: NaN and inf print as null).
- Bad input exits 2 with ONE line on stderr that names the value and what is allowed:
  a non-number, NaN or inf, a value out of range, an unknown or repeated option, an
  output that cannot be written. It is checked before any long work starts, and nothing
  is written for it.
- Outputs: a file's folder must exist, and a folder output's parent must exist (the tool
  makes that one folder, nothing above it). Writability is probed by creating and
  removing a temporary file there (as root, os.access says yes even on /proc).
- Negative numbers are values, also in comma lists: ``--pressures -0.1,0.1``.
- Progress: tools that run longer than ~10 s log on the "softjoint" loggers at INFO to
  stderr (``add_quiet`` and ``setup_logging``); ``--quiet`` keeps only warnings. stdout
  stays the result alone (strict JSON with ``--json``; ``print_fields``: that, or one
  ``key: value`` line a key).
- Under mpirun, srun or Slurm only the launcher's rank 0 prints the error line.
- Ctrl-C inside ``errors()`` ends with one line and exit 130 (EXIT_INTERRUPTED).
- A library module run as ``python -m`` (it has no command line) says in one line which
  command does its work and exits 2 (``not_a_command``), instead of running nothing and
  exiting 0.

Usage::

    ap = cli.Parser(prog="python -m fem.cli.solve", description=...)
    ap.add_argument("--p", type=cli.number(-0.3, 0.3, "MPa"), default=0.0)
    ap.add_output("--out", suffix=".json")
    args = ap.parse_args(argv)          # every value and output checked
    with ap.errors():                   # ValueError / OSError -> one line, exit 2
        ...

Plain Python: importing it never imports dolfinx or torch.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

from contract.files import dumps

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
#: Set to 1 to see the traceback behind a one-line error (development).
TRACEBACK_ENV = "SOFTJOINT_TRACEBACK"


def launcher_rank() -> int:
    """This process's rank as the MPI launcher or Slurm set it (0 when serial), known
    before MPI starts (arguments are parsed on every rank)."""
    for var in ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


def number(lo: float | None = None, hi: float | None = None, unit: str = "", integer: bool = False,
           open_lo: bool = False):
    """argparse type: a finite number in [lo, hi] (or (lo, hi] with open_lo); ints with
    ``integer``. The error names the value and the allowed range."""
    kind = "an integer" if integer else "a finite number"
    span = f"{'(' if open_lo else '['}{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
    span = f"{span} {unit}".rstrip()
    allowed = f" (allowed {span})" if (lo, hi) != (None, None) else f" (in {unit})" if unit else ""

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {kind}{allowed}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not {kind}{allowed}")
        if (lo is not None and (value < lo or (open_lo and value == lo))) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"{text} is outside {span}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def numbers(count: int, lo: float | None = None, hi: float | None = None, unit: str = ""):
    """argparse type: ``count`` comma-separated finite numbers in [lo, hi] -> tuple."""
    one = number(lo, hi, unit)

    def parse(text: str):
        parts = text.split(",")
        if len(parts) != count:
            raise argparse.ArgumentTypeError(f"{text!r}: expected {count} comma-separated numbers")
        return tuple(one(p.strip()) for p in parts)

    parse.__name__ = "numbers"
    return parse


def number_list(lo: float | None = None, hi: float | None = None, unit: str = ""):
    """argparse type: one or more comma-separated finite numbers in [lo, hi] -> tuple
    (the count is the tool's to check: it may depend on another option)."""
    one = number(lo, hi, unit)

    def parse(text: str):
        return tuple(one(p.strip()) for p in text.split(","))

    parse.__name__ = "numbers"
    return parse


def _missing_folder(folder: Path) -> str | None:
    """Why files cannot be created in ``folder`` (it must exist), or None."""
    if folder.is_dir():
        return None
    above = folder
    while not above.exists() and above != above.parent:
        above = above.parent
    if above.exists() and not above.is_dir():
        return f"{above} is not a folder"
    return f"folder {folder} does not exist"


def probe_write(folder: str | Path) -> str | None:
    """Why a file cannot be created in the existing ``folder``, or None: really creates
    and removes an empty temporary file (os.access answers yes to root even on /proc)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".softjoint-probe-", dir=folder)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    os.close(fd)
    os.unlink(name)
    return None


def check_output(path: str | Path, folder: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (or, with ``folder``, be a folder that
    files are written into), or None. A file's folder must exist; a folder may be new
    if its parent exists (no folder is made above what the user named). Nothing is
    left behind."""
    path = Path(path)
    if path.exists() and path.is_dir() != folder:
        return f"{path} is {'a file, not a folder' if folder else 'a folder, not a file'}"
    where = path if folder and path.is_dir() else path.parent
    why = _missing_folder(where)
    if why:
        return f"cannot create {path}: {why}"
    why = probe_write(where)
    if why:
        return f"cannot write {path}: {where}: {why}"
    return None


def make_output_folder(path: str | Path) -> Path:
    """Create the output folder ``path`` (its parent must exist: check_output) and return
    it; an existing folder is fine."""
    path = Path(path)
    path.mkdir(exist_ok=True)
    return path


#: argparse takes "-0.1" for a value only when it looks like one number; these also
#: count as values: comma lists ("-0.1,0.1"), exponents ("-1e-3") and "-inf"/"-nan"
#: (refused later with the usual message).
NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d|inf\b|nan\b)", re.IGNORECASE)


def add_quiet(ap: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress lines on stderr (warnings and errors only)."""
    ap.add_argument("--quiet", action="store_true",
                    help="no progress lines on stderr (they never go to stdout)")


def _progress_or_warning(record: logging.LogRecord) -> bool:
    """Pass warnings and errors, and the project's own progress; drop other libraries'
    chatter (the form compiler's build lines: setuptools lowers the root level to INFO)."""
    return record.levelno >= logging.WARNING or record.name.split(".")[0] == "softjoint"


def setup_logging(quiet: bool = False, verbose: bool = False) -> None:
    """Progress (INFO) of the "softjoint" loggers to stderr, one line each; ``quiet``:
    warnings only; ``verbose``: DEBUG too. stdout is never used."""
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(level=logging.WARNING, format="%(message)s", stream=sys.stderr, force=True)
    for handler in logging.getLogger().handlers:
        handler.addFilter(_progress_or_warning)
    logging.getLogger("softjoint").setLevel(level)


@contextlib.contextmanager
def heartbeat(what: str, every: float = 10.0, enabled: bool = True):
    """While the block runs, log "<what>: still working, N s" on the "softjoint" logger
    every ``every`` s (a daemon thread; a C call that holds the GIL delays a line, it
    does not lose the next one). ``enabled=False`` (other MPI ranks) does nothing."""
    stop = threading.Event()
    t0 = time.perf_counter()
    log = logging.getLogger("softjoint.progress")

    def beat():
        while not stop.wait(every):
            log.info("%s: still working, %.0f s", what, time.perf_counter() - t0)

    thread = threading.Thread(target=beat, daemon=True) if enabled else None
    if thread:
        thread.start()
    try:
        yield
    finally:
        stop.set()


class Parser(argparse.ArgumentParser):
    """argparse with the contract of the module docstring. ``json=False`` for a parser
    whose subcommands carry the flag (subparsers are Parsers with ``--json``)."""

    def __init__(self, *args, json: bool = True, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_VALUE
        self._outputs: list[tuple[str, str | None, bool]] = []
        if json:
            self.add_argument("--json", action="store_true", help="print the figures as JSON")

    def add_output(self, *flags, suffix: str | None = None, folder: bool = False, **kwargs):
        """An output file (or, with folder=True, a folder) option, checked writable right
        after parsing (check_output), before the tool's work starts. Nothing is created
        for it here, so a run refused later (a corrupt input, a failed solve) leaves no
        trace."""
        action = self.add_argument(*flags, **kwargs)
        self._outputs.append((action.dest, suffix, folder))
        return action

    def add_subparsers(self, **kwargs):
        kwargs.setdefault("parser_class", Parser)
        return super().add_subparsers(**kwargs)

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {' '.join(str(message).split())}\n")

    def _print_message(self, message, file=None):
        if launcher_rank() == 0:
            super()._print_message(message, file)

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        self._refuse_repeats(args)
        namespace, extras = super().parse_known_args(args, namespace)
        for dest, suffix, folder in self._outputs:
            value = getattr(namespace, dest, None)
            if value is None:
                continue
            if suffix and not str(value).lower().endswith(suffix):
                self.error(f"{value}: expected a {suffix} file")
            why = check_output(value, folder)
            if why:
                self.error(why)
        return namespace, extras

    def _refuse_repeats(self, args: list[str]) -> None:
        seen = {}
        for token in args:
            if token == "--":
                break
            action = self._option_string_actions.get(token.split("=", 1)[0])
            if action is None or isinstance(action, (argparse._AppendAction, argparse._CountAction,
                                                     argparse._HelpAction)):
                continue
            option = token.split("=", 1)[0]
            if action.dest in seen:
                first = seen[action.dest]
                self.error(f"{first} given twice: give each option once" if first == option else
                           f"{first} and {option} both given: give one of them")
            seen[action.dest] = option

    @contextlib.contextmanager
    def errors(self):
        """Turn a ValueError or OSError from the tool's work (bad value found late, corrupt
        file, unwritable output) into one line and exit 2, and Ctrl-C into one line and exit
        130 (128 + SIGINT, the shells' convention) instead of a traceback (a file output is
        written whole or not at all: contract.files' atomic writes)."""
        try:
            yield
        except KeyboardInterrupt:
            if os.environ.get(TRACEBACK_ENV) == "1":
                raise
            self.exit(EXIT_INTERRUPTED, f"{self.prog}: interrupted (Ctrl-C)\n")
        except (ValueError, OSError) as exc:
            if os.environ.get(TRACEBACK_ENV) == "1":
                raise
            text = " ".join(str(exc).split()) or type(exc).__name__
            self.error(text)


def print_json(obj) -> None:
    """Print ``obj`` as strict JSON (non-finite floats as null). A reader that closes the
    pipe early (``| head``) ends the output quietly."""
    try:
        print(dumps(obj), flush=True)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def print_fields(doc: dict, as_json: bool, width: int | None = None, value=str, sep: str = ": ") -> None:
    """A tool's answer: ``doc`` as strict JSON (``--json``, print_json), else one line a key,
    the key right-aligned in ``width`` characters (None: the longest key's), then ``sep``
    and ``value(v)``."""
    if as_json:
        print_json(doc)
        return
    width = max(map(len, doc)) if width is None else width
    for key, v in doc.items():
        print(f"{key:>{width}}{sep}{value(v)}")


def not_a_command(command: str) -> None:
    """Refuse ``python -m LIBRARY``: one line on stderr naming the command that does the
    library's work (``command``, a module path, optionally with its subcommand) and exit 2.
    Called under a library module's ``if __name__ == "__main__":``."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    module = spec.name if spec is not None else "this module"
    print(f"python -m {module}: a library, not a command; the command is python -m {command}", file=sys.stderr)
    raise SystemExit(2)
