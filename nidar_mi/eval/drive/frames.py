"""The frames of a drive: LiDAR points along a trajectory, and the camera images NIDAR needs.

Two sources give the same :class:`Frame` records:

* :func:`render_drive` scans a scene from every pose of a trajectory (one instantaneous sweep per
  pose: :func:`nidar_mi.lidar.scan.scan` with ``to_world``, the compiled kernels reused) and, when
  asked, renders the rig's camera at the same pose (the camera rides rigidly with the LiDAR).
  Frames are cached one file per frame under ``DIR/<variant>/``, so an interrupted run resumes
  and a changed request (scene, poses, columns, camera settings) renders again.
* :func:`read_sequence` reads the sequence folder of ``render SCENE --trajectory FILE``
  (``poses.txt`` relative to the first frame, ``times.txt``, ``frames/NNNNNN/<lidar>/points.npz``,
  with the per-point firing time ``t`` when the renderer writes it).

:func:`nidar_columns` adds NIDAR's intensity to cached frames from their camera images (cached per
weights folder, so new weights re-run only this step).
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass

import numpy as np

from ...errors import NidarError

__all__ = ["Frame", "render_drive", "read_sequence", "nidar_columns", "frame_count"]

_POINT_KEYS = ("xyz", "intensity", "range", "reflectance", "cos_incidence")


@dataclass
class Frame:
    """One LiDAR frame of a drive.

    Attributes:
        xyz: (N, 3) float32 points in the LiDAR frame, m.
        intensity: (N,) float32 simulated intensity (the scene's ``intensity_mode``).
        range: (N,) float32 m.
        t: (N,) float32 s since the sweep's start, or None (an instantaneous sweep).
        extra: other per-point columns (e.g. ``intensity_nidar``, ``nidar_observed``).
    """

    xyz: np.ndarray
    intensity: np.ndarray
    range: np.ndarray
    t: np.ndarray | None = None
    extra: dict | None = None


def _frame_path(folder: str, k: int, stem: str = "") -> str:
    return os.path.join(folder, f"{stem}{k:06d}.npz")


def _prepare(folder: str, request: dict) -> None:
    """Create ``folder`` for ``request``; frames of another request there are removed."""
    os.makedirs(folder, exist_ok=True)
    req_path = os.path.join(folder, "request.json")
    if os.path.exists(req_path):
        with open(req_path, encoding="utf-8") as f:
            if json.load(f) == request:
                return
        for name in os.listdir(folder):
            if name.endswith(".npz") or name.endswith(".npy"):
                os.remove(os.path.join(folder, name))
    from ...io.atomic import atomic_write_json

    atomic_write_json(req_path, request)


def frame_count(folder: str) -> int:
    """Frames cached in ``folder`` (consecutive from 0)."""
    k = 0
    while os.path.exists(_frame_path(folder, k)):
        k += 1
    return k


def _set_camera_pose(camera, matrix: np.ndarray) -> None:
    import mitsuba as mi

    params = mi.traverse(camera)
    params["to_world"] = mi.Transform4f(matrix.astype(np.float64))
    params.update()


def render_drive(
    scene_path: str,
    poses: np.ndarray,
    folder: str,
    *,
    rgb_twin: bool = False,
    cameras: bool = False,
    params: dict[str, str] | None = None,
    spp: int = 4,
    seed: int = 0,
    progress: bool = True,
) -> str:
    """Scan ``scene_path`` from every pose and cache the frames in ``folder``.

    Args:
        scene_path: scene XML with one ``lidar`` (and, with ``cameras``, one perspective camera).
        poses: (N, 4, 4) ``T_world_lidar`` per frame.
        folder: cache folder (created); frame k is ``k:06d.npz`` (points) and, with cameras,
            ``cam_k:06d.npz`` (``rgb`` uint8 (H, W, 3), ``depth`` float32 (H, W), ``K``,
            ``T_cam_lidar``).
        rgb_twin: load the scene's RGB-only twin.
        cameras: also render the camera at every pose.
        params: the scene's ``<default>`` values (e.g. ``cols``, ``width``, ``height``).
        spp: camera samples per pixel.
        seed: noise and dropout seed of frame 0 (frame k uses ``seed + k``).
        progress: progress bar on stderr.

    Returns:
        ``folder``.
    """
    from ...io.cache_key import file_sha256

    poses = np.asarray(poses, dtype=np.float64)
    request = {
        "scene_sha256": file_sha256(scene_path),
        # to the micrometre: the same drive read back from another file format is the same
        "poses_sha256": hashlib.sha256((np.round(poses, 6) + 0.0).tobytes()).hexdigest(),
        "rgb_twin": rgb_twin,
        "cameras": cameras,
        "params": dict(sorted((params or {}).items())),
        "spp": spp,
        "seed": seed,
    }
    _prepare(folder, request)
    todo = [
        k
        for k in range(len(poses))
        if not os.path.exists(_frame_path(folder, k))
        or (cameras and not os.path.exists(_frame_path(folder, k, "cam_")))
    ]
    if not todo:
        return folder
    with warnings.catch_warnings():
        if rgb_twin:  # the twin is RGB-only by design: no warning per material
            warnings.filterwarnings("ignore", message=".*is RGB-only.*")
        return _render(
            scene_path, poses, folder, todo, rgb_twin, cameras, params, spp, seed, progress
        )


def _render(scene_path, poses, folder, todo, rgb_twin, cameras, params, spp, seed, progress):
    """Scan (and photograph) the frames ``todo`` into ``folder``."""
    from ...camera import render_camera
    from ...geometry.se3 import transform_matrix
    from ...io.atomic import atomic_path
    from ...lidar.scan import scan
    from ...progress import progress_bar
    from ...scene import load_scene

    # no labels: they keep ~2000 shapes apart and make every sweep ~7x slower
    loaded = load_scene(scene_path, rgb_twin=rgb_twin, params=params, labels=False)
    if len(loaded.lidars) != 1:
        raise NidarError(f"{scene_path}: a drive needs exactly one lidar sensor")
    lidar = loaded.lidars[0]
    camera = None
    if cameras:
        if not loaded.cameras:
            raise NidarError(f"{scene_path}: NIDAR needs a perspective camera in the scene")
        camera = loaded.cameras[0]
        T_wl0 = transform_matrix(lidar.world_transform())
        M0 = transform_matrix(camera.world_transform())
        lidar_to_cam_mount = np.linalg.inv(T_wl0) @ M0
    desc = f"{os.path.basename(folder)} frames"
    for k in progress_bar(todo, show=progress, desc=desc, unit="frame"):
        result = scan(loaded.scene, lidar, seed=seed + k, to_world=poses[k])
        pts = result.points()
        with atomic_path(_frame_path(folder, k)) as tmp, open(tmp, "wb") as f:
            np.savez(f, **{key: pts[key] for key in _POINT_KEYS})
        if camera is not None:
            _set_camera_pose(camera, poses[k] @ lidar_to_cam_mount)
            r = render_camera(
                loaded,
                camera,
                wavelength=lidar.config.wavelength,
                spp=spp,
                seed=seed + k,
                nir=False,
                albedo=False,
            )
            T_cam_lidar = np.linalg.inv(r.T_world_cam) @ poses[k]
            with atomic_path(_frame_path(folder, k, "cam_")) as tmp, open(tmp, "wb") as f:
                np.savez(f, rgb=r.srgb8(), depth=r.depth, K=r.K, T_cam_lidar=T_cam_lidar)
    return folder


def load_frame(folder: str, k: int) -> Frame:
    """Frame ``k`` of a :func:`render_drive` cache (with the NIDAR columns when cached)."""
    from ...io.points import read_npz

    pts = read_npz(_frame_path(folder, k))
    return Frame(xyz=pts["xyz"], intensity=pts["intensity"], range=pts["range"])


def nidar_columns(
    folder: str, frames: int, weights: str | None = None, *, progress: bool = True
) -> str:
    """NIDAR intensity of every cached frame from its camera image (R branch, calibrated).

    Writes ``folder/nidar_<weights hash>/k:06d.npz`` (``intensity_nidar`` float32 in [0, 1],
    ``nidar_observed`` bool) and returns that folder; frames already there are kept.
    """
    from ...geometry.camera_model import CameraModel
    from ...io.atomic import atomic_path
    from ...io.points import read_npz
    from ...nidar.pipeline import NidarModel, shipped_weights_dir
    from ...progress import progress_bar
    from ...render_folder import weights_sha256

    wdir = weights or str(shipped_weights_dir())
    out = os.path.join(folder, f"nidar_{weights_sha256(wdir)[:12]}")
    os.makedirs(out, exist_ok=True)
    todo = [k for k in range(frames) if not os.path.exists(_frame_path(out, k))]
    if not todo:
        return out
    model = NidarModel.load(weights)
    for k in progress_bar(todo, show=progress, desc="NIDAR", unit="frame"):
        pts = read_npz(_frame_path(folder, k))
        cam = read_npz(_frame_path(folder, k, "cam_"))
        H, W = cam["rgb"].shape[:2]
        model_cam = CameraModel(K=cam["K"], T_cam_lidar=cam["T_cam_lidar"], width=W, height=H)
        res = model.point_intensity(
            pts["xyz"], [model_cam], [cam["rgb"]], depth_images=[cam["depth"]]
        )
        with atomic_path(_frame_path(out, k)) as tmp, open(tmp, "wb") as f:
            np.savez(f, intensity_nidar=res.intensity, nidar_observed=res.observed)
    return out


# ---------------------------------------------------------------- sequence folders


def read_sequence(folder: str, lidar: str | None = None):
    """The frames of a ``render --trajectory`` sequence folder.

    Args:
        folder: the sequence folder (``poses.txt``, ``times.txt``, ``frames/``).
        lidar: the LiDAR's id (None: the only one).

    Returns:
        ``(poses, times, load)``: (N, 4, 4) ``T_{lidar_0 <- lidar_k}``, (N,) s, and a function
        ``load(k) -> Frame``.

    Raises:
        NidarError: a missing or malformed file, or frame folders that do not match the poses.
    """
    from ...io.kitti import read_kitti_poses, read_kitti_times
    from ...io.points import read_npz

    poses = read_kitti_poses(os.path.join(folder, "poses.txt"))
    times = read_kitti_times(os.path.join(folder, "times.txt"))
    frames_dir = os.path.join(folder, "frames")
    names = sorted(os.listdir(frames_dir)) if os.path.isdir(frames_dir) else []
    if len(times) != len(poses) or len(names) != len(poses):
        raise NidarError(
            f"{folder}: {len(poses)} poses, {len(times)} times and {len(names)} frame folders"
        )
    first = os.path.join(frames_dir, names[0])
    lidars = sorted(
        d for d in os.listdir(first) if os.path.isfile(os.path.join(first, d, "points.npz"))
    )
    if lidar is None:
        if len(lidars) != 1:
            raise NidarError(f"{first}: {len(lidars)} LiDARs ({', '.join(lidars)}); name one")
        lidar = lidars[0]

    def load(k: int) -> Frame:
        pts = read_npz(os.path.join(frames_dir, names[k], lidar, "points.npz"))
        extra = {
            key: pts[key] for key in ("intensity_nidar", "nidar_observed", "label") if key in pts
        }
        return Frame(
            xyz=pts["xyz"],
            intensity=pts["intensity"],
            range=pts["range"],
            t=pts.get("t"),
            extra=extra,
        )

    return poses, times, load
