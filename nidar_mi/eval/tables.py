"""Result tables as Markdown, CSV and JSON (written atomically).

Rows are flat dicts (see :func:`nidar_mi.eval.rendered.result_rows`); a table is a list of rows
plus the columns to show. Missing values (``None``, NaN) print as ``–`` in Markdown and as an
empty cell in CSV; JSON keeps ``null`` (NaN and inf become ``null``).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = [
    "BEST",
    "MAP_COLUMNS",
    "SCENE_COLUMNS",
    "ablation_markdown",
    "goal_check",
    "group_markdown",
    "heldout_materials_markdown",
    "loo_markdown",
    "photos_markdown",
    "labelled",
    "fmt_value",
    "markdown_table",
    "write_csv",
    "write_json",
    "write_text",
]

MAP_COLUMNS = (
    ("map_rmse", "RMSE↓", 4),
    ("map_medae", "MedAE↓", 4),
    ("map_psnr", "PSNR↑ (dB)", 2),
    ("map_ssim", "SSIM↑", 4),
    ("map_lpips", "LPIPS↓", 4),
    ("point_rmse", "pt RMSE↓", 4),
    ("point_mae", "pt MAE↓", 4),
    ("spearman", "Spearman↑", 3),
    ("ri_ssim", "RI SSIM↑", 4),
    ("ri_psnr", "RI PSNR↑", 2),
)
"""(key, header, decimals) of the metric columns of the held-out tables."""


def fmt_value(v: Any, decimals: int = 4) -> str:
    """A table cell: numbers with ``decimals`` places, ``–`` for missing/NaN, ``inf`` kept."""
    if v is None:
        return "–"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return str(v)
    if math.isnan(v):
        return "–"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{decimals}f}"


def markdown_table(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[tuple[str, str, int]],
    *,
    bold_best: Mapping[str, str] | None = None,
) -> str:
    """A GitHub Markdown table.

    Args:
        rows: the rows.
        columns: (key, header, decimals) per column; decimals is ignored for text.
        bold_best: key -> ``"min"`` or ``"max"``: the best value of that column is bold.

    Returns:
        The table text, ending with a newline.
    """
    best: dict[str, float] = {}
    for key, how in (bold_best or {}).items():
        vals = [
            r.get(key)
            for r in rows
            if isinstance(r.get(key), (int, float)) and math.isfinite(r.get(key))
        ]
        if vals:
            best[key] = min(vals) if how == "min" else max(vals)
    lines = [
        "| " + " | ".join(h for _, h, _ in columns) + " |",
        "|" + "|".join("---" for _ in columns) + "|",
    ]
    for r in rows:
        cells = []
        for key, _, dec in columns:
            v = r.get(key)
            s = fmt_value(v, dec)
            if key in best and isinstance(v, (int, float)) and v == best[key]:
                s = f"**{s}**"
            cells.append(s)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _csv_cell(v: Any) -> Any:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return v


def write_csv(path: str | os.PathLike, rows: Sequence[Mapping[str, Any]]) -> None:
    """Rows as CSV; the header is the union of the keys in first-seen order."""
    keys: list[str] = []
    for r in rows:
        keys.extend(k for k in r if k not in keys)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _csv_cell(r.get(k)) for k in keys})
    write_text(path, buf.getvalue())


def _clean(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Mapping):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item") and hasattr(obj, "dtype"):  # NumPy scalar
        return _clean(obj.item())
    return obj


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """JSON with NaN/inf as ``null`` (strict JSON), atomically."""
    from ..io.atomic import atomic_write_json

    atomic_write_json(path, _clean(obj))


def write_text(path: str | os.PathLike, text: str) -> None:
    """UTF-8 text, atomically."""
    from ..io.atomic import atomic_write_text

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    atomic_write_text(path, text)


SCENE_COLUMNS = (
    ("scene", "scene", 0),
    ("label", "method", 0),
    ("n_points", "points", 0),
    ("map_rmse", "RMSE↓", 4),
    ("map_psnr", "PSNR↑", 2),
    ("map_ssim", "SSIM↑", 4),
    ("point_mae", "pt MAE↓", 4),
    ("spearman", "Spearman↑", 3),
)
BEST = {
    "map_rmse": "min",
    "map_medae": "min",
    "map_psnr": "max",
    "map_ssim": "max",
    "map_lpips": "min",
    "point_rmse": "min",
    "point_mae": "min",
    "spearman": "max",
    "ri_ssim": "max",
    "ri_psnr": "max",
}


def goal_check(
    mean_rows: Sequence[Mapping[str, Any]],
    ours: str,
    rivals: Sequence[str],
    metrics: Sequence[tuple[str, str]] = (("map_ssim", "max"), ("map_rmse", "min")),
) -> list[str]:
    """One line per metric: whether ``ours`` beats every rival in ``mean_rows``, with numbers."""
    by = {r["method"]: r for r in mean_rows}
    if ours not in by:
        return [f"{ours} was not evaluated"]
    lines = []
    for key, how in metrics:
        v = by[ours].get(key)
        beaten_by = []
        for k in rivals:
            if k not in by or by[k].get(key) is None or v is None:
                continue
            w = by[k][key]
            if (how == "max" and w >= v) or (how == "min" and w <= v):
                beaten_by.append(f"{k} {fmt_value(w)}")
        verdict = (
            "ahead of every baseline" if not beaten_by else "NOT ahead of " + ", ".join(beaten_by)
        )
        lines.append(
            f"{key} ({'higher' if how == 'max' else 'lower'} is better): {ours} "
            f"{fmt_value(v)}, {verdict}"
        )
    return lines


def labelled(rows: Sequence[Mapping[str, Any]], labels: Mapping[str, str]) -> list[dict]:
    """Rows with a ``label`` column (the method's display name)."""
    return [{**r, "label": labels.get(r["method"], r["method"])} for r in rows]


def _mean_columns(rows: Sequence[Mapping[str, Any]]) -> list[tuple[str, str, int]]:
    cols = [("label", "method", 0), ("frames", "frames", 0)]
    for key, head, dec in MAP_COLUMNS:
        if any(r.get(key) is not None for r in rows):
            cols.append((key, head, dec))
    return cols


def group_markdown(title: str, group: Mapping[str, Any], labels: Mapping[str, str]) -> str:
    """Mean table, goal check and per-scene table of one held-out group."""
    mean = labelled(group["mean"], labels)
    parts = [f"## {title}\n\n", group["note"] + "\n\n" if group.get("note") else ""]
    parts.append(
        f"Mean over {mean[0]['frames'] if mean else 0} frames (scenes: "
        f"{', '.join(group.get('scenes', []))}). Camera-projection map metrics (RMSE, MedAE, "
        "PSNR, SSIM, LPIPS), point metrics (pt RMSE, pt MAE, Spearman) and SSIM/PSNR on the "
        "LiDAR range image (RI); best value in bold.\n\n"
    )
    parts.append(markdown_table(mean, _mean_columns(mean), bold_best=BEST))
    rivals = [r["method"] for r in group["mean"] if r["method"] != "nidar_full"]
    checks = goal_check(group["mean"], "nidar_full", rivals)
    parts.append("\nGoal (NIDAR-Full ahead of every baseline on SSIM and RMSE):\n\n")
    parts.extend(f"- {c}\n" for c in checks)
    parts.append("\n<details><summary>Per scene</summary>\n\n")
    parts.append(markdown_table(labelled(group["rows"], labels), SCENE_COLUMNS))
    parts.append("\n</details>\n")
    return "".join(parts)


def loo_markdown(loo: Mapping[str, Any]) -> str:
    """The KITTI leave-one-frame-out section: mean and per-fold tables, goal check."""
    from .scan_metrics import BIN_M, BIN_MIN_POINTS, SCAN_METRICS

    if "skipped" in loo:
        return f"## Real data: KITTI, leave one frame out\n\nSkipped: {loo['skipped']}\n"
    cols = [("label", "method", 0), ("folds", "folds", 0)] + [
        (k, h, d) for k, h, d, _ in SCAN_METRICS
    ]
    best = {k: b for k, _, _, b in SCAN_METRICS}
    parts = [
        "## Real data: KITTI, leave one frame out\n\n",
        f"{loo['frames']} frames; folds: {', '.join(loo['folds'])}. Fold k fits every method on "
        f"the other {loo['train_frames']} frames and scores it on frame k; reference: the stored "
        "Velodyne reflectance at the returns camera 2 sees. SSIM on the camera map (returns at "
        "their nearest pixel) and on the range image (rings x 2048 azimuth columns); Spearman "
        f"in {BIN_M:g} m bins: the count-weighted mean over range bins with at least "
        f"{BIN_MIN_POINTS} returns. Mean over folds; best value in bold.\n\n",
        markdown_table(loo["mean"], cols, bold_best=best),
    ]
    if loo.get("note"):
        parts.append(f"\nNote: {loo['note']}.\n")
    parts.append("\n<details><summary>Per fold</summary>\n\n")
    parts.append(markdown_table(loo["rows"], [("frame", "frame", 0)] + cols[:1] + cols[2:]))
    parts.append("\n</details>\n")
    return "".join(parts)


def photos_markdown(photos: Mapping[str, Any]) -> str:
    """The held-out RGB/NIR photo section: mean and per-category tables."""
    from .photos import PHOTO_METRICS

    if "skipped" in photos:
        return f"## Pseudo-NIR against real NIR photos\n\nSkipped: {photos['skipped']}\n"
    n = {k: len(v) for k, v in photos["split"].items()}
    w = photos["linear_weights"]
    cols = [("label", "method", 0), ("images", "images", 0)] + list(PHOTO_METRICS)
    parts = [
        "## Pseudo-NIR against real NIR photos\n\n",
        f"Held-out split by image, every category represented: {n['train']} train, {n['val']} "
        f"val, {n['test']} test pairs. The linear map (fitted on {photos['linear_fitted_on']}): "
        f"nir = {w[0]:.3f} r {w[1]:+.3f} g {w[2]:+.3f} b {w[3]:+.3f} (linear values). Pearson r "
        "over all pixels; SSIM after the per-image least-squares gain and offset; mean over the "
        "test images.\n\n",
        markdown_table(photos["mean"], cols, bold_best={"r": "max", "ssim": "max"}),
        "\nPer category (Pearson r):\n\n",
    ]
    cats = sorted(next(iter(photos["per_category"].values())))
    rows = [
        {"label": next(m["label"] for m in photos["mean"] if m["method"] == k)}
        | {c: v[c]["r"] for c in cats}
        for k, v in photos["per_category"].items()
    ]
    parts.append(markdown_table(rows, [("label", "method", 0)] + [(c, c, 2) for c in cats]))
    return "".join(parts)


def intrinsic_markdown(intr: Mapping[str, Any]) -> str:
    """The decomposition section: R and S against the rendered frames' true maps."""
    cols = [
        ("frame", "frame", 0),
        ("r_R_shading", "r(R, S_true)", 3),
        ("r_true_shading", "r(R_true, S_true)", 3),
        ("r_input_shading", "r(input, S_true)", 3),
        ("r_R_reflectance", "r(R, R_true)", 3),
        ("spearman_R_reflectance", "Spearman(R, R_true)", 3),
        ("r_R_S", "r(R, S)", 3),
    ]
    rows = [*intr["rows"], {"frame": "mean", **intr["mean"]}]
    return "".join(
        [
            "## Decomposition against the true maps\n\n",
            f"Rendered test frames, pixels with a surface, networks at {intr['scale']:g} of the "
            "frames' resolution. r(R, S_true): how much shading (cast "
            "shadows, incidence) the reflectance branch carries; a perfect R has the true maps' "
            "own r(R_true, S_true). r(R, R_true): how well R recovers the material.\n\n",
            markdown_table(rows, cols),
        ]
    )


def heldout_materials_markdown(h: Mapping[str, Any], labels: Mapping[str, str]) -> str:
    """The held-out materials section."""
    mean = labelled(h["mean"], labels)
    cols = [
        ("label", "method", 0),
        ("frames", "frames", 0),
        ("n_points", "returns", 0),
        ("spearman", "Spearman↑ (mean over frames)", 3),
        ("pooled_spearman", "Spearman↑ (all returns)", 3),
        ("rmse", "RMSE↓", 4),
    ]
    return "".join(
        [
            "## Scenes of held-out materials\n\n",
            f"Scenes {', '.join(h['scenes'])}; scored on the returns of the materials no training "
            f"scene has ({', '.join(h['materials'])}), against the physical intensity.\n\n",
            markdown_table(
                mean, cols, bold_best={"spearman": "max", "pooled_spearman": "max", "rmse": "min"}
            ),
            _ceiling_line(h.get("ceiling")),
        ]
    )


def _ceiling_line(c: Mapping[str, Any] | None) -> str:
    if not c:
        return ""
    return (
        "\nThe noise-free physics at the same returns (`g·ρ·cos θ·exp(−2αd)` from the "
        "renderer's exact ρ and cos θ, without the receiver noise the reference carries): "
        f"Spearman {fmt_value(c['spearman'], 3)} (mean over frames) / "
        f"{fmt_value(c['pooled_spearman'], 3)} (all returns), RMSE {fmt_value(c['rmse'])}. No "
        "method can be expected to rank the noisy reference better.\n"
    )


def ablation_markdown(ab: Mapping[str, Any]) -> str:
    """The two ablation tables with the settings they were trained with."""
    s = ab["settings"]
    parts = [
        "## Ablations\n\n",
        f"Every run: IRNet width {s['width']}, {s['crop_size']} px crops, batch "
        f"{s['batch_size']}, {s['epochs']} epochs, Adam lr {s['lr']}, intensity-loss warm-up "
        f"{s['int_warmup_epochs']} epoch(s), seed {s['seed']}, the shipped STN fixed; scored "
        f"on the '{ab['split']}' frames' projected intensity (masked pixels, mean over "
        "frames).\n\n### IRNet structural ablation (Î)\n\n",
        markdown_table(
            ab["structural"],
            [
                ("variant", "variant", 0),
                ("val_loss", "val. loss", 4),
                ("rmse", "RMSE↓", 4),
                ("mae", "MAE↓", 4),
                ("ssim", "SSIM↑", 4),
                ("psnr", "PSNR↑", 2),
            ],
            bold_best={"rmse": "min", "mae": "min", "ssim": "max", "psnr": "max"},
        ),
        "\n### Pseudo-NIR vs RGB input (unet+deeplabv3)\n\n",
        markdown_table(
            ab["input"],
            [
                ("input", "input", 0),
                ("val_loss", "val. loss", 4),
                ("output", "output", 0),
                ("post", "post.", 0),
                ("mae", "MAE↓", 4),
                ("rmse", "RMSE↓", 4),
                ("ssim", "SSIM↑", 4),
            ],
        ),
    ]
    return "".join(parts)
