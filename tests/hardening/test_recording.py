"""Issue 12, item 6: damaged or edited recordings end in RecordingError naming the file and
the problem; --overwrite writes beside the old recording and swaps, so one whole recording
survives any interruption."""

from __future__ import annotations

import io
import json
from pathlib import Path

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


@pytest.fixture
def rec(stream, tmp_path) -> Path:
    return write_stream(stream, tmp_path / "rec")


def edit_meta(path: Path, change) -> None:
    doc = json.loads((path / "meta.json").read_text())
    change(doc)
    (path / "meta.json").write_text(json.dumps(doc))


def rewrite_frame(path: Path, i: int, change) -> None:
    """Replace frame ``i``'s arrays and fix its index entry (size, checksum) to match, as a
    careful hand edit would."""
    import hashlib

    name = f"frames/{i:06d}.npz"
    with np.load(path / name) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    data = buf.getvalue()
    (path / name).write_bytes(data)
    lines = (path / "index.jsonl").read_text().splitlines()
    out = []
    for line in lines:
        e = json.loads(line)
        if e["file"] == name:
            e["bytes"], e["sha256"] = len(data), hashlib.sha256(data).hexdigest()
        out.append(json.dumps(e))
    (path / "index.jsonl").write_text("\n".join(out) + "\n")


def test_bad_intrinsics_in_meta(rec):
    edit_meta(rec, lambda d: d["intrinsics"].update(fx="abc"))  # raw ValueError before
    with pytest.raises(RecordingError, match=r"meta\.json: bad intrinsics .*fx must be a number"):
        ReplayCamera(rec)


def test_bad_camera_pose_in_meta(rec):
    edit_meta(rec, lambda d: d["meta"].update(T_world_camera=[1, 2, 3]))  # raw ValueError
    with pytest.raises(RecordingError, match=r"meta\.T_world_camera must be a 4x4 matrix"):
        ReplayCamera(rec)
    edit_meta(rec, lambda d: d["meta"].update(T_world_camera=np.full((4, 4), 2.0).tolist()))
    with pytest.raises(RecordingError, match="not a rigid transform"):
        ReplayCamera(rec)
    edit_meta(rec, lambda d: d["meta"].update(T_world_camera=[["a"] * 4] * 4))
    with pytest.raises(RecordingError, match="not a 4x4 matrix of numbers"):
        ReplayCamera(rec)
    edit_meta(rec, lambda d: d.update(meta=[1, 2]))  # meta.T_world_camera: AttributeError
    with pytest.raises(RecordingError, match="'meta' must be a mapping"):
        ReplayCamera(rec)


def test_action_stored_as_an_array(rec):
    rewrite_frame(rec, 2, lambda a: a.update(action=np.array([0, 1])))  # TypeError before
    with pytest.raises(RecordingError, match=r"000002\.npz: frame 2 is invalid .*action"):
        Recording(rec).frame(2)


def test_labels_of_the_wrong_shape(rec):
    rewrite_frame(rec, 1, lambda a: a.update(labels=np.zeros((3, 3), np.int16)))  # accepted
    with pytest.raises(RecordingError, match=r"000001\.npz: frame 1 is invalid .*labels"):
        read_stream(rec)


def test_swapped_index_entries(rec):
    lines = (rec / "index.jsonl").read_text().splitlines()
    a, b = json.loads(lines[1]), json.loads(lines[2])
    a["i"], b["i"] = b["i"], a["i"]  # frame 0 now names frame 1's file and the other way
    (rec / "index.jsonl").write_text(
        "\n".join([lines[0], json.dumps(a), json.dumps(b), *lines[3:]]) + "\n"
    )
    with pytest.raises(RecordingError, match="line 2 is corrupt .*names the file"):
        Recording(rec)


def test_swapped_index_values(rec):
    lines = (rec / "index.jsonl").read_text().splitlines()
    a, b = json.loads(lines[1]), json.loads(lines[2])
    a["timestamp"], b["timestamp"] = b["timestamp"], a["timestamp"]
    (rec / "index.jsonl").write_text(
        "\n".join([lines[0], json.dumps(a), json.dumps(b), *lines[3:]]) + "\n"
    )
    with pytest.raises(RecordingError, match=r"frame 1 has timestamp .* but index\.jsonl lists"):
        read_stream(rec)


def test_overwrite_over_a_recording_with_a_stray_subdirectory(stream, rec):
    (rec / "frames" / "stray").mkdir()  # IsADirectoryError, old recording half deleted before
    (rec / "frames" / "stray" / "x").write_bytes(b"x")
    short = Stream(stream.frames[-3:])
    write_stream(short, rec, overwrite=True)
    again = Recording(rec)
    assert again.complete and len(again) == 3
    assert not (rec / "frames" / "stray").exists()
    assert [p.name for p in rec.parent.iterdir()] == ["rec"]  # nothing left beside it


def test_interrupted_overwrite_keeps_the_old_recording(stream, rec):
    with pytest.raises(KeyboardInterrupt), RecordingWriter(rec, overwrite=True) as w:
        w.add_frame(0, stream.frames[0])
        raise KeyboardInterrupt
    old = Recording(rec)
    assert old.complete and len(old) == len(stream)
    assert [p.name for p in rec.parent.iterdir()] == ["rec"]


def test_a_killed_overwrite_leaves_the_old_recording_whole(stream, rec):
    w = RecordingWriter(rec, overwrite=True)
    for i, f in enumerate(stream.frames[:3]):
        w.add_frame(i, f)
    # the process dies here: no close(), no swap
    old = Recording(rec)
    assert old.complete and len(old) == len(stream)
    hidden = [p for p in rec.parent.iterdir() if p.name != "rec"]
    assert len(hidden) == 1 and hidden[0].name.startswith(".rec.new-")
    assert len(Recording(hidden[0])) == 3


def test_overwrite_refuses_a_directory_that_is_not_a_recording(stream, tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("keep me")
    with pytest.raises(RecordingError, match="not a cablesim recording .*refusing to overwrite"):
        write_stream(stream, tmp_path / "notes", overwrite=True)
    assert (tmp_path / "notes" / "todo.txt").read_text() == "keep me"
    (tmp_path / "file").write_text("x")
    with pytest.raises(RecordingError, match="exists and is not a directory"):
        write_stream(stream, tmp_path / "file")


def test_two_writers_use_different_temporary_names(stream, tmp_path):
    # temporary names carry the process id and a random token: never the same twice
    from cablesim.recording import _unique_name

    names = {_unique_name(tmp_path / "meta.json", "tmp").name for _ in range(100)}
    assert len(names) == 100
    assert all(n.startswith(".meta.json.tmp-") for n in names)
