"""Fuzzing recording files: whatever happens to a recording on disk (edited meta.json or index
lines, frames replaced by other arrays, flipped or cut bytes), reading and replaying it works
or raises RecordingError; never another exception."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cablesim.camera.replay import ReplayCamera
from cablesim.errors import RecordingError
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.recording import Recording, write_stream

from ._fuzz import HOSTILE, fuzz

FRAME_KEYS = ["rgb", "depth", "gripper", "action", "sample", "timestamp", "gripper_quat",
              "gripper_opening", "labels", "grasped_hose"]  # fmt: skip


@pytest.fixture(scope="module")
def original(tmp_path_factory) -> Path:
    spec = SyntheticSpec(height=12, width=16, periods=1, samples_per_period=2)
    stream = synthetic_stream([Region((2, 6, 2, 12), label=0)], spec)
    stream.meta["T_world_camera"] = np.eye(4).tolist()
    return write_stream(stream, tmp_path_factory.mktemp("rec") / "rec")


def fresh(original: Path, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("case") / "rec"
    shutil.copytree(original, path)
    return path


def read_everything(path: Path) -> None:
    """Open, read every frame and replay: RecordingError is the only way to fail."""
    try:
        rec = Recording(path)
        stream = rec.to_stream()
        cam = ReplayCamera(rec)
        for _ in range(len(cam)):
            cam.capture()
        assert cam.T_world_camera is None or cam.T_world_camera.shape == (4, 4)
        assert len(stream) == len(rec)
    except RecordingError as e:
        assert str(path) in str(e) or "recording" in str(e)


def put_path(doc, path, value):
    for k in path[:-1]:
        doc = doc[k]
    doc[path[-1]] = value


META_PATHS = [("format",), ("version",), ("complete",), ("frames",), ("meta",),
              ("intrinsics",), ("meta", "T_world_camera"), ("intrinsics", "fx"),
              ("intrinsics", "width"), ("intrinsics", "cy")]  # fmt: skip


@fuzz(60)
@given(st.lists(st.tuples(st.sampled_from(META_PATHS), HOSTILE), min_size=1, max_size=3))
def test_edited_meta(original, tmp_path_factory, edits):
    path = fresh(original, tmp_path_factory)
    doc = json.loads((path / "meta.json").read_text())
    for where, value in edits:
        try:
            put_path(doc, where, value)
        except (KeyError, TypeError, IndexError):  # the parent was replaced: skip this edit
            pass
    (path / "meta.json").write_text(json.dumps(doc))
    read_everything(path)


INDEX_KEYS = ["kind", "i", "file", "bytes", "sha256", "action", "sample", "timestamp"]


@fuzz(80)
@given(
    st.lists(
        st.one_of(
            st.tuples(st.just("set"), st.integers(0, 20), st.sampled_from(INDEX_KEYS), HOSTILE),
            st.tuples(st.just("drop"), st.integers(0, 20)),
            st.tuples(st.just("dup"), st.integers(0, 20)),
            st.tuples(st.just("swap"), st.integers(0, 20), st.integers(0, 20)),
            st.tuples(st.just("line"), st.integers(0, 20), st.binary(max_size=30)),
        ),
        min_size=1,
        max_size=3,
    )
)
def test_edited_index(original, tmp_path_factory, edits):
    path = fresh(original, tmp_path_factory)
    lines = (path / "index.jsonl").read_bytes().splitlines()
    for op, i, *rest in edits:
        i %= len(lines) or 1
        if not lines:
            break
        if op == "set":
            e = json.loads(lines[i]) if lines[i].startswith(b"{") else {}
            if isinstance(e, dict):
                e[rest[0]] = rest[1]
                lines[i] = json.dumps(e).encode()
        elif op == "drop":
            del lines[i]
        elif op == "dup":
            lines.insert(i, lines[i])
        elif op == "swap":
            j = rest[0] % len(lines)
            lines[i], lines[j] = lines[j], lines[i]
        else:
            lines[i] = rest[0]
    (path / "index.jsonl").write_bytes(b"\n".join(lines) + b"\n")
    read_everything(path)


def any_array():
    dtypes = st.sampled_from([np.uint8, np.int16, np.int64, np.float32, np.float64, bool])
    return dtypes.flatmap(
        lambda dt: hnp.arrays(np.dtype(dt), hnp.array_shapes(min_dims=0, max_dims=3, max_side=16))
    )


@fuzz(80)
@given(
    st.integers(0, 20),
    st.dictionaries(st.sampled_from(FRAME_KEYS), any_array(), min_size=1, max_size=3),
    st.lists(st.sampled_from(FRAME_KEYS), max_size=2),
)
def test_frames_replaced_by_other_arrays(original, tmp_path_factory, i, arrays, removed):
    """A frame file rewritten with other arrays and its index entry updated to match (the
    checksum passes): the content itself must be checked."""
    path = fresh(original, tmp_path_factory)
    lines = (path / "index.jsonl").read_text().splitlines()
    i %= len([ln for ln in lines if '"frame"' in ln])
    name = f"frames/{i:06d}.npz"
    with np.load(path / name) as z:
        content = {k: z[k] for k in z.files}
    content.update(arrays)
    for k in removed:
        content.pop(k, None)
    buf = io.BytesIO()
    np.savez_compressed(buf, **content)
    data = buf.getvalue()
    (path / name).write_bytes(data)
    out = []
    for line in lines:
        e = json.loads(line)
        if e["file"] == name:
            e["bytes"], e["sha256"] = len(data), hashlib.sha256(data).hexdigest()
        out.append(json.dumps(e))
    (path / "index.jsonl").write_text("\n".join(out) + "\n")
    read_everything(path)


@fuzz(60)
@given(
    st.sampled_from(["meta.json", "index.jsonl", "frames/000000.npz", "flow/000001.npz"]),
    st.one_of(
        st.tuples(st.just("flip"), st.integers(0, 10**6), st.integers(1, 255)),
        st.tuples(st.just("cut"), st.integers(0, 10**6)),
        st.tuples(st.just("bytes"), st.binary(max_size=64)),
        st.tuples(st.just("dir")),
    ),
)
def test_damaged_files(original, tmp_path_factory, name, damage):
    path = fresh(original, tmp_path_factory)
    f = path / name
    data = f.read_bytes()
    if damage[0] == "flip" and data:
        b = bytearray(data)
        b[damage[1] % len(b)] ^= damage[2]
        f.write_bytes(bytes(b))
    elif damage[0] == "cut":
        f.write_bytes(data[: damage[1] % (len(data) + 1)])
    elif damage[0] == "bytes":
        f.write_bytes(damage[1])
    elif damage[0] == "dir":
        f.unlink()
        f.mkdir()
    read_everything(path)
