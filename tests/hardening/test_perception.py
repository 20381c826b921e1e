"""Issue 12, item 4: perception inputs are checked and end in InputError naming the problem."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.formats.movingcables import write_flow_png
from cablesim.frames import Frame, Intrinsics, Stream
from cablesim.perception import score_mask
from cablesim.perception.correlation import CorrelationParams
from cablesim.perception.flow import DISFlow, FarnebackFlow
from cablesim.perception.grasp_sampler import GraspSampler

K = Intrinsics(100.0, 100.0, 31.5, 23.5, 64, 48)


def hose_votes(value: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """A horizontal bar of ``value`` votes at 1 m in a 64x48 image."""
    votes = np.zeros((48, 64), dtype)
    votes[22:27, 10:50] = value
    return votes, np.full((48, 64), 1.0, np.float32)


def test_sampler_visits_only_the_vote_levels_present():
    # int64 votes of 1e6 ran one pass per level (past 60 s): now one level, one proposal
    votes, depth = hose_votes(10**6, np.int64)
    res = GraspSampler().propose(votes, depth, K)
    assert {c.level for c in res.candidates} == {10**6}
    assert res.proposal is not None and res.proposal.level == 10**6


def test_votes_above_int32_do_not_wrap():
    votes, depth = hose_votes(2**32 + 1, np.int64)  # wrapped to 1 as int32
    res = GraspSampler().propose(votes, depth, K)
    assert res.proposal is not None and res.proposal.level == 2**32 + 1
    too_big = np.full((48, 64), np.iinfo(np.uint64).max, np.uint64)
    with pytest.raises(InputError, match="do not fit"):
        GraspSampler().propose(too_big, depth, K)


def test_score_mask_refuses_a_label_image():
    labels = np.full((8, 8), -1, np.int16)  # background -1 was counted as "true"
    labels[2:4] = 0
    with pytest.raises(InputError, match=r"truth must be a mask .* values -1\.\.0"):
        score_mask(labels == 0, labels)
    with pytest.raises(InputError, match="prediction must be a mask"):
        score_mask(labels, labels == 0)
    assert score_mask((labels == 0).astype(np.uint8), labels == 0).iou == 1.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tau_n": float("nan")}, "tau_n: must be a finite number, got nan"),
        ({"min_samples": 2.5}, "min_samples: must be an integer, got 2.5"),
        ({"min_samples": True}, "min_samples: must be an integer, got True"),
        ({"c0_min": "0.2"}, "c0_min: must be a number"),
    ],
)
def test_correlation_params_are_checked(kwargs, match):
    with pytest.raises(InputError, match=match):
        CorrelationParams(**kwargs)


def test_intrinsics_need_whole_pixels_and_numbers():
    with pytest.raises(InputError, match=r"intrinsics\.width must be a positive integer, got 1\.7"):
        Intrinsics(100.0, 100.0, 0.0, 0.0, 1.7, 48)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"intrinsics\.fx must be a number, got 'abc'"):
        Intrinsics.from_dict({"fx": "abc", "fy": 1, "cx": 0, "cy": 0, "width": 4, "height": 4})
    with pytest.raises(InputError, match="whole number of pixels"):
        Intrinsics.from_dict({"fx": 1, "fy": 1, "cx": 0, "cy": 0, "width": 4.5, "height": 4})
    assert Intrinsics.from_dict(K.to_dict()) == K


def frame(intrinsics: Intrinsics, action: int = 0) -> Frame:
    h, w = intrinsics.height, intrinsics.width
    return Frame(
        np.zeros((h, w, 3), np.uint8),
        np.ones((h, w), np.float32),
        intrinsics,
        np.zeros(3),
        action=action,
    )


def test_a_stream_keeps_one_intrinsics():
    other = Intrinsics(120.0, 120.0, 31.5, 23.5, 64, 48)
    with pytest.raises(InputError, match="frame 1 has other intrinsics than frame 0"):
        Stream([frame(K), frame(other, -1)])
    with pytest.raises(InputError, match="frame action must be an integer"):
        Frame(np.zeros((48, 64, 3), np.uint8), None, K, np.zeros(3), action=np.array([0]))


@pytest.mark.parametrize("size", [(0, 0), (10, 10), (11, 64), (40, 15)])
def test_dis_refuses_images_too_small_for_its_pyramid(size):
    img = np.zeros((*size, 3), np.uint8)
    with pytest.raises(InputError, match="empty|too small for DIS"):
        DISFlow().compute(img, img)


def test_farneback_refuses_empty_images():
    with pytest.raises(InputError, match="empty"):
        FarnebackFlow().compute(np.zeros((0, 5), np.uint8), np.zeros((0, 5), np.uint8))


def test_flow_png_refuses_flow_it_would_clip(tmp_path):
    flow = np.zeros((4, 4, 2), np.float32)
    flow[1, 1] = (1e4, 0.0)  # was clipped to 511.98 px and stored as if measured
    with pytest.raises(InputError, match="does not fit a flow PNG"):
        write_flow_png(tmp_path / "f.png", flow)
    flow[1, 1] = (511.0, -512.0)
    write_flow_png(tmp_path / "f.png", flow)
