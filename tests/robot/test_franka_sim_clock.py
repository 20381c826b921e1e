"""The franka-sim server's clock: why the robot tests no longer fail at random.

A late client (libfranka's control thread in this process, descheduled by a loaded host) loses
control cycles on franka-sim's wall clock; the server extrapolates the motion generator across
them, and the next real command trips a ``*_discontinuity`` reflex.  The test server runs in
lockstep instead (``FrankaSimServer(clock="lockstep")``): a cycle ends when the client has
answered it.  Both clocks are run here with this process stopped for 2-12 ms every 50-250 ms
(:class:`~cablesim.twin.franka_sim.Stalls`), so the fault is provoked, not waited for.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.twin.episode import FRANKA_SIM_ROBOT
from cablesim.twin.franka_sim import (
    HOST,
    LOCKSTEP_WAIT,
    SERVER_NICENESS,
    FrankaSimServer,
    FrankaSimUnavailable,
    Stalls,
    parse_cycle_violations,
)

T_WORLD_BASE = np.eye(4)
T_WORLD_CAMERA = np.array(
    [[0, 0, -1, 1.2], [1, 0, 0, 0.0], [0, -1, 0, 0.6], [0, 0, 0, 1]], dtype=float
)
#: Four short horizontal world-frame strokes and back: about 5 s of motion under the stalls.
STROKES = [np.array(d) for d in ([0, -0.03, 0], [0, 0.03, 0], [0.03, 0, 0], [-0.03, 0, 0])]


def _session(clock: str, work) -> tuple[list, int, str, list[float]]:
    """Home, then the strokes with this process stalled; (results, lost cycles, server log,
    the length of each lost cycle in s)."""
    pytest.importorskip("franky", reason="franky-control is not installed (the 'real' extra)")
    trace = work / "cycles.txt"
    server = FrankaSimServer(
        object_width=0.02,
        enforce_motion_limits=True,
        lifetime=240.0,
        workdir=work,
        trace=trace,
        clock=clock,
    )
    try:
        server.start()
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))
    try:
        assert server.running_clock() == clock
        robot = FrankyPanda(HOST, T_WORLD_CAMERA, T_WORLD_BASE, **FRANKA_SIM_ROBOT)
        try:
            home = robot.home(0.5)  # before the stalls
            assert home, home.reason
            with Stalls(os.getpid(), seed=11):
                results = [robot.move_relative(d, "world", speed=0.1) for d in STROKES]
        finally:
            robot.close()
    finally:
        server.stop()
    # time, message id, active, lost: one row per state franka-sim published (it publishes
    # while a motion runs, so a session whose motions a reflex cut short has fewer rows:
    # 863 seen on the wall clock); the motions' cycles must be there
    ticks = np.loadtxt(trace, ndmin=2)
    assert ticks.shape[1:] == (4,) and ticks[:, 2].sum() > 100, (
        ticks.shape,
        server.log_text()[-3000:],
    )
    # the length of each lost cycle: the time from the state before it to the state closing it
    silences = [float(ticks[i, 0] - ticks[i - 1, 0]) for i in np.nonzero(ticks[1:, 3])[0] + 1]
    return results, int(ticks[:, 3].sum()), server.log_text(), silences


def test_a_stalled_client_loses_cycles_on_the_wall_clock(tmp_path) -> None:
    """The fault, provoked: on franka-sim's own clock the stalled client misses cycles (the
    server extrapolates them; measured: 17 of 18 motions then aborted by a reflex)."""
    results, lost, _, _ = _session("realtime", tmp_path)
    assert lost > 0, [r.reason for r in results]


def test_in_lockstep_a_stalled_client_loses_no_cycle_and_no_motion(tmp_path) -> None:
    """The remedy: the same stalls in lockstep lose no cycle, log no violation and abort no
    motion."""
    results, lost, log, silences = _session("lockstep", tmp_path)
    # every motion ran to its end and the arm stands at its target (franka-sim's servo is
    # stable on the model it is given, FRANKA_SIM_ARMATURE: measured 0.3-0.4 mm here); a
    # failure shows the lost cycles and franka-sim's own violation lines (value and limit), so
    # that a rare abort (1 in 30 runs on a loaded host) names its cause
    violations = [line for line in log.splitlines() if "violat" in line]
    starved = [s for s in silences if s >= LOCKSTEP_WAIT]
    cycle_violations = parse_cycle_violations(log)
    if (
        not all(results)
        and starved
        and len(starved) == lost
        and cycle_violations
        and all(v.host_timing for v in cycle_violations)
    ):
        # the host kept the client silent for longer than the wait (a lost cycle the server
        # had to extrapolate, which is what the wall clock does on every late answer) and
        # every violation is a discontinuity right after such a cycle: the remedy's
        # precondition failed, so this run cannot judge it.  Ordinary motion stays
        # far inside the limits: the strokes' largest IK jerk is 2920 rad/s^3 on joint 4 in
        # every run (limit 15000), bit for bit idle or loaded.
        pytest.skip(
            f"the host starved the client for {max(starved):.2f} s >= LOCKSTEP_WAIT "
            f"({LOCKSTEP_WAIT} s), {lost} cycle(s) lost: {violations[-3:]}"
        )
    # the short facts first (pytest cuts a long message): whether the host starved the client,
    # and whether franka-sim timed each violation as a host stall
    assert all(results), (
        f"lost {lost}, starved {starved}, longest silences {sorted(silences)[-3:]}, "
        f"violations timed by the host {[v.host_timing for v in cycle_violations]}",
        [r.reason for r in results],
        violations[-20:],
    )
    assert max(r.position_error for r in results) < 0.002, [r.position_error for r in results]
    # a lockstep cycle is lost only when the client stays silent for the whole LOCKSTEP_WAIT:
    # none of the provoked 2-12 ms stalls may cost one (a host that starves the client for
    # longer is out of the remedy's reach, and the trace shows it: the silence before each
    # lost cycle)
    assert lost == len(silences)
    assert all(s >= LOCKSTEP_WAIT for s in silences), (lost, silences)
    assert cycle_violations == []


def test_an_unknown_clock_is_refused() -> None:
    with pytest.raises(InputError, match="clock: 'wall'"):
        FrankaSimServer(clock="wall")


def test_a_port_left_in_time_wait_is_free_and_a_listening_one_is_not() -> None:
    """A server stopped under a connected client leaves its port in TIME_WAIT (the server
    side closed first); franka-sim binds over that, so the probe must not call it in use."""
    import socket

    from cablesim.twin.franka_sim import PORTS, ports_free

    if not ports_free():
        pytest.skip(f"ports {PORTS} on {HOST} are in use")
    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((HOST, PORTS[0]))
        listener.listen(1)
        assert not ports_free()  # a server listens there
        with socket.create_connection((HOST, PORTS[0])) as client:
            conn, _ = listener.accept()
            conn.close()  # the server's side closes first: its port goes to TIME_WAIT
            client.recv(1)
    assert ports_free()


def test_the_clock_is_read_once_the_physics_thread_reports_it(tmp_path) -> None:
    """ "Server ready" can be logged before the physics thread reports lockstep (a loaded host
    once showed a robot test that gap); ``running_clock`` waits for the report."""
    import threading

    server = FrankaSimServer()
    server.log = tmp_path / "server.log"
    server.log.write_text("cablesim-clock: lockstep (wait 0.250 s)\nServer ready for new client\n")

    def physics_starts() -> None:
        with server.log.open("a") as f:
            f.write("cablesim-clock: physics in lockstep\n")

    later = threading.Timer(0.5, physics_starts)
    later.start()
    try:
        assert server.running_clock() == "lockstep"
    finally:
        later.join()
    server.log.write_text("Server ready for new client\n")  # franka-sim's own clock
    assert server.running_clock(timeout=0.1) == "realtime"


def _may_raise_priority() -> bool:
    """Whether this process may give a child a negative nice value (root or CAP_SYS_NICE)."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, os.getpriority(os.PRIO_PROCESS, 0) - 1)
    except PermissionError:
        return False
    os.setpriority(os.PRIO_PROCESS, 0, os.getpriority(os.PRIO_PROCESS, 0) + 1)
    return True


def test_the_server_runs_ahead_of_ordinary_processes_where_permitted(tmp_path) -> None:
    """Every thread of franka-sim gets ``SERVER_NICENESS`` (the threads it starts after the
    renice inherit it), or, where this process may not raise a priority, nothing is set."""
    server = FrankaSimServer(object_width=None, lifetime=60.0, workdir=tmp_path)
    try:
        server.start()
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))
    try:
        tasks = sorted((Path("/proc") / str(server.proc.pid) / "task").iterdir())
        nice = {int(t.name): os.getpriority(os.PRIO_PROCESS, int(t.name)) for t in tasks}
    finally:
        server.stop()
    if not _may_raise_priority():
        assert server.niceness_applied is None
        return
    assert server.niceness_applied == SERVER_NICENESS < 0
    assert len(nice) > 1 and set(nice.values()) == {SERVER_NICENESS}, nice
