"""Helpers of the fuzz suite (see conftest.py)."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from cablesim.errors import CablesimError

MODE = os.environ.get("CABLESIM_FUZZ", "")  # "" (default run), "random" or "deep"
DEEP = MODE == "deep"


def fuzz(n: int, deadline_ms: int | None = 5000) -> settings:
    """Settings of a fuzz test: ``n`` examples, derandomised (the same every run, so a failure
    reproduces), no example database, a per-example deadline (generous: the machine is shared;
    hangs are caught by the SIGALRM guard in conftest.py).  ``CABLESIM_FUZZ=random``: fresh
    random examples, as many; ``CABLESIM_FUZZ=deep``: ten times as many, no deadline."""
    if DEEP:
        return settings(
            max_examples=10 * n,
            derandomize=False,
            database=None,
            deadline=None,
            suppress_health_check=list(HealthCheck),
        )
    return settings(
        max_examples=n,
        derandomize=MODE != "random",
        database=None,
        deadline=deadline_ms,
        suppress_health_check=[
            HealthCheck.too_slow,
            HealthCheck.data_too_large,
            HealthCheck.function_scoped_fixture,
        ],
        print_blob=False,
    )


def own_error_or_result(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)``, or ``None`` when it raises the project's own error; any other
    exception propagates and fails the test (hypothesis then shrinks the input)."""
    try:
        return fn(*args, **kwargs)
    except CablesimError as e:
        assert str(e), "a cablesim error must say what is wrong"
        return None


#: Values a hostile user might put anywhere: wrong types, NaN, infinities, huge integers.
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.integers(-3, 10),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 0.0, -0.0, 1e308, 5e-324]),
    st.text(max_size=4),
)
HOSTILE = st.recursive(
    SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=3), inner, max_size=3)
    ),
    max_leaves=6,
)
