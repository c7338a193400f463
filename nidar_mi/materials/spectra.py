"""Sampled spectra: the :class:`Spectrum` type, the library's wavelength grid and model shapes.

Every material spectrum is stored on :data:`GRID_NM` (360-1700 nm every 10 nm), which covers the
visible range used for sRGB and the 905 / 1550 nm LiDAR bands. Between samples spectra are
linear (the same convention Mitsuba's ``irregular`` spectrum uses), so a lookup in Python and in
a render agree exactly.

The shape helpers (:func:`flat`, :func:`logistic`, :func:`absorption_band`) build the modelled
spectra of materials no measurement in the library covers; each material cites what its shape
stands for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import NidarError

__all__ = [
    "GRID_NM",
    "WL_MIN_NM",
    "WL_MAX_NM",
    "Spectrum",
    "check_wavelengths",
    "flat",
    "logistic",
    "absorption_band",
]

WL_MIN_NM = 360.0
WL_MAX_NM = 1700.0
#: The library's wavelength grid, nm: 360, 370, ..., 1700 (135 samples).
GRID_NM = np.arange(WL_MIN_NM, WL_MAX_NM + 1.0, 10.0)


def check_wavelengths(wavelengths_nm, lo: float = WL_MIN_NM, hi: float = WL_MAX_NM) -> np.ndarray:
    """``wavelengths_nm`` as a float array, checked to lie in ``[lo, hi]`` nm.

    Raises:
        NidarError: a wavelength is not finite or lies outside the range.
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if np.any(~np.isfinite(wl)) or np.any(wl < lo - 1e-9) or np.any(wl > hi + 1e-9):
        raise NidarError(f"wavelength outside {lo:g}-{hi:g} nm: {np.atleast_1d(wl).tolist()[:8]}")
    return wl


@dataclass(frozen=True, eq=False)
class Spectrum:
    """A piecewise-linear spectrum sampled at increasing wavelengths.

    Attributes:
        wavelengths_nm: (N,) increasing wavelengths, nm.
        values: (N,) values at those wavelengths (reflectance, refractive index, ...).
    """

    wavelengths_nm: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        wl = np.asarray(self.wavelengths_nm, dtype=np.float64)
        v = np.asarray(self.values, dtype=np.float64)
        if wl.ndim != 1 or wl.shape != v.shape or wl.size < 2:
            raise ValueError(
                f"spectrum needs matching 1-D arrays of >= 2 samples, got {wl.shape}, {v.shape}"
            )
        if np.any(np.diff(wl) <= 0):
            raise ValueError("spectrum wavelengths must be strictly increasing")
        if not np.all(np.isfinite(v)):
            raise ValueError("spectrum values must be finite")
        wl.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "wavelengths_nm", wl)
        object.__setattr__(self, "values", v)

    def __call__(self, wavelengths_nm: np.ndarray | float) -> np.ndarray:
        """Linear interpolation at ``wavelengths_nm`` (any shape, nm).

        Raises:
            NidarError: a wavelength lies outside the sampled range.
        """
        wl = check_wavelengths(wavelengths_nm, self.wavelengths_nm[0], self.wavelengths_nm[-1])
        return np.interp(wl, self.wavelengths_nm, self.values)

    def resample(self, grid_nm: np.ndarray = GRID_NM) -> Spectrum:
        """This spectrum linearly interpolated onto ``grid_nm`` (must lie within its range)."""
        return Spectrum(grid_nm, self(grid_nm))

    def map(self, fn) -> Spectrum:
        """A spectrum on the same wavelengths with values ``fn(values)``."""
        return Spectrum(self.wavelengths_nm, fn(self.values))

    def clip(self, lo: float = 0.0, hi: float = 1.0) -> Spectrum:
        """Values clipped to ``[lo, hi]``."""
        return self.map(lambda v: np.clip(v, lo, hi))

    def mitsuba_dict(self) -> dict:
        """Mitsuba ``irregular`` spectrum dict (``mi.load_dict`` form)."""
        return {
            "type": "irregular",
            "wavelengths": ", ".join(f"{w:g}" for w in self.wavelengths_nm),
            "values": ", ".join(f"{v:.6g}" for v in self.values),
        }

    def xml_value(self) -> str:
        """The ``value`` attribute of an XML ``<spectrum>``: ``"wl:v, wl:v, ..."``."""
        return ", ".join(f"{w:g}:{v:.6g}" for w, v in zip(self.wavelengths_nm, self.values))

    @staticmethod
    def parse_xml_value(text: str) -> Spectrum:
        """Inverse of :meth:`xml_value` (``"wl:v, ..."``, wavelengths in nm).

        Raises:
            ValueError: the text is not a list of ``wavelength:value`` pairs.
        """
        pairs = [p.strip() for p in text.replace("\n", " ").split(",") if p.strip()]
        wl, v = [], []
        for p in pairs:
            a, sep, b = p.partition(":")
            if not sep:
                raise ValueError(f"not a 'wavelength:value' pair: {p!r}")
            wl.append(float(a))
            v.append(float(b))
        order = np.argsort(wl)
        return Spectrum(np.asarray(wl)[order], np.asarray(v)[order])


def flat(value: float, grid_nm: np.ndarray = GRID_NM) -> Spectrum:
    """A constant spectrum on ``grid_nm``."""
    return Spectrum(grid_nm, np.full(grid_nm.shape, float(value)))


def logistic(
    low: float, high: float, center_nm: float, width_nm: float, grid_nm: np.ndarray = GRID_NM
) -> Spectrum:
    """A smooth step from ``low`` (short wavelengths) to ``high`` (long), as an absorption edge.

    ``value = low + (high - low) / (1 + exp(-(wl - center) / width))``.
    """
    x = (grid_nm - center_nm) / width_nm
    return Spectrum(grid_nm, low + (high - low) / (1.0 + np.exp(-x)))


def absorption_band(base: Spectrum, center_nm: float, fwhm_nm: float, depth: float) -> Spectrum:
    """``base`` multiplied by ``1 - depth * gaussian`` (a band of relative ``depth`` at its centre).

    Args:
        base: spectrum to modulate.
        center_nm: band centre, nm.
        fwhm_nm: full width at half maximum, nm.
        depth: relative depth at the centre, in [0, 1].
    """
    sigma = fwhm_nm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
    g = np.exp(-0.5 * ((base.wavelengths_nm - center_nm) / sigma) ** 2)
    return base.map(lambda v: v * (1.0 - depth * g))
