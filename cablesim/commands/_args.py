"""Command-line arguments shared by the subcommands, and the one place that turns them into the
typed configs (so ``scene``, ``episode`` and ``explore`` read ``--seed --hoses --width ...``
alike).

A flag is a shortcut for one field of the command's config: :func:`build_config` starts
from the default config or ``--config FILE``, writes every flag that was given into its
field's dotted path (``--width`` -> ``episode.scene.camera.width`` in ``explore``; the tables
:data:`SCENE_FLAGS` and :data:`EPISODE_FLAGS`) and then every ``--set FIELD=VALUE``, and
builds the config once, checked (a config that exists is valid)."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from cablesim.cables import CABLE_KINDS, DEFAULT_KIND, PATTERNS
from cablesim.config import ConfigMigrationWarning, flatten, parse_value, replace_paths
from cablesim.errors import ConfigError, InputError
from cablesim.panda.description import VISUALS
from cablesim.sim.config import SURFACES
from cablesim.sim.settle import cache_dir

T = TypeVar("T")

#: Scene flags (argparse ``dest``) -> the field they write, below a SceneConfig.
SCENE_FLAGS: Mapping[str, str] = {
    "seed": "seed",
    "draw": "draw",
    "scene": "surface",
    "hoses": "hoses.count",
    "cable": "hoses.kind",
    "pattern": "hoses.pattern",
    "width": "camera.width",
    "height": "camera.height",
    "robot_visual": "robot.visual",
}
#: Episode flags -> the field they write, below an EpisodeConfig (the scene's under ``scene.``).
EPISODE_FLAGS: Mapping[str, str] = {
    **{dest: f"scene.{path}" for dest, path in SCENE_FLAGS.items()},
    "hose": "hose",
    "periods": "interaction.actions.periods",
}


def below(prefix: str, flags: Mapping[str, str]) -> dict[str, str]:
    """``flags`` with every path under ``prefix`` (``below("episode", EPISODE_FLAGS)``)."""
    return {dest: f"{prefix}.{path}" for dest, path in flags.items()}


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


def check_settle_cache(cfg: T, scene: str = "") -> T:
    """With the settle cache on, make sure ``$CABLESIM_CACHE`` can be written before the
    scene settles; if it cannot, warn and return ``cfg`` with the cache off (its scene at the
    dotted path ``scene``; same result, no reuse)."""
    node: Any = cfg
    for key in filter(None, scene.split(".")):
        node = getattr(node, key)
    if not node.physics.cache:
        return cfg

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
        return replace_paths(cfg, {f"{scene}.physics.cache" if scene else "physics.cache": False})
    return cfg


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
    ``to_dict``; a run's file that holds several configs names this one ``section``).  A file
    of an earlier cablesim loads with its moved fields in their new place: each move is a
    warning line on stderr naming the old and the new field."""
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
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConfigMigrationWarning)
        try:
            cfg = cls.from_dict(data)
        except ConfigError as e:
            raise InputError(f"--config {path}: {e}") from e
    for w in caught:
        if issubclass(w.category, ConfigMigrationWarning):
            print(f"cablesim: warning: --config {path}: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return cfg


def set_values(args: argparse.Namespace) -> dict[str, Any]:
    """The ``--set FIELD=VALUE`` assignments (in order; a later one of a field wins)."""
    out: dict[str, Any] = {}
    for assignment in getattr(args, "set", None) or []:
        path, sep, text = assignment.partition("=")
        if not sep or not path.strip():
            raise ConfigError("--set", f"expected FIELD=VALUE, got {assignment!r}")
        out[path.strip()] = parse_value(text.strip())
    return out


def build_config(
    cls: type[T],
    args: argparse.Namespace,
    flags: Mapping[str, str],
    values: Mapping[str, Any] | None = None,
    section: str | None = None,
) -> T:
    """The command's config: ``cls()`` or ``--config FILE``; then each flag of ``flags``
    (argparse ``dest`` -> dotted field path) that was given (not None), then ``values``
    (field path -> value: what other flags mean), then every ``--set``; built once and
    checked, so the order of the changes does not matter (``--set`` wins over a flag)."""
    cfg = load_config(cls, args, section)
    changes = {
        path: getattr(args, dest)
        for dest, path in flags.items()
        if getattr(args, dest, None) is not None
    }
    for path in list(changes):  # --cable/--pattern: every cable of that kind, none per cable
        if path.split(".")[-2:] in (["hoses", "kind"], ["hoses", "pattern"]):
            changes[path + "s"] = ()
    changes.update(values or {})
    changes.update(set_values(args))
    return replace_paths(cfg, changes, shortcuts=False) if changes else cfg


def show_config(cfg: Any) -> int:
    """``--show-config``: one ``field = value`` line per field, by its full dotted path (what
    ``--set`` takes); every field once."""
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


def add_cable_argument(p: argparse.ArgumentParser, default: str = DEFAULT_KIND) -> None:
    """``--cable KIND``: every cable of one kind (``cablesim cables`` lists them)."""
    p.add_argument(
        "--cable",
        choices=tuple(CABLE_KINDS),
        default=None,
        help=f"the kind of every cable (default {default}; `cablesim cables` lists them)",
    )


def add_pattern_argument(
    p: argparse.ArgumentParser, default: str = "the kind's", kind_choice: bool = False
) -> None:
    """``--pattern NAME``: every cable wears one surface pattern (``cablesim cables``)."""
    p.add_argument(
        "--pattern",
        choices=(("kind",) if kind_choice else ()) + tuple(PATTERNS),
        default=None,
        help=f"the surface pattern of every cable (default {default}"
        + ("; kind: each cable its kind's" if kind_choice else "")
        + "; `cablesim cables` lists them)",
    )


def add_surface_argument(p: argparse.ArgumentParser) -> None:
    """``--scene board|table``: cables hanging on the task board, or lying on the table."""
    p.add_argument(
        "--scene",
        choices=SURFACES,
        default=None,
        help="board: cables hanging from a vertical task board (default); table: cables lying "
        "and crossing on a table, grasped from above",
    )


def add_scene_arguments(p: argparse.ArgumentParser, seed_help: str = "scene seed") -> None:
    add_config_arguments(p)
    add_surface_argument(p)
    p.add_argument("--seed", type=int, default=None, help=f"{seed_help} (default 0)")
    p.add_argument(
        "--draw",
        type=int,
        default=None,
        help="draw of the seed's scene (default 0, its own layout; a simulated session re-draws "
        "when a draw does not settle or has no suitable hose, and records which draw served)",
    )
    p.add_argument("--hoses", type=int, default=None, help="number of hoses (default 4)")
    add_cable_argument(p)
    add_pattern_argument(p)
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
