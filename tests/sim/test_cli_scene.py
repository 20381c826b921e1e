"""``cablesim scene``: writes every file, and the same seed gives the same files bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cablesim.cli import main

FILES = (
    "rgb.png",
    "depth.png",
    "depth.npy",
    "labels.png",
    "labels.npy",
    "rgb_moved.png",
    "labels_moved.npy",
    "flow.png",
    "flow.npy",
    "flow_valid.npy",
    "scene.json",
)


def _run(out, seed=1):
    args = ["scene", "--seed", str(seed), "--out", str(out), "--width", "160", "--height", "120"]
    assert main([*args, "--hoses", "3", "--no-robot", "--background", "solid"]) == 0


def test_scene_files_and_determinism(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    _run(a)
    _run(b)
    assert "[scene]" in capsys.readouterr().out
    for name in FILES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    meta = json.loads((a / "scene.json").read_text())
    assert meta["intrinsics"]["width"] == 160 and meta["config"]["hoses"]["count"] == 3
    depth, labels = np.load(a / "depth.npy"), np.load(a / "labels.npy")
    flow = np.load(a / "flow.npy")
    assert depth.dtype == np.float32 and depth.shape == (120, 160)
    assert labels.dtype == np.int16 and set(np.unique(labels)) <= {-1, 0, 1, 2}
    assert flow.shape == (120, 160, 2) and np.abs(flow[labels == 0]).max() > 0.5


def test_scene_bad_hose_index(tmp_path, capsys):
    args = ["scene", "--out", str(tmp_path), "--width", "160", "--height", "120", "--no-robot"]
    assert main([*args, "--hose", "7"]) == 2
    assert "--hose 7" in capsys.readouterr().err


def test_unknown_subcommand_exits():
    with pytest.raises(SystemExit):
        main(["nope"])
