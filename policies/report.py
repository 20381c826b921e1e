"""What an exploration writes for a person to look at.

Files in the output directory (every picture is a row of titled tiles, :mod:`cablesim.viz`):

- ``start.png``: the start image with the given segment in magenta;
- ``interaction{k}_votes.png``: target RGB | votes in shades of green over it (darker = fewer
  actions) | ground truth (hose of interest, white) | the segment the interaction aimed at;
- ``interaction{k}_errors.png``: the interaction's mask (votes >= 1) against ground truth:
  true positives green, false positives red, false negatives blue, with pixel counts;
- ``interaction{k}_flow.png``: estimated | ground-truth flow of the kept frame farthest
  from the target (HSV wheel: hue = direction, brightness = magnitude, same scale), with the
  wheel as a key;
- ``interaction{k}_maps.png``: |c0| and R^2 of each action with colour bars
  (correlation/ablation only);
- ``interaction{k}_votes.npy``, ``merged_votes.npy``: the vote images (HxW int16), for
  ``cablesim view``;
- ``merged.png``: merged votes of all interactions over the final target | ground truth;
- ``merged_errors.png``: the merged mask (votes >= ``merged_votes``) against ground truth;
- ``episode.mp4`` (H.264, :class:`cablesim.video.VideoWriter`; OpenCV ``mp4v`` if H.264
  cannot be written, an animated GIF if no mp4 reads back): every kept frame of every
  interaction, then the votes;
- ``metrics.json``: per interaction and merged precision, recall, F_0.4, F_1, IoU, the config.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from cablesim.frames import Stream
from cablesim.jsonutil import json_default
from cablesim.video import VideoWriter, count_video_frames
from cablesim.viz import (
    SEGMENT_COLOUR,
    colour_flow,
    colour_map,
    errors_tile,
    label,
    overlay_mask,
    overlay_votes,
    panel,
    with_colour_bar,
    with_flow_wheel,
    write_png,
)


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

    def _npy(self, name: str, votes: np.ndarray) -> None:
        np.save(self.out / name, np.asarray(votes, np.int16))
        self.files.append(name)

    def start(self, rgb: np.ndarray, segment: np.ndarray) -> None:
        img = overlay_mask(rgb, segment, SEGMENT_COLOUR, dim=1.0)
        self._png("start.png", panel([img], ["start image, given segment (magenta)"]))
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
        titles = [f"interaction {k}: target frame", f"votes (of {n_actions} actions)"]
        if inter.truth is not None:
            tiles.append(overlay_mask(rgb, inter.truth))
            titles.append("ground truth: hose of interest")
        if inter.segment is not None:
            tiles.append(overlay_mask(rgb, inter.segment, SEGMENT_COLOUR))
            titles.append(f"aimed segment ({inter.source})")
        self._png(f"interaction{k}_votes.png", panel(tiles, titles))
        self._npy(f"interaction{k}_votes.npy", seg.votes)
        if inter.truth is not None:
            self._errors(
                f"interaction{k}_errors.png",
                rgb,
                seg.mask(1),
                inter.truth,
                inter.scores,
                f"interaction {k}: votes >= 1 vs ground truth",
            )
        if inter.flow_example is not None:
            est, gt = inter.flow_example
            mm = float(max(np.linalg.norm(gt, axis=-1).max(initial=0), 1.0))
            name = getattr(flow, "name", None) or getattr(self.config, "flow", "estimated")
            self._png(
                f"interaction{k}_flow.png",
                panel(
                    [colour_flow(est, mm), with_flow_wheel(colour_flow(gt, mm), mm)],
                    [f"estimated flow ({name})", "ground-truth flow"],
                ),
            )
        if seg.c0:
            tiles, titles = [], []
            for a in sorted(seg.c0):
                tiles.append(with_colour_bar(colour_map(np.abs(seg.c0[a]), 0.0, 1.0), 0.0, 1.0))
                titles.append(f"|c0|, action {a}")
                tiles.append(with_colour_bar(colour_map(seg.r2[a], 0.0, 1.0), 0.0, 1.0))
                titles.append(f"R^2, action {a}")
            self._png(f"interaction{k}_maps.png", panel(tiles, titles))
        for _ in range(10):
            self.video.write(label(overlay_votes(rgb, seg.votes, n_actions), f"votes {k}"))
        if merged_votes is not None:
            for _ in range(10):
                self.video.write(label(overlay_votes(rgb, merged_votes), f"merged after {k}"))

    def _errors(
        self,
        name: str,
        rgb: np.ndarray,
        pred: np.ndarray,
        truth: np.ndarray,
        scores: dict[str, float],
        title: str,
    ) -> None:
        if scores:
            title += (
                f": P {scores['precision']:.2f}, R {scores['recall']:.2f}, "
                f"F0.4 {scores['f0.4']:.2f}"
            )
        self._png(name, panel([errors_tile(rgb, pred, truth)], [title]))

    def failed(self, inter: Any) -> None:
        pass

    def finish(self, result: Any) -> None:
        if result.merged_votes is not None and result.final_rgb is not None:
            rgb, votes = result.final_rgb, result.merged_votes
            n = len(result.successes)
            tiles = [overlay_votes(rgb, votes)]
            titles = [f"merged votes of {n} interaction{'s' * (n != 1)} (final target)"]
            if result.final_truth is not None:
                tiles.append(overlay_mask(rgb, result.final_truth))
                titles.append("ground truth: hose of interest")
            self._png("merged.png", panel(tiles, titles))
            self._npy("merged_votes.npy", votes)
            if result.final_truth is not None:
                threshold = int(getattr(self.config, "merged_votes", 1))
                self._errors(
                    "merged_errors.png",
                    rgb,
                    votes >= threshold,
                    result.final_truth,
                    result.merged,
                    f"merged votes >= {threshold} vs ground truth",
                )
        video = self.video.close()
        metrics = result.metrics()
        metrics["files"] = sorted(self.files + ([video.name] if video is not None else []))
        (self.out / "metrics.json").write_text(
            json.dumps(metrics, indent=2, default=json_default) + "\n"
        )

    def close(self) -> None:
        self.video.close()


# drawing and video helpers live in cablesim.viz / cablesim.video; these names stay importable
# from here for existing callers
__all__ = [
    "ExplorationWriter",
    "VideoWriter",
    "colour_flow",
    "count_video_frames",
    "flow_example",
    "overlay_mask",
    "overlay_votes",
    "write_png",
]
