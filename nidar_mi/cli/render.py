"""``python -m nidar_mi.render SCENE.xml -o OUT``: scan every LiDAR and render every camera.

The work is :func:`nidar_mi.simulate.render_scene` with the
:class:`~nidar_mi.render_session.RenderOptions` the flags give; the folder layout is
:mod:`nidar_mi.render_folder` (table in the README, "Rendering"). With ``--trajectory`` the
scene is rendered along a trajectory, one render folder per frame
(:func:`nidar_mi.sequence.render_sequence`). The command chooses the Mitsuba variant
(``--variant``) before any work.
"""

from __future__ import annotations

import os

from ..render_folder import BIN_INTENSITY, DEFAULT_FORMATS, FORMATS
from ..render_session import INTENSITY_SOURCES, NIDAR_BRANCHES
from ..sequence import MAX_FRAMES
from ._common import (
    add_weather_args,
    out_path,
    parse_defines,
    parser,
    run,
    scene_inputs,
    seed_arg,
    show_progress,
    weather_of,
)

__all__ = ["main", "build_parser"]


def _parse_formats(text: str) -> list[str]:
    from ..errors import NidarError

    fmts = [f.strip().lower() for f in text.split(",") if f.strip()]
    bad = [f for f in fmts if f not in FORMATS]
    if bad or not fmts:
        raise NidarError(
            f"--formats: unknown format '{','.join(bad)}' (choose from {', '.join(FORMATS)})"
        )
    return fmts


def _memory(text: str | None, flag: str = "--max-memory") -> int | None:
    from ..errors import NidarError
    from ..io.sizes import parse_size

    if text is None:
        return None
    try:
        return parse_size(text)
    except ValueError as e:
        raise NidarError(f"{flag}: {e}") from None


def _sequence_summary(manifest: dict, out_dir: str) -> str:
    fps = manifest["frames_per_s"]
    return (
        f"wrote {manifest['frame_count']} frames at {manifest['rate_hz']:g} Hz to {out_dir} "
        f"({fps:.2f} frames/s rendered, {manifest['timings_s']['total']:.1f} s in all)"
    )


def _summary(manifest: dict, out_dir: str) -> str:
    rows = [("sensor", "kind", "rays/pixels", "returns", "time (s)")]
    for name, e in manifest["lidars"].items():
        t = f"{e['timings_s']['scan_total']:.2f}"
        rows.append((name, "lidar", str(e["rays"]), str(e["returns"]), t))
    for name, e in manifest["cameras"].items():
        t = f"{e['timings_s']['render_total']:.2f}"
        rows.append((name, "camera", str(e["width"] * e["height"]), "-", t))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    total = manifest["timings_s"]["total"]
    lines.append(f"wrote {len(manifest['files'])} files to {out_dir} in {total:.1f} s")
    return "\n".join(lines)


def build_parser():
    p = parser(
        "render",
        "Scan every lidar sensor of a scene (points with NIR intensity) and render every "
        "camera (RGB, NIR band at the LiDAR wavelength, depth).",
        verbose="one per sensor scanned or rendered, and with --trajectory one per frame, each "
        "with its time",
    )
    p.add_argument("scene", help="scene XML file")
    p.add_argument(
        "-o", "--out", type=out_path, help="output directory (default: out/<scene name>)"
    )
    p.add_argument(
        "--formats",
        default=",".join(DEFAULT_FORMATS),
        help=f"point formats, from {','.join(FORMATS)} (default {','.join(DEFAULT_FORMATS)})",
    )
    p.add_argument(
        "--seed",
        type=seed_arg,
        default=None,
        help="overrides every lidar's seed; camera sampler seed; 0 .. 2**32-1 "
        "(default: each lidar's own seed, sampler seed 0)",
    )
    p.add_argument("--spp", type=int, default=16, help="camera samples per pixel (default 16)")
    p.add_argument(
        "--variant",
        default=None,
        help="Mitsuba variant (default: cuda_ad_spectral if CUDA works, else llvm_ad_spectral)",
    )
    p.add_argument(
        "-D",
        dest="params",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a scene parameter (<default name=...>), e.g. -D cols=512; repeatable",
    )
    _add_intensity_args(p)
    p.add_argument("--rgb-twin", action="store_true", help="load the scene's RGB-only twin")
    p.add_argument("--no-cameras", action="store_true", help="skip the camera renders")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT of the other kind of render (one scene / --trajectory) or one "
        "written by nidar_mi 0.1.0 (no record of its files); a file render did not write is "
        "never removed",
    )
    p.add_argument(
        "--max-memory",
        default=None,
        metavar="SIZE",
        help="memory a scan or camera render may use, e.g. 16G (default: half the machine's "
        "memory, or NIDAR_MAX_MEMORY); larger requests are refused before anything runs",
    )
    add_weather_args(p, what="for every lidar and camera (replacing the scene's own)")
    _add_sequence_args(p)
    p.add_argument(
        "--deskew",
        action="store_true",
        help="also write xyz_deskewed: the points in the lidar frame at the sweep's start",
    )
    return p


def _add_intensity_args(p) -> None:
    """``--intensity`` and what goes with it; the ``.bin`` intensity convention."""
    p.add_argument(
        "--intensity",
        default="physics",
        choices=INTENSITY_SOURCES,
        help="nidar: also predict intensity_nidar / nidar_observed from the cameras with NIDAR",
    )
    p.add_argument(
        "--weights",
        default=None,
        help="NIDAR weights folder for --intensity nidar (default: the shipped model)",
    )
    p.add_argument(
        "--nidar-branch",
        default=None,
        choices=NIDAR_BRANCHES,
        help="with --intensity nidar: R, the calibrated reflectance branch (the paper's, "
        "default); I_hat, the dense intensity head",
    )
    p.add_argument(
        "--bin-intensity",
        default=None,
        choices=BIN_INTENSITY,
        help="intensity in points.bin: unit, KITTI's [0, 1] (intensity / the sensor's full "
        "scale, clipped; default); raw, the simulated intensity as it is",
    )
    p.add_argument(
        "--profile",
        default=None,
        help="NIDAR sensor profile: sim-905 (the simulator's; default), kitti-hdl64e, "
        "generic-compensated, generic-raw, or a profile file from python -m nidar_mi.calibrate",
    )


def _add_sequence_args(p) -> None:
    """Rendering along a trajectory."""
    seq = p.add_argument_group("sequences (rendering along a trajectory)")
    seq.add_argument(
        "--trajectory",
        metavar="FILE",
        default=None,
        help="rig poses: KITTI odometry (12 numbers per line), TUM (t x y z qx qy qz qw) or CSV "
        "with a t,x,y,z,qx,qy,qz,qw header; writes one render folder per frame",
    )
    seq.add_argument(
        "--rate",
        type=float,
        default=None,
        help="frames per second (default: the first lidar's frame rate, its rotation_rate but "
        "for the at128's 10 Hz); also the sample "
        "rate of KITTI odometry poses",
    )
    seq.add_argument(
        "--frames", type=int, default=None, help="number of frames (default: all that fit)"
    )
    seq.add_argument(
        "--sequence-formats",
        default="",
        metavar="LIST",
        help="whole-sequence outputs beside the frame folders: kitti (KITTI odometry layout), "
        "rosbag (ROS 2 bag); comma-separated",
    )
    seq.add_argument(
        "--previews",
        choices=("all", "first", "none"),
        default=None,
        help="range previews (range.png, intensity.png) of every frame, the first frame only "
        "(default) or none",
    )
    seq.add_argument(
        "--max-frames",
        type=int,
        default=None,
        metavar="N",
        help=f"the most frames a sequence may have (default {MAX_FRAMES}); longer ones are "
        "refused before anything runs",
    )
    seq.add_argument(
        "--max-disk",
        default=None,
        metavar="SIZE",
        help="disk space a sequence may take, e.g. 50G (default: the free space of OUT's "
        "filesystem); a sequence estimated larger is refused before anything runs",
    )


def _bin_intensity(args) -> str:
    """``--bin-intensity``, refused where no ``.bin`` is written (default ``unit``)."""
    from ..errors import NidarError

    if args.bin_intensity is None:
        return "unit"
    bins = "bin" in _parse_formats(args.formats) or "kitti" in args.sequence_formats.lower()
    if not bins:
        raise NidarError(
            "--bin-intensity applies to the .bin points: add bin to --formats (or, with "
            "--trajectory, kitti to --sequence-formats)"
        )
    return args.bin_intensity


def _sequence_options(args):
    """The :class:`~nidar_mi.sequence.SequenceOptions` of ``--trajectory``."""
    from ..errors import NidarError
    from ..render_session import RenderOptions
    from ..sequence import SequenceOptions

    if args.intensity != "physics" or args.rgb_twin:
        raise NidarError("--trajectory renders physics intensity of the scene itself")
    if args.weights is not None or args.nidar_branch is not None or args.profile:
        raise NidarError(
            "--weights, --nidar-branch and --profile are used only with --intensity nidar"
        )
    frame = RenderOptions(
        args.scene,
        formats=tuple(_parse_formats(args.formats)),
        seed=args.seed,
        spp=args.spp,
        params=parse_defines(args.params),
        cameras=not args.no_cameras,
        bin_intensity=_bin_intensity(args),
        max_memory=_memory(args.max_memory),
        deskew=args.deskew,
        progress=show_progress(args),
        weather=weather_of(args),
    )
    return SequenceOptions(
        frame,
        args.trajectory,
        rate=args.rate,
        frames=args.frames,
        sequence_formats=tuple(
            f.strip().lower() for f in args.sequence_formats.split(",") if f.strip()
        ),
        max_frames=MAX_FRAMES if args.max_frames is None else args.max_frames,
        max_disk=_memory(args.max_disk, "--max-disk"),
        previews=args.previews or "first",
    )


def _render_options(args):
    """The :class:`~nidar_mi.render_session.RenderOptions` of a single render."""
    from ..errors import NidarError
    from ..render_session import RenderOptions

    if args.intensity == "nidar" and args.no_cameras:
        raise NidarError("--intensity nidar needs the camera renders (drop --no-cameras)")
    weather = weather_of(args)
    if weather is not None and not weather.clear and args.intensity == "nidar":
        raise NidarError(
            "--intensity nidar reads the surfaces from the camera images, which the weather "
            "veils (NIDAR learned clear days): render weather with --intensity physics"
        )
    profile = None
    if args.intensity == "nidar":
        from ..datasets.sensor_profiles import profile_line

        if not args.quiet:
            print(profile_line(args.profile, branch=args.nidar_branch))
    if args.profile is not None:
        if args.intensity != "nidar":
            raise NidarError("--profile applies to --intensity nidar")
        from ..datasets.sensor_profiles import resolve_profile
        from ..nidar.pipeline import NidarModel

        profile = resolve_profile(args.profile, NidarModel.load(args.weights))
    return RenderOptions(
        args.scene,
        formats=tuple(_parse_formats(args.formats)),
        seed=args.seed,
        spp=args.spp,
        rgb_twin=args.rgb_twin,
        params=parse_defines(args.params),
        cameras=not args.no_cameras,
        intensity=args.intensity,
        weights=args.weights,
        nidar_branch=args.nidar_branch,
        profile=profile,
        bin_intensity=_bin_intensity(args),
        max_memory=_memory(args.max_memory),
        deskew=args.deskew,
        progress=show_progress(args),
        weather=weather,
    )


def _require_extras(args) -> None:
    """The optional dependencies the options need (:mod:`nidar_mi.extras`), checked before any
    work."""
    from ..errors import NidarError
    from ..extras import require

    if args.profile is not None and args.intensity != "nidar":
        raise NidarError("--profile applies to --intensity nidar")
    if args.intensity == "nidar":
        require("nidar", "--intensity nidar")
    if "laz" in _parse_formats(args.formats):
        require("laz", "--formats laz")
    if "rosbag" in args.sequence_formats.lower():
        require("ros", "--sequence-formats rosbag")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    out = args.out or os.path.join("out", os.path.splitext(os.path.basename(args.scene))[0])

    def work():
        from ..backend import set_variant
        from ..errors import NidarError
        from ..io.atomic import check_output_folder
        from ..render_folder import RENDER_OWNER, SEQUENCE_OWNER

        sequence_only = (args.rate, args.frames, args.max_frames, args.max_disk)
        inputs = [*scene_inputs(args.scene), args.trajectory, args.weights, args.profile]
        owner = RENDER_OWNER if args.trajectory is None else SEQUENCE_OWNER
        check_output_folder(out, owner=owner, overwrite=args.overwrite, inputs=inputs)
        _require_extras(args)
        if args.trajectory is None and (
            any(v is not None for v in sequence_only)
            or args.sequence_formats
            or args.previews is not None
        ):
            raise NidarError(
                "--rate, --frames, --sequence-formats, --previews, --max-frames and --max-disk "
                "need --trajectory"
            )
        if args.trajectory is not None:
            from ..sequence import check_sequence, render_sequence

            options = _sequence_options(args)
            check_sequence(options)  # bad options are named before the variant starts
            set_variant(args.variant)
            manifest = render_sequence(options, out, overwrite=args.overwrite)
            if not args.quiet:
                print(_sequence_summary(manifest, out))
            return

        from ..render_session import check_options
        from ..simulate import render_scene

        options = _render_options(args)
        check_options(options)  # bad options are named before the variant starts
        set_variant(args.variant)
        manifest = render_scene(options, out, overwrite=args.overwrite)
        if not args.quiet:
            print(_summary(manifest, out))

    return run(work, args=args)
