"""Command-line arguments shared by the subcommands, and the one place that turns them into the
typed configs (so ``scene``, ``episode`` and ``explore`` read ``--seed --hoses --width ...``
alike)."""

from __future__ import annotations

import argparse
from typing import Any

from cablesim.sim.config import SceneConfig


def add_scene_arguments(p: argparse.ArgumentParser, seed_help: str = "scene seed") -> None:
    p.add_argument("--seed", type=int, default=0, help=f"{seed_help} (default 0)")
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


def add_interaction_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--periods", type=int, default=None, help="periods per action (K_p, 3)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def apply_scene_arguments(scene: SceneConfig, args: argparse.Namespace) -> SceneConfig:
    """``scene`` with the scene arguments that were given (in place; returned)."""
    scene.seed = args.seed
    if getattr(args, "draw", None) is not None:
        scene.draw = args.draw
    if args.hoses is not None:
        scene.hoses.count = args.hoses
    if getattr(args, "width", None) is not None:
        scene.camera.width = args.width
    if getattr(args, "height", None) is not None:
        scene.camera.height = args.height
    return scene


def apply_interaction_arguments(interaction: Any, args: argparse.Namespace) -> Any:
    if getattr(args, "periods", None) is not None:
        interaction.actions.periods = args.periods
    return interaction
