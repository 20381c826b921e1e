"""The house's seams: what each layer may import (checked module by module in a fresh
interpreter).

- ``perception``, ``formats`` and ``camera``: neither the simulator (``cablesim.sim``, MuJoCo) nor any layer
  above them (``episode``, ``policies``, ``envs``);
- ``robot``: nothing of the simulator, ``episode``, ``policies`` or ``envs`` (the real arm
  reads the Panda's description in ``cablesim.panda``, whose arm-only kinematics model uses
  MuJoCo as a geometry library, never ``cablesim.sim``);
- ``episode`` (the interaction runner shared by the simulated and the real robot): nothing of
  ``cablesim.sim``, ``policies`` or ``envs``.

The digital twin (``cablesim.twin``) counts as simulation: none of them imports it.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

ABOVE = ("cablesim.episode", "cablesim.policies", "cablesim.envs")
SIM = ("cablesim.sim", "cablesim.twin")  # the digital twin is simulation too
RULES = {
    "cablesim.perception": SIM + ABOVE + ("mujoco",),
    "cablesim.formats": SIM + ABOVE + ("mujoco",),
    "cablesim.camera": SIM + ABOVE + ("mujoco",),
    "cablesim.robot": SIM + ABOVE,
    "cablesim.episode": SIM + ("cablesim.policies", "cablesim.envs"),
}

SCRIPT = """
import importlib, json, pkgutil, sys
package, forbidden = sys.argv[1], tuple(sys.argv[2].split(","))
pkg = importlib.import_module(package)
names = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__))
bad = {}
def offenders():
    return sorted(m for m in sys.modules if m.startswith(forbidden) and
                  (m in forbidden or m.startswith(tuple(f + "." for f in forbidden))))
before = offenders()
for name in names:
    importlib.import_module(package + "." + name)
    now = offenders()
    new = [m for m in now if m not in before]
    if new:
        bad[name] = new
    before = now
print(json.dumps({"modules": names, "bad": bad, "loaded": before}))
"""


@pytest.mark.parametrize("package", sorted(RULES))
def test_layer_imports_nothing_it_must_not(package: str) -> None:
    forbidden = ",".join(RULES[package])
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, package, forbidden],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["modules"], f"no modules found in {package}"
    assert not out["loaded"], f"importing {package} loads {out['loaded']}"
    assert not out["bad"], f"modules of {package} import what they must not: {out['bad']}"
