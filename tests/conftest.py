"""Select the headless OpenGL back end before any test module imports mujoco; give each
pytest-xdist worker a loopback address of its own for franka-sim.

franka-sim serves libfranka's fixed ports (1337, 1338); two workers that each start a server
bind them on different loopback addresses (127.0.0.2 for gw0, 127.0.0.3 for gw1, ...), so the
robot tests can run beside each other (``cablesim.twin.franka_sim.HOST``).  Set before any
test module imports ``cablesim.twin``; subprocesses (``cablesim twin``) inherit it.
"""

import os

_worker = os.environ.get("PYTEST_XDIST_WORKER", "")  # "gw0", "gw1", ...
if _worker.startswith("gw") and _worker[2:].isdigit():
    os.environ.setdefault("CABLESIM_FRANKA_SIM_HOST", f"127.0.0.{2 + int(_worker[2:])}")

import cablesim  # noqa: E402, F401  (cablesim.gl sets MUJOCO_GL on import)
