"""The sweeps of a drive: rendered along its trajectory, read back, and NIDAR's intensity on them.

* :func:`render_sweeps` renders the drive's scene along its trajectory with the package's one
  trajectory renderer, :mod:`nidar_mi.sequence`: one instantaneous sweep per pose (``motion``
  off: each frame scanned from the rig pose of its time) and, when asked, the rig's camera at the
  same pose. The scene's labels are not read: labelled shapes stay apart and make every sweep of
  a generated city ~7x slower. The sequence folder is published whole and reused while its
  request holds (:func:`nidar_mi.sequence.ensure_sequence`: the scene, the trajectory and every
  option), so a second run with the same request renders nothing.
* :func:`read_sequence` reads the frames of any sequence folder, ``render --trajectory``'s
  included (``poses.txt`` relative to the first frame, ``times.txt``,
  ``frames/NNNNNN/<lidar>/points.npz`` with the per-point firing time ``t``).
* :func:`nidar_intensity` adds NIDAR's intensity to the frames of a sequence from their camera
  images (cached per weights folder, so new weights re-run only this step).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...errors import NidarError

__all__ = [
    "EXTRA_COLUMNS",
    "Sweep",
    "SweepRequest",
    "nidar_intensity",
    "read_sequence",
    "render_sweeps",
]

#: The point columns a sweep holds besides ``xyz``, ``intensity``, ``range`` and ``t``.
EXTRA_COLUMNS = ("intensity_nidar", "nidar_observed", "label")


@dataclass
class Sweep:
    """One LiDAR sweep of a drive.

    Attributes:
        xyz: (N, 3) float32 points in the LiDAR frame, m.
        intensity: (N,) float32 simulated intensity (the scene's ``intensity_mode``).
        range: (N,) float32 m.
        t: (N,) float32 s since the sweep's start, or None.
        extra: other per-point columns (:data:`EXTRA_COLUMNS` that the file has).
    """

    xyz: np.ndarray
    intensity: np.ndarray
    range: np.ndarray
    t: np.ndarray | None = None
    extra: dict | None = None


@dataclass(frozen=True)
class SweepRequest:
    """What :func:`render_sweeps` renders of a drive.

    Attributes:
        scene: scene XML with one ``lidar`` (and, with ``cameras``, a perspective camera).
        trajectory: the rig's TUM, CSV or KITTI odometry poses (the LiDAR and the camera ride
            on the rig at their scene poses).
        rate_hz: frames per second (frame ``k`` at ``k / rate_hz`` s after the first pose).
        frames: how many frames.
        params: the scene's ``<default>`` values (e.g. ``cols``, ``width``, ``height``).
        rgb_twin: load the scene's RGB-only twin.
        cameras: also render the camera of every frame.
        spp: camera samples per pixel.
        seed: noise and dropout seed of frame 0 (frame ``k`` uses ``seed + k``).
    """

    scene: str
    trajectory: str
    rate_hz: float
    frames: int
    params: dict[str, str] | None = None
    rgb_twin: bool = False
    cameras: bool = False
    spp: int = 4
    seed: int = 0


def render_sweeps(request: SweepRequest, folder: str, *, progress: bool = True) -> str:
    """Render the sweeps of ``request`` into the sequence folder ``folder`` (module docstring)
    unless it holds them already; ``folder``.

    Raises:
        NidarError: a bad scene (not exactly one LiDAR; no camera with ``cameras``), trajectory
            or option.
    """
    from ...render_session import RenderOptions
    from ...sequence import SequenceOptions, ensure_sequence

    frame = RenderOptions(
        request.scene,
        formats=("npz",),
        seed=request.seed,
        spp=request.spp,
        rgb_twin=request.rgb_twin,
        params=request.params,
        cameras=request.cameras,
        labels=False,
        progress=progress,
    )
    options = SequenceOptions(
        frame,
        request.trajectory,
        rate=request.rate_hz,
        frames=request.frames,
        previews="none",
        motion=False,
    )
    with warnings.catch_warnings():
        if request.rgb_twin:  # the twin is RGB-only by design: no warning per material
            warnings.filterwarnings("ignore", message=".*is RGB-only.*")
        ensure_sequence(options, folder)
    lidars, cameras = _frame_sensors(folder)
    if len(lidars) != 1:
        raise NidarError(f"{request.scene}: a drive needs exactly one lidar sensor")
    if request.cameras and not cameras:
        raise NidarError(f"{request.scene}: NIDAR needs a perspective camera in the scene")
    return folder


def _frame_sensors(folder: str) -> tuple[list[str], list[str]]:
    """The LiDAR and camera ids of the first frame of a sequence folder."""
    from ...render_folder import read_manifest

    first = read_manifest(os.path.join(folder, "frames", "000000"))
    return sorted(first.get("lidars", {})), sorted(first.get("cameras", {}))


def read_sequence(
    folder: str, lidar: str | None = None
) -> tuple[np.ndarray, np.ndarray, Callable[[int], Sweep]]:
    """The frames of a sequence folder (:mod:`nidar_mi.sequence`).

    Args:
        folder: the sequence folder (``poses.txt``, ``times.txt``, ``frames/``).
        lidar: the LiDAR's id (None: the only one).

    Returns:
        ``(poses, times, load)``: (N, 4, 4) ``T_{lidar_0 <- lidar_k}``, (N,) s, and a function
        ``load(k) -> Sweep``.

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

    def load(k: int) -> Sweep:
        pts = read_npz(os.path.join(frames_dir, names[k], lidar, "points.npz"))
        extra = {key: pts[key] for key in EXTRA_COLUMNS if key in pts}
        return Sweep(pts["xyz"], pts["intensity"], pts["range"], t=pts.get("t"), extra=extra)

    return poses, times, load


def nidar_intensity(
    sequence: str, folder: str, weights: str | None = None, *, progress: bool = True
) -> str:
    """NIDAR's intensity of every frame of a sequence from its camera image (R branch,
    calibrated), cached per weights folder.

    Writes ``folder/nidar_<weights hash>/k:06d.npz`` (``intensity_nidar`` float32 in [0, 1],
    ``nidar_observed`` bool, one per point of the frame's first LiDAR) and returns that folder;
    frames already there are kept.

    Args:
        sequence: a sequence folder whose frames have a camera.
        folder: where the cache folder goes.
        weights: NIDAR weights folder (None: the shipped model).
        progress: progress bar on stderr.
    """
    from ...io.atomic import atomic_path
    from ...nidar.pipeline import NidarModel, shipped_weights_dir
    from ...progress import progress_bar
    from ...render_folder import read_render, weights_sha256

    wdir = weights or str(shipped_weights_dir())
    out = os.path.join(folder, f"nidar_{weights_sha256(wdir)[:12]}")
    os.makedirs(out, exist_ok=True)
    frames = sorted(os.listdir(os.path.join(sequence, "frames")))
    todo = [k for k in range(len(frames)) if not os.path.exists(_cached(out, k))]
    if not todo:
        return out
    model = NidarModel.load(weights)
    for k in progress_bar(todo, show=progress, desc="NIDAR", unit="frame"):
        render = read_render(os.path.join(sequence, "frames", frames[k]))
        if not render.cameras:
            raise NidarError(f"{render.folder}: NIDAR needs the frame's camera image")
        cam = render.cameras[0]
        res = model.point_intensity(
            render.points["xyz"], [cam.model], [cam.rgb8()], depth_images=[cam.depth]
        )
        with atomic_path(_cached(out, k)) as tmp, open(tmp, "wb") as f:
            np.savez(f, intensity_nidar=res.intensity, nidar_observed=res.observed)
    return out


def _cached(folder: str, k: int) -> str:
    return os.path.join(folder, f"{k:06d}.npz")
