"""Reading back what ``python -m nidar_mi.render`` wrote: one LiDAR's returns and the cameras.

Used by the dataset builder and the evaluation, which both pair a scan with the camera images
of the same render folder.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

from .errors import NidarError

__all__ = ["RenderedScan", "RenderedCamera", "read_render"]


@dataclass
class RenderedCamera:
    """One camera of a render folder.

    Attributes:
        name: camera id.
        folder: its output folder (rgb.png, nir.exr, depth.exr, calib.json).
        model: :class:`nidar_mi.geometry.CameraModel` with ``T_cam_lidar`` of the scan's LiDAR.
        depth: (H, W) float32 z-depth in m, 0 where no surface.
    """

    name: str
    folder: str
    model: object
    depth: np.ndarray

    def rgb8(self) -> np.ndarray:
        """(H, W, 3) uint8 sRGB (rgb.png)."""
        from .io.images import read_png

        return read_png(os.path.join(self.folder, "rgb.png"))[..., :3]

    def nir(self) -> np.ndarray:
        """(H, W) float32 NIR band radiance (nir.exr)."""
        from .io.images import read_exr

        return next(iter(read_exr(os.path.join(self.folder, "nir.exr")).values())).astype(
            np.float32
        )


@dataclass
class RenderedScan:
    """A render folder seen from one LiDAR.

    Attributes:
        manifest: the folder's manifest.json.
        lidar: the LiDAR id.
        parameters: its resolved parameters.
        points: its points dict (``points.npz``).
        compensated: (N,) float32 range-compensated intensity ``g·ρ·cosθ·exp(-2αd)`` (+ noise·d²
            in ``raw`` mode).
        cameras: every camera, sorted by id.
    """

    manifest: dict
    lidar: str
    parameters: dict
    points: dict
    compensated: np.ndarray
    cameras: list[RenderedCamera]


def read_render(render_dir: str, lidar_id: str | None = None) -> RenderedScan:
    """Read a render folder (the first LiDAR by id unless ``lidar_id`` names one).

    Raises:
        NidarError: missing or malformed manifest, or an unknown LiDAR id.
    """
    from .geometry import CameraModel
    from .io.images import read_exr
    from .io.points import read_npz
    from .nidar.frames import compensate

    path = os.path.join(render_dir, "manifest.json")
    try:
        with open(path, encoding="utf-8") as f:
            manifest = json.load(f)
    except OSError as e:
        raise NidarError(f"{render_dir}: no readable manifest.json ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise NidarError(f"{path}: not valid JSON ({e})") from None
    lidars = sorted(manifest.get("lidars", {}))
    if not lidars:
        raise NidarError(f"{render_dir}: the manifest lists no lidar")
    lid = lidar_id or lidars[0]
    if lid not in manifest["lidars"]:
        raise NidarError(f"{render_dir}: no lidar '{lid}' (has {', '.join(lidars)})")
    params = manifest["lidars"][lid]["parameters"]
    pts = read_npz(os.path.join(render_dir, lid, "points.npz"))
    comp = compensate(pts["intensity"], pts["range"], params["intensity_mode"])
    cameras = []
    for cam_id, cam in sorted(manifest.get("cameras", {}).items()):
        folder = os.path.join(render_dir, cam_id)
        T = np.array(cam["T_cam_lidar"][lid])
        model = CameraModel(np.array(cam["K"]), cam["width"], cam["height"], T, name=cam_id)
        depth = next(iter(read_exr(os.path.join(folder, "depth.exr")).values())).astype(np.float32)
        cameras.append(RenderedCamera(cam_id, folder, model, depth))
    return RenderedScan(manifest, lid, params, pts, comp, cameras)
