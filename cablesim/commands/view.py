"""Look at a recording or a run in the rerun viewer: write a rerun recording (.rrd), or open one.

PATH is one of
  - a cablesim recording (a folder with meta.json and frames/, see cablesim.recording);
  - a run folder: ``cablesim explore --out`` (its recordings/interaction*/ when it was run with
    --record, metrics.json, the pictures and votes) or ``cablesim episode --out`` (recording/);
  - an .rrd file, which --spawn opens.

What the .rrd holds (timeline ``frame``: every frame of every interaction in order; ``time``:
the frames' timestamps in seconds):
  world/camera                   the camera pose (T_world_camera of the recording; identity,
                                 i.e. the camera frame, when a recording has none)
  world/camera/image             the pinhole (intrinsics, image size; x right, y down, z forward)
  world/camera/image/rgb         RGB (JPEG, --jpeg-quality)
  world/camera/image/depth       depth (uint16 millimetres)
  world/camera/image/labels      ground-truth labels when recorded (hoses, robot, background)
  world/camera/image/votes       the votes of each interaction, at its target frame (run folder)
  world/camera/gripper           the gripper (TCP) position per frame, camera frame
  world/camera/gripper_path      each interaction's gripper trajectory as a 3D line strip
  metrics/<interaction>/<score>  precision, recall, F_0.4, IoU at each target frame (run folder)
  pictures/<name>                the run folder's pictures; metrics.json as a text document

Without --out the file is written beside the input: <run>/view.rrd, <recording>.rrd.
--spawn starts the viewer on the file (needs a display); nothing is downloaded.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.errors import InputError, RecordingError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT, Frame
from cablesim.recording import FORMAT, Recording
from cablesim.viz import LABEL_COLOURS, ROBOT_COLOUR

CAMERA = "world/camera"
IMAGE = f"{CAMERA}/image"
# label ids in the .rrd (SegmentationImage wants non-negative classes; 0 is drawn transparent)
SEG_BACKGROUND, SEG_ROBOT, SEG_HOSE0 = 0, 1, 2
MAX_VOTE_CLASSES = 16


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", type=Path, help="a recording, a run folder or an .rrd file")
    p.add_argument("--out", type=Path, default=None, help="the .rrd to write")
    p.add_argument("--spawn", action="store_true", help="open the viewer on the file")
    p.add_argument("--stride", type=int, default=1, help="log every n-th frame (default 1)")
    p.add_argument("--jpeg-quality", type=int, default=90, help="RGB JPEG quality (default 90)")


@dataclass
class Source:
    """What was found at PATH."""

    path: Path
    recordings: list[tuple[str, Path]] = field(default_factory=list)  # (name, folder)
    run: Path | None = None  # a run folder (pictures, metrics.json, votes)


def find_source(path: Path) -> Source:
    """The recordings and run folder at ``path`` (raises InputError if there is nothing)."""
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    if not path.is_dir():
        raise InputError(f"{path}: expected a recording, a run folder or an .rrd file")
    if _is_recording(path):
        return Source(path, [(path.name, path)])
    src = Source(path, run=path)
    recs = path / "recordings"
    if recs.is_dir():
        found = [p for p in recs.iterdir() if p.is_dir() and _is_recording(p)]
        src.recordings = [(p.name, p) for p in sorted(found, key=_natural)]
    elif _is_recording(path / "recording"):
        src.recordings = [("recording", path / "recording")]
    if not src.recordings and not (path / "metrics.json").is_file():
        raise InputError(
            f"{path}: neither a cablesim recording (meta.json) nor a run folder "
            "(recordings/, recording/ or metrics.json)"
        )
    return src


def _is_recording(path: Path) -> bool:
    meta = path / "meta.json"
    if not meta.is_file():
        return False
    try:
        return json.loads(meta.read_text(encoding="utf-8")).get("format") == FORMAT
    except (OSError, ValueError, AttributeError):
        return False


def _natural(p: Path) -> tuple:
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name))


def default_out(src: Source) -> Path:
    if src.run is not None:
        return src.run / "view.rrd"
    return src.path.with_name(src.path.name + ".rrd")


# ---------------------------------------------------------------------------- writing
def write_rrd(
    src: Source, out: Path, stride: int = 1, jpeg_quality: int = 90, say=print
) -> dict[str, Any]:
    """Write everything found in ``src`` to ``out``; returns counts of what was logged."""
    import rerun as rr  # lazy: optional heavy package

    if stride < 1:
        raise InputError(f"--stride must be at least 1, got {stride}")
    if not 1 <= jpeg_quality <= 100:
        raise InputError(f"--jpeg-quality must be within 1..100, got {jpeg_quality}")
    out.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("cablesim", recording_id=str(src.path.resolve()))
    rec.save(str(out))
    counts: dict[str, Any] = {"frames": 0, "interactions": 0, "votes": 0, "pictures": 0}
    try:
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log(IMAGE + "/labels", _label_context(rr), static=True)
        rec.log(IMAGE + "/votes", _votes_context(rr), static=True)
        metrics = _read_metrics(src.run)
        frame_no = 0
        targets: dict[int, int] = {}  # interaction index -> frame number of its target frame
        for name, folder in src.recordings:
            k = _interaction_index(name, len(targets))
            try:
                recording = Recording(folder)
            except RecordingError as e:
                say(f"[view] skipped {folder}: {e}")
                continue
            first = frame_no
            frame_no = _log_recording(rr, rec, recording, name, frame_no, stride, jpeg_quality)
            counts["frames"] += frame_no - first
            counts["interactions"] += 1
            if frame_no > first:
                targets[k] = frame_no - 1
            say(f"[view] {name}: {frame_no - first} frames")
        if src.run is not None:
            counts["votes"] = _log_votes(rr, rec, src.run, targets)
            _log_scores(rr, rec, metrics, targets)
            counts["pictures"] = _log_pictures(rr, rec, src.run, metrics)
    finally:
        rec.flush()
        rec.disconnect()
    return counts


def _interaction_index(name: str, default: int) -> int:
    m = re.fullmatch(r"interaction(\d+)", name)
    return int(m.group(1)) if m else default


def _log_recording(
    rr: Any, rec: Any, recording: Recording, name: str, frame_no: int, stride: int, quality: int
) -> int:
    meta = recording.meta
    T = np.asarray(meta.get("T_world_camera", np.eye(4)), float)
    if T.shape != (4, 4):
        raise RecordingError(f"{recording.path / 'meta.json'}: T_world_camera is not 4x4")
    rec.set_time("frame", sequence=frame_no)
    rec.log(CAMERA, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
    K = recording.intrinsics
    if K is not None:
        rec.log(
            IMAGE,
            rr.Pinhole(
                image_from_camera=[[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]],
                resolution=[K.width, K.height],
                camera_xyz=rr.ViewCoordinates.RDF,
            ),
        )
    path: list[np.ndarray] = []
    first = frame_no
    n = len(recording)
    for i in range(n):
        if i % stride and i != n - 1:  # the last (target) frame is always kept
            continue
        f = recording.frame(i)
        rec.set_time("frame", sequence=frame_no)
        rec.set_time("time", duration=float(f.timestamp))
        _log_frame(rr, rec, f, quality)
        if not f.is_target:
            path.append(f.gripper)
        frame_no += 1
    if path:
        rec.set_time("frame", sequence=first)
        rec.log(
            f"{CAMERA}/gripper_path/{name}",
            rr.LineStrips3D([np.asarray(path)], radii=0.002),
        )
    return frame_no


def _log_frame(rr: Any, rec: Any, f: Frame, quality: int) -> None:
    ok, jpeg = cv2.imencode(
        ".jpg", np.ascontiguousarray(f.rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality]
    )
    if not ok:  # pragma: no cover - OpenCV always has a JPEG encoder
        raise InputError("could not encode a frame as JPEG")
    rec.log(IMAGE + "/rgb", rr.EncodedImage(contents=jpeg.tobytes(), media_type="image/jpeg"))
    mm = np.clip(np.round(np.nan_to_num(f.depth) * 1000.0), 0, 65535).astype(np.uint16)
    rec.log(IMAGE + "/depth", rr.DepthImage(mm, meter=1000.0))
    if f.truth is not None and f.truth.labels is not None:
        rec.log(IMAGE + "/labels", rr.SegmentationImage(segmentation_ids(f.truth.labels)))
    if f.is_target:
        rec.log(CAMERA + "/gripper", rr.Clear(recursive=False))
    else:
        rec.log(CAMERA + "/gripper", rr.Points3D([f.gripper], radii=0.006, colors=[255, 0, 255]))


def segmentation_ids(labels: np.ndarray) -> np.ndarray:
    """cablesim labels (hose index, LABEL_ROBOT, LABEL_BACKGROUND) -> non-negative class ids."""
    ids = np.full(labels.shape, SEG_BACKGROUND, np.uint16)
    ids[labels == LABEL_ROBOT] = SEG_ROBOT
    hose = labels >= 0
    ids[hose] = labels[hose].astype(np.uint16) + SEG_HOSE0
    return ids


def _label_context(rr: Any) -> Any:
    infos = [
        rr.AnnotationInfo(id=SEG_BACKGROUND, label="background", color=(0, 0, 0, 0)),
        rr.AnnotationInfo(id=SEG_ROBOT, label="robot", color=(*ROBOT_COLOUR, 255)),
    ]
    for i in range(16):
        c = LABEL_COLOURS[i % len(LABEL_COLOURS)]
        infos.append(rr.AnnotationInfo(id=SEG_HOSE0 + i, label=f"hose {i}", color=(*c, 255)))
    assert LABEL_BACKGROUND < 0 and LABEL_ROBOT < 0
    return rr.AnnotationContext(infos)


def _votes_context(rr: Any) -> Any:
    infos = [rr.AnnotationInfo(id=0, label="no vote", color=(0, 0, 0, 0))]
    for n in range(1, MAX_VOTE_CLASSES):
        g = int(round(110 + 145 * min(n, 4) / 4))
        infos.append(rr.AnnotationInfo(id=n, label=f"{n} votes", color=(0, g, 0, 200)))
    return rr.AnnotationContext(infos)


def _read_metrics(run: Path | None) -> dict[str, Any]:
    if run is None or not (run / "metrics.json").is_file():
        return {}
    try:
        doc = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputError(f"{run / 'metrics.json'}: unreadable ({e})") from e
    return doc if isinstance(doc, dict) else {}


def _log_votes(rr: Any, rec: Any, run: Path, targets: dict[int, int]) -> int:
    """Each ``interaction{k}_votes.npy`` at its target frame, ``merged_votes.npy`` after."""
    n = 0
    last = max(targets.values(), default=-1)
    for path in sorted(run.glob("interaction*_votes.npy"), key=_natural):
        k = int(re.search(r"interaction(\d+)_votes", path.name).group(1))
        rec.set_time("frame", sequence=targets.get(k, last + 1 + k))
        rec.log(IMAGE + "/votes", rr.SegmentationImage(_votes(path)))
        n += 1
    merged = run / "merged_votes.npy"
    if merged.is_file():
        rec.set_time("frame", sequence=max(last, 0))
        rec.log(IMAGE + "/merged_votes", rr.SegmentationImage(_votes(merged)))
        n += 1
    return n


def _votes(path: Path) -> np.ndarray:
    try:
        v = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: unreadable votes ({e})") from e
    if v.ndim != 2:
        raise InputError(f"{path}: votes must be HxW, got shape {v.shape}")
    return np.clip(v, 0, MAX_VOTE_CLASSES - 1).astype(np.uint16)


def _log_scores(rr: Any, rec: Any, metrics: dict[str, Any], targets: dict[int, int]) -> None:
    for inter in metrics.get("interactions", []):
        k, scores = inter.get("index"), inter.get("scores") or {}
        if k not in targets:
            continue
        rec.set_time("frame", sequence=targets[k])
        for key in ("precision", "recall", "f0.4", "iou"):
            if key in scores:
                rec.log(f"metrics/interaction/{key}", rr.Scalars(float(scores[key])))
        for key, value in (inter.get("merged") or {}).items():
            if key in ("precision", "recall", "f0.4", "iou"):
                rec.log(f"metrics/merged/{key}", rr.Scalars(float(value)))


def _log_pictures(rr: Any, rec: Any, run: Path, metrics: dict[str, Any]) -> int:
    n = 0
    for png in sorted(run.glob("*.png"), key=_natural):
        rec.log(f"pictures/{png.stem}", rr.EncodedImage(path=png), static=True)
        n += 1
    if metrics:
        text = "```json\n" + json.dumps(metrics, indent=2)[:200_000] + "\n```"
        rec.log("metrics.json", rr.TextDocument(text, media_type="text/markdown"), static=True)
    return n


# ---------------------------------------------------------------------------- command
def spawn_viewer(rrd: Path) -> None:
    """Start the rerun viewer (shipped with rerun-sdk) on ``rrd`` in the background."""
    subprocess.Popen([sys.executable, "-m", "rerun", str(rrd)])  # noqa: S603


def run(args: argparse.Namespace) -> int:
    try:
        import rerun  # noqa: F401  # lazy: optional heavy package
    except ImportError as e:
        raise InputError(
            "cablesim view needs rerun-sdk: pip install -e '.[viewer]' (or '.[dev]')"
        ) from e
    path: Path = args.path
    if path.suffix == ".rrd" and not path.is_dir():
        if not path.is_file():
            raise InputError(f"{path}: no such file")
        if not args.spawn:
            print(f"[view] {path} is already a rerun recording; --spawn opens it")
            return 0
        spawn_viewer(path)
        return 0
    src = find_source(path)
    out = args.out if args.out is not None else default_out(src)
    if out.suffix != ".rrd":
        raise InputError(f"--out {out}: the file name must end in .rrd")
    counts = write_rrd(src, out, args.stride, args.jpeg_quality)
    print(
        f"[view] wrote {out}: {counts['frames']} frames of {counts['interactions']} "
        f"recording(s), {counts['votes']} vote images, {counts['pictures']} pictures"
    )
    if args.spawn:
        spawn_viewer(out)
    return 0
