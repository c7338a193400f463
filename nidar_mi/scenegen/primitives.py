"""Plain records of a generated scene: shapes, light and the sensor rig.

Everything is in the world frame (z up, metres, degrees for angles). Every shape carries the
name of a library material (:func:`nidar_mi.materials.list_materials`). The records are frozen
and hold only Python floats, strings and tuples, so two layouts compare equal exactly when
they would write the same XML.

Shapes map onto Mitsuba's built-in shapes:

============  ===========================================================================
record        Mitsuba shape and pose
============  ===========================================================================
Patch         ``rectangle``: centre, half extents, yaw about z, normal +z (ground, paint)
Panel         ``rectangle`` standing vertically, its normal at azimuth ``heading_deg``
Block         ``cube``: centre, half extents, yaw about z
Cylinder      ``cylinder`` between two points
Sphere        ``sphere``
============  ===========================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Patch",
    "Panel",
    "Block",
    "Cylinder",
    "Sphere",
    "Shape",
    "Sun",
    "Sky",
    "Rig",
    "Layout",
    "rotate_z",
]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Patch:
    """A horizontal rectangle (normal +z).

    Attributes:
        id: unique shape id.
        material: library material name.
        center: (x, y, z) in m.
        half_size: (half length along its x, half width along its y) in m.
        yaw_deg: rotation about z, degrees, counter-clockwise.
    """

    id: str
    material: str
    center: Vec3
    half_size: tuple[float, float]
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Panel:
    """A vertical rectangle (a window, a sign face) seen from the side its normal points to.

    Attributes:
        id: unique shape id.
        material: library material name.
        center: (x, y, z) in m.
        half_size: (half width, half height) in m.
        heading_deg: azimuth of the normal, degrees from +x, counter-clockwise.
    """

    id: str
    material: str
    center: Vec3
    half_size: tuple[float, float]
    heading_deg: float


@dataclass(frozen=True)
class Block:
    """A box.

    Attributes:
        id: unique shape id.
        material: library material name.
        center: (x, y, z) in m.
        half_size: (x, y, z) half extents in m, before the yaw.
        yaw_deg: rotation about z, degrees.
    """

    id: str
    material: str
    center: Vec3
    half_size: Vec3
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Cylinder:
    """A capless cylinder (trunks, poles, wheels, bollards).

    Attributes:
        id: unique shape id.
        material: library material name.
        p0, p1: axis end points in m.
        radius: m.
    """

    id: str
    material: str
    p0: Vec3
    p1: Vec3
    radius: float


@dataclass(frozen=True)
class Sphere:
    """A sphere (tree crowns, bushes, boulders).

    Attributes:
        id: unique shape id.
        material: library material name.
        center: (x, y, z) in m.
        radius: m.
    """

    id: str
    material: str
    center: Vec3
    radius: float


Shape = Patch | Panel | Block | Cylinder | Sphere


@dataclass(frozen=True)
class Sun:
    """The sun: ASTM G-173 direct irradiance times ``scale`` (:func:`~nidar_mi.illumination.sun_irradiance`).

    Attributes:
        elevation_deg: above the horizon.
        azimuth_deg: direction *towards* the sun, degrees from +x, counter-clockwise.
        scale: irradiance scale (haze, season).
    """

    elevation_deg: float
    azimuth_deg: float
    scale: float

    @property
    def direction(self) -> np.ndarray:
        """(3,) unit vector of the light's travel (from the sun to the ground)."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        return -np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


@dataclass(frozen=True)
class Sky:
    """A uniform sky: ASTM G-173 diffuse radiance times ``scale`` (:func:`~nidar_mi.illumination.sky_radiance`)."""

    scale: float


@dataclass(frozen=True)
class Rig:
    """A roof rig: one LiDAR and one forward camera.

    Attributes:
        lidar_preset: beam pattern preset (``hdl64e`` or ``vlp16``).
        lidar_position: (x, y, z) of the LiDAR origin, m.
        lidar_yaw_deg: heading of the LiDAR's +x axis.
        camera_position: (x, y, z) of the camera centre, m.
        camera_yaw_deg: heading of the optical axis.
        camera_pitch_deg: elevation of the optical axis (negative looks down).
        camera_fov_deg: horizontal field of view (Mitsuba ``fov`` with ``fov_axis="x"``).
    """

    lidar_preset: str
    lidar_position: Vec3
    lidar_yaw_deg: float
    camera_position: Vec3
    camera_yaw_deg: float
    camera_pitch_deg: float
    camera_fov_deg: float

    @property
    def camera_direction(self) -> np.ndarray:
        """(3,) unit optical axis in the world frame."""
        yaw, pitch = math.radians(self.camera_yaw_deg), math.radians(self.camera_pitch_deg)
        return np.array(
            [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)]
        )

    def T_world_lidar(self) -> np.ndarray:
        """(4,4) LiDAR-to-world (LiDAR frame: x forward, y left, z up)."""
        T = np.eye(4)
        T[:3, :3] = rotate_z(self.lidar_yaw_deg)
        T[:3, 3] = self.lidar_position
        return T

    def T_world_cam(self) -> np.ndarray:
        """(4,4) camera-to-world in OpenCV axes (x right, y down, z forward)."""
        z = self.camera_direction
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2] = x, y, z
        T[:3, 3] = self.camera_position
        return T

    def T_cam_lidar(self) -> np.ndarray:
        """(4,4) LiDAR frame -> OpenCV camera frame (the extrinsics a dataset stores)."""
        return np.linalg.inv(self.T_world_cam()) @ self.T_world_lidar()


@dataclass(frozen=True)
class Layout:
    """One generated scene.

    Attributes:
        kind: ``urban`` or ``vegetated``.
        shapes: every shape, in writing order (ids unique).
        sun: the sun.
        sky: the sky.
        rig: the sensor rig.
    """

    kind: str
    shapes: tuple[Shape, ...]
    sun: Sun
    sky: Sky
    rig: Rig

    def materials(self) -> list[str]:
        """Sorted names of the library materials the shapes use."""
        return sorted({s.material for s in self.shapes})


def rotate_z(angle_deg: float) -> np.ndarray:
    """(3,3) rotation about +z by ``angle_deg`` (counter-clockwise seen from above)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
