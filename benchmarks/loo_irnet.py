"""Leave-one-frame-out evaluation of an IRNet trained per fold on the real KITTI frames.

``python benchmarks/loo_irnet.py DATA WORK --stn-weights STN --config irnet_kitti.json
[--folds 0 1 ...] [--forms range_ring distance_quantile] [--baselines] [--init-irnet W]
[--renders DATA_SIM] [--json out.json]``

``DATA`` is a KITTI data folder of ``python -m nidar_mi.dataset --kitti ...`` (its ``test``
frames are the folds); ``WORK`` holds one training run per fold (resumable, reused when done;
:mod:`nidar_mi.eval.loo_irnet`). The configuration is a :class:`~nidar_mi.nidar.config.TrainConfig`
JSON (e.g. a compact ``unet`` at ``scale`` 0.25 with 64 x 160 crops). Rows: IRNet ``R`` and
``Î`` through each profile form and ``Î`` raw (every fold's IRNet starts from ``--init-irnet``
when given, e.g. weights pretrained on renders, and mixes the train frames of ``--renders`` into
its crops to supervise R and S with their true maps); with ``--baselines`` also the image-free
profiles (``range_only``; ``geometry_gbm``, range and elevation) and luminance through each
form. Prints the per-fold and mean table
(:func:`nidar_mi.eval.tables.loo_markdown`), the training time of each fold and, per fold, the
correlation of the R and S maps over the test image (how much shading R still carries);
``--json`` writes the whole result. Folds run one after the other; run it under ``nice``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path)
    p.add_argument("work", type=Path)
    p.add_argument("--stn-weights", type=Path, required=True)
    p.add_argument("--config", type=Path, required=True)
    p.add_argument("--folds", type=int, nargs="*", help="indices of the test frames (default all)")
    p.add_argument("--forms", nargs="*", default=["gbm", "range_ring", "distance_quantile"])
    p.add_argument("--baselines", action="store_true")
    p.add_argument("--init-irnet", type=Path, help="IRNet weights every fold starts from")
    p.add_argument("--renders", type=Path, help="rendered dataset mixed into every fold's crops")
    p.add_argument("--json", type=Path)
    p.add_argument("--progress", action="store_true")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")

    from nidar_mi.datasets.scans import frames_from_data
    from nidar_mi.eval.loo import leave_one_out, standard_methods
    from nidar_mi.eval.loo_irnet import FoldModels, irnet_methods
    from nidar_mi.eval.tables import loo_markdown
    from nidar_mi.nidar.config import TrainConfig
    from nidar_mi.training_frames import list_frames, load_meta

    cfg = TrainConfig.from_dict(json.loads(args.config.read_text()))
    cfg.validate()
    tests = load_meta(args.data)["frames"]["test"]
    if args.folds:
        tests = [tests[k] for k in args.folds]
    scans = frames_from_data(args.data)
    models = FoldModels(
        cfg,
        args.data,
        args.work,
        args.stn_weights,
        progress=args.progress,
        init_weights=args.init_irnet,
        render_frames=list_frames(args.renders, "train") if args.renders else None,
    )
    methods = {}
    if args.baselines:
        base = standard_methods(forms=tuple(args.forms))
        keep = ("range_only", "geometry_gbm", "geometry_gbm_inc")
        methods |= {k: v for k, v in base.items() if k in keep or k.startswith("lum_")}
    methods |= irnet_methods(models, forms=tuple(args.forms))
    res = leave_one_out(scans, tests, methods, progress=args.progress)
    timing = {}
    for test in tests:
        t = args.work / f"fold-{test}" / "timing.json"
        if t.is_file():
            timing[test] = json.loads(t.read_text())["train_seconds"]
    res |= {"config": cfg.to_dict(), "train_seconds": timing, "data": str(args.data)}
    res["r_of_R_and_S"] = _decomposition_check(scans, tests, models)
    res["frames"] = len(scans)
    print(loo_markdown(res))
    print("training seconds per fold:", timing)
    print("Pearson r of R and S over the test image, per fold:", res["r_of_R_and_S"])
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1, default=float))
    return 0


def _decomposition_check(scans, tests, models) -> dict[str, float]:
    """Pearson's r of the R and S maps over each test frame's pixels (fold's network): how much
    shading the reflectance branch still carries (0: none)."""
    import numpy as np

    out = {}
    for test in tests:
        scan = next(s for s in scans if s.name == test)
        train = [s for s in scans if s.name != test]
        maps = models.model(train).predict_image(scan.images[0])
        out[test] = round(float(np.corrcoef(maps["R"].ravel(), maps["S"].ravel())[0, 1]), 3)
    return out


if __name__ == "__main__":
    sys.exit(main())
