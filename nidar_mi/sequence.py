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

import numpy as np

from . import render_folder as rf
from .errors import NidarError

__all__ = ["SEQUENCE_FORMATS", "render_sequence", "camera_trigger_time"]

#: Whole-sequence outputs beside the frame folders.
SEQUENCE_FORMATS = ("kitti", "rosbag")
#: Points columns kept per frame for the sequence outputs.
_SEQUENCE_COLUMNS = ("xyz", "intensity", "ring", "t", "label", "instance")


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


def _frame_times(traj, rate: float, frames: int | None, sweep_s: float) -> np.ndarray:
    t0, t1 = traj.span
    fit = int(np.floor((t1 - t0 - sweep_s) * rate + 1e-9)) + 1 if t1 - t0 >= sweep_s else 0
    if fit < 1:
        raise NidarError(
            f"{traj.path}: the trajectory spans {t1 - t0:.3g} s, less than one sweep "
            f"({sweep_s:.3g} s)"
        )
    if frames is None:
        frames = fit
    elif frames > fit:
        raise NidarError(
            f"--frames {frames}: the trajectory ({t1 - t0:.3g} s) holds {fit} frames at "
            f"{rate:g} Hz (each needs its whole sweep of {sweep_s:.3g} s inside it)"
        )
    return t0 + np.arange(frames) / rate


def render_sequence(
    scene_path: str,
    out_dir: str,
    trajectory: str,
    *,
    rate: float | None = None,
    frames: int | None = None,
    formats=rf.FORMATS,
    sequence_formats=(),
    bin_intensity: str = "unit",
    seed: int | None = None,
    spp: int = 16,
    variant: str | None = None,
    params: dict[str, str] | None = None,
    cameras: bool = True,
    deskew: bool = False,
    max_memory: int | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict:
    """Render ``scene_path`` along ``trajectory`` into ``out_dir`` (layout: module docstring).

    Args:
        scene_path: scene XML.
        out_dir: the sequence folder (replaced whole; a non-empty folder that is not an earlier
            sequence needs ``overwrite``).
        trajectory: KITTI odometry, TUM or CSV poses of the rig.
        rate: frames per second (default: the first LiDAR's rotation rate); also the sample rate
            of a KITTI odometry pose file.
        frames: number of frames (default: as many as the trajectory holds).
        formats: point formats of each frame.
        sequence_formats: whole-sequence outputs, from :data:`SEQUENCE_FORMATS`.
        bin_intensity: ``unit`` or ``raw`` KITTI ``.bin`` intensity of each frame
            (:func:`nidar_mi.render_folder.write_lidar`).
        seed: base seed; frame ``k`` uses ``seed + k`` modulo 2³² (each LiDAR's own seed + k
            without it; the camera sampler ``k`` without it).
        spp: camera samples per pixel.
        variant: Mitsuba variant.
        params: the scene's ``<default>`` values.
        cameras: render the cameras.
        deskew: add ``xyz_deskewed`` (points in the LiDAR frame at the sweep's start) to every
            frame's points.
        max_memory: bytes one scan may use (None: the default limit).
        progress: show a progress bar on stderr.
        overwrite: replace a non-empty ``out_dir``.

    Returns:
        The sequence manifest.
    """
    from tqdm.auto import tqdm

    from .io.atomic import staged_directory
    from .io.kitti import write_kitti_poses, write_kitti_times
    from .io.trajectory import read_trajectory
    from .simulate import _check_memory, _check_request, _load, _versions, nir_wavelengths

    if rate is not None and not (rate > 0 and np.isfinite(rate)):
        raise NidarError(f"--rate must be > 0 Hz (got {rate})")
    if frames is not None and frames < 1:
        raise NidarError(f"--frames must be >= 1 (got {frames})")
    bad = [f for f in sequence_formats if f not in SEQUENCE_FORMATS]
    if bad:
        raise NidarError(
            f"--sequence-formats: unknown '{','.join(bad)}' "
            f"(choose from {', '.join(SEQUENCE_FORMATS)})"
        )
    req = rf.RenderRequest.of(
        scene_path,
        params=params,
        seed=seed,
        spp=spp,
        formats=tuple(formats),
        cameras=cameras,
        bin_intensity=bin_intensity,
    )
    _check_request(req)
    if not os.path.isfile(trajectory):
        raise NidarError(f"{trajectory}: no such trajectory file")
    t_start = time.perf_counter()
    loaded = _load(req, variant)
    lidars = loaded.lidars
    rate = float(rate if rate is not None else lidars[0].config.rotation_rate)
    traj = read_trajectory(trajectory, rate=rate)
    sweep_s = max(float(s.config.pattern.column_time_s().max()) for s in lidars)
    times = _frame_times(traj, rate, frames, sweep_s)
    _check_memory(loaded, cameras, spp, max_memory)
    mounts = {s.id(): _matrix(s.world_transform()) for s in lidars}
    cams = list(loaded.cameras) if cameras else []
    cam_mounts = {c.id(): _matrix(c.world_transform()) for c in cams}
    lead = lidars[0]
    cam_offsets = {
        c.id(): camera_trigger_time(lead.config, mounts[lead.id()], cam_mounts[c.id()])
        for c in cams
    }
    request = req.to_dict() | {
        "trajectory": os.path.abspath(trajectory),
        "trajectory_sha256": rf.file_sha256(trajectory),
        "rate_hz": rate,
        "frames": len(times),
        "deskew": deskew,
        "sequence_formats": list(sequence_formats),
    }
    frame_log = []
    start_poses = []
    keep: list[dict] = []  # per frame what the sequence outputs need
    with staged_directory(out_dir, overwrite=overwrite, marker=rf.MANIFEST) as stage:
        written: list[str] = []
        bar = tqdm(
            total=len(times), desc="sequence", unit="frame", disable=not progress, file=sys.stderr
        )
        try:
            for k, t_k in enumerate(times):
                folder = os.path.join(stage, "frames", f"{k:06d}")
                entry = _render_frame(
                    loaded,
                    folder,
                    k,
                    t_k,
                    traj,
                    mounts,
                    cam_mounts,
                    cam_offsets,
                    formats=formats,
                    bin_intensity=bin_intensity,
                    wavelengths=nir_wavelengths(loaded),
                    seed=seed,
                    spp=spp,
                    deskew=deskew,
                    max_memory=max_memory,
                    request=req.to_dict() | {"frame": k},
                    variant=loaded.variant,
                    versions=_versions(),
                    keep=keep if sequence_formats else None,
                )
                written += [os.path.join(folder, f) for f in entry.pop("files")]
                start_poses.append(entry.pop("lidar_start_pose"))
                frame_log.append(entry)
                bar.update(1)
        finally:
            bar.close()
        P0_inv = np.linalg.inv(start_poses[0])
        write_kitti_poses(os.path.join(stage, "poses.txt"), [P0_inv @ P for P in start_poses])
        write_kitti_times(os.path.join(stage, "times.txt"), times - times[0])
        written += [os.path.join(stage, "poses.txt"), os.path.join(stage, "times.txt")]
        written += _sequence_outputs(
            stage, sequence_formats, keep, np.asarray(start_poses), times, lead.id()
        )
        total = time.perf_counter() - t_start
        render_s = sum(f["timings_s"]["frame_total"] for f in frame_log)
        manifest = {
            "kind": "sequence",
            "request": request,
            "scene": req.scene,
            "variant": loaded.variant,
            "versions": _versions(),
            "rate_hz": rate,
            "frame_count": len(times),
            "trajectory_start_s": float(times[0]),
            "poses_lidar": lead.id(),
            "frames": frame_log,
            "frames_per_s": len(times) / render_s if render_s > 0 else None,
            "timings_s": {"total": total, "frames": render_s},
            "files": sorted(os.path.relpath(p, stage) for p in written) + [rf.MANIFEST],
        }
        rf.write_manifest(stage, manifest)
    return manifest


def _sequence_outputs(stage, sequence_formats, keep, poses, times, lidar) -> list[str]:
    """Write the KITTI odometry layout and the ROS 2 bag of the kept frames."""
    written = []
    if "kitti" in sequence_formats:
        from .io.kitti import write_sequence

        clouds = [f["points"] for f in keep]
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


def _render_frame(
    loaded,
    folder,
    k,
    t_k,
    traj,
    mounts,
    cam_mounts,
    cam_offsets,
    *,
    formats,
    bin_intensity,
    wavelengths,
    seed,
    spp,
    deskew,
    max_memory,
    request,
    variant,
    versions,
    keep=None,
) -> dict:
    """Scan every LiDAR and render every camera of frame ``k``; write its render folder.
    With ``keep`` (a list), append what the sequence outputs need of this frame."""
    from .camera import render_camera
    from .lidar.scan import scan

    t0 = time.perf_counter()
    os.makedirs(folder, exist_ok=True)
    lidar_entries, camera_entries, files = {}, {}, []
    results, images = {}, {}
    for sensor in loaded.lidars:
        lid = sensor.id()
        cfg = sensor.config
        T_rig = traj.at(t_k + cfg.pattern.column_time_s())
        columns = T_rig @ mounts[lid]
        start = traj.at(t_k)[0] @ mounts[lid]
        frame_seed = ((cfg.seed if seed is None else seed) + k) % 2**32
        ts = time.perf_counter()
        result = scan(
            loaded.scene,
            sensor,
            seed=frame_seed,
            to_world=start,
            poses_per_column=columns,
            max_memory=max_memory,
            labels=loaded.labels,
        )
        scan_s = time.perf_counter() - ts
        results[lid] = result
        tw = time.perf_counter()
        written = rf.write_lidar(folder, result, formats, None, bin_intensity, deskew=deskew)
        files += written
        lidar_entries[lid] = {
            "parameters": result.config.to_dict() | {"seed": frame_seed},
            "to_world": start.tolist(),
            "time_s": float(t_k),
            "rays": int(result.valid.size),
            "hits": int(result.hit.sum()),
            "returns": int(sum(layer.valid.sum() for layer in result.returns)),
            "materials": result.material_names,
            "timings_s": result.timings | {"scan_total": scan_s, "write": time.perf_counter() - tw},
        }
    for cam in loaded.cameras if cam_mounts else []:
        cid = cam.id()
        t_cam = t_k + cam_offsets[cid]
        rig = traj.at(t_cam)[0]
        _set_camera_pose(cam, rig @ cam_mounts[cid])
        ts = time.perf_counter()
        r = render_camera(
            loaded,
            cam,
            wavelength=wavelengths[0],
            other_wavelengths=wavelengths[1:],
            spp=spp,
            seed=((seed or 0) + k) % 2**32,
        )
        render_s = time.perf_counter() - ts
        lidar_poses = {lid: rig @ mounts[lid] for lid in results}
        calib, written = rf.write_camera(folder, r, lidar_poses)
        if keep is not None:
            images[cid] = {"rgb": r.srgb8(), "K": r.K, "T_world_cam": r.T_world_cam}
            images[cid]["stamp_s"] = float(t_cam)
        files += written
        camera_entries[cid] = calib | {
            "spp": spp,
            "time_s": float(t_cam),
            "timings_s": r.timings | {"render_total": render_s},
        }
    for cam in loaded.cameras if cam_mounts else []:  # back to the scene's own pose
        _set_camera_pose(cam, cam_mounts[cam.id()])
    frame_total = time.perf_counter() - t0
    manifest = {
        "request": request,
        "scene": request["scene"],
        "scene_sha256": request["scene_sha256"],
        "variant": variant,
        "versions": versions,
        "frame": k,
        "time_s": float(t_k),
        "seed": request["seed"],
        "spp": spp,
        "formats": list(formats),
        "intensity": "physics",
        "lidars": lidar_entries,
        "cameras": camera_entries,
        "timings_s": {"total": frame_total},
        "files": sorted(os.path.relpath(p, folder) for p in files) + [rf.MANIFEST],
    }
    rf.write_manifest(folder, manifest)
    lead = loaded.lidars[0].id()
    if keep is not None:
        pts = results[lead].points()
        keep.append(
            {"points": {c: pts[c] for c in _SEQUENCE_COLUMNS if c in pts}, "cameras": images}
        )
    return {
        "frame": k,
        "time_s": float(t_k),
        "folder": os.path.relpath(folder, os.path.dirname(os.path.dirname(folder))),
        "cameras_time_s": {c: e["time_s"] for c, e in camera_entries.items()},
        "timings_s": {"frame_total": frame_total},
        "files": [os.path.relpath(p, folder) for p in files] + [rf.MANIFEST],
        "lidar_start_pose": np.asarray(lidar_entries[lead]["to_world"]),
    }
