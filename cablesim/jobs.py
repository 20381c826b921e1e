"""Scene-by-scene jobs run in parallel: local worker processes or a Ray cluster, same results.

    jobs = [Job("thesis.interaction", f"interaction-s{s:06d}-p1", {"seed": s, ...}) for s in seeds]
    summary = execute(jobs, "runs/thesis/results", workers=2)            # local processes
    summary = execute(jobs, "runs/thesis/results", ray="auto")           # a Ray cluster
    print(summary.report())                                              # failures by outcome

A :class:`Job` names a runner (``kind``, a key of :data:`RUNNERS`: ``module:function``), a
file stem (``key``) and JSON-able parameters.  The runner gets ``(params, out_dir)`` and returns
``{"status": "ok"|"failed", "outcome": str, "result": {...}}`` (plus optional ``"timings"``);
an exception inside it becomes a failed job with the exception's class as its outcome, so one
bad scene never stops a run.  Each finished job is written at once, atomically, to
``out_dir/<key>.json`` by the driver (timings go to ``out_dir/timings.jsonl`` instead, so the
result files of a local and a Ray run are byte for byte the same); jobs whose file exists are
skipped (resumable).  Aggregates are recomputed from the files (:func:`load_results`).

Interrupted runs lose nothing: a job is finished exactly when its result file exists (written
last, after every data file the runner wrote), so a run killed at any point and started again
redoes the unfinished jobs and gives the same result files, byte for byte, as one that never
stopped.  Runners that write data files write them into a staging folder and move them into
place when complete (:func:`cablesim.files.staged`), replacing what an unfinished earlier run
left.  :func:`execute` holds ``out_dir/.lock`` (:class:`cablesim.files.OutputLock`: a second
process writing there is refused with ``OutputBusyError``), removes the temporary files and the
cut-off last line of ``timings.jsonl`` that a killed run left, and stops (``DiskFullError``
naming the file) when the disk is full, without recording the job that hit it.  Worker
processes die with the process that started them, so a killed run leaves none writing on.

Local runs use a ``ProcessPoolExecutor`` with the ``spawn`` start method (each worker builds
its own MuJoCo and GL context; ``workers <= 1`` runs in this process).  ``ray`` is ``"auto"``
(an existing cluster), an address (``ray://host:10001`` or ``host:6379``) or ``"local"`` (a
fresh local instance with ``workers`` CPUs); the worker processes import cablesim, so the
cluster's image must have it installed, and runners that write data files (datasets) need
``out_dir`` on storage every node sees.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import multiprocessing as mp
import os
import signal
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from cablesim.errors import ConfigError, DiskFullError, InputError
from cablesim.files import (
    OutputLock,
    append_line,
    drop_partial_last_line,
    remove_tmp_files,
    write_text,
)
from cablesim.jsonutil import json_default

#: kind -> "module:function" of the runner (imported in the worker)
RUNNERS: dict[str, str] = {
    "thesis.interaction": "cablesim.thesis.scene:run_interaction",
    "thesis.explore": "cablesim.thesis.scene:run_exploration",
    "thesis.clip": "cablesim.thesis.scene:run_clip",
    "dataset.movingcables": "cablesim.dataset.generate:run_movingcables",
    "dataset.mcor": "cablesim.dataset.generate:run_mcor",
    "test.echo": "cablesim.jobs:echo",
}


@dataclass(frozen=True)
class Job:
    kind: str
    key: str
    params: dict[str, Any] = field(default_factory=dict)

    def validate(self) -> Job:
        if self.kind not in RUNNERS:
            raise ConfigError("job.kind", f"unknown job kind {self.kind!r}; known: {list(RUNNERS)}")
        if not self.key or any(c in self.key for c in "/\\ ") or self.key.startswith("."):
            raise ConfigError("job.key", f"{self.key!r} is not a usable file name")
        return self


def echo(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """A trivial runner (tests of the executors): returns its parameters, fails on request;
    ``pid_file``: write the worker's process id there first; ``sleep``: then wait that many
    seconds; ``done_file``: then write that file; ``disk_full``: raise ``DiskFullError`` naming
    that path."""
    if params.get("pid_file"):
        write_text(params["pid_file"], str(os.getpid()))
    if params.get("sleep"):
        time.sleep(float(params["sleep"]))
    if params.get("done_file"):
        write_text(params["done_file"], "done")
    if params.get("disk_full"):
        raise DiskFullError(params["disk_full"], "asked to")
    if params.get("raise"):
        raise InputError(f"asked to fail: {params['raise']}")
    if params.get("fail"):
        return {"status": "failed", "outcome": str(params["fail"]), "result": {}}
    return {"status": "ok", "outcome": "ok", "result": {"value": params.get("value"), "pid": 0}}


def _resolve(kind: str) -> Callable[[dict[str, Any], str], dict[str, Any]]:
    module, name = RUNNERS[kind].split(":")
    return getattr(importlib.import_module(module), name)


def run_job(job: Job, out_dir: str) -> dict[str, Any]:
    """Run one job where it is called (a worker): a result record, never an exception."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        out = _resolve(job.kind)(dict(job.params), str(out_dir))
        status = out.get("status", "ok")
        record = {
            "status": status,
            "outcome": out.get("outcome", "ok" if status == "ok" else "failed"),
            "result": out.get("result", {}),
        }
        timings = dict(out.get("timings", {}))
    except DiskFullError as e:  # not an outcome of the scene: the run stops (``execute``)
        record = {
            "status": "failed",
            "outcome": e.outcome,
            "result": {"error": str(e), "path": e.path, "detail": e.detail},
            "stop": True,
        }
        timings = {}
    except Exception as e:  # noqa: BLE001 - a failed scene is an outcome, not a crash
        record = {
            "status": "failed",
            "outcome": type(e).__name__,
            "result": {"error": str(e)[:2000], "traceback": traceback.format_exc()[-4000:]},
        }
        timings = {}
    timings["wall_s"] = time.perf_counter() - t0
    timings["cpu_s"] = time.process_time() - c0
    return {"key": job.key, "kind": job.kind, "params": job.params, **record, "timings": timings}


def result_path(out_dir: str | Path, job: Job) -> Path:
    return Path(out_dir) / f"{job.key}.json"


def read_result(path: Path) -> dict[str, Any] | None:
    """A finished job's record, or None when missing or unreadable (then it runs again)."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return doc if isinstance(doc, dict) and "status" in doc else None


def write_result(out_dir: str | Path, record: dict[str, Any]) -> Path:
    """Write a record returned by :func:`run_job` atomically (timings to ``timings.jsonl``,
    one line per run of a job: they differ from run to run and are never compared)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec = {k: v for k, v in record.items() if k not in ("timings", "stop")}
    path = out / f"{record['key']}.json"
    write_text(path, json.dumps(rec, indent=1, sort_keys=True, default=json_default) + "\n")
    append_line(
        out / "timings.jsonl", json.dumps({"key": record["key"], **record.get("timings", {})})
    )
    return path


def _stop_if_disk_full(record: dict[str, Any]) -> None:
    if record.get("stop"):
        r = record["result"]
        raise DiskFullError(r["path"], r.get("detail", ""))


def exit_with_parent() -> None:
    """In a worker process: end it when the process that started it dies (a killed run must
    leave no worker behind that goes on writing files).  Linux's ``PR_SET_PDEATHSIG`` where it
    exists, and a thread that watches the parent's process id everywhere."""
    parent = os.getppid()
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


@dataclass
class Summary:
    """What a call of :func:`execute` did."""

    total: int
    skipped: int  # already finished before the call
    ran: int
    outcomes: Counter = field(default_factory=Counter)  # over all jobs, finished before or now
    failures: dict[str, list[str]] = field(default_factory=dict)  # outcome -> keys
    wall_s: float = 0.0
    backend: str = "local"
    missing: int = 0  # jobs without a result file left unrun (``dry``)

    @property
    def ok(self) -> int:
        return self.outcomes.get("ok", 0)

    @property
    def failed(self) -> int:
        return self.total - self.missing - self.ok

    def report(self) -> str:
        lines = [
            f"{self.total} jobs ({self.backend}): {self.ran} run now, {self.skipped} already "
            f"done; {self.ok} ok, {self.failed} failed; {self.wall_s:.0f} s"
        ]
        if self.missing:
            lines[0] += f"; {self.missing} not run"
        for outcome, keys in sorted(self.failures.items()):
            shown = ", ".join(keys[:5]) + (f", ... ({len(keys)})" if len(keys) > 5 else "")
            lines.append(f"  failed [{outcome}]: {shown}")
        return "\n".join(lines)


def _bar(total: int, desc: str, enabled: bool) -> Any:

    return tqdm(total=total, desc=desc, disable=not enabled, unit="job", dynamic_ncols=True)


def _check(jobs: Sequence[Job]) -> list[Job]:
    seen: set[str] = set()
    for j in jobs:
        j.validate()
        if j.key in seen:
            raise ConfigError("job.key", f"two jobs share the key {j.key!r}")
        seen.add(j.key)
    return list(jobs)


def _local(pending: list[Job], out_dir: str, workers: int, done: Callable) -> None:
    if workers <= 1:
        for job in pending:
            done(run_job(job, out_dir))
        return

    todo = list(pending)
    while todo:
        with ProcessPoolExecutor(
            workers, mp_context=mp.get_context("spawn"), initializer=exit_with_parent
        ) as pool:
            futures = {pool.submit(run_job, job, out_dir): job for job in todo}
            todo = []
            broken = False
            try:
                for fut in as_completed(futures):
                    job = futures[fut]
                    try:
                        rec = fut.result()
                    except BrokenProcessPool:
                        # a worker died (out of memory, a crash in native code): the job that
                        # killed it cannot be told from the ones queued with it; mark the first
                        # one failed and run the others again in a fresh pool
                        if not broken:
                            broken = True
                            done(_crashed(job))
                        else:
                            todo.append(job)
                        continue
                    done(rec)
            except BaseException:  # a full disk, Ctrl-C: stop the workers, record nothing more
                _stop_pool(pool)
                raise
        # a pool that broke leaves its unfinished jobs in ``todo``


def _stop_pool(pool: Any) -> None:
    """Cancel what is queued and end the running workers now (their unfinished jobs have no
    result file, so the next run redoes them)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(5)


def _crashed(job: Job) -> dict[str, Any]:
    return {
        "key": job.key,
        "kind": job.kind,
        "params": job.params,
        "status": "failed",
        "outcome": "worker_crashed",
        "result": {"error": "the worker process died while running this job or one beside it"},
        "timings": {},
    }


def _import_ray() -> Any:
    try:
        import ray  # lazy: optional heavy package
    except ImportError as e:  # pragma: no cover - depends on the install
        raise ConfigError("ray", "Ray is not installed: pip install -e '.[cluster]'") from e
    return ray


def ray_init(address: str, workers: int = 1) -> bool:
    """Connect to Ray (``"local"``: start a local instance with ``workers`` CPUs); False when
    already connected.  :func:`execute` calls it itself; call it once around several
    :func:`execute` calls to keep one connection (and :func:`ray_shutdown` after)."""
    ray = _import_ray()
    if ray.is_initialized():
        return False
    kw: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
    if address == "local":
        ray.init(num_cpus=max(1, workers), include_dashboard=False, **kw)
    else:
        ray.init(address=address, **kw)
    return True


def ray_shutdown() -> None:
    _import_ray().shutdown()


def _ray(pending: list[Job], out_dir: str, address: str, workers: int, done: Callable) -> None:
    ray = _import_ray()
    started = ray_init(address, workers)
    try:
        remote = ray.remote(num_cpus=1, max_retries=1)(run_job)
        refs = {remote.remote(job, out_dir): job for job in pending}
        waiting = list(refs)
        while waiting:
            ready, waiting = ray.wait(waiting, num_returns=1)
            for ref in ready:
                try:
                    rec = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a lost worker or node
                    rec = _crashed(refs[ref])
                    rec["outcome"] = f"ray_{type(e).__name__}"
                done(rec)
    finally:
        if started:
            ray.shutdown()


def execute(
    jobs: Iterable[Job],
    out_dir: str | os.PathLike[str],
    workers: int = 1,
    ray: str | None = None,
    progress: bool = True,
    desc: str = "jobs",
    retry_failed: bool = False,
    dry: bool = False,
) -> Summary:
    """Run the jobs that have no result file in ``out_dir`` yet (module docstring); with
    ``dry`` run nothing and only count what is there (``Summary.missing`` jobs have no file).
    ``OutputBusyError`` when another process is running jobs into ``out_dir``."""
    jobs = _check(list(jobs))
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ConfigError("workers", f"must be a non-negative integer, got {workers!r}")
    out = Path(out_dir)
    with OutputLock(out):
        if not dry:  # what a killed run left: temporary files, a cut-off timings line
            remove_tmp_files(out)
            drop_partial_last_line(out / "timings.jsonl")
        return _execute(jobs, out, workers, ray, progress, desc, retry_failed, dry)


def _execute(
    jobs: list[Job],
    out: Path,
    workers: int,
    ray: str | None,
    progress: bool,
    desc: str,
    retry_failed: bool,
    dry: bool,
) -> Summary:
    t0 = time.perf_counter()
    pending, outcomes, failures = [], Counter(), {}

    def count(rec: dict[str, Any]) -> None:
        outcomes[rec["outcome"] if rec["status"] != "ok" else "ok"] += 1
        if rec["status"] != "ok":
            failures.setdefault(rec["outcome"], []).append(rec["key"])

    for job in jobs:
        rec = read_result(result_path(out, job))
        if rec is None or (retry_failed and rec["status"] != "ok"):
            pending.append(job)
        else:
            count(rec)
    skipped = len(jobs) - len(pending)
    missing = len(pending) if dry else 0
    if dry:
        pending = []
    bar = _bar(len(pending), desc, progress and bool(pending))

    new_failures = [0]

    def done(rec: dict[str, Any]) -> None:
        _stop_if_disk_full(rec)
        write_result(out, rec)
        count(rec)
        new_failures[0] += rec["status"] != "ok"
        bar.update(1)
        bar.set_postfix(failed=new_failures[0], refresh=False)

    backend = "local" if ray is None else f"ray ({ray})"
    try:
        if pending:
            if ray is None:
                _local(pending, str(out), workers, done)
            else:
                _ray(pending, str(out.resolve()), ray, workers, done)
    finally:
        bar.close()
    return Summary(
        len(jobs),
        skipped,
        len(pending),
        outcomes,
        {k: sorted(v) for k, v in failures.items()},
        time.perf_counter() - t0,
        backend,
        missing,
    )


def load_results(out_dir: str | os.PathLike[str], jobs: Iterable[Job]) -> list[dict[str, Any]]:
    """The records of ``jobs`` found in ``out_dir`` (missing ones are left out)."""
    out = []
    for job in jobs:
        rec = read_result(result_path(out_dir, job))
        if rec is not None:
            out.append(rec)
    return out


def parse_range(text: str, name: str = "--scenes") -> tuple[int, int]:
    """``"A:B"`` -> (A, B), 0 <= A < B (B excluded)."""
    try:
        a, b = (int(x) for x in str(text).split(":"))
    except ValueError as e:
        raise ConfigError(
            name, f"expected A:B (first and one past the last seed), got {text!r}"
        ) from e
    if a < 0 or b <= a:
        raise ConfigError(name, f"need 0 <= A < B, got {text!r}")
    return a, b
