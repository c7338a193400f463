"""Render a scene along a trajectory: one render folder per frame, poses and times beside them.

The trajectory (:mod:`nidar_mi.io.trajectory`) moves the rig; every sensor keeps its scene pose
as its mounting on the rig, so at time ``t`` a sensor is at ``T_rig(t) · T_mount``. Frame ``k``
starts at ``t_k = t_0 + k / rate``. Each LiDAR sweeps from ``t_k`` on: column ``j`` fires at
``t_k + t_j`` (:class:`nidar_mi.lidar.pattern.BeamPattern`) and is cast from the rig pose
SE(3)-interpolated at that time (motion distortion; ``t`` per point). Each camera is exposed
when the first LiDAR's sweep points along the camera's optical axis (how KITTI triggers its
cameras), from the rig pose of that time. Without ``motion`` every sweep is cast from the
frame's start pose (an instantaneous sweep; the points keep their firing times ``t``) and every
camera is exposed at ``t_k``. Poses enter the kernels as data: after the first frame no kernel
is compiled again, for any sensor.

:func:`ensure_sequence` renders only when ``OUT`` does not hold the same request already.

Frame ``k`` is written on a background thread (:class:`nidar_mi.io.background.BackgroundWriter`,
two frames queued at most) while frame ``k + 1`` is rendered; the sequence outputs are written
as the frames arrive. Ctrl-C or SIGTERM stops the writer after the file it is on and the staging
folder is removed: ``OUT`` is complete or untouched.

Layout (``OUT``)::

    manifest.json       request (scene, trajectory, rate, frames, ...), per-frame times and
                        timings, throughput, file list
    poses.txt           KITTI odometry: per frame T_{lidar_0 <- lidar_k} (3×4 row-major), the
                        first LiDAR's pose at the frame's start relative to frame 0
    times.txt           per frame its start time t_k - t_0, s
    frames/000000/ ...  one render folder per frame (:mod:`nidar_mi.render_folder`); the range
                        previews (``range.png``, ``intensity.png``) in the first frame only,
                        in every frame or in none (``previews``)
    kitti/              with sequence format ``kitti``: the first LiDAR's sweeps in the KITTI
                        odometry layout (:func:`nidar_mi.io.kitti.write_sequence`)
    rosbag/             with ``rosbag``: a ROS 2 bag of the first LiDAR's sweeps and the camera
                        images (:func:`nidar_mi.io.rosbag.write_ros2_bag`), stamped in trajectory
                        time

The ``kitti`` and ``rosbag`` outputs are streamed: each frame's scan (x, y, z, intensity, ring,
t, label, instance of the first LiDAR) and camera images are written when the frame is;
``kitti/poses.txt``, ``times.txt`` and ``calib.txt`` and the bag's index at the end.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field

import numpy as np

from . import render_folder as rf
from .errors import NidarError
from .geometry.se3 import transform_matrix
from .io.cache_key import file_sha256
from .render_session import RenderOptions, RenderSession, check_options

__all__ = [
    "MAX_FRAMES",
    "PREVIEWS",
    "SEQUENCE_FORMATS",
    "SequenceOptions",
    "camera_trigger_time",
    "check_sequence",
    "ensure_sequence",
    "render_sequence",
    "sequence_bytes",
]

log = logging.getLogger("nidar_mi.sequence")

#: Whole-sequence outputs beside the frame folders.
SEQUENCE_FORMATS = ("kitti", "rosbag")
#: ``previews``: the range previews of every frame, of the first frame only, or of none.
PREVIEWS = ("all", "first", "none")
#: Frames a sequence may have unless ``max_frames`` says otherwise (KITTI's longest odometry
#: sequence has 4,661; this is 2.8 h at 10 Hz).
MAX_FRAMES = 100_000
#: Bytes per point the sequence outputs write: a KITTI ``.bin`` and ``.label``; a ROS 2 bag's
#: PointCloud2 (rounded up).
_OUTPUT_POINT_BYTES = {"kitti": 20, "rosbag": 32}
#: Frames rendered but not yet written that the background writer may hold.
WRITE_QUEUE = 2
#: Points columns kept per frame for the sequence outputs.
_SEQUENCE_COLUMNS = ("xyz", "intensity", "ring", "t", "label", "instance")


@dataclass(frozen=True)
class SequenceOptions:
    """What to render of a scene along a trajectory, and how.

    Attributes:
        frame: what every frame renders, and how
            (:class:`~nidar_mi.render_session.RenderOptions`: the scene, its parameters and
            twin, point formats, seed, spp, cameras, labels, ``bin_intensity``, ``deskew``,
            ``max_memory``, ``progress``); the physics intensity only. Frame ``k`` uses
            ``seed + k`` modulo 2³² (each LiDAR's own seed + k without one; the camera sampler
            ``k``).
        trajectory: KITTI odometry, TUM or CSV poses of the rig.
        rate: frames per second, Hz (None: the first LiDAR's rotation rate); also the sample
            rate of a KITTI odometry pose file.
        frames: number of frames (None: as many as the trajectory holds).
        sequence_formats: whole-sequence outputs, from :data:`SEQUENCE_FORMATS`.
        max_frames: the most frames the sequence may have (:data:`MAX_FRAMES`).
        max_disk: bytes the sequence may take on disk (None: the free space of its filesystem).
        previews: range previews of ``all`` frames, the ``first`` only or ``none``
            (:data:`PREVIEWS`).
        motion: sweeps and exposures along the trajectory (module docstring); False: each
            frame from its start pose, so the last frame may start at the trajectory's end.
    """

    frame: RenderOptions
    trajectory: str
    rate: float | None = None
    frames: int | None = None
    sequence_formats: tuple[str, ...] = ()
    max_frames: int = MAX_FRAMES
    max_disk: int | None = None
    previews: str = "first"
    motion: bool = True


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
    # at most the last time that fits: t0 + k / rate may round past it by an ulp
    return np.minimum(t0 + np.arange(frames) / rate, t1 - sweep_s)


def render_sequence(
    options: SequenceOptions, out_dir: str, *, overwrite: bool = False, nested: bool = False
) -> dict:
    """Render a scene along a trajectory into ``out_dir`` (layout: module docstring), in the
    active Mitsuba variant (:func:`nidar_mi.backend.set_variant`).

    Args:
        options: what to render (:class:`SequenceOptions`).
        out_dir: the sequence folder (an earlier sequence folder is replaced whole, any other
            folder as :func:`nidar_mi.io.ownership.check_owner` says).
        overwrite: the user passed ``overwrite`` (:func:`~nidar_mi.io.ownership.check_owner`).
        nested: ``out_dir`` is a cache inside an output of the caller's own (the drive study's
            sweeps).

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
    publish = dict(owner=rf.SEQUENCE_OWNER, overwrite=overwrite, nested=nested)
    with staged_directory(out_dir, **publish) as stage:
        frames = _render_frames(stage, session, options, traj, times, rig)
        frames.written += _write_poses_and_times(stage, frames.start_poses, times)
        request = _sequence_request(session, options, rate, len(times))
        manifest = _sequence_manifest(session, request, rate, times, rig.lead, frames, stage)
        manifest["timings_s"]["total"] = time.perf_counter() - t_start
        rf.write_manifest(stage, manifest)
    return manifest


def ensure_sequence(options: SequenceOptions, out_dir: str) -> dict:
    """The manifest of ``out_dir`` when it holds this sequence complete, else
    :func:`render_sequence` (replacing ``out_dir`` whole, as ``overwrite``). ``out_dir`` is a
    cache, inside an output of the caller's own or anywhere else.

    The request of the manifest is compared with that of ``options``: the frames' cache key
    (the scene file's hash included), the trajectory file's hash and every sequence option; a
    rate or frame count left to the scene and the trajectory is taken as recorded (the scene
    and the trajectory decide it, and their hashes are compared).
    """
    request = check_sequence(options).to_dict()
    try:
        manifest = rf.read_manifest(out_dir)
    except NidarError:
        manifest = {}
    recorded = manifest.get("request") or {}
    rate = options.rate if options.rate is not None else recorded.get("rate_hz")
    frames = options.frames if options.frames is not None else recorded.get("frames")
    want = request | _sequence_fields(options, rate, frames)
    files = manifest.get("files", [])
    if (
        manifest.get("kind") == "sequence"
        and recorded == want
        and all(os.path.isfile(os.path.join(out_dir, f)) for f in files)
    ):
        return manifest
    return render_sequence(options, out_dir, overwrite=True, nested=True)


def check_sequence(options: SequenceOptions):
    """Refuse options that cannot be rendered, before anything is loaded: a bad rate, frame
    count, sequence format or previews value, a bad frame option, a missing trajectory file. The frames' cache
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
    if options.previews not in PREVIEWS:
        raise NidarError(
            f"`previews` must be one of {', '.join(PREVIEWS)} (got '{options.previews}')"
        )
    bad = [f for f in options.sequence_formats if f not in SEQUENCE_FORMATS]
    if bad:
        raise NidarError(
            f"`sequence_formats`: unknown '{','.join(bad)}' "
            f"(choose from {', '.join(SEQUENCE_FORMATS)})"
        )
    if options.frame.intensity != "physics":
        raise NidarError(
            f"`intensity`: a sequence renders the physics intensity (got '{options.frame.intensity}')"
        )
    request = check_options(options.frame)
    if not os.path.isfile(options.trajectory):
        raise NidarError(f"{options.trajectory}: no such trajectory file")
    return request


def _open(options: SequenceOptions):
    """Check the options, load the scene and the trajectory: the session, the trajectory, the
    frame rate (Hz) and the (F,) frame start times (s)."""
    from .io.trajectory import read_trajectory

    request = check_sequence(options)
    session = RenderSession.open(options.frame, request)
    lidars = session.lidars
    rate = float(options.rate if options.rate is not None else lidars[0].config.frame_rate)
    traj = read_trajectory(options.trajectory, rate=rate)
    sweep_s = max(float(s.config.pattern.column_time_s().max()) for s in lidars)
    sweep_s = sweep_s if options.motion else 0.0
    times = _frame_times(traj, rate, options.frames, sweep_s, options.max_frames)
    return session, traj, rate, times


def sequence_bytes(session: RenderSession, options: SequenceOptions, frames: int):
    """Estimated size of a sequence: ``(per_frame, on_disk)`` bytes, per frame folder
    (:func:`nidar_mi.render_folder.folder_bytes`) and on disk in all, with the sequence
    outputs (streamed frame by frame, so nothing of them accumulates in memory)."""
    lidars = [s.config for s in session.lidars]
    cameras = [tuple(int(v) for v in c.film().size()) for c in session.cameras]
    bands = len(session.nir_wavelengths)
    per_frame = rf.folder_bytes(
        lidars, cameras, options.frame.formats, deskew=options.frame.deskew, bands=bands
    )
    lead = lidars[0].rings * lidars[0].horizontal_resolution * lidars[0].max_returns
    pixels = sum(w * h for w, h in cameras)
    out = sum(_OUTPUT_POINT_BYTES[f] * lead for f in options.sequence_formats)
    out += 3 * pixels if "rosbag" in options.sequence_formats else 0
    return per_frame, frames * (per_frame + out)


def _check_bounds(session: RenderSession, options: SequenceOptions, frames: int, out_dir) -> None:
    """Refuse, before any work, a sequence that does not fit on disk (``max_disk``, and the
    free space of ``out_dir``'s filesystem)."""
    from .io.sizes import check_disk, format_size

    per_frame, on_disk = sequence_bytes(session, options, frames)
    what = f"{frames} frames x {format_size(per_frame)}"
    if options.sequence_formats:
        what += " and the " + ", ".join(options.sequence_formats) + " outputs"
    check_disk(on_disk, out_dir, what, options.max_disk)


def _rig(session: RenderSession) -> _Rig:
    """Every sensor's scene pose as its mounting on the rig; each camera's trigger time."""
    lidars, cams = session.lidars, session.cameras
    mounts = {s.id(): transform_matrix(s.world_transform()) for s in lidars}
    cam_mounts = {c.id(): transform_matrix(c.world_transform()) for c in cams}
    lead = lidars[0]
    cam_offsets = {
        c.id(): camera_trigger_time(lead.config, mounts[lead.id()], cam_mounts[c.id()])
        for c in cams
    }
    return _Rig(mounts, cam_mounts, cam_offsets, lead.id())


def _render_frames(stage, session, options: SequenceOptions, traj, times, rig: _Rig) -> _Frames:
    """Render every frame into ``stage/frames/<k>`` under one progress bar: the sensors on this
    thread, the files on a background writer (frame ``k`` is written while ``k + 1`` renders).

    Each log entry's ``timings_s.frame_total`` is the frame's time in the loop (its render and
    any wait for the writer; the last frame's includes writing what was left), so their sum is
    the loop's wall time."""
    from .io.background import BackgroundWriter
    from .progress import progress_bar

    frames = _Frames()
    lead = session.lidars[0].config
    outputs = _SequenceOutputs(
        stage,
        options.sequence_formats,
        rig.lead,
        lambda i: rf.bin_intensity_values(i, lead, options.frame.bin_intensity),
    )
    show = options.frame.progress
    bar = progress_bar(total=len(times), show=show, desc="sequence", unit="frame")
    loop = []
    try:
        with BackgroundWriter(depth=WRITE_QUEUE, on_abort=outputs.discard) as writer:
            for k, t_k in enumerate(times):
                t0 = time.perf_counter()
                shot = _FrameShot(session, traj, rig, k, float(t_k), options.motion)
                rendered = _render_frame(shot, _previews(options.previews, k))
                frames.start_poses.append(rendered.lidar_start_pose)
                writer.submit(_write_frame, rendered, stage, frames, outputs)
                loop.append(time.perf_counter() - t0)
                log.debug(
                    "frame %d/%d (t = %.3f s) rendered in %.2f s", k + 1, len(times), t_k, loop[-1]
                )
                bar.update(1)
            t0 = time.perf_counter()
            poses = np.asarray(frames.start_poses)
            writer.submit(outputs.finish, poses, np.asarray(times), frames.written)
        loop[-1] += time.perf_counter() - t0
    finally:
        bar.close()
        for cam in session.cameras:  # back to the scene's own pose
            _set_camera_pose(cam, rig.cam_mounts[cam.id()])
    for entry, s in zip(frames.log, loop):
        entry["timings_s"]["frame_total"] = s
    return frames


def _previews(previews: str, k: int) -> bool:
    """Whether frame ``k`` gets the range previews."""
    return previews == "all" or (previews == "first" and k == 0)


def _write_poses_and_times(stage, start_poses: list, times: np.ndarray) -> list[str]:
    """``poses.txt`` (the lead LiDAR's start poses relative to frame 0) and ``times.txt``."""
    from .io.kitti import write_kitti_poses, write_kitti_times

    P0_inv = np.linalg.inv(start_poses[0])
    write_kitti_poses(os.path.join(stage, "poses.txt"), [P0_inv @ P for P in start_poses])
    write_kitti_times(os.path.join(stage, "times.txt"), times - times[0])
    return [os.path.join(stage, "poses.txt"), os.path.join(stage, "times.txt")]


def _sequence_request(session: RenderSession, options: SequenceOptions, rate, frames) -> dict:
    """The request a sequence manifest records: the frames' cache key and the trajectory."""
    return session.request.to_dict() | _sequence_fields(options, rate, frames)


def _sequence_fields(options: SequenceOptions, rate, frames) -> dict:
    """The sequence's own part of its request (:func:`_sequence_request`)."""
    return {
        "trajectory": os.path.abspath(options.trajectory),
        "trajectory_sha256": file_sha256(options.trajectory),
        "rate_hz": rate,
        "frames": frames,
        "deskew": options.frame.deskew,
        "motion": options.motion,
        "sequence_formats": list(options.sequence_formats),
        "previews": options.previews,
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


class _SequenceOutputs:
    """The whole-sequence outputs (:data:`SEQUENCE_FORMATS`), written frame by frame as the
    frames arrive; on the background writer's thread only (a bag's SQLite file belongs to the
    thread that opened it).

    Args:
        stage: the sequence's staging folder.
        formats: the sequence formats asked for.
        lidar: the lead LiDAR's id (its sweeps are the outputs).
        bin_intensity: maps the lead LiDAR's (N,) intensity to what a KITTI ``.bin`` holds, as
            each frame's ``points.bin`` (:func:`nidar_mi.render_folder.bin_intensity_values`).
    """

    def __init__(self, stage, formats, lidar: str, bin_intensity):
        self.stage, self.formats, self.lidar = stage, tuple(formats), lidar
        self.bin_intensity = bin_intensity
        self._bag = None

    def add(self, k: int, points: dict, cameras: dict, pose: np.ndarray, t: float) -> list[str]:
        """Write frame ``k``: ``points`` of the lead LiDAR (its sequence columns), ``cameras``
        (id -> rgb, K, T_world_cam, stamp_s), its (4, 4) start ``pose``, start time ``t`` (s).
        The paths written."""
        written = []
        if "kitti" in self.formats:
            from .io.kitti import write_sequence_frame

            kitti_points = points | {"intensity": self.bin_intensity(points["intensity"])}
            written += write_sequence_frame(os.path.join(self.stage, "kitti"), k, kitti_points)
        if "rosbag" in self.formats:
            from .io.rosbag import BagCamera, BagFrame, Ros2BagWriter

            if self._bag is None:
                self._bag = Ros2BagWriter(os.path.join(self.stage, "rosbag"), self.lidar).open()
            cams = {cid: BagCamera(**c) for cid, c in cameras.items()}
            self._bag.write(BagFrame(stamp_s=t, T_world_lidar=pose, points=points, cameras=cams))
        return written

    def finish(self, poses: np.ndarray, times: np.ndarray, written: list) -> None:
        """Complete the outputs (KITTI poses, times, calibration; the bag), given every frame's
        (4, 4) start pose and start time (s); append the paths written to ``written``."""
        if "kitti" in self.formats:
            from .io.kitti import write_sequence_index

            kitti = os.path.join(self.stage, "kitti")
            written += write_sequence_index(kitti, poses, times - times[0])
        if self._bag is not None:
            bag, self._bag = self._bag, None
            path = bag.close()
            written += [os.path.join(root, n) for root, _, names in os.walk(path) for n in names]

    def discard(self) -> None:
        """Drop an unfinished bag (after a failure or an interruption)."""
        if self._bag is not None:
            bag, self._bag = self._bag, None
            bag.discard()


@dataclass
class _FrameShot:
    """Frame ``k`` of a sequence: the session, the trajectory, the rig and the start time.

    Attributes:
        session: the sequence's render session.
        traj: the rig's trajectory (:class:`~nidar_mi.io.trajectory.Trajectory`).
        rig: the sensors' mountings and camera trigger times.
        k: frame index.
        t_k: the frame's start time on the trajectory, s.
        motion: sweeps and exposures along the trajectory (:attr:`SequenceOptions.motion`).
    """

    session: RenderSession
    traj: object
    rig: _Rig
    k: int
    t_k: float
    motion: bool = True

    def seed(self, base: int) -> int:
        """``base + k`` modulo 2³²: the seed of this frame."""
        return (base + self.k) % 2**32


@dataclass
class _Rendered:
    """One frame's sensor data, in memory (NumPy only): what the writer thread writes.

    Attributes:
        shot: the frame.
        previews: write the range previews.
        scans: LiDAR id -> its :class:`~nidar_mi.lidar.scan.ScanResult`.
        lidar_entries: LiDAR id -> its manifest entry (the writer adds ``timings_s.write``).
        cameras: camera id -> (its :class:`~nidar_mi.camera.CameraRender`, its manifest entry
            without the calibration, LiDAR id -> (4, 4) LiDAR pose at the camera's time).
        lidar_start_pose: (4, 4) the lead LiDAR's pose at the frame's start.
        render_s: time the frame's scans and renders took, s.
    """

    shot: _FrameShot
    previews: bool
    scans: dict
    lidar_entries: dict
    cameras: dict
    lidar_start_pose: np.ndarray
    render_s: float


def _render_frame(shot: _FrameShot, previews: bool) -> _Rendered:
    """Scan every LiDAR and render every camera of one frame (this thread drives the JIT)."""
    t0 = time.perf_counter()
    scans, lidar_entries = _scan_frame(shot)
    cameras = _shoot_frame(shot)
    pose = np.asarray(lidar_entries[shot.rig.lead]["to_world"])
    render_s = time.perf_counter() - t0
    return _Rendered(shot, previews, scans, lidar_entries, cameras, pose, render_s)


def _scan_frame(shot: _FrameShot):
    """Scan every LiDAR along the trajectory (motion distortion): the scan results and their
    manifest entries."""
    from .lidar.scan import scan

    session, traj, t_k = shot.session, shot.traj, shot.t_k
    opts, loaded = session.options, session.loaded
    lidar_entries, results = {}, {}
    for sensor in session.lidars:
        lid = sensor.id()
        cfg = sensor.config
        start = traj.at(t_k)[0] @ shot.rig.mounts[lid]
        columns = None
        if shot.motion:
            columns = traj.at(t_k + cfg.pattern.column_time_s()) @ shot.rig.mounts[lid]
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
        lidar_entries[lid] = {
            "parameters": result.config.to_dict() | {"seed": frame_seed},
            "to_world": start.tolist(),
            "time_s": t_k,
            "rays": int(result.valid.size),
            "hits": int(result.hit.sum()),
            "returns": int(sum(layer.valid.sum() for layer in result.returns)),
            "materials": result.material_names,
            "timings_s": result.timings | {"scan_total": scan_s},
        }
    return results, lidar_entries


def _shoot_frame(shot: _FrameShot) -> dict:
    """Render every camera from the rig pose of its trigger time: camera id -> (render,
    manifest entry without the calibration, LiDAR poses at the camera's time)."""
    from .camera import render_camera

    session, rig = shot.session, shot.rig
    wavelengths = session.nir_wavelengths
    cameras = {}
    for cam in session.cameras:
        cid = cam.id()
        t_cam = shot.t_k + (rig.cam_offsets[cid] if shot.motion else 0.0)
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
            albedo=False,
        )
        render_s = time.perf_counter() - ts
        entry = {
            "spp": session.options.spp,
            "time_s": float(t_cam),
            "timings_s": r.timings | {"render_total": render_s},
        }
        cameras[cid] = (r, entry, {lid: T_rig @ rig.mounts[lid] for lid in rig.mounts})
    return cameras


def _write_frame(rendered: _Rendered, stage, frames: _Frames, outputs: _SequenceOutputs) -> None:
    """Write one rendered frame (on the writer thread): its render folder, its part of the
    sequence outputs; append its log entry and files to ``frames``."""
    t0 = time.perf_counter()
    shot, opts = rendered.shot, rendered.shot.session.options
    folder = os.path.join(stage, "frames", f"{shot.k:06d}")
    os.makedirs(folder, exist_ok=True)
    files = []
    for lid, result in rendered.scans.items():
        tw = time.perf_counter()
        files += rf.write_lidar(folder, result, opts.formats, None, opts.bin_intensity,
                                deskew=opts.deskew, previews=rendered.previews)  # fmt: skip
        rendered.lidar_entries[lid]["timings_s"]["write"] = time.perf_counter() - tw
    camera_entries, images = {}, {}
    for cid, (r, entry, lidar_poses) in rendered.cameras.items():
        calib, written = rf.write_camera(folder, r, lidar_poses)
        files += written
        camera_entries[cid] = calib | entry
        images[cid] = {"rgb": r.srgb8(), "K": r.K, "T_world_cam": r.T_world_cam}
        images[cid]["stamp_s"] = entry["time_s"]  # srgb8 is cached: rgb.png computed it
    total = rendered.render_s + time.perf_counter() - t0
    _write_frame_manifest(shot, folder, rendered.lidar_entries, camera_entries, files, total)
    frames.written += files + [os.path.join(folder, rf.MANIFEST)]
    if outputs.formats:
        pts = rendered.scans[shot.rig.lead].points()
        points = {c: pts[c] for c in _SEQUENCE_COLUMNS if c in pts}
        frames.written += outputs.add(shot.k, points, images, rendered.lidar_start_pose, shot.t_k)
    frames.log.append(
        {
            "frame": shot.k,
            "time_s": shot.t_k,
            "folder": os.path.relpath(folder, stage),
            "cameras_time_s": {c: e["time_s"] for c, e in camera_entries.items()},
            "timings_s": {
                "frame_total": total,
                "render": rendered.render_s,
                "write": total - rendered.render_s,
            },
        }
    )


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
