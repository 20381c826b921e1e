"""Command-line arguments shared by the subcommands, and the one place that turns them into the
typed configs (so ``scene``, ``episode`` and ``explore`` read ``--seed --hoses --width ...``
alike)."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from cablesim.config import flatten, override
from cablesim.errors import ConfigError, InputError
from cablesim.panda.visuals import VISUALS
from cablesim.sim.config import SceneConfig


def output_path(text: str) -> Path:
    """argparse ``type`` of ``--out``: a non-empty path (``Path("")`` would be the current
    directory)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("the output directory is empty")
    return Path(text)


def prepare_output_dir(out: Path | str, flag: str = "--out") -> Path:
    """Create the output directory ``out`` (and its parents) and make sure files can be
    written there, before any expensive step; ``InputError`` naming the flag and the path."""
    if out is None:
        raise InputError(f"{flag} is required: give an output directory")
    if str(out).strip() == "":
        raise InputError(f"{flag} is empty: give an output directory")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{flag} {out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as e:
        raise InputError(f"{flag} {out}: cannot write there ({e.strerror or e})") from e
    return out


def check_settle_cache(scene: SceneConfig) -> None:
    """With the settle cache on, make sure ``$CABLESIM_CACHE`` can be written before the
    scene settles; if it cannot, warn and settle without the cache (same result, no reuse)."""
    if not scene.physics.cache:
        return
    from cablesim.sim.settle import cache_dir

    where = cache_dir()
    try:
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as e:
        print(
            f"cablesim: warning: the settle cache {where} is not writable "
            f"({e.strerror or e}; set CABLESIM_CACHE); settling without it",
            file=sys.stderr,
        )
        scene.physics.cache = False


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """``--config FILE``, ``--set FIELD=VALUE`` and ``--show-config``: the whole typed config
    of a command from the line (see :func:`build_config`)."""
    g = p.add_argument_group("configuration (every field of the typed config)")
    g.add_argument(
        "--config",
        type=Path,
        default=None,
        help="start from this JSON config (a run's config.json: rerun it); flags given on the "
        "line and --set override it",
    )
    g.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="set any field by its dotted path, e.g. --set episode.scene.hoses.count=3 "
        "(JSON values; repeatable; --show-config lists the fields)",
    )
    g.add_argument(
        "--show-config",
        action="store_true",
        help="print every field of the config this command line gives, and exit",
    )


def load_config(cls: type, args: argparse.Namespace, section: str | None = None) -> Any:
    """The base config of a command: ``cls()``, or ``--config FILE`` (a config as written by
    ``to_dict``; a run's file that holds several configs names this one ``section``)."""
    path = getattr(args, "config", None)
    if path is None:
        return cls()
    try:
        data = json.loads(Path(path).read_text())
    except OSError as e:
        raise InputError(f"--config {path}: cannot read it ({e.strerror or e})") from e
    except ValueError as e:
        raise InputError(f"--config {path}: not JSON ({e})") from e
    if isinstance(data, dict) and section is not None and isinstance(data.get(section), dict):
        data = data[section]
    try:
        return cls.from_dict(data)
    except ConfigError as e:
        raise InputError(f"--config {path}: {e}") from e


def finish_config(cfg: Any, args: argparse.Namespace) -> Any:
    """``cfg`` with every ``--set FIELD=VALUE`` applied (in order), validated."""
    for assignment in getattr(args, "set", None) or []:
        cfg = override(cfg, assignment)
    return cfg.validate()


def show_config(cfg: Any) -> int:
    """``--show-config``: one ``field = value`` line per field (what ``--set`` takes)."""
    for path, value in flatten(cfg):
        print(f"{path} = {json.dumps(value)}")
    return 0


def write_config(out: Path, cfg: Any, **extra: Any) -> Path:
    """The run's config as ``out/config.json`` (rerun it with ``--config``)."""
    doc = {**cfg.to_dict(), **extra} if extra else cfg.to_dict()
    path = Path(out) / "config.json"
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path


def add_grow_colour_argument(p: argparse.ArgumentParser, applies_to: str = "") -> None:
    """``--grow-colour LAB``: the masks grow along the target's colour (``RefineParams.grow``)."""
    p.add_argument(
        "--grow-colour",
        type=float,
        default=None,
        metavar="LAB",
        help="grow the masks along the target's colour within this CIELAB distance (off; "
        f"{applies_to}helps only where the hoses differ in colour)",
    )


def add_scene_arguments(p: argparse.ArgumentParser, seed_help: str = "scene seed") -> None:
    add_config_arguments(p)
    p.add_argument("--seed", type=int, default=None, help=f"{seed_help} (default 0)")
    p.add_argument(
        "--draw",
        type=int,
        default=None,
        help="draw of the seed's scene (default 0, its own layout; a simulated session re-draws "
        "when a draw does not settle or has no suitable hose, and records which draw served)",
    )
    p.add_argument("--hoses", type=int, default=None, help="number of hoses (default 4)")
    p.add_argument("--width", type=int, default=None, help="image width (default 640)")
    p.add_argument("--height", type=int, default=None, help="image height (default 480)")
    p.add_argument(
        "--robot-visual",
        choices=VISUALS,
        default=None,
        help="how the arm is drawn: primitive (default) or mesh (franka_ros's meshes; same physics)",
    )


def add_interaction_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--periods", type=int, default=None, help="periods per action (K_p, 3)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def apply_scene_arguments(scene: SceneConfig, args: argparse.Namespace) -> SceneConfig:
    """``scene`` with the scene arguments that were given (in place; returned)."""
    if getattr(args, "seed", None) is not None:
        scene.seed = args.seed
    if getattr(args, "draw", None) is not None:
        scene.draw = args.draw
    if args.hoses is not None:
        scene.hoses.count = args.hoses
    if getattr(args, "width", None) is not None:
        scene.camera.width = args.width
    if getattr(args, "height", None) is not None:
        scene.camera.height = args.height
    if getattr(args, "robot_visual", None) is not None:
        scene.robot.visual = args.robot_visual
    return scene


def episode_config_from_args(args: argparse.Namespace) -> Any:
    """The ``EpisodeConfig`` of ``episode`` and ``twin``: ``--config`` or the default, then the
    seed, hose, scene and interaction flags that were given (not yet ``finish_config``-ed)."""
    from cablesim.sim.session import EpisodeConfig

    cfg = load_config(EpisodeConfig, args)
    if getattr(args, "seed", None) is not None:
        cfg.seed = args.seed
    if getattr(args, "hose", None) is not None:
        cfg.hose = args.hose
    apply_scene_arguments(cfg.scene, args)
    apply_interaction_arguments(cfg.interaction, args)
    return cfg


def apply_interaction_arguments(interaction: Any, args: argparse.Namespace) -> Any:
    if getattr(args, "periods", None) is not None:
        interaction.actions.periods = args.periods
    return interaction
