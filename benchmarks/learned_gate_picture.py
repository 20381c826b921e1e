"""Where the learned flow's gate sees motion: a held-out simulated frame beside real ones.

    .venv/bin/python -m benchmarks.learned_gate_picture --sim SPLIT [--out PNG]

One row per frame: the image, the true moving pixels, DIS medium's moving pixels (|flow| >
1 px), the network's moving probability and the learned flow's moving pixels (DIS medium where
the probability is at least the gate); in the masks the arm or stick, never scored, is grey.
The simulated frame is the image of the first clip of ``SPLIT`` (a held-out test split of
``cablesim dataset movingcables``; truth: normal flow > 1 px) where most pixels move; the real
frames are the middle frames of the MovingCables clips 0003 and 0006
(``benchmarks.real_clips``; evaluation only).  Writes ``docs/img/learned_flow_gate.png`` by
default.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from benchmarks.real_clips import load_clip
from cablesim.formats.movingcables import list_clips, read_clip
from cablesim.perception.flow import make_flow
from cablesim.perception.learned import LearnedFlow

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "learned_flow_gate.png"


def sim_frame(split: Path) -> tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(title, image, first image, true moving mask, arm mask) of ``split``'s first clip."""
    clip = list_clips(split)[0]
    frames = list(read_clip(split, clip))
    moving = [int((np.linalg.norm(f.normal_flow, axis=2) > 1.0).sum()) for f in frames]
    mid = frames[int(np.argmax(moving))]  # the frame where most of the hose moves
    truth = np.linalg.norm(mid.normal_flow, axis=2) > 1.0
    arm = mid.stick_mask if mid.stick_mask is not None else np.zeros_like(truth)
    return f"simulated (held out), clip {clip}", mid.rgb, frames[0].rgb, truth, arm


def real_frame(name: str) -> tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    clip = load_clip(name)
    k = len(clip.rgb) // 2
    stick = clip.stick[k] if clip.stick is not None else np.zeros(clip.truth[k].shape, bool)
    return f"real MovingCables {name}", clip.rgb[k], clip.rgb[0], clip.truth[k], stick


def _mask(moving: np.ndarray, never: np.ndarray) -> np.ndarray:
    """An RGB picture of a moving mask: moving yellow, ``never`` (the arm, the stick) grey."""
    out = np.zeros((*moving.shape, 3), np.float32)
    out[moving] = (1.0, 0.9, 0.3)
    out[never] = (0.35, 0.35, 0.35)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", type=Path, required=True, help="a held-out test split folder")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    rows = [sim_frame(args.sim), real_frame("0003"), real_frame("0006")]
    learned = LearnedFlow()
    dis = make_flow("dis-medium")
    cols = ["image", "true moving", "DIS medium moving", "network: P(moving)", "learned moving"]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.2 * len(cols), 2.6 * len(rows)))
    for r, (title, img, first, truth, arm) in enumerate(rows):
        d = np.linalg.norm(dis.compute(img, first), axis=2) > 1.0
        flow, prob = learned.predict(img, first)
        moved = (np.linalg.norm(flow, axis=2) > 1.0) & (prob >= learned.gate)
        panels = [img, *(_mask(m, arm) for m in (truth, d)), prob, _mask(moved, arm)]
        for c, p in enumerate(panels):
            ax = axes[r, c]
            ax.imshow(p, cmap=None if p.ndim == 3 else "magma", vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(cols[c], fontsize=10)
        axes[r, 0].set_ylabel(title, fontsize=9)
    fig.suptitle(
        "Where the learned flow sees motion: simulated (held out) and real frames "
        f"(gate {learned.gate})"
    )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=64)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
