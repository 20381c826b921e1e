"""What an exploration writes for a person to look at.

Files in the output directory:

- ``start.png``: the start image with the given segment in magenta;
- ``interaction{k}_votes.png``: [target RGB | votes in shades of green over it (darker = fewer
  actions) | ground truth (hose of interest, white) | the segment the interaction aimed at];
- ``interaction{k}_flow.png``: estimated flow | ground-truth flow of the kept frame farthest
  from the target (HSV wheel: hue = direction, brightness = magnitude, same scale);
- ``interaction{k}_maps.png``: |c0| and R^2 of each action (correlation/ablation only);
- ``merged.png``: merged votes of all interactions over the final target | ground truth;
- ``episode.mp4`` (OpenCV ``mp4v``; checked by reading it back, else ``episode.gif``): every
  kept frame of every interaction, then the merged votes;
- ``metrics.json``: per interaction and merged precision, recall, F_0.4, F_1, IoU, the config.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.jsonutil import json_default
from cablesim.perception.frames import Stream
from cablesim.viz import (  # noqa: F401  (re-exported: envs and callers import them from here)
    GREEN,
    colour_flow,
    colour_map,
    hstack,
    label,
    overlay_mask,
    overlay_votes,
    write_png,
)


class VideoWriter:
    """mp4 (OpenCV ``mp4v``) written frame by frame; verified on close by reading it back.
    Falls back to an animated GIF (imageio/Pillow) when no mp4 encoder works."""

    def __init__(self, path: Path, fps: float = 15.0, max_gif_frames: int = 300) -> None:
        self.path, self.fps = path, fps
        self.frames_written = 0
        self._size: tuple[int, int] | None = None
        self._cv: cv2.VideoWriter | None = None
        self._gif: list[np.ndarray] = []
        self._max_gif = max_gif_frames
        self.final_path: Path | None = None

    def write(self, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        if self._size is None:
            self._size = (w - w % 2, h - h % 2)
            self._cv = cv2.VideoWriter(
                str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, self._size
            )
            if not self._cv.isOpened():
                self._cv = None
        frame = np.ascontiguousarray(rgb[: self._size[1], : self._size[0]])
        if self._cv is not None:
            self._cv.write(np.ascontiguousarray(frame[..., ::-1]))
        if len(self._gif) < self._max_gif:  # kept in case the mp4 does not read back
            self._gif.append(cv2.resize(frame, (frame.shape[1] // 2, frame.shape[0] // 2)))
        self.frames_written += 1

    def close(self) -> Path | None:
        if self._cv is not None:
            self._cv.release()
            self._cv = None
            if count_video_frames(self.path) == self.frames_written > 0:
                self.final_path = self.path
                self._gif = []
                return self.final_path
        if self._gif:
            import imageio.v2 as imageio

            gif = self.path.with_suffix(".gif")
            imageio.mimsave(gif, self._gif[::2], duration=2.0 / self.fps, loop=0)
            self.final_path = gif
            if self.path.exists():
                self.path.unlink()
        self._gif = []
        return self.final_path


def count_video_frames(path: Path) -> int:
    """Frames OpenCV can decode from a video file (0 if it cannot be opened)."""
    cap = cv2.VideoCapture(str(path))
    n = 0
    try:
        while cap.isOpened():
            ok, _ = cap.read()
            if not ok:
                break
            n += 1
    finally:
        cap.release()
    return n


def flow_example(stream: Stream, flow: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(estimated, ground-truth) flow of the kept frame farthest from the target, for the
    picture; None without ground truth."""
    frames = [f for f in stream.frames if not f.is_target and f.truth is not None]
    if not frames:
        return None
    g1 = frames[0].gripper
    f = max(frames, key=lambda fr: float(np.linalg.norm(fr.gripper - g1)))
    gt = f.truth.flow_to_target
    if gt is None:
        return None
    est = flow.frame_flow(f, stream.target)
    gt = np.where(f.truth.flow_valid[..., None], gt, 0.0) if f.truth.flow_valid is not None else gt
    return est, np.asarray(gt, np.float32)


class ExplorationWriter:
    """Writes the pictures, the video and the metrics of one exploration as it runs."""

    def __init__(self, out: Path, config: Any) -> None:
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.config = config
        self.video = VideoWriter(self.out / "episode.mp4")
        self.files: list[str] = []

    def _png(self, name: str, rgb: np.ndarray) -> None:
        write_png(self.out / name, rgb)
        self.files.append(name)

    def start(self, rgb: np.ndarray, segment: np.ndarray) -> None:
        img = rgb.copy()
        img[segment] = (255, 0, 255)
        self._png("start.png", img)
        for _ in range(8):
            self.video.write(label(img, "start segment"))

    def interaction(
        self, inter: Any, stream: Stream, merged_votes: np.ndarray | None, flow: Any = None
    ) -> None:
        k = inter.index
        if flow is not None:
            inter.flow_example = flow_example(stream, flow)
        for f in stream.frames:
            if not f.is_target:
                self.video.write(label(f.rgb, f"interaction {k}, action {f.action}"))
        rgb, seg = inter.target_rgb, inter.seg
        n_actions = max(len(seg.masks), 1)
        tiles = [rgb, overlay_votes(rgb, seg.votes, n_actions)]
        if inter.truth is not None:
            tiles.append(overlay_mask(rgb, inter.truth))
        if inter.segment is not None:
            tiles.append(overlay_mask(rgb, inter.segment, (255, 0, 255)))
        self._png(f"interaction{k}_votes.png", hstack(tiles))
        if inter.flow_example is not None:
            est, gt = inter.flow_example
            mm = float(max(np.linalg.norm(gt, axis=-1).max(initial=0), 1.0))
            self._png(
                f"interaction{k}_flow.png", hstack([colour_flow(est, mm), colour_flow(gt, mm)])
            )
        if seg.c0:
            tiles = []
            for a in sorted(seg.c0):
                tiles.append(label(colour_map(np.abs(seg.c0[a]), 0.0, 1.0), f"|c0| action {a}"))
                tiles.append(label(colour_map(seg.r2[a], 0.0, 1.0), f"R^2 action {a}"))
            self._png(f"interaction{k}_maps.png", hstack(tiles))
        for _ in range(10):
            self.video.write(label(overlay_votes(rgb, seg.votes, n_actions), f"votes {k}"))
        if merged_votes is not None:
            for _ in range(10):
                self.video.write(label(overlay_votes(rgb, merged_votes), f"merged after {k}"))

    def failed(self, inter: Any) -> None:
        pass

    def finish(self, result: Any) -> None:
        if result.merged_votes is not None and result.final_rgb is not None:
            tiles = [overlay_votes(result.final_rgb, result.merged_votes)]
            if result.final_truth is not None:
                tiles.append(overlay_mask(result.final_rgb, result.final_truth))
            self._png("merged.png", hstack(tiles))
        video = self.video.close()
        metrics = result.metrics()
        metrics["files"] = sorted(self.files + ([video.name] if video is not None else []))
        (self.out / "metrics.json").write_text(
            json.dumps(metrics, indent=2, default=json_default) + "\n"
        )

    def close(self) -> None:
        self.video.close()
