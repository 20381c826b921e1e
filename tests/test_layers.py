"""The house's seams: what each layer may import, read from the source of every module.

Every ``.py`` file under ``cablesim/``, ``envs/`` (``cablesim.envs``) and ``policies/``
(``cablesim.policies``) is parsed and every import in it is checked, those at module level and
those inside functions alike:

- the ground floor (``cablesim.frames``, ``cablesim.pose``, ``cablesim.checks`` and what they
  stand on: ``cablesim.errors``, ``cablesim.outcomes``, ``cablesim.config``): nothing of
  cablesim above it, and neither MuJoCo nor any other heavy package: every layer may use it;
- ``perception``, ``formats`` and ``camera``: neither the simulator (``cablesim.sim``, MuJoCo)
  nor any layer above them (``episode``, ``policies``, ``envs``);
- ``robot``: nothing of the simulator (``cablesim.sim``, ``cablesim.twin``, MuJoCo itself),
  ``episode``, ``policies`` or ``envs`` (the real arm reads the Panda's description in
  ``cablesim.panda``, whose arm-only kinematics model uses MuJoCo as a geometry library: only
  ``panda`` imports MuJoCo directly);
- ``perception``, ``camera`` and ``robot`` (with ``panda``, the Panda's description beneath
  it) import the ground floor, never each other;
- ``episode`` (the interaction runner shared by the simulated and the real robot): nothing of
  ``cablesim.sim``, ``policies`` or ``envs``.

The digital twin (``cablesim.twin``) counts as simulation: none of them imports it.

An import inside a function (a lazy import) is allowed only for an optional heavy package
(:data:`LAZY_ALLOWED`), and only with the marker :data:`MARKER` on its line: everything else
is imported at module level, where a seam that breaks shows at once.  A fresh interpreter
also checks that importing each layer loads nothing it must not, and that importing the light
packages loads none of the heavy ones.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# import name -> source folder (pyproject.toml's package-dir)
PACKAGES = {"cablesim": "cablesim", "cablesim.envs": "envs", "cablesim.policies": "policies"}

GROUND = (
    "cablesim.frames",
    "cablesim.pose",
    "cablesim.checks",
    "cablesim.errors",
    "cablesim.outcomes",
    "cablesim.config",
)
ABOVE = ("cablesim.episode", "cablesim.policies", "cablesim.envs")
SIM = ("cablesim.sim", "cablesim.twin")  # the digital twin is simulation too
# perception, camera and robot share the ground floor, never each other
PERCEPTION, CAMERA = ("cablesim.perception",), ("cablesim.camera",)
ROBOT = ("cablesim.robot", "cablesim.panda")
RULES = {
    "cablesim.perception": SIM + ABOVE + ("mujoco",) + CAMERA + ROBOT,
    "cablesim.formats": SIM + ABOVE + ("mujoco",),
    "cablesim.camera": SIM + ABOVE + ("mujoco",) + PERCEPTION + ROBOT,
    "cablesim.robot": SIM + ABOVE + PERCEPTION + CAMERA,
    "cablesim.panda": SIM + ABOVE + PERCEPTION + CAMERA + ("cablesim.robot",),
    "cablesim.episode": SIM + ("cablesim.policies", "cablesim.envs"),
}
# what a layer must not import itself though a layer beneath it may load it: the robot layer
# reaches MuJoCo only through cablesim.panda (the arm model's kinematics, mink)
DIRECT_RULES = {"cablesim.robot": ("mujoco", "mink")}
# third-party packages the ground floor must not load (it is imported by every layer)
GROUND_FORBIDDEN_THIRD_PARTY = ("mujoco", "mink", "cv2", "scipy", "torch", "ray", "matplotlib")

# Optional heavy packages: an extra that may be missing (torch, ray, rerun, franky,
# pyrealsense2, stable_baselines3) or a binary needed by one path only (imageio_ffmpeg's
# ffmpeg, for H.264 videos; trimesh, which only the asset writer needs, ~0.3 s of CPU to
# import).  Only these may be imported inside a function.
LAZY_ALLOWED = (
    "torch",
    "ray",
    "rerun",
    "franky",
    "pyrealsense2",
    "imageio_ffmpeg",
    "stable_baselines3",
    "trimesh",
)
MARKER = "# lazy: optional heavy package"


@dataclass(frozen=True)
class Import:
    """One import statement's target as seen in the source."""

    module: str  # the importing module
    path: str  # its file, relative to the tree's root
    line: int
    target: str  # the imported module (for ``from X import Y``: X, and X.Y as a candidate)
    candidates: tuple[str, ...]
    lazy: bool  # inside a function
    marked: bool  # the lazy marker is on its line


def _module_name(package: str, folder: Path, path: Path) -> str:
    parts = list(path.relative_to(folder).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([package, *parts])


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


class _Visitor(ast.NodeVisitor):
    def __init__(self, module: str, is_package: bool, path: str, lines: list[str]) -> None:
        self.module, self.is_package, self.path, self.lines = module, is_package, path, lines
        self.depth = 0
        self.found: list[Import] = []

    def _function(self, node: ast.AST) -> None:
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _function

    def _add(self, node: ast.stmt, target: str, candidates: tuple[str, ...]) -> None:
        marked = MARKER in self.lines[node.lineno - 1]
        self.found.append(
            Import(self.module, self.path, node.lineno, target, candidates, self.depth > 0, marked)
        )

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self._add(node, alias.name, (alias.name,))

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            target = _resolve(self.module, self.is_package, node.level, node.module)
        else:
            target = node.module or ""
        names = tuple(f"{target}.{a.name}" for a in node.names if a.name != "*")
        self._add(node, target, (target, *names))


def collect_imports(root: Path, packages: dict[str, str] = PACKAGES) -> list[Import]:
    """Every import statement in every module of ``packages`` under ``root``."""
    found: list[Import] = []
    for package, folder_name in sorted(packages.items()):
        folder = root / folder_name
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(folder)
            # a nested mapped package (cablesim.envs under envs/) is walked on its own
            if any(part.startswith(".") for part in rel.parts):
                continue
            source = path.read_text(encoding="utf-8")
            tree = ast.parse(source, filename=str(path))
            module = _module_name(package, folder, path)
            v = _Visitor(
                module, path.name == "__init__.py", str(path.relative_to(root)), source.splitlines()
            )
            v.visit(tree)
            found.extend(v.found)
    return found


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def violations(imports: list[Import]) -> list[str]:
    """Each import that breaks a seam or is lazy without reason, as ``path:line: why``."""
    bad: list[str] = []
    for imp in imports:
        where = f"{imp.path}:{imp.line}: {imp.module} imports {imp.target}"
        top = imp.target.split(".")[0]
        for layer, forbidden in RULES.items():
            if _within(imp.module, (layer,)):
                hit = [c for c in imp.candidates if _within(c, forbidden)]
                if hit:
                    bad.append(f"{where}: {layer} must not import {hit[0]}")
        for layer, forbidden in DIRECT_RULES.items():
            if _within(imp.module, (layer,)) and _within(imp.target, forbidden):
                bad.append(f"{where}: {layer} must not import {top} itself")
        if _within(imp.module, GROUND):
            above = [c for c in imp.candidates if c.startswith("cablesim.")]
            if top == "cablesim" and not all(_within(c, GROUND) for c in above):
                bad.append(f"{where}: the ground floor imports nothing of cablesim above it")
            if _within(imp.target, GROUND_FORBIDDEN_THIRD_PARTY):
                bad.append(f"{where}: the ground floor must stay light")
        if imp.lazy:
            if not _within(imp.target, LAZY_ALLOWED):
                bad.append(f"{where}: inside a function; import it at module level")
            elif not imp.marked:
                bad.append(f"{where}: lazy import without the marker {MARKER!r}")
    return bad


def test_every_import_keeps_to_the_layers() -> None:
    imports = collect_imports(ROOT)
    modules = {i.module for i in imports}
    for package in (*RULES, *GROUND, "cablesim.envs", "cablesim.policies"):
        assert any(_within(m, (package,)) for m in modules), f"no module of {package} read"
    bad = violations(imports)
    assert not bad, "\n".join(bad)


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp_path / "cablesim" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text, encoding="utf-8")
    return tmp_path


def test_checker_fails_on_a_function_level_import_across_a_seam(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "__init__.py": "",
            "perception/__init__.py": "",
            "perception/flow.py": (
                "def truth(stream):\n"
                f"    from cablesim.sim import flow_gt  {MARKER}\n"
                "    return flow_gt(stream)\n"
            ),
            "perception/other.py": "def f():\n    from ..sim.truth import SimTruth\n",
            "frames.py": "from cablesim.perception import flow\n",
            "pose.py": "from cablesim import gl\n",
            "robot/__init__.py": "",
            "robot/arm.py": "import numpy\nimport mujoco\nfrom cablesim.panda import ik\n",
        },
    )
    bad = violations(collect_imports(root, {"cablesim": "cablesim"}))
    assert any("perception/flow.py:2" in b and "must not import cablesim.sim" in b for b in bad), (
        bad
    )
    # the marker is no licence: cablesim.sim is no optional heavy package
    assert any("perception/flow.py:2" in b and "inside a function" in b for b in bad), bad
    # a relative import is resolved before it is judged
    assert any("perception/other.py:2" in b and "cablesim.sim.truth" in b for b in bad), bad
    assert any("frames.py:1" in b and "ground floor" in b for b in bad), bad
    assert any("pose.py:1" in b and "ground floor" in b for b in bad), bad
    # the robot layer reaches MuJoCo only through cablesim.panda, never by itself
    assert any("robot/arm.py:2" in b and "must not import mujoco itself" in b for b in bad), bad
    assert not any("robot/arm.py:1" in b or "robot/arm.py:3" in b for b in bad), bad


def test_checker_reports_an_unmarked_lazy_import(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "__init__.py": "",
            "perception/__init__.py": "",
            "perception/raft.py": (
                "def load():\n"
                "    import torch\n"
                f"    import ray  {MARKER}\n"
                "    import json\n"
                "    return torch, ray, json\n"
            ),
        },
    )
    bad = violations(collect_imports(root, {"cablesim": "cablesim"}))
    assert any("raft.py:2" in b and "without the marker" in b for b in bad), bad
    assert not any("raft.py:3" in b for b in bad), bad
    assert any("raft.py:4" in b and "module level" in b for b in bad), bad
    assert len(bad) == 2, bad


SCRIPT = """
import importlib, json, pkgutil, sys
package, forbidden = sys.argv[1], tuple(sys.argv[2].split(","))
pkg = importlib.import_module(package)
names = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__)) if hasattr(pkg, "__path__") else []
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


def _fresh(package: str, forbidden: tuple[str, ...]) -> dict:
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, package, ",".join(forbidden)],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("package", sorted(RULES))
def test_layer_imports_nothing_it_must_not_in_a_fresh_interpreter(package: str) -> None:
    out = _fresh(package, RULES[package])
    assert out["modules"], f"no modules found in {package}"
    assert not out["loaded"], f"importing {package} loads {out['loaded']}"
    assert not out["bad"], f"modules of {package} import what they must not: {out['bad']}"


@pytest.mark.parametrize("module", ["cablesim.frames", "cablesim.pose", "cablesim.checks"])
def test_ground_floor_loads_nothing_above_it(module: str) -> None:
    above = ("cablesim.perception", "cablesim.robot", "cablesim.panda", "cablesim.camera")
    out = _fresh(module, above + SIM + ABOVE + GROUND_FORBIDDEN_THIRD_PARTY)
    assert not out["loaded"], f"importing {module} loads {out['loaded']}"


def test_light_packages_load_no_optional_heavy_package() -> None:
    heavy = ("torch", "ray", "rerun", "franky", "pyrealsense2", "stable_baselines3")
    for package in ("cablesim.perception", "cablesim.episode", "cablesim.robot"):
        out = _fresh(package, heavy)
        assert not out["loaded"], f"importing {package} loads {out['loaded']}"


def test_a_simulated_run_does_not_import_trimesh() -> None:
    # trimesh only writes the shipped connector meshes (python -m cablesim.sim.assets); the
    # simulator reads the files, and the import cost every command ~0.3 s of CPU (issue 21)
    for package in ("cablesim.sim", "cablesim.commands"):
        out = _fresh(package, ("trimesh",))
        assert not out["loaded"], f"importing {package} loads {out['loaded']}"
