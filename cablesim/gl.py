"""Pick a headless OpenGL back end for MuJoCo before it is imported.

If the user set ``MUJOCO_GL`` we keep it.  Otherwise: a machine with a display uses ``glfw``;
a headless one uses ``egl`` when libEGL with a Mesa or vendor driver is installed, else
``osmesa``.  ``scripts/setup.sh`` installs the Debian packages for both.
"""

from __future__ import annotations

import ctypes.util
import os

_CHOSEN: str | None = None


def _has_lib(name: str) -> bool:
    return ctypes.util.find_library(name) is not None


def select_backend() -> str:
    """The back end we would use (or the one the user chose)."""
    user = os.environ.get("MUJOCO_GL")
    if user:
        return user
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "glfw"
    if _has_lib("EGL"):
        return "egl"
    if _has_lib("OSMesa"):
        return "osmesa"
    return "egl"


def configure() -> str:
    """Set ``MUJOCO_GL`` (and ``PYOPENGL_PLATFORM``) if the user has not; return the choice."""
    global _CHOSEN
    if _CHOSEN is None:
        _CHOSEN = select_backend()
        os.environ.setdefault("MUJOCO_GL", _CHOSEN)
        if _CHOSEN in ("egl", "osmesa"):
            os.environ.setdefault("PYOPENGL_PLATFORM", _CHOSEN)
    return _CHOSEN
