"""Shipped assets (textures, meshes). ``path(name)`` resolves a file in this folder."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent


def path(*parts: str) -> Path:
    return ROOT.joinpath(*parts)
