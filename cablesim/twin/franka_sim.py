"""A ``franka-sim`` server on 127.0.0.1 serving our Panda: the robot end of the digital twin.

    with FrankaSimServer(object_width=0.015) as server:     # started, ready for a client
        robot = FrankyPanda(server.host, T_world_camera, T_world_base, realtime=False)

franka-sim 1.1.7 speaks libfranka's protocol (arm on port 1337, gripper on 1338) but needs
mujoco 3.2 and numpy 1.26, which clash with this project's mujoco 4.0, so it runs as a
subprocess from its own environment: the Python named by ``$CABLESIM_FRANKA_SIM_PYTHON``, else
``.cache/franka-sim-venv/bin/python`` in the repository (see README "Real robot"), else this
interpreter if it can import ``franka_sim``.  The server is bound to 127.0.0.1 only (its command
line binds all interfaces, so it is started from Python) and exits on its own after
``lifetime`` seconds whatever happens to this process.  Its arm model is
:func:`~cablesim.twin.franka_sim_model.franka_sim_mjcf` (our Panda); its gripper is franka-sim's
kinematic hand with a virtual object of ``object_width`` between the fingers (a grasp stops
there and reports success).

:class:`FrankaSimUnavailable` (with the reason) is raised when the server environment is
missing or the ports are taken, so that callers (tests) can skip.
"""

from __future__ import annotations

import ipaddress
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from cablesim.errors import CablesimError, InputError
from cablesim.twin.franka_sim_model import franka_sim_mjcf


def _loopback_host() -> str:
    """``$CABLESIM_FRANKA_SIM_HOST`` (default 127.0.0.1), which must be a loopback address:
    several servers can run side by side on 127.0.0.2, 127.0.0.3, ... (one per test worker),
    each with libfranka's fixed ports, and none is ever reachable from another machine."""
    host = os.environ.get("CABLESIM_FRANKA_SIM_HOST", "127.0.0.1")
    try:
        loopback = ipaddress.IPv4Address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise InputError(
            f"CABLESIM_FRANKA_SIM_HOST: {host!r} is not a loopback address (127.0.0.0/8)"
        )
    return host


HOST = _loopback_host()  # loopback only, never anything else
PORTS = (1337, 1338)  # libfranka's arm and gripper ports (fixed by the protocol)
REPO = Path(__file__).resolve().parents[2]

_SCRIPT = """
import logging, os, signal, sys, threading
logging.basicConfig(level=logging.INFO, stream=sys.stdout,
                    format="%(asctime)s %(levelname)s %(name)s: %(message)s")
threading.Timer({lifetime}, lambda: os._exit(3)).start()  # never outlive the caller
from franka_sim import FrankaSimServer
{monitor}
{clock}

def _interrupt(*_):
    raise KeyboardInterrupt

signal.signal(signal.SIGTERM, _interrupt)
server = FrankaSimServer(host="{host}", enable_vis=False, enable_gripper=True,
                         gripper_object_width={object_width}, enforce_motion_limits={enforce},
                         joint_discontinuity_scale={joint_discontinuity_scale})
try:
    server.start()
except KeyboardInterrupt:
    pass
finally:
    close_trace()  # first: franka-sim's own stop can outlast the caller's patience on a busy host
    server.stop()
    os._exit(0)
"""


#: The cycle monitor, run inside the server process (franka-sim 1.1.7's own classes, wrapped):
#: every state-publish tick (``CommConstraintTracker.tick``, one per 1 ms cycle) is remembered
#: with whether the cycle it closed was lost (no answer from the client, so the server
#: extrapolated the motion generator), and every motion-limit violation
#: (``MotionLimitChecker.report``) is logged as one ``cablesim-cycles`` JSON line with what the
#: last :data:`MONITOR_WINDOW` cycles before it looked like.  With ``trace`` set, every tick
#: is also appended to a file (time, message id, active, lost) for the timing benchmark.
#: Where franka-sim's internals differ, the monitor logs that it is unavailable and records
#: nothing: :func:`host_timing` then never answers True.
_MONITOR = """
import collections, json, time
monitor_log = logging.getLogger("cablesim.cycles")
close_trace = lambda: None  # noqa: E731
try:
    from franka_sim import comm_constraints as _cc
    from franka_sim.limits import checker as _ck
    _tick, _report = _cc.CommConstraintTracker.tick, _ck.MotionLimitChecker.report
except (ImportError, AttributeError) as exc:
    monitor_log.warning("cablesim-cycles: unavailable (%s)", exc)
else:
    _recent = collections.deque(maxlen={window} + 1)
    # line-buffered: every cycle is on disk even if the process is killed
    _trace = open({trace!r}, "w", buffering=1) if {trace!r} else None

    def _monitored_tick(self, published_id):
        outcome = _tick(self, published_id)
        now = time.perf_counter()
        lost = bool(outcome.active and outcome.lost)
        _recent.append((now, lost))
        if _trace is not None:
            try:
                _trace.write(f"{{now:.6f}} {{published_id}} {{int(outcome.active)}} {{int(lost)}}\\n")
            except ValueError:  # closed: the server is shutting down
                pass
        return outcome

    def _monitored_report(self, violation, *, enforced):
        if violation.error_index not in getattr(self, "_logged", ()):
            ticks = list(_recent)
            record = dict(
                violation=violation.error_name,
                enforced=bool(enforced),
                lost_cycles=sum(lost for _, lost in ticks[1:]),
                span_ms=round((ticks[-1][0] - ticks[0][0]) * 1e3, 3) if len(ticks) > 1 else 0.0,
                cycles=len(ticks) - 1,
                time=time.perf_counter(),
            )
            monitor_log.info("cablesim-cycles: %s", json.dumps(record))
        return _report(self, violation, enforced=enforced)

    _cc.CommConstraintTracker.tick = _monitored_tick
    _ck.MotionLimitChecker.report = _monitored_report
    if _trace is not None:
        close_trace = _trace.close
"""

#: The server's clock in simulated time (``clock="lockstep"``, run inside the server process):
#: franka-sim paces its state stream to the wall clock and closes a cycle the client has not
#: answered within 1 ms as lost, extrapolating the motion generator across it, as the FCI does.
#: On a robot's realtime kernel a client never misses that window; on a shared machine without
#: one it does (``benchmarks/franka_sim_timing.py``), and the next real command, differenced
#: against the guess, trips a ``*_discontinuity`` reflex the motion never caused.  In lockstep
#: the publish loop's drain gate (``MotionSessionMixin._drain_gate``, which already holds a
#: state back until the answer to the last one is applied, for at most one period) holds it
#: for up to :data:`LOCKSTEP_WAIT` seconds instead: a cycle ends when the client has answered
#: it, so the robot's time (the state's ``message_id``, which libfranka reads as its clock in
#: ms) advances one cycle per answered state however late the host runs either process.  The
#: physics follows the same clock: franka-sim steps it in a thread of its own paced to the wall
#: clock, dropping steps when the host is slow, so the states a client saw depended on the
#: load; in lockstep it steps exactly once (1 ms) per state cycle, and the arm's motion is the
#: same whatever the load.  (Where a finished motion ends is the servo's stability on the
#: model, not the clock: see ``FRANKA_SIM_ARMATURE`` in :mod:`cablesim.twin.franka_sim_model`.)
#: Nothing else changes: every motion limit is still checked on every command, and a client
#: that stops answering for longer than the wait still loses cycles (20 in a row abort the
#: motion with ``communication_constraints_violation``).  Where franka-sim's internals differ,
#: the server logs that lockstep is unavailable and runs on the wall clock.
_LOCKSTEP = """
import threading as _threading, time as _time
try:
    import mujoco as _mujoco
    from franka_sim.server.motion_session import MotionSessionMixin as _Session
    from franka_sim.mujoco_franka_sim import MujocoFrankaSim as _Physics
    _gate = _Session._drain_gate
    assert abs(_Physics.__init__.__globals__["DEFAULT_DT"] - 0.001) < 1e-12
except (ImportError, AttributeError, KeyError, AssertionError) as exc:
    logging.getLogger("cablesim.clock").warning("cablesim-clock: lockstep unavailable (%s)", exc)
else:
    _clock_cycles = {{"published": 0, "stepped": 0}}
    _clock_cv = _threading.Condition()

    def _lockstep_gate(self, answer_deadline=0.0):
        waited = _gate(self, answer_deadline=answer_deadline + {wait})
        started = _time.perf_counter()
        with _clock_cv:  # one physics step (1 ms) per state cycle, however slow the host
            _clock_cycles["published"] += 1
            _clock_cv.notify_all()
            _clock_cv.wait_for(
                lambda: _clock_cycles["stepped"] >= _clock_cycles["published"], timeout={physics_wait}
            )
        return waited + (_time.perf_counter() - started)

    def _lockstep_physics(self):
        logging.getLogger("cablesim.clock").info("cablesim-clock: physics in lockstep")
        while self.running:
            with _clock_cv:
                due = _clock_cv.wait_for(
                    lambda: _clock_cycles["stepped"] < _clock_cycles["published"] or not self.running, 0.1
                )
            if not due or not self.running:
                continue
            self._read_and_publish_state()
            self._apply_control()
            _mujoco.mj_step(self.model, self.data)
            with _clock_cv:
                _clock_cycles["stepped"] += 1
                _clock_cv.notify_all()

    _Session._DRAIN_GATE_TIMEOUT = {wait}
    _Session._drain_gate = _lockstep_gate
    _Physics.run_simulation = _lockstep_physics
    logging.getLogger("cablesim.clock").info("cablesim-clock: lockstep (wait %.3f s)", {wait})
"""

#: Longest a lockstep server waits for the client's answer to a state (s) before it closes the
#: cycle as lost.  A loaded host can keep the client silent for longer than one expects: on
#: two cores with a CI run and three busy processes beside the robot tests (load 7.5), the
#: stalled client of ``test_franka_sim_clock`` lost 2 cycles in 14 runs with 0.25 s, each
#: after 252-258 ms of silence, and a CI run lost one the same way; 1 s leaves four times the
#: longest silence measured.  Only a client that died waits this long per cycle (20 such
#: cycles abort its motion, as before).
LOCKSTEP_WAIT = 1.0
#: Longest a lockstep server waits for the physics to take the step of a cycle (s): a state
#: never goes out ahead of the physics unless the physics thread is gone.
LOCKSTEP_PHYSICS_WAIT = 5.0
#: The server clocks :class:`FrankaSimServer` offers (``clock``).
CLOCKS = ("lockstep", "realtime")

#: Cycles the monitor looks back from a violation.
MONITOR_WINDOW = 3
#: A state stream slower than this over the monitor's window (ms for MONITOR_WINDOW cycles,
#: i.e. under a third of real time) counts as the server stalled by this host.
STALL_SPAN_MS = 10.0


@dataclass(frozen=True)
class CycleViolation:
    """One motion-limit violation as the server's cycle monitor saw it (see ``_MONITOR``)."""

    violation: str  # franka-sim's error name, e.g. "joint_motion_generator_velocity_discontinuity"
    enforced: bool  # whether it aborted the motion
    lost_cycles: int  # cycles lost (extrapolated by the server) among the last ``cycles``
    span_ms: float  # wall-clock time the last ``cycles`` state cycles took (1 ms each nominally)
    cycles: int
    time: float  # the server's perf_counter

    @property
    def host_timing(self) -> bool:
        """Whether this violation is the host's timing, not the motion: a motion-generator
        *discontinuity* (the only checks a late command can trip: libfranka documents that
        dropped packets "could trigger discontinuity errors") right after a cycle the server
        had to extrapolate, or after the state stream stalled to under a third of real time.
        Measured here (``benchmarks/franka_sim_timing.py``): 46 of 46 timing reflexes met
        this, against 17 % of ordinary cycle windows, so it can mislabel a genuine
        discontinuity; a genuine one comes back on every attempt, so a bounded retry on it
        still fails."""
        return self.violation.endswith("_discontinuity") and (
            self.lost_cycles > 0 or self.span_ms > STALL_SPAN_MS
        )


def parse_cycle_violations(log_text: str) -> list[CycleViolation]:
    """The monitor's ``cablesim-cycles`` records in a server log, oldest first."""
    out = []
    for line in log_text.splitlines():
        _, sep, payload = line.partition("cablesim-cycles: {")
        if sep:
            record = json.loads("{" + payload)
            out.append(CycleViolation(**record))
    return out


_STALLER = """
import os, random, signal, sys, time
pid, rng = int(sys.argv[1]), random.Random(int(sys.argv[2]))
lo, hi, gap_lo, gap_hi = map(float, sys.argv[3:7])
try:
    while True:
        time.sleep(rng.uniform(gap_lo, gap_hi))
        os.kill(pid, signal.SIGSTOP)
        time.sleep(rng.uniform(lo, hi))
        os.kill(pid, signal.SIGCONT)
except ProcessLookupError:
    pass
"""


class Stalls:
    """Stop a process (SIGSTOP) for ``stall`` seconds every ``every`` seconds (uniform ranges,
    seeded), as a hypervisor or a busy neighbour deschedules a process on a loaded machine:
    what such a host does at random, on demand.  A context manager; the process is always
    continued when it ends.

        with Stalls(os.getpid()):   # this process: the libfranka control thread misses cycles
            robot.move_relative(...)
    """

    def __init__(
        self,
        pid: int,
        seed: int = 7,
        stall: tuple[float, float] = (0.002, 0.012),
        every: tuple[float, float] = (0.05, 0.25),
    ) -> None:
        self.pid, self.seed, self.stall, self.every = pid, seed, stall, every
        self._proc: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> Stalls:
        args = [str(self.pid), str(self.seed), *map(str, (*self.stall, *self.every))]
        self._proc = subprocess.Popen([sys.executable, "-c", _STALLER, *args])
        return self

    def __exit__(self, *exc: object) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait()
            self._proc = None
        try:
            os.kill(self.pid, signal.SIGCONT)
        except ProcessLookupError:
            pass


class FrankaSimUnavailable(CablesimError, RuntimeError):
    """franka-sim cannot be started here (not installed, or its ports are taken)."""


def server_python() -> str | None:
    """The first Python that can import franka-sim (see the module docstring), or None."""
    candidates = [
        os.environ.get("CABLESIM_FRANKA_SIM_PYTHON", ""),
        str(REPO / ".cache" / "franka-sim-venv" / "bin" / "python"),
        str(Path.cwd() / ".cache" / "franka-sim-venv" / "bin" / "python"),
        sys.executable,
    ]
    for python in candidates:
        if not python or not Path(python).exists():
            continue
        probe = subprocess.run(
            [python, "-c", "import franka_sim.franka_sim_server"],
            capture_output=True,
            timeout=60,
            check=False,
        )
        if probe.returncode == 0:
            return python
    return None


def ports_free() -> bool:
    """Whether libfranka's ports are free on the server's loopback address (TCP and UDP).

    The TCP probe binds with ``SO_REUSEADDR``, as franka-sim's own listening sockets do: a
    server stopped while its client was still connected closes first and leaves its port in
    ``TIME_WAIT`` for a minute, which franka-sim binds over but a plain bind refuses (a run
    of robot tests right after one whose twin episode failed skipped 13 tests, "ports in
    use", with no server running).  A port another server listens on is still refused."""
    for port in PORTS:
        for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
            with socket.socket(socket.AF_INET, kind) as s:
                if kind == socket.SOCK_STREAM:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    s.bind((HOST, port))
                except OSError:
                    return False
    return True


#: The server's scheduling priority (nice value) where this process may raise it (root or
#: CAP_SYS_NICE): ahead of ordinary processes, so that a test run beside it on a small machine
#: does not starve it.  Starved for a second, it sends libfranka no state and the client fails
#: with ``UDP receive: Timeout`` (seen in a ``tests/robot`` loop beside a CI run, load 4.8 on
#: two cores: the twin's arm mid-motion, and the connection in ``test_franka_sim_clock``).
SERVER_NICENESS = -5


def _renice(pid: int, niceness: int) -> int | None:
    """Give process ``pid`` and its threads ``niceness``; the value set, or None where this
    process may not (then the server keeps the priority it inherited).  Set right after the
    process starts, before its Python creates threads (new threads inherit it); threads
    already there are set one by one (Linux's nice value is per thread)."""
    tasks = Path(f"/proc/{pid}/task")
    ids = [int(t.name) for t in tasks.iterdir()] if tasks.is_dir() else [pid]
    try:
        for tid in ids:
            os.setpriority(os.PRIO_PROCESS, tid, niceness)
    except (PermissionError, ProcessLookupError):
        return None
    return niceness


class FrankaSimServer:
    """A franka-sim server subprocess on 127.0.0.1 (module docstring); a context manager.

    ``object_width``: the virtual object between the fingers (m), None for an empty hand.
    ``enforce_motion_limits``: abort motions that break the FCI limits with a reflex, as the
    robot does.  Timing-induced reflexes (a loaded machine misses control cycles, which the
    server extrapolates into velocity discontinuities) make long motion sequences flaky on a
    shared CPU; the digital-twin tests switch it off (limits are still checked and logged).
    ``joint_discontinuity_scale``: franka-sim judges the joint-side discontinuity of Cartesian
    commands on its own differential IK of each commanded pose, which trips at the end of
    ordinary slow motions on this model, so that one check is loosened by default.
    ``trace``: a file the server appends every state cycle to (``time message_id active
    lost``), line by line as the cycles pass (closed before franka-sim's own stop); for
    ``benchmarks/franka_sim_timing.py``.
    ``clock``: ``"lockstep"`` (default: a cycle ends when the client has answered it, so a
    host that runs either process late slows the robot's time down instead of losing cycles;
    see ``_LOCKSTEP``) or ``"realtime"`` (franka-sim's own 1 kHz wall-clock pacing, where a
    late client loses cycles as on the robot; for measuring this host's timing).
    ``niceness``: the server's nice value where permitted (``SERVER_NICENESS``; None leaves
    it as inherited); ``niceness_applied`` says what was set.
    :meth:`cycle_violations` reads the cycle monitor's record of every motion-limit violation
    (``_MONITOR``), which tells a reflex caused by this host's timing from one caused by the
    motion (:attr:`CycleViolation.host_timing`).
    """

    #: the server process's script (a format string; see ``_SCRIPT``)
    script = _SCRIPT

    def __init__(
        self,
        object_width: float | None = 0.015,
        enforce_motion_limits: bool = True,
        joint_discontinuity_scale: float = 3.0,
        lifetime: float = 600.0,
        startup_timeout: float = 60.0,
        stop_timeout: float = 20.0,
        workdir: str | os.PathLike[str] | None = None,
        trace: str | os.PathLike[str] | None = None,
        clock: str = "lockstep",
        niceness: int | None = SERVER_NICENESS,
    ) -> None:
        if clock not in CLOCKS:
            raise InputError(f"clock: {clock!r} is not one of {', '.join(CLOCKS)}")
        self.clock = clock
        self.niceness = niceness
        self.niceness_applied: int | None = None  # what start() could set (None: nothing)
        self.object_width = object_width
        self.enforce_motion_limits = bool(enforce_motion_limits)
        self.joint_discontinuity_scale = float(joint_discontinuity_scale)
        self.lifetime = float(lifetime)
        self.startup_timeout = float(startup_timeout)
        self.stop_timeout = float(stop_timeout)
        self._workdir = None if workdir is None else Path(workdir)
        self.trace = None if trace is None else Path(trace)
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.proc: subprocess.Popen[bytes] | None = None
        self.log: Path | None = None
        self._log_text = ""  # kept when the working directory is removed

    @property
    def host(self) -> str:
        return HOST

    def start(self) -> FrankaSimServer:
        """Start the server and wait until it accepts a client; raises
        :class:`FrankaSimUnavailable` when it cannot run here, ``RuntimeError`` when it died."""

        python = server_python()
        if python is None:
            raise FrankaSimUnavailable(
                "franka-sim is not installed: see README 'Real robot' "
                "(.cache/franka-sim-venv or $CABLESIM_FRANKA_SIM_PYTHON)"
            )
        if not ports_free():
            raise FrankaSimUnavailable(
                f"ports {PORTS} on {HOST} are in use (another franka-sim server?)"
            )
        if self._workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="cablesim-franka-sim-")
            work = Path(self._tmp.name)
        else:
            work = self._workdir
            work.mkdir(parents=True, exist_ok=True)
        model = work / "panda.xml"
        model.write_text(franka_sim_mjcf())
        script = work / "serve.py"
        script.write_text(
            self.script.format(
                lifetime=self.lifetime,
                host=HOST,
                object_width=self.object_width,
                enforce=self.enforce_motion_limits,
                joint_discontinuity_scale=self.joint_discontinuity_scale,
                monitor=_MONITOR.format(
                    window=MONITOR_WINDOW, trace=str(self.trace) if self.trace else ""
                ),
                clock=_LOCKSTEP.format(wait=LOCKSTEP_WAIT, physics_wait=LOCKSTEP_PHYSICS_WAIT)
                if self.clock == "lockstep"
                else "",
            )
        )
        self.log = work / "server.log"
        env = dict(os.environ, FR3_MJCF=str(model), MUJOCO_GL="egl")
        with open(self.log, "wb") as out:
            self.proc = subprocess.Popen(
                [python, str(script)],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                cwd=work,
                start_new_session=True,
            )
        if self.niceness is not None:
            self.niceness_applied = _renice(self.proc.pid, self.niceness)
        deadline = time.monotonic() + self.startup_timeout
        while "Server ready for new client connection" not in self.log_text():
            if self.proc.poll() is not None:
                code = self.proc.returncode
                text = self.log_text()[-3000:]
                self.stop()
                raise RuntimeError(f"franka-sim exited ({code}):\n{text}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"franka-sim did not start in {self.startup_timeout:.0f} s")
            time.sleep(0.1)
        return self

    def log_text(self) -> str:
        """The server's output so far (also after it stopped)."""
        if self.log is not None and self.log.exists():
            self._log_text = self.log.read_text(errors="replace")
        return self._log_text

    def cycle_violations(self) -> list[CycleViolation]:
        """Every motion-limit violation the server's cycle monitor logged so far."""
        return parse_cycle_violations(self.log_text())

    def running_clock(self, timeout: float = 10.0) -> str:
        """The clock the server reported it runs on: ``"lockstep"`` or ``"realtime"`` (also
        where lockstep was asked for but franka-sim's internals did not allow it).  The
        physics thread reports lockstep when it starts, which can come after "Server ready"
        on a loaded host (a robot test once read the log in between and saw no lockstep), so
        a server that installed lockstep is given up to ``timeout`` s to report it."""
        deadline = time.monotonic() + timeout
        while True:
            text = self.log_text()
            installed = "cablesim-clock: lockstep (" in text
            if installed and "physics in lockstep" in text:
                return "lockstep"
            if not installed or time.monotonic() > deadline:
                return "realtime"
            if self.proc is not None and self.proc.poll() is not None:
                return "realtime"
            time.sleep(0.05)

    def stop(self) -> None:
        """Interrupt the server (SIGINT, then SIGKILL after ``stop_timeout``)."""
        proc = self.proc
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(self.stop_timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        self.log_text()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> FrankaSimServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
