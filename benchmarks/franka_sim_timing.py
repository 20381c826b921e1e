"""Why the robot tests against franka-sim see reflexes on this machine: the host's timing.

    .venv/bin/python -m benchmarks.franka_sim_timing [--rounds 6] [--load] [--write]
    .venv/bin/python -m benchmarks.franka_sim_timing --server switch-interval   # a remedy
    .venv/bin/python -m benchmarks.franka_sim_timing --client libfranka         # the old client

Two measurements, in one run:

1. **Wake-up lateness of this host**: a thread sleeping to absolute 1 ms deadlines (5000
   cycles), at the normal policy and, where the process may, at ``SCHED_FIFO`` 90: how late it
   wakes (median, p99, p99.9, max, share over 0.5 ms).  A 1 kHz control loop needs every one.
2. **A franka-sim session**: the server (every motion limit enforced, its cycle monitor
   tracing every state cycle) and :class:`~cablesim.robot.franky_panda.FrankyPanda` running
   ``--rounds`` times the motions of ``tests/robot/test_franky_panda.py`` (home, a Cartesian
   move, two relative moves, home, a joint move), without the tests' retry: the motions the
   robot aborted, the state-publish intervals, the cycles the client did not answer in time
   (the server extrapolated them), for each reflex the cycles since the last lost cycle and
   what the cycle monitor made of it (``CycleViolation.host_timing``), and how often an
   ordinary window of three cycles would meet that rule.

``--clock``: ``realtime`` (franka-sim's own wall-clock pacing: a late client loses cycles) or
``lockstep`` (the server's default in cablesim: a cycle ends when the client answered it).
``--server``: ``default``, ``switch-interval`` (the server's GIL switch interval 0.2 ms instead
of 5 ms), ``fifo`` (the server at ``SCHED_FIFO`` 50), ``pinned`` (server on CPU 0, client on
CPU 1).  ``--client``: ``adapter`` (the calling thread keeps its policy, libfranka's goes to the
control thread) or ``libfranka`` (the calling thread left at libfranka's ``SCHED_FIFO`` 99, as
before).  ``--load``: two busy processes beside it.  ``--stall client|server``: that process
stopped for 2-12 ms every 50-250 ms (:class:`~cablesim.twin.franka_sim.Stalls`), the descheduling a loaded host does at
random, on demand.  ``--write`` appends the run to
``benchmarks/results/franka_sim_timing.md``.  Needs the franka-sim environment (README "Real
robot").
"""

from __future__ import annotations

import argparse
import datetime
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import RESULTS
from cablesim import provenance as pv
from cablesim.panda import HOME_QPOS
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.twin.franka_sim import (
    HOST,
    MONITOR_WINDOW,
    STALL_SPAN_MS,
    FrankaSimServer,
    Stalls,
)

OUT = RESULTS / "franka_sim_timing.md"
SERVER_PRELUDES = {
    "default": "",
    "switch-interval": "import sys\nsys.setswitchinterval(0.0002)\n",
    "fifo": "os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))\n",
    "pinned": "os.sched_setaffinity(0, [0])\n",
}
# the test file's frames: a base neither at the origin nor aligned, a camera looking along -x
_c, _s = np.cos(0.5), np.sin(0.5)
T_WORLD_BASE = np.array([[_c, -_s, 0, 0.3], [_s, _c, 0, -0.2], [0, 0, 1, 0.05], [0, 0, 0, 1]])
T_WORLD_CAMERA = np.array(
    [[0, 0, -1, 1.2], [1, 0, 0, 0.0], [0, -1, 0, 0.6], [0, 0, 0, 1]], dtype=float
)


def wake_lateness(policy: str, cycles: int = 5000) -> dict[str, float] | None:
    """Lateness (us) of a thread sleeping to absolute 1 ms deadlines; None where the policy
    is not allowed."""
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    if policy == "fifo":
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(90))
        except PermissionError:
            return None
    try:
        late = np.empty(cycles)
        deadline = time.perf_counter()
        for i in range(cycles):
            deadline += 0.001
            remaining = deadline - time.perf_counter()
            if remaining > 0:
                time.sleep(remaining)
            late[i] = (time.perf_counter() - deadline) * 1e6
    finally:
        os.sched_setscheduler(0, *before)
    return {
        "median": float(np.median(late)),
        "p99": float(np.percentile(late, 99)),
        "p99.9": float(np.percentile(late, 99.9)),
        "max": float(late.max()),
        "over_0.5ms_pct": float(np.mean(late > 500) * 100),
    }


def steal_jiffies() -> int:
    """Time the hypervisor ran something else on this VM's CPUs (``/proc/stat`` steal)."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()
    return int(fields[8]) if len(fields) > 8 else 0


def motions(robot: FrankyPanda, rounds: int) -> list[tuple[str, str]]:
    """The test file's motions, ``rounds`` times; (motion, reason) of each one aborted."""
    failed = []
    for _ in range(rounds):
        for name, run in (
            ("home", lambda: robot.home(0.5)),
            ("cartesian", lambda: robot.move_to(robot.ee_pose().translated([0.05, 0.03, -0.05]))),
            ("relative tcp", lambda: robot.move_relative(np.array([0, 0, 0.04]), "tcp")),
            ("relative world", lambda: robot.move_relative(np.array([0, -0.03, 0]), "world")),
            ("home", lambda: robot.home(0.5)),
            (
                "joint",
                lambda: robot.move_joints(
                    np.asarray(HOME_QPOS) + np.array([0.2, -0.1, 0.1, 0.15, 0.0, -0.1, 0.3])
                ),
            ),
        ):
            result = run()
            if not result:
                failed.append((name, result.reason.replace("\n", " ")))
    return failed


def session(args: argparse.Namespace, work: Path) -> dict[str, object]:
    class Server(FrankaSimServer):
        script = FrankaSimServer.script.replace(
            "from franka_sim import FrankaSimServer\n",
            "from franka_sim import FrankaSimServer\n" + SERVER_PRELUDES[args.server],
        )

    trace = work / "cycles.txt"
    server = Server(
        object_width=0.02,
        enforce_motion_limits=True,
        lifetime=900,
        workdir=work,
        trace=trace,
        clock=args.clock,
    )
    server.start()
    assert server.running_clock() == args.clock, server.log_text()[-2000:]
    if args.server == "pinned":
        os.sched_setaffinity(0, [1])
    stalls = None
    if args.stall != "none":
        stalls = Stalls(os.getpid() if args.stall == "client" else server.proc.pid).__enter__()
    steal0, t0 = steal_jiffies(), time.monotonic()
    try:
        robot = FrankyPanda(
            HOST,
            T_WORLD_CAMERA,
            T_WORLD_BASE,
            realtime=False,
            position_tolerance=0.01,
            rotation_tolerance=0.05,
            joint_tolerance=0.02,
            motion_timeout=15.0,
        )
        if args.client == "libfranka":
            os.sched_setscheduler(0, *robot._scheduling.control)
        failed = motions(robot, args.rounds)
        robot.close()
    finally:
        if stalls is not None:
            stalls.__exit__()
        server.stop()
    seconds = time.monotonic() - t0
    steal = (steal_jiffies() - steal0) / os.sysconf("SC_CLK_TCK")
    ticks = np.loadtxt(trace, ndmin=2)  # time, message id, active, lost
    active = ticks[:, 2] > 0
    lost = ticks[:, 3] > 0
    gaps = np.diff(ticks[:, 0]) * 1e3
    W = MONITOR_WINDOW
    since, labelled = [], []
    for v in server.cycle_violations():
        i = int(np.searchsorted(ticks[:, 0], v.time))
        before = np.flatnonzero(lost[max(0, i - 100) : i])
        since.append(int(min(i, 100) - before[-1]) if len(before) else None)
        labelled.append(v.host_timing)
    idx = np.flatnonzero(active)
    idx = idx[idx > W][::5]
    span = (ticks[idx, 0] - ticks[idx - W, 0]) * 1e3
    window_hits = np.array([lost[i - W + 1 : i + 1].any() for i in idx]) | (span > STALL_SPAN_MS)
    return {
        "motions": 6 * args.rounds,
        "failed": failed,
        "publish_ms": {
            "median": float(np.median(gaps)),
            "p99": float(np.percentile(gaps, 99)),
            "max": float(gaps.max()),
        },
        "active_cycles": int(active.sum()),
        "lost_cycles": int(lost.sum()),
        "violations": len(labelled),
        "host_timing": int(sum(labelled)),
        "cycles_since_lost": since,
        "window_rate_pct": float(window_hits.mean() * 100) if len(idx) else float("nan"),
        "steal_pct": float(steal / seconds / os.cpu_count() * 100),
    }


def report(args: argparse.Namespace, wake: dict[str, object], run: dict[str, object]) -> str:
    pub = run["publish_ms"]
    lines = [
        f"## {datetime.date.today()}: server {args.server}, {args.clock} clock, "
        f"client {args.client}"
        f"{', 2 busy processes beside it' if args.load else ''}"
        f"{f', the {args.stall} stalled 2-12 ms every 50-250 ms' if args.stall != 'none' else ''}",
        "",
        f"{pv.machine()}, commit {pv.git_commit()}, `{' '.join(sys.argv[1:]) or '(defaults)'}`",
        "",
        "| wake-up lateness of a 1 ms sleep (us) | median | p99 | p99.9 | max | > 0.5 ms |",
        "|---|---|---|---|---|---|",
    ]
    for policy, w in wake.items():
        if w is None:
            lines.append(f"| {policy} | not allowed here | | | | |")
        else:
            lines.append(
                f"| {policy} | {w['median']:.0f} | {w['p99']:.0f} | {w['p99.9']:.0f} | "
                f"{w['max']:.0f} | {w['over_0.5ms_pct']:.1f} % |"
            )
    lost_pct = run["lost_cycles"] / max(run["active_cycles"], 1) * 100
    lines += [
        "",
        f"- motions aborted: **{len(run['failed'])} of {run['motions']}**",
        f"- state-publish interval (ms; 1.0 nominal): median {pub['median']:.2f}, "
        f"p99 {pub['p99']:.1f}, max {pub['max']:.1f}",
        f"- cycles lost (extrapolated by the server): {run['lost_cycles']} of "
        f"{run['active_cycles']} during motions ({lost_pct:.2f} %)",
        f"- CPU time stolen by the hypervisor during the session: {run['steal_pct']:.1f} %",
        f"- violations logged: {run['violations']}, of which the cycle monitor calls "
        f"{run['host_timing']} host timing; cycles from the last lost cycle to each: "
        f"{run['cycles_since_lost']} (None: no lost cycle in the 100 before)",
        f"- ordinary {MONITOR_WINDOW}-cycle windows during motions that meet the host-timing "
        f"rule: {run['window_rate_pct']:.1f} %",
    ]
    for name, reason in run["failed"]:
        lines.append(f"  - {name}: {reason[-170:]}")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--server", choices=sorted(SERVER_PRELUDES), default="default")
    ap.add_argument("--client", choices=["adapter", "libfranka"], default="adapter")
    ap.add_argument(
        "--clock",
        choices=["realtime", "lockstep"],
        default="realtime",
        help="the server's clock (FrankaSimServer's clock): franka-sim's wall-clock pacing, "
        "or cycles that end when the client answered",
    )
    ap.add_argument("--load", action="store_true", help="two busy processes beside the run")
    ap.add_argument(
        "--stall",
        choices=["none", "client", "server"],
        default="none",
        help="stop that process for 2-12 ms every 50-250 ms (twin.franka_sim.Stalls)",
    )
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    busy = []
    if args.load:
        busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        wake = {policy: wake_lateness(policy) for policy in ("normal", "fifo")}
        with tempfile.TemporaryDirectory(prefix="cablesim-timing-") as work:
            run = session(args, Path(work))
    finally:
        for p in busy:
            p.kill()
    text = report(args, wake, run)
    print(text)
    if args.write:
        head = (
            ""
            if OUT.exists()
            else "# franka-sim and this host's timing\n\n"
            + (
                "Written by `python -m benchmarks.franka_sim_timing` (its docstring says what is "
                "measured).\n\n"
            )
        )
        with open(OUT, "a") as f:
            f.write(head + text + "\n")
        print(f"appended to {OUT}")


if __name__ == "__main__":
    main()
