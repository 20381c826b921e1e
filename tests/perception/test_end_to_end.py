"""End to end with a real flow estimator: rendered patches, DIS, correlation."""

from __future__ import annotations

import numpy as np

from cablesim.perception import DISFlow, Frame, Intrinsics, Stream, segment_stream
from cablesim.perception.synthetic import SyntheticSpec, triangle_wave

from .helpers import texture, to_u8_rgb

H, W = 96, 128
F = 600.0


def _render(shift_a, shift_b, rng):
    img = np.full((H, W), 128.0) + rng.normal(0, 0.8, (H, W))
    tex_a = texture(20, 60, seed=11)
    tex_b = texture(20, 40, seed=12)
    ya, xa = 15 + int(round(shift_a[1])), 20 + int(round(shift_a[0]))
    yb, xb = 60 + int(round(shift_b[1])), 60 + int(round(shift_b[0]))
    img[ya : ya + 20, xa : xa + 60] = tex_a
    img[yb : yb + 20, xb : xb + 40] = tex_b
    return to_u8_rgb(img)


def test_dis_correlation_labels_the_grasped_patch():
    spec = SyntheticSpec(samples_per_period=8, periods=2)
    prof = triangle_wave(spec)
    rng = np.random.default_rng(0)
    K = Intrinsics(F, F, W / 2, H / 2, W, H)
    depth = np.ones((H, W), np.float32)
    frames = []
    for a, u in enumerate([np.array([1.0, 0, 0]), np.array([0, 1.0, 0])]):
        for k, d in enumerate(prof):
            sa = 0.5 * d * F * u[:2]  # patch A follows the gripper (gain 0.5)
            sb = rng.uniform(-6, 6, 2) if k else np.zeros(2)  # patch B moves at random
            frames.append(
                Frame(
                    _render(sa, sb, rng),
                    depth,
                    K,
                    np.array([0, 0, 1.0]) + d * u,
                    action=a,
                    sample=k,
                )
            )
    frames.append(Frame(_render((0, 0), (0, 0), rng), depth, K, np.array([0.4, 0.4, 0.6])))
    seg = segment_stream(Stream(frames), "correlation", flow=DISFlow("medium"))
    m = seg.mask("union")
    a_box = m[18:32, 24:76]
    b_box = m[62:78, 64:96]
    rest = m.copy()
    rest[10:40, 10:90] = False
    rest[52:86, 50:106] = False
    assert a_box.mean() > 0.6
    assert b_box.mean() < 0.1
    assert rest.mean() < 0.02
