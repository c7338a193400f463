"""The visible colour of a surface's albedo, and what that colour predicts of ρ at the LiDAR line.

A camera sees ``albedo × shading``; once the shading is removed, the albedo's colour is what an
image can tell about a surface. Two pieces turn that colour into a LiDAR reflectance cue:

* :func:`srgb_weights` — ``(41, 3)`` weights (shipped in ``data/albedo_srgb_weights.csv``,
  written by :func:`write_srgb_weights`) ``W`` such that ``rho(λ_k) @ W`` is the linear
  sRGB (D65 white, unclipped) of a reflectance sampled at :data:`ALBEDO_WAVELENGTHS_NM`
  (380–780 nm every 10 nm) and read linearly between the samples, exactly as
  :func:`nidar_mi.materials.srgb.spectrum_to_linear_srgb` reads a spectrum (CIE 1931 2°, D65,
  IEC 61966-2-1): the weights are the sRGB of the 41 hat functions. A flat ρ gives (ρ, ρ, ρ)
  up to the 1 nm integration.
* :func:`colour_reflectance_map` — the least-squares linear map ``ρ(λ) ≈ c₀ + c·rgb`` from the
  linear sRGB of every spectrum in the earthlib library (7261 measured surfaces: soils,
  vegetation, built materials, minerals; :mod:`nidar_mi.materials.earthlib_data`) to its
  reflectance at the LiDAR wavelength ``λ``. It is fitted on the library, never on a scene.

Rendered frames carry the true albedo colour (``A_true``); training can supervise IRNet's R with
``colour_reflectance_map(λ)(A_true)`` — a target the image determines once shading is removed,
unlike ρ(λ) itself, which the visible image does not fix.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError

__all__ = [
    "ALBEDO_WAVELENGTHS_NM",
    "ColourReflectanceMap",
    "colour_reflectance_map",
    "compute_srgb_weights",
    "srgb_weights",
    "write_srgb_weights",
]

#: Wavelengths (nm) at which the albedo is sampled for its colour.
ALBEDO_WAVELENGTHS_NM = np.arange(380.0, 781.0, 10.0)


#: :func:`compute_srgb_weights`, as shipped (read without importing colour-science, which takes
#: seconds; ``tests/materials/test_visible_albedo.py`` checks the file against the computation).
WEIGHTS_FILE = os.path.join(os.path.dirname(__file__), "data", "albedo_srgb_weights.csv")


def compute_srgb_weights() -> np.ndarray:
    """(41, 3) float64 ``W``: linear sRGB = ``rho_k @ W`` for ρ sampled at
    :data:`ALBEDO_WAVELENGTHS_NM` (read linearly between the samples): the colour-science sRGB
    of each sample's hat function (module docstring)."""
    from .spectra import Spectrum
    from .srgb import colour_tables, spectrum_to_xyz

    colour, _, _ = colour_tables()
    wl = ALBEDO_WAVELENGTHS_NM
    step = float(wl[1] - wl[0])
    grid = np.concatenate(([wl[0] - step], wl, [wl[-1] + step]))
    rows = []
    for k in range(len(wl)):
        hat = np.zeros(len(grid))
        hat[k + 1] = 1.0
        xyz = spectrum_to_xyz(Spectrum(grid, hat))
        rows.append(colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False))
    return np.asarray(rows, dtype=np.float64)


@functools.lru_cache(maxsize=1)
def srgb_weights() -> np.ndarray:
    """(41, 3) float64: :func:`compute_srgb_weights` as shipped in :data:`WEIGHTS_FILE`.

    Raises:
        NidarError: the file is missing or not a (41, 3) table of the wavelengths.
    """
    try:
        table = np.loadtxt(WEIGHTS_FILE, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as e:
        raise NidarError(f"cannot read the albedo colour weights {WEIGHTS_FILE}: {e}") from e
    if table.shape != (len(ALBEDO_WAVELENGTHS_NM), 4) or not np.array_equal(
        table[:, 0], ALBEDO_WAVELENGTHS_NM
    ):
        raise NidarError(f"{WEIGHTS_FILE}: expected wavelength,R,G,B rows at 380-780 nm")
    return table[:, 1:]


def write_srgb_weights(path: str = WEIGHTS_FILE) -> None:
    """Write :func:`compute_srgb_weights` as ``wavelength_nm,R,G,B`` rows (full precision)."""
    w = compute_srgb_weights()
    lines = ["wavelength_nm,R,G,B"] + [
        f"{x:g}," + ",".join(repr(float(v)) for v in row)
        for x, row in zip(ALBEDO_WAVELENGTHS_NM, w)
    ]
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


@dataclass(frozen=True)
class ColourReflectanceMap:
    """``ρ(λ) ≈ intercept + coefficients · rgb``, clipped to [0, 1].

    Attributes:
        wavelength_nm: the LiDAR wavelength λ the map predicts.
        intercept: c₀.
        coefficients: (3,) c for linear sRGB (R, G, B) in [0, 1].
        spearman: rank correlation of the prediction with ρ(λ) over the library it was fitted on.
        spectra: how many library spectra it was fitted on.
    """

    wavelength_nm: float
    intercept: float
    coefficients: tuple[float, float, float]
    spearman: float
    spectra: int

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) linear sRGB albedo -> (...) float32 predicted ρ(λ) in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        if rgb.shape[-1:] != (3,):
            raise NidarError(f"`rgb` must end in 3 colour channels, got shape {rgb.shape}")
        rho = self.intercept + rgb @ np.asarray(self.coefficients)
        return np.clip(rho, 0.0, 1.0).astype(np.float32)


@functools.lru_cache(maxsize=8)
def colour_reflectance_map(wavelength_nm: float = 905.0) -> ColourReflectanceMap:
    """The linear albedo-colour -> ρ(λ) map fitted on the earthlib library (module docstring).

    Args:
        wavelength_nm: LiDAR wavelength in nm, within the library's 400–1700 nm.

    Raises:
        NidarError: ``wavelength_nm`` outside the library, or earthlib not installed.
    """
    from scipy.stats import spearmanr

    from .earthlib_data import extend_below, load_earthlib

    wavelength_nm = float(wavelength_nm)
    if not 400.0 <= wavelength_nm <= 1700.0:
        raise NidarError(f"`wavelength_nm` must lie in [400, 1700] nm, got {wavelength_nm:g}")
    lib = load_earthlib()
    grid = np.append(ALBEDO_WAVELENGTHS_NM, wavelength_nm)
    rows = []
    for row in lib.data.astype(np.float64):
        ok = np.isfinite(row)
        rows.append(np.clip(extend_below(lib.wavelengths_nm[ok], row[ok], grid), 0.0, 1.0))
    values = np.asarray(rows)
    rgb = np.clip(values[:, :-1] @ srgb_weights(), 0.0, 1.0)
    target = values[:, -1]
    design = np.column_stack((np.ones(len(rgb)), rgb))
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    fitted = ColourReflectanceMap(
        wavelength_nm, float(coef[0]), tuple(map(float, coef[1:])), 0.0, len(rgb)
    )
    rho = float(spearmanr(fitted(rgb), target).statistic)
    return ColourReflectanceMap(wavelength_nm, fitted.intercept, fitted.coefficients, rho, len(rgb))
