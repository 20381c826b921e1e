"""Issue 12, items 1 and 7: the command line turns every expected failure into one line on
stderr and a non-zero exit, and checks its output directory, settle cache and RAFT checkpoint
before any expensive step."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cablesim.cli import main

SMALL = ["--seed", "8", "--hoses", "1", "--width", "32", "--height", "24"]


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    try:
        rc = main(list(argv))
    except SystemExit as e:  # argparse
        rc = int(e.code or 0)
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    return lines[-1]


@pytest.mark.parametrize("sub", ["scene", "episode", "explore"])
def test_out_is_an_existing_file(capsys, tmp_path, sub):
    f = tmp_path / "f"
    f.write_text("")
    rc, _, err = run_cli(capsys, sub, "--out", str(f), *SMALL)
    assert rc == 2
    assert one_line_error(err) == f"cablesim {sub}: error: --out {f}: exists and is not a directory"


def test_out_below_a_file_or_in_proc(capsys, tmp_path):
    (tmp_path / "f").write_text("")
    rc, _, err = run_cli(capsys, "scene", "--out", str(tmp_path / "f" / "sub"), *SMALL)
    assert rc == 2 and "cannot write there (Not a directory)" in one_line_error(err)
    rc, _, err = run_cli(capsys, "scene", "--out", "/proc/x", *SMALL)
    assert rc == 2 and one_line_error(err).startswith("cablesim scene: error: --out /proc/x:")


@pytest.mark.parametrize("sub", ["scene", "episode", "explore"])
def test_empty_out_is_refused(capsys, tmp_path, sub, monkeypatch):
    monkeypatch.chdir(tmp_path)  # "" wrote into the current directory
    rc, _, err = run_cli(capsys, sub, "--out", "", *SMALL)
    assert rc == 2 and "argument --out: the output directory is empty" in one_line_error(err)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_cache_warns_and_settles_without_it(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("CABLESIM_CACHE", "/proc/nc")  # was fatal after settling
    rc, _, err = run_cli(capsys, "scene", "--out", str(tmp_path / "o" / "x"), *SMALL)
    assert rc == 0, err
    assert "settle cache /proc/nc/settled is not writable" in err
    assert (tmp_path / "o" / "x" / "scene.json").is_file()


def test_missing_raft_checkpoint_fails_before_the_scene(capsys, tmp_path):
    out = tmp_path / "run"
    rc, stdout, err = run_cli(
        capsys, "explore", "--out", str(out), "--flow", "raft",
        "--raft-checkpoint", "/nonexistent.pt", *SMALL,
    )  # fmt: skip
    assert rc == 2
    assert one_line_error(err) == (
        "cablesim explore: error: RAFT checkpoint not found: /nonexistent.pt "
        "(weights are never downloaded; supply a checkpoint file)"
    )
    assert not out.exists() and "[explore]" not in stdout  # nothing was built or written


def test_corrupt_raft_checkpoint_fails_before_the_scene(capsys, tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not torch")
    rc, _, err = run_cli(
        capsys, "explore", "--out", str(tmp_path / "run"), "--flow", "raft",
        "--raft-checkpoint", str(bad), *SMALL,
    )  # fmt: skip
    assert rc == 2 and f"cannot read RAFT checkpoint {bad}" in one_line_error(err)
    assert not (tmp_path / "run").exists()


def test_ctrl_c_is_one_line_and_exit_130(tmp_path):
    env = dict(os.environ, CABLESIM_CACHE=str(tmp_path / "cache"))  # must settle: takes a while
    cmd = [sys.executable, "-m", "cablesim.cli", "scene", "--out", str(tmp_path / "o")]
    cmd += ["--seed", "8", "--hoses", "4", "--width", "32", "--height", "24"]
    # Ctrl-C as a terminal delivers it: to a process whose SIGINT is not ignored (a test run
    # started in the background, `nohup pytest &`, hands its children an ignored SIGINT, and
    # Python then installs no KeyboardInterrupt handler: the scene ran to its end, exit 0)
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert p.stdout is not None
        first = p.stdout.readline()  # "[scene] building ...", printed just before World.build
        assert first.startswith("[scene] building"), first
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 130, err
    assert one_line_error(err) == "cablesim scene: interrupted"
    assert not (tmp_path / "o" / "scene.json").exists()


def test_an_os_error_while_running_is_one_line(tmp_path):
    # `cablesim scene ... | head -c0`: writing the progress lines fails with EPIPE
    cmd = [sys.executable, "-m", "cablesim.cli", "scene", "--out", str(tmp_path / "o"), *SMALL]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()
    err = p.stderr.read()
    p.wait(timeout=120)
    assert p.returncode == 2, err
    assert one_line_error(err) == "cablesim scene: error: Broken pipe"
    assert len(err.strip().splitlines()) == 1


def test_cli_module_runs(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "cablesim.cli", "scene", "--out", str(Path("/proc/x")), *SMALL],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
