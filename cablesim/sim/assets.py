"""Procedural assets: board textures and connector meshes.

The files in ``assets/`` were written by ``python -m cablesim.sim.assets`` (deterministic: the
same code writes the same bytes) and ship with the package; the simulator only reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from cablesim.assets import ROOT as ASSET_ROOT

if TYPE_CHECKING:
    import trimesh

TEXTURE_SIZE = 512
TEXTURES = {"wood": "board_wood.png", "bushes": "board_bushes.png", "cables": "board_cables.png"}
MESHES = {"male": "connector_male.stl", "female": "connector_female.stl"}


def texture_path(background: str) -> Path:
    return ASSET_ROOT / "textures" / TEXTURES[background]


def mesh_path(kind: str) -> Path:
    return ASSET_ROOT / "meshes" / MESHES[kind]


def _smooth_noise(rng: np.random.Generator, size: int, scale: int) -> np.ndarray:
    small = rng.random((max(2, size // scale), max(2, size // scale)), dtype=np.float32)
    return cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)


def wood_texture(size: int = TEXTURE_SIZE, seed: int = 1) -> np.ndarray:
    """Plain light wood (plywood-like grain), RGB uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    warp = _smooth_noise(rng, size, 64) * 0.08 + _smooth_noise(rng, size, 16) * 0.01
    grain = 0.5 + 0.5 * np.sin((x * 0.15 + y + warp) * 2 * np.pi * 18)
    fine = _smooth_noise(rng, size, 4) * 0.5
    base = np.array([196, 158, 112], np.float32)
    dark = np.array([160, 118, 74], np.float32)
    t = np.clip(0.55 * grain**3 + 0.25 * fine, 0, 1)[..., None]
    return np.clip(base * (1 - t) + dark * t, 0, 255).astype(np.uint8)


def bushes_texture(size: int = TEXTURE_SIZE, seed: int = 2) -> np.ndarray:
    """Leafy clutter: many overlapping leaves in greens and browns, RGB uint8."""
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), (38, 60, 30), np.uint8)
    for _ in range(2600):
        c = (int(rng.integers(0, size)), int(rng.integers(0, size)))
        axes = (int(rng.integers(4, 14)), int(rng.integers(2, 6)))
        g = rng.uniform(0.35, 1.0)
        color = (int(40 * g + rng.integers(0, 30)), int(150 * g), int(45 * g + rng.integers(0, 20)))
        if rng.random() < 0.12:
            color = (int(110 * g), int(85 * g), int(40 * g))
        cv2.ellipse(img, c, axes, float(rng.uniform(0, 180)), 0, 360, color, -1, cv2.LINE_AA)
    return img


def cables_texture(size: int = TEXTURE_SIZE, seed: int = 3) -> np.ndarray:
    """Network-cable clutter: thin coloured curves over a dark panel, RGB uint8."""
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), (60, 62, 66), np.uint8)
    palette = [
        (40, 90, 200),
        (200, 200, 205),
        (230, 200, 40),
        (200, 60, 50),
        (60, 160, 80),
        (30, 30, 35),
        (120, 120, 130),
    ]
    t = np.linspace(0, 1, 60)[:, None]
    for _ in range(70):
        p = rng.uniform(-0.1, 1.1, (4, 2)) * size
        curve = (
            (1 - t) ** 3 * p[0]
            + 3 * (1 - t) ** 2 * t * p[1]
            + 3 * (1 - t) * t**2 * p[2]
            + t**3 * p[3]
        )
        color = palette[int(rng.integers(0, len(palette)))]
        thick = int(rng.integers(3, 8))
        pts = curve.astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], False, (20, 20, 20), thick + 2, cv2.LINE_AA)
        cv2.polylines(img, [pts], False, color, thick, cv2.LINE_AA)
    return img


def male_connector_mesh() -> trimesh.Trimesh:
    """Male garden-hose connector along +z from z = 0 (base flange) to its tip at z = 0.06."""
    # only where the meshes are (re)written, not on every run (~0.3 s of CPU)
    import trimesh  # lazy: optional heavy package

    hexnut = trimesh.creation.cylinder(radius=0.016, height=0.012, sections=6)
    hexnut.apply_translation([0, 0, 0.006])
    body = trimesh.creation.cylinder(radius=0.0105, height=0.03, sections=24)
    body.apply_translation([0, 0, 0.027])
    thread = trimesh.creation.cylinder(radius=0.0125, height=0.018, sections=24)
    thread.apply_translation([0, 0, 0.051])
    return trimesh.util.concatenate([hexnut, body, thread])


def female_connector_mesh() -> trimesh.Trimesh:
    """Female coupling on a hose end, along +z from z = 0 (mating face) to z = 0.05."""
    import trimesh  # lazy: optional heavy package

    parts = []
    nut = trimesh.creation.cylinder(radius=0.0165, height=0.022, sections=12)
    nut.apply_translation([0, 0, 0.011])
    parts.append(nut)
    for k in range(3):
        rib = trimesh.creation.cylinder(radius=0.0115, height=0.004, sections=24)
        rib.apply_translation([0, 0, 0.027 + 0.008 * k])
        parts.append(rib)
    sleeve = trimesh.creation.cylinder(radius=0.0095, height=0.028, sections=24)
    sleeve.apply_translation([0, 0, 0.036])
    parts.append(sleeve)
    return trimesh.util.concatenate(parts)


def write_all(root: Path = ASSET_ROOT) -> list[Path]:
    """(Re)write every procedural asset under ``root``; returns the paths."""
    (root / "textures").mkdir(parents=True, exist_ok=True)
    (root / "meshes").mkdir(parents=True, exist_ok=True)
    out = []
    for name, fn in (
        ("wood", wood_texture),
        ("bushes", bushes_texture),
        ("cables", cables_texture),
    ):
        p = root / "textures" / TEXTURES[name]
        cv2.imwrite(str(p), cv2.cvtColor(fn(), cv2.COLOR_RGB2BGR))
        out.append(p)
    for kind, fn in (("male", male_connector_mesh), ("female", female_connector_mesh)):
        p = root / "meshes" / MESHES[kind]
        fn().export(str(p))
        out.append(p)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description="write cablesim's procedural assets")
    ap.add_argument("--root", type=Path, default=ASSET_ROOT)
    for p in write_all(ap.parse_args().root):
        print(p)


if __name__ == "__main__":
    main()
