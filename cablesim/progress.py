"""Progress lines of long work, one printer for the whole project.

    say = Progress("explore", enabled=True)
    say("interaction 0: grasped")          # [explore   12.3s] interaction 0: grasped

A disabled printer swallows every line; any ``Callable[[str], None]`` can stand in for one.
Long loops show a tqdm bar (on stderr) through :meth:`Progress.bar`; while a bar is open the
printer's lines go above it (``tqdm.write``) instead of through it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from tqdm import tqdm

Say = Callable[[str], None]


class Progress:
    """Prints ``[name  elapsed] message`` lines (to stderr when ``stream`` says so)."""

    def __init__(self, name: str, enabled: bool = True, stream=None) -> None:
        self.name = name
        self.enabled = enabled
        self.stream = stream or sys.stdout
        self.t0 = time.perf_counter()
        self._bar: Any = None

    def __call__(self, msg: str) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self.t0
            line = f"[{self.name} {elapsed:6.1f}s] {msg}"
            if self._bar is not None:
                self._bar.write(line, file=self.stream)
                self.stream.flush()
            else:
                print(line, file=self.stream, flush=True)

    @contextmanager
    def bar(self, total: int, desc: str, unit: str = "it") -> Iterator[Any]:
        """A tqdm progress bar on stderr for ``total`` steps (``update(n)``, ``set_postfix``),
        disabled when the printer is or stderr is not a terminal (a log file keeps the plain
        lines); lines said meanwhile print above it."""

        bar = tqdm(
            total=total,
            desc=f"[{self.name}] {desc}",
            unit=unit,
            disable=True if not self.enabled else None,  # None: off where stderr is no TTY
            file=sys.stderr,
            dynamic_ncols=True,
            leave=True,
        )
        outer, self._bar = self._bar, bar
        try:
            yield bar
        finally:
            self._bar = outer
            bar.close()


def quiet(_msg: str) -> None:
    """A printer that prints nothing."""
