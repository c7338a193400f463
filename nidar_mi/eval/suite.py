"""The whole evaluation behind ``python -m nidar_mi.evaluate``: every group, tables, figures.

Held-out generated scenes (a dataset's ``test`` split), hand-made scene files, scenes of held-out
materials and the IRNet ablations (scored with :mod:`nidar_mi.eval.frames`), and the real data:
KITTI leave-one-frame-out (:mod:`nidar_mi.eval.loo`) and the held-out RGB/NIR photos
(:mod:`nidar_mi.eval.photos`), both via :mod:`nidar_mi.eval.real`. The results are written as
``OUT/results.{md,csv,json}`` and ``OUT/figures/*.png`` (no figure of real data), published whole
when everything succeeded; renders and ablation runs are cached outside ``OUT``
(:func:`cache_dir`; the KITTI frames in the user's cache, :mod:`nidar_mi.datasets.paths`).
"""

from __future__ import annotations

import logging
import os
import time

from ..errors import NidarError

__all__ = ["run", "cache_dir"]

log = logging.getLogger("nidar_mi.evaluate")


def _group(results, name: str, scenes: list[str], note: str = "") -> dict:
    from .frames import mean_table, result_rows

    rows = result_rows(results, name)
    return {"scenes": scenes, "rows": rows, "mean": mean_table(rows), "note": note}


def _figures(results, group: str, fig_dir: str, count: int) -> list[str]:
    import numpy as np

    from .figures import maps_figure, scatter_figure
    from .frames import METHOD_LABELS

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


def cache_dir(args) -> str:
    """The evaluation's cache: ``--cache``, default ``DATA/cache/evaluate``.

    It holds ``renders/<scene>`` (the hand-made scenes rendered with the dataset's parameters;
    reused while their render request holds), ``renders_heldout/<scene>`` (the scenes of
    held-out materials, likewise) and ``ablation/<key>/<run>`` (the ablation runs;
    ``key`` hashes the dataset, the STN and the settings, so a run is reused only for the
    same inputs). Nothing of it is written into ``OUT``.
    """
    return args.cache or os.path.join(args.data, "cache", "evaluate")


def run(args, argv_text: str) -> dict:
    """Everything the command does; returns the results payload (also written to OUT).

    ``OUT`` (results and figures) is published whole when everything succeeded
    (:func:`nidar_mi.io.atomic.staged_directory`); caches go to :func:`cache_dir`.
    """
    from ..io.atomic import check_output_folder, staged_directory
    from ..nidar.pipeline import NidarModel
    from .metrics import lpips_unavailable_reason

    t0 = time.perf_counter()
    check_output_folder(args.out, overwrite=args.overwrite, marker="results.json")
    meta = _check_inputs(args)
    if args.scenes or args.heldout_materials:
        from ..tasks import check_parallel

        check_parallel(args.workers, args.ray_address)
    if args.lpips:
        reason = lpips_unavailable_reason()
        if reason:
            raise NidarError(f"--lpips: LPIPS is unavailable: {reason}")
    model = NidarModel.load(args.weights)
    if meta is not None and model.calibration is None:
        raise NidarError(f"{model.weights_dir}: no calibration.json beside the weights")
    if meta is not None and (not args.no_twin or args.scenes or args.heldout_materials):
        from ..backend import set_variant

        set_variant("llvm_ad_spectral")
    with staged_directory(args.out, overwrite=args.overwrite, marker="results.json") as stage:
        fig_dir = os.path.join(stage, "figures")
        os.makedirs(fig_dir)
        payload = _evaluate(args, argv_text, meta, model, fig_dir)
        payload["figures"] = [
            os.path.join(args.out, os.path.relpath(p, stage)) for p in payload["figures"]
        ]
        if not payload["figures"]:
            os.rmdir(fig_dir)
        payload["seconds"] = time.perf_counter() - t0
        _write(stage, payload, args.out)
    return payload


def _check_inputs(args) -> dict | None:
    """The dataset's meta (None without ``--data``), after checking every input exists."""
    from ..frames import load_meta

    if not (args.data or args.kitti or args.photos):
        raise NidarError("nothing to evaluate: give --data, --kitti and/or --photos")
    if args.scenes and not os.path.isdir(args.scenes):
        raise NidarError(f"--scenes: no such directory {args.scenes}")
    if args.heldout_materials and not os.path.isdir(args.heldout_materials):
        raise NidarError(f"--heldout-materials: no such directory {args.heldout_materials}")
    if not args.data:
        for flag, value in (
            ("--scenes", args.scenes),
            ("--ablation", args.ablation),
            ("--heldout-materials", args.heldout_materials),
        ):
            if value:
                raise NidarError(f"{flag} needs --data (the training scenes)")
        return None
    meta = load_meta(args.data)
    splits = meta.get("scenes", {})
    if not splits.get(args.split):
        raise NidarError(f"{args.data}: the dataset has no '{args.split}' scenes")
    if not splits.get("train"):
        raise NidarError(f"{args.data}: the dataset has no 'train' scenes to fit baselines on")
    renders = os.path.join(args.data, "renders")
    for name in splits[args.split] + splits["train"]:
        if not os.path.isfile(os.path.join(renders, name, "manifest.json")):
            raise NidarError(f"{args.data}: scene {name} is not rendered under {renders}")
    return meta


def _evaluate(args, argv_text: str, meta: dict | None, model, fig_dir: str) -> dict:
    """The evaluation proper; figures go to ``fig_dir``."""
    from .metrics import lpips_unavailable_reason

    payload: dict = {
        "command": argv_text,
        "data": os.path.abspath(args.data) if args.data else None,
        "weights": str(model.weights_dir),
        "lpips": lpips_unavailable_reason() if args.lpips else "not requested",
        "groups": {},
        "figures": [],
    }
    if meta is not None:
        _synthetic(args, meta, model, fig_dir, payload)
    linear = None
    if args.photos:
        from ..datasets.rgbnir import list_pairs

        try:
            list_pairs(args.photos)
        except NidarError as e:
            log.warning("skipping the RGB/NIR photos: %s", e)
            payload["photos"] = {"skipped": str(e)}
        else:
            from .real import evaluate_photos, fit_linear_nir

            log.info("RGB/NIR photos: the held-out table")
            payload["photos"] = evaluate_photos(args.photos, model, progress=not args.quiet)
            linear, _ = fit_linear_nir(args.photos)
    if args.kitti:
        from ..datasets.kitti import frame_ids

        present = [d for d in args.kitti if frame_ids(d)]
        if not present:
            msg = f"no KITTI frames at {', '.join(args.kitti)}"
            log.warning("skipping the real-data evaluation: %s", msg)
            payload["kitti"] = {"skipped": msg}
        else:
            from .real import evaluate_kitti_loo

            log.info("KITTI leave-one-frame-out")
            payload["kitti"] = evaluate_kitti_loo(
                present, model, linear_nir=linear, progress=not args.quiet
            )
            if linear is None:
                payload["kitti"]["note"] = "row (i) needs the RGB/NIR photos (--photos)"
    return payload


def _synthetic(args, meta: dict, model, fig_dir: str, payload: dict) -> None:
    """The groups on rendered scenes: held-out generated, hand-made, held-out materials,
    ablations."""
    from ..datasets.profile_fitting import fit_split_calibration
    from ..frames import frame_has, list_frames
    from .heldout import evaluate_renders, fit_class_constant, render_scenes

    scale = float(meta.get("intensity_scale", 1.0))
    splits = meta["scenes"]
    renders = os.path.join(args.data, "renders")
    payload["intensity_scale"] = scale
    payload["ground_truth"] = "clip(range-compensated intensity / intensity_scale, 0, 1)"
    log.info("fitting baselines (c) and (e) on the training split")
    class_const = fit_class_constant([os.path.join(renders, n) for n in splits["train"]], scale)
    pseudo_cal = fit_split_calibration(model, args.data, "train", branch="pseudo_nir")
    common = dict(
        class_const=class_const,
        pseudo_calibration=pseudo_cal,
        twin=not args.no_twin,
        lpips=args.lpips,
    )
    log.info("evaluating the %d '%s' scenes", len(splits[args.split]), args.split)
    res = evaluate_renders(
        [os.path.join(renders, n) for n in splits[args.split]], model, scale, **common
    )
    payload["groups"]["generated"] = _group(res, "generated", splits[args.split])
    payload["figures"] += _figures(res, "generated", fig_dir, args.figures)
    frames = list_frames(args.data, args.split)
    if frames and all(frame_has(f, ("R_true", "S_true")) for f in frames):
        from .intrinsic import intrinsic_scores

        payload["intrinsic"] = intrinsic_scores(model, frames)
    render_opts = dict(
        params=meta.get("params"), seed=int(meta.get("seed", 0)), spp=int(meta.get("spp", 16))
    )
    if args.scenes:
        from ..render_dataset import find_scenes

        files = find_scenes(args.scenes)
        log.info("rendering and evaluating %d hand-made scenes", len(files))
        dirs = render_scenes(
            files,
            os.path.join(cache_dir(args), "renders"),
            **render_opts,
            workers=args.workers,
            ray_address=args.ray_address,
            progress=not args.quiet,
        )
        res = evaluate_renders(dirs, model, scale, **common)
        names = [os.path.basename(d) for d in dirs]
        note = (
            "Hand-made scenes (never used in training); their materials may be absent from the "
            "training scenes, in which case baseline (c) predicts the global training mean."
        )
        payload["groups"]["handmade"] = _group(res, "handmade", names, note)
        payload["figures"] += _figures(res, "handmade", fig_dir, args.figures)
    if args.heldout_materials:
        from ..render_dataset import find_scenes
        from .heldout import heldout_material_scores

        files = find_scenes(args.heldout_materials)
        log.info("rendering and evaluating %d scenes of held-out materials", len(files))
        cache = os.path.join(cache_dir(args), "renders_heldout")
        dirs = render_scenes(files, cache, **render_opts)
        res = evaluate_renders(dirs, model, scale, **common)
        scores = heldout_material_scores(res, class_const.classes)
        payload["heldout_materials"] = scores | {
            "scenes": [os.path.basename(d) for d in dirs],
            "train_materials": sorted(map(str, class_const.classes)),
        }
    if args.ablation:
        from .ablation import run_ablation

        log.info("ablation: training the IRNet variants")
        stn = model.weights_dir / "stn.safetensors"
        payload["ablation"] = run_ablation(
            args.data,
            os.path.join(cache_dir(args), "ablation", _ablation_key(meta, stn)),
            stn,
            split=args.split,
        )


def _ablation_key(meta: dict, stn) -> str:
    """16 hex digits naming the ablation runs of one dataset, STN and settings."""
    import hashlib
    import json

    from ..render_folder import file_sha256
    from .ablation import AblationSettings

    data = {k: meta.get(k) for k in ("request", "frames", "intensity_scale")}
    stn_hash = file_sha256(stn) if os.path.isfile(stn) else None
    text = json.dumps([data, stn_hash, AblationSettings().to_dict()], sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _write(stage: str, payload: dict, out: str) -> None:
    """Write the tables into ``stage`` (figure paths in ``payload`` name their place in
    ``out``)."""
    from . import report
    from .frames import METHOD_LABELS

    titles = {"generated": "Held-out generated scenes", "handmade": "Hand-made scenes"}
    md = [
        "# NIDAR evaluation\n\n",
        f"Command: `{payload['command']}`\n\n",
        f"Weights: `{payload['weights']}`; data: `{payload['data']}`; LPIPS: "
        f"{payload['lpips'] or 'computed'}.\n\n",
    ]
    if "ground_truth" in payload:
        md.append(
            f"Ground truth of the rendered scenes: {payload['ground_truth']} with "
            f"intensity_scale = {payload['intensity_scale']:g}.\n\n"
        )
    csv_rows = []
    for key, group in payload["groups"].items():
        md.append(report.group_markdown(titles.get(key, key), group, METHOD_LABELS) + "\n")
        csv_rows += group["rows"] + [
            {"group": key, "scene": "mean", "camera": "", **r} for r in group["mean"]
        ]
    if "intrinsic" in payload:
        md.append(report.intrinsic_markdown(payload["intrinsic"]) + "\n")
    if "heldout_materials" in payload:
        h = payload["heldout_materials"]
        md.append(report.heldout_materials_markdown(h, METHOD_LABELS) + "\n")
        csv_rows += [{"group": "heldout_materials", **r} for r in h["rows"]]
    if "kitti" in payload:
        md.append(report.loo_markdown(payload["kitti"]) + "\n")
        csv_rows += [{"group": "kitti_loo", **r} for r in payload["kitti"].get("rows", [])]
    if "photos" in payload:
        md.append(report.photos_markdown(payload["photos"]) + "\n")
        csv_rows += [{"group": "photos", **r} for r in payload["photos"].get("rows", [])]
    if "ablation" in payload:
        md.append(report.ablation_markdown(payload["ablation"]) + "\n")
    if payload["figures"]:
        md.append("## Figures\n\n")
        md.extend(f"- `{os.path.relpath(p, out)}`\n" for p in payload["figures"])
    report.write_csv(os.path.join(stage, "results.csv"), csv_rows)
    report.write_json(os.path.join(stage, "results.json"), payload)
    report.write_text(os.path.join(stage, "results.md"), "".join(md))
