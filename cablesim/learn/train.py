"""``cablesim train``: the learned flow (:mod:`cablesim.perception.learned`) from simulated clips.

One run folder holds everything a run needs to be resumed and judged::

    RUN/config.json        the TrainConfig (reload it with --config RUN/config.json)
    RUN/provenance.json    commit, machine, date, torch version
    RUN/data.json          every clip trained and validated on: split folder, clip, seed
    RUN/log.csv            per logged step: loss, its parts, learning rate, seconds
    RUN/validation.csv     per validation: EPE (all known / moving pixels) and moving IoU,
                           of the network and of its DIS input on the same pairs
    RUN/loss.png           the curves, titled
    RUN/checkpoint.pt      network, optimiser and step (written atomically every val_every)
    RUN/learned_flow.pt    the final weights (what ``--flow learned,weights=FILE`` loads)

The data are made on demand: the clips of ``data.train`` and ``data.validation`` (``SURFACE
A:B`` seed ranges) are written by the dataset jobs of ``cablesim dataset movingcables`` under
``data.root`` (parallel, resumable, the same bytes whatever the number of workers) unless they
are there already.  Training pairs are drawn by :class:`~cablesim.learn.pairs.PairSource`:
sample i depends on (seed, i) alone, so a run killed and started again with the same command
continues from its last checkpoint and sees the very samples it would have seen.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from cablesim.cables import CABLE_KINDS, PATTERNS
from cablesim.commands.dataset import (
    CLIP_AMPLITUDE,
    CLIP_DIRECTIONS,
    CLIP_H264_CRF,
    check_finished,
    check_h264,
    check_motion,
    check_scenes,
    dataset_jobs,
)
from cablesim.config import Config, check_int, check_positive
from cablesim.dataset.randomize import Randomization
from cablesim.errors import ConfigError, InputError
from cablesim.files import OutputLock, append_line, drop_partial_last_line, write_text
from cablesim.jobs import execute, load_results
from cablesim.learn.pairs import AugmentConfig, ClipRef, PairSource, find_clips
from cablesim.perception.learned import (
    LearnedFlowConfig,
    _torch,
    build_model,
    read_weights,
    save_weights,
    weights_path,
)
from cablesim.progress import Progress
from cablesim.provenance import provenance
from cablesim.sim.config import SURFACES

LOG_FIELDS = ("step", "loss", "flow_l1", "bce", "lr", "seconds")
VAL_FIELDS = (
    "step",
    "epe",
    "epe_moving",
    "iou",
    "dis_epe",
    "dis_epe_moving",
    "dis_iou",
)


def parse_source(spec: str, where: str) -> tuple[str, int, int]:
    """``"SURFACE A:B"`` -> (surface, A, B); ``"folder PATH"`` -> ("folder", 0, 0)."""
    kind, _, rest = str(spec).strip().partition(" ")
    if kind == "folder" and rest.strip():
        return "folder", 0, 0
    parts = str(spec).split()
    if len(parts) != 2 or parts[0] not in SURFACES or ":" not in parts[1]:
        raise ConfigError(
            where,
            f"expected 'SURFACE A:B' (SURFACE one of {SURFACES}) or 'folder PATH', got {spec!r}",
        )
    a, _, b = parts[1].partition(":")
    try:
        first, stop = int(a), int(b)
    except ValueError:
        raise ConfigError(where, f"seeds A:B must be integers, got {parts[1]!r}") from None
    if not 0 <= first < stop or stop - first > 9999:
        raise ConfigError(where, f"need 0 <= A < B and at most 9999 seeds, got {parts[1]!r}")
    return parts[0], first, stop


@dataclass(frozen=True)
class DataConfig(Config):
    """The simulated clips: seed ranges per surface (``"board 100000:100040"``), made on
    demand under ``root``, or MovingCables split folders made before (``"folder PATH"``)."""

    SECTION: ClassVar[str] = "data"

    root: str = "runs/learned-flow-data"
    train: tuple[str, ...] = ("board 100000:100040", "table 100500:100540")
    validation: tuple[str, ...] = ("board 101000:101010", "table 101500:101510")
    width: int = 640
    height: int = 480
    # the hand's motion in each clip (``cablesim dataset movingcables --directions/--amplitude``)
    directions: tuple[str, ...] = CLIP_DIRECTIONS
    amplitude: tuple[float, float] = CLIP_AMPLITUDE
    # the scenes (``cablesim dataset --hoses/--same-colour/--h264``): cables per scene, the
    # share of scenes whose cables all wear one colour, the share of clips seen through H.264
    # at a CRF in ``h264_crf``; the defaults keep the clips of runs made before them
    hoses: tuple[int, int] = Randomization.hoses
    same_colour: float = 0.0
    h264: float = 0.0
    h264_crf: tuple[int, int] = CLIP_H264_CRF

    def _validate(self) -> None:
        # the same checks as the command line, named as this file names the fields
        check_motion(self.directions, self.amplitude, ("data.directions", "data.amplitude"))
        check_scenes(self.same_colour, self.hoses, ("data.same_colour", "data.hoses"))
        check_h264(self.h264, self.h264_crf, "data.h264", "data.h264_crf")
        spans: list[tuple[str, int, int, str]] = []
        for name in ("train", "validation"):
            if not getattr(self, name):
                raise ConfigError(f"data.{name}", "needs at least one 'SURFACE A:B'")
            for i, spec in enumerate(getattr(self, name)):
                surface, a, b = parse_source(spec, f"data.{name}[{i}]")
                if surface == "folder":
                    continue
                for _s, a2, b2, n2 in spans:
                    if a < b2 and a2 < b:
                        raise ConfigError(
                            f"data.{name}[{i}]",
                            f"seeds {a}:{b} overlap {n2}'s {a2}:{b2}: training and validation "
                            "scenes must be apart",
                        )
                spans.append((surface, a, b, f"data.{name}[{i}]"))
        check_int("data.width", self.width, 64)
        check_int("data.height", self.height, 64)

    def folders(self, split: str) -> list[tuple[str, int, int, Path]]:
        """(surface, first, stop, the split folder) of each source of ``split``."""
        out = []
        for spec in getattr(self, split):
            surface, a, b = parse_source(spec, f"data.{split}")
            if surface == "folder":
                out.append((surface, a, b, Path(str(spec).strip().partition(" ")[2].strip())))
                continue
            out.append((surface, a, b, Path(self.root) / f"{surface}-{a}-{b}" / split))
        return out


@dataclass(frozen=True)
class TrainConfig(Config):
    """A training run of the learned flow (``cablesim train --show-config``)."""

    SECTION: ClassVar[str] = "train"

    seed: int = 0
    steps: int = 3000
    batch: int = 8
    lr: float = 2e-3  # AdamW, cosine decay to lr_min
    lr_min: float = 2e-5
    weight_decay: float = 1e-4
    moving_weight: float = 1.0  # weight of the moving pixels' mean flow error (still: 1)
    bce_weight: float = 0.5  # weight of the moving probability's cross-entropy
    log_every: int = 25
    val_every: int = 250  # validation and checkpoint
    val_pairs: int = 64
    threads: int = 2  # torch threads
    # where the network trains: "cpu" (bit for bit reproducible, resumable to the same
    # weights) or "cuda" (a GPU: the same data and schedule, not bit for bit); the weights
    # written run on the CPU either way
    device: str = "cpu"
    # a weights file to start from (a shipped model's name, e.g. "raft", or a path): the
    # run fine-tunes it, its network config must be ``model``; "" starts from random weights
    init: str = ""
    model: LearnedFlowConfig = field(default_factory=LearnedFlowConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    data: DataConfig = field(default_factory=DataConfig)

    def _validate(self) -> None:
        check_int("train.seed", self.seed, 0)
        for name, lo in (
            ("steps", 1),
            ("batch", 1),
            ("log_every", 1),
            ("val_every", 1),
            ("val_pairs", 1),
            ("threads", 1),
        ):
            check_int(f"train.{name}", getattr(self, name), lo)
        for name in ("lr", "lr_min"):
            check_positive(f"train.{name}", getattr(self, name))
        for name in ("weight_decay", "moving_weight", "bce_weight"):
            check_positive(f"train.{name}", getattr(self, name), allow_zero=True)
        if self.device not in ("cpu", "cuda"):
            raise ConfigError("train.device", f"must be 'cpu' or 'cuda', got {self.device!r}")
        if self.lr_min > self.lr:
            raise ConfigError("train.lr_min", f"exceeds lr {self.lr}, got {self.lr_min}")


# ----------------------------------------------------------------------------- data
def ensure_data(cfg: DataConfig, workers: int, ray: str | None, say: Progress) -> dict:
    """Write the clips of every source that is not complete yet (the dataset jobs: resumable,
    parallel); returns what data.json records."""
    record: dict[str, Any] = {}
    for split in ("train", "validation"):
        rows = []
        for surface, a, b, folder in cfg.folders(split):
            if surface == "folder":
                for c in find_clips([folder]):
                    rows.append(
                        {
                            "folder": str(folder),
                            "clip": c.clip,
                            "seed": None,
                            "surface": None,
                            "images": len(c.indices),
                        }
                    )
                continue
            scene: dict[str, Any] = {"width": cfg.width, "height": cfg.height}
            if surface != "board":
                scene["surface"] = surface
            jobs = dataset_jobs(
                "movingcables",
                a,
                b,
                folder.parent,
                split,
                scene,
                None,
                tuple(CABLE_KINDS),
                tuple(PATTERNS),
                cfg.directions,
                cfg.amplitude,
                cfg.same_colour,
                tuple(cfg.hoses),
                cfg.h264,
                cfg.h264_crf,
            )
            check_finished(jobs, folder.parent / "jobs")
            summary = execute(
                jobs,
                folder.parent / "jobs",
                workers,
                ray,
                say.enabled,
                f"clips {surface} {a}:{b} ({split})",
            )
            say(f"{split} {surface} {a}:{b}: {summary.ok} of {summary.total} clips")
            for rec in load_results(folder.parent / "jobs", jobs):
                if rec["status"] == "ok":
                    r = rec["result"]
                    rows.append(
                        {
                            "folder": str(folder),
                            "clip": r["clip"],
                            "seed": r["seed"],
                            "surface": surface,
                            "images": r["images"],
                        }
                    )
        record[split] = rows
    return record


def clips_of(record: dict, split: str) -> list[ClipRef]:
    """The clips ``record`` lists for ``split`` (a folder may hold more: other seed ranges)."""
    wanted = {(str(r["folder"]), str(r["clip"])) for r in record[split]}
    folders = sorted({Path(r["folder"]) for r in record[split]}, key=str)
    return [c for c in find_clips(folders) if (str(c.split), c.clip) in wanted]


# ----------------------------------------------------------------------------- metrics
def moving_iou(pred: np.ndarray, truth: np.ndarray, known: np.ndarray) -> float:
    """IoU of two boolean masks over the known pixels (NaN where both are empty, as the
    published evaluation: such pairs do not count)."""
    p, t = pred & known, truth & known
    union = np.count_nonzero(p | t)
    return math.nan if union == 0 else np.count_nonzero(p & t) / union


def flow_scores(
    flow: np.ndarray, truth: np.ndarray, known: np.ndarray, moving: np.ndarray, moving_px: float
) -> tuple[float, float, float]:
    """(EPE over the known pixels, EPE over the moving ones, IoU of |flow| > moving_px with
    the moving ones) of one 2xHxW flow."""
    err = np.linalg.norm(flow - truth, axis=0)
    m = moving & known
    epe = float(err[known].mean()) if known.any() else math.nan
    epe_m = float(err[m].mean()) if m.any() else math.nan
    iou = moving_iou(np.linalg.norm(flow, axis=0) > moving_px, m, known)
    return epe, epe_m, iou


# ----------------------------------------------------------------------------- training
@dataclass
class RunState:
    step: int = 0
    seconds: float = 0.0


def _lr(cfg: TrainConfig, step: int) -> float:
    t = min(step / max(cfg.steps, 1), 1.0)
    return cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1 + math.cos(math.pi * t))


def _loss(torch: Any, out: Any, batch: dict[str, Any], cfg: TrainConfig) -> tuple[Any, Any, Any]:
    """Class-balanced losses: the moving pixels are a percent or two of a crop, so the mean
    error over the still pixels and the mean over the moving ones (times ``moving_weight``)
    are added, and the moving probability's cross-entropy is the mean of the two classes'
    (with plain pixel means a network learns that nothing moves, and stays there)."""
    F = torch.nn.functional
    norm = cfg.model.flow_norm
    pred = batch["dis"] + out[:, :2] * norm
    valid = batch["valid"]
    moving = batch["moving"]
    w_move, w_still = valid * moving, valid * (1.0 - moving)
    n_move, n_still = w_move.sum().clamp(min=1.0), w_still.sum().clamp(min=1.0)
    err = (pred - batch["flow"]).abs().sum(1)  # L1 per pixel, px
    flow_l1 = (err * w_still).sum() / n_still + cfg.moving_weight * (err * w_move).sum() / n_move
    bce = F.binary_cross_entropy_with_logits(out[:, 2], moving, reduction="none")
    bce = 0.5 * ((bce * w_still).sum() / n_still + (bce * w_move).sum() / n_move)
    return flow_l1 + cfg.bce_weight * bce, flow_l1, bce


def _tensors(torch: Any, batch: dict[str, np.ndarray], device: str = "cpu") -> dict[str, Any]:
    return {k: torch.from_numpy(v).to(device) for k, v in batch.items()}


def validate(model: Any, pairs: list[dict[str, np.ndarray]], cfg: TrainConfig) -> dict[str, float]:
    """The network's and DIS's scores on fixed validation pairs (gate 0.5, as shipped)."""
    torch = _torch()
    rows = []
    model.eval()
    with torch.inference_mode():
        for b in pairs:
            out = model(torch.from_numpy(b["x"]).to(cfg.device)).cpu().numpy()
            for j in range(out.shape[0]):
                flow = b["dis"][j] + out[j, :2] * cfg.model.flow_norm
                flow = np.where(out[j, 2] < 0.0, 0.0, flow)  # probability < 1/2
                known = b["valid"][j] > 0.5
                moving = b["moving"][j] > 0.5
                net = flow_scores(flow, b["flow"][j], known, moving, cfg.augment.moving_px)
                dis = flow_scores(b["dis"][j], b["flow"][j], known, moving, cfg.augment.moving_px)
                rows.append(net + dis)
    model.train()
    a = np.nanmean(np.array(rows, np.float64), axis=0)
    return dict(zip(VAL_FIELDS[1:], (float(v) for v in a), strict=True))


def plot_curves(run: Path) -> Path | None:
    """``loss.png``: training loss and validation EPE / IoU against step."""
    matplotlib.use("Agg")
    log = _read_csv(run / "log.csv")
    val = _read_csv(run / "validation.csv")
    if not log:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    st = [r["step"] for r in log]
    axes[0].plot(st, [r["loss"] for r in log], label="loss", lw=0.8)
    axes[0].plot(st, [r["flow_l1"] for r in log], label="flow L1 (weighted)", lw=0.8)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("step")
    axes[0].set_title("training loss")
    axes[0].legend()
    if val:
        vs = [r["step"] for r in val]
        ax = axes[1]
        ax.plot(vs, [r["epe_moving"] for r in val], "o-", label="EPE moving, network")
        ax.plot(vs, [r["dis_epe_moving"] for r in val], "--", label="EPE moving, DIS")
        ax.set_xlabel("step")
        ax.set_ylabel("px")
        ax2 = ax.twinx()
        ax2.plot(vs, [r["iou"] for r in val], "s-", color="tab:green", label="IoU, network")
        ax2.plot(vs, [r["dis_iou"] for r in val], ":", color="tab:green", label="IoU, DIS")
        ax2.set_ylabel("moving IoU")
        ax2.set_ylim(0, 1)
        ax.set_title("validation (simulated clips)")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="center right")
    fig.suptitle(f"cablesim train: {run.name}")
    fig.tight_layout()
    path = run / "loss.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _read_csv(path: Path) -> list[dict[str, float]]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def _csv_line(path: Path, names: tuple[str, ...], values: dict[str, float]) -> None:
    if not path.is_file():
        append_line(path, ",".join(names))
    append_line(path, ",".join(f"{values[n]:.6g}" for n in names))


def _truncate_csv(path: Path, step: int) -> None:
    """Drop rows after ``step`` (a killed run logged past its last checkpoint)."""
    if not path.is_file():
        return
    drop_partial_last_line(path)
    lines = path.read_text().splitlines()
    keep = [lines[0]] + [ln for ln in lines[1:] if float(ln.split(",")[0]) <= step]
    write_text(path, "\n".join(keep) + "\n")


def train(
    cfg: TrainConfig,
    run: Path,
    workers: int = 2,
    ray: str | None = None,
    progress: bool = True,
    stop_at: int | None = None,
) -> Path | None:
    """Train (or resume) the run in ``run``; returns the final weights' path.  ``stop_at``
    stops after that step with a checkpoint written, as a killed run would have left it
    (returns None then): the same call without it resumes there."""
    torch = _torch()
    run = Path(run)
    run.mkdir(parents=True, exist_ok=True)
    say = Progress("train", progress)
    with OutputLock(run):
        cfg_path = run / "config.json"
        if cfg_path.is_file():
            try:  # as read now: a field added since takes its default
                old = TrainConfig.from_dict(json.loads(cfg_path.read_text())).to_dict()
            except (ValueError, ConfigError):
                old = None
            if old != cfg.to_dict():
                raise InputError(
                    f"{run} holds a run of another config ({cfg_path}); resume it with "
                    f"--config {cfg_path}, or choose a new --out"
                )
        else:
            write_text(cfg_path, json.dumps(cfg.to_dict(), indent=1) + "\n")
        start = initial_weights(cfg)  # checked before the data are made
        record = ensure_data(cfg.data, workers, ray, say)
        write_text(run / "data.json", json.dumps(record, indent=1) + "\n")
        train_clips, val_clips = clips_of(record, "train"), clips_of(record, "validation")
        say(f"{len(train_clips)} training clips, {len(val_clips)} validation clips")

        if cfg.device == "cuda" and not torch.cuda.is_available():
            raise InputError("train.device is 'cuda' but torch sees no GPU on this machine")
        torch.manual_seed(cfg.seed)
        torch.set_num_threads(cfg.threads)
        model = build_model(cfg.model)
        if start is not None:
            model.load_state_dict(start)
            say(f"starting from {weights_path(cfg.init)}")
        model = model.to(cfg.device)
        opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        state = RunState()
        ckpt_path = run / "checkpoint.pt"
        if ckpt_path.is_file():
            ck = torch.load(ckpt_path, map_location=cfg.device, weights_only=True)
            model.load_state_dict(ck["model"])
            opt.load_state_dict(ck["optimizer"])
            state = RunState(int(ck["step"]), float(ck["seconds"]))
            say(f"resumed at step {state.step} ({ckpt_path})")
        for name in ("log.csv", "validation.csv"):
            _truncate_csv(run / name, state.step)
        if not (run / "provenance.json").is_file():
            write_text(
                run / "provenance.json",
                json.dumps(provenance(torch=torch.__version__), indent=1) + "\n",
            )

        source = PairSource(train_clips, cfg.model, cfg.augment, cfg.seed)
        vsource = PairSource(val_clips, cfg.model, cfg.augment, cfg.seed + 1_000_003)
        val_batches = [
            vsource.batch(i, min(cfg.batch, cfg.val_pairs - i))
            for i in range(0, cfg.val_pairs, cfg.batch)
        ]
        model.train()
        t_run = time.perf_counter() - state.seconds
        with say.bar(cfg.steps, "steps", "step") as bar:
            bar.update(state.step)
            while state.step < cfg.steps:
                if stop_at is not None and state.step >= stop_at:
                    _save_checkpoint(torch, ckpt_path, model, opt, state)
                    return None
                batch = _tensors(torch, source.batch(state.step * cfg.batch, cfg.batch), cfg.device)
                lr = _lr(cfg, state.step)
                for g in opt.param_groups:
                    g["lr"] = lr
                out = model(batch["x"])
                loss, flow_l1, bce = _loss(torch, out, batch, cfg)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                state.step += 1
                state.seconds = time.perf_counter() - t_run
                bar.update(1)
                if state.step % cfg.log_every == 0 or state.step == cfg.steps:
                    values = {
                        "step": state.step,
                        "loss": loss.item(),
                        "flow_l1": flow_l1.item(),
                        "bce": bce.item(),
                        "lr": lr,
                        "seconds": state.seconds,
                    }
                    _csv_line(run / "log.csv", LOG_FIELDS, values)
                    bar.set_postfix(loss=f"{values['loss']:.3f}")
                if state.step % cfg.val_every == 0 or state.step == cfg.steps:
                    v = validate(model, val_batches, cfg)
                    _csv_line(run / "validation.csv", VAL_FIELDS, {"step": state.step, **v})
                    say(
                        f"step {state.step}: validation EPE moving {v['epe_moving']:.2f} px "
                        f"(DIS {v['dis_epe_moving']:.2f}), IoU {v['iou']:.3f} "
                        f"(DIS {v['dis_iou']:.3f})"
                    )
                    _save_checkpoint(torch, ckpt_path, model, opt, state)
                    plot_curves(run)
        weights = save_weights(
            run / "learned_flow.pt",
            model,
            meta={
                "run": run.name,
                "steps": state.step,
                "seconds": round(state.seconds, 1),
                "commit": provenance().get("commit"),
                "config": cfg.to_dict(),
            },
        )
        plot_curves(run)
        say(f"weights: {weights}")
        return weights


def initial_weights(cfg: TrainConfig) -> dict[str, Any] | None:
    """The state dict ``cfg.init`` names (float32), or None; the project's error naming the
    file when it is missing, not a weights file, or of another network than ``cfg.model``."""
    if not cfg.init:
        return None
    path = weights_path(cfg.init)
    ckpt = read_weights(path)
    theirs, ours = ckpt["config"].to_dict(), cfg.model.to_dict()
    if theirs != ours:
        diff = sorted(k for k, v in ours.items() if theirs.get(k) != v)
        raise ConfigError(
            "train.init", f"{path} holds another network than train.model (differs in {diff})"
        )
    return {k: v.float() if v.is_floating_point() else v for k, v in ckpt["state_dict"].items()}


def _save_checkpoint(torch: Any, path: Path, model: Any, opt: Any, state: RunState) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    torch.save(
        {
            "model": model.state_dict(),
            "optimizer": opt.state_dict(),
            "step": state.step,
            "seconds": state.seconds,
        },
        tmp,
    )
    tmp.replace(path)
