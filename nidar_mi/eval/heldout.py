"""Scene-level pieces of the held-out evaluation: fitting baselines, rendering, scanning twins.

* :func:`fit_class_constant`: baseline (c) on the training scenes' returns, by material name.
* :func:`twin_prediction`: baseline (a) at a frame's points from the RGB-twin scan.
* :func:`render_scenes`: cached renders of scene files (the hand-made scenes).
* :func:`evaluate_renders`: every frame of a set of rendered scenes through
  :func:`~nidar_mi.eval.rendered.predict_frame` and :func:`~nidar_mi.eval.rendered.evaluate_frame`.
* :func:`heldout_material_scores`: the methods on the returns whose material no training scene
  has (scenes from ``python -m nidar_mi.scenegen --materials heldout``).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import NidarError
from .baselines import ClassConstant
from .metrics import scale_intensity
from .rendered import (
    FrameData,
    FrameResult,
    evaluate_frame,
    load_render_frames,
    predict_frame,
)

__all__ = [
    "evaluate_renders",
    "fit_class_constant",
    "heldout_material_scores",
    "render_scenes",
    "twin_prediction",
]

log = logging.getLogger("nidar_mi.evaluate")


def fit_class_constant(
    render_dirs: Sequence[str], intensity_scale: float, lidar_id: str | None = None
) -> ClassConstant:
    """Baseline (c): mean scaled intensity per material name over every return of the scenes.

    Args:
        render_dirs: rendered training scenes.
        intensity_scale: divisor of the metric scale.
        lidar_id: LiDAR to read; None takes the first by id.
    """
    from ..render_folder import read_render

    labels, values = [], []
    for rdir in render_dirs:
        r = read_render(rdir, lidar_id)
        names = np.asarray(r.points["material_names"]).astype(str)
        mat = np.asarray(r.points["material"], dtype=np.int64)
        ok = mat >= 0
        labels.append(names[mat[ok]])
        values.append(scale_intensity(r.compensated, intensity_scale)[ok])
    if not labels:
        raise NidarError("class constant: no training scenes")
    return ClassConstant.fit(np.concatenate(labels), np.concatenate(values))


def twin_prediction(frame: FrameData, twin, intensity_scale: float) -> np.ndarray:
    """Baseline (a) at the frame's points from an RGB-twin :class:`ScanResult`.

    The twin's intensity at the same (ring, column), compensated with the twin's own range
    like the ground truth and put on the metric scale; 0 where the twin has no return.
    """
    from ..lidar.return_model import compensate

    r, c = frame.ring, frame.column
    valid = twin.valid[r, c]
    inten = compensate(
        twin.intensity[r, c].astype(np.float32),
        twin.range[r, c].astype(np.float32),
        twin.config.intensity_mode,
    )
    return np.where(valid, scale_intensity(inten, intensity_scale), 0.0)


def render_scenes(
    scene_files: Sequence[str],
    cache_dir: str,
    *,
    params: dict[str, str] | None = None,
    seed: int = 0,
    spp: int = 16,
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = False,
) -> list[str]:
    """Render scenes into ``cache_dir/<name>`` unless already rendered with the same request.

    One task per scene (:mod:`nidar_mi.tasks`); a scene that fails is reported and the others
    are rendered before the error is raised.

    Args:
        scene_files: scene XML files.
        cache_dir: folder of the renders.
        params: scene parameters, passed only to scenes that use them (``$name`` in the XML).
        seed: scan seed.
        spp: camera samples per pixel.
        workers: scenes at once on a local Ray runtime (None: one after the other).
        ray_address: run on this Ray cluster instead.
        progress: show a progress bar.

    Returns:
        The render folders, in the order of ``scene_files``.

    Raises:
        NidarError: a scene failed (:class:`~nidar_mi.tasks.TasksFailed`), or bad arguments.
    """
    from functools import partial

    from ..backend import worker_setup
    from ..render_dataset import scene_params
    from ..render_folder import is_current
    from ..render_session import RenderOptions
    from ..simulate import ensure_rendered
    from ..tasks import Task, run_tasks

    tasks, out = [], []
    for path in map(os.path.abspath, scene_files):
        name = os.path.splitext(os.path.basename(path))[0]
        rdir = os.path.join(os.path.abspath(cache_dir), name)
        opts = RenderOptions(
            path,
            formats=("npz",),
            seed=seed,
            spp=spp,
            params=scene_params(path, params),
            progress=False,
        )
        skip = partial(is_current, rdir, opts.key())
        tasks.append(Task(name, ensure_rendered, (opts, rdir), output=rdir, skip=skip))
        out.append(rdir)
    report = run_tasks(
        tasks,
        workers=workers,
        address=ray_address,
        setup=worker_setup(),
        progress=progress,
        desc="render",
        unit="scene",
    )
    report.raise_on_failure("scenes")
    return out


def evaluate_renders(
    render_dirs: Sequence[str],
    model,
    intensity_scale: float,
    *,
    class_const: ClassConstant | None = None,
    pseudo_calibration=None,
    twin: bool = True,
    lpips: bool = False,
    lidar_id: str | None = None,
    on_frame: Callable[[FrameResult], None] | None = None,
) -> list[FrameResult]:
    """Predict and score every camera frame of the rendered scenes.

    Args:
        render_dirs: rendered scenes (see :func:`load_render_frames`).
        model: :class:`~nidar_mi.nidar.pipeline.NidarModel`, or None for the baselines only.
        intensity_scale: divisor of the metric scale.
        class_const: fitted baseline (c).
        pseudo_calibration: baseline (e)'s calibration.
        twin: scan each scene's RGB-only twin for baseline (a) (needs Mitsuba and the XML).
        lpips: compute LPIPS on the camera maps.
        lidar_id: LiDAR to evaluate.
        on_frame: called with each result as soon as it is ready (figures, logging).
    """
    from .baselines import rgb_twin_scan

    results = []
    for rdir in render_dirs:
        frames = load_render_frames(rdir, intensity_scale, lidar_id)
        twin_scan = None
        if twin and frames:
            f0 = frames[0]
            if not os.path.isfile(f0.scene_path):
                raise NidarError(f"{rdir}: scene file {f0.scene_path} not found for the RGB twin")
            twin_scan = rgb_twin_scan(f0.scene_path, params=f0.params, seed=f0.seed, lidar=lidar_id)
        for frame in frames:
            if frame.gt.size == 0:
                continue
            tp = None if twin_scan is None else twin_prediction(frame, twin_scan, intensity_scale)
            pred = predict_frame(
                frame,
                model,
                class_const=class_const,
                pseudo_calibration=pseudo_calibration,
                twin_pred=tp,
            )
            res = evaluate_frame(frame, pred, lpips=lpips)
            log.debug("%s: %d returns scored", getattr(frame, "name", rdir), frame.gt.size)
            if on_frame is not None:
                on_frame(res)
            results.append(res)
    return results


#: Key of the noise-free physics among the scored values (reported apart, not as a method).
_CEILING = "physics_noise_free"


def heldout_material_scores(results: Sequence[FrameResult], train_materials) -> dict[str, object]:
    """Every method on the returns of materials no training scene has.

    Args:
        results: evaluated frames (:func:`evaluate_renders`).
        train_materials: material names of the training scenes' returns.

    Returns:
        ``{"materials": held-out names seen, "rows": per frame and method (``spearman``,
        ``rmse``, ``n_points``), "mean": per method (unweighted over frames, and ``pooled``:
        Spearman over all held-out returns together), "ceiling": the same scores of the
        noise-free physics (:attr:`FrameData.physics`) at the same returns, or None where a
        frame lacks it}``. The reference carries the receiver noise, which no method can
        predict: the ceiling is the best ranking of it to be expected.
    """
    from .metrics import rmse, spearman

    train = set(map(str, train_materials))
    rows, pooled, seen = [], {}, set()
    ceiling = all(r.frame.physics is not None for r in results)
    for r in results:
        mat = np.asarray(r.frame.material).astype(str)
        held = (mat != "") & ~np.isin(mat, list(train))
        if held.sum() < 2:
            continue
        seen |= set(mat[held])
        pred = dict(r.pred) | ({_CEILING: r.frame.physics} if ceiling else {})
        for k, p in pred.items():
            rows.append(
                {
                    "scene": r.frame.scene,
                    "camera": r.frame.camera,
                    "method": k,
                    "n_points": int(held.sum()),
                    "spearman": spearman(p[held], r.frame.gt[held]),
                    "rmse": rmse(p[held], r.frame.gt[held]),
                }
            )
            pooled.setdefault(k, ([], []))
            pooled[k][0].append(p[held])
            pooled[k][1].append(r.frame.gt[held])
    mean = []
    for k, (ps, gs) in pooled.items():
        rs = [x for x in rows if x["method"] == k]
        sp = [x["spearman"] for x in rs if np.isfinite(x["spearman"])]
        mean.append(
            {
                "method": k,
                "frames": len(rs),
                "n_points": int(sum(x["n_points"] for x in rs)),
                "spearman": float(np.mean(sp)) if sp else None,
                "pooled_spearman": spearman(np.concatenate(ps), np.concatenate(gs)),
                "rmse": float(np.mean([x["rmse"] for x in rs])),
            }
        )
    top = next((m for m in mean if m["method"] == _CEILING), None)
    return {
        "materials": sorted(seen),
        "rows": [x for x in rows if x["method"] != _CEILING],
        "mean": [m for m in mean if m["method"] != _CEILING],
        "ceiling": top,
    }
