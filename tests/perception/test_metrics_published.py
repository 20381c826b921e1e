"""Metrics as published: mask scores with NaN where undefined, means without the NaNs, scores
in a crop, and the MovingCables flow protocol, against hand-worked cases."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception.metrics import (
    BETAS,
    f_beta_counts,
    flow_epe,
    mean_scores,
    movingcables_frame,
    movingcables_summary,
    score_mask,
)


def test_betas_down_to_0_1_from_counts():
    assert BETAS == (1.0, 0.5, 0.4, 0.3, 0.2, 0.1)
    truth = np.zeros((4, 4), bool)
    truth[0] = True
    pred = np.zeros((4, 4), bool)
    pred[0, :2] = True
    pred[1, 0] = True  # TP 2, FP 1, FN 2
    s = score_mask(pred, truth)
    # F_0.1 = 1.01 * 2 / (1.01 * 2 + 0.01 * 2 + 1)
    assert s.f[0.1] == pytest.approx(2.02 / 3.04)
    assert s.f[0.4] == pytest.approx(f_beta_counts(2, 1, 2, 0.4))
    assert s.to_dict()["f0.1"] == s.f[0.1]


def test_scores_in_the_crop_only():
    truth = np.zeros((6, 8), bool)
    truth[1, 1:4] = True
    pred = truth.copy()
    pred[5, 7] = True  # a false positive outside the crop
    assert score_mask(pred, truth).precision == pytest.approx(0.75)
    assert score_mask(pred, truth, crop=(0, 0, 5, 4)).precision == 1.0
    with pytest.raises(InputError, match="crop"):
        score_mask(pred, truth, crop=(0, 0, 5))


def test_nanmean_over_sequences():
    full = np.ones((2, 2), bool)
    none = np.zeros((2, 2), bool)
    m = mean_scores([score_mask(full, full), score_mask(none, full), score_mask(none, none)])
    assert m.precision == 1.0  # only the first sequence has a precision
    assert m.recall == 0.5 and m.iou == 0.5 and m.f[0.4] == 0.5


def test_movingcables_frame_hand_worked():
    gt = np.zeros((4, 4, 2), np.float32)
    gt[0, :3] = (3.0, 0.0)  # 3 moving pixels (|gt| 3 > 2)
    gt[1, 0] = (0.0, 1.5)  # neither moving nor static
    pred = np.zeros_like(gt)
    pred[0, :2] = (3.0, 0.0)  # 2 right
    pred[2, 0] = (0.0, 2.5)  # 1 wrong, on a static pixel
    pred[3, 3] = (5.0, 0.0)  # under the stick: no motion, zero flow
    stick = np.zeros((4, 4), bool)
    stick[3, 3] = True
    f = movingcables_frame(gt, pred, 2.0, 1.0, stick)
    assert (f.precision, f.recall, f.iou) == pytest.approx((2 / 3, 2 / 3, 2 / 4))
    assert f.false_motion == pytest.approx(1 / 3)
    assert (f.n_gt_moving, f.n_gt_static, f.n_pred_moving) == (3, 12, 3)
    # EPE over all 16 pixels: 3 (missed) + 1.5 + 2.5 = 7 (the stick pixel's 5 px are zeroed)
    assert f.epe == pytest.approx(7 / 16)
    empty = movingcables_frame(np.zeros_like(gt), np.zeros_like(gt), 2.0)
    assert np.isnan(empty.precision) and np.isnan(empty.recall) and np.isnan(empty.iou)
    s = movingcables_summary([f, empty])
    assert s.precision == pytest.approx(2 / 3) and s.iou == pytest.approx(0.5)
    assert s.epe == pytest.approx(7 / 32)
    # split by |gt|: <= 1 px pools 12 + 16 pixels with errors 2.5; > 1 px pools 4 pixels: 3 + 1.5
    assert s.epe_gt_le1 == pytest.approx(2.5 / 28)
    assert s.epe_gt_gt1 == pytest.approx(4.5 / 4)
    # split by |prediction|: > 1 px are the two right pixels and the wrong one
    assert s.epe_pred_gt1 == pytest.approx(2.5 / 3)
    assert s.gt_moving_share == pytest.approx(3 / 32)
    # cablesim's own EPE (moving pixels only) stays beside it
    assert flow_epe(pred, gt) == pytest.approx((0 + 0 + 3 + 1.5) / 4)
    with pytest.raises(InputError):
        movingcables_summary([])
