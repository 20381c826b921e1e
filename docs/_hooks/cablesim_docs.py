"""MkDocs hooks of cablesim's docs site: pages generated from the repository at build time.

- ``notebooks/*.ipynb`` become ``notebooks/<name>.md`` with their stored outputs (text and PNG
  images); nothing is executed.
- ``benchmarks/results/**`` (markdown tables and plots) become ``results/...`` pages, and
  ``results/index.md`` lists them by title: the numbers on the site are the committed results
  files, never copies.
- A line ``<!-- results: FILE.md#Heading -->`` in a page is replaced by that section of
  ``benchmarks/results/FILE.md`` (everything under the first heading that starts with
  ``Heading``, up to the next heading of the same or a higher level).  Options after the
  heading, each after a ``|``: ``table: N`` keeps only the section's N-th table, and
  ``rows: A; B`` keeps of each table its header and the rows whose first cell starts with
  ``A`` or ``B``.  An
  unknown file, heading or option, a missing table or a row filter that keeps no row fails the
  build.
- Sphinx roles in docstrings (``:class:`x```, ``:func:`~a.b```) are shown as code in the API
  pages, and the ``::`` that introduces a reStructuredText literal block as ``:``.
- A page the navigation names that another part of the project writes and that is not in
  ``docs/`` yet (``PENDING_PAGES``) is generated as a short note, so the site builds while
  those pages are on their way.

Pure standard library plus MkDocs; used by ``mkdocs.yml`` (``hooks:``) and nothing else.
"""

from __future__ import annotations

import base64
import json
import logging
import posixpath
import re
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.cablesim_docs")

RESULTS = Path("benchmarks") / "results"
NOTEBOOKS = Path("notebooks")
PENDING_PAGES = {
    "outcomes.md": "One interaction's outcomes",
    "plugins.md": "Plug in your own flow back end or method",
    "configuration.md": "Configuration",
}
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
_RESULTS_DIRECTIVE = re.compile(
    r"^<!--\s*results:\s*(?P<file>[^#\s]+)#(?P<heading>[^|]+?)\s*(?P<options>\|.*?)?-->\s*$",
    re.M,
)
_ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|exc|obj|const):(<code>)~?")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


def _root(config) -> Path:
    return Path(config["config_file_path"]).resolve().parent


def _add(files: Files, config, src_uri: str, **kw) -> None:
    if files.get_file_from_path(src_uri) is None:
        files.append(File.generated(config, src_uri, **kw))


def on_files(files: Files, config) -> Files:
    root = _root(config)
    for nb in sorted((root / NOTEBOOKS).glob("*.ipynb")):
        for src_uri, content in notebook_pages(nb):
            _add(files, config, src_uri, content=content)
    results = root / RESULTS
    index = []
    for path in sorted(results.rglob("*")):
        rel = path.relative_to(results).as_posix()
        if path.suffix == ".md":
            _add(files, config, f"results/{rel}", abs_src_path=str(path))
            index.append((rel, _title(path)))
        elif path.suffix in (".png", ".svg"):
            _add(files, config, f"results/{rel}", abs_src_path=str(path))
    _add(files, config, "results/index.md", content=results_index(index))
    for name, title in PENDING_PAGES.items():
        if files.get_file_from_path(name) is None:
            log.info("docs/%s is not written yet: a note stands in for it", name)
            _add(files, config, name, content=f"# {title}\n\nThis page is being written.\n")
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    root = _root(config)

    def include(m: re.Match) -> str:
        where = f"{page.file.src_uri}: {m['file']}#{m['heading'].strip()}"
        text = results_section(root / RESULTS / m["file"], m["heading"].strip(), where)
        text = relink(text, f"results/{m['file']}", page.file.src_uri)
        for option in (m["options"] or "").split("|")[1:]:
            name, _, value = option.partition(":")
            if name.strip() == "table":
                text = nth_table(text, int(value), where)
            elif name.strip() == "rows":
                keep = [r.strip() for r in value.split(";") if r.strip()]
                text = filter_rows(text, keep, where)
            else:
                raise PluginError(f"{where}: unknown option {option.strip()!r} (table, rows)")
        return text

    return _RESULTS_DIRECTIVE.sub(include, markdown)


def on_page_content(html: str, page, config, files) -> str:
    if page.file.src_uri.startswith("api/"):
        html = _ROLE.sub(r"\1", html)
        # reStructuredText's "text::" before a literal block: Markdown shows the block already
        html = html.replace("::</p>", ":</p>")
    return html


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        m = _HEADING.match(line)
        if m and len(m[1]) == 1:
            return m[2].replace("`", "")
    return path.stem


def results_index(entries: list[tuple[str, str]]) -> str:
    """The ``results/index.md`` page: every results file by title, linked."""
    lines = [
        "# Results",
        "",
        "Every benchmark writes its results, with the machine and the date, to",
        "`benchmarks/results/` in the repository (see [Benchmarks](../benchmarks.md) for the",
        "commands). These pages are those files, included when the site is built.",
        "",
        "| results file | what it measures |",
        "|---|---|",
    ]
    for rel, title in entries:
        lines.append(f"| [`{rel}`]({rel}) | {title} |")
    return "\n".join(lines) + "\n"


def results_section(path: Path, heading: str, where: str) -> str:
    """The section of a results file under ``heading`` (its first line), heading included."""
    if not path.is_file():
        raise PluginError(f"{where}: results file {path} does not exist")
    lines = path.read_text(encoding="utf-8").splitlines()
    start = level = None
    for i, line in enumerate(lines):
        m = _HEADING.match(line)
        if not m:
            continue
        if start is None and m[2].replace("`", "").startswith(heading.replace("`", "")):
            start, level = i, len(m[1])
        elif start is not None and len(m[1]) <= level:
            return _section_text(lines[start], lines[start + 1 : i], path)
    if start is None:
        raise PluginError(f"{where}: no heading starting with {heading!r} in {path}")
    return _section_text(lines[start], lines[start + 1 :], path)


_LINK = re.compile(r"(\]\()(?P<target>[^)#\s:]+)(?=[)#\s])")


def relink(text: str, source_uri: str, page_uri: str) -> str:
    """Relative links of an included results section, made relative to the including page."""
    src_dir = posixpath.dirname(source_uri)
    page_dir = posixpath.dirname(page_uri) or "."

    def fix(m: re.Match) -> str:
        target = posixpath.normpath(posixpath.join(src_dir, m["target"]))
        return m[1] + posixpath.relpath(target, page_dir)

    return _LINK.sub(fix, text)


def nth_table(text: str, n: int, where: str) -> str:
    """Only the n-th table (from 1) of a section, with the section's source line."""
    tables: list[list[str]] = []
    previous = False
    for line in text.splitlines():
        is_row = line.startswith("|")
        if is_row and not previous:
            tables.append([])
        if is_row:
            tables[-1].append(line)
        previous = is_row
    if not 1 <= n <= len(tables):
        raise PluginError(f"{where}: no table {n} (the section has {len(tables)})")
    source = text.rstrip().splitlines()[-1]
    return "\n".join(tables[n - 1]) + f"\n\n{source}\n"


def filter_rows(text: str, keep: list[str], where: str) -> str:
    """Keep each table's header and separator and the rows whose first cell starts with a key."""
    out, kept, in_table = [], 0, 0
    for line in text.splitlines():
        if line.startswith("|"):
            in_table += 1
            first = line.strip("|").split("|", 1)[0].strip()
            if in_table <= 2 or any(first.startswith(k) for k in keep):
                out.append(line)
                kept += in_table > 2
            continue
        in_table = 0
        out.append(line)
    if not kept:
        raise PluginError(f"{where}: no table row starts with any of {keep}")
    return "\n".join(out) + "\n"


def _section_text(heading: str, lines: list[str], path: Path) -> str:
    """The section as it is included: its heading as a caption, its body, where it is from."""
    body = "\n".join(lines).strip("\n")
    # sub-headings of the included section would otherwise join the page's table of contents
    body = re.sub(r"^#{1,6}\s+(.*)$", r"**\1**", body, flags=re.M)
    caption = _HEADING.match(heading)[2]
    name = path.name
    return f"**{caption}**\n\n{body}\n\n*From [`{_results_uri(path)}`]({name}).*\n"


def _results_uri(path: Path) -> str:
    """``benchmarks/results/...`` of a results file, or its name elsewhere."""
    parts = path.parts
    at = [k for k in range(len(parts) - 1) if parts[k : k + 2] == ("benchmarks", "results")]
    return "/".join(parts[at[-1] :]) if at else path.name


def notebook_pages(path: Path) -> list[tuple[str, str | bytes]]:
    """A notebook as a Markdown page with its stored outputs, plus its images as files."""
    nb = json.loads(path.read_text(encoding="utf-8"))
    stem = path.stem
    out: list[tuple[str, str | bytes]] = []
    note = (
        f'!!! note "`notebooks/{path.name}`"\n'
        "    Executed and committed with its outputs; this page shows them as stored (nothing runs\n"
        "    when the site is built). Open the notebook in Jupyter to run it; `tests/test_notebook.py`\n"
        "    runs it with `CABLESIM_NB_SMALL=1`.\n"
    )
    parts: list[str] = []
    for i, cell in enumerate(nb.get("cells", [])):
        source = "".join(cell.get("source", ""))
        if cell.get("cell_type") == "markdown":
            parts.append(source)
        elif cell.get("cell_type") == "code":
            if source.strip():
                parts.append(f"```python\n{source}\n```")
            for j, output in enumerate(cell.get("outputs", [])):
                parts.extend(_output(output, f"{stem}_{i}_{j}", out, stem))
    # the note goes under the page's title (the first heading of the first markdown cell)
    first = parts[0].split("\n", 1) if parts and parts[0].startswith("# ") else None
    if first:
        parts[0:1] = [first[0], note, first[1] if len(first) > 1 else ""]
    else:
        parts.insert(0, note)
    page = "\n\n".join(p.strip("\n") for p in parts if p.strip()) + "\n"
    return [(f"notebooks/{stem}.md", page), *out]


def _output(output: dict, name: str, files: list, stem: str) -> list[str]:
    kind = output.get("output_type")
    if kind == "stream":
        return [_text_block("".join(output.get("text", "")))]
    if kind == "error":
        return [_text_block("\n".join(output.get("traceback", [])))]
    data = output.get("data", {})
    if "image/png" in data:
        png = data["image/png"]
        png = "".join(png) if isinstance(png, list) else png
        files.append((f"notebooks/{name}.png", base64.b64decode(png)))
        return [f"![output of {stem}]({name}.png)"]
    if "text/markdown" in data:
        return ["".join(data["text/markdown"])]
    if "text/plain" in data:
        return [_text_block("".join(data["text/plain"]))]
    return []


def _text_block(text: str) -> str:
    # a progress bar rewrites its line with carriage returns: keep what it showed last
    lines = [line.rsplit("\r", 1)[-1] for line in _ANSI.sub("", text).split("\n")]
    text = "\n".join(lines).rstrip()
    return f"```text\n{text}\n```" if text else ""
