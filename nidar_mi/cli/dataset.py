"""``python -m nidar_mi.dataset``: NIDAR training frames from rendered scenes or real KITTI frames.

    python -m nidar_mi.dataset --scenes DIR -o DATA [...]        rendered scenes
    python -m nidar_mi.dataset --kitti DIR [--kitti DIR ...] -o DATA   real KITTI frames

The frame format is :mod:`nidar_mi.training_frames`; KITTI frames are
:mod:`nidar_mi.datasets.kitti_frames` (held-out frame list, rings, short scans). KITTI data is
non-commercial: keep ``DATA`` out of any repository.
"""

from __future__ import annotations

from ..errors import NidarError
from ._common import out_path, parse_defines, parser, run, seed_arg, show_progress
from ._workers import add_worker_options

__all__ = ["main", "build_parser"]


def build_parser():
    p = parser(
        "dataset",
        "Render scenes (cached in DATA/renders) and turn every camera into a NIDAR training "
        "frame; the frames and meta.json are published together when every scene is done.",
        verbose="one per scene (rendered or cached, its frames) or KITTI frame, and a failed "
        "scene's traceback",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--scenes", help="folder of scene XML files (e.g. from nidar_mi.scenegen)")
    src.add_argument(
        "--kitti",
        action="append",
        metavar="DIR",
        help="KITTI folder (velodyne/, image_2/, calib/); repeatable, e.g. "
        "../shared/data/kitti and ../shared/data/kitti_raw_0926",
    )
    p.add_argument("-o", "--out", required=True, type=out_path, help="dataset folder")
    p.add_argument(
        "--split",
        default="0.8,0.1,0.1",
        help="train,val,test fractions of the scenes, summing to 1; scenes are split whole "
        "(default 0.8,0.1,0.1)",
    )
    p.add_argument(
        "--seed",
        type=seed_arg,
        default=0,
        help="seed of the split, the scan noise and the camera sampler, 0 .. 2**32-1 (default 0)",
    )
    p.add_argument("--spp", type=int, default=16, help="camera samples per pixel (default 16)")
    p.add_argument("--lidar", default=None, help="lidar id (default: the first by id)")
    p.add_argument(
        "--intensity-scale",
        type=float,
        default=1.0,
        help="recorded in meta.json: training divides the LiDAR intensity by it and clips to "
        "[0, 1] (default 1)",
    )
    p.add_argument(
        "-D",
        dest="params",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="scene parameter (<default name=...>) for every scene that has it, e.g. -D "
        "width=320; repeatable; a name no scene has is an error",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a dataset of the other source (--scenes / --kitti) or one written by "
        "nidar_mi 0.1.0 (no record of its files); a file dataset did not write is never removed",
    )
    add_worker_options(p, "scenes")
    return p


#: Options of --scenes (rendered scenes): given with --kitti they would have no effect.
_SCENE_OPTIONS = {
    "--split": "split",
    "--seed": "seed",
    "--spp": "spp",
    "--lidar": "lidar",
    "--intensity-scale": "intensity_scale",
    "-D": "params",
    "--workers": "workers",
    "--ray-address": "ray_address",
}


def main(argv=None) -> int:
    p = build_parser()
    args = p.parse_args(argv)

    def work():
        from ..render_dataset import build_dataset
        from ..training_frames import SPLITS

        if args.kitti:
            given = [f for f, d in _SCENE_OPTIONS.items() if getattr(args, d) != p.get_default(d)]
            if given:
                raise NidarError(f"{', '.join(given)}: options of --scenes, not of --kitti")
            from ..datasets.kitti_frames import build_kitti_frames

            meta = build_kitti_frames(
                args.kitti, args.out, progress=show_progress(args), overwrite=args.overwrite
            )
            if not args.quiet:
                for s in SPLITS:
                    print(f"{s:5s}  {len(meta['frames'][s]):5d} frames")
            return

        try:
            fractions = tuple(float(x) for x in args.split.split(","))
        except ValueError:
            raise NidarError(f"--split: expected three numbers (got '{args.split}')") from None
        legal = len(fractions) == 3 and all(0 <= f <= 1 for f in fractions)  # NaN: False
        if not legal or abs(sum(fractions) - 1) > 1e-6:
            raise NidarError(
                f"--split: three fractions in [0, 1] summing to 1 expected (got '{args.split}')"
            )
        from ..backend import set_variant

        set_variant()  # the renders' variant, also the workers' (nidar_mi.backend.worker_setup)
        meta = build_dataset(
            args.scenes,
            args.out,
            fractions=fractions,
            seed=args.seed,
            spp=args.spp,
            params=parse_defines(args.params),
            lidar_id=args.lidar,
            intensity_scale=args.intensity_scale,
            progress=show_progress(args),
            overwrite=args.overwrite,
            workers=args.workers,
            ray_address=args.ray_address,
        )
        if not args.quiet:
            for s in SPLITS:
                n_scenes, n_frames = len(meta["scenes"][s]), len(meta["frames"][s])
                print(f"{s:5s}  {n_scenes:4d} scenes  {n_frames:5d} frames")

    return run(
        work,
        on_interrupt="no dataset published; the completed renders are kept in "
        f"{args.out}/renders for the next run",
        flags={"scene_dir": "--scenes", "fractions": "--split", "lidar_id": "--lidar"},
        args=args,
    )
