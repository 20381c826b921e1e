"""Vendor the Panda's visual meshes from the dm-robotics-panda wheel into ``assets/panda/``.

A development-time tool; nothing runs it at run time and the simulator only reads its output.

    .venv/bin/pip download dm-robotics-panda==0.4.8 --no-deps -d /tmp/wheels
    .venv/bin/pip install fast-simplification==0.2.0        # only for this script
    .venv/bin/python scripts/vendor_panda_meshes.py /tmp/wheels/dm_robotics_panda-0.4.8-py3-none-any.whl

The wheel ships franka_ros's Panda meshes (Apache-2.0, Copyright 2017 Franka Emika GmbH) as
OBJ files whose faces take their colour from a 6-colour palette texture (``panda.png``).  For
each link this script

1. reads the OBJ (its vertices are in the link's DH frame, as in franka_ros);
2. gives every face the palette colour under its texture coordinates and splits the link into
   one part per colour (white shell, dark joint covers, light grey rings, the status lights);
3. welds duplicate vertices and reduces each part to ``--keep`` of its faces with quadric edge
   collapse (parts under ``MIN_FACES`` faces are kept whole);
4. writes each part as a binary STL (``{link}_{colour}.stl``, metres, link frame), a manifest
   ``parts.json`` (file, link, colour, faces), the NOTICE (franka_ros's, with where the files
   come from and how they were changed) and the Apache-2.0 text from the wheel.

The output is deterministic for the same wheel and options.
"""

from __future__ import annotations

import argparse
import io
import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import trimesh

LINKS = ("link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand", "finger")
WHEEL_DIR = "dm_robotics/panda/assets/panda/"
WHEEL_LICENCE = "dm_robotics_panda-0.4.8.dist-info/licenses/LICENSE"  # Apache-2.0, full text
# palette colour (RGB of panda.png) -> part name; the rgba the model draws it with
PALETTE: dict[tuple[int, int, int], str] = {
    (255, 255, 255): "white",
    (204, 204, 204): "grey",
    (64, 64, 64): "dark",
    (39, 138, 205): "blue",
    (255, 0, 0): "red",
    (0, 255, 0): "green",
}
MIN_FACES = 400
OUT = Path(__file__).resolve().parents[1] / "assets" / "panda"

LICENCE_HEADER = """\
The Panda meshes in this folder are derived from franka_ros (https://github.com/frankaemika/franka_ros,
franka_description/meshes/visual), as redistributed in the PyPI wheel dm-robotics-panda 0.4.8
(dm_robotics/panda/assets/panda/*.obj, panda.png, NOTICE).  Its NOTICE follows, verbatim:

"""
MODIFICATIONS = """
Modifications (by cablesim, with scripts/vendor_panda_meshes.py): each link's faces were split
by the colour of its palette texture into one mesh per colour, duplicate vertices were welded,
the meshes were simplified (quadric edge collapse) and written as binary STL in the link frame.
The full text of the Apache License, Version 2.0 is in LICENSE-2.0.txt beside this file.
"""


def _read(wheel: zipfile.ZipFile, name: str) -> bytes:
    return wheel.read(WHEEL_DIR + name)


def split_by_colour(mesh: trimesh.Trimesh, texture: np.ndarray) -> dict[str, trimesh.Trimesh]:
    """One mesh per palette colour, from the texture colour at each face's mean uv."""
    uv = np.asarray(mesh.visual.uv, dtype=np.float64)
    h, w = texture.shape[:2]
    centre = uv[mesh.faces].mean(axis=1)
    px = np.clip((centre[:, 0] * w).astype(int), 0, w - 1)
    py = np.clip(((1.0 - centre[:, 1]) * h).astype(int), 0, h - 1)
    colour = texture[py, px, :3]
    parts = {}
    for rgb, name in PALETTE.items():
        faces = np.flatnonzero(np.all(colour == rgb, axis=1))
        if faces.size == 0:
            continue
        sub = trimesh.Trimesh(
            vertices=np.asarray(mesh.vertices), faces=np.asarray(mesh.faces)[faces], process=False
        )
        sub.merge_vertices(merge_tex=True, merge_norm=True)
        sub.remove_unreferenced_vertices()
        parts[name] = sub
    unknown = len(mesh.faces) - sum(len(p.faces) for p in parts.values())
    if unknown:
        raise SystemExit(f"{unknown} faces have a colour outside the palette")
    return parts


def simplify(mesh: trimesh.Trimesh, keep: float) -> trimesh.Trimesh:
    if keep >= 1.0 or len(mesh.faces) < MIN_FACES:
        return mesh
    import fast_simplification

    points, faces = fast_simplification.simplify(
        np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces), 1.0 - keep
    )
    out = trimesh.Trimesh(vertices=points, faces=faces, process=True)
    out.remove_unreferenced_vertices()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("wheel", type=Path, help="dm_robotics_panda-0.4.8-py3-none-any.whl")
    ap.add_argument("--keep", type=float, default=0.25, help="fraction of faces kept per part")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    import imageio.v2 as imageio

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.stl"):
        old.unlink()
    manifest = []
    with zipfile.ZipFile(args.wheel) as wheel, tempfile.TemporaryDirectory() as scratch:
        tmp = Path(scratch)
        for member in wheel.namelist():
            if member.startswith(WHEEL_DIR) and not member.endswith("/"):
                (tmp / member[len(WHEEL_DIR) :]).write_bytes(wheel.read(member))
        texture = np.asarray(imageio.imread(io.BytesIO(_read(wheel, "panda.png"))))
        notice = _read(wheel, "NOTICE").decode()
        licence = wheel.read(WHEEL_LICENCE).decode()
        for link in LINKS:
            obj = trimesh.load(tmp / f"{link}.obj", process=False, force="mesh")
            for colour, part in split_by_colour(obj, texture).items():
                small = simplify(part, args.keep)
                name = f"{link}_{colour}.stl"
                (out / name).write_bytes(trimesh.exchange.stl.export_stl(small))
                manifest.append(
                    {"file": name, "link": link, "colour": colour, "faces": len(small.faces)}
                )
                print(f"{name}: {len(part.faces)} -> {len(small.faces)} faces")
    (out / "parts.json").write_text(json.dumps(manifest, indent=1) + "\n")
    if "Apache License" not in licence or "Version 2.0" not in licence:
        raise SystemExit(f"{WHEEL_LICENCE} is not the Apache License 2.0")
    (out / "LICENSE-2.0.txt").write_text(licence)
    (out / "NOTICE").write_text(LICENCE_HEADER + notice.rstrip() + "\n" + MODIFICATIONS)
    total = sum(p["faces"] for p in manifest)
    print(f"wrote {len(manifest)} parts, {total} faces, to {out}")


if __name__ == "__main__":
    main()
