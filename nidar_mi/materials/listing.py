"""The material library as a text table and as a plot of reflectance spectra."""

from __future__ import annotations

import logging

import numpy as np

from ..io.atomic import atomic_path
from .library import get_material, list_materials, reflectance, srgb
from .spectra import GRID_NM
from .srgb import srgb_hex

__all__ = ["format_table", "plot_spectra", "list_materials"]

#: Wavelengths of the table columns and of the plot markers, nm.
TABLE_WAVELENGTHS_NM = (550.0, 905.0, 1550.0)
LIDAR_WAVELENGTHS_NM = (905.0, 1550.0)

log = logging.getLogger(__name__)


def format_table(names: list[str]) -> str:
    """Text table: name, kind, rho at 550/905/1550 nm, sRGB hex, source (one line each)."""
    width = max(len(n) for n in names)
    head = f"{'name':<{width}}  {'kind':<14}  rho550  rho905 rho1550  sRGB     source"
    lines = [head, "-" * len(head)]
    for name in names:
        m = get_material(name)
        r = reflectance(name, np.array(TABLE_WAVELENGTHS_NM))
        lines.append(
            f"{name:<{width}}  {m.kind:<14}  {r[0]:6.3f}  {r[1]:6.3f}  {r[2]:6.3f}  "
            f"{srgb_hex(srgb(name))}  {m.source}"
        )
    return "\n".join(lines) + "\n"


def plot_spectra(names: list[str], out_path: str) -> None:
    """Write a PNG of the reflectance of ``names`` from 360 to 1700 nm to ``out_path``.

    The file appears complete or not at all (written to a temporary file, then renamed).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    for name in names:
        m = get_material(name)  # fail on a bad name before drawing anything
        log.debug("%s: %s spectrum from %s", name, m.kind, m.source)
    fig = Figure(figsize=(11, 5), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for name in names:
        colour = srgb(name)
        if float(np.mean(colour)) > 0.8:  # near-white: darken so the line shows on white
            colour = 0.75 * colour
        ax.plot(GRID_NM, reflectance(name, GRID_NM), label=name, lw=1.8, color=colour)
    for wl in LIDAR_WAVELENGTHS_NM:
        ax.axvline(wl, color="k", ls="--", lw=0.9)
        ax.annotate(
            f"{wl:g} nm", (wl, 1.0), xytext=(3, -12), textcoords="offset points", fontsize=8
        )
    ax.axvspan(380, 780, color="0.93", zorder=0, label="visible (380-780 nm)")
    ax.set_xlim(GRID_NM[0], GRID_NM[-1])
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("Wavelength (nm)")
    ax.set_ylabel("Reflectance (unitless, 0-1)")
    ax.set_title("nidar_mi material spectra (conductors/glass: normal-incidence Fresnel R)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()

    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, format="png")
