"""The whole evaluation behind ``python -m nidar_mi.evaluate``: every group, tables, figures.

Held-out generated scenes (a dataset's ``test`` split), hand-made scene files, scenes of held-out
materials and the IRNet ablations (scored with :mod:`nidar_mi.eval.rendered`), and the real data:
KITTI leave-one-frame-out (:mod:`nidar_mi.eval.loo`) and the held-out RGB/NIR photos
(:mod:`nidar_mi.eval.photos`), both via :mod:`nidar_mi.eval.real`. The results are written as
``OUT/results.{md,csv,json}`` and ``OUT/figures/*.png`` (no figure of real data), published whole
when everything succeeded; renders and ablation runs are cached outside ``OUT``
(:func:`evaluation_cache`; the KITTI frames in the user's cache, :mod:`nidar_mi.datasets.paths`).

The run is described by an :class:`EvaluateOptions` (the command line builds one from its
arguments). Scanning and rendering scenes (baseline (a), ``scenes``, ``heldout_materials``)
needs a Mitsuba variant set by the caller (:func:`nidar_mi.backend.set_variant`; the command
sets ``llvm_ad_spectral``).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time

from ..errors import NidarError
from ..io.ownership import Owner

__all__ = ["EvaluateOptions", "OWNER", "run_evaluation", "evaluation_cache"]

#: Who writes an evaluation's output folder (:mod:`nidar_mi.io.ownership`).
OWNER = Owner(
    "evaluate", "results", names=("results.md", "results.csv", "results.json", "figures/*")
)

log = logging.getLogger("nidar_mi.evaluate")


@dataclasses.dataclass(frozen=True)
class EvaluateOptions:
    """What one evaluation run scores and where it writes (paths are folders unless stated)."""

    out: str
    """Output folder: ``results.md``, ``results.csv``, ``results.json``, ``figures/*.png``."""
    data: str | None = None
    """Dataset folder (``meta.json``, ``renders/``, splits); None evaluates real data only."""
    weights: str | None = None
    """NIDAR weights folder; None: the shipped model."""
    scenes: str | None = None
    """Folder of hand-made scene XML files rendered and scored too (needs ``data``)."""
    heldout_materials: str | None = None
    """Folder of scenes made of held-out materials (needs ``data``)."""
    kitti: tuple[str, ...] = ()
    """KITTI folders (``velodyne/``, ``image_2/``, ``calib/``) for leave-one-frame-out."""
    photos: str | None = None
    """RGB/NIR photo pairs (``<category>/NNNN_rgb.jpg``); also fits baseline (i)."""
    ablation: bool = False
    """Train and score the IRNet ablations (needs ``data``)."""
    split: str = "test"
    """Dataset split of the held-out generated scenes."""
    twin: bool = True
    """Score baseline (a), the RGB-twin Mitsuba scans."""
    lpips: bool = False
    """Also score LPIPS (an error when the lpips package or its weights are missing)."""
    figures: int = 3
    """Frames per group with map figures (0: none)."""
    cache: str | None = None
    """Folder of the renders and ablation runs a rerun reuses; None: ``DATA/cache/evaluate``."""
    overwrite: bool = False
    """Replace ``out`` even when it holds other files."""
    progress: bool = True
    """Show progress bars of the real-data evaluations."""
    workers: int | None = None
    """Hand-made scenes rendered at once on Ray (None: one after the other, without Ray)."""
    ray_address: str | None = None
    """An existing Ray cluster to render the hand-made scenes on."""
    command: str = ""
    """How the run was started, recorded in the results (empty: not recorded)."""

    @property
    def scans_scenes(self) -> bool:
        """Whether the run casts Mitsuba scans (baseline (a) or rendered scenes): it then
        needs a Mitsuba variant."""
        return bool(self.data) and bool(self.twin or self.scenes or self.heldout_materials)


def evaluation_cache(options: EvaluateOptions) -> str:
    """The evaluation's cache: ``options.cache``, default ``DATA/cache/evaluate``.

    It holds ``renders/<scene>`` (the hand-made scenes rendered with the dataset's parameters;
    reused while their render request holds), ``renders_heldout/<scene>`` (the scenes of
    held-out materials, likewise) and ``ablation/<key>/<run>`` (the ablation runs;
    ``key`` hashes the dataset, the STN and the settings, so a run is reused only for the
    same inputs). Nothing of it is written into ``OUT``.
    """
    return options.cache or os.path.join(options.data, "cache", "evaluate")


def run_evaluation(options: EvaluateOptions) -> dict:
    """Everything the evaluation does; returns the results payload (also written to OUT).

    ``OUT`` (results and figures) is published whole when everything succeeded
    (:func:`nidar_mi.io.atomic.staged_directory`); caches go to :func:`evaluation_cache`.

    Raises:
        NidarError: a missing or inconsistent input, LPIPS requested but unavailable, no
            Mitsuba variant set while :attr:`EvaluateOptions.scans_scenes`.
    """
    from ..extras import require
    from ..io.atomic import check_output_folder, staged_directory

    t0 = time.perf_counter()
    out = options.out
    publish = dict(owner=OWNER, overwrite=options.overwrite, inputs=_inputs(options))
    require("nidar", "evaluate")  # the NIDAR model, always loaded
    check_output_folder(out, **publish)
    meta = _check_inputs(options)
    _check_environment(options)
    model = _load_model(options, meta)
    with staged_directory(out, **publish) as stage:
        fig_dir = os.path.join(stage, "figures")
        os.makedirs(fig_dir)
        payload = _evaluate(options, meta, model, fig_dir)
        payload["figures"] = [
            os.path.join(out, os.path.relpath(p, stage)) for p in payload["figures"]
        ]
        if not payload["figures"]:
            os.rmdir(fig_dir)
        payload["seconds"] = time.perf_counter() - t0
        _write(stage, payload, out)
    return payload


def _inputs(options: EvaluateOptions) -> list[str | None]:
    """Every file and folder the run reads (the output must not hold one); the cache too,
    which a replaced output would take with it."""
    o = options
    extra = [o.cache or (evaluation_cache(o) if o.data else None)]
    return [o.data, o.weights, o.scenes, o.heldout_materials, *o.kitti, o.photos, *extra]


def _real_data(options: EvaluateOptions) -> bool:
    """Whether ``kitti`` or ``photos`` hold anything to score (else both would be skipped)."""
    from ..datasets.kitti_objects import frame_ids
    from ..datasets.rgbnir import list_pairs

    if any(frame_ids(d) for d in options.kitti):
        return True
    if options.photos:
        try:
            return bool(list_pairs(options.photos))
        except NidarError:
            return False
    return False


def _check_inputs(options: EvaluateOptions) -> dict | None:
    """The dataset's meta (None without ``data``), after checking every input exists."""
    from ..training_frames import load_meta

    o = options
    if not (o.data or o.kitti or o.photos):
        raise NidarError("nothing to evaluate: give `data`, `kitti` and/or `photos`")
    if isinstance(o.figures, bool) or not isinstance(o.figures, int) or o.figures < 0:
        raise NidarError(f"`figures` must be an integer >= 0 (got {o.figures})")
    if o.scenes and not os.path.isdir(o.scenes):
        raise NidarError(f"`scenes`: no such directory {o.scenes}")
    if o.heldout_materials and not os.path.isdir(o.heldout_materials):
        raise NidarError(f"`heldout_materials`: no such directory {o.heldout_materials}")
    if not o.data:
        for name in ("scenes", "ablation", "heldout_materials"):
            if getattr(o, name):
                raise NidarError(f"`{name}` needs `data` (the training scenes)")
        if not _real_data(o):
            given = [f"`kitti` {d}" for d in o.kitti] + [f"`photos` {o.photos}"] * bool(o.photos)
            raise NidarError(
                f"nothing to evaluate: no KITTI frame or RGB/NIR photo pair in {', '.join(given)}"
            )
        return None
    meta = load_meta(o.data)
    splits = meta.get("scenes", {})
    if not splits.get(o.split):
        raise NidarError(f"{o.data}: the dataset has no '{o.split}' scenes")
    if not splits.get("train"):
        raise NidarError(f"{o.data}: the dataset has no 'train' scenes to fit baselines on")
    renders = os.path.join(o.data, "renders")
    for name in splits[o.split] + splits["train"]:
        if not os.path.isfile(os.path.join(renders, name, "manifest.json")):
            raise NidarError(f"{o.data}: scene {name} is not rendered under {renders}")
    return meta


def _check_environment(options: EvaluateOptions) -> None:
    """Ray for parallel renders, LPIPS when asked for, a Mitsuba variant for the scans."""
    from .metrics import lpips_unavailable_reason

    if options.scenes or options.heldout_materials:
        from ..tasks import check_parallel

        check_parallel(options.workers, options.ray_address)
    if options.lpips:
        reason = lpips_unavailable_reason()
        if reason:
            raise NidarError(f"`lpips`: LPIPS is unavailable: {reason}")
    if options.scans_scenes:
        import mitsuba as mi

        if mi.variant() is None:
            raise NidarError(
                "the scans need a Mitsuba variant: call "
                "nidar_mi.backend.set_variant('llvm_ad_spectral') first"
            )


def _load_model(options: EvaluateOptions, meta: dict | None):
    """The NIDAR model; the rendered groups need its source-domain calibration."""
    from ..nidar.pipeline import NidarModel

    model = NidarModel.load(options.weights)
    if meta is not None and model.calibration is None:
        raise NidarError(f"{model.weights_dir}: no calibration.json beside the weights")
    return model


def _evaluate(options: EvaluateOptions, meta: dict | None, model, fig_dir: str) -> dict:
    """The evaluation proper; figures go to ``fig_dir``."""
    from .metrics import lpips_unavailable_reason

    payload: dict = {
        "command": options.command,
        "data": os.path.abspath(options.data) if options.data else None,
        "weights": str(model.weights_dir),
        "lpips": lpips_unavailable_reason() if options.lpips else "not requested",
        "groups": {},
        "figures": [],
    }
    if meta is not None:
        _synthetic(options, meta, model, fig_dir, payload)
    linear = _photos(options, model, payload) if options.photos else None
    if options.kitti:
        _kitti(options, model, linear, payload)
    return payload


def _photos(options: EvaluateOptions, model, payload: dict):
    """The held-out RGB/NIR photo table into ``payload["photos"]``; returns baseline (i)'s
    linear RGB -> NIR map (None when the photos are absent)."""
    from ..datasets.rgbnir import list_pairs

    try:
        list_pairs(options.photos)
    except NidarError as e:
        log.warning("skipping the RGB/NIR photos: %s", e)
        payload["photos"] = {"skipped": str(e)}
        return None
    from .real import evaluate_photos, fit_linear_nir

    log.info("RGB/NIR photos: the held-out table")
    payload["photos"] = evaluate_photos(options.photos, model, progress=options.progress)
    linear, _ = fit_linear_nir(options.photos)
    return linear


def _kitti(options: EvaluateOptions, model, linear, payload: dict) -> None:
    """KITTI leave-one-frame-out into ``payload["kitti"]`` (skipped without frames)."""
    from ..datasets.kitti_objects import frame_ids

    present = [d for d in options.kitti if frame_ids(d)]
    if not present:
        msg = f"no KITTI frames at {', '.join(options.kitti)}"
        log.warning("skipping the real-data evaluation: %s", msg)
        payload["kitti"] = {"skipped": msg}
        return
    from .real import evaluate_kitti_loo

    log.info("KITTI leave-one-frame-out")
    payload["kitti"] = evaluate_kitti_loo(
        present, model, linear_nir=linear, progress=options.progress
    )
    if linear is None:
        payload["kitti"]["note"] = "row (i) needs the RGB/NIR photos (--photos)"


@dataclasses.dataclass(frozen=True)
class _Rendered:
    """What every group of rendered scenes shares: the dataset's scale, its render settings and
    the baselines fitted on its training split."""

    scale: float
    render_opts: dict
    scoring: dict


def _synthetic(options: EvaluateOptions, meta: dict, model, fig_dir: str, payload: dict) -> None:
    """The groups on rendered scenes: held-out generated, hand-made, held-out materials,
    ablations."""
    ctx = _fit_baselines(options, meta, model, payload)
    _generated(options, meta, model, ctx, fig_dir, payload)
    if options.scenes:
        _handmade(options, model, ctx, fig_dir, payload)
    if options.heldout_materials:
        _heldout_materials(options, model, ctx, payload)
    if options.ablation:
        from .ablation import run_ablation

        log.info("ablation: training the IRNet variants")
        stn = model.weights_dir / "stn.safetensors"
        payload["ablation"] = run_ablation(
            options.data,
            os.path.join(evaluation_cache(options), "ablation", _ablation_key(meta, stn)),
            stn,
            split=options.split,
        )


def _fit_baselines(options: EvaluateOptions, meta: dict, model, payload: dict) -> _Rendered:
    """Baselines (c) and (e) fitted on the training split; the ground truth's definition into
    ``payload``."""
    from ..datasets.profile_fitting import fit_split_calibration
    from .heldout import fit_class_constant

    scale = float(meta.get("intensity_scale", 1.0))
    renders = os.path.join(options.data, "renders")
    payload["intensity_scale"] = scale
    payload["ground_truth"] = "clip(range-compensated intensity / intensity_scale, 0, 1)"
    log.info("fitting baselines (c) and (e) on the training split")
    train = [os.path.join(renders, n) for n in meta["scenes"]["train"]]
    class_const = fit_class_constant(train, scale)
    pseudo_cal = fit_split_calibration(model, options.data, "train", branch="pseudo_nir")
    scoring = dict(
        class_const=class_const,
        pseudo_calibration=pseudo_cal,
        twin=options.twin,
        lpips=options.lpips,
    )
    render_opts = dict(
        params=meta.get("params"), seed=int(meta.get("seed", 0)), spp=int(meta.get("spp", 16))
    )
    return _Rendered(scale=scale, render_opts=render_opts, scoring=scoring)


def _generated(options, meta: dict, model, ctx: _Rendered, fig_dir: str, payload: dict) -> None:
    """The dataset's held-out generated scenes (and the decomposition against the true maps
    when the frames carry them)."""
    from ..training_frames import frame_has, list_frames
    from .heldout import evaluate_renders

    names = meta["scenes"][options.split]
    renders = os.path.join(options.data, "renders")
    log.info("evaluating the %d '%s' scenes", len(names), options.split)
    res = evaluate_renders(
        [os.path.join(renders, n) for n in names], model, ctx.scale, **ctx.scoring
    )
    payload["groups"]["generated"] = _group(res, "generated", names)
    payload["figures"] += _figures(res, "generated", fig_dir, options.figures)
    frames = list_frames(options.data, options.split)
    if frames and all(frame_has(f, ("R_true", "S_true")) for f in frames):
        from .intrinsic import intrinsic_scores

        payload["intrinsic"] = intrinsic_scores(model, frames)


def _handmade(options, model, ctx: _Rendered, fig_dir: str, payload: dict) -> None:
    """The hand-made scene files, rendered with the dataset's settings, then scored."""
    from ..render_dataset import find_scenes
    from .heldout import evaluate_renders, render_scenes

    files = find_scenes(options.scenes)
    log.info("rendering and evaluating %d hand-made scenes", len(files))
    dirs = render_scenes(
        files,
        os.path.join(evaluation_cache(options), "renders"),
        **ctx.render_opts,
        workers=options.workers,
        ray_address=options.ray_address,
        progress=options.progress,
    )
    res = evaluate_renders(dirs, model, ctx.scale, **ctx.scoring)
    names = [os.path.basename(d) for d in dirs]
    note = (
        "Hand-made scenes (never used in training); their materials may be absent from the "
        "training scenes, in which case baseline (c) predicts the global training mean."
    )
    payload["groups"]["handmade"] = _group(res, "handmade", names, note)
    payload["figures"] += _figures(res, "handmade", fig_dir, options.figures)


def _heldout_materials(options, model, ctx: _Rendered, payload: dict) -> None:
    """The scenes of held-out materials, scored on those materials' returns."""
    from ..render_dataset import find_scenes
    from .heldout import evaluate_renders, heldout_material_scores, render_scenes

    files = find_scenes(options.heldout_materials)
    log.info("rendering and evaluating %d scenes of held-out materials", len(files))
    cache = os.path.join(evaluation_cache(options), "renders_heldout")
    dirs = render_scenes(files, cache, **ctx.render_opts)
    res = evaluate_renders(dirs, model, ctx.scale, **ctx.scoring)
    class_const = ctx.scoring["class_const"]
    scores = heldout_material_scores(res, class_const.classes)
    payload["heldout_materials"] = scores | {
        "scenes": [os.path.basename(d) for d in dirs],
        "train_materials": sorted(map(str, class_const.classes)),
    }


def _group(results, name: str, scenes: list[str], note: str = "") -> dict:
    from .rendered import mean_table, result_rows

    rows = result_rows(results, name)
    return {"scenes": scenes, "rows": rows, "mean": mean_table(rows), "note": note}


def _figures(results, group: str, fig_dir: str, count: int) -> list[str]:
    import numpy as np

    from .figures import maps_figure, scatter_figure
    from .rendered import METHOD_LABELS

    paths = []
    for r in results[: max(count, 0)]:
        f = r.frame
        path = os.path.join(fig_dir, f"{group}_{f.scene}_{f.camera}_maps.png")
        maps_figure(
            f.rgb,
            f.uv,
            f.gt,
            r.pred,
            path,
            labels=METHOD_LABELS,
            title=f"{f.scene} / {f.camera}: intensity at the camera-visible LiDAR returns",
        )
        paths.append(path)
    if results:
        keys = list(results[0].pred)
        gt = np.concatenate([r.frame.gt for r in results])
        preds = {k: np.concatenate([r.pred[k] for r in results]) for k in keys}
        path = os.path.join(fig_dir, f"{group}_scatter.png")
        scatter_figure(
            gt, preds, path, labels=METHOD_LABELS, title=f"{group}: predicted vs GT, all points"
        )
        paths.append(path)
    return paths


def _ablation_key(meta: dict, stn) -> str:
    """16 hex digits naming the ablation runs of one dataset, STN and settings."""
    from ..io.cache_key import cache_key, file_sha256
    from .ablation import AblationSettings

    data = {k: meta.get(k) for k in ("request", "frames", "intensity_scale")}
    stn_hash = file_sha256(stn) if os.path.isfile(stn) else None
    return cache_key([data, stn_hash, AblationSettings().to_dict()])


def _write(stage: str, payload: dict, out: str) -> None:
    """Write the tables into ``stage`` (figure paths in ``payload`` name their place in
    ``out``)."""
    from . import tables

    md, csv_rows = _tables(payload)
    if payload["figures"]:
        md.append("## Figures\n\n")
        md.extend(f"- `{os.path.relpath(p, out)}`\n" for p in payload["figures"])
    tables.write_csv(os.path.join(stage, "results.csv"), csv_rows)
    tables.write_json(os.path.join(stage, "results.json"), payload)
    tables.write_text(os.path.join(stage, "results.md"), "".join(md))


def _tables(payload: dict) -> tuple[list[str], list[dict]]:
    """``results.md`` as a list of parts (figures left out) and the rows of ``results.csv``."""
    from . import tables
    from .rendered import METHOD_LABELS

    titles = {"generated": "Held-out generated scenes", "handmade": "Hand-made scenes"}
    md = ["# NIDAR evaluation\n\n"]
    if payload["command"]:
        md.append(f"Command: `{payload['command']}`\n\n")
    md.append(
        f"Weights: `{payload['weights']}`; data: "
        + (f"`{payload['data']}`" if payload["data"] else "none")
        + f"; LPIPS: {payload['lpips'] or 'computed'}.\n\n"
    )
    if "ground_truth" in payload:
        md.append(
            f"Ground truth of the rendered scenes: {payload['ground_truth']} with "
            f"intensity_scale = {payload['intensity_scale']:g}.\n\n"
        )
    csv_rows = []
    for key, group in payload["groups"].items():
        md.append(tables.group_markdown(titles.get(key, key), group, METHOD_LABELS) + "\n")
        csv_rows += group["rows"] + [
            {"group": key, "scene": "mean", "camera": "", **r} for r in group["mean"]
        ]
    if "intrinsic" in payload:
        md.append(tables.intrinsic_markdown(payload["intrinsic"]) + "\n")
    if "heldout_materials" in payload:
        h = payload["heldout_materials"]
        md.append(tables.heldout_materials_markdown(h, METHOD_LABELS) + "\n")
        csv_rows += [{"group": "heldout_materials", **r} for r in h["rows"]]
    if "kitti" in payload:
        md.append(tables.loo_markdown(payload["kitti"]) + "\n")
        csv_rows += [{"group": "kitti_loo", **r} for r in payload["kitti"].get("rows", [])]
    if "photos" in payload:
        md.append(tables.photos_markdown(payload["photos"]) + "\n")
        csv_rows += [{"group": "photos", **r} for r in payload["photos"].get("rows", [])]
    if "ablation" in payload:
        md.append(tables.ablation_markdown(payload["ablation"]) + "\n")
    return md, csv_rows
