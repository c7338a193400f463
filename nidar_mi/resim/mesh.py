"""Surfaces of a drive from its scans: each scan meshed on its (ring, column) grid, the
frames fused by vertex clustering.

**Per scan** (:func:`scan_mesh`): the returns sit on the sensor's range image; every 2x2 block
of neighbouring cells (rings r, r+1; columns c, c+1) with three or four returns gives one or two
triangles. A triangle is kept when it is seen at an incidence below :data:`MAX_INCIDENCE_DEG`
from its scan's origin (a triangle that bridges a depth discontinuity lies almost along the
rays) and none of its edges is longer than ``EDGE_RATIO`` times the nearest vertex's range plus
:data:`EDGE_PAD_M` (nor :data:`MAX_EDGE_M`). Triangles face their sensor. Unlike a Poisson
surface this keeps thin structures (poles, signs, kerbs) and fills no hole the sensor did not
see across; it measured 0.09-0.1 m Chamfer to held-out scans where screened Poisson (Open3D,
depth 10) measured more (``docs/RESIMULATION.md``).

**Fusion** (:func:`fuse_meshes`): the scans' meshes in world coordinates are merged by vertex
clustering (Rossignac and Borrel, 1993): vertices in the same cube of side ``voxel`` become one
vertex at their mean, triangles whose corners collapse are dropped, and a triangle found in
several scans is kept once. Overlapping scans thus give one surface, shared by every frame that
saw it, whose vertices carry the reflectance (:mod:`.inversion`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .range_image import ScanGrid

__all__ = [
    "Mesh",
    "compact",
    "compact_index",
    "scan_mesh",
    "scan_triangles",
    "fuse_meshes",
    "merge_meshes",
    "crease_vertices",
    "CREASE_DEG",
    "MAX_INCIDENCE_DEG",
    "EDGE_RATIO",
    "EDGE_PAD_M",
    "MAX_EDGE_M",
]

#: Triangles seen more obliquely than this from their scan's origin are dropped, degrees.
MAX_INCIDENCE_DEG = 88.0
#: The same for a triangle that is not level (normal more than LEVEL_DEG from vertical), degrees.
MAX_INCIDENCE_STEEP_DEG = 80.0
LEVEL_DEG = 20.0
#: Longest edge, as a share of the nearest vertex's range (plus :data:`EDGE_PAD_M`).
EDGE_RATIO = 0.15
EDGE_PAD_M = 0.2
#: Longest edge of any triangle, m.
MAX_EDGE_M = 4.0
#: A vertex is on a crease when a triangle around it turns more than this from its normal, deg.
CREASE_DEG = 60.0


@dataclass
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 positions, m.
        faces: (T, 3) int64 vertex indices, counter-clockwise seen from the front.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def transformed(self, T: np.ndarray) -> Mesh:
        """The mesh moved by the (4, 4) transform ``T``."""
        v = self.vertices @ T[:3, :3].T + T[:3, 3]
        return Mesh(v, self.faces)


def _grid_index(grid: ScanGrid, n: int) -> np.ndarray:
    """(rings, columns) index of the return in each cell (the first stored), -1 where none."""
    img = np.full((grid.rings, grid.columns), -1, dtype=np.int64)
    order = np.arange(n)[::-1]  # the first stored return of a cell is written last, and wins
    img[grid.ring[order], grid.column[order]] = order
    return img


def scan_mesh(xyz: np.ndarray, grid: ScanGrid, *, wrap: bool = False) -> Mesh:
    """The mesh of one scan on its range image (module docstring), in the LiDAR frame.

    Args:
        xyz: (N, 3) returns, LiDAR frame, m.
        grid: their (ring, column) cells.
        wrap: join the last column to the first (a full revolution).

    Returns:
        Vertices are the returns themselves (unused ones removed); triangles face the origin.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    return compact(Mesh(xyz, scan_triangles(xyz, grid, wrap=wrap)))


def scan_triangles(xyz: np.ndarray, grid: ScanGrid, *, wrap: bool = False) -> np.ndarray:
    """(T, 3) int64 :func:`scan_mesh`'s triangles as indices of the returns ``xyz`` (N, 3)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    img = _grid_index(grid, len(xyz))
    if wrap:
        img = np.concatenate([img, img[:, :1]], axis=1)
    a, b = img[:-1, :-1].ravel(), img[:-1, 1:].ravel()  # ring r: columns c, c+1
    c, d = img[1:, :-1].ravel(), img[1:, 1:].ravel()  # ring r+1
    tris = np.concatenate(
        [
            np.column_stack([a, c, b])[(a >= 0) & (b >= 0) & (c >= 0)],
            np.column_stack([b, c, d])[(b >= 0) & (c >= 0) & (d >= 0)],
            # a missing corner: the other diagonal's triangle
            np.column_stack([a, c, d])[(a >= 0) & (c >= 0) & (d >= 0) & (b < 0)],
            np.column_stack([a, d, b])[(a >= 0) & (b >= 0) & (d >= 0) & (c < 0)],
        ]
    )
    return tris[_kept(xyz, tris)]


def _kept(xyz: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) bool: triangles that pass the incidence and edge tests; flips the rest to face the
    origin in place."""
    p0, p1, p2 = xyz[tris[:, 0]], xyz[tris[:, 1]], xyz[tris[:, 2]]
    n = np.cross(p1 - p0, p2 - p0)
    area2 = np.linalg.norm(n, axis=1)
    centre = (p0 + p1 + p2) / 3.0
    dist = np.linalg.norm(centre, axis=1)
    cos_inc = np.abs(np.einsum("ij,ij->i", n, centre)) / np.maximum(area2 * dist, 1e-12)
    r_min = np.minimum.reduce([np.linalg.norm(p, axis=1) for p in (p0, p1, p2)])
    edge = np.maximum.reduce(
        [
            np.linalg.norm(p1 - p0, axis=1),
            np.linalg.norm(p2 - p1, axis=1),
            np.linalg.norm(p0 - p2, axis=1),
        ]
    )
    level = np.abs(n[:, 2]) >= np.cos(np.radians(LEVEL_DEG)) * area2  # road-like: up to 88°
    limit = np.where(level, MAX_INCIDENCE_DEG, MAX_INCIDENCE_STEEP_DEG)
    ok = (
        (area2 > 1e-10)
        & (cos_inc >= np.cos(np.radians(limit)))
        & (edge <= np.minimum(EDGE_RATIO * r_min + EDGE_PAD_M, MAX_EDGE_M))
    )
    away = np.einsum("ij,ij->i", n, centre) > 0  # normal points away from the sensor
    tris[away] = tris[away][:, [0, 2, 1]]
    return ok


def compact(mesh: Mesh) -> Mesh:
    """The mesh without unreferenced vertices."""
    return compact_index(mesh)[0]


def compact_index(mesh: Mesh) -> tuple[Mesh, np.ndarray]:
    """:func:`compact` and the (V',) indices of the vertices it kept, in their order."""
    used = np.unique(mesh.faces)
    remap = np.full(len(mesh.vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.vertices[used], remap[mesh.faces]), used


def merge_meshes(meshes: list[Mesh]) -> Mesh:
    """The meshes side by side in one (no vertex shared, every triangle kept)."""
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]),
    )


def fuse_meshes(meshes: list[Mesh], voxel: float) -> Mesh:
    """One mesh from several (world coordinates) by vertex clustering at ``voxel`` m.

    Returns:
        Vertices at the mean of their cluster; no degenerate or repeated triangle (a triangle
        and its reverse count as one; the first one's orientation is kept).
    """
    merged = merge_meshes(meshes)
    verts, faces = merged.vertices, merged.faces
    if len(verts) == 0:
        return merged
    keys = np.floor((verts - verts.min(axis=0)) / voxel).astype(np.int64)
    if keys.max(initial=0) >= 1 << 21:
        raise ValueError(f"the drive spans more than {(1 << 21) * voxel:g} m at voxel {voxel} m")
    code = (keys[:, 0] << 42) | (keys[:, 1] << 21) | keys[:, 2]
    _, cluster, counts = np.unique(code, return_inverse=True, return_counts=True)
    centre = np.zeros((len(counts), 3))
    np.add.at(centre, cluster, verts)
    centre /= counts[:, None]
    f = cluster[faces]
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    f = f[ok]
    s = np.sort(f, axis=1)
    order = np.lexsort((s[:, 2], s[:, 1], s[:, 0]))
    s = s[order]
    new = np.concatenate([[True], np.any(s[1:] != s[:-1], axis=1)])
    return compact(Mesh(centre, f[np.sort(order[new])]))


def crease_vertices(mesh: Mesh, angle_deg: float = CREASE_DEG) -> np.ndarray:
    """(V,) bool: the vertices where the surface folds (a wall meets the road, a box's edge) or
    is rough: some triangle around the vertex has its normal more than ``angle_deg`` from the
    vertex's normal. The vertex normal is the principal axis of the area-weighted normals of its
    triangles (the eigenvector of ``Σ a·n·nᵀ`` with the largest eigenvalue), so a triangle's
    winding does not matter. A vertex of no triangle is not on a crease.

    At such a vertex one reflectance and one interpolated normal stand for two surfaces: a
    return there reads the wall's ρ at the road's incidence, or the other way round.
    """
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    crease = np.zeros(len(v), bool)
    if len(f) == 0:
        return crease
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length = 2 · area
    outer = (n[:, :, None] * n[:, None, :]).reshape(-1, 9)
    outer /= np.maximum(np.linalg.norm(n, axis=1), 1e-12)[:, None]
    corner = f.T.ravel()  # each triangle once per corner
    tensor = np.stack(
        [np.bincount(corner, np.tile(outer[:, j], 3), len(v)) for j in range(9)], axis=1
    ).reshape(-1, 3, 3)
    axis = np.linalg.eigh(tensor)[1][:, :, 2]  # eigenvalues ascending: the last is the largest
    unit = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    worst = np.ones(len(v))
    for k in range(3):
        np.minimum.at(worst, f[:, k], np.abs(np.einsum("ti,ti->t", unit, axis[f[:, k]])))
    return worst < np.cos(np.radians(angle_deg))
