"""A Griffe extension: cablesim's sub-packages that Griffe does not find by itself.

``pyproject.toml`` maps ``cablesim.envs`` to ``envs/`` and ``cablesim.policies`` to
``policies/`` (``[tool.setuptools] package-dir``), and a package such as ``cablesim.dataset``
may have no ``__init__.py``.  Griffe finds sub-packages by walking ``cablesim/`` and skips
folders without an init module, so this extension reads those packages as sub-packages of
``cablesim`` once ``cablesim`` is loaded; the API reference then documents them under their
public import paths.  The list comes from ``pyproject.toml``, so a package added there needs no
change here.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import griffe

ROOT = Path(__file__).resolve().parents[2]


def mapped_packages(root: Path = ROOT) -> dict[str, Path | list[Path]]:
    """``{name: path}`` of every ``cablesim.X`` in ``pyproject.toml`` that Griffe cannot find.

    That is a package mapped to another folder (``package-dir``) or a folder without an
    ``__init__.py`` (a namespace package, which Griffe skips inside a regular package): the
    path is the ``__init__.py`` of the first, the folder (in a list) of the second.
    """
    cfg = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    setup = cfg["tool"]["setuptools"]
    package_dir = setup.get("package-dir", {})
    out: dict[str, Path | list[Path]] = {}
    for name in setup.get("packages", []):
        head, _, sub = name.partition(".")
        if head != "cablesim" or not sub or "." in sub:
            continue
        folder = (root / package_dir.get(name, f"cablesim/{sub}")).resolve()
        init = folder / "__init__.py"
        if folder != (root / "cablesim" / sub).resolve() and init.is_file():
            out[sub] = init
        elif not init.is_file() and folder.is_dir():
            out[sub] = [folder]
    return out


class MappedPackages(griffe.Extension):
    """Attach the packages of :func:`mapped_packages` to the loaded ``cablesim`` package."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs) -> None:
        if pkg.name != "cablesim":
            return
        for sub, init in mapped_packages().items():
            if sub not in pkg.members:
                # a private loader method, pinned with griffelib in the docs extra
                module = loader._load_module(sub, init, parent=pkg)
                pkg.set_member(sub, module)
        hide_reexported_originals(pkg, loader)


def hide_reexported_originals(module: griffe.Module, loader: griffe.GriffeLoader) -> None:
    """Document a re-exported object once, at its public path.

    ``cablesim.episode`` exports ``InteractionConfig`` from ``cablesim.episode.config``; the
    API page shows it as ``cablesim.episode.InteractionConfig`` and leaves it out of the
    submodule's section (``filters: public`` in ``mkdocs.yml``), which still lists everything
    else the submodule defines.
    """
    for name, member in module.members.items():
        if member.is_alias:
            target = member.target_path
            if (
                module.exports is not None
                and name in module.exports
                and target.startswith(f"{module.path}.")
            ):
                try:
                    original = loader.modules_collection.get_member(target)
                except KeyError:
                    continue
                if not original.is_alias:
                    original.public = False
        elif member.is_module:
            hide_reexported_originals(member, loader)
