import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))


def pytest_terminal_summary(terminalreporter, exitstatus, config):  # noqa: ARG001
    """List the franka-sim motions retried because this host missed control cycles."""
    host_timing = sys.modules.get("host_timing")
    if host_timing is None:
        return
    retries = host_timing.RETRIES
    terminalreporter.write_sep("-", f"franka-sim host-timing retries: {len(retries)}")
    for r in retries:
        v = ", ".join(
            f"{x.violation} (lost {x.lost_cycles}, {x.span_ms:.1f} ms)" for x in r.violations
        )
        terminalreporter.write_line(f"{r.test} {r.motion}: {v}")
