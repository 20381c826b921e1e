"""The torch import and the guarded ``torch.load`` shared by the network flow back ends
(:mod:`cablesim.perception.raft`, :mod:`cablesim.perception.learned`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cablesim.errors import InputError


def import_torch(needed_by: str) -> Any:
    """torch, or ``InputError`` saying that ``needed_by`` needs it."""
    try:
        import torch  # lazy: optional heavy package
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise InputError(f"{needed_by} needs torch: pip install 'cablesim[torch]'") from e
    return torch


def load_torch_file(path: Path, what: str) -> Any:
    """``torch.load`` of ``path`` on the CPU with ``weights_only``; a truncated, corrupt or
    non-torch file is an ``InputError`` naming ``what`` and the file."""
    torch = import_torch(f"reading {what}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for corrupt files
        raise InputError(
            f"cannot read {what} {path}: truncated, corrupt or not a torch file "
            f"({type(e).__name__}: {e})"
        ) from e
