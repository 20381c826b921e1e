"""Select the headless OpenGL back end before any test module imports mujoco."""

import cablesim  # noqa: F401  (cablesim.gl sets MUJOCO_GL on import)
