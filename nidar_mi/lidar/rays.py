"""World-space rays of a block of beams: the pose (one, or one per column), beam origins, and the
sub-rays of a diverging beam, built in Dr.Jit.

Every per-frame value enters the kernels as data, never as a literal: a single pose is an opaque
``mi.Transform4f``, per-column poses are arrays gathered by column, the block's first beam index
is an opaque integer. Scanning another frame, pose or block launches the same kernels.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "Poses",
    "BlockRays",
    "jit_float",
    "jit_scalars",
    "static_pose",
    "column_poses",
    "block_rays",
]


def jit_float(values: np.ndarray):
    """A ``mi.Float`` holding ``values`` (float32) in 64-byte aligned memory.

    Dr.Jit maps NumPy memory as it is and compiles unaligned loads for unaligned buffers, so a
    kernel fed arrays of varying alignment is compiled again; aligned inputs keep it cached.
    """
    import mitsuba as mi

    a = np.asarray(values, dtype=np.float32).ravel()  # float32 input: bits copied as they are
    buf = np.empty(a.size + 16, dtype=np.float32)
    off = (-buf.ctypes.data % 64) // 4
    out = buf[off : off + a.size]
    out[:] = a
    return mi.Float(out)


_index_cache: dict[tuple[str, int], Any] = {}


def jit_scalars(values: np.ndarray) -> list:
    """Width-1 ``mi.Float`` values of a (k,) float32 array, uploaded in one copy.

    Each is a gather from that buffer at an evaluated index (a literal index would make Dr.Jit
    copy each element eagerly, one transfer each); the caller evaluates them together (one
    width-1 kernel), so that the kernels using them read evaluated scalars: data, not literals,
    and other values launch the same kernels. The bits are kept (a float32 view of integers
    reads back unchanged through ``dr.reinterpret_array``).
    """
    import drjit as dr
    import mitsuba as mi

    buf = jit_float(values)
    out = []
    for i in range(len(values)):
        key = (mi.variant(), i)
        if key not in _index_cache:
            _index_cache[key] = mi.UInt32(np.array([i], dtype=np.uint32))
            dr.eval(_index_cache[key])
        out.append(dr.gather(mi.Float, buf, _index_cache[key]))
    return out


class Poses(NamedTuple):
    """The LiDAR's world pose for a sweep: one opaque transform, or one per column.

    Attributes:
        transform: ``mi.Transform4f`` (opaque) when the pose is the same for every column.
        rows: 12 ``mi.Float`` arrays of length C (row-major 3×4 ``[R | t]`` per column), or None.
    """

    transform: Any
    rows: Any


class BlockRays(NamedTuple):
    """The rays of one block of beams (``n`` beams × ``N`` sub-rays, sub-ray-major per beam).

    Attributes:
        ray: ``mi.Ray3f`` world-space rays, unit directions.
        axis: ``mi.Vector3f`` world-space beam axis of each ray (the ray itself when N = 1).
        weight: ``mi.Float`` footprint weight of each sub-ray (1 when N = 1).
    """

    ray: Any
    axis: Any
    weight: Any


def static_pose(entries) -> Poses:
    """A single pose from its 16 row-major matrix entries (width-1 ``mi.Float``, e.g. of
    :func:`jit_scalars`)."""
    import mitsuba as mi

    return Poses(mi.Transform4f(mi.Matrix4f(*entries)), None)


def column_poses(poses: np.ndarray) -> Poses:
    """Per-column poses from a (C, 4, 4) float64 array (world pose at each column's time)."""
    import drjit as dr

    p = np.asarray(poses, dtype=np.float64).reshape(-1, 16)[:, :12]
    rows = [jit_float(p[:, i]) for i in range(12)]
    dr.eval(rows)
    return Poses(None, rows)


def _apply(poses: Poses, column, p_local, d_local):
    """World origins and directions: ``T · p`` and ``normalize(R · d)`` per ray."""
    import drjit as dr
    import mitsuba as mi

    if poses.transform is not None:
        T = poses.transform
        return T @ p_local, dr.normalize(T @ d_local)
    m = [dr.gather(mi.Float, r, column) for r in poses.rows]

    def rot(v):
        return mi.Vector3f(
            m[0] * v.x + m[1] * v.y + m[2] * v.z,
            m[4] * v.x + m[5] * v.y + m[6] * v.z,
            m[8] * v.x + m[9] * v.y + m[10] * v.z,
        )

    o = rot(p_local) + mi.Vector3f(m[3], m[7], m[11])
    return mi.Point3f(o), dr.normalize(rot(d_local))


def block_rays(
    poses: Poses,
    directions,
    origins,
    *,
    first_beam,
    cols: int,
    subrays: tuple[np.ndarray, np.ndarray] | None = None,
    half_angle=None,
) -> BlockRays:
    """The world rays of a block of beams.

    Args:
        poses: the sweep's pose(s).
        directions: ``mi.Vector3f`` unit beam directions in the LiDAR frame, one per beam.
        origins: ``mi.Point3f`` beam origins in the LiDAR frame (m), or None (all at the origin).
        first_beam: opaque ``mi.UInt32``, flat index of the block's first beam (for the column).
        cols: columns per sweep.
        subrays: ``(offsets (N, 2), weights (N,))`` of :func:`nidar_mi.lidar.footprint.subray_offsets`,
            or None for one ray per beam.
        half_angle: opaque ``mi.Float``, the 1/e² half-angle θ_w in rad (with ``subrays``).

    Returns:
        The rays.
    """
    import drjit as dr
    import mitsuba as mi

    n = dr.width(directions)
    if subrays is None:
        column = None
        if poses.rows is not None:
            column = (dr.arange(mi.UInt32, n) + first_beam) % cols
        p = mi.Point3f(0.0) if origins is None else origins
        o, d = _apply(poses, column, p, directions)
        return BlockRays(mi.Ray3f(o, d), d, mi.Float(1.0))
    offsets, weights = subrays
    count = len(weights)
    idx = dr.arange(mi.UInt32, n * count)
    beam, k = idx // count, idx % count
    d_local = dr.gather(mi.Vector3f, directions, beam)
    p_local = mi.Point3f(0.0) if origins is None else dr.gather(mi.Point3f, origins, beam)
    column = (beam + first_beam) % cols if poses.rows is not None else None
    o, axis = _apply(poses, column, p_local, d_local)
    s, t = mi.coordinate_system(axis)
    ox = dr.gather(mi.Float, jit_float(offsets[:, 0]), k)
    oy = dr.gather(mi.Float, jit_float(offsets[:, 1]), k)
    w = dr.gather(mi.Float, jit_float(weights), k)
    d = dr.normalize(axis + dr.tan(ox * half_angle) * s + dr.tan(oy * half_angle) * t)
    return BlockRays(mi.Ray3f(o, d), axis, w)
