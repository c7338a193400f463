"""Beam patterns of spinning LiDARs: sensor presets and the (ring, column) ray grid.

Frame: x forward, y left, z up. Azimuth is measured counter-clockwise from +x, elevation positive
up. Column ``j`` of ``cols`` points at azimuth ``(j + 0.5) * fov_h / cols`` (degrees); the half-column
offset keeps rays off axis-aligned edges. Rings are ordered like the rows of a range image:
ring 0 is the **highest** beam, the last ring the lowest.

Elevation tables (degrees):

* ``vlp16`` — Velodyne VLP-16 user manual (63-9243 Rev. E), Table 9-1: -15..+15 in 2 deg steps.
* ``hdl32e`` — Velodyne HDL-32E user manual (63-9113 Rev. J), laser table: -30.67..+10.67 in 4/3 deg
  steps (the sensor of nuScenes, Caesar et al., CVPR 2020).
* ``hdl64e`` — Velodyne HDL-64E S2 datasheet: vertical field of view +2 deg up to -24.8 deg down
  with 64 equally spaced subdivisions (~0.4 deg); the sensor of KITTI (Geiger et al., IJRR 2013:
  26.8 deg vertical field of view).
* ``os1_128`` — Ouster OS1 Rev 6 datasheet: 128 channels, 45 deg vertical field of view, uniform
  spacing (-22.5..+22.5).
* ``waymo_top`` — Waymo Open Dataset top LiDAR (Sun et al., CVPR 2020, Table 1): 64 beams over
  -17.6..+2.4 deg; the real beam inclinations are non-uniform and per-vehicle, here uniform over that
  field of view; 2650 columns as in the dataset's range images.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Preset",
    "PRESETS",
    "elevation_table",
    "parse_angles",
    "azimuths_deg",
    "beam_directions",
]


@dataclass(frozen=True)
class Preset:
    """A sensor's beam pattern and nominal limits.

    Attributes:
        elevations_deg: (R,) elevation of each ring in degrees, ring 0 highest.
        horizontal_resolution: columns per revolution.
        range_min: minimum range in m.
        range_max: maximum range in m.
        reference: datasheet or paper the table comes from.
        detection_threshold: default ``raw``-mode detection threshold (1/m², gain 1): 0 where
            the datasheet gives no range for a stated reflectivity; for ``hdl64e`` the
            datasheet's 10 % at 50 m (:mod:`nidar_mi.lidar.calibration`).
    """

    elevations_deg: tuple[float, ...]
    horizontal_resolution: int
    range_min: float
    range_max: float
    reference: str
    detection_threshold: float = 0.0


def _desc(values: np.ndarray) -> tuple[float, ...]:
    return tuple(float(round(v, 4)) for v in sorted(values.tolist(), reverse=True))


PRESETS: dict[str, Preset] = {
    "vlp16": Preset(
        _desc(np.arange(-15.0, 15.0 + 1e-9, 2.0)),
        1800,
        0.5,
        100.0,
        "Velodyne VLP-16 user manual 63-9243 Rev. E",
    ),
    "hdl32e": Preset(
        _desc(-30.67 + np.arange(32) * (41.34 / 31.0)),
        1084,
        0.5,
        100.0,
        "Velodyne HDL-32E user manual 63-9113 Rev. J (nuScenes)",
    ),
    "hdl64e": Preset(
        _desc(np.linspace(2.0, -24.8, 64)),
        2048,
        0.9,
        120.0,
        "Velodyne HDL-64E S2 datasheet (KITTI, Geiger et al. IJRR 2013)",
        4.0e-5,  # 0.10 / 50 m²: 10 % at normal incidence detected to 50 m (datasheet)
    ),
    "os1_128": Preset(
        _desc(np.linspace(-22.5, 22.5, 128)),
        2048,
        0.3,
        120.0,
        "Ouster OS1 Rev 6 datasheet",
    ),
    "waymo_top": Preset(
        _desc(np.linspace(-17.6, 2.4, 64)),
        2650,
        0.5,
        75.0,
        "Waymo Open Dataset top LiDAR (Sun et al. CVPR 2020)",
    ),
}


def elevation_table(preset: str) -> np.ndarray:
    """(R,) float64 elevations in degrees of a preset, ring 0 highest."""
    return np.asarray(PRESETS[preset].elevations_deg, dtype=np.float64)


def parse_angles(text: str) -> np.ndarray:
    """Parse a comma- or space-separated list of elevation angles in degrees.

    Returns:
        (R,) float64 sorted with ring 0 highest.

    Raises:
        ValueError: a value is not a number, not finite, or outside [-90, 90], or the list is empty.
    """
    parts = [p for p in text.replace(",", " ").split() if p]
    if not parts:
        raise ValueError("is empty")
    values = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise ValueError(f"has a non-numeric angle '{p}'") from None
        if not np.isfinite(v) or abs(v) > 90.0:
            raise ValueError(f"has an angle outside [-90, 90] degrees: {p}")
        values.append(v)
    return np.sort(np.asarray(values, dtype=np.float64))[::-1].copy()


def azimuths_deg(cols: int, fov_h: float = 360.0) -> np.ndarray:
    """(cols,) azimuth of each column in degrees: ``(j + 0.5) * fov_h / cols``."""
    return (np.arange(cols, dtype=np.float64) + 0.5) * (fov_h / cols)


def beam_directions(elevations_deg: np.ndarray, cols: int, fov_h: float = 360.0) -> np.ndarray:
    """Unit ray directions of the whole scan in the LiDAR frame.

    Args:
        elevations_deg: (R,) ring elevations in degrees.
        cols: columns per scan.
        fov_h: horizontal field of view in degrees.

    Returns:
        (R, cols, 3) float64 unit vectors; ``[r, j]`` is ring r, column j.
    """
    el = np.deg2rad(np.asarray(elevations_deg, dtype=np.float64))[:, None]
    az = np.deg2rad(azimuths_deg(cols, fov_h))[None, :]
    return np.stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) * np.ones_like(az)], axis=-1
    )
