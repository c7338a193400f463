"""The ``range_ring`` profile form: monotone maps per range bin, and ring gains.

A sensor-profile form (:mod:`nidar_mi.profiles`). A model
value ``v`` (reflectance-like, the same for a surface whatever sees it) at a return of range
``d`` from ring ``r`` becomes the sensor's intensity

    I = clip(g_r · Q(v; d), 0, 1)

* ``Q(·; d)``: within each range bin a monotone (quantile) map from the model values to the
  ring-normalised intensities of the training returns in that bin
  (:class:`~nidar_mi.profiles.quantile_map.QuantileMap`); between the median ranges of neighbouring
  bins the two maps are blended linearly, beyond the first and last the nearest is used. Bins
  start :data:`DEFAULT_BIN_M` wide and grow until they hold :data:`DEFAULT_MIN_POINTS` returns.
  Within a bin ``Q`` keeps the order of the model values: the ranking of surfaces stays the
  model's; only the sensor's range response (its mean, spread and shape per distance) is
  learned.
* ``g_r``: a gain per ring (laser), for sensors whose lasers differ in sensitivity (the HDL-64E
  of KITTI). Fitted with ``Q`` by alternating means (iterative proportional fitting) of the
  multiplicative model ``I ≈ a(range bin) · g(ring)``, normalised to a count-weighted mean of 1;
  rings with fewer than ``min_ring_points`` returns get 1. A return without a ring (``-1``) takes
  the ring whose median elevation is nearest to its own (:attr:`RangeRingMap.ring_elevation_deg`)
  when elevations are given, else gain 1.

Pure NumPy; the map is stored as plain lists (``to_dict``) in a profile file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import NidarError
from .quantile_map import DEFAULT_K, QuantileMap

__all__ = [
    "DEFAULT_BIN_M",
    "DEFAULT_MIN_POINTS",
    "RangeRingFitOptions",
    "RangeRingMap",
    "range_bins",
    "ring_gains",
]

#: Initial width of the range bins, m.
DEFAULT_BIN_M = 2.0
#: Fewest training returns in a range bin (bins grow until they have them).
DEFAULT_MIN_POINTS = 2000
#: Fewest returns for a ring to get its own gain.
DEFAULT_MIN_RING_POINTS = 500
#: Iterations of the alternating-means fit of the ring gains.
_GAIN_ITERATIONS = 20


def range_bins(
    range_m: np.ndarray, width: float = DEFAULT_BIN_M, min_points: int = DEFAULT_MIN_POINTS
) -> np.ndarray:
    """Bin edges (m) over the ranges: ``width`` wide, grown until each holds ``min_points``.

    Returns:
        (B + 1,) float64 edges, the first 0, the last ``inf``; a last bin with too few points is
        merged into the one before.
    """
    d = np.sort(np.asarray(range_m, dtype=np.float64).reshape(-1))
    if d.size == 0 or not np.all(np.isfinite(d)):
        raise NidarError("range_bins: ranges must be finite and non-empty")
    if not width > 0 or min_points < 1:
        raise NidarError("range_bins: width must be > 0 and min_points >= 1")
    edges = [0.0]
    hi = 0.0
    while True:
        lo_count = np.searchsorted(d, edges[-1], side="left")
        hi = edges[-1] + width
        while np.searchsorted(d, hi, side="left") - lo_count < min_points and hi <= d[-1]:
            hi += width
        if hi > d[-1]:
            break
        edges.append(hi)
    if len(edges) > 1 and d.size - np.searchsorted(d, edges[-1]) < min_points:
        edges.pop()  # too few returns beyond the last edge: merge them into the last bin
    return np.array(edges + [np.inf])


def ring_gains(
    reference: np.ndarray,
    bin_index: np.ndarray,
    ring: np.ndarray,
    n_bins: int,
    n_rings: int,
    min_ring_points: int = DEFAULT_MIN_RING_POINTS,
) -> np.ndarray:
    """Ring gains of ``reference ≈ a[bin] · g[ring]`` by alternating means (module docstring).

    Args:
        reference: (N,) intensities >= 0.
        bin_index: (N,) range bin of each return.
        ring: (N,) ring of each return, -1 where unknown (not used).
        n_bins: number of range bins.
        n_rings: number of rings.
        min_ring_points: rings with fewer returns keep gain 1.

    Returns:
        (n_rings,) float64 gains, count-weighted mean 1 over the fitted rings.
    """
    y = np.asarray(reference, dtype=np.float64)
    known = ring >= 0
    y, b, r = y[known], bin_index[known], ring[known].astype(np.int64)
    counts = np.bincount(r, minlength=n_rings).astype(np.float64)
    fitted = counts >= min_ring_points
    g = np.ones(n_rings)
    if not fitted.any() or y.sum() <= 0:
        return g
    for _ in range(_GAIN_ITERATIONS):
        a = np.bincount(b, weights=y, minlength=n_bins) / np.maximum(
            np.bincount(b, weights=g[r], minlength=n_bins), 1e-12
        )
        num = np.bincount(r, weights=y, minlength=n_rings)
        den = np.bincount(r, weights=a[b], minlength=n_rings)
        g = np.where(fitted & (den > 0), num / np.maximum(den, 1e-12), 1.0)
        mean = np.sum(g[fitted] * counts[fitted]) / counts[fitted].sum()
        g = np.where(fitted, g / mean, 1.0)
    return g


def _gain(gains: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """(N,) gain of each return: its ring's, 1 where the ring is unknown (-1)."""
    out = np.ones(ring.shape, dtype=np.float64)
    known = ring >= 0
    out[known] = gains[ring[known]]
    return out


@dataclass(frozen=True)
class RangeRingFitOptions:
    """How a ``range_ring`` map is fitted (keyword options of :func:`nidar_mi.profiles.fit`).

    Attributes:
        n_rings: number of rings (default: the largest ring + 1).
        ring_gains_on: fit ring gains (else all 1).
        width: initial range-bin width, m.
        min_points: fewest returns per range bin.
        min_ring_points: fewest returns for a ring's own gain.
        K: quantile levels per map.
    """

    n_rings: int | None = None
    ring_gains_on: bool = True
    width: float = DEFAULT_BIN_M
    min_points: int = DEFAULT_MIN_POINTS
    min_ring_points: int = DEFAULT_MIN_RING_POINTS
    K: int = DEFAULT_K


@dataclass(frozen=True, eq=False)
class RangeRingMap:
    """Per-range-bin monotone maps and ring gains (module docstring).

    Attributes:
        edges_m: (B + 1,) bin edges in m, first 0, last ``inf``.
        centres_m: (B,) median training range of each bin, m (increasing).
        maps: B quantile maps, model value -> ring-normalised intensity.
        gains: (R,) gain per ring (all 1 for a sensor without ring gains).
        ring_elevation_deg: (R,) median elevation of each ring's training returns, degrees (NaN
            where unknown); used for returns without a ring.
    """

    #: The form's name in a profile file.
    form: ClassVar[str] = "range_ring"
    #: Whether the form can read the returns' incidence cosines.
    reads_incidence: ClassVar[bool] = False
    #: The keyword options of its :meth:`fit`.
    fit_options: ClassVar[type] = RangeRingFitOptions

    edges_m: np.ndarray
    centres_m: np.ndarray
    maps: tuple[QuantileMap, ...]
    gains: np.ndarray
    ring_elevation_deg: np.ndarray

    def __post_init__(self) -> None:
        e = np.asarray(self.edges_m, dtype=np.float64)
        c = np.asarray(self.centres_m, dtype=np.float64)
        g = np.asarray(self.gains, dtype=np.float64)
        el = np.asarray(self.ring_elevation_deg, dtype=np.float64)
        if e.ndim != 1 or e.size < 2 or e[0] != 0.0 or e[-1] != np.inf or np.any(np.diff(e) <= 0):
            raise NidarError("range_ring: edges_m must increase from 0 to inf")
        if c.shape != (e.size - 1,) or np.any(np.diff(c) <= 0) or not np.all(np.isfinite(c)):
            raise NidarError("range_ring: one increasing centre per bin expected")
        if len(self.maps) != c.size or not all(isinstance(m, QuantileMap) for m in self.maps):
            raise NidarError("range_ring: one quantile map per bin expected")
        if g.ndim != 1 or not np.all(np.isfinite(g)) or np.any(g < 0):
            raise NidarError("range_ring: gains must be finite and non-negative")
        if el.shape != g.shape:
            raise NidarError("range_ring: one elevation per ring expected")
        for name, arr in (
            ("edges_m", e),
            ("centres_m", c),
            ("gains", g),
            ("ring_elevation_deg", el),
        ):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "maps", tuple(self.maps))

    @property
    def uses_incidence(self) -> bool:
        """False: the map reads the value, range, ring and elevation only."""
        return False

    def _bin_values(self, v: np.ndarray, d: np.ndarray) -> np.ndarray:
        out = np.empty_like(v)
        c = self.centres_m
        if c.size == 1:
            return self.maps[0](v)
        j = np.clip(np.searchsorted(c, d) - 1, 0, c.size - 2)
        t = np.clip((d - c[j]) / (c[j + 1] - c[j]), 0.0, 1.0)
        for k in np.unique(j):
            s = j == k
            out[s] = (1.0 - t[s]) * self.maps[k](v[s]) + t[s] * self.maps[k + 1](v[s])
        return out

    def resolve_rings(self, ring: np.ndarray | None, elevation_deg: np.ndarray | None, n: int):
        """(N,) ring per return: the given one, else the ring of nearest median elevation, else
        -1."""
        r = np.full(n, -1, dtype=np.int64) if ring is None else np.asarray(ring, np.int64).copy()
        r[(r < -1) | (r >= self.gains.size)] = -1
        missing = r < 0
        known = np.isfinite(self.ring_elevation_deg)
        if missing.any() and elevation_deg is not None and known.any():
            table = np.flatnonzero(known)
            el = np.asarray(elevation_deg, dtype=np.float64)[missing]
            near = np.abs(el[:, None] - self.ring_elevation_deg[table][None, :]).argmin(1)
            r[missing] = table[near]
        return r

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray:
        """Intensities of returns (module docstring).

        Args:
            values: (N,) model values.
            range_m: (N,) ranges, m.
            ring: optional (N,) rings (-1 unknown).
            elevation_deg: optional (N,) elevations, degrees (for returns without a ring).
            cos_incidence: ignored (the form does not read the incidence).

        Returns:
            (N,) float64 in [0, 1].
        """
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        d = np.asarray(range_m, dtype=np.float64).reshape(-1)
        if v.shape != d.shape:
            raise NidarError(f"range_ring: {v.size} values but {d.size} ranges")
        r = self.resolve_rings(ring, elevation_deg, v.size)
        return np.clip(_gain(self.gains, r) * self._bin_values(v, d), 0.0, 1.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation (``inf`` written as the string ``"inf"``)."""
        return {
            "edges_m": [float(x) for x in self.edges_m[:-1]] + ["inf"],
            "centres_m": self.centres_m.tolist(),
            "maps": [m.to_dict() for m in self.maps],
            "gains": self.gains.tolist(),
            "ring_elevation_deg": [
                None if not np.isfinite(x) else float(x) for x in self.ring_elevation_deg
            ],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RangeRingMap:
        """Inverse of :meth:`to_dict`; :class:`NidarError` on malformed input."""
        if not isinstance(data, Mapping):
            raise NidarError("range_ring: expected an object")
        missing = [
            k
            for k in ("edges_m", "centres_m", "maps", "gains", "ring_elevation_deg")
            if k not in data
        ]
        if missing:
            raise NidarError(f"range_ring: missing key(s) {', '.join(missing)}")
        try:
            edges = [np.inf if x == "inf" else float(x) for x in data["edges_m"]]
            elev = [np.nan if x is None else float(x) for x in data["ring_elevation_deg"]]
            maps = [QuantileMap.from_dict(m) for m in data["maps"]]
        except (TypeError, ValueError) as e:
            raise NidarError(f"range_ring: malformed values ({e})") from None
        return cls(
            edges_m=np.array(edges),
            centres_m=np.asarray(data["centres_m"], dtype=np.float64),
            maps=tuple(maps),
            gains=np.asarray(data["gains"], dtype=np.float64),
            ring_elevation_deg=np.array(elev),
        )

    @classmethod
    def fit(
        cls,
        values: Any,
        range_m: Any,
        intensity: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
        input: str = "R",
        options: RangeRingFitOptions | None = None,
    ) -> RangeRingMap:
        """Fit the map on training returns (:func:`nidar_mi.profiles.fit` is the entry point).

        Args:
            values: (N,) model values at the returns.
            range_m: (N,) their ranges, m.
            intensity: (N,) the sensor's intensities there, in [0, 1].
            ring: optional (N,) rings (-1 unknown).
            elevation_deg: optional (N,) elevations, degrees (for the rings' median elevations).
            cos_incidence, input: not read by this form.
            options: the fitting options (:class:`RangeRingFitOptions`; default its defaults).

        Raises:
            NidarError: mismatched, empty or non-finite inputs.
        """
        o = options or RangeRingFitOptions()
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        d = np.asarray(range_m, dtype=np.float64).reshape(-1)
        y = np.asarray(intensity, dtype=np.float64).reshape(-1)
        if not v.size or v.shape != d.shape or v.shape != y.shape:
            raise NidarError(
                "fit range_ring: need as many values, ranges and intensities "
                f"(got {v.size}, {d.size}, {y.size})"
            )
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(d)) and np.all(np.isfinite(y))):
            raise NidarError("fit range_ring: values, ranges and references must be finite")
        r, n_r = _rings(ring, v.size, o.n_rings)
        edges = range_bins(d, o.width, o.min_points)
        b = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, edges.size - 2)
        n_b = edges.size - 1
        if o.ring_gains_on and n_r > 0:
            g = ring_gains(y, b, r, n_b, n_r, o.min_ring_points)
        else:
            g = np.ones(n_r)
        y_norm = y / np.maximum(_gain(g, r), 1e-12)
        maps, centres = _bin_maps(v, d, y_norm, b, n_b, o.K)
        return cls(
            edges_m=edges,
            centres_m=centres,
            maps=maps,
            gains=g,
            ring_elevation_deg=_ring_elevations(elevation_deg, r, n_r),
        )


def _rings(ring: Any, n: int, n_rings: int | None) -> tuple[np.ndarray, int]:
    """(N,) int64 rings (-1 unknown, and for rings at or beyond ``n_rings``) and the number of
    rings (default: the largest ring + 1)."""
    r = np.full(n, -1, np.int64) if ring is None else np.asarray(ring, np.int64).reshape(-1)
    if r.shape != (n,):
        raise NidarError("fit range_ring: one ring per value expected")
    n_r = int(n_rings) if n_rings is not None else max(int(r.max()) + 1, 0)
    return np.where(r < n_r, r, -1), n_r


def _bin_maps(v, d, y_norm, b, n_b: int, K: int) -> tuple[tuple[QuantileMap, ...], np.ndarray]:
    """One quantile map per range bin (values ``v`` to gain-normalised intensities ``y_norm``,
    bin ``b`` of each return) and each bin's median range, m."""
    maps, centres = [], []
    for k in range(n_b):
        s = b == k
        if np.ptp(v[s]) == 0:  # one value in the bin (a range-only profile): its median
            maps.append(QuantileMap([0.5], [v[s][0]], [float(np.median(y_norm[s]))]))
        else:
            maps.append(QuantileMap.fit(v[s], y_norm[s], K=K))
        centres.append(float(np.median(d[s])))
    return tuple(maps), np.array(centres)


def _ring_elevations(elevation_deg: Any, r: np.ndarray, n_r: int) -> np.ndarray:
    """(n_r,) median elevation of each ring's returns, degrees (NaN without any)."""
    el = np.full(n_r, np.nan)
    if elevation_deg is not None and n_r:
        e = np.asarray(elevation_deg, dtype=np.float64).reshape(-1)
        for k in range(n_r):
            s = r == k
            if s.any():
                el[k] = float(np.median(e[s]))
    return el
