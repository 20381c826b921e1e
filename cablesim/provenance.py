"""What a result records about the run that made it: date, commit, machine, load.

The one place the benchmarks (``benchmarks/``), the thesis report (:mod:`cablesim.thesis`)
and the seed sweep (:mod:`cablesim.sweep`) take these lines from:

- :func:`utc_date`: ``2026-12-03 08:30 UTC``;
- :func:`git_commit`: the cablesim checkout's short commit, ``(with uncommitted changes)``
  added when tracked files differ from it, ``unknown`` outside a checkout;
- :func:`cpu_model`, :func:`machine`: CPU model, cores, platform and Python;
- :func:`float_platform`: architecture and CPU vendor, the machines whose floating point
  results agree bit for bit (MuJoCo, NumPy and Mesa's llvmpipe take vendor-specific SIMD
  paths: the same seed gave the same votes and last-digit-different floats and frames on an
  Intel Xeon and an AMD EPYC machine of this project);
- :func:`load_average`: the 1, 5 and 15 minute load averages;
- :func:`provenance`: all of them as one dict.
"""

from __future__ import annotations

import datetime as dt
import os
import platform
import subprocess
from pathlib import Path
from typing import Any

__all__ = [
    "cpu_model",
    "float_platform",
    "float_platforms",
    "git_commit",
    "load_average",
    "machine",
    "provenance",
    "utc_date",
]


def utc_date() -> str:
    """Now, to the minute, in UTC."""
    return dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what ``platform`` says, else unknown."""
    return _cpuinfo("model name") or platform.processor() or "unknown"


def _cpuinfo(key: str) -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(key):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def float_platform() -> str:
    """``x86_64 GenuineIntel``, ``x86_64 AuthenticAMD``: the architecture and the CPU vendor
    (``/proc/cpuinfo``'s ``vendor_id``; ``unknown`` where there is none). Runs repeat bit
    for bit on one machine; pinned result hashes are kept per platform."""
    return f"{platform.machine() or 'unknown'} {_cpuinfo('vendor_id') or 'unknown'}"


def float_platforms() -> tuple[str, ...]:
    """The names this machine's pinned results are looked up under, the most specific first:
    the platform with its CPU family (``x86_64 AuthenticAMD family 26``), then the platform
    alone (:func:`float_platform`).  One vendor's CPU generations can round differently: an
    AMD EPYC of family 26 gave other floats than the AMD machines the platform's pins came
    from, so a family pinned on its own is told apart, and one that is not uses its vendor's."""
    base = float_platform()
    family = _cpuinfo("cpu family")
    return (f"{base} family {family}", base) if family else (base,)


def machine() -> str:
    """CPU model, cores, platform and Python version, on one line."""
    return (
        f"{cpu_model()}, {os.cpu_count()} cores, {platform.platform()}, "
        f"python {platform.python_version()}"
    )


def load_average(digits: int = 2) -> str:
    """The 1, 5 and 15 minute load averages; ``unknown`` where the platform has none."""
    try:
        return " ".join(f"{x:.{digits}f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def git_commit() -> str:
    """The cablesim checkout's short commit, marked when tracked files have changes."""
    root = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=False,
        )
        if out.returncode != 0:
            return "unknown"
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=False,
        ).stdout.strip()
    except OSError:
        return "unknown"
    return out.stdout.strip() + (" (with uncommitted changes)" if dirty else "")


def provenance(**extra: Any) -> dict[str, Any]:
    """``date``, ``commit`` and ``machine`` of this run, then ``extra``."""
    return {"date": utc_date(), "commit": git_commit(), "machine": machine(), **extra}
