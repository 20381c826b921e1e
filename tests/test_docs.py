"""The docs site builds strictly and offline, and shows what the repository holds.

``mkdocs build --strict`` (warnings are errors: a broken link, a docstring mkdocstrings cannot
render, a missing page) runs once into a temporary folder; the tests then read the built
pages.  The hooks that generate pages at build time (``docs/_hooks/cablesim_docs.py``) are also
tested on their own.
"""

from __future__ import annotations

import base64
import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs", reason="the docs extra (in dev) is not installed")
pytest.importorskip("mkdocstrings_handlers.python", reason="the docs extra is not installed")

from mkdocs.exceptions import PluginError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _hooks():
    spec = importlib.util.spec_from_file_location(
        "cablesim_docs_hooks", ROOT / "docs" / "_hooks" / "cablesim_docs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _hooks()


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-8000:]
    return out


def _page(site: Path, path: str) -> str:
    return (site / path / "index.html").read_text(encoding="utf-8")


def test_config_builds_strictly_and_offline() -> None:
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert re.search(r"^strict: true$", text, re.M)
    assert re.search(r"^\s+font: false\b", text, re.M), "web fonts would be fetched"


def test_site_has_every_guide_page_and_no_web_assets(site: Path) -> None:
    for page in ("getting-started", "scene", "interaction", "perception", "exploration", "thesis"):
        assert "<h1" in _page(site, page), page
    for page in ("envs", "real-robot", "twin", "benchmarks", "layout", "cluster_plan"):
        assert "<h1" in _page(site, page), page
    # nothing the browser would fetch from the network: no fonts, scripts or styles from a CDN
    remote = re.compile(r"""<(?:link|script|img)[^>]+(?:href|src)=["']https?://""")
    for html in site.rglob("*.html"):
        assert not remote.search(html.read_text(encoding="utf-8")), html


def test_api_reference_documents_the_public_packages(site: Path) -> None:
    perception = _page(site, "api/perception")
    assert 'id="cablesim.perception.FlowEstimator"' in perception
    assert "compute" in perception
    envs = _page(site, "api/envs")  # envs/ is cablesim.envs through package-dir
    assert 'id="cablesim.envs.HoseExploreEnv"' in envs
    assert 'id="cablesim.policies.ExploreConfig"' in _page(site, "api/policies")
    episode = _page(site, "api/episode")
    # a re-exported class is documented once, at the package's public path
    assert 'id="cablesim.episode.InteractionConfig"' in episode
    assert 'id="cablesim.episode.config.InteractionConfig"' not in episode
    assert 'id="cablesim.sim.world.World"' in _page(site, "api/sim")
    assert 'id="cablesim.dataset.randomize"' in _page(site, "api/thesis")  # no __init__.py
    # Sphinx roles are shown as code, not as ":class:"
    for page in site.joinpath("api").rglob("*.html"):
        assert ":class:<code>" not in page.read_text(encoding="utf-8"), page


def test_results_pages_are_the_committed_results_files(site: Path) -> None:
    index = _page(site, "results")
    files = sorted(p.relative_to(RESULTS).as_posix() for p in RESULTS.rglob("*.md"))
    assert files
    for rel in files:
        assert f'href="{rel[:-3]}/"' in index, rel
        assert (site / "results" / rel[:-3] / "index.html").is_file(), rel
    # a number on a guide page comes from the results file it names
    summary = hooks.results_section(RESULTS / "seeds.md", "Summary", "test")
    seeds_line = next(line for line in summary.splitlines() if "gave a successful" in line)
    number = re.search(r"\*\*(\d+ of \d+)", seeds_line)[1]
    assert number in _page(site, "interaction")
    # the thesis report's plots come along
    assert (site / "results" / "thesis" / "pr_curves.png").is_file()


def test_notebook_pages_show_the_stored_outputs(site: Path) -> None:
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        html = _page(site, f"notebooks/{nb.stem}")
        cells = json.loads(nb.read_text(encoding="utf-8"))["cells"]
        pngs = sum("image/png" in o.get("data", {}) for c in cells for o in c.get("outputs", []))
        shown = re.findall(rf'<img[^>]+src="\.\./({nb.stem}_\d+_\d+\.png)"', html)
        assert len(shown) == pngs > 0, nb.name
        for name in shown:
            assert (site / "notebooks" / name).is_file(), name


def test_front_page_screenshot_is_shown(site: Path) -> None:
    assert (ROOT / "docs" / "img" / "site_front.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "site_front.png" in _page(site, "getting-started")


def test_results_section_includes_one_section_and_fails_on_unknown(tmp_path: Path) -> None:
    f = tmp_path / "r.md"
    f.write_text(
        "# Title\n\nintro\n\n## Alpha one\n\n| a | b |\n|---|---|\n| x | 1 |\n| y | 2 |\n\n"
        "### Sub\n\ntext\n\n## Beta\n\nother\n",
        encoding="utf-8",
    )
    text = hooks.results_section(f, "Alpha", "page.md")
    assert text.startswith("**Alpha one**")
    assert "| y | 2 |" in text and "**Sub**" in text and "other" not in text
    assert "| y |" not in hooks.filter_rows(text, ["x"], "page.md")
    assert "| x | 1 |" in hooks.filter_rows(text, ["x"], "page.md")
    with pytest.raises(PluginError, match="no heading"):
        hooks.results_section(f, "Gamma", "page.md")
    with pytest.raises(PluginError, match="does not exist"):
        hooks.results_section(tmp_path / "missing.md", "Alpha", "page.md")
    with pytest.raises(PluginError, match="no table row"):
        hooks.filter_rows(text, ["z"], "page.md")
    with pytest.raises(PluginError, match="no table 2"):
        hooks.nth_table(text, 2, "page.md")


def test_relink_makes_included_links_relative_to_the_page() -> None:
    text = "![p](clip.png) [w](https://x.org/a) [s](#here)"
    out = hooks.relink(text, "results/thesis/report.md", "thesis.md")
    assert out == "![p](results/thesis/clip.png) [w](https://x.org/a) [s](#here)"
    assert hooks.relink("[e](../env.md)", "results/thesis/report.md", "api/x.md") == (
        "[e](../results/env.md)"
    )


def test_notebook_page_converts_cells_and_outputs(tmp_path: Path) -> None:
    png = b"\x89PNG\r\n\x1a\nfake"
    nb = {
        "cells": [
            {"cell_type": "markdown", "source": ["# A title\n", "words"]},
            {
                "cell_type": "code",
                "source": ["print(1)"],
                "outputs": [
                    {"output_type": "stream", "text": ["10%\r50%\r100%\n", "\x1b[1mdone\x1b[0m\n"]},
                    {
                        "output_type": "display_data",
                        "data": {"image/png": base64.b64encode(png).decode(), "text/plain": "x"},
                    },
                ],
            },
        ]
    }
    path = tmp_path / "demo.ipynb"
    path.write_text(json.dumps(nb), encoding="utf-8")
    (uri, page), (img_uri, img) = hooks.notebook_pages(path)
    assert uri == "notebooks/demo.md" and img_uri == "notebooks/demo_1_1.png" and img == png
    assert page.startswith("# A title\n\n!!! note")
    assert "```python\nprint(1)\n```" in page
    assert "```text\n100%\ndone\n```" in page  # the bar's last state, no escape codes
    assert "![output of demo](demo_1_1.png)" in page
