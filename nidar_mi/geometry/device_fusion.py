""":func:`~nidar_mi.geometry.fusion.sample_cameras` in torch, on any device (CUDA, or the CPU).

The same steps as the NumPy reference (:mod:`.projection`, :mod:`.visibility`, :mod:`.fusion`),
in float64 on the device of the images: projection, the occlusion test (a rendered depth image
or the cloud's own z-buffer, by ``scatter_reduce``), bilinear sampling and the fusion of the
cameras' samples. The points go to the device once and the results come back once, so a model
on a GPU keeps its maps there. Units and conventions are the reference's: points in the LiDAR
frame in metres, pixel centres at integer ``(u, v) = (column, row)``. The outputs equal the
reference's to floating-point rounding (the projection sums in another order: pixel
coordinates within ~1e-12 px; tests/geometry/test_device_fusion.py checks values within 1e-9 and
identical observed flags on clouds of every test).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from nidar_mi.errors import NidarError

from .camera_model import CameraModel
from .fusion import FUSION_RULES
from .projection import _points
from .visibility import DEFAULT_ABS_TOL, DEFAULT_REL_TOL, DEFAULT_ZBUFFER_CELL

__all__ = ["sample_cameras_on", "to_host"]


def _project(p, cam: CameraModel):
    """``(uv, depth, in_front)`` of (N, 3) float64 points on the device (:func:`.project`)."""
    import torch

    T = cam.T_cam_lidar
    rot = cam.R_opencv_cam @ T[:3, :3]
    shift = cam.R_opencv_cam @ T[:3, 3]
    cv = [
        p[:, 0] * rot[i, 0] + p[:, 1] * rot[i, 1] + p[:, 2] * rot[i, 2] + shift[i] for i in range(3)
    ]
    depth = cv[2]
    in_front = depth > 1e-6
    z = torch.where(in_front, depth, torch.ones_like(depth))
    x, y = cv[0] / z, cv[1] / z
    K = cam.K
    uv = torch.stack([x * K[0, 0] + y * K[0, 1] + K[0, 2], x * K[1, 0] + y * K[1, 1] + K[1, 2]], 1)
    uv = torch.where(in_front[:, None], uv, torch.full_like(uv, math.nan))
    return uv, depth, in_front


def _in_image(uv, cam: CameraModel):
    u, v = uv[:, 0], uv[:, 1]
    return (u >= -0.5) & (u < cam.width - 0.5) & (v >= -0.5) & (v < cam.height - 0.5)


def _visible(uv, depth, cam: CameraModel, depth_image, opts: dict[str, Any]):
    """(N,) bool: in the image, in front and unoccluded (:func:`.visible_mask`)."""
    import torch

    rel_tol = opts["rel_tol"]
    if rel_tol is None:
        rel_tol = DEFAULT_REL_TOL["zbuffer" if depth_image is None else "depth_image"]
    if rel_tol < 0 or opts["abs_tol"] < 0:
        raise NidarError("visible_mask: tolerances must be non-negative")
    cand = _in_image(uv, cam) & torch.isfinite(depth) & (depth > 0)
    if depth_image is not None:
        return cand & _depth_image_test(uv, depth, cam, depth_image, rel_tol, opts)
    cell = int(opts["zbuffer_cell"])
    if cell < 1:
        raise NidarError(f"visible_mask: zbuffer_cell must be >= 1, got {opts['zbuffer_cell']!r}")
    ncols = (cam.width + cell - 1) // cell
    nrows = (cam.height + cell - 1) // cell
    safe = torch.where(cand[:, None], uv, torch.zeros_like(uv))
    key = torch.floor((safe[:, 1] + 0.5) / cell).long() * ncols
    key = key + torch.floor((safe[:, 0] + 0.5) / cell).long()
    z = torch.where(cand, depth, torch.full_like(depth, math.inf))
    zmin = torch.full((nrows * ncols,), math.inf, dtype=depth.dtype, device=depth.device)
    zmin = zmin.scatter_reduce(0, key, z, reduce="amin", include_self=True)
    return cand & (depth <= zmin[key] * (1.0 + rel_tol) + opts["abs_tol"])


def _depth_image_test(uv, depth, cam: CameraModel, depth_image, rel_tol: float, opts):
    """(N,) bool: not hidden by the rendered depth image (points outside the image: any)."""
    import torch

    dimg = torch.as_tensor(np.asarray(depth_image, dtype=np.float64), device=depth.device)
    if tuple(dimg.shape) != (cam.height, cam.width):
        raise NidarError(
            f"visible_mask: depth image is {tuple(dimg.shape)}, camera is {(cam.height, cam.width)}"
        )
    safe = torch.nan_to_num(uv, nan=0.0, posinf=0.0, neginf=0.0)
    if opts["depth_kind"] == "z":
        own = depth
    elif opts["depth_kind"] == "range":
        kinv = torch.as_tensor(np.linalg.inv(cam.K), device=depth.device)
        homog = torch.cat([safe, torch.ones_like(safe[:, :1])], 1)
        own = depth * torch.linalg.norm(homog @ kinv.T, dim=1)
    else:
        raise NidarError(
            f"visible_mask: depth_kind must be 'z' or 'range', not {opts['depth_kind']!r}"
        )
    col = torch.floor(safe[:, 0] + 0.5).long().clamp(0, cam.width - 1)
    row = torch.floor(safe[:, 1] + 0.5).long().clamp(0, cam.height - 1)
    occ = dimg[row, col]
    no_surface = ~torch.isfinite(occ) | (occ <= 0)
    return no_surface | (own <= occ * (1.0 + rel_tol) + opts["abs_tol"])


def _bilinear(img, uv, seen):
    """(N,) float64 bilinear samples (:func:`.bilinear_sample`), NaN where not ``seen``."""
    import torch

    H, W = img.shape
    safe = torch.where(seen[:, None], uv, torch.zeros_like(uv))
    u = safe[:, 0].clamp(0.0, W - 1.0)
    v = safe[:, 1].clamp(0.0, H - 1.0)
    c0 = torch.floor(u).long().clamp(max=max(W - 2, 0))
    r0 = torch.floor(v).long().clamp(max=max(H - 2, 0))
    c1 = (c0 + 1).clamp(max=W - 1)
    r1 = (r0 + 1).clamp(max=H - 1)
    fu, fv = u - c0, v - r0
    top = (1.0 - fu) * img[r0, c0] + fu * img[r0, c1]
    bottom = (1.0 - fu) * img[r1, c0] + fu * img[r1, c1]
    out = (1.0 - fv) * top + fv * bottom
    return torch.where(seen, out, torch.full_like(out, math.nan))


def _sample_camera(p, cam: CameraModel, img, depth_image, occlusion: bool, opts):
    """One camera's ``(value, centre score, depth)`` per point; NaN / inf where unseen."""
    import torch

    uv, depth, in_front = _project(p, cam)
    if occlusion:
        seen = _visible(uv, depth, cam, depth_image, opts)
    else:
        seen = in_front & _in_image(uv, cam)
    value = _bilinear(img, uv, seen)
    ok = torch.isfinite(value)
    du = (uv[:, 0] - (cam.width - 1) / 2.0) / (cam.width / 2.0)
    dv = (uv[:, 1] - (cam.height - 1) / 2.0) / (cam.height / 2.0)
    inf = torch.full_like(depth, math.inf)
    return value, torch.where(ok, torch.hypot(du, dv), inf), torch.where(ok, depth, inf)


def _fuse(vals, score, dep, fusion: str):
    """(C, N) per-camera samples -> ``(values, observed, camera_index)`` on the device."""
    import torch

    observed = torch.isfinite(vals).any(0)
    pick = torch.argmin(dep if fusion == "min_depth" else score, 0)
    if fusion == "mean":
        fused = torch.nanmean(vals, 0)
    else:
        fused = vals.gather(0, pick[None])[0]
    values = torch.where(observed, fused, torch.zeros_like(fused)).float()
    return values, observed, torch.where(observed, pick, torch.full_like(pick, -1))


def sample_cameras_on(
    device: Any,
    points: Any,
    cameras: Sequence[CameraModel],
    images: Sequence[Any],
    *,
    depth_images: Sequence[Any] | None = None,
    occlusion: bool = True,
    fusion: str = "nearest_center",
    as_tensors: bool = False,
    **visibility: Any,
) -> tuple[Any, Any, Any]:
    """:func:`~nidar_mi.geometry.fusion.sample_cameras` computed on a torch ``device``.

    Args:
        device: a torch device (``"cuda"``, ``"cpu"``, a ``torch.device``).
        points, cameras, images, depth_images, occlusion, fusion: as
            :func:`~nidar_mi.geometry.fusion.sample_cameras`; images may be torch tensors
            (on any device) or arrays.
        as_tensors: return the three results as tensors on ``device`` (nothing comes back to
            the host; :func:`to_host` brings them back in one transfer).
        **visibility: ``depth_kind``, ``rel_tol``, ``abs_tol``, ``zbuffer_cell`` as there.

    Returns:
        ``(values, observed, camera_index)`` as NumPy arrays: (N,) float32, (N,) bool,
        (N,) int64 (module docstring on equality with the reference); tensors of those dtypes
        with ``as_tensors``.

    Raises:
        NidarError: as :func:`~nidar_mi.geometry.fusion.sample_cameras`.
    """
    import torch

    if isinstance(cameras, CameraModel):
        cameras = [cameras]
    unknown = set(visibility) - {"depth_kind", "rel_tol", "abs_tol", "zbuffer_cell"}
    if unknown:
        raise NidarError(f"sample_cameras: unknown option(s) {', '.join(sorted(unknown))}")
    opts = {
        "depth_kind": "z",
        "rel_tol": None,
        "abs_tol": DEFAULT_ABS_TOL,
        "zbuffer_cell": DEFAULT_ZBUFFER_CELL,
    } | visibility
    depth_images = _check(cameras, images, depth_images, fusion)
    p = torch.as_tensor(_points(points), device=device)
    per_camera = []
    for k, (cam, img, dimg) in enumerate(zip(cameras, images, depth_images, strict=True)):
        img = torch.as_tensor(img, device=p.device).to(torch.float64)
        if tuple(img.shape) != (cam.height, cam.width):
            raise NidarError(
                f"sample_cameras: image {k} is {tuple(img.shape)}, "
                f"camera {k} is {(cam.height, cam.width)}"
            )
        per_camera.append(_sample_camera(p, cam, img, dimg, occlusion, opts))
    vals, score, dep = (torch.stack(a) for a in zip(*per_camera, strict=True))
    values, observed, index = _fuse(vals, score, dep, fusion)
    if as_tensors:
        return values, observed, index
    return to_host(values, observed, index)


def to_host(*tensors: Any) -> list[np.ndarray]:
    """(N,) tensors of one device as NumPy arrays of their dtypes, in one transfer.

    The tensors are stacked as float64 on their device (exact for float32, bool and integers
    below 2**53) and copied to the host once.

    Args:
        *tensors: (N,) tensors of the same length and device.

    Returns:
        One array per tensor, of its dtype.
    """
    import torch

    if not tensors:
        return []
    host = torch.stack([t.to(torch.float64) for t in tensors]).cpu().numpy()
    dtypes = _numpy_dtypes()
    return [row.astype(dtypes[t.dtype]) for row, t in zip(host, tensors, strict=True)]


def _numpy_dtypes() -> dict:
    import torch

    return {
        torch.float32: np.float32,
        torch.float64: np.float64,
        torch.bool: np.bool_,
        torch.int64: np.int64,
        torch.int32: np.int32,
    }


def _check(cameras, images, depth_images, fusion: str) -> Sequence[Any]:
    """The depth images (one None per camera when not given), after the reference's checks."""
    if len(cameras) == 0:
        raise NidarError("sample_cameras: no cameras given")
    if fusion not in FUSION_RULES:
        raise NidarError(f"sample_cameras: fusion must be one of {FUSION_RULES}, not {fusion!r}")
    if len(images) != len(cameras):
        raise NidarError(f"sample_cameras: {len(cameras)} cameras but {len(images)} images")
    if depth_images is None:
        return [None] * len(cameras)
    if len(depth_images) != len(cameras):
        raise NidarError(
            f"sample_cameras: {len(cameras)} cameras but {len(depth_images)} depth images"
        )
    return depth_images
