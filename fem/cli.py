"""The command-line contract shared by every ``python -m <package>.<tool>``.

- ``--help`` on every tool, and ``--json`` (strict JSON: NaN and inf print as null).
- Bad input exits 2 with ONE line on stderr that names the value and what is allowed:
  a non-number, NaN or inf, a value out of range, an unknown or repeated option, an
  output that cannot be written. It is checked before any long work starts, and nothing
  is written for it (output folders are made by the atomic writers, when they write).
- Under mpirun, srun or Slurm only the launcher's rank 0 prints the error line.

Usage::

    ap = cli.Parser(prog="python -m fem.solve", description=...)
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
import math
import os
import sys
from pathlib import Path

from fem.files import dumps

EXIT_USAGE = 2
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


def check_output(path: str | Path, folder: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (or, with ``folder``, be a folder that
    files are written into), or None. Nothing is created."""
    path = Path(path)
    if path.is_dir() != folder and path.exists():
        return f"{path} is {'a file, not a folder' if folder else 'a folder, not a file'}"
    parent = path if folder else path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f"cannot create {path}: {parent} is not a folder"
    target = path if path.exists() else parent
    if not os.access(target, os.W_OK | (os.X_OK if target.is_dir() else 0)):
        return f"cannot write {path}: permission denied"
    return None


class Parser(argparse.ArgumentParser):
    """argparse with the contract of the module docstring. ``json=False`` for a parser
    whose subcommands carry the flag (subparsers are Parsers with ``--json``)."""

    def __init__(self, *args, json: bool = True, **kwargs):
        super().__init__(*args, **kwargs)
        self._outputs: list[tuple[str, str | None, bool]] = []
        if json:
            self.add_argument("--json", action="store_true", help="print the figures as JSON")

    def add_output(self, *flags, suffix: str | None = None, folder: bool = False, **kwargs):
        """An output file (or, with folder=True, a folder) option, checked writable right
        after parsing, before the tool's work starts. Nothing is created for it here: the
        atomic writers of fem.files create the folders when they write, so a run refused
        later (a corrupt input, a failed solve) leaves no trace."""
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
            if action.dest in seen:
                self.error(f"{seen[action.dest]} given twice: give each option once")
            seen[action.dest] = token.split("=", 1)[0]

    @contextlib.contextmanager
    def errors(self):
        """Turn a ValueError or OSError from the tool's work (bad value found late, corrupt
        file, unwritable output) into one line and exit 2."""
        try:
            yield
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
