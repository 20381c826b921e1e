"""Regenerate the published-code reference of ``tests/perception/test_published.py``.

Runs the published ``cmcor.motion_correlation.compute_correlation_images`` and
``cmcor.motion_segmentation.compute_segmentation_images`` (holesond/cmcor, with scikit-learn)
on two small synthetic streams whose flows are fed in as the flow predictor's answers, and
stores inputs and outputs in ``tests/perception/data/published_reference.npz``.  The test
feeds the same inputs to cablesim's ``published`` variant and compares.

    PYTHONPATH=/path/to/cmcor:/path/to/sklearn \
        .venv/bin/python -m benchmarks.experiments.published_reference

(cmcor is not a dependency of cablesim; this script is only needed to regenerate the file.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream

OUT = (
    Path(__file__).resolve().parents[2]
    / "tests"
    / "perception"
    / "data"
    / "published_reference.npz"
)


def cases() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """name -> (flows N x H x W x 2, gripper N x 3, action codes N, meters per pixel)."""
    regions = [
        Region((2, 6, 2, 18), "linear", 0.7, label=0),
        Region((7, 10, 2, 18), "random", 0.8, label=1),
        Region((11, 15, 2, 18), "oneside", 0.6, label=2),
    ]
    spec = SyntheticSpec(
        height=16, width=20, focal=600.0, samples_per_period=6, periods=2, noise_px=0.3, seed=7
    )
    s = synthetic_stream(regions, spec)
    # flows on a 1/256 px grid (exact in float32) keep the stored file small
    flows = np.stack([f.truth.flow_to_target for f in s.frames]).astype(np.float64)
    flows = (np.round(flows * 256) / 256).astype(np.float32)
    grip = np.array([f.gripper for f in s.frames])
    codes = np.array([f.action for f in s.frames])
    out = {"plain": (flows, grip, codes, 1.0 / 600.0)}
    # blocks that come back, frames outside actions, the target as a sample of action 1
    codes2 = codes.copy()
    n0 = int((codes == 0).sum())
    codes2[n0 // 2 : n0 // 2 + 2] = -1
    codes2[n0 + 3 : n0 + 6] = 0
    codes2[-1] = 1
    out["blocks"] = (flows, grip, codes2, 1.0 / 600.0)
    return out


class Predictor:
    """The published flow predictor's interface, answering with the stored flow of each frame."""

    def __init__(self, by_id: dict[int, np.ndarray]) -> None:
        self.by_id = by_id

    def flow(self, target: np.ndarray, reference: np.ndarray) -> np.ndarray:  # noqa: ARG002
        return self.by_id[id(reference)].copy()


def main() -> None:
    from cmcor import motion_correlation as mc
    from cmcor import motion_segmentation as ms

    data: dict[str, np.ndarray] = {}
    for name, (flows, grip, codes, mpp) in cases().items():
        buf = [{"rgb_image": np.zeros((2, 2, 3), np.uint8)} for _ in flows]
        by_id = {id(b["rgb_image"]): f for b, f in zip(buf, flows, strict=True)}

        predictor = Predictor(by_id)
        _, a2i, moments, cod, a_img, std = mc.compute_correlation_images(
            np.float64(mpp), grip, codes, buf, predictor
        )
        seg, s2i = ms.compute_segmentation_images(grip, codes, buf, predictor)
        data["flows"] = flows  # the same in every case
        data["gripper"] = grip
        data[f"{name}_codes"] = codes
        data[f"{name}_mpp"] = np.float64(mpp)
        for a, i in a2i.items():
            data[f"{name}_r2_{a}"] = cod[i]
            data[f"{name}_abs_c0_{a}"] = np.abs(a_img[i])
            data[f"{name}_std_{a}"] = std[i]
            data[f"{name}_n_{a}"] = np.int64(moments[i]["n_samples"])
            data[f"{name}_share_{a}"] = seg[s2i[a]]
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **data)
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
