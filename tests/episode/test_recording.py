"""Recording format: round trip, replay through the Camera interface, truncation, corruption,
interrupted recordings.  Synthetic streams only (fast, no simulation)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cablesim.camera.replay import ReplayCamera
from cablesim.errors import RecordingError
from cablesim.frames import Stream
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.recording import Recording, RecordingWriter, read_stream, write_stream


@pytest.fixture(scope="module")
def stream() -> Stream:
    spec = SyntheticSpec(height=24, width=32, periods=1, samples_per_period=4)
    return synthetic_stream([Region((4, 12, 4, 20), label=0)], spec)


def assert_same_frames(a: Stream, b: Stream, flow: bool = True) -> None:
    assert len(a) == len(b)
    for fa, fb in zip(a, b, strict=True):
        assert np.array_equal(fa.rgb, fb.rgb)
        assert np.array_equal(fa.depth, fb.depth)
        assert np.array_equal(fa.gripper, fb.gripper)
        assert (fa.action, fa.sample, fa.timestamp) == (fb.action, fb.sample, fb.timestamp)
        assert fa.intrinsics == fb.intrinsics
        if fa.truth is not None:
            assert fb.truth is not None
            assert np.array_equal(fa.truth.labels, fb.truth.labels)
            if flow:
                assert np.array_equal(fa.truth.flow_to_target, fb.truth.flow_to_target)
                assert np.array_equal(fa.truth.flow_valid, fb.truth.flow_valid)
            else:  # flow comes after the target frame: not there when interrupted
                assert fb.truth.flow_to_target is None


def test_round_trip_and_replay(stream, tmp_path):
    write_stream(stream, tmp_path / "rec")
    rec = Recording(tmp_path / "rec")
    assert rec.complete and len(rec) == len(stream)
    assert_same_frames(stream, read_stream(tmp_path / "rec"))
    cam = ReplayCamera(tmp_path / "rec")
    assert cam.intrinsics == stream.intrinsics
    for f in stream:
        img = cam.capture()
        assert np.array_equal(img.rgb, f.rgb) and np.array_equal(img.depth, f.depth)
        assert img.timestamp == f.timestamp
        assert cam.last_frame is not None and np.array_equal(cam.last_frame.gripper, f.gripper)
    with pytest.raises(RecordingError, match="end of the recording"):
        cam.capture()
    assert_same_frames(stream, cam.stream())


def test_existing_directory_is_not_overwritten(stream, tmp_path):
    write_stream(stream, tmp_path / "rec")
    with pytest.raises(RecordingError, match="not empty"):
        write_stream(stream, tmp_path / "rec")
    write_stream(stream, tmp_path / "rec", overwrite=True)
    assert len(Recording(tmp_path / "rec")) == len(stream)


def test_truncated_frame_names_the_file(stream, tmp_path):
    write_stream(stream, tmp_path / "rec")
    victim = tmp_path / "rec" / "frames" / "000003.npz"
    victim.write_bytes(victim.read_bytes()[:100])
    rec = Recording(tmp_path / "rec")
    rec.frame(2)  # the others still read
    with pytest.raises(RecordingError, match=r"000003\.npz.*frame 3.*truncated"):
        rec.frame(3)
    with pytest.raises(RecordingError, match="000003"):
        read_stream(tmp_path / "rec")


def test_corrupt_frame_and_flow(stream, tmp_path):
    write_stream(stream, tmp_path / "rec")
    for sub, what in (("frames", "frame 1"), ("flow", "flow of frame 1")):
        victim = tmp_path / "rec" / sub / "000001.npz"
        good = victim.read_bytes()
        data = bytearray(good)
        data[len(data) // 2] ^= 0xFF
        victim.write_bytes(bytes(data))
        with pytest.raises(RecordingError, match=f"{sub}/000001.npz: {what} is corrupt"):
            Recording(tmp_path / "rec").frame(1)
        # without the checksum the zip/npz reader must still notice or give the same bytes
        victim.write_bytes(good)


def test_missing_or_corrupt_meta_and_index(stream, tmp_path):
    with pytest.raises(RecordingError, match="meta.json: missing"):
        Recording(tmp_path)
    write_stream(stream, tmp_path / "rec")
    index = tmp_path / "rec" / "index.jsonl"
    lines = index.read_text().splitlines()
    index.write_text("\n".join([lines[0], "{not json", *lines[2:]]) + "\n")
    with pytest.raises(RecordingError, match="index.jsonl: line 2 is corrupt"):
        Recording(tmp_path / "rec")
    (tmp_path / "rec" / "meta.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(RecordingError, match="not a cablesim-recording"):
        Recording(tmp_path / "rec")


def test_interrupted_recording_keeps_frames_written(stream, tmp_path):
    path = tmp_path / "rec"
    with pytest.raises(RuntimeError, match="boom"):
        with RecordingWriter(path, meta={"what": "interrupted"}) as w:
            for i, f in enumerate(stream.frames[:5]):
                w.add_frame(i, f)
            raise RuntimeError("boom")
    rec = Recording(path)
    assert not rec.complete and len(rec) == 5
    assert_same_frames(Stream(stream.frames[:5]), rec.to_stream(), flow=False)


def test_killed_recording_with_partial_index_line(stream, tmp_path):
    """A process killed mid-write: no close(), a half-written index line, a stray temp file."""
    path = tmp_path / "rec"
    w = RecordingWriter(path)
    for i, f in enumerate(stream.frames[:4]):
        w.add_frame(i, f)
    w._index.write('{"kind": "frame", "i": 4, "fi')  # noqa: SLF001 - simulate the crash
    w._index.flush()  # noqa: SLF001
    (path / "frames" / "000004.npz.tmp").write_bytes(b"partial")
    rec = Recording(path)
    assert not rec.complete and len(rec) == 4
    assert_same_frames(Stream(stream.frames[:4]), rec.to_stream(), flow=False)
