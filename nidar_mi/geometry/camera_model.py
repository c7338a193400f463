"""The pinhole camera model: intrinsics, extrinsics and the two camera-axis conventions.

**Frames.** ``CameraModel.T_cam_lidar`` (4, 4) maps LiDAR-frame points (metres) to the
camera frame, ``p_cam = T_cam_lidar @ p_lidar`` (the NIDAR paper's
``T_{c<-e} = T_{e<-c}^{-1}``). The camera frame follows ``convention``:

* ``"opencv"`` (also KITTI): x right, y down, z forward;
  ``x_n = X/Z, y_n = Y/Z``, depth ``Z``.
* ``"waymo"`` (the paper's projection equation): x forward, y left, z up;
  ``x_n = -Y/X, y_n = -Z/X``, depth ``X``.

Both are then ``[u, v, 1]^T = K [x_n, y_n, 1]^T`` with ``K`` in pixels. A Waymo-convention
camera equals an OpenCV one whose extrinsic is premultiplied by :data:`R_OPENCV_FROM_WAYMO`
(see :meth:`CameraModel.to_opencv`). "Depth" always means the camera-forward coordinate, in
metres.

**Pixel convention** (the one OpenCV and KITTI intrinsics use): the centre of the pixel in
column ``c`` and row ``r`` (``img[r, c]``) is at ``(u, v) = (c, r)``; the pixel covers
``[c - 0.5, c + 0.5) x [r - 0.5, r + 0.5)``. A point is inside the image iff
``-0.5 <= u < W - 0.5`` and ``-0.5 <= v < H - 0.5``; the image centre is
``((W - 1) / 2, (H - 1) / 2)``. (Renderers such as Mitsuba put pixel centres at
half-integers: build their ``K`` with ``c_x = W / 2 - 0.5``, ``c_y = H / 2 - 0.5`` for a
centred axis.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nidar_mi.errors import NidarError

__all__ = ["CONVENTIONS", "R_OPENCV_FROM_WAYMO", "CameraModel"]

CONVENTIONS = ("opencv", "waymo")
"""Camera-axis conventions a :class:`CameraModel` accepts."""

R_OPENCV_FROM_WAYMO = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
"""(3, 3) rotation taking Waymo camera axes (fwd, left, up) to OpenCV axes (right, down, fwd)."""
R_OPENCV_FROM_WAYMO.setflags(write=False)

_R_OPENCV_FROM = {"opencv": np.eye(3), "waymo": R_OPENCV_FROM_WAYMO}
_R_OPENCV_FROM["opencv"].setflags(write=False)


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A pinhole camera rigidly attached to the LiDAR.

    Attributes:
        K: (3, 3) intrinsics ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (module
            pixel convention: pixel centres at integer coordinates).
        width: image width W in pixels.
        height: image height H in pixels.
        T_cam_lidar: (4, 4) LiDAR-to-camera transform, metres (last row ``[0, 0, 0, 1]``).
        convention: camera axes, ``"opencv"`` or ``"waymo"`` (see the module docstring).
        name: optional label.

    Raises:
        NidarError: on construction, for a malformed ``K`` or ``T_cam_lidar``, an unknown
            convention or a non-positive size (one-line message naming the camera).
    """

    K: np.ndarray
    width: int
    height: int
    T_cam_lidar: np.ndarray
    convention: str = "opencv"
    name: str = ""

    def __post_init__(self) -> None:
        label = f"camera {self.name!r}" if self.name else "camera"
        K = np.array(self.K, dtype=np.float64)
        T = np.array(self.T_cam_lidar, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise NidarError(f"{label}: K must be a finite 3x3 matrix")
        if not np.array_equal(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
            raise NidarError(f"{label}: K must have the form [[fx,s,cx],[0,fy,cy],[0,0,1]]")
        if K[0, 0] == 0.0 or K[1, 1] == 0.0:
            raise NidarError(f"{label}: K has a zero focal length")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise NidarError(f"{label}: T_cam_lidar must be a finite 4x4 matrix")
        if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise NidarError(f"{label}: T_cam_lidar last row must be [0, 0, 0, 1]")
        if abs(np.linalg.det(T[:3, :3])) < 1e-9:
            raise NidarError(f"{label}: T_cam_lidar is singular")
        if self.convention not in CONVENTIONS:
            raise NidarError(f"{label}: convention must be one of {CONVENTIONS}")
        try:
            width, height = int(self.width), int(self.height)
        except (TypeError, ValueError):
            raise NidarError(f"{label}: width and height must be integers") from None
        if width != self.width or height != self.height or width < 1 or height < 1:
            raise NidarError(f"{label}: width and height must be positive integers")
        for arr in (K, T):
            arr.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "T_cam_lidar", T)
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)

    @property
    def T_lidar_cam(self) -> np.ndarray:
        """(4, 4) camera-to-LiDAR transform, the inverse of ``T_cam_lidar``."""
        return np.linalg.inv(self.T_cam_lidar)

    @property
    def R_opencv_cam(self) -> np.ndarray:
        """(3, 3) read-only rotation from this camera's axes to OpenCV axes (identity for
        ``"opencv"``, :data:`R_OPENCV_FROM_WAYMO` for ``"waymo"``)."""
        return _R_OPENCV_FROM[self.convention]

    def to_opencv(self) -> CameraModel:
        """The same physical camera expressed in the OpenCV convention."""
        T = self.T_cam_lidar.copy()
        T[:3] = self.R_opencv_cam @ T[:3]
        return CameraModel(self.K, self.width, self.height, T, "opencv", self.name)
