"""The torch RAFT back end: checkpoints in, flow out; clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import make_flow

torch = pytest.importorskip("torch")

from cablesim.perception.raft import (  # noqa: E402
    RaftConfig,
    RaftFlow,
    build_raft,
    load_raft,
    save_raft_checkpoint,
)

SMALL = RaftConfig(
    feature_dim=32, hidden_dim=32, context_dim=16, corr_levels=2, corr_radius=2, iters=2
)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    return save_raft_checkpoint(tmp_path_factory.mktemp("raft") / "raft.pt", config=SMALL)


def test_random_checkpoint_runs(ckpt):
    est = make_flow("raft", checkpoint=ckpt, device="cpu")
    assert isinstance(est, RaftFlow)
    rng = np.random.default_rng(0)
    a = rng.integers(0, 255, (37, 50, 3), dtype=np.uint8)  # not a multiple of 8
    b = rng.integers(0, 255, (37, 50, 3), dtype=np.uint8)
    flow = est.compute(a, b)
    assert flow.shape == (37, 50, 2) and flow.dtype == np.float32
    assert np.isfinite(flow).all()
    g = est.compute(a[..., 0], b[..., 0])  # grey images work too
    assert g.shape == (37, 50, 2)


def test_roundtrip_state_dict(ckpt, tmp_path):
    m = load_raft(ckpt)
    p2 = save_raft_checkpoint(tmp_path / "again.pt", model=m)
    m2 = load_raft(p2)
    for (k, v), (k2, v2) in zip(m.state_dict().items(), m2.state_dict().items(), strict=True):
        assert k == k2 and torch.equal(v, v2)


def test_convex_upsampling_of_constant_flow():
    model = build_raft(SMALL)
    flow = torch.full((1, 2, 3, 4), 1.5)
    up = model._upsample(flow, torch.zeros(1, 64 * 9, 3, 4))
    assert up.shape == (1, 2, 24, 32)
    assert torch.allclose(up[..., 8:16, 8:24], torch.tensor(12.0))


def test_checkpoint_errors(tmp_path, ckpt):
    with pytest.raises(InputError, match="not found"):
        RaftFlow(tmp_path / "missing.pt", device="cpu")
    bad = tmp_path / "corrupt.pt"
    bad.write_bytes(b"\x00garbage" * 10)
    with pytest.raises(InputError, match="corrupt"):
        RaftFlow(bad, device="cpu")
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(InputError, match="not a cablesim RAFT checkpoint"):
        RaftFlow(other, device="cpu")
    ck = torch.load(ckpt, weights_only=True)
    ck["state_dict"].pop(next(iter(ck["state_dict"])))
    torch.save(ck, tmp_path / "partial.pt")
    with pytest.raises(InputError, match="do not match"):
        RaftFlow(tmp_path / "partial.pt", device="cpu")
