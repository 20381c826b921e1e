"""The Panda's look: franka_ros's visual meshes on the primitive model, or the primitives alone.

``visual="primitive"`` draws the capsules, cylinders and boxes that :mod:`cablesim.panda.model`
collides with.  ``visual="mesh"`` adds, per link, the franka_ros visual meshes shipped in
``assets/panda/`` (Apache-2.0; provenance, licence and modifications in ``assets/panda/NOTICE``;
written by ``scripts/vendor_panda_meshes.py``) as *visual-only* geoms and moves the primitives
to a hidden geom group:

- mesh geoms: ``contype = conaffinity = 0``, no mass (the bodies' inertials are explicit),
  group :data:`VISUAL_GROUP` (2, drawn by default);
- primitives: unchanged except ``group`` = :data:`HIDDEN_COLLISION_GROUP` (3, which MuJoCo's
  default ``MjvOption`` does not draw), so contacts, masses and the simulated physics are
  exactly those of the primitive model (bit for bit, ``tests/robot/test_panda_visuals.py``).

Segmentation rendering draws only visible geoms, so the robot's labels follow the meshes.
The meshes' vertices are in franka_ros's link frames, which are the DH frames the model's
bodies use (link0-7), the hand frame (flange, -45 degrees about z) and the finger frames.
"""

from __future__ import annotations

import json
from functools import cache

import mujoco

from cablesim.assets import path as asset_path
from cablesim.panda.description import VISUALS, check_visual  # noqa: F401 (re-exported)

VISUAL_GROUP = 2
HIDDEN_COLLISION_GROUP = 3
MESH_DIR = "panda"

# part colour -> (rgba, specular, shininess); franka_ros's palette, shell slightly warm white
_MATERIALS: dict[str, tuple[tuple[float, float, float, float], float, float]] = {
    "white": ((0.94, 0.94, 0.93, 1.0), 0.35, 0.45),
    "grey": ((0.78, 0.78, 0.78, 1.0), 0.3, 0.4),
    "dark": ((0.22, 0.22, 0.23, 1.0), 0.25, 0.3),
    "blue": ((0.15, 0.54, 0.80, 1.0), 0.3, 0.5),
    "red": ((0.90, 0.05, 0.05, 1.0), 0.3, 0.5),
    "green": ((0.05, 0.85, 0.10, 1.0), 0.3, 0.5),
}


@cache
def mesh_parts() -> tuple[dict, ...]:
    """The vendored parts: ``{"file", "link", "colour", "faces"}`` per mesh."""
    manifest = asset_path(MESH_DIR, "parts.json")
    return tuple(json.loads(manifest.read_text()))


def add_mesh_visuals(spec: mujoco.MjSpec, prefix: str = "") -> None:
    """Add the visual meshes to the Panda in ``spec`` (bodies ``{prefix}link0..7``, ``hand``,
    ``left_finger``, ``right_finger``) and hide its primitive geoms (see the module doc)."""

    p = prefix
    bodies = [f"{p}link{i}" for i in range(8)] + [f"{p}hand", f"{p}left_finger", f"{p}right_finger"]
    for name in bodies:
        for g in spec.body(name).geoms:
            g.group = HIDDEN_COLLISION_GROUP
    for colour, (rgba, specular, shininess) in _MATERIALS.items():
        spec.add_material(
            name=f"{p}panda_{colour}", rgba=list(rgba), specular=specular, shininess=shininess
        )
    meshes = set()
    for part in mesh_parts():
        mesh_name = f"{p}panda_{part['file'].removesuffix('.stl')}"
        if mesh_name not in meshes:
            spec.add_mesh(name=mesh_name, file=str(asset_path(MESH_DIR, part["file"])))
            meshes.add(mesh_name)
        link = part["link"]
        targets = [f"{p}left_finger", f"{p}right_finger"] if link == "finger" else [p + link]
        for body_name in targets:
            body = spec.body(body_name)
            g = body.add_geom(name=f"{body_name}_visual_{part['colour']}")
            g.type = mujoco.mjtGeom.mjGEOM_MESH
            g.meshname = mesh_name
            g.material = f"{p}panda_{part['colour']}"
            g.contype = 0
            g.conaffinity = 0
            g.group = VISUAL_GROUP
            g.mass = 0.0
            g.density = 0.0


def add_mesh_visuals_same_view(
    spec: mujoco.MjSpec, model: mujoco.MjModel, prefix: str = ""
) -> mujoco.MjModel:
    """Add the meshes to ``spec`` (compiled as ``model`` with primitive visuals) and compile it
    again with ``model``'s statistics (extent, centre, mean size) kept: MuJoCo derives the
    clip planes and shadow range of every camera from them, so a frame in which the arm is out
    of view renders the same bytes with either look."""
    spec.stat.extent = float(model.stat.extent)
    spec.stat.center = model.stat.center.tolist()
    spec.stat.meansize = float(model.stat.meansize)
    add_mesh_visuals(spec, prefix)
    return spec.compile()
