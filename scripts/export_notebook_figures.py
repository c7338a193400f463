"""Run the notebooks headless and export their figures to docs/figures/notebooks/.

    .venv/bin/python scripts/export_notebook_figures.py [--fast] [NOTEBOOK ...]

Every notebook in ``notebooks/`` (or the ones named) is executed with nbclient on the
``python3`` kernel of this interpreter, as ``tests/test_notebooks.py`` does, and each PNG figure
it displays is written to ``docs/figures/notebooks/<notebook stem>/figure_<NN>.png`` (NN counts
the notebook's figures from 01); figures of an earlier export that the notebook no longer draws
are removed. The notebooks stay committed without outputs. ``--fast`` uses the notebooks' small
settings (``NIDAR_NOTEBOOK_FAST=1``); the committed figures are the full settings.

No exported figure may derive from the non-commercial datasets (KITTI, nuScenes, the EPFL
photos): the notebooks run with ``NIDAR_MI_DATA`` pointing at a folder that does not exist, so
a notebook that compares with real sweeps (``05_ground_coverage``) draws its simulated half only.
"""

from __future__ import annotations

import argparse
import base64
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "docs" / "figures" / "notebooks"
CELL_TIMEOUT_S = 1800
#: Where the notebooks look for KITTI while exporting: nowhere (no figure of restricted data).
NO_DATA = "/nonexistent/restricted-data-is-not-exported"


def figures(nb) -> list[bytes]:
    """The PNG figures a notebook's outputs display, in order."""
    return [
        base64.b64decode(out["data"]["image/png"])
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") in ("display_data", "execute_result")
        and "image/png" in out.get("data", {})
    ]


def execute(path: Path, *, fast: bool):
    """The notebook at ``path``, executed (outputs filled in)."""
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    env = {"MPLBACKEND": "module://matplotlib_inline.backend_inline"}
    env["NIDAR_NOTEBOOK_FAST"] = "1" if fast else ""
    env["NIDAR_MI_DATA"] = NO_DATA
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        client = nbclient.NotebookClient(
            nb,
            kernel_name="python3",
            timeout=CELL_TIMEOUT_S,
            resources={"metadata": {"path": str(path.parent)}},
        )
        client.execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def export(nb, name: str, out_dir: Path = OUT) -> list[Path]:
    """Write the figures of an executed notebook to ``out_dir/<name>/figure_NN.png``."""
    from nidar_mi.io.atomic import atomic_path

    folder = out_dir / name
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for k, png in enumerate(figures(nb), start=1):
        path = folder / f"figure_{k:02d}.png"
        with atomic_path(path) as tmp:
            tmp.write_bytes(png)
        written.append(path)
    for stale in sorted(set(folder.glob("figure_*.png")) - set(written)):
        stale.unlink()
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("notebooks", nargs="*", help="notebooks to run (default: all in notebooks/)")
    p.add_argument("--fast", action="store_true", help="the notebooks' small settings")
    args = p.parse_args(argv)
    paths = [Path(n) for n in args.notebooks] or sorted((REPO / "notebooks").glob("*.ipynb"))
    for path in paths:
        t0 = time.perf_counter()
        written = export(execute(path, fast=args.fast), path.stem)
        rel = [str(w.relative_to(REPO)) for w in written]
        print(f"{path.name}: {len(rel)} figures in {time.perf_counter() - t0:.0f} s: {rel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
