"""Every notebook in notebooks/ runs headless with small settings and draws at least one figure."""

import os
import sys
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
#: Seconds a single cell may take (the fast settings keep a whole notebook well under a minute).
CELL_TIMEOUT_S = 300


def test_notebooks_and_their_documentation_agree():
    """docs/NOTEBOOKS.md describes every notebook, and names no notebook that is not there."""
    import re

    docs = (NOTEBOOKS[0].parents[1] / "docs" / "NOTEBOOKS.md").read_text(encoding="utf-8")
    names = {p.name for p in NOTEBOOKS}
    assert names, "no notebooks"
    assert {n for n in names if n not in docs} == set()
    assert set(re.findall(r"([0-9]{2}_[a-z_]+\.ipynb)", docs)) <= names


def _exporter():
    import importlib.util

    path = NOTEBOOKS[0].parents[1] / "scripts" / "export_notebook_figures.py"
    spec = importlib.util.spec_from_file_location("export_notebook_figures", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_exported_figures_are_there_and_documented():
    """docs/figures/notebooks holds figures of every notebook, and docs/NOTEBOOKS.md links
    exactly those files."""
    import re

    root = NOTEBOOKS[0].parents[1]
    fig_root = root / "docs" / "figures" / "notebooks"
    found = {str(p.relative_to(root / "docs")) for p in fig_root.rglob("*.png")}
    for nb in NOTEBOOKS:
        assert list((fig_root / nb.stem).glob("figure_*.png")), f"no exported figure of {nb.name}"
    docs = (root / "docs" / "NOTEBOOKS.md").read_text(encoding="utf-8")
    linked = set(re.findall(r"\((figures/notebooks/[^)]+\.png)\)", docs))
    assert linked == found
    assert {p.parent.name for p in fig_root.rglob("*.png")} == {nb.stem for nb in NOTEBOOKS}


def test_export_writes_every_figure_in_order_and_drops_stale_ones(tmp_path):
    import base64

    nbformat = pytest.importorskip("nbformat")
    export = _exporter()
    pngs = [b"\x89PNG first", b"\x89PNG second"]
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("plot()")
    cell.outputs = [
        nbformat.v4.new_output("stream", name="stdout", text="hello"),
        *[
            nbformat.v4.new_output("display_data", data={"image/png": base64.b64encode(p).decode()})
            for p in pngs
        ],
    ]
    nb.cells = [nbformat.v4.new_markdown_cell("# t"), cell]
    stale = tmp_path / "demo" / "figure_03.png"
    stale.parent.mkdir()
    stale.write_bytes(b"old")
    written = export.export(nb, "demo", tmp_path)
    assert [p.name for p in written] == ["figure_01.png", "figure_02.png"]
    assert [p.read_bytes() for p in written] == pngs
    assert sorted(p.name for p in (tmp_path / "demo").iterdir()) == [
        "figure_01.png",
        "figure_02.png",
    ]


def _figures(nb) -> int:
    return sum(
        1
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") in ("display_data", "execute_result")
        and "image/png" in out.get("data", {})
    )


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs_headless(path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")

    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:  # committed with outputs cleared
        if cell.cell_type == "code":
            assert not cell.outputs, f"{path.name}: commit the notebook with outputs cleared"
    monkeypatch.setenv("NIDAR_NOTEBOOK_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    # the kernel runs this interpreter (jupyter_client maps the python3 kernel's "python" to it)
    assert Path(sys.executable).exists()
    client = nbclient.NotebookClient(
        nb,
        kernel_name="python3",
        timeout=CELL_TIMEOUT_S,
        resources={"metadata": {"path": str(path.parent)}},
    )
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.outputs
        if out.get("output_type") == "error"
    ]
    assert not errors
    assert _figures(nb) >= 1, f"{path.name} drew no figure"
    out_dir = os.environ.get("NIDAR_NOTEBOOK_OUT")
    if out_dir:  # keep the executed notebook for inspection
        os.makedirs(out_dir, exist_ok=True)
        nbformat.write(nb, os.path.join(out_dir, path.name))
