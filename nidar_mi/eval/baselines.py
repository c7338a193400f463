"""Baselines for LiDAR intensity, each a per-point prediction on the evaluation points.

* :func:`rgb_twin_scan`: physics on RGB assets (what engines do today): the LiDAR return model
  run on the scene's RGB-only twin, whose reflectance at the laser wavelength is whatever the
  sRGB upsampling gives.
* :func:`luminance_rho`: the camera's Rec. 709 luminance (of linearised sRGB) used as ρ.
* :class:`ClassConstant`: one reflectance (or intensity) per semantic class, the mean of the
  training points of that class.
* :func:`carla`: CARLA's ``I = exp(-0.004 d)`` (its default atmosphere attenuation rate).
* :class:`LinearColourDistance`: (h) a 9-parameter least-squares regression of the intensity
  on colour and distance, features ``r, g, b, r/Σ, g/Σ, b/Σ, log d, d/50, 1`` (``r, g, b`` the
  8-bit sRGB values / 255 at the point, bilinear; ``Σ = r + g + b + 1e-6``; ``d`` the range in m,
  ``log`` of at least 0.1 m).
* :class:`LinearNIR`: the 4-parameter linear map from linear RGB to linear NIR,
  ``nir = w_r r + w_g g + w_b b + w_0``, fitted by least squares on RGB/NIR photo pairs (both
  8-bit images linearised with the sRGB transfer function; 20 000 pixels per pair drawn with a
  seeded generator).

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
    "LinearColourDistance",
    "LinearNIR",
    "colour_distance_features",
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
        variant: the active Mitsuba variant expected (None: whichever is active).

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


def colour_distance_features(colour: Any, range_m: Any) -> np.ndarray:
    """(N, 9) features of :class:`LinearColourDistance` (module docstring).

    Args:
        colour: (N, 3) 8-bit sRGB / 255 at the points.
        range_m: (N,) ranges, m.
    """
    c = np.asarray(colour, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(range_m, dtype=np.float64).reshape(-1)
    if c.shape[0] != d.shape[0]:
        raise NidarError(f"colour_distance_features: {c.shape[0]} colours but {d.size} ranges")
    total = c.sum(1, keepdims=True) + 1e-6
    return np.concatenate(
        [
            c,
            c / total,
            np.log(np.maximum(d, 0.1))[:, None],
            d[:, None] / 50.0,
            np.ones((d.size, 1)),
        ],
        axis=1,
    )


@dataclass(frozen=True)
class LinearColourDistance:
    """(h) Least-squares intensity from colour and distance (module docstring).

    Attributes:
        weights: (9,) coefficients of :func:`colour_distance_features`.
    """

    weights: np.ndarray

    @classmethod
    def fit(cls, colour: Any, range_m: Any, intensity: Any) -> LinearColourDistance:
        """Fit on training points: (N, 3) colours, (N,) ranges, (N,) intensities."""
        X = colour_distance_features(colour, range_m)
        y = np.asarray(intensity, dtype=np.float64).reshape(-1)
        if (
            X.shape[0] != y.size
            or y.size < 9
            or not np.all(np.isfinite(X))
            or not np.all(np.isfinite(y))
        ):
            raise NidarError("LinearColourDistance.fit: need >= 9 finite points with intensities")
        w, *_ = np.linalg.lstsq(X, y, rcond=None)
        return cls(weights=w)

    def predict(self, colour: Any, range_m: Any) -> np.ndarray:
        """(N,) float64 predictions, clipped to [0, 1]."""
        return np.clip(colour_distance_features(colour, range_m) @ self.weights, 0.0, 1.0)


@dataclass(frozen=True)
class LinearNIR:
    """The 4-parameter linear RGB -> NIR map (module docstring).

    Attributes:
        weights: (4,) ``w_r, w_g, w_b, w_0``.
    """

    weights: np.ndarray

    @classmethod
    def fit(cls, pairs, pixels_per_pair: int = 20000, seed: int = 0) -> LinearNIR:
        """Fit on ``(rgb uint8 (H, W, 3), nir uint8 (H, W))`` pairs (an iterable)."""
        from ..io.images import srgb_to_linear

        rng = np.random.default_rng(seed)
        X, y = [], []
        for rgb, nir in pairs:
            n = nir.size
            sel = rng.choice(n, min(pixels_per_pair, n), replace=False)
            X.append(srgb_to_linear(rgb.reshape(-1, 3)[sel].astype(np.float32) / 255.0))
            y.append(srgb_to_linear(nir.reshape(-1)[sel].astype(np.float32) / 255.0))
        if not X:
            raise NidarError("LinearNIR.fit: no pairs")
        A = np.concatenate(X).astype(np.float64)
        A = np.concatenate([A, np.ones((len(A), 1))], 1)
        w, *_ = np.linalg.lstsq(A, np.concatenate(y).astype(np.float64), rcond=None)
        return cls(weights=w)

    def __call__(self, rgb_uint8: Any) -> np.ndarray:
        """(H, W) float32 linear pseudo-NIR of an (H, W, 3) uint8 sRGB image."""
        from ..io.images import srgb_to_linear

        lin = srgb_to_linear(np.asarray(rgb_uint8).astype(np.float32) / 255.0)
        return (lin @ self.weights[:3].astype(np.float32) + np.float32(self.weights[3])).astype(
            np.float32
        )
