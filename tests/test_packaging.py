"""The wheel: every package of the tree listed in ``pyproject.toml``, built without a setuptools
warning, holding every runtime file (code, meshes, textures, the Panda's files), and installed
into a fresh environment it runs ``cablesim scene`` from outside the checkout with the same
result as the checkout.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
#: what a build copies: the project file, the readme it names and the package roots
BUILD_INPUTS = ("pyproject.toml", "README.md", *sorted(set(PYPROJECT["package-dir"].values())))
#: a warning as setuptools and Python print it (``BuildBackendWarning: ...``, ``!!`` banners)
WARNING = re.compile(r"\w*Warning\b|^\s*!!\s*$|#\s*Package would be ignored", re.M)


def _skipped(path: Path) -> bool:
    return "__pycache__" in path.parts or path.suffix == ".pyc"


def _tree_files(root: Path = ROOT) -> dict[str, Path]:
    """Every file under the package roots, by the path it has in an installed package."""
    out = {}
    for package, folder in PYPROJECT["package-dir"].items():
        base = root / folder
        for p in sorted(base.rglob("*")):
            if p.is_file() and not _skipped(p.relative_to(base)):
                rel = p.relative_to(base)
                # a root nested in another one's tree (none today) is counted once, by its own
                out.setdefault("/".join([*package.split("."), *rel.parts]), p)
    return out


def _tree_packages(root: Path = ROOT) -> set[str]:
    """Dotted names of the folders holding files under the package roots: what Python can
    import and setuptools must be told about."""
    return {name.rsplit("/", 1)[0].replace("/", ".") for name in _tree_files(root)}


def test_every_package_of_the_tree_is_listed() -> None:
    listed = set(PYPROJECT["packages"])
    assert len(listed) == len(PYPROJECT["packages"]), "a package is listed twice"
    tree = _tree_packages()
    assert {"cablesim.calibration", "cablesim.assets.panda", "cablesim.twin"} <= tree
    assert tree - listed == set(), "importable but absent from [tool.setuptools] packages"
    assert listed - tree == set(), "listed in [tool.setuptools] packages but not in the tree"


def _copy_sources(dest: Path) -> Path:
    for name in BUILD_INPUTS:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(src, dest / name)
    return dest


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """(the wheel built from a copy of the sources, everything the build printed)."""
    src = _copy_sources(tmp_path_factory.mktemp("src"))
    out = tmp_path_factory.mktemp("wheel")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    cmd += ["--no-index", "--disable-pip-version-check", "-w", str(out), str(src)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    (whl,) = out.glob("cablesim-*.whl")
    return whl, r.stdout + r.stderr


def test_the_wheel_builds_without_warnings(wheel: tuple[Path, str]) -> None:
    _, log = wheel
    found = [line for line in log.splitlines() if WARNING.search(line)]
    assert not found, "\n".join(found)


def test_the_warning_pattern_catches_what_setuptools_prints() -> None:
    printed = (
        "  /x/setuptools/command/build_py.py:215: BuildBackendWarning: Package "
        "'cablesim.assets.meshes' is absent from the `packages` configuration.\n  !!\n"
    )
    assert len(WARNING.findall(printed)) == 2
    assert not WARNING.search("Successfully built cablesim\nCreated wheel for cablesim")


def test_the_wheel_holds_every_runtime_file(wheel: tuple[Path, str]) -> None:
    whl, _ = wheel
    with zipfile.ZipFile(whl) as z:
        names = set(z.namelist())
        entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
        assert "cablesim = cablesim.cli:main" in z.read(entry_points).decode()
    tree = _tree_files()
    missing = sorted(set(tree) - names)
    assert not missing, f"not in the wheel: {missing}"
    # the assets the scene loads at run time, by name
    for name in (
        "cablesim/assets/meshes/connector_male.stl",
        "cablesim/assets/textures/board_wood.png",
        "cablesim/assets/panda/parts.json",
        "cablesim/assets/panda/link0_white.stl",
        "cablesim/assets/panda/LICENSE-2.0.txt",
        "cablesim/calibration/board.py",
        "cablesim/twin/replay.py",
        "cablesim/perception/weights/learned_flow.pt",
    ):
        assert name in names
    packaged = {n for n in names if not n.startswith("cablesim-")}
    assert packaged == set(tree), (
        f"in the wheel but not in the tree: {sorted(packaged - set(tree))}"
    )


SCENE = ["scene", "--seed", "3", "--width", "160", "--height", "120", "--robot-visual", "mesh"]


@pytest.mark.slow
def test_the_installed_wheel_runs_scene_outside_the_checkout(
    wheel: tuple[Path, str], tmp_path: Path
) -> None:
    """A fresh environment with the wheel installed (its dependencies borrowed from this one,
    whose own cablesim is not visible there) writes the scene of the checkout, bit for bit."""
    whl, _ = wheel
    env_dir = tmp_path / "venv"
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True, timeout=120
    )
    python = env_dir / "bin" / "python"
    site = subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout.strip()
    # this environment's packages as plain path entries: their .pth files (the editable
    # cablesim's finder among them) are not run there
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    Path(site, "_cablesim_test_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    r = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps"]
        + ["--no-index", "--disable-pip-version-check", "-q", str(whl)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert not [line for line in (r.stdout + r.stderr).splitlines() if WARNING.search(line)]
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["CABLESIM_CACHE"] = str(tmp_path / "cache")  # settles afresh: no state of the checkout
    where = subprocess.run(
        [python, "-c", "import cablesim, cablesim.assets as a; print(cablesim.__file__, a.ROOT)"],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert where.returncode == 0, where.stderr
    assert all(Path(p).is_relative_to(env_dir) for p in where.stdout.split()), where.stdout
    run = subprocess.run(
        [env_dir / "bin" / "cablesim", *SCENE, "--out", str(work / "installed")],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    from cablesim.cli import main

    assert main([*SCENE, "--out", str(tmp_path / "checkout")]) == 0
    for name in ("rgb.png", "labels.npy", "depth.npy", "flow.npy", "rgb_moved.png"):
        a = (work / "installed" / name).read_bytes()
        assert a == (tmp_path / "checkout" / name).read_bytes(), name


def _pins(path: Path) -> dict[str, str]:
    pins = {}
    for line in path.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    return pins


def test_the_environment_is_the_one_the_results_were_pinned_in() -> None:
    """Every package this environment shares with ``scripts/constraints.txt`` has the version
    written there (``setup.sh`` installs with it): the pinned result hashes depend on them
    (OpenCV 5.1 instead of 5.0 changes PNG bytes and flow)."""
    from importlib import metadata

    pins = _pins(ROOT / "scripts" / "constraints.txt")
    assert {"numpy", "opencv-python-headless", "mujoco", "scipy"} <= set(pins)
    installed = {
        re.sub(r"[-_.]+", "-", d.metadata["Name"]).lower(): d.version
        for d in metadata.distributions()
    }
    drift = {n: (installed[n], v) for n, v in pins.items() if n in installed and installed[n] != v}
    assert not drift, (
        f"installed vs scripts/constraints.txt: {drift}; run bash scripts/setup.sh dev"
    )


def test_constraints_parse() -> None:
    assert _pins(ROOT / "scripts" / "constraints-franka-sim.txt")["franka-sim"] == "1.1.7"
