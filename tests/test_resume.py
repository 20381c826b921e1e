"""Runs that are interrupted or collide lose nothing (issue 19).

- ``cablesim dataset``, ``cablesim benchmark thesis`` and ``python -m benchmarks.seeds`` killed with
  SIGKILL mid-run (one job finished, another in progress) and started again write the same
  files, byte for byte, as a run that never stopped (what times the run aside: ``timings.jsonl``,
  the date and run lines of ``report.md``, ``cablesim.sweep.VOLATILE``).  The seed sweep runs a stand-in
  for its per-seed episode (a real seed takes 15-40 s here); its resume logic is the real one.
- A second command into an ``--out`` another process holds is refused at once with the
  project's error naming the lock file and the holder; the holder finishes unharmed; a stale
  lock of a killed process blocks nothing.
- A full disk (a small tmpfs where this process may mount one, else ``ENOSPC`` injected) is a
  ``DiskFullError`` naming the file, one line from the command line, with every finished
  sequence and recorded frame readable and nothing of the unfinished one left.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from benchmarks import seeds
from cablesim import sweep
from cablesim.errors import DiskFullError, OutputBusyError
from cablesim.files import OutputLock
from cablesim.jobs import Job, execute, read_result

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--width", "160", "--height", "120", "--periods", "1", "--workers", "1", "--quiet"]
# 2 clips, about 20 s: seed 406 pulls along by 4.8 cm, 407 across by 4.5 cm (402:404, used
# before the hand's motion was drawn per clip, now tears seed 403's hose pulled along by 2.9 cm)
DATASET = ["dataset", "movingcables", "--scenes", "406:408", *TINY]
CLIP_1 = "movingcables-test-0001-s000406"
CLIP_2 = "movingcables-test-0002-s000407"
THESIS = [
    "benchmark",
    "thesis",
    "--validation",
    "11:12",
    "--test",
    "21:22",
    "--flows",
    "oracle",
    "dis",
    "--perturb",
    "off",
    "--hoses",
    "2",
    "--no-explore",
    "--no-clips",  # the clips' writer is the dataset's, killed and resumed above
    *TINY,
]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "cablesim.cli", *args]


def _files(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (hidden ones included), but the run's timings."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "timings.jsonl"
    }


def _wait_for(cond: Callable[[], bool], proc: subprocess.Popen, what: str) -> None:
    """Poll until ``cond()``; fail with the process's output if it ends first."""
    deadline = time.monotonic() + 600  # only against a hang: the test never waits this long
    while not cond():
        if proc.poll() is not None:
            out = proc.stdout.read() if proc.stdout else ""
            pytest.fail(f"the run ended (rc {proc.returncode}) before {what}:\n{out[-3000:]}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"no {what} after 600 s")
        time.sleep(0.02)


def _start(args: list[str], **kw: object) -> subprocess.Popen:
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)


def _kill(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.wait()


def _timings_lines_are_whole(path: Path) -> None:
    for line in path.read_text().splitlines():
        json.loads(line)


def _refused_while_held(holder: subprocess.Popen, args: list[str], lock: Path, **kw: object) -> str:
    """Run ``args`` while ``holder`` (stopped meanwhile, so it cannot finish first) holds
    ``lock``; the refusal's stderr."""
    _wait_for(lambda: f"pid {holder.pid}:" in lock.read_text(), holder, "the lock taken")
    holder.send_signal(signal.SIGSTOP)
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=300, **kw)
    finally:
        holder.send_signal(signal.SIGCONT)
    assert r.returncode == 2, r.stdout + r.stderr
    return r.stderr


# --------------------------------------------------------------------------- real commands
@pytest.mark.slow
def test_killed_dataset_run_resumes_to_the_same_files_and_refuses_a_second_writer(tmp_path):
    out = tmp_path / "mc"
    subprocess.run(_cli(*DATASET, "--out", str(out)), check=True, capture_output=True)
    reference = _files(out)
    out.rename(tmp_path / "reference")  # the same --out path below: the job files name it
    assert any("/0002/" in k for k in reference) and "jobs/summary.json" in reference

    killed = _start(_cli(*DATASET, "--out", str(out)))
    _wait_for(lambda: (out / "jobs" / f"{CLIP_1}.json").exists(), killed, "the first clip")
    _kill(killed)  # while the second clip is simulated
    assert not (out / "jobs" / f"{CLIP_2}.json").exists()
    assert f"pid {killed.pid}:" in (out / ".lock").read_text()  # a stale lock left behind
    # and what a kill at another moment leaves: part of the clip in place, its staging folder,
    # a cut-off timings line, a temporary result file
    (out / "test" / "rgb_clips" / "0002").mkdir(parents=True)
    (out / "test" / "rgb_clips" / "0002" / "00000099.png").write_bytes(b"half")
    (out / "test" / ".partial" / "0002.1.dead").mkdir(parents=True)
    (out / "test" / ".partial" / "0002.1.dead" / "x.png").write_bytes(b"half")
    with open(out / "jobs" / "timings.jsonl", "a") as f:
        f.write('{"key": "movingc')
    (out / "jobs" / f".{CLIP_2}.json.1.abcd.tmp").write_text("{")

    resumed = _start(_cli(*DATASET, "--out", str(out)))
    err = _refused_while_held(resumed, _cli(*DATASET, "--out", str(out)), out / ".lock")
    assert len(err.strip().splitlines()) == 1, err
    assert str(out / ".lock") in err and f"pid {resumed.pid}: cablesim dataset" in err
    assert "in use by another cablesim process" in err
    assert resumed.wait(timeout=600) == 0, resumed.stdout.read()
    assert "1 run now, 1 already done" in resumed.stdout.read()
    assert _files(out) == reference  # byte for byte, leftovers gone
    _timings_lines_are_whole(out / "jobs" / "timings.jsonl")


@pytest.mark.slow
def test_killed_thesis_benchmark_resumes_to_the_same_files(tmp_path):
    out = tmp_path / "thesis"
    subprocess.run(_cli(*THESIS, "--out", str(out)), check=True, capture_output=True)
    reference = _files(out)
    out.rename(tmp_path / "reference")
    assert len([k for k in reference if k.startswith("results/interaction-")]) == 2

    killed = _start(_cli(*THESIS, "--out", str(out)))
    results = out / "results"
    _wait_for(lambda: len(list(results.glob("interaction-*.json"))) >= 1, killed, "a scene")
    _kill(killed)
    assert len(list(results.glob("interaction-*.json"))) == 1, "both scenes were done"
    assert not (out / "report.md").exists()

    resumed = subprocess.run(_cli(*THESIS, "--out", str(out)), capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    again = _files(out)

    def steady(files: dict[str, bytes]) -> dict[str, bytes]:  # report.md's date and run lines
        md = files["report.md"].decode().splitlines()
        keep = [x for x in md if not x.startswith(("- date:", "- run:"))]
        assert len(keep) == len(md) - 2
        return {**files, "report.md": "\n".join(keep).encode()}

    assert steady(again) == steady(reference)
    assert again["report.json"] == reference["report.json"]
    _timings_lines_are_whole(results / "timings.jsonl")


# --------------------------------------------------------------------------- the seed sweep
FAKE_SEEDS = """
import os, sys, time
import cablesim.sweep
from benchmarks import seeds

def fake(seed, cache_dir=None, config=None):
    if os.environ.get("HOLD_SEED") == str(seed):
        time.sleep(600)  # in progress until killed
    return {"seed": seed, "success": seed % 2 == 1, "outcome": "ok" if seed % 2 else "slipped",
            "reason": "", "hose": seed % 3, "grasp_retries": 0, "resamples": 0,
            "wall_s": time.time() % 7, "cpu_s": time.process_time()}

cablesim.sweep.run_seed = fake
sys.exit(seeds.main(sys.argv[1:]))
"""


def _seeds_cmd(out: Path) -> list[str]:
    return [
        sys.executable,
        "-c",
        FAKE_SEEDS,
        "--seeds",
        "1",
        "2",
        "3",
        "--workers",
        "0",
        "--json",
        str(out / "seeds.json"),
        "--md",
        str(out / "seeds.md"),
    ]


def test_killed_seed_sweep_resumes_with_the_rows_it_had(tmp_path):
    out = tmp_path / "sweep"
    subprocess.run(_seeds_cmd(out), check=True, capture_output=True, cwd=ROOT)
    reference = json.loads((out / "seeds.json").read_text())
    out.rename(tmp_path / "reference")

    def rows() -> list[int]:
        try:
            return [r["seed"] for r in json.loads((out / "seeds.json").read_text())["rows"]]
        except (OSError, ValueError):
            return []

    killed = _start(_seeds_cmd(out), env={**os.environ, "HOLD_SEED": "2"}, cwd=ROOT)
    _wait_for(lambda: rows() == [1], killed, "seed 1's row")
    err = _refused_while_held(killed, _seeds_cmd(out), out / ".seeds.json.lock", cwd=ROOT)
    assert f"pid {killed.pid}:" in err and str(out / ".seeds.json.lock") in err
    _kill(killed)
    first = json.loads((out / "seeds.json").read_text())["rows"][0]

    resumed = subprocess.run(_seeds_cmd(out), capture_output=True, text=True, check=True, cwd=ROOT)
    assert "resuming: 1 of 3 seeds" in resumed.stdout
    doc = json.loads((out / "seeds.json").read_text())
    assert doc["rows"][0] == first  # seed 1 kept, not run again
    assert sweep.comparable(doc) == sweep.comparable(reference)
    assert sweep.comparable(doc)["summary"]["successes"] == 2
    assert "| 3 | yes |" in (out / "seeds.md").read_text()
    fresh = subprocess.run([*_seeds_cmd(out), "--fresh"], capture_output=True, text=True, cwd=ROOT)
    assert fresh.returncode == 0 and "resuming" not in fresh.stdout


# --------------------------------------------------------------------------- locks
@pytest.fixture
def held(tmp_path) -> Iterator[Callable[[Path, str], subprocess.Popen]]:
    """Start a process that holds a lock file (``folder``, ``name``) until killed."""
    procs: list[subprocess.Popen] = []

    def hold(folder: Path, name: str = ".lock") -> subprocess.Popen:
        code = (
            "import sys, time\n"
            "from cablesim.files import OutputLock\n"
            "OutputLock(sys.argv[1], 'the holder', name=sys.argv[2]).acquire()\n"
            "print('held', flush=True)\n"
            "time.sleep(600)\n"
        )
        p = subprocess.Popen(
            [sys.executable, "-c", code, str(folder), name], stdout=subprocess.PIPE, text=True
        )
        procs.append(p)
        assert p.stdout is not None and p.stdout.readline().strip() == "held"
        return p

    yield hold
    for p in procs:
        _kill(p)


@pytest.mark.parametrize("command", ["dataset", "benchmark", "seeds"])
def test_a_held_out_folder_is_refused_before_any_work(tmp_path, held, capsys, monkeypatch, command):
    from cablesim.cli import main

    out = tmp_path / "out"
    if command == "seeds":
        holder = held(out, ".seeds.json.lock")
        monkeypatch.setattr(
            sweep, "run_seed", lambda s, *a: {"seed": s, "outcome": "ok", "wall_s": 0, "cpu_s": 0}
        )
        rc = seeds.main(["--seeds", "1", "--workers", "0", "--json", str(out / "other.json")])
        assert rc == 0 and (out / "other.json").exists()  # another results file: not held
        rc = seeds.main(["--seeds", "1", "--json", str(out / "seeds.json")])
        lock = out / ".seeds.json.lock"
        assert not (out / "seeds.json").exists()
    else:
        holder = held(out)
        args = DATASET if command == "dataset" else THESIS
        rc = main([*args, "--out", str(out)])
        lock = out / ".lock"
        assert sorted(p.name for p in out.iterdir()) == [".lock"]  # nothing else written
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert f"{lock}: the folder is in use by another cablesim process (pid {holder.pid}:" in err
    assert "the holder" in err
    _kill(holder)  # a killed holder's lock file stays, and blocks nothing
    assert f"pid {holder.pid}" in lock.read_text()
    with OutputLock(out, name=lock.name) as again:
        assert again.held and f"pid {os.getpid()}:" in lock.read_text()
    assert lock.read_text() == ""  # emptied on release


def test_job_runs_lock_their_folder_and_reenter_in_one_process(tmp_path, held):
    holder = held(tmp_path / "jobs")
    with pytest.raises(OutputBusyError, match=f"pid {holder.pid}: the holder") as e:
        execute([Job("test.echo", "a", {"value": 1})], tmp_path / "jobs", progress=False)
    assert e.value.path == str(tmp_path / "jobs" / ".lock")
    with OutputLock(tmp_path / "mine"):  # the caller's own lock: execute may take it again
        s = execute([Job("test.echo", "a", {"value": 1})], tmp_path / "mine", progress=False)
    assert s.ok == 1


# --------------------------------------------------------------------------- job level
def _echo_jobs() -> list[Job]:
    return [Job("test.echo", k, {"value": k}) for k in ("a", "b", "c")]


def test_what_a_killed_run_leaves_is_redone_or_removed(tmp_path):
    execute(_echo_jobs(), tmp_path / "clean", progress=False)
    out = tmp_path / "killed"
    execute(_echo_jobs()[:1], out, progress=False)
    (out / ".b.json.4242.tmp").write_text('{"key": "b", "sta')  # killed mid-write (old name)
    (out / ".c.json.4242.0f0f.tmp").write_text("{")
    with open(out / "timings.jsonl", "a") as f:
        f.write('{"key": "b", "wall')  # killed mid-line
    s = execute(_echo_jobs(), out, progress=False)
    assert (s.skipped, s.ran) == (1, 2)
    assert _files(out) == _files(tmp_path / "clean")  # no temporary file left
    lines = (out / "timings.jsonl").read_text().splitlines()
    assert [json.loads(x)["key"] for x in lines] == ["a", "b", "c"]


def _dead(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return True
    return "\nState:\tZ" in state  # a zombie nobody reaped: dead too


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_workers_die_with_a_killed_driver(tmp_path):
    """Worker processes of a killed run do not go on writing into the folder."""
    jobs = [
        Job("test.echo", f"w{i}", {"pid_file": str(tmp_path / f"w{i}.pid"), "sleep": 600})
        for i in range(2)
    ]
    code = (
        "import sys, pickle\n"
        "from cablesim.jobs import execute\n"
        "execute(pickle.loads(bytes.fromhex(sys.argv[1])), sys.argv[2], workers=2,"
        " progress=False)\n"
    )
    import pickle

    driver = _start([sys.executable, "-c", code, pickle.dumps(jobs).hex(), str(tmp_path / "o")])
    pids = [tmp_path / f"w{i}.pid" for i in range(2)]
    _wait_for(lambda: all(p.exists() for p in pids), driver, "both workers started")
    workers = [int(p.read_text()) for p in pids]
    assert not any(_dead(w) for w in workers)
    _kill(driver)
    deadline = time.monotonic() + 60
    while not all(_dead(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    survivors = [w for w in workers if not _dead(w)]
    for w in survivors:  # leave nothing running when the test fails
        os.kill(w, signal.SIGKILL)
    assert not survivors, "a worker outlived the killed driver"
    assert not list((tmp_path / "o").glob("w*.json"))


def test_a_full_disk_stops_the_run_without_recording_the_job(tmp_path):
    jobs = [
        Job("test.echo", "a", {"value": 1}),
        Job("test.echo", "b", {"disk_full": str(tmp_path / "data" / "x.png")}),
        Job("test.echo", "c", {"value": 3}),
    ]
    with pytest.raises(DiskFullError, match="x.png: no space left on device") as e:
        execute(jobs, tmp_path / "o", progress=False)
    assert e.value.path == str(tmp_path / "data" / "x.png")
    assert read_result(tmp_path / "o" / "a.json")["status"] == "ok"
    assert not (tmp_path / "o" / "b.json").exists()  # unfinished: the next run redoes it
    assert not (tmp_path / "o" / "c.json").exists()  # the run stopped at b
    s = execute(jobs[:1] + jobs[2:], tmp_path / "o", progress=False)
    assert (s.skipped, s.ran) == (1, 1)


def test_a_full_disk_in_a_worker_stops_the_others_at_once(tmp_path):
    """Worker pool: the job beside the one that hit the full disk is ended, not waited for."""
    slow = {"pid_file": str(tmp_path / "c.pid"), "sleep": 60, "done_file": str(tmp_path / "c")}
    jobs = [
        Job("test.echo", "c", slow),  # starts first, still asleep when b fails
        Job("test.echo", "a", {"value": 1}),
        Job("test.echo", "b", {"disk_full": str(tmp_path / "x.png")}),
    ]
    with pytest.raises(DiskFullError, match="x.png"):
        execute(jobs, tmp_path / "o", workers=2, progress=False)
    assert (tmp_path / "c.pid").exists() and _dead(int((tmp_path / "c.pid").read_text()))
    assert not (tmp_path / "c").exists()  # ended asleep, not waited for
    assert not (tmp_path / "o" / "b.json").exists() and not (tmp_path / "o" / "c.json").exists()


# --------------------------------------------------------------------------- a full disk
@pytest.fixture
def small_disk(tmp_path, monkeypatch) -> Iterator[Callable[[int], tuple[Path, str]]]:
    """``small_disk(size, budget)`` -> (folder, how): a tmpfs of ``size`` bytes where this
    process may mount one, else a folder where the files that :mod:`cablesim.files` and the
    recording writer write fail with ``ENOSPC`` after ``budget`` bytes (no 4 kB blocks)."""
    mounted: list[Path] = []

    def make(size: int, budget: int) -> tuple[Path, str]:
        d = tmp_path / f"disk{len(mounted)}"
        d.mkdir()
        try:
            r = subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)],
                capture_output=True,
            )
            ok = r.returncode == 0
        except OSError:  # no mount command
            ok = False
        if ok:
            mounted.append(d)
            return d, "tmpfs"
        _budget(monkeypatch, d, budget)
        return d, "injected"

    yield make
    for d in mounted:
        subprocess.run(["umount", str(d)], check=False)


def _budget(monkeypatch: pytest.MonkeyPatch, root: Path, size: int) -> None:
    import builtins

    import cablesim.files
    import cablesim.recording

    left = [size]

    class Budgeted:
        def __init__(self, f):
            self.f = f

        def write(self, data):
            if len(data) > left[0]:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            left[0] -= len(data)
            return self.f.write(data)

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def budgeted_open(path, mode="r", *a, **kw):
        f = builtins.open(path, mode, *a, **kw)
        inside = Path(path).resolve().is_relative_to(root.resolve())
        return Budgeted(f) if inside and ("w" in mode or "a" in mode) else f

    monkeypatch.setattr(cablesim.files, "open", budgeted_open, raising=False)
    monkeypatch.setattr(cablesim.recording, "open", budgeted_open, raising=False)


def _noise_stream(n: int):
    from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream

    spec = SyntheticSpec(height=120, width=160, periods=1, samples_per_period=n)
    stream = synthetic_stream([Region((4, 12, 4, 20), label=0)], spec)
    rng = np.random.default_rng(0)
    for f in stream.frames:  # incompressible: each frame costs about 130 kB on disk
        f.rgb = rng.integers(0, 255, f.rgb.shape, dtype=np.uint8)
        f.depth = rng.random(f.depth.shape, dtype=np.float32)
    return stream


def test_a_full_disk_keeps_a_recording_of_the_frames_before(small_disk):
    from cablesim.frames import Stream
    from cablesim.recording import Recording, RecordingWriter

    disk, how = small_disk(1_000_000, 1_000_000)
    stream = _noise_stream(16)
    path = disk / "rec"
    written = 0
    with pytest.raises(DiskFullError) as e:
        with RecordingWriter(path, meta={"seed": 1}) as w:
            for i, f in enumerate(stream.frames):
                w.add_frame(i, f)
                written += 1
    assert 2 <= written < len(stream), how
    assert e.value.path.startswith(str(path)) and str(path) in str(e.value)
    assert (path / "index.jsonl").read_bytes().endswith(b"\n")  # no torn line
    rec = Recording(path)
    assert not rec.complete and len(rec) == written
    for a, b in zip(Stream(stream.frames[:written]).frames, rec.to_stream().frames, strict=True):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)


def test_a_torn_index_line_is_taken_back(tmp_path, monkeypatch):
    from cablesim.recording import Recording, RecordingWriter

    stream = _noise_stream(4)
    w = RecordingWriter(tmp_path / "rec")
    w.add_frame(0, stream.frames[0])
    real_write = os.write
    index_fd = w._index.fileno()  # noqa: SLF001

    def torn(fd: int, data: bytes) -> int:  # the disk fills in the middle of the line
        return real_write(fd, data[:10]) if fd == index_fd else real_write(fd, data)

    monkeypatch.setattr(os, "write", torn)
    with pytest.raises(DiskFullError, match="000001.npz: no space left"):
        w.add_frame(1, stream.frames[1])
    monkeypatch.undo()
    text = (tmp_path / "rec" / "index.jsonl").read_text()
    assert text.endswith("\n") and text.count("\n") == 1  # the torn piece taken back
    w.add_frame(1, stream.frames[1])  # room again: the next line follows a whole one
    w.close()
    rec = Recording(tmp_path / "rec")
    assert len(rec) == 2 and not rec.complete  # a write failed on the way: not complete
    assert np.array_equal(rec.frame(1).rgb, stream.frames[1].rgb)


@pytest.mark.slow
def test_a_full_disk_during_a_dataset_keeps_the_finished_sequences(small_disk, capsys):
    from cablesim.cli import main
    from cablesim.formats.movingcables import list_clips, read_clip

    # clip 1 takes 2.63 MB in 4 kB blocks (1.71 MB of files), clip 2 2.42 MB (1.68): only
    # clip 1 fits
    disk, how = small_disk(3_400_000, 2_400_000)
    out = disk / "mc"
    assert main([*DATASET, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"cablesim dataset: error: {out}/") and "no space left on device" in err
    clip1 = read_result(out / "jobs" / f"{CLIP_1}.json")
    assert clip1 is not None and clip1["status"] == "ok", how
    assert not (out / "jobs" / f"{CLIP_2}.json").exists()
    assert list_clips(out / "test") == ["0001"]
    assert len(list(read_clip(out / "test", "0001"))) == clip1["result"]["images"]
    leftovers = [p for p in out.rglob("*") if p.name in ("0002", ".partial")]
    assert not leftovers, leftovers
    if how == "tmpfs":  # room again: the rerun writes the unfinished clip only
        subprocess.run(["mount", "-o", "remount,size=8m", str(disk)], check=True)
        assert main([*DATASET, "--out", str(out)]) == 0
        assert "1 run now, 1 already done" in capsys.readouterr().out
        assert list_clips(out / "test") == ["0001", "0002"]
