"""``python -m nidar_mi.evaluate``: NIDAR and the baselines on held-out scenes, hand-made scenes,
scenes of held-out materials, real KITTI frames (leave one frame out), real RGB/NIR photos, and
the ablations.

    python -m nidar_mi.evaluate [--data DATA] [--weights DIR] [--scenes scenes/]
                                [--heldout-materials DIR] [--kitti DIR ...] [--photos DIR]
                                [--ablation] [--cache DIR] [--overwrite] -o OUT

* ``DATA`` is a dataset from :mod:`nidar_mi.render_dataset`: its ``test`` scenes (rendered under
  ``DATA/renders``) are the held-out generated scenes, its ``train`` scenes fit baselines (c)
  and (e), ``meta.json`` gives ``intensity_scale``.
* ``--scenes`` renders the hand-made scene files (cached in ``CACHE/renders``) with the
  dataset's parameters, seed and spp, and evaluates them the same way; ``--workers N`` /
  ``--ray-address`` render them on Ray (:mod:`nidar_mi.tasks`).
* ``--heldout-materials`` renders scenes made of materials the training scenes lack
  (``python -m nidar_mi.scenegen --materials heldout``; cached in ``CACHE/renders_heldout``) and
  scores every method on those materials' returns.
* ``--kitti`` (repeatable: e.g. ``../shared/data/kitti`` and ``../shared/data/kitti_raw_0926``)
  runs the leave-one-frame-out protocol (:mod:`nidar_mi.eval.loo`); skipped with a message when
  the folders hold no frame. The frames are converted once and cached in the user's cache.
* ``--photos`` (e.g. ``../shared/data/rgbnir``) scores pseudo-NIR against the held-out real NIR
  photos (:mod:`nidar_mi.eval.photos`) and fits baseline (i)'s linear map for the KITTI table;
  skipped with a message when absent.
* ``--ablation`` trains the IRNet variants and the RGB-input model into ``CACHE/ablation``
  (finished runs of the same dataset, STN and settings are reused) and scores them on the
  test frames.

``--data`` may be left out when only real data is evaluated. ``CACHE`` is ``--cache`` (default
``DATA/cache/evaluate``): a rerun reuses what it holds, and nothing of it is written into
``OUT``. ``OUT`` receives ``results.md``, ``results.csv`` (one row per frame and method, plus
``mean`` rows), ``results.json`` and ``figures/*.png`` (no figure of real data), published whole
when everything succeeded. See :mod:`nidar_mi.eval.rendered` for the methods and the metric scale.
"""

from __future__ import annotations

import logging
import os
import sys

from ._common import out_path, parser, run, show_progress
from ._workers import add_worker_options

__all__ = ["main"]

log = logging.getLogger("nidar_mi.evaluate")


def _parser():
    p = parser(
        "evaluate",
        "Score NIDAR and the baselines on held-out and hand-made scenes, real KITTI frames, real "
        "RGB/NIR photos, and the ablations.",
        verbose="one per rendered frame scored (its returns)",
    )
    p.add_argument("--data", help="dataset folder (meta.json, renders/, splits)")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument("--scenes", help="folder of hand-made scene XML files to evaluate too")
    p.add_argument(
        "--heldout-materials",
        metavar="DIR",
        help="folder of scenes made of held-out materials (scenegen --materials heldout)",
    )
    p.add_argument(
        "--kitti",
        action="append",
        metavar="DIR",
        help="KITTI folder (velodyne/, image_2/, calib/), repeatable: leave-one-frame-out",
    )
    p.add_argument("--photos", metavar="DIR", help="RGB/NIR photo pairs (<category>/NNNN_rgb.jpg)")
    p.add_argument("--ablation", action="store_true", help="train and score the ablations")
    p.add_argument(
        "--split", default="test", help="dataset split of the held-out scenes (default test)"
    )
    p.add_argument("--no-twin", action="store_true", help="skip baseline (a) (no Mitsuba scans)")
    p.add_argument(
        "--lpips",
        action="store_true",
        help="also score LPIPS (needs the lpips package and cached AlexNet weights; an error "
        "without them)",
    )
    p.add_argument(
        "--figures", type=int, default=3, help="frames per group with map figures (default 3)"
    )
    p.add_argument(
        "--cache",
        help="folder of the renders and ablation runs a rerun reuses (default: DATA/cache/evaluate)",
    )
    p.add_argument(
        "-o", "--out", required=True, type=out_path, help="output folder (results, figures)"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT written by nidar_mi 0.1.0 (no record of its files); a file "
        "evaluate did not write is never removed",
    )
    add_worker_options(p, "hand-made scenes to render")
    return p


def options(args, argv_text: str):
    """The :class:`~nidar_mi.eval.suite.EvaluateOptions` of the parsed command line."""
    from ..eval.suite import EvaluateOptions

    return EvaluateOptions(
        out=args.out,
        data=args.data,
        weights=args.weights,
        scenes=args.scenes,
        heldout_materials=args.heldout_materials,
        kitti=tuple(args.kitti or ()),
        photos=args.photos,
        ablation=args.ablation,
        split=args.split,
        twin=not args.no_twin,
        lpips=args.lpips,
        figures=args.figures,
        cache=args.cache,
        overwrite=args.overwrite,
        progress=show_progress(args),
        workers=args.workers,
        ray_address=args.ray_address,
        command=argv_text,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 on a user error)."""
    args = _parser().parse_args(argv)
    argv_text = "python -m nidar_mi.evaluate " + " ".join(
        sys.argv[1:] if argv is None else list(argv)
    )

    def work():
        from ..eval.suite import run_evaluation

        opts = options(args, argv_text)
        if opts.scans_scenes:
            from ..backend import set_variant

            set_variant("llvm_ad_spectral")
        payload = run_evaluation(opts)
        log.info("wrote %s in %.0f s", os.path.join(opts.out, "results.md"), payload["seconds"])

    return run(work, flags={"scene_dir": "--scenes"}, args=args)
