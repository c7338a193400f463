"""``python -m nidar_mi.render SCENE.xml -o OUT``: scan every LiDAR and render every camera.

The work is :func:`nidar_mi.simulate.render_scene`; the folder layout is
:mod:`nidar_mi.render_folder` (table in the README, "Rendering").
"""

from __future__ import annotations

import os

from ..render_folder import DEFAULT_FORMATS, FORMATS
from ..simulate import INTENSITY_SOURCES, NIDAR_BRANCHES
from ._common import parse_defines, parser, run

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
    )
    p.add_argument("scene", help="scene XML file")
    p.add_argument("-o", "--out", help="output directory (default: out/<scene name>)")
    p.add_argument(
        "--formats",
        default=",".join(DEFAULT_FORMATS),
        help=f"point formats, from {','.join(FORMATS)} (default {','.join(DEFAULT_FORMATS)})",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="overrides every lidar's seed; camera sampler seed"
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
    p.add_argument(
        "--intensity",
        default="physics",
        choices=INTENSITY_SOURCES,
        help="nidar: also predict intensity_nidar / nidar_observed from the cameras with NIDAR",
    )
    p.add_argument(
        "--weights", default=None, help="NIDAR weights folder (default: the shipped model)"
    )
    p.add_argument(
        "--nidar-branch",
        default="R",
        choices=NIDAR_BRANCHES,
        help="R: calibrated reflectance branch (the paper's, default); I_hat: dense intensity head",
    )
    p.add_argument(
        "--profile",
        default=None,
        help="NIDAR sensor profile: sim-905 (the simulator's; default), kitti-hdl64e, or a "
        "profile file from python -m nidar_mi.calibrate",
    )
    p.add_argument("--rgb-twin", action="store_true", help="load the scene's RGB-only twin")
    p.add_argument("--no-cameras", action="store_true", help="skip the camera renders")
    p.add_argument(
        "--overwrite", action="store_true", help="replace OUT even when it holds other files"
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    out = args.out or os.path.join("out", os.path.splitext(os.path.basename(args.scene))[0])

    def work():
        from ..simulate import render_scene

        profile = None
        if args.profile is not None:
            from ..errors import NidarError

            if args.intensity != "nidar":
                raise NidarError("--profile applies to --intensity nidar")
            from ..nidar.pipeline import NidarModel
            from ..nidar.profiles import resolve_profile

            profile = resolve_profile(args.profile, NidarModel.load(args.weights))
        manifest = render_scene(
            args.scene,
            out,
            formats=_parse_formats(args.formats),
            seed=args.seed,
            spp=args.spp,
            variant=args.variant,
            rgb_twin=args.rgb_twin,
            params=parse_defines(args.params),
            cameras=not args.no_cameras,
            progress=not args.quiet,
            intensity=args.intensity,
            weights=args.weights,
            nidar_branch=args.nidar_branch,
            profile=profile,
            overwrite=args.overwrite,
        )
        if not args.quiet:
            print(_summary(manifest, out))

    return run(work)
