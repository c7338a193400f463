"""``python -m nidar_mi.calibrate``: fit a sensor profile on a sensor's own scans.

    python -m nidar_mi.calibrate SCANS... -o profile.json [--name NAME] [--sensor TEXT]
                                 [--form context|gbm|range_ring|distance_quantile|physical]
                                 [--inputs GROUP,...] [--kind gbm|mlp] [--balance group|frame]
                                 [--target intensity|rank|blend]
                                 [--branch R|I_hat]
                                 [--no-geometry | --no-incidence]
                                 [--weights DIR] [--intensity-scale S] [--splits S,...]
                                 [--max-frames K] [--overwrite] [-q | -v] [--progress | --no-progress]

The default form is ``kitti-hdl64e``'s, ``context`` (below). A ``gbm`` profile reads the
incidence unless ``--no-incidence``.

``SCANS`` are folders (:mod:`nidar_mi.datasets.scans`): KITTI layouts (``velodyne/``,
``image_2/``, ``calib/``), NIDAR data folders (``meta.json``), or generic folders with
``points/<id>.<ext>`` (an ``intensity`` field, optionally ``ring``), ``images/`` and
``calib.yaml``. The NIDAR model (``--weights``, default the shipped one) is run on every image;
its ``--branch`` map at the returns a camera sees is fitted to the sensor's intensities
(:func:`nidar_mi.datasets.profile_fitting.fit_scan_profile`). A ``gbm`` profile also reads each
return's ``|cos θ|``, from normals estimated on the scan's own points
(:func:`nidar_mi.geometry.incidence_cosine`), unless ``--no-incidence`` (the former recipe of
``kitti-hdl64e`` reads it). ``assign`` and ``render`` then estimate it the same way on the clouds
they are given. With ``--no-geometry`` the profile reads the value and the
incidence only, not the range and elevation: the form of a range-compensated intensity
``g·ρ·cos θ``, which learns no range response and no scene layout (the simulator's ``sim-905``).
``--max-frames K`` fits on K of the frames, evenly spaced over their order
(:func:`nidar_mi.datasets.profile_fitting.select_frames`): one to ten frames of a sensor already
beat the generic profiles (docs/NIDAR.md, "Calibrating from a few frames"). ``--form physical``
fits the closed form of the generic profiles (gain and range exponent). ``--form context`` reads
each return's named inputs (:mod:`nidar_mi.profiles.inputs`): range, elevation and incidence,
the laser index, the local geometry of the scan around it, the image around its pixel and all
of NIDAR's maps there; ``--inputs`` names the groups (default: ``return,ring,geometry,image,
nidar``, the recipe measured leave one group out; ``image_rel`` adds the image inputs with the
exposure divided out; without ``image``, ``image_rel`` and ``nidar`` the profile needs no
image); ``--kind mlp`` puts
the small learned head (:mod:`nidar_mi.profiles.head`) in place of the trees, some thirty times
cheaper to apply. A context profile weighs each recording alike (``--balance group``, the
default: a recording is a scan folder, or for a KITTI frame named ``<source>__<id>`` its source,
:func:`nidar_mi.datasets.scans.recording_of`; the frames of a recording share its weight, so
that a long drive does not outweigh short ones) or each frame (``--balance frame``). The trees fit the intensity and its per-frame rank and
average the two (``--target blend``, the default; ``intensity`` or ``rank``: one regression, half
the cost to apply; the head fits the intensity). The profile file
(:mod:`nidar_mi.profiles.sensor_profile`) then goes to ``assign --profile FILE`` or
``render --intensity nidar --profile FILE``.

An existing ``-o`` file is replaced only when it is a profile (an earlier output) or with
``--overwrite``; the file is written atomically.
"""

from __future__ import annotations

import json
import os
import sys

from ..datasets.sensor_profiles import (
    KITTI_PROFILE_FORM,
    KITTI_PROFILE_INCIDENCE,
    KITTI_PROFILE_OPTIONS,
)
from ..errors import NidarError
from ..extras import require
from ._common import out_path, parser, run, show_progress

__all__ = ["build_parser", "main"]


def build_parser():
    p = parser(
        "calibrate",
        "Fit a sensor profile (its response to the value and the return's geometry) on a "
        "sensor's own scans.",
        verbose="the frames read and the returns each gives, the fit's summary",
    )
    p.add_argument(
        "scans", nargs="+", metavar="SCANS", help="scan folders (KITTI, data or generic)"
    )
    p.add_argument(
        "-o", "--out", required=True, type=out_path, help="profile file to write (.json)"
    )
    p.add_argument("--name", help="profile name (default: the output file's stem)")
    p.add_argument("--sensor", default="", help="what the sensor is, free text")
    p.add_argument(
        "--form",
        default=KITTI_PROFILE_FORM,
        choices=("gbm", "context", "range_ring", "distance_quantile", "physical"),
        help="context: gradient-boosted regression on the return's inputs (--inputs; the "
        "default, the recipe of kitti-hdl64e); gbm: gradient-boosted regression on value, range "
        "and elevation, monotone in the value; "
        "range_ring: monotone map per range bin + ring gains; "
        "distance_quantile: the paper's distance encoding + quantile map; physical: "
        "gain * R * |cos θ| / d^p, the generic profiles' closed form",
    )
    p.add_argument(
        "--no-incidence",
        action="store_true",
        help="gbm, physical: do not read the incidence |cos θ| of each return (read by default)",
    )
    p.add_argument(
        "--no-geometry",
        action="store_true",
        help="gbm: read the value and the incidence only, not the range and elevation (a "
        "range-compensated sensor; carries over to other layouts)",
    )
    p.add_argument(
        "--inputs",
        metavar="GROUP,...",
        help="context: the input groups read, of return, ring, geometry, image, image_rel, "
        "nidar (default: return,ring,geometry,image,nidar; image_rel: the image inputs with "
        "the exposure divided out)",
    )
    p.add_argument(
        "--kind",
        choices=("gbm", "mlp"),
        help="context: LightGBM's trees or the small learned head (default: kitti-hdl64e's, "
        f"{KITTI_PROFILE_OPTIONS.get('kind', 'gbm')})",
    )
    p.add_argument(
        "--balance",
        choices=("group", "frame"),
        help="context: weigh each recording (scan folder) alike, its frames sharing its weight "
        "(group, the default), or each frame alike (frame)",
    )
    p.add_argument(
        "--target",
        choices=("intensity", "rank", "blend"),
        help="context: fit the intensity, its per-frame rank, or both and average them "
        "(default: blend for the trees, intensity for the head)",
    )
    p.add_argument("--branch", default="R", choices=("R", "I_hat"), help="NIDAR map to calibrate")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument(
        "--intensity-scale",
        type=float,
        help="divide generic clouds' intensities by this (default: the simulator's own clouds by "
        "their sensor's full scale; others by 1 or 255, from their range)",
    )
    p.add_argument("--splits", help="data folders: only these splits, e.g. train,val")
    p.add_argument(
        "--max-frames",
        type=int,
        metavar="K",
        help="fit on K of the frames, evenly spaced over their order (default: all)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing -o file that is not a sensor profile (an earlier profile is always replaced)",
    )
    return p


def _is_profile(path) -> bool:
    """Whether ``path`` holds a sensor profile (an earlier output of this command)."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f).get("schema", "").startswith("nidar_mi.sensor_profile/")
    except (OSError, ValueError, AttributeError, UnicodeDecodeError):
        return False


def _check_target(path: str, overwrite: bool, inputs: list) -> str:
    """The profile file to write (a link's target; :func:`nidar_mi.io.atomic.check_output_file`)."""
    from ..io.atomic import check_output_file

    checked = check_output_file(
        path, overwrite=overwrite, inputs=inputs, earlier=_is_profile, kind="a sensor profile"
    )
    return str(checked)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        require("nidar", "calibrate")
        _calibrate(args, argv)

    return run(work, args=args)


def _calibrate(args, argv) -> None:
    from ..datasets.profile_fitting import fit_scan_profile, select_frames
    from ..datasets.scans import load_scans
    from ..nidar.pipeline import NidarModel

    if args.no_incidence and args.form not in ("gbm", "physical"):
        raise NidarError(f"--no-incidence needs --form gbm or physical (got --form {args.form})")
    options = _context_options(args)
    if args.max_frames is not None and args.max_frames < 1:
        raise NidarError(f"--max-frames must be at least 1 (got {args.max_frames})")
    incidence = args.form in ("gbm", "physical") and (
        KITTI_PROFILE_INCIDENCE and not args.no_incidence
    )
    if args.no_geometry and not incidence:
        raise NidarError(
            "--no-geometry needs the incidence (--form gbm, without --no-incidence): the profile "
            "reads the value and the incidence"
        )
    if args.no_geometry and args.form != "gbm":
        raise NidarError(f"--no-geometry needs --form gbm (got --form {args.form})")
    target = _check_target(args.out, args.overwrite, [*args.scans, args.weights])
    name = args.name or os.path.splitext(os.path.basename(args.out))[0]
    splits = [s.strip() for s in args.splits.split(",")] if args.splits else None
    scans = load_scans(
        args.scans,
        splits=splits,
        intensity_scale=args.intensity_scale,
        progress=show_progress(args),
    )
    scans = select_frames(scans, args.max_frames)
    model = NidarModel.load(args.weights)
    command = "python -m nidar_mi.calibrate " + " ".join(sys.argv[1:] if argv is None else argv)
    profile = fit_scan_profile(
        model,
        scans,
        name=name,
        sensor=args.sensor or "(not described)",
        form=args.form,
        branch=args.branch,
        provenance={"data": [os.path.abspath(s) for s in args.scans], "command": command},
        progress=show_progress(args),
        incidence=incidence,
        **({"use_geometry": False} if args.no_geometry else {}),
        **options,
    )
    profile.save(target)
    if not args.quiet:
        prov = profile.provenance
        print(
            f"{profile.form} profile '{profile.name}'"
            f"{_reads(profile)} fitted on {prov['frames']} frames, "
            f"{prov['returns']} returns (rings: {prov['rings']}); wrote {args.out}"
        )


def _context_options(args) -> dict:
    """The ``context`` form's options from ``--inputs`` (``features``: the groups' inputs),
    ``--kind``, ``--balance`` and ``--target``."""
    flags = (("--inputs", args.inputs), ("--kind", args.kind), ("--balance", args.balance))
    flags += (("--target", args.target),)
    given = [f for f, v in flags if v is not None]
    if given and args.form != "context":
        raise NidarError(f"{given[0]} needs --form context (got --form {args.form})")
    options = {}
    if args.form == "context":
        options["kind"] = args.kind or KITTI_PROFILE_OPTIONS.get("kind", "gbm")
    if args.balance is not None:
        options["balance"] = args.balance
    if args.target is not None:
        options["target"] = args.target
    if args.inputs is None:
        return options
    from ..profiles.inputs import GROUPS

    groups = [g.strip() for g in args.inputs.split(",") if g.strip()]
    bad = [g for g in groups if g not in GROUPS]
    if bad or not groups:
        raise NidarError(f"--inputs: groups of {', '.join(GROUPS)} (got {args.inputs!r})")
    return options | {"features": tuple(f for g in GROUPS if g in groups for f in GROUPS[g])}


def _reads(profile) -> str:
    """What the summary line adds about the incidence (or the inputs of a context profile)."""
    if profile.form == "context":
        m = profile.mapping
        return f" ({m.kind}, {m.target}; inputs: {', '.join(m.groups)})"
    if not profile.uses_incidence:
        return ""
    if profile.form == "physical":
        return " (with incidence)"
    return " (with incidence)" if profile.mapping.uses_geometry else " (value and incidence only)"
