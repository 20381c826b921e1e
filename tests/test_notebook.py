"""The executed notebooks run top to bottom on a tiny configuration (CABLESIM_NB_SMALL=1)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import nbformat
import pytest
from jupyter_client.kernelspec import KernelSpecManager
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
#: notebook -> strings its outputs must contain
EXPECTED = {
    "01_prototyping.ipynb": ("correlation", "interaction ok"),
    "02_sequences.ipynb": ("layouts: cablesim-recording / mcor", "published", "[segment] union"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_notebook_executes(name, monkeypatch):
    # the "python3" kernel spec of this environment's ipykernel; jupyter_client replaces its
    # "python" with sys.executable, so the kernel is this interpreter (the venv's)
    spec = KernelSpecManager().get_kernel_spec("python3")
    assert spec.argv[0] in ("python", "python3", sys.executable), spec.argv
    monkeypatch.setenv("CABLESIM_NB_SMALL", "1")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    client = NotebookClient(
        nb, kernel_name="python3", timeout=300, resources={"metadata": {"path": str(NOTEBOOKS)}}
    )
    client.execute(env=dict(os.environ))
    text = "".join(
        o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
    )
    assert f"python: {sys.executable}" in text
    for expected in EXPECTED[name]:
        assert expected in text, expected
    images = [
        o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if "data" in o
    ]
    assert any("image/png" in o["data"] for o in images)
