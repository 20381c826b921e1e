"""The real-frame evaluation on the published MovingCables videos (``benchmarks.real_clips``):
the panels are found, the truth read from them is plausible, the metric is the published one on
a hand-worked case, and DIS scores in a sane band on clip 0006 (a broken extraction falls out
of it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import real_clips as rc
from cablesim.errors import InputError
from cablesim.perception.flow import FlowEstimator
from cablesim.perception.metrics import movingcables_frame


@pytest.fixture(scope="module")
def clips() -> dict[str, rc.RealClip]:
    return {c: rc.load_clip(c) for c in rc.CLIPS}


def test_the_videos_are_there() -> None:
    for c in rc.CLIPS:
        assert rc.video_path(c).is_file()
    readme = (rc.DATA / "README.md").read_text(encoding="utf-8")
    assert "evaluation only" in readme.lower()
    assert "MIT License" in (rc.DATA / "LICENSE").read_text(encoding="utf-8")


def test_the_panel_boxes_are_found_and_equal_sized(clips) -> None:
    for clip in clips.values():
        assert list(clip.boxes) == list(rc.PANELS)
        sizes = {(b.width, b.height) for b in clip.boxes.values()}
        assert len(sizes) == 1
        (w, h) = sizes.pop()
        assert 270 <= w <= 280 and 200 <= h <= 212
        for box, frame in zip(clip.boxes.values(), clip.frames, strict=True):
            # inside its axes frame, off the frame's black line
            assert frame.x < box.x and box.x + box.width < frame.x + frame.width
            assert frame.y < box.y and box.y + box.height < frame.y + frame.height
            assert box.x + box.width <= 1200 and box.y + box.height <= 600
        top = [clip.boxes[p].y for p in rc.PANELS[:4]]
        bottom = [clip.boxes[p].y for p in rc.PANELS[4:]]
        assert len(set(top)) == 1 and len(set(bottom)) == 1 and bottom[0] > top[0]
        assert clip.rgb.shape == (60, h, w, 3) and clip.rgb.dtype == np.uint8


def test_the_truth_is_a_plausible_moving_mask(clips) -> None:
    for clip in clips.values():
        t = clip.truth
        assert t.shape == clip.rgb.shape[:3] and t.dtype == bool
        assert not t[0].any()  # the first frame's flow to itself is zero: all white
        share = t[1:].mean(axis=(1, 2))
        assert t.any() and share.max() < 0.25  # a few cables move, not the scene
        # the truth panel is white along the panel's borders except where cables leave it:
        # no frame line or title is read as motion
        assert t[:, :, 0].mean() < 0.2 and t[:, 0, :].mean() < 0.2


def test_the_stick_is_where_the_published_predictions_are_zeroed(clips) -> None:
    assert clips["0006"].stick is None
    stick = clips["0003"].stick
    assert stick is not None and 3000 < stick[0].sum() < 9000
    for p in rc.PUBLISHED:
        # the published evaluation zeroes the predictions on the stick: white in the video
        assert clips["0003"].published[p][stick].mean() < 0.01
    assert not (clips["0003"].truth & stick).any(axis=0).mean() > 0.001


def test_the_metric_by_hand() -> None:
    truth = np.zeros((3, 4), bool)
    truth[0, :3] = True  # 3 moving pixels
    pred = np.zeros((3, 4), bool)
    pred[0, 1:3] = True  # 2 of them found
    pred[2, 0] = True  # a false alarm
    pred[2, 3] = True  # on the stick: not counted
    stick = np.zeros((3, 4), bool)
    stick[2, 2:] = True
    p, r, iou = rc.frame_scores(pred, truth, stick)
    # TP 2, FP 1, FN 1
    assert (p, r, iou) == (2 / 3, 2 / 3, 2 / 4)
    # the same as the published per-image evaluation of flows with those magnitudes
    gt_flow = np.zeros((3, 4, 2), np.float32)
    gt_flow[truth] = (3.0, 0.0)
    pred_flow = np.zeros((3, 4, 2), np.float32)
    pred_flow[pred] = (0.0, -2.0)
    ref = movingcables_frame(gt_flow, pred_flow, rc.MOTION_THRESHOLD, actor_mask=stick)
    assert (ref.precision, ref.recall, ref.iou) == (p, r, iou)
    # nothing moves, nothing predicted: undefined, left out of the clip's mean
    assert all(math.isnan(v) for v in rc.frame_scores(np.zeros_like(pred), np.zeros_like(truth)))


class _Still(FlowEstimator):
    name = "still"

    def __init__(self, min_size: int = 0) -> None:
        self.min_size = min_size
        self.sizes: list[tuple[int, int]] = []

    def check_size(self, width: int, height: int) -> None:
        if min(width, height) < self.min_size:
            raise InputError(f"needs {self.min_size} px")

    def compute(self, image1, image2):
        self.sizes.append(image1.shape[:2])
        return np.zeros((*image1.shape[:2], 2), np.float32)


def test_an_estimator_object_is_scored_and_a_refused_size_is_said(clips) -> None:
    clip = clips["0006"]
    s = rc.evaluate(clip, _Still())
    assert s.method == "still" and len(s.iou) == 60
    assert s.mean["iou"] == 0.0 and s.mean["recall"] == 0.0 and math.isnan(s.mean["precision"])
    with pytest.raises(InputError, match="--scale"):
        rc.evaluate(clip, _Still(min_size=300))
    big = _Still(min_size=300)
    rc.evaluate(clip, big, scale=2)
    assert big.sizes[0] == (2 * clip.size[1], 2 * clip.size[0])


def test_dis_on_clip_0006_scores_in_a_sane_band(clips) -> None:
    s = rc.evaluate(clips["0006"], "dis-medium")
    assert 0.25 <= s.mean["iou"] <= 0.45, s.mean
    assert 0.4 <= s.mean["precision"] <= 0.8, s.mean
