"""The gripper log of a RealSense recording: format, checks and pairing by time."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cablesim.errors import InputError, RecordingError
from cablesim.formats.gripper_log import read_gripper_log, write_gripper_log


def test_pairing_by_time(tmp_path):
    recs = [(1.0, -1, (0, 0, 1)), (2.0, 0, (0.01, 0, 1)), (2.1, 0, (0.02, 0, 1))]
    recs += [(2.2, 1, (0.02, 0.01, 1)), (3.0, 1, (0, 0, 1))]
    log = read_gripper_log(write_gripper_log(tmp_path / "g.jsonl", recs))
    pos, act = log.pair([0.5, 1.5, 2.05, 2.1, 2.15, 2.6, 3.0, 3.5], max_gap=1.0)
    assert act.tolist() == [-1, -1, 0, 0, 0, 1, 1, -1]
    np.testing.assert_allclose(pos[2], [0.015, 0, 1])  # halfway between the records
    np.testing.assert_allclose(pos[0], [0, 0, 1])  # before the log: its first position
    # records farther apart than max_gap do not make an action sample
    _, act = log.pair([2.6], max_gap=0.2)
    assert act.tolist() == [-1]


def test_base_frame_log(tmp_path):
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    T[:3, 3] = [0.1, 0.2, 0.9]
    path = write_gripper_log(tmp_path / "g.jsonl", [(0.0, 0, (0.5, 0.0, 0.3))], "base", T)
    log = read_gripper_log(path)
    np.testing.assert_allclose(log.position[0], [0.1, -0.1, 1.4])
    with pytest.raises(InputError, match="base_to_camera"):
        write_gripper_log(tmp_path / "x.jsonl", [], "base")


def test_bad_logs_are_named(tmp_path):
    p = tmp_path / "g.jsonl"
    with pytest.raises(RecordingError, match="not found"):
        read_gripper_log(p)
    header = {"format": "cablesim-gripper-log", "version": 1, "frame": "camera"}
    for lines, match in [
        ([{"format": "other"}], "header"),
        ([dict(header, version=2)], "version"),
        ([dict(header, frame="base")], "transform"),
        ([header], "no records"),
        ([header, {"t": 1.0, "action": 0}], "line 2"),
        ([header, {"t": 1.0, "action": 0, "position": [0, 0]}], "line 2"),
        ([header] + [{"t": 1.0, "action": 0, "position": [0, 0, 1]}] * 2, "increasing"),
    ]:
        p.write_text("\n".join(json.dumps(x) for x in lines))
        with pytest.raises(RecordingError, match=match):
            read_gripper_log(p)
