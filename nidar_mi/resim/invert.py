"""The inversion run on a drive: the training samples cast into the surfaces, the mounting's
shadow found in them (its misses then left out, :mod:`.shadow`), NIDAR's prior, the fit with
per-laser gains and the fit without them (a baseline), and the fit's residuals."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beam_rays import Rays, concat, miss_rays
from .build import drop_scratch, scratch_scene, training_rays
from .drive_folder import Drive
from .frames import Frames
from .inversion import FitOptions, SensorFit, edges_of, fit_drive, predict_returns, sensor_samples
from .mesh import Mesh, crease_vertices
from .shadow import Shadow, find_shadow, ray_columns

__all__ = ["Inversion", "invert", "sensor_summary", "MAX_SAMPLES"]

#: The most returns the fit samples; more are subsampled evenly (seeded); misses at most half.
MAX_SAMPLES = 2_000_000


@dataclass
class Inversion:
    """The fitted reflectance and sensor, with and without per-laser gains.

    Attributes:
        rho, sensor: the fit (ρ (V,) per vertex of the mesh, then of the splats; the
            recovered sensor).
        rho_flat, sensor_flat: the fit without per-laser gains.
        prior: (V,) NIDAR's R per vertex (NaN unseen), or None; prior_scale: ρ ≈ scale·R.
        residuals: the fit's residuals on the training samples.
        shadow: the mounting's shadow found in the training samples (:mod:`.shadow`).
    """

    rho: np.ndarray
    sensor: SensorFit
    rho_flat: np.ndarray
    sensor_flat: SensorFit
    prior: np.ndarray | None
    prior_scale: float
    residuals: dict
    shadow: Shadow

    def summary(self) -> dict:
        """JSON-safe: the recovered sensor, the residuals, the prior's coverage."""
        return {
            "sensor": sensor_summary(self.sensor),
            "sensor_without_laser_gains": sensor_summary(self.sensor_flat),
            "residuals": self.residuals,
            "rho": {
                "median": float(np.median(self.rho)),
                "p05": float(np.percentile(self.rho, 5)),
                "p95": float(np.percentile(self.rho, 95)),
            },
            "nidar_prior": None
            if self.prior is None
            else {
                "vertices_seen": int(np.isfinite(self.prior).sum()),
                "scale": self.prior_scale,
            },
        }


def sensor_summary(s: SensorFit) -> dict:
    """JSON-safe fields of a :class:`SensorFit` (the loss history's last entry)."""
    return {
        "laser_gains": s.gains.round(5).tolist(),
        "range_response": {"knots_m": list(s.knots_m), "values": s.response.round(5).tolist()},
        "laser_range_response": None
        if s.laser_response is None
        else s.laser_response.round(5).tolist(),
        "intensity_offset": s.offset,
        "detection_threshold": s.threshold,
        "receiver_noise_std": s.noise,
        "dropout": s.dropout,
        "final_loss": s.history[-1] if s.history else None,
    }


def _subsample(rays: Rays, values: np.ndarray, limit: int, rng) -> tuple[Rays, np.ndarray]:
    if len(values) <= limit:
        return rays, values
    keep = np.sort(rng.choice(len(values), limit, replace=False))
    return Rays(*(getattr(rays, f)[keep] for f in Rays._fields)), values[keep]


def _misses(drive: Drive, frames: Frames, poses: np.ndarray) -> Rays:
    idx = [drive.index(i) for i in drive.train]
    return concat(
        [miss_rays(frames.grid[k], frames.coverage, frames.layout, poses[k], k) for k in idx]
    )


def _residuals(samples, rho_fit: SensorFit, predicted: np.ndarray) -> dict:
    """Residuals of the fit on its own samples."""
    from ..eval.metrics import spearman

    det = samples.detected
    shown = np.maximum(predicted[det] - rho_fit.offset, 0.0)
    y = samples.intensity[det]
    from scipy.special import ndtr

    p = (1.0 - rho_fit.dropout) * ndtr((predicted - rho_fit.threshold) / rho_fit.noise)
    rings = len(rho_fit.gains)
    return {
        "laser_returns": np.bincount(samples.ring.numpy()[det], minlength=rings).tolist(),
        "samples_returns": int(det.sum()),
        "samples_misses": int((~det).sum()),
        "intensity_rmse": float(np.sqrt(np.mean((np.clip(shown, 0, 1) - y) ** 2))),
        "intensity_spearman": spearman(shown, y),
        "detection_rate_observed": float(det.mean()),
        "detection_rate_fitted": float(p.mean()),
    }


def _prior_weight(samples, mesh: Mesh) -> np.ndarray:
    """(V,) 1 / (1 + returns landing on triangles around the vertex): the prior weighs most
    where the LiDAR rarely hit."""
    prim = samples.beams.si.prim_index.numpy().astype(np.int64)[samples.detected]
    corners = mesh.faces[prim].ravel()
    hits = np.bincount(corners, minlength=len(mesh.vertices))
    return 1.0 / (1.0 + hits)


def invert(
    drive: Drive, frames: Frames, poses: np.ndarray, mesh: Mesh, options, stage: str, splats=None
):
    """Cast the training samples, run NIDAR for the prior, fit twice (module docstring).

    ``splats`` (:class:`.splats.Splats`) take no part in the fit: their vertices' ρ come from
    their own returns through each fitted sensor, after the mesh's in every per-vertex array."""
    from .observations import cast_samples
    from .prior import nidar_prior

    rng = np.random.default_rng(options.seed)
    scene = scratch_scene(stage)(mesh)
    rays, intensity = training_rays(drive, frames, poses)
    rays, intensity = _subsample(rays, intensity, MAX_SAMPLES, rng)
    misses = _misses(drive, frames, poses)
    misses, _ = _subsample(misses, np.zeros(len(misses.ring)), MAX_SAMPLES // 2, rng)
    samples = cast_samples(scene, mesh.faces, rays, intensity, misses)
    train = [drive.index(i) for i in drive.train]
    shadow = find_shadow(samples, poses, train, (frames.layout.rings, frames.columns))
    if shadow.mask.any():  # the shadow's misses are not the receiver's: out of the fit
        open_ = ~shadow.mask[misses.ring, ray_columns(misses, poses, frames.columns)]
        misses = Rays(*(getattr(misses, f)[open_] for f in Rays._fields))
        samples = cast_samples(scene, mesh.faces, rays, intensity, misses)
    n = len(mesh.vertices)
    vertices = (
        mesh.vertices if splats is None else np.concatenate([mesh.vertices, splats.mesh.vertices])
    )
    prior_all = (
        nidar_prior(drive, vertices, poses, weights=options.weights) if options.prior else None
    )
    prior = None if prior_all is None else prior_all[:n]
    edges = edges_of(mesh.faces)
    fo = FitOptions(iterations=options.iterations)
    kw = {
        "prior": prior,
        "prior_weight": _prior_weight(samples, mesh),
        "sensor_rows": sensor_samples(samples, crease_vertices(mesh)),
        "progress": options.progress,
    }
    rho, sensor = fit_drive(samples, scene, edges, frames.layout.rings, fo, **kw)
    residuals = _residuals(samples, sensor, predict_returns(samples, rho, sensor))
    residuals["sensor_returns"] = int((kw["sensor_rows"] & samples.detected).sum())
    fo_flat = FitOptions(iterations=options.iterations, per_laser=False)
    rho_flat, sensor_flat = fit_drive(samples, scene, edges, frames.layout.rings, fo_flat, **kw)
    drop_scratch(stage)
    scale = np.nan
    if prior is not None and np.isfinite(prior).any():
        seen = np.isfinite(prior) & (prior > 1e-3)
        scale = float(np.median(rho[seen] / prior[seen])) if seen.any() else np.nan
    if splats is not None:
        rho = np.concatenate([rho, splats.reflectance(sensor)])
        rho_flat = np.concatenate([rho_flat, splats.reflectance(sensor_flat)])
    return Inversion(rho, sensor, rho_flat, sensor_flat, prior_all, scale, residuals, shadow)
