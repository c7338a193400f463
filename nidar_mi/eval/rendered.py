"""Held-out evaluation: every method's intensity on the same camera-visible LiDAR returns.

One *frame* is a (scene, camera) pair of a rendered scene (``DATA/renders/<scene>/``, written by
:func:`nidar_mi.simulate.render_scene`). Its evaluation points are the LiDAR returns the camera
sees: in front of it, inside the image and not hidden behind the rendered depth
(:func:`nidar_mi.geometry.camera_returns`), exactly the returns of the training frames.

**Ground truth** is the range-compensated physical intensity ``g·ρ·cosθ·exp(-2αd)``
(:func:`nidar_mi.lidar.return_model.compensate`) on the metric scale
``clip(I / intensity_scale, 0, 1)`` (:func:`nidar_mi.eval.metrics.scale_intensity`, LiDAR4D's
convention; ``intensity_scale`` comes from the dataset's ``meta.json``).

**Methods** (a)-(g): the baselines and NIDAR variants this evaluation compares (keys in
:data:`METHODS`), each an (N,) prediction on the [0, 1] scale at the same points:

==============  ==================================================================================
key             prediction
==============  ==================================================================================
rgb_twin        (a) the return model on the scene's RGB-only twin, same seed, compensated and
                scaled like the ground truth, at the same (ring, column); 0 where the twin
                reports no return there
luminance       (b) Rec. 709 luminance of the linearised camera image at the projected point
class_const     (c) mean scaled intensity of the training points of the same material name
carla           (d) ``exp(-0.004 d)``
nidar_no_irnet  (e) the STN pseudo-NIR at the point through its own calibration, fitted on the
                training split like NIDAR's (distance encoding + quantile map)
nidar_ihat      (f) IRNet's dense head Î at the point, raw (clipped to [0, 1])
nidar_full      (g) :meth:`NidarModel.point_intensity`: R through the weights' default sensor
                profile (``profiles/sim-905.json``, else the distance encoding + quantile map)
==============  ==================================================================================

**Metrics** per frame and method: point RMSE/MAE/Spearman
(:func:`~nidar_mi.eval.metrics.point_metrics`); map RMSE/MedAE/PSNR/SSIM(/LPIPS) on the
sparse camera-projection map (each visible return splatted to its nearest pixel, nearest
return wins; metrics over the occupied pixels, :func:`~nidar_mi.eval.metrics.map_metrics`);
and SSIM/PSNR on the LiDAR range image (rings x columns), restricted to the same returns.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import NidarError
from .baselines import ClassConstant, carla, luminance_rho
from .metrics import map_metrics, point_metrics, psnr, scale_intensity, ssim

__all__ = [
    "METHODS",
    "METHOD_LABELS",
    "FrameData",
    "FrameResult",
    "load_render_frames",
    "predict_frame",
    "evaluate_frame",
    "METRIC_COLUMNS",
    "mean_table",
    "result_rows",
]

METHODS = (
    "rgb_twin",
    "luminance",
    "class_const",
    "carla",
    "nidar_no_irnet",
    "nidar_ihat",
    "nidar_full",
)
"""Method keys, in the order of the methods (a)-(g) of the module docstring."""

METHOD_LABELS = {
    "rgb_twin": "(a) RGB-asset physics",
    "luminance": "(b) RGB luminance as ρ",
    "class_const": "(c) constant per class",
    "carla": "(d) CARLA exp(-0.004 d)",
    "nidar_no_irnet": "(e) NIDAR w/o IRNet",
    "nidar_ihat": "(f) NIDAR Î direct",
    "nidar_full": "(g) NIDAR-Full",
}


@dataclass
class FrameData:
    """The camera-visible returns of one rendered (scene, camera) frame.

    Attributes:
        scene: scene name.
        camera: camera id.
        xyz: (N, 3) float64 points in the LiDAR frame, m.
        range_m: (N,) float64 ranges, m.
        gt: (N,) float64 ground-truth intensity on the [0, 1] scale.
        ring: (N,) int64 ring (row of the range image).
        column: (N,) int64 column of the range image.
        material: (N,) str material name of each point.
        uv: (N, 2) float64 pixel coordinates.
        rgb: (H, W, 3) uint8 camera image.
        depth: (H, W) float32 camera z-depth, m.
        camera_model: the :class:`~nidar_mi.geometry.CameraModel`.
        grid_shape: (rings, columns) of the LiDAR range image.
        scene_path: scene XML (for the RGB-twin scan).
        params: scene parameters the render used.
        seed: scan seed the render used.
        physics: (N,) float64 noise-free intensity on the ``gt`` scale, ``g·ρ·cos θ·exp(−2αd)``
            from the renderer's exact ρ and cos θ of each return (without the receiver noise
            of ``gt``); None where the render stores neither.
    """

    scene: str
    camera: str
    xyz: np.ndarray
    range_m: np.ndarray
    gt: np.ndarray
    ring: np.ndarray
    column: np.ndarray
    material: np.ndarray
    uv: np.ndarray
    rgb: np.ndarray
    depth: np.ndarray
    camera_model: Any
    grid_shape: tuple[int, int]
    scene_path: str = ""
    params: dict = field(default_factory=dict)
    seed: int | None = None
    physics: np.ndarray | None = None


@dataclass
class FrameResult:
    """Predictions and metrics of one frame.

    Attributes:
        frame: the evaluated frame.
        pred: method -> (N,) prediction on the [0, 1] scale.
        point: method -> :func:`point_metrics` dict.
        camera_map: method -> :func:`map_metrics` dict on the camera projection.
        range_image: method -> ``{"ssim", "psnr"}`` on the LiDAR range image.
        maps: ``"gt"`` and method -> (H, W) sparse camera maps; ``"mask"`` the occupied pixels.
    """

    frame: FrameData
    pred: dict[str, np.ndarray]
    point: dict[str, dict]
    camera_map: dict[str, dict]
    range_image: dict[str, dict]
    maps: dict[str, np.ndarray]


def load_render_frames(
    render_dir: str, intensity_scale: float, lidar_id: str | None = None
) -> list[FrameData]:
    """The camera-visible returns of every camera of one rendered scene.

    Args:
        render_dir: ``DATA/renders/<scene>`` (manifest.json, ``<lidar>/points.npz``, per-camera
            ``rgb.png`` and ``depth.exr``).
        intensity_scale: divisor of the metric scale (the dataset's ``intensity_scale``).
        lidar_id: LiDAR to evaluate; None takes the first by id.

    Returns:
        One :class:`FrameData` per camera, sorted by camera id.
    """
    from ..geometry import camera_returns
    from ..render_folder import read_render

    r = read_render(render_dir, lidar_id)
    manifest, lparams, pts = r.manifest, r.parameters, r.points
    gt_all = scale_intensity(r.compensated, intensity_scale)
    names = np.asarray(pts["material_names"]).astype(str)
    mat = np.asarray(pts["material"], dtype=np.int64)
    mat_name = np.where(mat >= 0, names[np.clip(mat, 0, max(len(names) - 1, 0))], "")
    grid = (int(lparams["rings"]), int(lparams["horizontal_resolution"]))
    scene = os.path.basename(os.path.normpath(render_dir))
    xyz = np.asarray(pts["xyz"], dtype=np.float64)
    physics = _noise_free(pts, lparams, intensity_scale)
    frames = []
    for cam in r.cameras:
        visible = camera_returns(xyz, cam.model, depth_image=cam.depth)
        idx = visible.index
        frames.append(
            FrameData(
                scene=scene,
                camera=cam.name,
                xyz=xyz[idx],
                range_m=np.asarray(pts["range"], dtype=np.float64)[idx],
                gt=gt_all[idx],
                ring=np.asarray(pts["ring"], dtype=np.int64)[idx],
                column=np.asarray(pts["column"], dtype=np.int64)[idx],
                material=mat_name[idx],
                uv=visible.uv,
                rgb=cam.rgb8(),
                depth=cam.depth,
                camera_model=cam.model,
                grid_shape=grid,
                scene_path=manifest.get("scene", ""),
                params=dict(manifest.get("params", {})),
                seed=manifest.get("seed"),
                physics=None if physics is None else physics[idx],
            )
        )
    return frames


def _noise_free(pts: dict, lparams: dict, intensity_scale: float) -> np.ndarray | None:
    """(N,) ``g·ρ·cos θ·exp(−2αd)`` of every return on the metric scale (None: no ρ, cos θ)."""
    from ..lidar.return_model import expected_intensity

    if "reflectance" not in pts or "cos_incidence" not in pts:
        return None
    value = expected_intensity(
        float(lparams["gain"]),
        np.asarray(pts["reflectance"], dtype=np.float64),
        np.asarray(pts["range"], dtype=np.float64),
        np.asarray(pts["cos_incidence"], dtype=np.float64),
        float(lparams["atmospheric_extinction"]),
        "compensated",
    )
    return scale_intensity(value, intensity_scale)


def predict_frame(
    frame: FrameData,
    model,
    *,
    class_const: ClassConstant | None = None,
    pseudo_calibration=None,
    twin_pred: np.ndarray | None = None,
    maps: dict[str, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """Every available method's (N,) prediction on the [0, 1] scale at the frame's points.

    Args:
        frame: the frame.
        model: :class:`~nidar_mi.nidar.pipeline.NidarModel` (None skips (e)-(g)).
        class_const: fitted baseline (c) (None skips it).
        pseudo_calibration: calibration of the pseudo-NIR for (e) (None skips it).
        twin_pred: baseline (a) from :func:`twin_prediction` (None skips it).
        maps: precomputed ``model.predict_image(frame.rgb)``.

    Returns:
        method key -> (N,) float64, in :data:`METHODS` order.
    """
    from ..geometry import bilinear_sample

    out: dict[str, np.ndarray] = {}
    if twin_pred is not None:
        out["rgb_twin"] = np.asarray(twin_pred, dtype=np.float64)
    out["luminance"] = np.clip(luminance_rho(frame.rgb, frame.uv), 0.0, 1.0)
    if class_const is not None:
        out["class_const"] = class_const.predict(frame.material)
    out["carla"] = carla(frame.range_m)
    if model is not None:
        maps = maps if maps is not None else model.predict_image(frame.rgb)
        if pseudo_calibration is not None and "pseudo_nir" in maps:
            pn = bilinear_sample(maps["pseudo_nir"], frame.uv)
            out["nidar_no_irnet"] = pseudo_calibration(pn, frame.range_m).astype(np.float64)
        out["nidar_ihat"] = np.clip(bilinear_sample(maps["I_hat"], frame.uv), 0.0, 1.0)
        res = model.point_intensity(
            frame.xyz,
            [frame.camera_model],
            [frame.rgb],
            depth_images=[frame.depth],
            maps=[maps],
        )
        out["nidar_full"] = res.intensity.astype(np.float64)
    for k, v in out.items():
        if v.shape != frame.gt.shape or not np.all(np.isfinite(v)):
            raise NidarError(f"{frame.scene}/{frame.camera}: method {k} gave no finite values")
    return {k: out[k] for k in METHODS if k in out}


def _camera_maps(frame: FrameData, values: dict[str, np.ndarray]):
    from ..geometry import splat_points

    return splat_points(frame.xyz, values, frame.camera_model, depth_image=frame.depth)


def _range_image(frame: FrameData, values: np.ndarray) -> np.ndarray:
    img = np.zeros(frame.grid_shape, dtype=np.float64)
    img[frame.ring, frame.column] = values
    return img


def evaluate_frame(
    frame: FrameData, pred: dict[str, np.ndarray], *, lpips: bool = False
) -> FrameResult:
    """Metrics of every method's prediction on one frame (all on the [0, 1] scale).

    Args:
        frame: the frame (its ``gt`` is the reference).
        pred: method -> (N,) prediction, as from :func:`predict_frame`.
        lpips: compute LPIPS on the camera maps (needs cached AlexNet weights).
    """
    if frame.gt.size == 0:
        raise NidarError(f"{frame.scene}/{frame.camera}: the camera sees no LiDAR return")
    maps, mask = _camera_maps(frame, {"gt": frame.gt, **pred})
    rmask = np.zeros(frame.grid_shape, dtype=bool)
    rmask[frame.ring, frame.column] = True
    gt_r = _range_image(frame, frame.gt)
    point, cam, rimg = {}, {}, {}
    for k, p in pred.items():
        point[k] = point_metrics(p, frame.gt)
        cam[k] = map_metrics(maps[k], maps["gt"], mask, lpips=lpips)
        pr = _range_image(frame, p)
        rimg[k] = {"ssim": ssim(pr, gt_r, rmask), "psnr": psnr(pr, gt_r, rmask)}
    maps = {k: v.astype(np.float32) for k, v in maps.items()} | {"mask": mask}
    return FrameResult(frame, pred, point, cam, rimg, maps)


def result_rows(results: Sequence[FrameResult], group: str) -> list[dict[str, Any]]:
    """Flat rows (one per frame and method) for the CSV/JSON tables.

    Columns: group, scene, camera, method, n_points, point_rmse, point_mae, spearman,
    map_rmse, map_medae, map_psnr, map_ssim, map_lpips, ri_ssim, ri_psnr.
    """
    rows = []
    for r in results:
        for k in r.pred:
            c, p, ri = r.camera_map[k], r.point[k], r.range_image[k]
            rows.append(
                {
                    "group": group,
                    "scene": r.frame.scene,
                    "camera": r.frame.camera,
                    "method": k,
                    "n_points": p["n"],
                    "point_rmse": p["rmse"],
                    "point_mae": p["mae"],
                    "spearman": p["spearman"],
                    "map_rmse": c["rmse"],
                    "map_medae": c["medae"],
                    "map_psnr": c["psnr"],
                    "map_ssim": c["ssim"],
                    "map_lpips": c["lpips"],
                    "ri_ssim": ri["ssim"],
                    "ri_psnr": ri["psnr"],
                }
            )
    return rows


METRIC_COLUMNS = (
    "point_rmse",
    "point_mae",
    "spearman",
    "map_rmse",
    "map_medae",
    "map_psnr",
    "map_ssim",
    "map_lpips",
    "ri_ssim",
    "ri_psnr",
)


def _nanmean(values: list) -> float | None:
    vals = [float(v) for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(vals)) if vals else None


def mean_table(
    rows: Sequence[dict[str, Any]], key: Callable[[dict], str] = lambda r: r["method"]
) -> list[dict[str, Any]]:
    """Per-method means over frames (unweighted; ``None`` entries and NaN skipped).

    Returns:
        One row per method (first-seen order) with ``method``, ``frames`` and the metric means.
    """
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r)
    out = []
    for name, rs in groups.items():
        row = {"method": name, "frames": len(rs)}
        for col in METRIC_COLUMNS:
            if col in rs[0]:
                row[col] = _nanmean([r.get(col) for r in rs])
        out.append(row)
    return out
