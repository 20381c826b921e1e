"""MovingCables flow PNGs and clip folders as published, and the published evaluation of a clip."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cablesim.errors import InputError, RecordingError
from cablesim.formats import detect_layout
from cablesim.formats.movingcables import (
    ClipFrame,
    PublishedFarneback,
    clip_indices,
    encode_values,
    evaluate_clip,
    labels_to_instances,
    list_clips,
    read_clip,
    read_flow_png,
    uncertainty_channel,
    write_clip,
    write_flow_png,
)
from cablesim.perception.flow import DISFlow


def test_flow_png_encoding_as_published(tmp_path):
    # floor(v * 64 + 2**15), computed in float32, clipped
    values = np.array([0.0, 1 / 64, -1 / 128, 0.0156249, 600.0, -600.0, np.nan], np.float32)
    assert encode_values(values).tolist() == [32768, 32769, 32767, 32769, 65535, 0, 32768]
    rng = np.random.default_rng(0)
    flow = rng.uniform(-100, 100, (6, 7, 2)).astype(np.float32)
    inst = rng.integers(0, 5, (6, 7)).astype(np.uint16)
    write_flow_png(tmp_path / "f.png", flow, inst)
    back, ids = read_flow_png(tmp_path / "f.png")
    err = flow - back  # floor: decoded <= true value, up to float32 rounding of the sum
    assert (err > -1e-2 / 64).all() and (err < 1 / 64).all() and (err > 1 / 128).any()
    assert np.array_equal(ids, inst)
    # the PNG stores x, y, id in RGB order; OpenCV reads them reversed (as the published reader)
    raw = cv2.imread(str(tmp_path / "f.png"), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and np.array_equal(raw[..., 0], inst)
    assert (raw[0, 0, 2] - 2**15) / 64 == back[0, 0, 0]
    # predicted flow: third channel = encoded |uncertainty|, or the encoded -1 without it
    assert (uncertainty_channel(None, (2, 3)) == 32704).all()
    u = np.zeros((2, 3, 2), np.float32)
    u[0, 0] = (3.0, 4.0)
    assert uncertainty_channel(u, (2, 3))[0, 0] == 32768 + 5 * 64
    assert labels_to_instances(np.array([[-2, -1, 0, 3]])).tolist() == [[0, 0, 1, 4]]


def test_flow_png_errors(tmp_path):
    with pytest.raises(RecordingError, match="not found"):
        read_flow_png(tmp_path / "none.png")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(RecordingError, match="decode"):
        read_flow_png(tmp_path / "bad.png")
    cv2.imwrite(str(tmp_path / "u8.png"), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(RecordingError, match="16-bit"):
        read_flow_png(tmp_path / "u8.png")
    with pytest.raises(InputError, match="third channel"):
        write_flow_png(tmp_path / "x.png", np.zeros((4, 4, 2), np.float32), np.zeros((3, 3)))


def _clip(h: int = 48, w: int = 64, n: int = 3, shift: float = 4.0) -> list[ClipFrame]:
    """A textured band moving right by ``shift`` px per image over a static texture; a stick
    (a static rectangle) in the corner; flow from each image back to the first."""
    rng = np.random.default_rng(3)
    board = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 1.5)
    band = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 1.5)
    band_rows = slice(16, 28)
    frames = []
    for k in range(n):
        d = shift * k
        moved = np.roll(band, int(d), axis=1)
        g = board.copy()
        g[band_rows] = moved[band_rows]
        rgb = np.repeat(
            cv2.normalize(g, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)[..., None], 3, 2
        )
        flow = np.zeros((h, w, 2), np.float32)
        flow[band_rows, :, 0] = -d  # current(p) = first(p + flow)
        inst = np.zeros((h, w), np.uint16)
        inst[band_rows] = 1
        stick = np.zeros((h, w), bool)
        stick[band_rows, 48:] = True  # the poking stick over a quarter of the band
        frames.append(ClipFrame(2 * k + 1, rgb, flow, flow.copy(), inst, stick))
    return frames


def test_clip_round_trip_and_layout(tmp_path):
    split = tmp_path / "test"
    frames = _clip()
    write_clip(split, "0001", frames)
    assert detect_layout(split) == "movingcables"
    assert list_clips(split) == ["0001"] and clip_indices(split, "0001") == [1, 3, 5]
    for a, b in zip(frames, read_clip(split, "0001"), strict=True):
        assert a.index == b.index and np.array_equal(a.rgb, b.rgb)
        assert (
            np.abs(a.flow - b.flow).max() < 1 / 64
            and np.abs(a.normal_flow - b.normal_flow).max() < 1 / 64
        )
        assert np.array_equal(a.instances, b.instances) and np.array_equal(
            a.stick_mask, b.stick_mask
        )
    for sub in ("rgb_clips", "flow_first_back", "normal_flow_first_back", "stick_masks"):
        assert (split / sub / "0001" / "00000003.png").is_file()
    with pytest.raises(InputError, match="odd"):
        write_clip(split, "0002", [ClipFrame(2, frames[0].rgb)])
    with pytest.raises(InputError, match="4 digits"):
        write_clip(split, "12", frames)
    (split / "rgb_clips" / "0001" / "00000004.png").write_bytes(b"")
    with pytest.raises(RecordingError, match="odd"):
        clip_indices(split, "0001")


def test_published_evaluation_of_a_clip(tmp_path):
    split = tmp_path / "test"
    write_clip(split, "0001", _clip(n=4, shift=2.0))
    frames, s = evaluate_clip(split, "0001", DISFlow(), thr_motion=1.0)
    assert len(frames) == s.images == 4
    assert frames[0].n_gt_moving == 0 and frames[0].n_pred_moving < 20  # the first image
    assert s.iou > 0.45 and s.precision > 0.8 and s.recall > 0.45
    assert s.epe < 1.0 and s.epe_gt_gt1 > s.epe_gt_le1
    # the stick hides the band's right quarter: those pixels are never predicted moving
    _, no_stick = evaluate_clip(split, "0001", DISFlow(), thr_motion=1.0, use_stick=False)
    assert s.recall < no_stick.recall - 0.1
    _, sp = evaluate_clip(split, "0001", PublishedFarneback(), thr_motion=1.0)
    assert sp.images == 4 and np.isfinite(sp.epe)
    with pytest.raises(InputError, match="truth"):
        evaluate_clip(split, "0001", DISFlow(), 1.0, truth="labels")
