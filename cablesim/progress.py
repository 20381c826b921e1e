"""Progress lines of long work, one printer for the whole project.

    say = Progress("explore", enabled=True)
    say("interaction 0: grasped")          # [explore   12.3s] interaction 0: grasped

A disabled printer swallows every line; any ``Callable[[str], None]`` can stand in for one.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

Say = Callable[[str], None]


class Progress:
    """Prints ``[name  elapsed] message`` lines (to stderr when ``stream`` says so)."""

    def __init__(self, name: str, enabled: bool = True, stream=None) -> None:
        self.name = name
        self.enabled = enabled
        self.stream = stream or sys.stdout
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self.t0
            print(f"[{self.name} {elapsed:6.1f}s] {msg}", file=self.stream, flush=True)


def quiet(_msg: str) -> None:
    """A printer that prints nothing."""
