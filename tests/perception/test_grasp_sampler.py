"""segment_pose and the grasp sampler's requirements and frontier order."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import (
    GraspSampler,
    GraspSamplerParams,
    Intrinsics,
    geometric_median,
    segment_pose,
)
from cablesim.perception.skeleton import split_skeleton, thinning

H, W = 240, 320
K = Intrinsics(300.0, 300.0, (W - 1) / 2, (H - 1) / 2, W, H)
DEPTH = np.full((H, W), 1.0, np.float32)


def _line(p0, p1, value=1, thickness=8, img=None):
    img = np.zeros((H, W), np.uint8) if img is None else img
    cv2.line(img, p0, p1, int(value), thickness)
    return img


def test_segment_pose_on_plane():
    m = _line((100, 120), (160, 120)).astype(bool)
    pose = segment_pose(m, DEPTH, K)
    expected = K.backproject(np.array([130.0, 120.0]), 1.0)
    assert np.allclose(pose.centre, expected, atol=3e-3)
    assert np.allclose(pose.axis, [1, 0, 0], atol=1e-3)
    assert pose.out_of_plane_deg < 1.0
    # depth ramp along x: the axis tilts out of the image plane
    ramp = (1.0 + (np.arange(W) - 130) * 0.003).astype(np.float32)[None].repeat(H, 0)
    tilted = segment_pose(m, ramp, K, inlier_distance=0.5)
    assert tilted.out_of_plane_deg > 30


def test_geometric_median_is_robust():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [100, 100, 0.0]])
    gm = geometric_median(pts)
    assert np.linalg.norm(gm[:2] - 0.5) < 0.6
    assert np.allclose(geometric_median(np.ones((3, 3))), 1.0)


def test_segment_pose_bad_input():
    m = _line((100, 120), (160, 120)).astype(bool)
    with pytest.raises(InputError, match="empty"):
        segment_pose(np.zeros((H, W), bool), DEPTH, K)
    with pytest.raises(InputError, match="no valid depth"):
        segment_pose(m, np.full((H, W), np.nan, np.float32), K)
    with pytest.raises(InputError, match="intrinsics are missing"):
        segment_pose(m, DEPTH, None)
    with pytest.raises(InputError, match="size"):
        segment_pose(m[:10], DEPTH, K)
    with pytest.raises(InputError, match="float"):
        segment_pose(m, DEPTH.astype(np.uint16), K)


def test_thinning_and_split():
    m = _line((20, 50), (220, 50), thickness=7).astype(bool)
    sk = thinning(m)
    assert sk.sum() < 0.25 * m.sum()
    assert (sk & m).sum() == sk.sum()
    labels = split_skeleton(sk, 30)
    sizes = np.bincount(labels[labels > 0])[1:]
    assert len(sizes) >= 6 and sizes.max() <= 31


def test_proposes_most_supported_and_records_rejections():
    votes = _line((20, 40), (300, 60), 2)
    votes = _line((20, 150), (300, 200), 1, img=votes)
    cv2.circle(votes, (160, 110), 12, 2, -1)  # round blob, 2 votes
    cv2.line(votes, (60, 110), (68, 110), 2, 1)  # tiny
    res = GraspSampler().propose(votes.astype(np.int16), DEPTH, K)
    assert res.proposal is not None and res.proposal.level == 2
    assert res.proposal.frontier == pytest.approx(0.2)
    rej = res.rejections()
    assert rej["eccentricity"] >= 1 and rej["area"] >= 1
    v, u = np.nonzero(res.proposal.mask)
    assert v.max() < 100  # on the 2-vote hose


def test_never_proposes_blacklisted_or_too_close():
    votes = _line((20, 40), (300, 60), 2).astype(np.int16)
    s = GraspSampler()
    centres = []
    for _ in range(10):
        res = s.propose(votes, DEPTH, K)
        if res.proposal is None:
            break
        c = res.proposal.centre
        for prev in centres:
            assert np.linalg.norm(prev - c) >= s.params.g_min - 1e-9
        centres.append(c)
        s.accept(res.proposal)
    assert 2 <= len(centres) <= 10
    res = s.propose(votes, DEPTH, K)
    assert res.proposal is None
    reasons = {c.rejected.split(":")[0] for c in res.candidates if c.rejected}
    assert reasons <= {"blacklisted", "too_close", "eccentricity", "area"}
    assert "too_close" in reasons or "blacklisted" in reasons


def test_frontier_order_within_and_across_levels():
    # previous grasp at the image centre; candidates at various distances
    centre_px = np.array([160.0, 120.0])
    s = GraspSampler(GraspSamplerParams(segment_length_px=60))
    s.add_grasp(K.backproject(centre_px, 1.0))
    votes = np.zeros((H, W), np.uint8)
    # level-2 segment ~0.13 m away (40 px at 300 px/m), big
    _line((130, 80), (190, 80), 2, 10, img=votes)
    # level-1 segment ~0.3 m away (90 px)
    _line((220, 210), (280, 210), 1, 8, img=votes)
    res = s.propose(votes.astype(np.int16), DEPTH, K)
    assert res.proposal.level == 2 and res.proposal.frontier == pytest.approx(0.1)
    # same level: the farther (>= 0.2 m) segment wins over a bigger closer one
    votes2 = np.zeros((H, W), np.uint8)
    _line((130, 80), (190, 80), 2, 12, img=votes2)  # ~0.13 m, larger area
    _line((20, 20), (80, 20), 2, 6, img=votes2)  # ~0.4 m
    res = s.propose(votes2.astype(np.int16), DEPTH, K)
    assert res.proposal.frontier == pytest.approx(0.2)
    assert res.proposal.candidate.min_distance >= 0.2


def test_reachability_callback_and_depth_requirement():
    votes = _line((20, 40), (300, 60), 1).astype(np.int16)
    calls = []

    def reach(c, a):
        calls.append(c)
        return (len(calls) > 2, "joint limits")

    s = GraspSampler(reachability=reach)
    res = s.propose(votes, DEPTH, K)
    assert res.proposal is not None and len(calls) == 3
    assert sum(1 for c in res.candidates if (c.rejected or "").startswith("unreachable")) == 2
    depth = DEPTH.copy()
    depth[:100] = 0.0
    res = GraspSampler().propose(votes, depth, K)
    assert res.proposal is None and res.rejections()["depth"] >= 1


def test_out_of_plane_rejected():
    votes = _line((100, 120), (140, 120), 1).astype(np.int16)
    ramp = (1.0 + (np.arange(W) - 120) * 0.02).astype(np.float32)[None].repeat(H, 0)
    res = GraspSampler(GraspSamplerParams(inlier_distance=1.0)).propose(votes, ramp, K)
    assert res.proposal is None and "out_of_plane" in res.rejections()


def test_sampler_bad_input():
    s = GraspSampler()
    with pytest.raises(InputError, match="intrinsics"):
        s.propose(np.zeros((H, W), np.int16), DEPTH, None)
    with pytest.raises(InputError, match="differ"):
        s.propose(np.zeros((10, 10), np.int16), DEPTH, K)
    with pytest.raises(InputError, match="integer"):
        s.propose(np.zeros((H, W), np.float32), DEPTH, K)
    with pytest.raises(InputError, match="intrinsics are for"):
        s.propose(np.zeros((H, W), np.int16), DEPTH, K.scaled(2.0))
    with pytest.raises(InputError, match="Intrinsics"):
        s.propose(np.zeros((H, W), np.int16), DEPTH, K.to_dict())
    with pytest.raises(InputError, match="area_min"):
        GraspSamplerParams(area_min=10, area_max=5)
    assert s.propose(np.zeros((H, W), np.int16), DEPTH, K).proposal is None


def test_unreachable_segment_not_asked_again_at_lower_level():
    votes = _line((110, 60), (130, 60), 2)  # short 2-vote segment: one piece
    votes = _line((20, 180), (300, 180), 1, img=votes)
    asked = []

    def reach(c, a):
        asked.append(c)
        return (c[1] > 0, "out of workspace")  # the upper (2-vote) segment is unreachable

    res = GraspSampler(reachability=reach).propose(votes.astype(np.int16), DEPTH, K)
    assert res.proposal is not None and res.proposal.level == 1
    assert res.proposal.centre[1] > 0
    upper = [c for c in asked if c[1] <= 0]
    assert len(upper) == 1  # asked once, remembered at level 1
    assert any("same segment" in (c.rejected or "") for c in res.candidates)
