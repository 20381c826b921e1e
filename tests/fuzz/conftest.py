"""Property-based fuzzing (hypothesis) of the public entry points: each input either works or
raises the project's own error (``CablesimError``), within a time bound; never a foreign
exception, never a hang.

Bounded for the default test run: derandomised (the same examples every run, so a failure
reproduces), no example database, ``max_examples`` per test and a per-example deadline; a
SIGALRM guard fails any test that runs past ``HANG_S`` (a hang would otherwise stall the whole
run).  ``CABLESIM_FUZZ=random`` draws fresh random examples (as many); ``CABLESIM_FUZZ=deep``
ten times as many, without deadlines or the guard (for a longer search by hand).
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from typing import Any

import pytest

from ._fuzz import DEEP

HANG_S = 0 if DEEP else 120  # seconds a whole fuzz test may take


class Hang(BaseException):
    """Not an ``Exception``: hypothesis stops at once instead of re-running (and shrinking)
    the input that hangs."""


@pytest.fixture(autouse=True)
def hang_guard() -> Iterator[None]:
    """Fail (instead of stalling the run) when a fuzz test takes longer than ``HANG_S``."""
    if not HANG_S:
        yield
        return

    def alarm(signum: int, frame: Any) -> None:
        raise Hang(f"a fuzz test ran past {HANG_S} s: an input hangs")

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(HANG_S)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
