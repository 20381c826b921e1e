"""Pictures for people: titles, keys that match the colours they explain, error overlays."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT
from cablesim.viz import (
    FN_COLOUR,
    FP_COLOUR,
    LABEL_COLOURS,
    TP_COLOUR,
    colour_bar,
    colour_depth,
    colour_flow,
    colour_labels,
    colour_map,
    errors_tile,
    flow_wheel,
    overlay_errors,
    panel,
    titled,
    write_png,
)


def test_titles_sit_above_each_tile():
    a = np.full((120, 160, 3), 90, np.uint8)
    out = titled(a, "votes")
    strip = out.shape[0] - 120
    assert strip >= 12 and out.shape[1] == 160
    assert np.array_equal(out[strip:], a)
    assert (out[:strip] < 100).any() and (out[:strip] == 255).mean() > 0.7  # dark text on white
    p = panel([a, np.zeros((100, 80, 3), np.uint8)], ["one", "two"])
    assert p.shape[0] == 120 + strip and p.shape[1] == 160 + 6 + 80
    with pytest.raises(ValueError, match="titles"):
        panel([a], ["one", "two"])


def test_flow_wheel_is_the_key_of_colour_flow():
    d, mm = 101, 8.0
    wheel = flow_wheel(d, mm)
    c = d // 2
    for du, dv in ((1, 0), (0, 1), (-1, 0), (0, -1), (0.7, -0.7)):
        u, v = int(round(c + du * 0.9 * c)), int(round(c + dv * 0.9 * c))
        flow = np.array([[[(u - c) / c * mm, (v - c) / c * mm]]])
        assert np.abs(wheel[v, u].astype(int) - colour_flow(flow, mm)[0, 0]).max() <= 2
    assert (wheel[0, 0] == 255).all()  # outside the disc
    assert (wheel[c, c] < 10).all()  # no motion is black
    invalid = colour_flow(np.ones((4, 4, 2)), valid=np.eye(4, dtype=bool))
    assert (invalid[~np.eye(4, dtype=bool)] == 0).all() and (
        invalid[np.eye(4, dtype=bool)] > 0
    ).any()


def test_colour_bar_runs_from_hi_at_top_to_lo():
    bar = colour_bar(200, 0.0, 1.0)
    col = 8  # inside the ramp
    top, bottom = bar[9, col], bar[200 - 10, col]
    hi = colour_map(np.array([[1.0]]), 0.0, 1.0)[0, 0]
    lo = colour_map(np.array([[0.0]]), 0.0, 1.0)[0, 0]
    assert np.abs(top.astype(int) - hi).max() <= 12 and np.abs(bottom.astype(int) - lo).max() <= 12
    rev = colour_bar(200, 0.0, 1.0, "turbo", reverse=True)
    assert (
        np.abs(rev[9, col].astype(int) - colour_map(np.array([[0.0]]), 0, 1, "turbo")[0, 0]).max()
        <= 12
    )


def test_depth_and_labels():
    depth = np.tile(np.linspace(0.5, 2.0, 50, dtype=np.float32), (10, 1))
    depth[0, 0] = 0.0
    rgb = colour_depth(depth)
    assert (rgb[0, 0] == 0).all()
    assert rgb[5, 1, 0] > rgb[5, 1, 2] and rgb[5, 48, 2] > rgb[5, 48, 0]  # near warm, far cold
    labels = np.array([[LABEL_BACKGROUND, LABEL_ROBOT, 0, 9]], np.int16)
    out = colour_labels(labels)
    assert (out[0, 0] == 0).all() and (out[0, 1] == 255).all()
    assert (out[0, 2] == LABEL_COLOURS[0]).all() and (out[0, 3] == LABEL_COLOURS[1]).all()


def test_errors_overlay_tp_green_fp_red_fn_blue(tmp_path):
    rgb = np.full((6, 8, 3), 200, np.uint8)
    pred = np.zeros((6, 8), bool)
    truth = np.zeros((6, 8), bool)
    pred[0:2, 0:4], truth[0:2, 2:6] = True, True
    out = overlay_errors(rgb, pred, truth)
    assert tuple(out[0, 2]) == TP_COLOUR and tuple(out[0, 0]) == FP_COLOUR
    assert tuple(out[0, 5]) == FN_COLOUR and tuple(out[5, 5]) == (70, 70, 70)
    tile = errors_tile(
        np.full((120, 160, 3), 200, np.uint8),
        np.eye(120, 160, dtype=bool),
        np.eye(120, 160, dtype=bool),
    )
    assert tile.shape[0] == 120 and tile.shape[1] > 160  # the key beside the image
    write_png(tmp_path / "e.png", panel([tile], ["errors"]))
    assert (tmp_path / "e.png").stat().st_size > 0
