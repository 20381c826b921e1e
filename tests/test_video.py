"""Videos: H.264 that plays everywhere, checked by its sample entry and by ffmpeg itself; the
mp4v and GIF fallbacks."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from cablesim.errors import ConfigError, InputError
from cablesim.video import VideoWriter, count_video_frames, h264_roundtrip, video_codec


def _frames(n: int = 24, h: int = 121, w: int = 161) -> list[np.ndarray]:
    out = []
    for i in range(n):
        f = np.zeros((h, w, 3), np.uint8)
        f[:, 4 * i : 4 * i + 20] = (255, 128, 0)
        f[20:40, :] = (0, 0, 200)
        out.append(f)
    return out


def _write(path, encoders=("h264", "mp4v")) -> VideoWriter:
    w = VideoWriter(path, fps=15, encoders=encoders)
    for f in _frames():
        w.write(f)
    w.close()
    return w


def test_h264_is_written_and_reads_back(tmp_path):
    w = _write(tmp_path / "a.mp4")
    assert w.final_path == tmp_path / "a.mp4" and w.encoder == "h264"
    assert video_codec(w.final_path) == "avc1"
    assert count_video_frames(w.final_path) == 24
    # the bundled ffmpeg names the stream H.264 too (an independent reader of the same file)
    import imageio_ffmpeg

    probe = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(w.final_path)],
        capture_output=True,
        text=True,
    )
    assert "Video: h264" in probe.stderr and "yuv420p" in probe.stderr, probe.stderr
    assert "160x120" in probe.stderr  # odd sides are cropped to even ones


def test_same_frames_same_bytes(tmp_path):
    a, b = _write(tmp_path / "a.mp4"), _write(tmp_path / "b.mp4")
    assert a.final_path.read_bytes() == b.final_path.read_bytes()


def test_mp4v_fallback(tmp_path):
    w = _write(tmp_path / "c.mp4", encoders=("mp4v",))
    assert w.encoder == "mp4v" and video_codec(w.final_path) == "mp4v"
    assert count_video_frames(w.final_path) == 24


def test_gif_when_no_mp4_encoder(tmp_path):
    w = _write(tmp_path / "d.mp4", encoders=())
    assert w.encoder == "gif" and w.final_path == tmp_path / "d.gif"
    assert not (tmp_path / "d.mp4").exists()
    import imageio.v2 as imageio

    assert len(imageio.mimread(w.final_path)) == 12  # every other frame, half size


def test_codec_of_other_files(tmp_path):
    assert video_codec(tmp_path / "missing.mp4") is None
    (tmp_path / "junk.mp4").write_bytes(b"\x00\x00\x00\x08free" + b"junk" * 10)
    assert video_codec(tmp_path / "junk.mp4") is None
    with pytest.raises(ValueError, match="encoders"):
        VideoWriter(tmp_path / "x.mp4", encoders=("divx",))


def test_h264_roundtrip_degrades_like_a_video_and_repeats_itself():
    """A smooth moving pattern comes back close but not equal (blocks, chroma), the same bytes
    every time; a harder CRF loses more; an odd last row and column keep their pixels."""
    yy, xx = np.mgrid[0:121, 0:161].astype(np.float32)
    frames = []
    for k in range(6):
        g = 128 + 60 * np.sin((xx - 2 * k) / 5.0) * np.cos(yy / 7.0)
        frames.append(np.dstack([g, 255 - g, np.full_like(g, 90)]).clip(0, 255).astype(np.uint8))
    soft, again, hard = (h264_roundtrip(frames, c) for c in (18, 18, 40))
    assert len(soft) == 6 and all(f.shape == (121, 161, 3) and f.dtype == np.uint8 for f in soft)
    assert all(np.array_equal(a, b) for a, b in zip(soft, again, strict=True))

    def err(out):
        return np.mean(
            [
                np.abs(o[:120, :160].astype(int) - f[:120, :160]).mean()
                for o, f in zip(out, frames, strict=True)
            ]
        )

    assert 0 < err(soft) < 4.0 and err(hard) > 1.5 * err(soft)  # (3.1 and 6.9 when written)
    assert np.array_equal(soft[2][120], frames[2][120]) and np.array_equal(
        soft[2][:, 160], frames[2][:, 160]
    )
    with pytest.raises(ConfigError, match="crf"):
        h264_roundtrip(frames, 60)
    with pytest.raises(InputError, match="differ in size"):
        h264_roundtrip([frames[0], frames[1][:120]], 20)
