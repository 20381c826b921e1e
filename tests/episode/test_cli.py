"""``cablesim episode`` writes a recording, pictures and a summary."""

from __future__ import annotations

import json

import pytest

from cablesim.cli import main
from cablesim.recording import Recording


@pytest.mark.slow
def test_cli_episode(tmp_path, capsys):
    out = tmp_path / "ep"
    argv = ["episode", "--seed", "2", "--hose", "1", "--hoses", "3", "--width", "160"]
    argv += ["--height", "120", "--periods", "1", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "gain" in printed and "frames kept" in printed
    for name in ("contact_sheet.png", "start.png", "target.png", "target_labels.png"):
        assert (out / name).stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["result"]["success"]
    assert set(summary["gain"]) == {"along", "across"}
    assert summary["frames_kept"] + 1 == len(Recording(out / "recording"))
    # an existing recording is not overwritten without --overwrite
    assert main(argv) == 2
