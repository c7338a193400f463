"""The whole evaluation behind ``python -m nidar_mi.evaluate``: every group, tables, figures.

Held-out generated scenes (a dataset's ``test`` split), hand-made scene files, real KITTI frames
and the IRNet ablations, each scored with :mod:`nidar_mi.eval.frames`; the results are written
as ``OUT/results.{md,csv,json}`` and ``OUT/figures/*.png`` (no figure of KITTI frames).
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time

from ..errors import NidarError

__all__ = ["run", "KITTI_LABELS"]

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


def run(args, argv_text: str) -> dict:
    """Everything the command does; returns the results payload (also written to OUT)."""
    from ..dataset import load_meta
    from ..nidar.pipeline import NidarModel

    t0 = time.perf_counter()
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
    if args.scenes and not os.path.isdir(args.scenes):
        raise NidarError(f"--scenes: no such directory {args.scenes}")
    model = NidarModel.load(args.weights)
    if model.calibration is None:
        raise NidarError(f"{model.weights_dir}: no calibration.json beside the weights")
    if not args.no_twin or args.scenes:
        from ..backend import set_variant

        set_variant("llvm_ad_spectral")
    os.makedirs(args.out, exist_ok=True)
    # figures are staged and moved into OUT/figures only once everything succeeded
    fig_dir = tempfile.mkdtemp(prefix=".figures.partial-", dir=args.out)
    try:
        payload = _evaluate(args, argv_text, meta, model, fig_dir)
        final = os.path.join(args.out, "figures")
        os.makedirs(final, exist_ok=True)
        moved = []
        for p in payload["figures"]:
            target = os.path.join(final, os.path.basename(p))
            os.replace(p, target)
            moved.append(target)
        payload["figures"] = moved
        payload["seconds"] = time.perf_counter() - t0
        _write(args.out, payload)
    finally:
        shutil.rmtree(fig_dir, ignore_errors=True)
    return payload


def _evaluate(args, argv_text: str, meta: dict, model, fig_dir: str) -> dict:
    """The evaluation proper; figures go to ``fig_dir``."""
    from ..nidar.dataset_calibration import fit_dataset_calibration
    from .heldout import (
        evaluate_renders,
        fit_class_constant,
        render_scenes,
    )
    from .metrics import lpips_unavailable_reason

    scale = float(meta.get("intensity_scale", 1.0))
    splits = meta["scenes"]
    renders = os.path.join(args.data, "renders")
    log.info("fitting baselines (c) and (e) on the training split")
    class_const = fit_class_constant([os.path.join(renders, n) for n in splits["train"]], scale)
    pseudo_cal = fit_dataset_calibration(model, args.data, "train", branch="pseudo_nir")
    common = dict(
        class_const=class_const,
        pseudo_calibration=pseudo_cal,
        twin=not args.no_twin,
        lpips=args.lpips,
    )
    payload: dict = {
        "command": argv_text,
        "data": os.path.abspath(args.data),
        "weights": str(model.weights_dir),
        "intensity_scale": scale,
        "ground_truth": "clip(range-compensated intensity / intensity_scale, 0, 1)",
        "lpips": lpips_unavailable_reason() if args.lpips else "not requested",
        "groups": {},
        "figures": [],
    }
    log.info("evaluating the %d '%s' scenes", len(splits[args.split]), args.split)
    res = evaluate_renders(
        [os.path.join(renders, n) for n in splits[args.split]], model, scale, **common
    )
    payload["groups"]["generated"] = _group(res, "generated", splits[args.split])
    payload["figures"] += _figures(res, "generated", fig_dir, args.figures)
    if args.scenes:
        from ..dataset import find_scenes

        files = find_scenes(args.scenes)
        log.info("rendering and evaluating %d hand-made scenes", len(files))
        dirs = render_scenes(
            files,
            os.path.join(args.out, "renders"),
            params=meta.get("params"),
            seed=int(meta.get("seed", 0)),
            spp=int(meta.get("spp", 16)),
        )
        res = evaluate_renders(dirs, model, scale, **common)
        names = [os.path.basename(d) for d in dirs]
        note = (
            "Hand-made scenes (never used in training); their materials may be absent from the "
            "training scenes, in which case baseline (c) predicts the global training mean."
        )
        payload["groups"]["handmade"] = _group(res, "handmade", names, note)
        payload["figures"] += _figures(res, "handmade", fig_dir, args.figures)
    if args.kitti:
        from ..datasets.kitti import frame_ids
        from .frames import mean_table
        from .kitti import evaluate_kitti

        if not frame_ids(args.kitti):
            msg = f"no KITTI frames at {args.kitti}"
            log.warning("skipping the real-data evaluation: %s", msg)
            payload["kitti"] = {"skipped": msg}
        else:
            log.info("evaluating KITTI frames")
            k = evaluate_kitti(args.kitti, model, pseudo_calibration=pseudo_cal, lpips=args.lpips)
            k["mean"] = mean_table(k["rows"])
            payload["kitti"] = k
    if args.ablation:
        from .ablation import run_ablation

        log.info("ablation: training the IRNet variants")
        payload["ablation"] = run_ablation(
            args.data,
            os.path.join(args.out, "ablation"),
            model.weights_dir / "stn.safetensors",
            split=args.split,
        )
    return payload


KITTI_LABELS = {
    "luminance_loo": "(b) luminance + LOO remap",
    "carla_loo": "(d) CARLA + LOO remap",
    "nidar_ihat_loo": "(f) Î + LOO remap",
    "nidar_full_loo": "(g) NIDAR-Full, LOO remap",
}


def _write(out: str, payload: dict) -> None:
    from . import report
    from .frames import METHOD_LABELS

    labels = METHOD_LABELS | KITTI_LABELS
    titles = {"generated": "Held-out generated scenes", "handmade": "Hand-made scenes"}
    md = [
        "# NIDAR evaluation\n\n",
        f"Command: `{payload['command']}`\n\n",
        f"Weights: `{payload['weights']}`; data: `{payload['data']}`; ground truth: "
        f"{payload['ground_truth']} with intensity_scale = {payload['intensity_scale']:g}; "
        f"LPIPS: {payload['lpips'] or 'computed'}.\n\n",
    ]
    csv_rows = []
    for key, group in payload["groups"].items():
        md.append(report.group_markdown(titles.get(key, key), group, labels) + "\n")
        csv_rows += group["rows"] + [
            {"group": key, "scene": "mean", "camera": "", **r} for r in group["mean"]
        ]
    if "kitti" in payload:
        md.append(report.kitti_markdown(payload["kitti"], labels) + "\n")
        if "rows" in payload["kitti"]:
            csv_rows += payload["kitti"]["rows"] + [
                {"group": "kitti", "scene": "mean", "camera": "", **r}
                for r in payload["kitti"]["mean"]
            ]
    if "ablation" in payload:
        md.append(report.ablation_markdown(payload["ablation"]) + "\n")
    if payload["figures"]:
        md.append("## Figures\n\n")
        md.extend(f"- `{os.path.relpath(p, out)}`\n" for p in payload["figures"])
    os.makedirs(out, exist_ok=True)
    report.write_csv(os.path.join(out, "results.csv"), csv_rows)
    report.write_json(os.path.join(out, "results.json"), payload)
    report.write_text(os.path.join(out, "results.md"), "".join(md))
