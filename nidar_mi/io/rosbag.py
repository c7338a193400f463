"""A LiDAR sequence as a ROS 2 bag (rosbag2, SQLite 3 storage, CDR messages) via ``rosbags``.

Topics (``<lidar>`` and ``<camera>`` are the sensor ids; frame ids are the same names):

==============================  ============================  ===================================
topic                           type                          content
==============================  ============================  ===================================
``/<lidar>/points``             sensor_msgs/PointCloud2       one per frame, stamped at the sweep
                                                              start; fields ``x y z intensity``
                                                              (float32), ``ring`` (uint16),
                                                              ``time`` (float32, s since the
                                                              stamp), ``label`` (uint16),
                                                              ``instance`` (uint32)
``/<camera>/image_raw``         sensor_msgs/Image             ``rgb8``, at the image's own time
``/<camera>/camera_info``       sensor_msgs/CameraInfo        ``K`` and ``P = [K | 0]``, no
                                                              distortion (``plumb_bob``, zeros)
``/tf``                         tf2_msgs/TFMessage            ``world`` -> ``<lidar>`` per frame,
                                                              ``world`` -> ``<camera>`` per image
==============================  ============================  ===================================

Points are in the LiDAR frame (x forward, y left, z up, REP 103); cameras use the optical frame
(x right, y down, z forward: OpenCV, as ``calib.json``). ``time`` comes from the points' ``t``,
``label`` / ``instance`` from theirs; a column a cloud lacks is written as zeros. Types are those
of ROS 2 Humble (``rosbags.typesys.Stores.ROS2_HUMBLE``). The bag folder is written next to its
final path and renamed onto it when complete: a failure leaves nothing behind. A bag is written
frame by frame (:class:`Ros2BagWriter`): a sequence streams its sweeps into it as they are
rendered.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import NidarError

__all__ = ["BagCamera", "BagFrame", "POINT_FIELDS", "Ros2BagWriter", "write_ros2_bag"]

#: PointCloud2 fields: name -> (points-dict key, numpy dtype, PointField datatype).
POINT_FIELDS: dict[str, tuple[str, str, int]] = {
    "x": ("xyz", "<f4", 7),
    "y": ("xyz", "<f4", 7),
    "z": ("xyz", "<f4", 7),
    "intensity": ("intensity", "<f4", 7),
    "ring": ("ring", "<u2", 4),
    "time": ("t", "<f4", 7),
    "label": ("label", "<u2", 4),
    "instance": ("instance", "<u4", 6),
}
WORLD_FRAME = "world"


@dataclass
class BagCamera:
    """One camera image of a frame.

    Attributes:
        rgb: (H, W, 3) uint8 sRGB image.
        K: (3, 3) intrinsics in pixels (OpenCV convention).
        T_world_cam: (4, 4) camera-to-world pose (OpenCV optical frame).
        stamp_s: the image's time in s.
    """

    rgb: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray
    stamp_s: float


@dataclass
class BagFrame:
    """One LiDAR sweep and the camera images taken with it.

    Attributes:
        stamp_s: time of the sweep's start in s (the PointCloud2 stamp).
        T_world_lidar: (4, 4) LiDAR-to-world pose at ``stamp_s``.
        points: points dict (:mod:`nidar_mi.io.points`) with ``xyz`` and ``intensity`` at least.
        cameras: camera id -> its image.
    """

    stamp_s: float
    T_world_lidar: np.ndarray
    points: Mapping[str, np.ndarray]
    cameras: dict[str, BagCamera] = field(default_factory=dict)


def _stamp(typestore, t: float):
    Time = typestore.types["builtin_interfaces/msg/Time"]
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _header(typestore, t: float, frame: str):
    return typestore.types["std_msgs/msg/Header"](stamp=_stamp(typestore, t), frame_id=frame)


def _transform(typestore, t: float, parent: str, child: str, T: np.ndarray):
    from scipy.spatial.transform import Rotation

    ts = typestore.types
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return ts["geometry_msgs/msg/TransformStamped"](
        header=_header(typestore, t, parent),
        child_frame_id=child,
        transform=ts["geometry_msgs/msg/Transform"](
            translation=ts["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            rotation=ts["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
        ),
    )


def _cloud(typestore, frame: BagFrame, lidar: str):
    ts = typestore.types
    pts = frame.points
    xyz = np.asarray(pts["xyz"])
    n = len(xyz)
    record = np.zeros(n, dtype=[(name, spec[1]) for name, spec in POINT_FIELDS.items()])
    for i, axis in enumerate("xyz"):
        record[axis] = xyz[:, i]
    for name, (key, _, _) in POINT_FIELDS.items():
        if name not in "xyz" and key in pts:
            column = np.asarray(pts[key])
            if column.shape != (n,):
                raise NidarError(f"points '{key}' has shape {column.shape}, expected ({n},)")
            record[name] = column
    if not all(np.all(np.isfinite(record[k])) for k in ("x", "y", "z", "intensity", "time")):
        raise NidarError("a point cloud holds non-finite values")
    fields = [
        ts["sensor_msgs/msg/PointField"](
            name=name, offset=record.dtype.fields[name][1], datatype=spec[2], count=1
        )
        for name, spec in POINT_FIELDS.items()
    ]
    return ts["sensor_msgs/msg/PointCloud2"](
        header=_header(typestore, frame.stamp_s, lidar),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=record.dtype.itemsize,
        row_step=record.dtype.itemsize * n,
        data=np.frombuffer(record.tobytes(), dtype=np.uint8),
        is_dense=True,
    )


def _image(typestore, cam: BagCamera, name: str):
    rgb = np.ascontiguousarray(cam.rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(f"camera '{name}': image must be (H, W, 3) uint8, got {rgb.dtype}")
    h, w, _ = rgb.shape
    return typestore.types["sensor_msgs/msg/Image"](
        header=_header(typestore, cam.stamp_s, name),
        height=h,
        width=w,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * w,
        data=rgb.reshape(-1),
    )


def _camera_info(typestore, cam: BagCamera, name: str):
    ts = typestore.types
    K = np.asarray(cam.K, dtype=np.float64)
    P = np.hstack([K, np.zeros((3, 1))])
    h, w, _ = cam.rgb.shape
    return ts["sensor_msgs/msg/CameraInfo"](
        header=_header(typestore, cam.stamp_s, name),
        height=h,
        width=w,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=K.reshape(-1),
        r=np.eye(3).reshape(-1),
        p=P.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=ts["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


class Ros2BagWriter:
    """A ROS 2 bag written frame by frame (topics in the module docstring)::

        with Ros2BagWriter(path, lidar="lidar_top") as bag:
            for frame in frames:
                bag.write(frame)

    The bag grows in a hidden folder beside ``path`` and is renamed onto it when the block ends
    without an exception and at least one frame was written; otherwise (an error, Ctrl-C,
    SIGTERM) the folder is removed and nothing is left behind.

    Args:
        path: the bag folder to create; it must not exist.
        lidar: the LiDAR id (topic prefix and frame id).

    Raises:
        NidarError: ``path`` exists, a frame out of time order, bad arrays, no frame at the
            end, or a write failure.
    """

    def __init__(self, path: str | os.PathLike, lidar: str = "lidar_top"):
        self.path = os.fspath(path)
        self.lidar = lidar
        self.frames = 0
        self._last = -np.inf
        self._writer = None
        self._tmp_root = None
        self._conns: dict[str, object] = {}

    def __enter__(self) -> Ros2BagWriter:
        return self.open()

    def open(self) -> Ros2BagWriter:
        """Start the bag (what entering the ``with`` block does).

        Raises:
            NidarError: ``path`` exists or cannot be written.
        """
        from rosbags.rosbag2 import Writer
        from rosbags.typesys import Stores, get_typestore

        if os.path.exists(self.path):
            raise NidarError(f"{self.path}: exists (a bag is written into a new folder)")
        self._typestore = get_typestore(Stores.ROS2_HUMBLE)
        parent = os.path.dirname(os.path.abspath(self.path))
        try:
            os.makedirs(parent, exist_ok=True)
            name = os.path.basename(self.path)
            self._tmp_root = tempfile.mkdtemp(prefix=f".{name}.partial-", dir=parent)
            self._writer = Writer(os.path.join(self._tmp_root, "bag"), version=8)
            self._writer.open()
        except (OSError, ValueError) as e:
            self._discard()
            raise NidarError(f"{self.path}: cannot write the bag ({e})") from None
        return self

    def _put(self, topic: str, msg, t: float) -> None:
        if topic not in self._conns:
            self._conns[topic] = self._writer.add_connection(
                topic, msg.__msgtype__, typestore=self._typestore
            )
        data = self._typestore.serialize_cdr(msg, msg.__msgtype__)
        self._writer.write(self._conns[topic], int(round(t * 1e9)), data)

    def write(self, frame: BagFrame) -> None:
        """Append one sweep and its camera images (stamps finite, not before the last frame's).

        Raises:
            NidarError: a stamp out of order, bad arrays, or a write failure.
        """
        if not np.isfinite(frame.stamp_s) or frame.stamp_s < self._last:
            raise NidarError("frame stamps must be finite and in time order")
        ts, lidar = self._typestore, self.lidar
        TFMessage = ts.types["tf2_msgs/msg/TFMessage"]
        T = np.asarray(frame.T_world_lidar, dtype=np.float64)
        try:
            tf = _transform(ts, frame.stamp_s, WORLD_FRAME, lidar, T)
            self._put("/tf", TFMessage(transforms=[tf]), frame.stamp_s)
            self._put(f"/{lidar}/points", _cloud(ts, frame, lidar), frame.stamp_s)
            for name, cam in sorted(frame.cameras.items()):
                Tc = np.asarray(cam.T_world_cam, dtype=np.float64)
                tf = _transform(ts, cam.stamp_s, WORLD_FRAME, name, Tc)
                self._put("/tf", TFMessage(transforms=[tf]), cam.stamp_s)
                self._put(f"/{name}/image_raw", _image(ts, cam, name), cam.stamp_s)
                self._put(f"/{name}/camera_info", _camera_info(ts, cam, name), cam.stamp_s)
        except (OSError, ValueError) as e:
            raise NidarError(f"{self.path}: cannot write the bag ({e})") from None
        self._last = frame.stamp_s
        self.frames += 1

    def _discard(self) -> None:
        if self._tmp_root is not None:
            shutil.rmtree(self._tmp_root, ignore_errors=True)
            self._tmp_root = None

    def close(self) -> str:
        """Finish the bag and move it onto ``path`` (nothing is left behind on a failure).

        Returns:
            The bag folder.

        Raises:
            NidarError: no frame was written, or a write failure.
        """
        try:
            writer, self._writer = self._writer, None
            if writer is not None:
                writer.close()
            if not self.frames:
                raise NidarError("a bag needs at least one frame")
            os.replace(os.path.join(self._tmp_root, "bag"), self.path)
        except (OSError, ValueError) as e:
            raise NidarError(f"{self.path}: cannot write the bag ({e})") from None
        finally:
            self._discard()
        return self.path

    def discard(self) -> None:
        """Stop writing and remove the unfinished bag."""
        try:
            writer, self._writer = self._writer, None
            if writer is not None:
                writer.close()
        except (OSError, ValueError):
            pass
        finally:
            self._discard()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.discard()


def write_ros2_bag(
    path: str | os.PathLike, frames: Sequence[BagFrame], lidar: str = "lidar_top"
) -> str:
    """Write a sequence as a ROS 2 bag folder (topics in the module docstring; frame by frame
    through :class:`Ros2BagWriter`).

    Args:
        path: the bag folder to create; it must not exist.
        frames: the sweeps in time order.
        lidar: the LiDAR id (topic prefix and frame id).

    Returns:
        The bag folder.

    Raises:
        NidarError: ``path`` exists, no frames, frames out of time order, bad arrays, or a write
            failure (nothing is left behind).
    """
    path = os.fspath(path)
    if os.path.exists(path):
        raise NidarError(f"{path}: exists (a bag is written into a new folder)")
    if not frames:
        raise NidarError("a bag needs at least one frame")
    stamps = [f.stamp_s for f in frames]
    if any(b < a for a, b in zip(stamps, stamps[1:])) or not np.all(np.isfinite(stamps)):
        raise NidarError("frame stamps must be finite and in time order")
    with Ros2BagWriter(path, lidar=lidar) as bag:
        for frame in frames:
            bag.write(frame)
    return path
