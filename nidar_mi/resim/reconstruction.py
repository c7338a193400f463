"""``reconstruct``: a recorded drive in, a re-simulation folder out (the steps of
:mod:`nidar_mi.resim`, in order).

Output folder (published whole, with the record of :data:`OWNER`)::

    OUT/scene.xml, sensor_*.xml, surfaces.ply, layout.yaml    the scene (:mod:`.scene_files`)
    OUT/poses.txt          every frame's LiDAR pose in frame 0's LiDAR frame (KITTI format)
    OUT/heldout/<id>.bin   the re-simulated scan of each held-out frame (KITTI .bin: x, y, z,
                           intensity on the real sensor's [0, 1] scale; LiDAR frame; the
                           drive's coverage only, the beams of the mounting's shadow
                           dropped: :mod:`.shadow`; the expected scan: detected where E >= T,
                           intensity max(E - b, 0) without noise; the static surfaces, the
                           splats (:mod:`.splats`) and those that moved, as the training
                           frame nearest in time saw them, moved on: :mod:`.moving`; the
                           returns in the holes of the training scans next to the frame
                           dropped: :mod:`.holes`; the static triangles they saw
                           through hidden: :mod:`.seen_through`)
    OUT/report.json        inputs, timings, the recovered sensor and its shadow, the fit's
                           residuals, the held-out metrics of the re-simulation and of the
                           baselines

Held-out frames enter only the odometry (for their poses) and the evaluation: the layout, the
mesh, the prior and the fit see the training frames alone.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass

from ..errors import NidarError
from ..io.ownership import Owner
from .drive_folder import Drive, open_drive

__all__ = ["ReconstructOptions", "OWNER", "check", "reconstruct", "MAX_FRAMES"]

log = logging.getLogger("nidar_mi.reconstruct")

#: Who writes a re-simulation folder (:mod:`nidar_mi.io.ownership`): it replaces it whole.
OWNER = Owner(
    "reconstruct",
    "drive",
    names=(
        "scene.xml",
        "sensor_*.xml",
        "surfaces.ply",
        "layout.yaml",
        "poses.txt",
        "heldout/*",
        "report.json",
    ),
)

#: The most frames a drive may have (bounds memory and time before any work).
MAX_FRAMES = 400
#: The most fit steps and carving passes (each a pass over every training sample).
MAX_ITERATIONS = 10_000
MAX_CARVE_PASSES = 16
#: The accepted ``albedo_scale`` (the fitted ρ over the surfaces' reflectance).
ALBEDO_SCALE_RANGE = (0.01, 100.0)


@dataclass(frozen=True)
class ReconstructOptions:
    """What ``reconstruct`` does (the command's flags)."""

    drive: str
    out: str
    holdout: tuple[str, ...] = ()
    poses: str | None = None
    voxel_m: float = 0.1
    iterations: int = 40
    carve_passes: int = 2
    transient_frames: int = 3
    moving: bool = True
    holes: bool = True
    through: bool = True
    splats: bool = True
    range_offsets: bool = True
    prior: bool = True
    weights: str | None = None
    albedo_scale: float | None = None
    seed: int = 0
    max_frames: int = MAX_FRAMES
    progress: bool = False
    overwrite: bool = False


def check(options: ReconstructOptions) -> Drive:
    """Every check that needs no work: the drive, the held-out ids, the poses, the bounds, the
    output folder. Raises NidarError."""
    from ..extras import installed, require
    from ..io.atomic import check_output_folder

    if not 0.02 <= options.voxel_m <= 1.0:
        raise NidarError(f"`voxel` must lie in [0.02, 1] m (got {options.voxel_m:g})")
    if options.max_frames < 2:
        raise NidarError(f"`max_frames` must be >= 2 (got {options.max_frames})")
    for name, value, top in (
        ("transient_frames", options.transient_frames, options.max_frames),
        ("iterations", options.iterations, MAX_ITERATIONS),
        ("carve_passes", options.carve_passes, MAX_CARVE_PASSES),
    ):
        low = 1 if name == "iterations" else 0
        if not low <= value <= top:
            raise NidarError(f"`{name}` must lie in [{low}, {top}] (got {value})")
    k = options.albedo_scale
    low, top = ALBEDO_SCALE_RANGE
    if k is not None and not low <= k <= top:  # NaN fails too
        raise NidarError(f"`albedo_scale` must lie in [{low:g}, {top:g}] (got {k:g})")
    drive = open_drive(options.drive, holdout=list(options.holdout), poses_file=options.poses)
    if len(drive.ids) > options.max_frames:
        raise NidarError(
            f"{options.drive} has {len(drive.ids)} scans, more than `max_frames` "
            f"({options.max_frames})"
        )
    if drive.poses is None:  # KISS-ICP's odometry, refined by Open3D's registration
        absent = [m for m in ("kiss_icp", "open3d") if not installed(m)]
        if absent:
            raise NidarError(
                "reconstruct of a drive without poses needs the optional 'drive' and 'resim' "
                f"dependencies ({', '.join(absent)} not installed): "
                "pip install 'nidar_mi[drive,resim]' (or give `poses`)"
            )
    if options.weights is not None:
        if not options.prior:
            raise NidarError("`weights` are the NIDAR prior's: they have no effect with `no_prior`")
        if not os.path.isdir(options.weights):
            raise NidarError(f"`weights`: {options.weights} is not a folder")
        require("nidar", "`weights` (NIDAR's prior)")
    velodyne = os.path.realpath(os.path.join(options.drive, "velodyne"))
    out = os.path.realpath(options.out)
    if os.path.commonpath([velodyne, out]) == velodyne:
        raise NidarError(f"`out` {options.out} lies in the drive's scans ({velodyne})")
    check_output_folder(
        options.out, owner=OWNER, overwrite=options.overwrite, inputs=_inputs(options)
    )
    return drive


def _inputs(options: ReconstructOptions) -> list[str | None]:
    """What the command reads, which ``out`` may neither be nor hold."""
    return [options.drive, options.poses, options.weights]


def reconstruct(options: ReconstructOptions) -> dict:
    """Run the whole reconstruction into ``options.out``; returns the report."""
    from ..io.atomic import staged_directory

    drive = check(options)
    with staged_directory(
        options.out, owner=OWNER, overwrite=options.overwrite, inputs=_inputs(options)
    ) as stage:
        report = _run(drive, options, str(stage))
    return report


class _Clock:
    """Wall times of the steps, s."""

    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.times[name] = round(now - self._t, 3)
        self._t = now
        log.debug("%s: %.1f s", name, self.times[name])


def _run(drive: Drive, options: ReconstructOptions, stage: str) -> dict:
    from ..io.atomic import atomic_write_json
    from .build import build_surfaces, drive_poses, drop_scratch, scratch_scene
    from .frames import load_frames
    from .heldout_scans import evaluate_heldout
    from .invert import invert
    from .mesh import merge_meshes
    from .range_offsets import corrected_frames, fit_range_offsets
    from .write import albedo_scale, write_outputs

    clock = _Clock()
    frames = load_frames(drive, progress=options.progress)
    clock.lap("read")
    poses = drive_poses(drive, frames, progress=options.progress)
    clock.lap("poses")
    offsets = None
    if options.range_offsets:  # the held-out frames' returns stay as measured
        train = [drive.index(i) for i in drive.train]
        offsets = fit_range_offsets(frames, poses, train, scratch_scene(stage), options.voxel_m)
        drop_scratch(stage)
        frames = corrected_frames(frames, train, offsets.offsets_m)
        clock.lap("range_offsets")
    mesh, splats, carved, transient = build_surfaces(drive, frames, poses, options, stage)
    clock.lap("mesh")
    inv = invert(drive, frames, poses, mesh, options, stage, splats=splats)
    clock.lap("fit")
    surfaces = merge_meshes([mesh, splats.mesh])  # inv's ρ: the mesh's vertices, then the splats'
    albedo = albedo_scale(inv, options.albedo_scale)
    scene_path = write_outputs(
        stage, drive, frames, poses, surfaces, inv, range_offsets=offsets, albedo=albedo
    )
    clock.lap("write")
    held = evaluate_heldout(
        scene_path, drive, frames, poses, inv, stage, mesh=surfaces, moving=options.moving,
        holes=options.holes, through=options.through,
    )  # fmt: skip
    clock.lap("evaluate")
    report = {
        "drive": os.path.abspath(drive.root),
        "frames": list(drive.ids),
        "holdout": list(drive.holdout),
        "poses_source": drive.poses_source,
        "columns": frames.columns,
        "coverage": float(frames.coverage.mean()),
        "mesh": {
            "vertices": len(mesh.vertices),
            "faces": len(mesh.faces),
            "carved": carved["mesh"],
            "transient": transient,
        },
        "splats": {
            "vertices": len(splats.mesh.vertices),
            "faces": len(splats.mesh.faces),
            "carved": carved["splats"],
        },
        "layout": {
            "elevation_deg": frames.layout.elevation_deg.tolist(),
            "vertical_offset_m": frames.layout.vertical_offset_m.tolist(),
        },
        "range_offsets": None if offsets is None else offsets.summary(),
        "fit": inv.summary() | {"albedo": {"scale": albedo[0], "source": albedo[1]}},
        "shadow": inv.shadow.summary(),
        "heldout": held,
        "timings_s": clock.times,
    }
    atomic_write_json(os.path.join(stage, "report.json"), report)
    return report
