"""Returns that no triangle of their scan holds, kept as small quads ("splats").

The range-image mesh (:mod:`.mesh`) drops a triangle that bridges a depth discontinuity, lies
along the rays or has a long edge, and with it the returns that only such triangles held:
foliage, the edges of objects, far and sparse surfaces (on KITTI drives a tenth of a scan's
returns within 30 m, a quarter to a half past 40 m). Left out, a held-out scan finds nothing
where the real sensor returned. Each such return that lies off the fused mesh (farther than
:data:`OFF_MESH_M` from its vertices: nearer, the mesh holds its surface, and a splat there
would only hide the fitted surface behind one return's reflectance), or near its vertices but
in a hole of it (:func:`passed_by`: its own ray meets no triangle until it has passed the return
by more than :data:`PASS_M` across the surface; a dark car's scattered returns leave too few
neighbours for the range-image mesh, and the few triangles around them cover little of it),
becomes one quad of two
triangles, its cell of the range image (``d·2π/columns`` across, ``d·Δθ`` high, ``Δθ`` the
spacing of its ring's neighbours): facing its ray where its neighbours do not lie on one
plane, else that square's footprint on the plane (:func:`local_normals`), so that a far road
return lies on the road. Neighbouring splats tile the surface as the sensor sampled it. They
are not fused (a splat is smaller than a fusion voxel near the sensor); carving
(:mod:`.carve`) removes those that other frames' rays passed through. They take no part in the
fit: each vertex's ρ is its return inverted through the recovered sensor
(:meth:`Splats.reflectance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh, compact_index, merge_meshes
from .observations import ON_SURFACE_M

#: A splat is its cell's footprint on its surface up to this incidence; past it, the footprint
#: is no longer along the ray's trace than at this incidence, deg.
MAX_TILT_DEG = 80.0
#: Neighbours of a return that give its surface's normal, and the largest share of their
#: spread across the plane (the smallest eigenvalue over the sum) that still counts as one.
NEIGHBOURS = 8
PLANAR_SHARE = 0.02
#: A return this close to a vertex of the fused mesh gets no splat (the mesh holds it), m.
OFF_MESH_M = 0.3
#: ... unless its ray passes the mesh by more than this, across the surface, m: farther than
#: step 5 takes a return to lie on a surface.
PASS_M = ON_SURFACE_M

__all__ = [
    "OFF_MESH_M",
    "PASS_M",
    "passed_by",
    "Splats",
    "local_normals",
    "ring_spacing_rad",
    "unmeshed_returns",
    "scan_splats",
]


@dataclass(frozen=True)
class Splats:
    """Splats of a drive's training returns, and the return each vertex stands for.

    Attributes:
        mesh: 4 vertices and 2 triangles per splat (:func:`scan_splats`; carving may leave one
            of the two), world coordinates, m.
        ring, range_m, intensity, cos: (V,) the vertex's return: its laser, its range (m), its
            intensity on the sensor's scale, and ``|cos θ|`` of its ray on the splat.
    """

    mesh: Mesh
    ring: np.ndarray
    range_m: np.ndarray
    intensity: np.ndarray
    cos: np.ndarray

    _FIELDS = ("ring", "range_m", "intensity", "cos")

    @staticmethod
    def join(parts: list[Splats]) -> Splats:
        """The splats of several frames side by side (none: an empty set)."""
        if not parts:
            empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
            return Splats(empty, np.zeros(0, np.int64), *np.zeros((3, 0)))
        cat = {f: np.concatenate([getattr(p, f) for p in parts]) for f in Splats._FIELDS}
        return Splats(merge_meshes([p.mesh for p in parts]), **cat)

    def kept(self, faces: np.ndarray) -> Splats:
        """The splats with only the triangles ``faces`` (T,) bool, unused vertices removed."""
        mesh, used = compact_index(Mesh(self.mesh.vertices, self.mesh.faces[faces]))
        return Splats(mesh, **{f: getattr(self, f)[used] for f in Splats._FIELDS})

    def reflectance(self, sensor) -> np.ndarray:
        """(V,) each vertex's ρ from its own return through the recovered ``sensor``
        (:meth:`.inversion.SensorFit.reflectance_of`)."""
        return sensor.reflectance_of(self.intensity, self.ring, self.range_m, self.cos)


def passed_by(range_m: np.ndarray, t: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """(N,) bool: returns at ``range_m`` (N,) whose rays first meet a triangle at ``t`` (inf:
    none) with ``|cos θ|`` ``cos`` more than :data:`PASS_M` beyond them, across the surface
    (:func:`.carve.across_gap`: a grazing road a centimetre lower is no hole), or meet none."""
    from .carve import across_gap

    with np.errstate(invalid="ignore"):
        return ~np.isfinite(t) | (-across_gap(range_m, t, cos) > PASS_M)


def ring_spacing_rad(elevation_deg: np.ndarray) -> np.ndarray:
    """(R,) each ring's elevation spacing, radians: half the distance between its two
    neighbours (one neighbour at the first and last ring).

    Args:
        elevation_deg: (R,) ring elevations, degrees, R >= 2.
    """
    e = np.radians(np.asarray(elevation_deg, dtype=np.float64))
    if len(e) < 2:
        raise ValueError("ring_spacing_rad: at least two rings are needed")
    padded = np.concatenate([[2 * e[0] - e[1]], e, [2 * e[-1] - e[-2]]])
    return np.abs(padded[2:] - padded[:-2]) / 2.0


def unmeshed_returns(n: int, triangles: np.ndarray) -> np.ndarray:
    """(n,) bool: the returns that are a corner of none of ``triangles`` (T, 3)."""
    used = np.zeros(n, bool)
    used[np.asarray(triangles, dtype=np.int64).ravel()] = True
    return ~used


def scan_splats(
    xyz: np.ndarray,
    ring: np.ndarray,
    columns: int,
    spacing_rad: np.ndarray,
    normals: np.ndarray | None = None,
) -> Mesh:
    """The splats of some returns of one scan, in its LiDAR frame (module docstring).

    Args:
        xyz: (N, 3) the returns, LiDAR frame, m (none at the origin).
        ring: (N,) each return's ring; columns: columns per revolution.
        spacing_rad: (R,) each ring's elevation spacing (:func:`ring_spacing_rad`).
        normals: (N, 3) unit normals of the surfaces the returns lie on, NaN where unknown, or
            None: a splat with a normal is its cell's square projected along the ray onto that
            plane (its footprint), shrunk in that plane where the ray meets it more obliquely
            than :data:`MAX_TILT_DEG`; the others face their ray.

    Returns:
        4 N vertices, 2 N triangles, counter-clockwise seen from the sensor.
    """
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    d = np.linalg.norm(p, axis=1)
    if np.any(d <= 0):
        raise ValueError("scan_splats: a return at the sensor's origin")
    u = p / d[:, None]
    across = np.cross(np.array([0.0, 0.0, 1.0]), u)
    norm = np.linalg.norm(across, axis=1)
    across = np.where(norm[:, None] > 1e-9, across / np.maximum(norm, 1e-12)[:, None], [1, 0, 0])
    up = np.cross(u, across)
    half_w = (d * np.pi / columns)[:, None] * across
    half_h = (d * np.asarray(spacing_rad)[np.asarray(ring)] / 2.0)[:, None] * up
    offsets = np.stack([-half_w - half_h, half_w - half_h, half_w + half_h, -half_w + half_h], 1)
    if normals is not None:
        n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        known = np.all(np.isfinite(n), axis=1)
        n = np.where(known[:, None], n, u)  # unknown: the plane facing the ray
        un = np.einsum("ij,ij->i", u, n)
        un = np.where(np.abs(un) < 1e-6, 1e-6, un)
        along = np.einsum("nkj,nj->nk", offsets, n) / un[:, None]
        offsets = offsets - along[:, :, None] * u[:, None, :]  # along the ray onto the plane
        # past MAX_TILT_DEG, the footprint's length along the ray's trace on the plane (t)
        # shrinks to what it is at MAX_TILT_DEG; its width stays, the splat in the plane
        t = u - un[:, None] * n
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
        shrink = np.minimum(1.0, np.abs(un) / np.cos(np.radians(MAX_TILT_DEG)))
        on_t = np.einsum("nkj,nj->nk", offsets, t)
        offsets = offsets - ((1.0 - shrink)[:, None] * on_t)[:, :, None] * t[:, None, :]
    corners = (p[:, None, :] + offsets).reshape(-1, 3)
    base = 4 * np.arange(len(p))[:, None]
    # seen from the sensor (looking along u, `across` to the left, `up` up), 0-1-2-3 turn
    # clockwise; the reverse winding faces the sensor
    faces = np.concatenate([base + [0, 2, 1], base + [0, 3, 2]])
    return Mesh(corners, faces.astype(np.int64))


def local_normals(xyz: np.ndarray, which: np.ndarray, *, k: int = NEIGHBOURS) -> np.ndarray:
    """(M, 3) the normals of the surfaces that the returns ``xyz[which]`` lie on: the least
    principal axis of each one's ``k`` nearest returns of its scan (itself among them), NaN
    where they do not lie on a plane (the smallest eigenvalue more than
    :data:`PLANAR_SHARE` of the three: foliage, an edge) or spread wider than the range-image
    mesh's longest edge (:data:`.mesh.EDGE_RATIO` · d + :data:`.mesh.EDGE_PAD_M`).

    Args:
        xyz: (N, 3) one scan's returns, LiDAR frame, m; which: (M,) indices into them.
    """
    from scipy.spatial import cKDTree

    from .mesh import EDGE_PAD_M, EDGE_RATIO

    xyz = np.asarray(xyz, dtype=np.float64)
    q = xyz[np.asarray(which, dtype=np.int64)]
    out = np.full((len(q), 3), np.nan)
    if len(q) == 0 or len(xyz) < k:
        return out
    dist, idx = cKDTree(xyz).query(q, k=k)
    nb = xyz[idx] - xyz[idx].mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))  # ascending
    near = dist[:, -1] <= EDGE_RATIO * np.linalg.norm(q, axis=1) + EDGE_PAD_M
    flat = values[:, 0] <= PLANAR_SHARE * np.maximum(values.sum(axis=1), 1e-18)
    ok = near & flat
    out[ok] = vectors[ok, :, 0]
    return out
