"""Render a scene along a trajectory: one render folder per frame, poses and times beside them.

The trajectory (:mod:`nidar_mi.io.trajectory`) moves the rig; every sensor keeps its scene pose
as its mounting on the rig, so at time ``t`` a sensor is at ``T_rig(t) · T_mount``. Frame ``k``
starts at ``t_k = t_0 + k / rate``. Each LiDAR sweeps from ``t_k`` on: column ``j`` fires at
``t_k + t_j`` (:class:`nidar_mi.lidar.pattern.BeamPattern`) and is cast from the rig pose
SE(3)-interpolated at that time (motion distortion; ``t`` per point). Each camera is exposed
when the first LiDAR's sweep points along the camera's optical axis (how KITTI triggers its
cameras), from the rig pose of that time. Poses enter the kernels as data: no recompilation per
frame.

Layout (``OUT``)::

    manifest.json       request (scene, trajectory, rate, frames, ...), per-frame times and
                        timings, throughput, file list
    poses.txt           KITTI odometry: per frame T_{lidar_0 <- lidar_k} (3×4 row-major), the
                        first LiDAR's pose at the frame's start relative to frame 0
    times.txt           per frame its start time t_k - t_0, s
    frames/000000/ ...  one render folder per frame (:mod:`nidar_mi.render_folder`)
    kitti/              with sequence format ``kitti``: the first LiDAR's sweeps in the KITTI
                        odometry layout (:func:`nidar_mi.io.kitti.write_sequence`)
    rosbag/             with ``rosbag``: a ROS 2 bag of the first LiDAR's sweeps and the camera
                        images (:func:`nidar_mi.io.rosbag.write_ros2_bag`), stamped in trajectory
                        time

The ``kitti`` and ``rosbag`` outputs are written once every frame is rendered: the first LiDAR's
points (x, y, z, intensity, ring, t, label, instance) and the camera images stay in memory until
then.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import render_folder as rf
from .errors import NidarError
from .render_session import RenderOptions, RenderSession, check_options

__all__ = [
    "MAX_FRAMES",
    "SEQUENCE_FORMATS",
    "SequenceOptions",
    "camera_trigger_time",
    "check_sequence",
    "render_sequence",
    "sequence_bytes",
]

#: Whole-sequence outputs beside the frame folders.
SEQUENCE_FORMATS = ("kitti", "rosbag")
#: Points columns kept per frame for the sequence outputs.
_SEQUENCE_COLUMNS = ("xyz", "intensity", "ring", "t", "label", "instance")
#: Frames a sequence may have unless ``max_frames`` says otherwise (KITTI's longest odometry
#: sequence has 4,661; this is 2.8 h at 10 Hz).
MAX_FRAMES = 100_000
#: Bytes per point the sequence outputs keep in memory (``_SEQUENCE_COLUMNS``), and write: a
#: KITTI ``.bin`` and ``.label``; a ROS 2 bag's PointCloud2 (rounded up).
_KEPT_POINT_BYTES = 28
_OUTPUT_POINT_BYTES = {"kitti": 20, "rosbag": 32}


@dataclass(frozen=True)
class SequenceOptions:
    """What to render of a scene along a trajectory, and how.

    Attributes:
        scene: scene XML path.
        trajectory: KITTI odometry, TUM or CSV poses of the rig.
        rate: frames per second, Hz (None: the first LiDAR's rotation rate); also the sample
            rate of a KITTI odometry pose file.
        frames: number of frames (None: as many as the trajectory holds).
        formats: point formats of each frame (:data:`nidar_mi.render_folder.FORMATS`).
        sequence_formats: whole-sequence outputs, from :data:`SEQUENCE_FORMATS`.
        bin_intensity: ``unit`` or ``raw`` KITTI ``.bin`` intensity of each frame
            (:func:`nidar_mi.render_folder.write_lidar`).
        seed: base seed; frame ``k`` uses ``seed + k`` modulo 2³² (each LiDAR's own seed + k
            without it; the camera sampler ``k`` without it).
        spp: camera samples per pixel.
        params: the scene's ``<default>`` values (None: none).
        cameras: render the cameras.
        deskew: add ``xyz_deskewed`` (points in the LiDAR frame at the sweep's start) to every
            frame's points.
        max_memory: bytes one scan or camera render may use, and the sequence outputs keep in
            memory (None: the default limit).
        max_frames: the most frames the sequence may have (:data:`MAX_FRAMES`).
        max_disk: bytes the sequence may take on disk (None: the free space of its filesystem).
        progress: show a progress bar on stderr.
    """

    scene: str
    trajectory: str
    rate: float | None = None
    frames: int | None = None
    formats: tuple[str, ...] = rf.FORMATS
    sequence_formats: tuple[str, ...] = ()
    bin_intensity: str = "unit"
    seed: int | None = None
    spp: int = 16
    params: dict[str, str] | None = None
    cameras: bool = True
    deskew: bool = False
    max_memory: int | None = None
    max_frames: int = MAX_FRAMES
    max_disk: int | None = None
    progress: bool = True

    def frame_options(self) -> RenderOptions:
        """The options every frame is rendered with (physics intensity, the scene itself)."""
        return RenderOptions(
            self.scene,
            formats=tuple(self.formats),
            seed=self.seed,
            spp=self.spp,
            params=self.params,
            cameras=self.cameras,
            bin_intensity=self.bin_intensity,
            max_memory=self.max_memory,
            deskew=self.deskew,
            progress=self.progress,
        )


@dataclass
class _Rig:
    """The sensors' mountings on the rig and when each camera fires.

    Attributes:
        mounts: LiDAR id -> (4, 4) rig-from-LiDAR pose.
        cam_mounts: camera id -> (4, 4) rig-from-camera pose (empty without cameras).
        cam_offsets: camera id -> its trigger time after the sweep's start, s.
        lead: id of the first LiDAR (its poses are ``poses.txt``; its sweeps the sequence
            outputs).
    """

    mounts: dict[str, np.ndarray]
    cam_mounts: dict[str, np.ndarray]
    cam_offsets: dict[str, float]
    lead: str


@dataclass
class _Frames:
    """What the frame loop hands to the sequence's files and manifest."""

    log: list = field(default_factory=list)  # per frame its manifest entry
    start_poses: list = field(default_factory=list)  # per frame the lead LiDAR's (4, 4) pose
    keep: list = field(default_factory=list)  # per frame what the sequence outputs need
    written: list = field(default_factory=list)


def camera_trigger_time(lidar_config, T_lidar_mount: np.ndarray, T_camera_mount: np.ndarray):
    """Time after the sweep's start at which the LiDAR points along a camera's optical axis, s.

    Args:
        lidar_config: the LiDAR's :class:`~nidar_mi.lidar.config.LidarConfig`.
        T_lidar_mount, T_camera_mount: (4, 4) rig-from-sensor poses (Mitsuba cameras look
            along their +z).
    """
    pattern = lidar_config.pattern
    forward = np.linalg.inv(T_lidar_mount)[:3, :3] @ T_camera_mount[:3, 2]
    az = np.degrees(np.arctan2(forward[1], forward[0]))
    turn = pattern.spin * (az - pattern.scan_start_azimuth) / 360.0
    return float(np.mod(turn, 1.0) / pattern.rotation_rate)


def _matrix(T) -> np.ndarray:
    return np.array(T.matrix.numpy(), dtype=np.float64).reshape(4, 4)


def _set_camera_pose(camera, pose: np.ndarray) -> None:
    """Move a camera to ``pose`` (an opaque value: the render kernels are kept)."""
    import drjit as dr
    import mitsuba as mi

    params = mi.traverse(camera)
    T = mi.AffineTransform4f(np.asarray(pose, dtype=np.float32))
    dr.make_opaque(T)
    params["to_world"] = T
    params.update()


def _frame_times(
    traj, rate: float, frames: int | None, sweep_s: float, max_frames: int = MAX_FRAMES
) -> np.ndarray:
    t0, t1 = traj.span
    fit = int(np.floor((t1 - t0 - sweep_s) * rate + 1e-9)) + 1 if t1 - t0 >= sweep_s else 0
    if fit < 1:
        raise NidarError(
            f"{traj.path}: the trajectory spans {t1 - t0:.3g} s, less than one sweep "
            f"({sweep_s:.3g} s)"
        )
    if frames is None and fit > max_frames:
        raise NidarError(
            f"the trajectory ({t1 - t0:.3g} s) holds {fit} frames at {rate:g} Hz, more than the "
            f"limit of {max_frames} frames (`max_frames`); give `frames` or a lower `rate`"
        )
    if frames is None:
        frames = fit
    elif frames > fit:
        raise NidarError(
            f"`frames` {frames}: the trajectory ({t1 - t0:.3g} s) holds {fit} frames at "
            f"{rate:g} Hz (each needs its whole sweep of {sweep_s:.3g} s inside it)"
        )
    return t0 + np.arange(frames) / rate


def render_sequence(options: SequenceOptions, out_dir: str, *, overwrite: bool = False) -> dict:
    """Render a scene along a trajectory into ``out_dir`` (layout: module docstring), in the
    active Mitsuba variant (:func:`nidar_mi.backend.set_variant`).

    Args:
        options: what to render (:class:`SequenceOptions`).
        out_dir: the sequence folder (replaced whole; a non-empty folder that is not an earlier
            sequence needs ``overwrite``).
        overwrite: replace a non-empty ``out_dir``.

    Returns:
        The sequence manifest.

    Raises:
        NidarError: a bad option, scene or trajectory; ``out_dir`` is then left untouched.
    """
    from .io.atomic import staged_directory

    t_start = time.perf_counter()
    session, traj, rate, times = _open(options)
    session.check_memory()
    _check_bounds(session, options, len(times), out_dir)
    rig = _rig(session)
    with staged_directory(out_dir, overwrite=overwrite, marker=rf.MANIFEST) as stage:
        frames = _render_frames(
            stage, session, traj, times, rig, keep=bool(options.sequence_formats)
        )
        frames.written += _write_poses_and_times(stage, frames.start_poses, times)
        frames.written += _sequence_outputs(
            stage,
            options,
            frames.keep,
            np.asarray(frames.start_poses),
            times,
            session.lidars[0].config,
        )
        request = _sequence_request(session, options, rate, len(times))
        manifest = _sequence_manifest(session, request, rate, times, rig.lead, frames, stage)
        manifest["timings_s"]["total"] = time.perf_counter() - t_start
        rf.write_manifest(stage, manifest)
    return manifest


def check_sequence(options: SequenceOptions):
    """Refuse options that cannot be rendered, before anything is loaded: a bad rate, frame
    count (or more than ``max_frames``) or sequence format, a bad frame option, a missing trajectory file. The frames' cache
    key (:class:`~nidar_mi.render_folder.RenderRequest`).

    Raises:
        NidarError: one line naming the offending option.
    """
    rate, frames = options.rate, options.frames
    if rate is not None and not (rate > 0 and np.isfinite(rate)):
        raise NidarError(f"`rate` must be > 0 Hz (got {rate})")
    if frames is not None and frames < 1:
        raise NidarError(f"`frames` must be >= 1 (got {frames})")
    if not options.max_frames >= 1:
        raise NidarError(f"`max_frames` must be >= 1 (got {options.max_frames})")
    if frames is not None and frames > options.max_frames:
        raise NidarError(
            f"`frames` {frames} is more than the limit of {options.max_frames} frames "
            "(`max_frames`); render the sequence in parts or raise the limit"
        )
    bad = [f for f in options.sequence_formats if f not in SEQUENCE_FORMATS]
    if bad:
        raise NidarError(
            f"`sequence_formats`: unknown '{','.join(bad)}' "
            f"(choose from {', '.join(SEQUENCE_FORMATS)})"
        )
    request = check_options(options.frame_options())
    if not os.path.isfile(options.trajectory):
        raise NidarError(f"{options.trajectory}: no such trajectory file")
    return request


def _open(options: SequenceOptions):
    """Check the options, load the scene and the trajectory: the session, the trajectory, the
    frame rate (Hz) and the (F,) frame start times (s)."""
    from .io.trajectory import read_trajectory

    request = check_sequence(options)
    session = RenderSession.open(options.frame_options(), request)
    lidars = session.lidars
    rate = float(options.rate if options.rate is not None else lidars[0].config.rotation_rate)
    traj = read_trajectory(options.trajectory, rate=rate)
    sweep_s = max(float(s.config.pattern.column_time_s().max()) for s in lidars)
    times = _frame_times(traj, rate, options.frames, sweep_s, options.max_frames)
    return session, traj, rate, times


def sequence_bytes(session: RenderSession, options: SequenceOptions, frames: int):
    """Estimated size of a sequence: ``(per_frame, on_disk, kept)`` bytes, per frame folder
    (:func:`nidar_mi.render_folder.folder_bytes`), on disk in all (with the sequence outputs)
    and kept in memory for the sequence outputs until the last frame."""
    lidars = [s.config for s in session.lidars]
    cameras = [tuple(int(v) for v in c.film().size()) for c in session.cameras]
    bands = len(session.nir_wavelengths)
    per_frame = rf.folder_bytes(
        lidars, cameras, options.formats, deskew=options.deskew, bands=bands
    )
    lead = lidars[0].rings * lidars[0].horizontal_resolution * lidars[0].max_returns
    pixels = sum(w * h for w, h in cameras)
    out = sum(_OUTPUT_POINT_BYTES[f] * lead for f in options.sequence_formats)
    out += 3 * pixels if "rosbag" in options.sequence_formats else 0
    kept = lead * _KEPT_POINT_BYTES + 3 * pixels if options.sequence_formats else 0
    return per_frame, frames * (per_frame + out), frames * kept


def _check_bounds(session: RenderSession, options: SequenceOptions, frames: int, out_dir) -> None:
    """Refuse, before any work, a sequence that does not fit on disk (``max_disk``, the free
    space) or whose sequence outputs would keep more than ``max_memory`` in memory."""
    from .io.sizes import check_disk, format_size
    from .lidar.memory import default_limit

    per_frame, on_disk, kept = sequence_bytes(session, options, frames)
    what = f"{frames} frames x {format_size(per_frame)}"
    if options.sequence_formats:
        what += " and the " + ", ".join(options.sequence_formats) + " outputs"
    check_disk(on_disk, out_dir, what, options.max_disk)
    limit = default_limit() if options.max_memory is None else int(options.max_memory)
    if kept > limit:
        raise NidarError(
            f"`sequence_formats` {','.join(options.sequence_formats)} keep every frame's points "
            f"and images in memory until the last frame: about {format_size(kept)} for {frames} "
            f"frames, more than the limit of {format_size(limit)}; render fewer `frames` or "
            "raise the limit with `max_memory` (or NIDAR_MAX_MEMORY)"
        )


def _rig(session: RenderSession) -> _Rig:
    """Every sensor's scene pose as its mounting on the rig; each camera's trigger time."""
    lidars, cams = session.lidars, session.cameras
    mounts = {s.id(): _matrix(s.world_transform()) for s in lidars}
    cam_mounts = {c.id(): _matrix(c.world_transform()) for c in cams}
    lead = lidars[0]
    cam_offsets = {
        c.id(): camera_trigger_time(lead.config, mounts[lead.id()], cam_mounts[c.id()])
        for c in cams
    }
    return _Rig(mounts, cam_mounts, cam_offsets, lead.id())


def _render_frames(stage, session: RenderSession, traj, times, rig: _Rig, keep: bool) -> _Frames:
    """Render every frame into ``stage/frames/<k>`` under one progress bar (``keep``: hold
    what the sequence outputs need of each frame)."""
    from tqdm.auto import tqdm

    frames = _Frames()
    disable = not session.options.progress
    bar = tqdm(total=len(times), desc="sequence", unit="frame", disable=disable, file=sys.stderr)
    try:
        for k, t_k in enumerate(times):
            folder = os.path.join(stage, "frames", f"{k:06d}")
            shot = _FrameShot(session, traj, rig, k, float(t_k))
            entry = _render_frame(shot, folder, frames.keep if keep else None)
            frames.written += [os.path.join(folder, f) for f in entry.pop("files")]
            frames.start_poses.append(entry.pop("lidar_start_pose"))
            frames.log.append(entry)
            bar.update(1)
    finally:
        bar.close()
    return frames


def _write_poses_and_times(stage, start_poses: list, times: np.ndarray) -> list[str]:
    """``poses.txt`` (the lead LiDAR's start poses relative to frame 0) and ``times.txt``."""
    from .io.kitti import write_kitti_poses, write_kitti_times

    P0_inv = np.linalg.inv(start_poses[0])
    write_kitti_poses(os.path.join(stage, "poses.txt"), [P0_inv @ P for P in start_poses])
    write_kitti_times(os.path.join(stage, "times.txt"), times - times[0])
    return [os.path.join(stage, "poses.txt"), os.path.join(stage, "times.txt")]


def _sequence_request(session: RenderSession, options: SequenceOptions, rate, frames) -> dict:
    """The request a sequence manifest records: the frames' cache key and the trajectory."""
    return session.request.to_dict() | {
        "trajectory": os.path.abspath(options.trajectory),
        "trajectory_sha256": rf.file_sha256(options.trajectory),
        "rate_hz": rate,
        "frames": frames,
        "deskew": options.deskew,
        "sequence_formats": list(options.sequence_formats),
    }


def _sequence_manifest(session, request, rate, times, lead, frames: _Frames, stage) -> dict:
    """The sequence's ``manifest.json`` (``timings_s.total`` is filled in by the caller)."""
    render_s = sum(f["timings_s"]["frame_total"] for f in frames.log)
    return {
        "kind": "sequence",
        "request": request,
        "scene": session.request.scene,
        "variant": session.variant,
        "versions": session.versions,
        "rate_hz": rate,
        "frame_count": len(times),
        "trajectory_start_s": float(times[0]),
        "poses_lidar": lead,
        "frames": frames.log,
        "frames_per_s": len(times) / render_s if render_s > 0 else None,
        "timings_s": {"total": None, "frames": render_s},
        "files": sorted(os.path.relpath(p, stage) for p in frames.written) + [rf.MANIFEST],
    }


def _sequence_outputs(stage, options, keep, poses, times, lead) -> list[str]:
    """Write the KITTI odometry layout (its ``.bin`` intensity as each frame's ``points.bin``:
    ``options.bin_intensity``) and the ROS 2 bag of the kept frames of the ``lead`` LiDAR
    (its :class:`~nidar_mi.lidar.config.LidarConfig`)."""
    written, sequence_formats, lidar = [], options.sequence_formats, lead.name
    if "kitti" in sequence_formats:
        from .io.kitti import write_sequence

        clouds = [
            f["points"]
            | {
                "intensity": rf.bin_intensity_values(
                    f["points"]["intensity"], lead, options.bin_intensity
                )
            }
            for f in keep
        ]
        written += write_sequence(os.path.join(stage, "kitti"), clouds, poses, times - times[0])
    if "rosbag" in sequence_formats:
        from .io.rosbag import BagCamera, BagFrame, write_ros2_bag

        frames = [
            BagFrame(
                stamp_s=float(t),
                T_world_lidar=P,
                points=f["points"],
                cameras={cid: BagCamera(**c) for cid, c in f["cameras"].items()},
            )
            for f, P, t in zip(keep, poses, times)
        ]
        bag = write_ros2_bag(os.path.join(stage, "rosbag"), frames, lidar=lidar)
        written += [os.path.join(root, n) for root, _, names in os.walk(bag) for n in names]
    return written


@dataclass
class _FrameShot:
    """Frame ``k`` of a sequence: the session, the trajectory, the rig and the start time.

    Attributes:
        session: the sequence's render session.
        traj: the rig's trajectory (:class:`~nidar_mi.io.trajectory.Trajectory`).
        rig: the sensors' mountings and camera trigger times.
        k: frame index.
        t_k: the frame's start time on the trajectory, s.
    """

    session: RenderSession
    traj: object
    rig: _Rig
    k: int
    t_k: float

    def seed(self, base: int) -> int:
        """``base + k`` modulo 2³²: the seed of this frame."""
        return (base + self.k) % 2**32


def _render_frame(shot: _FrameShot, folder: str, keep: list | None = None) -> dict:
    """Scan every LiDAR and render every camera of one frame; write its render folder.
    With ``keep`` (a list), append what the sequence outputs need of this frame."""
    t0 = time.perf_counter()
    os.makedirs(folder, exist_ok=True)
    results, lidar_entries, files = _scan_frame(shot, folder)
    camera_entries, images = _shoot_frame(shot, folder, results, files, keep is not None)
    frame_total = time.perf_counter() - t0
    _write_frame_manifest(shot, folder, lidar_entries, camera_entries, files, frame_total)
    lead = shot.rig.lead
    if keep is not None:
        pts = results[lead].points()
        keep.append(
            {"points": {c: pts[c] for c in _SEQUENCE_COLUMNS if c in pts}, "cameras": images}
        )
    return {
        "frame": shot.k,
        "time_s": shot.t_k,
        "folder": os.path.relpath(folder, os.path.dirname(os.path.dirname(folder))),
        "cameras_time_s": {c: e["time_s"] for c, e in camera_entries.items()},
        "timings_s": {"frame_total": frame_total},
        "files": [os.path.relpath(p, folder) for p in files] + [rf.MANIFEST],
        "lidar_start_pose": np.asarray(lidar_entries[lead]["to_world"]),
    }


def _scan_frame(shot: _FrameShot, folder: str):
    """Scan every LiDAR along the trajectory (motion distortion) and write its files: the scan
    results, their manifest entries and the files written."""
    from .lidar.scan import scan

    session, traj, t_k = shot.session, shot.traj, shot.t_k
    opts, loaded = session.options, session.loaded
    lidar_entries, files, results = {}, [], {}
    for sensor in session.lidars:
        lid = sensor.id()
        cfg = sensor.config
        columns = traj.at(t_k + cfg.pattern.column_time_s()) @ shot.rig.mounts[lid]
        start = traj.at(t_k)[0] @ shot.rig.mounts[lid]
        frame_seed = shot.seed(cfg.seed if opts.seed is None else opts.seed)
        ts = time.perf_counter()
        result = scan(
            loaded.scene,
            sensor,
            seed=frame_seed,
            to_world=start,
            poses_per_column=columns,
            max_memory=opts.max_memory,
            labels=loaded.labels,
        )
        scan_s = time.perf_counter() - ts
        results[lid] = result
        tw = time.perf_counter()
        files += rf.write_lidar(
            folder, result, opts.formats, None, opts.bin_intensity, deskew=opts.deskew
        )
        lidar_entries[lid] = {
            "parameters": result.config.to_dict() | {"seed": frame_seed},
            "to_world": start.tolist(),
            "time_s": t_k,
            "rays": int(result.valid.size),
            "hits": int(result.hit.sum()),
            "returns": int(sum(layer.valid.sum() for layer in result.returns)),
            "materials": result.material_names,
            "timings_s": result.timings | {"scan_total": scan_s, "write": time.perf_counter() - tw},
        }
    return results, lidar_entries, files


def _shoot_frame(shot: _FrameShot, folder: str, results: dict, files: list, keep: bool):
    """Render every camera from the rig pose of its trigger time and write its files (appended
    to ``files``); the manifest entries and (``keep``) the images the sequence outputs need."""
    from .camera import render_camera

    session, rig = shot.session, shot.rig
    wavelengths = session.nir_wavelengths
    camera_entries, images = {}, {}
    for cam in session.cameras:
        cid = cam.id()
        t_cam = shot.t_k + rig.cam_offsets[cid]
        T_rig = shot.traj.at(t_cam)[0]
        _set_camera_pose(cam, T_rig @ rig.cam_mounts[cid])
        ts = time.perf_counter()
        r = render_camera(
            session.loaded,
            cam,
            wavelength=wavelengths[0],
            other_wavelengths=wavelengths[1:],
            spp=session.options.spp,
            seed=shot.seed(session.options.seed or 0),
        )
        render_s = time.perf_counter() - ts
        lidar_poses = {lid: T_rig @ rig.mounts[lid] for lid in results}
        calib, written = rf.write_camera(folder, r, lidar_poses)
        if keep:
            images[cid] = {"rgb": r.srgb8(), "K": r.K, "T_world_cam": r.T_world_cam}
            images[cid]["stamp_s"] = float(t_cam)
        files += written
        camera_entries[cid] = calib | {
            "spp": session.options.spp,
            "time_s": float(t_cam),
            "timings_s": r.timings | {"render_total": render_s},
        }
    for cam in session.cameras:  # back to the scene's own pose
        _set_camera_pose(cam, rig.cam_mounts[cam.id()])
    return camera_entries, images


def _write_frame_manifest(shot, folder, lidar_entries, camera_entries, files, total_s) -> None:
    """The frame's render-folder ``manifest.json``."""
    session = shot.session
    request = session.request.to_dict() | {"frame": shot.k}
    manifest = {
        "request": request,
        "scene": request["scene"],
        "scene_sha256": request["scene_sha256"],
        "variant": session.variant,
        "versions": session.versions,
        "frame": shot.k,
        "time_s": shot.t_k,
        "seed": request["seed"],
        "spp": session.options.spp,
        "formats": list(session.options.formats),
        "intensity": "physics",
        "lidars": lidar_entries,
        "cameras": camera_entries,
        "timings_s": {"total": total_s},
        "files": sorted(os.path.relpath(p, folder) for p in files) + [rf.MANIFEST],
    }
    rf.write_manifest(folder, manifest)
