"""The learned flow: training pairs against analytic motion, a short training that must
improve on its DIS input, weights files refused clearly, and the estimator behind the registry."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cablesim.errors import ConfigError, InputError
from cablesim.perception import make_flow

torch = pytest.importorskip("torch")

from cablesim.learn.pairs import AugmentConfig, PairSource, find_clips, make_pair  # noqa: E402
from cablesim.learn.train import DataConfig, TrainConfig, train  # noqa: E402
from cablesim.perception.learned import (  # noqa: E402
    LearnedFlow,
    LearnedFlowConfig,
    build_model,
    read_weights,
    save_weights,
)

from .synthetic import (  # noqa: E402
    BAND_NORMAL,
    band_image,
    normal_part,
    write_synthetic_clip,
)

# the default design made small, trained on the full flow: the striped band shows all of it
# (its stripes pin the motion along it)
SMALL = LearnedFlowConfig(widths=(8, 8, 16, 16), decoder=(16, 8, 8), work_width=160, target="flow")
# no camera effects and no rescaling: the sample's flow is the clip's exact flow, cropped
PLAIN = AugmentConfig(
    scale=(1.0, 1.0),
    crop=(128, 160),
    flip=False,
    contrast=(1.0, 1.0),
    brightness=0.0,
    channel_gain=0.0,
    gamma=(1.0, 1.0),
    blur=(0.0, 0.0),
    frame_gain=0.0,
    noise=(0.0, 0.0),
    jpeg=0.0,
)


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("clips")
    shifts = {}
    for i, seed in enumerate((1, 2, 3)):
        shifts[f"{i + 1:04d}"] = write_synthetic_clip(root / "train", f"{i + 1:04d}", seed)
    write_synthetic_clip(root / "validation", "0001", 9)
    return root, shifts


def test_a_pair_carries_the_exact_flow_of_the_clip(clips):
    root, shifts = clips
    clip = find_clips([root / "train"])[0]
    k = clip.indices[3]
    rng = np.random.default_rng(0)
    s = make_pair(clip.rgb(k), clip.rgb(1), clip.flow(k), None, SMALL, PLAIN, rng)
    assert s.x.shape == (13, 128, 160) and s.flow.shape == (2, 128, 160)
    sx, sy = shifts[clip.clip][3]
    on_band = s.moving > 0.5
    assert on_band.sum() > 200  # centred on the moving band
    np.testing.assert_allclose(s.flow[0][on_band], -sx, atol=1 / 64)  # PNG: 1/64 px
    np.testing.assert_allclose(s.flow[1][on_band], -sy, atol=1 / 64)
    assert np.all(s.flow[:, ~on_band] == 0)
    # image1 warped by the exact flow reproduces image1 on the band (what the net sees)
    assert s.valid.all()


def test_a_normal_flow_model_trains_on_the_normal_flow(clips):
    """``target="normal"`` (the default): a pair's flow is the clip's normal flow, the
    band's motion projected on its normal (what the MovingCables evaluation scores)."""
    assert LearnedFlowConfig().target == "normal"
    root, shifts = clips
    clip = find_clips([root / "train"])[0]
    k = clip.indices[3]
    normal = make_pair(
        clip.rgb(k),
        clip.rgb(1),
        clip.flow(k, normal=True),
        None,
        SMALL,
        PLAIN,
        np.random.default_rng(0),
    )
    on_band = normal.moving > 0.5
    assert on_band.sum() > 200
    nx, ny = normal_part(tuple(-v for v in shifts[clip.clip][3]))
    np.testing.assert_allclose(normal.flow[0][on_band], nx, atol=1 / 64)
    np.testing.assert_allclose(normal.flow[1][on_band], ny, atol=1 / 64)
    # the pair source draws the flow its model is trained on (the same draw otherwise)
    plain = PLAIN.replace(centre_on_motion=0.0)
    source = PairSource([clip], SMALL, plain, 0)
    i = next(i for i in range(50) if (source.sample(i).moving > 0.5).sum() > 100)
    full = source.sample(i)
    norm = PairSource([clip], SMALL.replace(target="normal"), plain, 0).sample(i)
    np.testing.assert_array_equal(full.x, norm.x)
    band = full.moving > 0.5
    projected = (BAND_NORMAL @ full.flow[:, band])[None] * BAND_NORMAL[:, None]
    np.testing.assert_allclose(norm.flow[:, band], projected, atol=1 / 32)
    assert np.abs(full.flow[:, band] - projected).max() > 0.5  # the band also slides along


def test_flips_change_the_flow_signs(clips):
    root, _ = clips
    clip = find_clips([root / "train"])[0]
    k = clip.indices[2]
    args = (clip.rgb(k), clip.rgb(1), clip.flow(k), None, SMALL)
    plain = make_pair(*args, PLAIN, np.random.default_rng(5))
    flipped_cfg = PLAIN.replace(flip=True)
    for seed in range(20):  # find a draw that flips left-right only
        rng = np.random.default_rng(seed)
        s = make_pair(*args, flipped_cfg, rng)
        mean_plain = plain.flow[:, plain.moving > 0.5].mean(axis=1)
        mean = s.flow[:, s.moving > 0.5].mean(axis=1)
        if np.sign(mean[0]) == -np.sign(mean_plain[0]) and np.sign(mean[1]) == np.sign(
            mean_plain[1]
        ):
            break
    else:
        pytest.fail("no left-right flip in 20 draws")
    np.testing.assert_allclose(np.abs(mean), np.abs(mean_plain), atol=1e-3)


def test_samples_depend_on_the_seed_and_index_alone(clips):
    root, _ = clips
    src = PairSource(find_clips([root / "train"]), SMALL, AugmentConfig(crop=(64, 96)), 7)
    a = src.sample(3)
    src.sample(0)  # another draw in between changes nothing
    b = PairSource(find_clips([root / "train"]), SMALL, AugmentConfig(crop=(64, 96)), 7).sample(3)
    for name in ("x", "flow", "valid", "moving"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    c = src.sample(4)
    assert not np.array_equal(a.x, c.x)


def _config(root, steps):
    return TrainConfig(
        steps=steps,
        batch=4,
        lr=3e-3,
        lr_min=3e-4,
        log_every=5,
        val_every=max(steps // 2, 1),
        val_pairs=8,
        threads=1,
        model=SMALL,
        augment=PLAIN.replace(crop=(96, 128)),
        data=DataConfig(
            root=str(root / "made"),
            train=(f"folder {root / 'train'}",),
            validation=(f"folder {root / 'validation'}",),
        ),
    )


def test_training_improves_on_its_dis_input(clips, tmp_path):
    """A striped band sliding over a textured background: DIS drags the band's motion onto
    the background beside it and misjudges plain regions; forty steps of training cut the
    validation clip's flow error over the known pixels to well below DIS's (to 0.62-0.72 of
    it over seeds 0-3 when this test was written) and the training loss falls."""
    root, _ = clips
    weights = train(_config(root, 40), tmp_path / "run", workers=1, progress=False)
    last = _rows(tmp_path / "run" / "validation.csv")[-1]
    assert last["step"] == 40
    assert last["epe"] < 0.8 * last["dis_epe"]
    loss = [r["loss"] for r in _rows(tmp_path / "run" / "log.csv")]  # every 5th step
    half = len(loss) // 2
    assert np.mean(loss[half:]) < np.mean(loss[:half])
    for name in ("config.json", "provenance.json", "data.json", "log.csv", "loss.png"):
        assert (tmp_path / "run" / name).is_file(), name
    assert read_weights(weights)["meta"]["steps"] == 40
    est = LearnedFlow(weights)  # what a run writes loads as the back end
    assert est.cfg == SMALL


def test_a_resumed_run_ends_with_the_same_weights(clips, tmp_path):
    root, _ = clips
    cfg = _config(root, 8)
    whole = train(cfg, tmp_path / "whole", workers=1, progress=False)
    half = tmp_path / "half"  # a run stopped after its checkpoint at step 4, then restarted
    assert train(cfg, half, workers=1, progress=False, stop_at=5) is None
    assert not (half / "learned_flow.pt").exists()
    resumed = train(cfg, half, workers=1, progress=False)
    a = read_weights(whole)["state_dict"]
    b = read_weights(resumed)["state_dict"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)

    def logged(run):  # what was logged, but the wall-clock seconds
        return [{k: v for k, v in r.items() if k != "seconds"} for r in _rows(run / "log.csv")]

    assert logged(half) == logged(tmp_path / "whole")


def _rows(path):
    lines = path.read_text().splitlines()
    names = lines[0].split(",")
    return [dict(zip(names, map(float, ln.split(",")), strict=True)) for ln in lines[1:]]


def test_a_run_of_another_config_is_refused(clips, tmp_path):
    root, _ = clips
    train(_config(root, 4), tmp_path / "run", workers=1, progress=False)
    with pytest.raises(InputError, match="another config"):
        train(_config(root, 8).replace(seed=3), tmp_path / "run", workers=1, progress=False)


def test_a_run_fine_tunes_the_weights_it_starts_from(clips, tmp_path):
    """``init`` loads a weights file as the starting point: at a vanishing learning rate the
    run ends where it started; a file of another network is refused, naming train.init,
    before any data is made."""
    root, _ = clips
    first = train(_config(root, 6), tmp_path / "first", workers=1, progress=False)
    still = _config(root, 2).replace(init=str(first), lr=1e-12, lr_min=1e-12, weight_decay=0.0)
    tuned = train(still, tmp_path / "tuned", workers=1, progress=False)
    a, b = read_weights(first)["state_dict"], read_weights(tuned)["state_dict"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=1e-6)
    assert read_weights(tuned)["meta"]["config"]["init"] == str(first)
    fresh = read_weights(train(_config(root, 2), tmp_path / "fresh", workers=1, progress=False))
    assert any(not torch.equal(a[k], fresh["state_dict"][k]) for k in a)  # init did the work
    other = still.replace(model=SMALL.replace(widths=(8, 8, 16, 24)))
    with pytest.raises(ConfigError, match="train.init: .*first.*another network.*widths"):
        train(other, tmp_path / "other", workers=1, progress=False)
    assert not (tmp_path / "other" / "data.json").exists()
    with pytest.raises(InputError, match="weights not found.*nothere.pt"):
        train(
            still.replace(init=str(tmp_path / "nothere.pt")),
            tmp_path / "x",
            workers=1,
            progress=False,
        )


def test_bad_weights_files_are_refused_naming_the_file(tmp_path):
    missing = tmp_path / "none.pt"
    with pytest.raises(InputError, match="none.pt"):
        LearnedFlow(missing)
    with pytest.raises(InputError, match="gate"):
        make_flow("learned,gate=abc")
    with pytest.raises(InputError, match="threads"):
        make_flow("learned,threads=0")
    good = save_weights(tmp_path / "w.pt", build_model(SMALL))
    cut = tmp_path / "cut.pt"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(InputError, match="cut.pt.*truncated"):
        LearnedFlow(cut)
    other = tmp_path / "other.pt"
    torch.save({"format": "something-else"}, other)
    with pytest.raises(InputError, match="other.pt.*not a cablesim learned flow"):
        LearnedFlow(other)
    ck = torch.load(good, weights_only=True)
    ck["config"]["widths"] = [8, 8, 16, 32]  # the weights no longer fit the network
    bad = tmp_path / "mismatch.pt"
    torch.save(ck, bad)
    with pytest.raises(InputError, match="mismatch.pt.*do not match"):
        LearnedFlow(bad)


def test_registry_builds_it_and_an_untrained_model_is_dis(tmp_path):
    """A fresh network's correction is zero (its head starts at zero): the flow is DIS's at
    the working size, so a translated texture comes out as its shift."""
    w = save_weights(tmp_path / "w.pt", build_model(SMALL))
    est = make_flow(f"learned,weights={w},gate=null")
    assert isinstance(est, LearnedFlow) and est.gate is None
    rng = np.random.default_rng(0)
    import cv2

    img = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160, 3)).astype(np.float32), (0, 0), 2)
    img = np.clip((img - 127) * 4 + 127, 0, 255).astype(np.uint8)
    moved = np.roll(img, (2, -3), axis=(0, 1))  # image2(p) = image1(p - (-3, 2))
    flow = est.compute(img, moved)
    assert flow.shape == (120, 160, 2)
    inner = flow[20:-20, 20:-20].reshape(-1, 2)
    np.testing.assert_allclose(np.median(inner, axis=0), (-3.0, 2.0), atol=0.3)


def test_weights_of_the_earlier_design_load_as_it(tmp_path):
    """A weights file written before ``arch`` and ``target`` existed (the U-Net trained on the
    full flow, shipped until 2026-12-07) loads as that network."""
    old = LearnedFlowConfig(widths=(8, 8, 16, 16), decoder=(16, 8, 8), arch="unet", target="flow")
    net = build_model(old)
    assert not any(name.startswith("feat") for name, _ in net.named_parameters())
    path = save_weights(tmp_path / "old.pt", net)
    ck = torch.load(path, weights_only=True)
    for key in ("arch", "target", "features", "corr_radius"):
        del ck["config"][key]
    torch.save(ck, path)
    est = LearnedFlow(path)
    assert (est.cfg.arch, est.cfg.target) == ("unet", "flow")


def test_the_correlation_peaks_at_the_shift():
    """The correlation layer of the ``arch="corr"`` design: image2's features shifted by
    (dx, dy) correlate best with image1's at that displacement."""
    from cablesim.perception.learned import _classes

    corr = _classes()["correlation"]
    g = torch.Generator().manual_seed(0)
    f1 = torch.randn(1, 8, 20, 24, generator=g)
    dx, dy = 2, -1
    f2 = torch.roll(f1, shifts=(dy, dx), dims=(2, 3))  # f2(p + d) = f1(p)
    c = corr(f1, f2, 3)[0, :, 5:-5, 5:-5].mean((1, 2))
    assert c.shape == (49,)
    best = int(torch.argmax(c))
    assert (best // 7 - 3, best % 7 - 3) == (dy, dx)
    # the design that uses it: any image size, and untrained it is DIS (a zero correction)
    net = build_model(SMALL.replace(arch="corr", features=(8, 8), corr_radius=(2, 3)))
    with torch.inference_mode():
        out = net(torch.randn(2, 13, 45, 61, generator=g))
    assert out.shape == (2, 3, 45, 61) and not out.any()


# RAFT-small made tiny: the same modules, few channels and two iterations
TINY_RAFT = SMALL.replace(arch="raft", raft_dims=(16, 16, 8), raft_iters=2)


def test_the_raft_design_starts_from_the_dis_flow():
    """``arch="raft"``: untrained, its flow is the DIS flow it was given (its iterations start
    there and its last flow layer is zero; the convex upsampling only blurs the image border),
    at any image size, and its moving probability is 1/2."""
    net = build_model(TINY_RAFT)
    g = torch.Generator().manual_seed(0)
    x = torch.rand(2, 13, 45, 61, generator=g) - 0.5
    x[:, 9], x[:, 10] = 0.3, -0.2  # a DIS flow of (3, -2) px in flow_norm (10 px) units
    with torch.inference_mode():
        out = net(x)
    assert out.shape == (2, 3, 45, 61)
    torch.testing.assert_close(out[:, :2, 8:-8, 8:-8], torch.zeros(2, 2, 29, 45), atol=1e-5, rtol=0)
    assert not out[:, 2].any()
    # and what it returns moves with the DIS flow it is given
    x[:, 9] = -0.5
    with torch.inference_mode():
        moved = net(x)
    torch.testing.assert_close(moved[:, :2, 8:-8, 8:-8], out[:, :2, 8:-8, 8:-8], atol=1e-5, rtol=0)


def test_the_raft_design_learns_and_loads_as_the_back_end(clips, tmp_path):
    """The RAFT design fits a batch of the synthetic clips (its training loss falls by a
    third in 30 steps), and what ``cablesim train`` writes for it is a learned flow back end,
    correlation volume and all, that runs on the CPU."""
    from cablesim.learn.train import _loss, _tensors

    root, _ = clips
    cfg = _config(root, 4).replace(model=TINY_RAFT)
    torch.manual_seed(0)
    net = build_model(TINY_RAFT)
    src = PairSource(find_clips([root / "train"]), TINY_RAFT, cfg.augment, 0)
    batch = _tensors(torch, src.batch(0, 4))
    opt = torch.optim.AdamW(net.parameters(), lr=2e-3)
    losses = []
    for _ in range(30):
        loss = _loss(torch, net(batch["x"]), batch, cfg)[0]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-5:]) < 0.67 * np.mean(losses[:5]), losses
    weights = train(cfg, tmp_path / "run", workers=1, progress=False)
    est = LearnedFlow(weights, gate=None, base="network")
    assert est.cfg.arch == "raft"
    img = band_image(120, 160, (0.0, 0.0), 6)[0]
    flow = est.compute(img, band_image(120, 160, (2.0, 1.0), 6)[0])
    assert flow.shape == (120, 160, 2) and np.isfinite(flow).all()


def test_training_on_a_gpu_is_refused_without_one(clips, tmp_path):
    root, _ = clips
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(InputError, match="train.device is 'cuda'"):
        train(_config(root, 2).replace(device="cuda"), tmp_path / "run", workers=1, progress=False)
    with pytest.raises(ConfigError, match="train.device"):
        _config(root, 2).replace(device="tpu")


def test_a_run_written_before_a_field_existed_resumes(clips, tmp_path):
    """A run folder whose config.json lacks fields added since (``device``, the RAFT
    design's) is the same config read now: it resumes instead of being refused."""
    root, _ = clips
    cfg = _config(root, 4)
    run = tmp_path / "run"
    assert train(cfg, run, workers=1, progress=False, stop_at=2) is None
    doc = json.loads((run / "config.json").read_text())
    del doc["device"], doc["model"]["raft_dims"], doc["model"]["raft_iters"]
    (run / "config.json").write_text(json.dumps(doc))
    assert train(cfg, run, workers=1, progress=False) is not None


def test_configs_are_checked():
    with pytest.raises(ConfigError, match="model.raft_iters"):
        LearnedFlowConfig(raft_iters=0)
    with pytest.raises(ConfigError, match=r"model.raft_dims\[2\]"):
        LearnedFlowConfig(raft_dims=(16, 16, 0))
    with pytest.raises(ConfigError, match="model.work_width"):
        LearnedFlowConfig(work_width=10)
    with pytest.raises(ConfigError, match="model.arch.*'pwc'"):
        LearnedFlowConfig(arch="pwc")
    with pytest.raises(ConfigError, match="model.target.*'full'"):
        LearnedFlowConfig(target="full")
    with pytest.raises(ConfigError, match=r"model.corr_radius\[1\].*9"):
        LearnedFlowConfig(corr_radius=(3, 9))
    with pytest.raises(ConfigError, match="augment.crop"):
        AugmentConfig(crop=(100, 128))
    with pytest.raises(ConfigError, match="overlap"):
        DataConfig(train=("board 0:10",), validation=("table 5:15",))
    with pytest.raises(ConfigError, match="SURFACE A:B"):
        DataConfig(train=("board 10",))
    assert DataConfig().directions == ("along", "across")  # the clips' hand motion
    with pytest.raises(ConfigError, match="data.amplitude: need 0 < LO <= HI"):
        DataConfig(amplitude=(0.05, 0.01))
    with pytest.raises(ConfigError, match="data.directions: unknown 'up'"):
        DataConfig(directions=("up",))
    with pytest.raises(ConfigError, match="data.hoses: need 1 <= LO <= HI <= 8, got 4 2"):
        DataConfig(hoses=(4, 2))
    with pytest.raises(ConfigError, match="data.h264: the share must be in"):
        DataConfig(h264=1.5)
    with pytest.raises(ConfigError, match=r"data.h264_crf: need 0 <= LO <= HI <= 51, got 30 20"):
        DataConfig(h264=0.5, h264_crf=(30, 20))
    with pytest.raises(ConfigError, match="data.same_colour"):
        DataConfig(same_colour=-0.5)


def test_band_helper_moves_by_its_shift():
    _, m0 = band_image(60, 80, (0.0, 0.0), 6)
    _, m1 = band_image(60, 80, (5.0, 2.0), 6)
    np.testing.assert_array_equal(m1[10:50, 20:70], m0[8:48, 15:65])


def test_the_command_shows_its_config_and_refuses_bad_values(capsys):
    from pathlib import Path

    from cablesim.cli import main

    config = Path(__file__).parents[2] / "configs/learned_flow.json"
    assert main(["train", "--config", str(config), "--show-config"]) == 0
    shown = capsys.readouterr().out
    assert "model.work_width = 276" in shown and "steps = 3000" in shown
    assert main(["train", "--out", "unused", "--steps", "0"]) != 0
    err = capsys.readouterr().err
    assert "train.steps" in err and "0" in err


def test_the_shipped_model_loads_and_finds_a_moving_band(clips):
    """The default weights (``cablesim train --config configs/learned_flow.json``) load, were
    made from that config, report no motion between two equal images and find the moving band
    of an analytic clip (DIS medium gated by the network's moving probability, the default:
    IoU 0.64-0.70 on these clips with the weights of 2026-12-07; the network's own
    flow, trained on the normal flow, 0.41-0.60; DIS medium 0.59-0.60)."""
    from pathlib import Path

    from cablesim.formats.movingcables import evaluate_clip

    est = LearnedFlow()
    config = json.loads((Path(__file__).parents[2] / "configs/learned_flow.json").read_text())
    assert est.cfg == LearnedFlowConfig.from_dict(config["model"])
    assert est.meta["steps"] == config["steps"]
    root, _ = clips
    first = find_clips([root / "train"])[0]
    img = first.rgb(1)
    assert not est.compute(img, img).any()
    _, summary = evaluate_clip(root / "train", first.clip, est, 1.0, truth="flow")
    assert summary.iou > 0.3, summary
    assert est.base == "dis-medium"
    own = LearnedFlow(base="network")  # DIS plus the network's correction, the same gate
    _, summary = evaluate_clip(root / "train", first.clip, own, 1.0, truth="flow")
    assert summary.iou > 0.3, summary
    with pytest.raises(InputError, match="unknown flow back end 'lava'"):
        LearnedFlow(base="lava")


def _textured_band_sequence(step: float, n: int) -> tuple[np.ndarray, list, list]:
    """(first image, images, band masks): a striped band 8 px wide moving ``step`` px per
    image across itself over a still textured background."""
    h, w = 160, 224
    rng = np.random.default_rng(0)
    noise = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
    bg = np.clip((cv2.GaussianBlur(noise, (0, 0), 1.5) - 127) * 2 + 127, 0, 255)
    bg = bg.astype(np.uint8)

    def image(s: float) -> tuple[np.ndarray, np.ndarray]:
        rgb, mask = band_image(h, w, (0.0, s), 8)
        out = bg.copy()
        out[mask] = rgb[mask]
        return out, mask

    seq = [image(step * k) for k in range(1, n + 1)]
    return image(0.0)[0], [s[0] for s in seq], [s[1] for s in seq]


def test_a_warm_start_follows_motion_that_grows_past_what_dis_finds():
    """On a sequence against its first image (the MovingCables protocol), the shipped RAFT
    design started from the flow of the image before (``warm``) keeps following a band that
    moves 2 px per image to 24 px, where started from DIS it loses it (mean error on the band
    over the last four images: 13.0 px cold, 9.2 warm with the weights of 2026-12-07); a new
    reference image, or ``reset``, starts from DIS again, bit for bit."""
    first, images, masks = _textured_band_sequence(2.0, 12)
    errors = {}
    for warm in (False, True):
        est = LearnedFlow("raft", gate=None, base="network", warm=warm, threads=1)
        e = []
        for k, (img, mask) in enumerate(zip(images, masks, strict=True), start=1):
            want = np.array(normal_part((0.0, -2.0 * k)), np.float32)
            e.append(float(np.linalg.norm(est.compute(img, first)[mask] - want, axis=1).mean()))
        errors[warm] = np.mean(e[-4:])
    assert errors[True] < 0.9 * errors[False], errors
    cold = LearnedFlow("raft", gate=None, base="network", threads=1).compute(images[5], first)
    est.reset()
    assert np.array_equal(est.compute(images[5], first), cold)
    est.compute(images[6], first)  # the sequence goes on ...
    other = images[0].copy()  # ... but against another reference the flow starts from DIS
    assert np.array_equal(
        est.compute(images[5], other),
        LearnedFlow("raft", gate=None, base="network", threads=1).compute(images[5], other),
    )


def test_iters_and_warm_need_the_raft_design_and_are_checked():
    with pytest.raises(InputError, match=r"iters and warm need a model of arch 'raft'.*\.pt"):
        LearnedFlow(warm=True)  # the shipped default is the U-Net
    with pytest.raises(InputError, match="iters must be an integer in"):
        LearnedFlow("raft", iters=0)
    with pytest.raises(InputError, match="warm must be true or false, got 'yes'"):
        make_flow("learned,weights=raft,warm=yes")
    est = make_flow("learned,weights=raft,iters=3,warm=true")
    assert est.describe()["iters"] == 3 and est.describe()["warm"] is True


def test_enlarging_a_small_image_finds_a_thin_band_the_native_size_misses():
    """A 140 px wide image with a 3 px band moving 3 px across itself: at its own size the
    RAFT design (trained at 640 px, hoses 3-10 px wide there) misses much of the motion, and
    with ``enlarge`` (the image brought to its 640 px working width and the flow back) it finds
    it (mean error on the band 2.8 px native, 1.6 enlarged with the weights of 2026-12-07);
    the flow comes back at the input's size."""
    h, w = 105, 140
    rng = np.random.default_rng(0)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (h, w, 3)).astype(np.float32), (0, 0), 1.0)
    bg = np.clip((noise - 127) * 2 + 127, 0, 255).astype(np.uint8)
    images = []
    for s in (0.0, 3.0):
        rgb, mask = band_image(h, w, (0.0, s), 3)
        out = bg.copy()
        out[mask] = rgb[mask]
        images.append(out)
    want = np.array(normal_part((0.0, -3.0)), np.float32)
    errors = {}
    for enlarge in (False, True):
        est = LearnedFlow("raft", gate=None, base="network", enlarge=enlarge, threads=1)
        flow = est.compute(images[1], images[0])
        assert flow.shape == (h, w, 2)
        errors[enlarge] = float(np.linalg.norm(flow[mask] - want, axis=1).mean())
    assert errors[True] < 0.75 * errors[False], errors
    with pytest.raises(InputError, match="enlarge must be true or false, got 2"):
        LearnedFlow("raft", enlarge=2)
