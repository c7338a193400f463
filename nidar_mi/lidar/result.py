"""A scan's result on the (ring, column) grid, and its points dict.

Single-return scans hold (R, C) arrays. A ``dual`` scan keeps its strongest return in the same
(R, C) fields (so every consumer of single-return scans reads it unchanged) and its other return
in ``further[0]``, a :class:`ReturnLayer` of (R, C) arrays; :meth:`ScanResult.points` lists the
returns one after the other with ``return_index`` 0, 1.

Geometry: the point of a return is ``origin + range · direction`` in the LiDAR frame at its
column's firing time (what a sensor reports, motion distortion included); ``xyz_world`` places it
with the pose of that time, and ``xyz_deskewed`` (on request) expresses it in the LiDAR frame at
the sweep's start (motion compensated).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..labels import ShapeLabels
from ..weather.media import SCATTERERS
from .config import LidarConfig

__all__ = ["ReturnLayer", "ScanResult"]


@dataclass
class ReturnLayer:
    """One return per beam, (R, C) arrays.

    Attributes:
        valid: bool, a return was reported.
        range: float32 m (after range noise); 0 where not valid.
        intensity: float32 (after intensity noise, clipped at 0); 0 where not valid.
        reflectance: float32 ρ at the laser wavelength of the surface returning (Fresnel
            reflectance for a glass echo); 0 where no hit.
        cos_incidence: float32 cosine of the incidence angle; 0 where no hit.
        material: int32 index into the scan's ``material_names``; -1 where no hit.
        shape_index: int32 index into the scan's ``shape_names`` (``scene.shapes()`` order);
            -1 where no hit.
        scatterer: in weather, uint8 what the return came from (an index into
            :data:`nidar_mi.weather.media.SCATTERERS`: surface, fog, drop, flake); None in
            clear weather.
    """

    valid: np.ndarray
    range: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray
    material: np.ndarray
    shape_index: np.ndarray
    scatterer: np.ndarray | None = None


@dataclass
class ScanResult:
    """One scan on the (ring, column) grid. All arrays are (R, C) unless noted.

    Attributes:
        config: the sensor's resolved parameters.
        valid, range, intensity, reflectance, cos_incidence, material: the first (or only)
            return of each beam, as in :class:`ReturnLayer` (the strongest in ``dual`` mode).
        directions: (R, C, 3) float32 unit beam directions in the LiDAR frame (read-only:
            shared by every scan of the same beam pattern).
        to_world: (4, 4) float64 LiDAR pose at the sweep's start.
        material_names: list of material (BSDF) ids.
        hit: bool, the beam (or one of its sub-rays) hit a surface (before range, threshold and
            dropout tests).
        timings: seconds per stage (``pattern``, ``raycast``, ``bsdf``, ``detect``, ``readback``).
        shape_index: int32 index into ``scene.shapes()`` of the surface returning; -1 where no
            hit.
        shape_labels: per-shape class and instance tables (:class:`nidar_mi.labels.ShapeLabels`)
            that :meth:`points` turns into ``label`` and ``instance``.
        shape_names: ids of ``scene.shapes()`` in that order (anonymous shapes: ``""``).
        time: float32 s, firing time of each beam since the sweep's start (read-only, shared
            like ``directions``).
        origins: (R, C, 3) float32 beam origins in the LiDAR frame, m (read-only, shared like
            ``directions``); None when every beam starts at the origin.
        column_poses: (C, 4, 4) float64 LiDAR world pose at each column's firing time; None
            when the pose is ``to_world`` throughout.
        further: the other returns (``dual``: one layer), empty for single-return scans.
        scatterer: in weather, uint8 what the first return came from (:class:`ReturnLayer`);
            None in clear weather.
        weather: the :class:`nidar_mi.weather.Weather` scanned in, None in clear weather.
    """

    config: LidarConfig
    valid: np.ndarray
    range: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray
    material: np.ndarray
    directions: np.ndarray
    to_world: np.ndarray
    material_names: list[str]
    hit: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    shape_index: np.ndarray | None = None
    shape_labels: ShapeLabels | None = None
    shape_names: list[str] = field(default_factory=list)
    time: np.ndarray | None = None
    origins: np.ndarray | None = None
    column_poses: np.ndarray | None = None
    further: list[ReturnLayer] = field(default_factory=list)
    scatterer: np.ndarray | None = None
    weather: Any = None

    @property
    def first(self) -> ReturnLayer:
        """The first (or only) return as a layer."""
        return ReturnLayer(
            self.valid,
            self.range,
            self.intensity,
            self.reflectance,
            self.cos_incidence,
            self.material,
            self.shape_index,
            self.scatterer,
        )

    @property
    def returns(self) -> list[ReturnLayer]:
        """Every return layer, the first one first."""
        return [self.first, *self.further]

    def _layer_points(self, layer: ReturnLayer, index: int, deskew: bool) -> dict:
        m = layer.valid
        rings, cols = np.nonzero(m)
        rng = layer.range[m].astype(np.float32)
        if self.origins is None:
            xyz = (self.directions[m] * rng[:, None]).astype(np.float32)
        else:
            xyz = (
                self.origins[m].astype(np.float64)
                + self.directions[m].astype(np.float64) * rng[:, None].astype(np.float64)
            ).astype(np.float32)
        if self.column_poses is None:
            R, t = self.to_world[:3, :3], self.to_world[:3, 3]
            world = xyz.astype(np.float64) @ R.T + t
        else:
            P = self.column_poses[cols]
            world = np.einsum("nij,nj->ni", P[:, :3, :3], xyz.astype(np.float64)) + P[:, :3, 3]
        pts = {
            "xyz": xyz,
            "xyz_world": world.astype(np.float32),
            "range": rng,
            "intensity": layer.intensity[m].astype(np.float32),
            "reflectance": layer.reflectance[m].astype(np.float32),
            "cos_incidence": layer.cos_incidence[m].astype(np.float32),
            "ring": rings.astype(np.uint16),
            "column": cols.astype(np.uint32),
            "material": layer.material[m].astype(np.int32),
        }
        if self.shape_labels is not None:
            pts["label"], pts["instance"] = self.shape_labels.lookup(layer.shape_index[m])
        if self.time is not None:
            pts["t"] = self.time[m].astype(np.float32)
        pts["return_index"] = np.full(len(rng), index, dtype=np.uint8)
        if layer.scatterer is not None:
            pts["scatterer"] = layer.scatterer[m].astype(np.uint8)
        if deskew:
            inv = np.linalg.inv(self.to_world)
            pts["xyz_deskewed"] = (world @ inv[:3, :3].T + inv[:3, 3]).astype(np.float32)
        return pts

    def points(self, *, deskew: bool = False) -> dict[str, np.ndarray]:
        """The valid returns as a points dict (schema in :mod:`nidar_mi.io.points`).

        Args:
            deskew: also give ``xyz_deskewed``, the points in the LiDAR frame at the sweep's
                start (motion compensated with the per-column poses).
        """
        layers = [self._layer_points(layer, i, deskew) for i, layer in enumerate(self.returns)]
        pts = (
            layers[0]
            if len(layers) == 1
            else {k: np.concatenate([p[k] for p in layers]) for k in layers[0]}
        )
        pts["material_names"] = np.asarray(self.material_names, dtype=np.str_)
        if self.shape_labels is not None:
            pts["instance_names"] = self.shape_labels.instance_names
        if self.scatterer is not None:
            pts["scatterer_names"] = np.asarray(SCATTERERS, dtype=np.str_)
        return pts
