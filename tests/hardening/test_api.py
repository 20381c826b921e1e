"""Issue 12: the public API checks its inputs before the expensive step (building the scene),
like the command line does."""

from __future__ import annotations

import pytest

from cablesim.errors import InputError, RecordingError
from cablesim.policies.config import ExploreConfig
from cablesim.policies.explore import explore
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.session import simulate_episode


def test_explore_checks_the_raft_checkpoint_first(tmp_path, monkeypatch):
    # an unwritable settle cache would stop a build: the error must come before that
    monkeypatch.setenv("CABLESIM_CACHE", "/proc/nc")
    cfg = ExploreConfig.of(seed=8, flow="raft", progress=False)
    with pytest.raises(InputError, match="RAFT checkpoint not found: /nonexistent.pt"):
        explore(cfg, flow_kwargs={"checkpoint": "/nonexistent.pt"})
    with pytest.raises(InputError, match="no RAFT checkpoint given"):
        explore(cfg)


def test_simulate_episode_checks_the_recording_path_first(tmp_path, monkeypatch):
    monkeypatch.setenv("CABLESIM_CACHE", "/proc/nc")
    (tmp_path / "file").write_text("")
    with pytest.raises(RecordingError, match="exists and is not a directory"):
        simulate_episode(EpisodeConfig.of(seed=8), record_to=tmp_path / "file")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "a.txt").write_text("mine")
    with pytest.raises(RecordingError, match="not empty"):
        simulate_episode(EpisodeConfig.of(seed=8), record_to=tmp_path / "notes")
    with pytest.raises(RecordingError, match="not a cablesim recording"):
        simulate_episode(EpisodeConfig.of(seed=8), record_to=tmp_path / "notes", overwrite=True)
