"""Measured reflectance spectra from the installed ``earthlib`` package (MIT licence).

earthlib ships 7261 spectra (ENVI spectral library ``data/spectra.sli`` with its ``.hdr`` and a
metadata table ``data/spectra.csv``, row-aligned) sampled every 10 nm from 400 to 2450 nm, with
the water-vapour bands 1350-1460 nm and 1790-1960 nm removed. The full library is read at run
time with numpy (the package's own import loads both of its libraries and pulls in pandas), from
the optional ``earthlib`` extra (``pip install 'nidar_mi[earthlib]'``): ``scenegen --spectra
earthlib`` and the colour -> ρ map of :mod:`.visible_albedo` need it. The 19 spectra the
material catalogue names ship with the package (``data/earthlib_catalog.json``, the library's
float32 values and metadata, written by ``scripts/extract_earthlib_spectra.py``), so rendering
needs no earthlib: :func:`earthlib_spectrum` and :func:`earthlib_notes` read a spectrum from
there when it holds it.

A spectrum is named by its metadata levels and name, ``(LEVEL_2, LEVEL_3, NAME)``, e.g.
``("built", "road", "rpaeye.006-")``; provenance strings read ``earthlib:built/road/rpaeye.006-``.

:func:`earthlib_spectrum` puts a spectrum on the library grid (360-1700 nm, 10 nm):

* 400-1700 nm: the measured values (the grids coincide), linearly interpolated across the removed
  1350-1460 nm water band (12 grid points);
* 360-390 nm, below the measurement: extended linearly with the least-squares slope of the
  400-440 nm samples, but never above the 400 nm value and never below half of it. Near-UV
  absorption edges (pigments, TiO2, lignin, chlorophyll, asphalt binder) make surfaces darker below
  400 nm, hardly ever brighter; the floor bounds the extrapolation over the 40 nm it spans. These
  four samples only touch the sRGB colour (weight of 360-400 nm in the CIE 1931 CMFs < 0.1 %);
* everything clipped to [0, 1].
"""

from __future__ import annotations

import csv
import functools
import importlib.util
import json
import os
import re
from dataclasses import dataclass
from importlib import resources

import numpy as np

from ..errors import NidarError
from ..extras import missing_extra
from .spectra import GRID_NM, Spectrum

__all__ = [
    "EARTHLIB_LICENSE",
    "EarthlibLibrary",
    "earthlib_dir",
    "load_earthlib",
    "catalog_library",
    "earthlib_spectrum",
    "earthlib_row_spectrum",
    "earthlib_notes",
    "extend_below",
]

EARTHLIB_LICENSE = "MIT (earthlib, https://github.com/earth-chris/earthlib)"

#: Measured range of earthlib spectra, nm.
_MEASURED_MIN_NM = 400.0
#: Samples used for the slope of the extension below 400 nm.
_SLOPE_FIT_MAX_NM = 440.0


@dataclass(frozen=True)
class EarthlibLibrary:
    """earthlib's full spectral library.

    Attributes:
        wavelengths_nm: (B,) band centres, nm (400-2450 without the water bands).
        data: (S, B) reflectance, float32.
        level_2, level_3, level_4, names, sources, notes: (S,) metadata columns ``LEVEL_2``,
            ``LEVEL_3``, ``LEVEL_4``, ``NAME``, ``SOURCE``, ``NOTES`` as strings.
    """

    wavelengths_nm: np.ndarray
    data: np.ndarray
    level_2: tuple[str, ...]
    level_3: tuple[str, ...]
    level_4: tuple[str, ...]
    names: tuple[str, ...]
    sources: tuple[str, ...]
    notes: tuple[str, ...]

    def index(self, level_2: str, level_3: str, name: str) -> int:
        """Row of the unique spectrum with these metadata values.

        Raises:
            NidarError: no such spectrum, or several.
        """
        rows = [
            i
            for i, (a, b, c) in enumerate(zip(self.level_2, self.level_3, self.names))
            if a == level_2 and b == level_3 and c == name
        ]
        if len(rows) != 1:
            what = "no" if not rows else f"{len(rows)}"
            raise NidarError(f"earthlib has {what} spectrum {level_2}/{level_3}/{name}")
        return rows[0]


def earthlib_dir() -> str:
    """Folder of the installed earthlib package's data files (without importing earthlib).

    Raises:
        NidarError: earthlib is not installed.
    """
    spec = importlib.util.find_spec("earthlib")
    if spec is None or not spec.submodule_search_locations:
        raise NidarError(missing_extra("earthlib", "the full earthlib spectral library"))
    return os.path.join(list(spec.submodule_search_locations)[0], "data")


def _header_field(header: str, key: str) -> str:
    m = re.search(rf"^{re.escape(key)}\s*=\s*(\{{[^}}]*\}}|[^\n]*)", header, flags=re.M)
    if m is None:
        raise NidarError(f"earthlib header lacks '{key}'")
    return m.group(1).strip().strip("{}").strip()


@functools.lru_cache(maxsize=1)
def load_earthlib(data_dir: str | None = None) -> EarthlibLibrary:
    """Read earthlib's ``spectra.sli`` (+ ``.hdr``) and ``spectra.csv``.

    Args:
        data_dir: folder holding the files; None uses the installed package.

    Raises:
        NidarError: the files are missing or inconsistent.
    """
    data_dir = data_dir or earthlib_dir()
    sli = os.path.join(data_dir, "spectra.sli")
    try:
        with open(sli + ".hdr", encoding="utf-8") as f:
            header = f.read()
        samples = int(_header_field(header, "samples"))
        lines = int(_header_field(header, "lines"))
        if int(_header_field(header, "data type")) != 4 or int(
            _header_field(header, "header offset")
        ):
            raise NidarError("earthlib spectra.sli: expected float32 data without header offset")
        dtype = ">f4" if int(_header_field(header, "byte order")) else "<f4"
        scale = 1000.0 if "micro" in _header_field(header, "wavelength units").lower() else 1.0
        wl = np.array([float(x) for x in _header_field(header, "wavelength").split(",")]) * scale
        data = np.fromfile(sli, dtype=dtype).astype(np.float32)
        with open(os.path.join(data_dir, "spectra.csv"), newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        raise NidarError(f"cannot read the earthlib library in {data_dir}: {e}") from e
    if wl.size != samples or data.size != samples * lines or len(rows) != lines:
        raise NidarError(
            f"earthlib library in {data_dir} is inconsistent: {wl.size} bands, {data.size} values, "
            f"{len(rows)} metadata rows for {lines}x{samples}"
        )
    return EarthlibLibrary(
        wavelengths_nm=np.round(wl, 6),
        data=data.reshape(lines, samples),
        level_2=tuple(r["LEVEL_2"] for r in rows),
        level_3=tuple(r["LEVEL_3"] for r in rows),
        level_4=tuple(r["LEVEL_4"] for r in rows),
        names=tuple(r["NAME"] for r in rows),
        sources=tuple(r["SOURCE"] for r in rows),
        notes=tuple(r["NOTES"] for r in rows),
    )


def extend_below(wavelengths_nm: np.ndarray, values: np.ndarray, grid_nm: np.ndarray) -> np.ndarray:
    """Values on ``grid_nm``: interpolated within the measurement, extended below its start.

    Args:
        wavelengths_nm: (B,) measured wavelengths, increasing, starting at or above ``grid_nm[0]``.
        values: (B,) measured values.
        grid_nm: (G,) target wavelengths, within ``[grid_nm[0], wavelengths_nm[-1]]``.

    Returns:
        (G,) values: linear interpolation inside the measured range (bridging gaps); below it,
        the least-squares slope over the first 40 nm, held between half the first value and the
        first value (see the module docstring).
    """
    out = np.interp(grid_nm, wavelengths_nm, values)
    below = grid_nm < wavelengths_nm[0]
    if np.any(below):
        fit = wavelengths_nm <= wavelengths_nm[0] + (_SLOPE_FIT_MAX_NM - _MEASURED_MIN_NM)
        slope = np.polyfit(wavelengths_nm[fit], values[fit], 1)[0] if fit.sum() >= 2 else 0.0
        v0 = values[0]
        ext = v0 + slope * (grid_nm[below] - wavelengths_nm[0])
        out[below] = np.clip(ext, min(0.5 * v0, v0), max(0.5 * v0, v0))
    return out


@functools.lru_cache(maxsize=1)
def catalog_library() -> EarthlibLibrary:
    """The earthlib spectra the material catalogue names, as shipped with the package
    (``nidar_mi/materials/data/earthlib_catalog.json``; module docstring)."""
    text = resources.files("nidar_mi.materials").joinpath("data", "earthlib_catalog.json")
    doc = json.loads(text.read_text("utf-8"))
    rows = doc["spectra"]
    values = [[np.nan if v is None else v for v in r["reflectance"]] for r in rows]
    return EarthlibLibrary(
        wavelengths_nm=np.asarray(doc["wavelengths_nm"], dtype=np.float64),
        data=np.asarray(values, dtype=np.float32),
        **{k: tuple(r[k] for r in rows) for k in ("level_2", "level_3", "level_4")},
        names=tuple(r["name"] for r in rows),
        sources=tuple(r["source"] for r in rows),
        notes=tuple(r["notes"] for r in rows),
    )


def _library_of(level_2: str, level_3: str, name: str) -> tuple[EarthlibLibrary, int]:
    """The shipped catalogue spectra when they hold this spectrum, else the installed library;
    and its row there."""
    shipped = catalog_library()
    keys = zip(shipped.level_2, shipped.level_3, shipped.names)
    if (level_2, level_3, name) in set(keys):
        return shipped, shipped.index(level_2, level_3, name)
    lib = load_earthlib()
    return lib, lib.index(level_2, level_3, name)


def earthlib_spectrum(
    level_2: str, level_3: str, name: str, grid_nm: np.ndarray = GRID_NM
) -> Spectrum:
    """One earthlib spectrum on ``grid_nm`` (default 360-1700 nm), processed as documented above.

    Raises:
        NidarError: a spectrum the package does not ship and earthlib is missing, or the
            library has no unique spectrum of that name.
    """
    return _row_spectrum(*_library_of(level_2, level_3, name), grid_nm)


def earthlib_row_spectrum(row: int, grid_nm: np.ndarray = GRID_NM) -> Spectrum:
    """Spectrum ``row`` of the library (:func:`load_earthlib`) on ``grid_nm``, processed as
    :func:`earthlib_spectrum`.

    Raises:
        NidarError: earthlib is missing, or the row has fewer than 2 finite values.
    """
    return _row_spectrum(load_earthlib(), row, grid_nm)


def _row_spectrum(lib: EarthlibLibrary, row: int, grid_nm: np.ndarray) -> Spectrum:
    data = lib.data[row].astype(np.float64)
    ok = np.isfinite(data)
    if ok.sum() < 2:
        raise NidarError(f"earthlib spectrum {row} has fewer than 2 finite values")
    values = extend_below(lib.wavelengths_nm[ok], data[ok], grid_nm)
    return Spectrum(grid_nm, np.clip(values, 0.0, 1.0))


def earthlib_notes(level_2: str, level_3: str, name: str) -> str:
    """earthlib's own metadata of a spectrum, e.g. ``"measured (asd): urban reflectance ..."``."""
    lib, i = _library_of(level_2, level_3, name)
    return f"{lib.level_4[i]} ({lib.sources[i]}): {lib.notes[i]}"
