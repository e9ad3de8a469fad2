"""Heartbeat: progress lines on stderr during long runs (atlas, inverse, NN training).

A ``Heartbeat(label)`` is called at natural checkpoints of a run (a ring of the atlas
sweep, a start of the inverse search, an epoch); it prints ``[label 12 s] text`` on
stderr when at least EVERY seconds have passed since the run began or since its last
line, so a run shorter than EVERY prints nothing. ``set_quiet(True)`` (the tools'
``--quiet``) silences every heartbeat of the process. stdout is never touched: the
tools' JSON stays clean.
"""
from __future__ import annotations

import sys
import time

EVERY = 10.0  # s between two progress lines
_quiet = [False]


def set_quiet(quiet: bool) -> None:
    """Silence (True) or restore (False) the progress lines of this process."""
    _quiet[0] = bool(quiet)


def quiet() -> bool:
    """Are progress lines silenced (``set_quiet``)?"""
    return _quiet[0]


class Heartbeat:
    """Progress of one run (module docstring)."""

    def __init__(self, label: str, every: float | None = None):
        self.label, self.every = label, EVERY if every is None else every
        self.t0 = self.last = time.monotonic()

    def __call__(self, text) -> None:
        """Print ``text`` (a string, or a callable giving one, built only when printed)."""
        now = time.monotonic()
        if _quiet[0] or now - self.last < self.every:
            return
        self.last = now
        print(f"[{self.label} {now - self.t0:.0f} s] {text() if callable(text) else text}", file=sys.stderr,
              flush=True)
