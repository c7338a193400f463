"""Baselines for LiDAR intensity, each a per-point prediction on the evaluation points.

* :func:`rgb_twin_scan`: physics on RGB assets (what engines do today): the LiDAR return model
  run on the scene's RGB-only twin, whose reflectance at the laser wavelength is whatever the
  sRGB upsampling gives.
* :func:`luminance_rho`: the camera's Rec. 709 luminance (of linearised sRGB) used as ρ.
* :class:`ClassConstant`: one reflectance (or intensity) per semantic class, the mean of the
  training points of that class.
* :func:`carla`: CARLA's ``I = exp(-0.004 d)`` (its default atmosphere attenuation rate).

The NIDAR variants (pseudo-NIR straight into calibration, Î direct, full) come from
:class:`nidar_mi.nidar.pipeline.NidarModel` (``predict_image`` maps, ``point_intensity``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = [
    "CARLA_ATTENUATION_PER_M",
    "ClassConstant",
    "carla",
    "luminance_rho",
    "rgb_twin_scan",
]

CARLA_ATTENUATION_PER_M = 0.004
"""CARLA's default ``atmosphere_attenuation_rate`` (1/m) in ``I = exp(-a d)``."""


def carla(distance_m: Any) -> np.ndarray:
    """CARLA's LiDAR intensity model ``I = exp(-0.004 d)``.

    Args:
        distance_m: (N,) ranges in metres (>= 0).

    Returns:
        (N,) float64 intensities in (0, 1].
    """
    d = np.asarray(distance_m, dtype=np.float64)
    if not np.all(np.isfinite(d)) or np.any(d < 0.0):
        raise NidarError("carla: distances must be finite and non-negative")
    return np.exp(-CARLA_ATTENUATION_PER_M * d)


def luminance_rho(rgb_uint8: Any, uv: Any) -> np.ndarray:
    """Rec. 709 luminance of the linearised sRGB image, bilinearly sampled at points.

    Args:
        rgb_uint8: (H, W, 3) uint8 sRGB image (the camera frame).
        uv: (N, 2) pixel coordinates of the projected points (pixel centres at integers, as in
            :mod:`nidar_mi.geometry.camera_model`).

    Returns:
        (N,) float64 ρ in [0, 1]; NaN for points outside the image.
    """
    from ..geometry import bilinear_sample
    from ..io.images import REC709_LUMA, srgb_to_linear

    rgb = np.asarray(rgb_uint8)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(
            f"luminance_rho: expected a uint8 (H, W, 3) image, got {rgb.dtype} {rgb.shape}"
        )
    linear = srgb_to_linear(rgb.astype(np.float64) / 255.0)
    return bilinear_sample(linear @ np.asarray(REC709_LUMA), uv)


def _label_kind(a: np.ndarray) -> str:
    return "text" if a.dtype.kind in "US" else "number" if a.dtype.kind in "biuf" else "other"


@dataclass(frozen=True)
class ClassConstant:
    """One value per semantic class: the mean over that class's training points.

    Class labels may be integers or strings; use labels shared across scenes (material names,
    say), since a scan's ``material`` indices are local to its scene.

    Attributes:
        classes: (K,) sorted class labels seen in training.
        means: (K,) mean value per class.
        counts: (K,) training points per class.
        global_mean: mean over all training points, predicted for unseen classes.
    """

    classes: np.ndarray
    means: np.ndarray
    counts: np.ndarray
    global_mean: float

    @classmethod
    def fit(cls, material_ids: Any, intensity: Any) -> ClassConstant:
        """Per-class means of ``intensity``.

        Args:
            material_ids: (N,) class label per training point.
            intensity: (N,) value per training point (intensity or reflectance).
        """
        ids = np.asarray(material_ids).ravel()
        y = np.asarray(intensity, dtype=np.float64).ravel()
        if ids.shape != y.shape or y.size == 0:
            raise NidarError(
                f"ClassConstant.fit: need as many labels as values, at least one "
                f"(got {ids.size} and {y.size})"
            )
        if not np.all(np.isfinite(y)):
            raise NidarError("ClassConstant.fit: non-finite training values")
        classes, inverse = np.unique(ids, return_inverse=True)
        counts = np.bincount(inverse, minlength=classes.size)
        means = np.bincount(inverse, weights=y, minlength=classes.size) / counts
        for a in (classes, means, counts):
            a.setflags(write=False)
        return cls(classes=classes, means=means, counts=counts, global_mean=float(y.mean()))

    def predict(self, ids: Any) -> np.ndarray:
        """(N,) float64 class means for the labels ``ids``; the global mean for unseen ones."""
        ids = np.asarray(ids).ravel()
        if ids.size == 0:
            return np.zeros(0, dtype=np.float64)
        if _label_kind(ids) != _label_kind(self.classes):
            raise NidarError(
                f"ClassConstant.predict: labels of type {ids.dtype} do not match the fitted "
                f"{self.classes.dtype} labels"
            )
        pos = np.searchsorted(self.classes, ids)
        pos = np.minimum(pos, self.classes.size - 1)
        seen = self.classes[pos] == ids
        return np.where(seen, self.means[pos], self.global_mean)


def rgb_twin_scan(
    scene_path: str,
    params: dict[str, str] | None = None,
    seed: int | None = None,
    *,
    lidar: str | None = None,
    variant: str | None = None,
):
    """Scan the RGB-only twin of a scene: the return model on RGB assets.

    The twin has the same geometry and sensor, so with the same ``seed`` its beams, range noise
    and dropout draws are those of the spectral scan; ``twin.intensity[ring, column]`` at the
    evaluation points is this baseline (0 where the twin's return falls below the detection
    threshold). The warning that RGB-only materials are not physical at the laser wavelength is
    silenced here: that is the point of the baseline.

    Args:
        scene_path: scene XML.
        params: values for the scene's ``<default>`` parameters.
        seed: overrides the sensor's noise/dropout seed.
        lidar: id of the LiDAR to scan; None takes the first (sorted by id).
        variant: Mitsuba variant; None picks the default.

    Returns:
        :class:`nidar_mi.lidar.scan.ScanResult` of the twin.

    Raises:
        NidarError: bad scene, no LiDAR, or no LiDAR with id ``lidar``.
    """
    from ..lidar.scan import scan
    from ..scene import load_scene

    loaded = load_scene(scene_path, variant=variant, rgb_twin=True, params=params)
    if not loaded.lidars:
        raise NidarError(f"{scene_path}: no lidar sensor")
    if lidar is None:
        sensor = loaded.lidars[0]
    else:
        found = [s for s in loaded.lidars if s.id() == lidar]
        if not found:
            ids = ", ".join(s.id() for s in loaded.lidars)
            raise NidarError(f"{scene_path}: no lidar '{lidar}' (has: {ids})")
        sensor = found[0]
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*is RGB-only", category=RuntimeWarning)
        return scan(loaded.scene, sensor, seed=seed)
