"""JSON of results and metadata that hold NumPy values (one helper for the whole project).

json.dumps(doc, default=json_default)     # arrays -> lists, numpy scalars -> numbers
jsonable(doc)                             # the same, as plain Python objects
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np


def json_default(v: Any) -> Any:
    """``default=`` for :func:`json.dumps`: arrays become lists, NumPy scalars numbers, and
    anything else its ``repr``."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return repr(v)


def jsonable(v: Any) -> Any:
    """``v`` as plain JSON-able Python objects (see :func:`json_default`)."""
    return json.loads(json.dumps(v, default=json_default))


def dumps(v: Any, indent: int | None = 2) -> str:
    return json.dumps(v, indent=indent, default=json_default)
