"""Surfaces that moved, at a held-out frame's time: what the training frame nearest in time
saw and the static surfaces lack, moved on as far as it went by then.

The reconstructed surfaces are static (:mod:`.build`): a vehicle that moved during the drive is
left out (:mod:`.transient`) or kept where it stood at the drive's end. A held-out frame inside
the drive sees it where it was *then*. The training frame nearest in time (ties: the earlier
one) saw it nearly there, so its returns that the static surfaces do not explain are put back,
for that held-out frame only, as a mesh of their own (:func:`moving_surfaces`). A return is
explained when its ray, cast into the static surfaces, ends on them where it was measured: the
gap across the surface ``|t - d| · max(|cos θ|, 0.05)`` at most
:data:`~.observations.ON_SURFACE_M`, the rule that makes a return an intensity sample of the
inversion. The moving mesh is that frame's range-image mesh (:func:`.mesh.scan_triangles`) on
the unexplained returns (a triangle whose three corners are unexplained), in world coordinates.

Each of its objects (:func:`object_labels`) then moves at constant velocity: its translation to
where a second training frame saw the surfaces that moved (:func:`partner_frame`: the nearest
one on the held-out frame's other side, or, past the drive's ends, the one before the nearest)
is found by ICP (:func:`track_shifts`) and scaled to the held-out frame's time (frame indices
as time: a constant scan rate). An object not found again stays where it was seen (the
zero-order model).

Its reflectance is each vertex's own return inverted through the recovered sensor
(:func:`moving_rho`): the sensor reports ``max(G_l · ρ · cos θ · r(d) - b, 0)``
(:mod:`.inversion`), so ``ρ = (y + b) / (G_l · r(d) · cos θ)`` (no lower than the sensor
detects: :meth:`.inversion.SensorFit.reflectance_of`), with ``cos θ`` taken on the
vertex normal Mitsuba computes for the mesh (the normal the renderer shades the vertex with:
re-scanned from where it was measured, the vertex gives back its return's intensity). Where
the second frame that times the motion saw it too (a return of that frame within
:data:`~.observations.ON_SURFACE_M` of the vertex moved on to its time), the vertex takes the
mean of the two returns' ρ, each inverted on the same normal (:func:`moving_rho`).
Casting each return into the mesh, as the inversion's samples are cast, would lose about a
quarter of them: a ray through a mesh's vertex may pass between its triangles.

Nothing is added where nothing moved.

Where an object went, the static surfaces keep the layers the training frames saw of it as it
passed, wherever no later training ray passed through them: an oncoming car seen from beside
leaves a trail of its flanks, each hidden from the later training views behind the car itself,
and seen again from the held-out pose once the car has moved on. The same object, moved along
its track to a training frame's time (its own frame's included: that copy too is left behind once
it moves on), lies on those layers; they are hidden for that held-out frame
(:func:`trail_faces`), and the returns of its frame that they explained join its moving surfaces
(:func:`surfaces_of`, :func:`carried_velocity`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beam_rays import Rays
from .mesh import Mesh, scan_triangles
from .observations import ON_SURFACE_M

#: Tracking an object between two frames (:func:`track_shifts`): its fewest vertices, the
#: share of them that must land within TRACK_INLIER_M (m) of the other frame's, and the
#: fastest motion tracked per frame step, m (3 m at 10 Hz: 108 km/h).
TRACK_MIN_VERTICES = 20
#: Surfaces that moved closer than this belong to one object (:func:`object_labels`), m; each
#: object's translation starts from no motion and the TRACK_STARTS nearest objects of the
#: other frame.
OBJECT_GAP_M = 0.5
TRACK_STARTS = 8
TRACK_MIN_SHARE = 0.5
TRACK_INLIER_M = 0.2
MAX_STEP_M = 3.0
#: A tracked object's trail (:func:`trail_faces`): a static surface within TRAIL_M (m) of where
#: the object stood at a training frame's time, facing the same way (|cos| of the normals
#: at least TRAIL_COS), is the object left there; only frames within TRAIL_FRAMES of the frame it
#: comes from are followed (constant velocity holds over a short time).
TRAIL_M = 0.15
TRAIL_COS = 0.7
TRAIL_FRAMES = 5
#: Trail points looked at per static vertex (the nearest).
TRAIL_NEIGHBOURS = 8

__all__ = [
    "MovingSurfaces",
    "nearest_frame",
    "partner_frame",
    "object_labels",
    "OBJECT_GAP_M",
    "track_shifts",
    "unexplained_returns",
    "moving_surfaces",
    "moving_rho",
    "trail_faces",
    "surfaces_of",
    "carried_velocity",
    "vertex_normals",
]


@dataclass(frozen=True)
class MovingSurfaces:
    """The moving surfaces put back for one held-out frame.

    Attributes:
        frame: the index of the training frame they come from.
        mesh: the mesh, world coordinates (m); empty when the frame saw nothing moving.
        returns: (V,) int64, each vertex's return in that frame's scan.
    """

    frame: int
    mesh: Mesh
    returns: np.ndarray


def nearest_frame(k: int, train) -> int:
    """The training frame index nearest to frame index ``k`` in time (ties: the earlier)."""
    train = list(train)
    if not train:
        raise ValueError("nearest_frame: no training frame")
    return min(train, key=lambda j: (abs(j - k), j))


def unexplained_returns(t: np.ndarray, cos: np.ndarray, range_m: np.ndarray) -> np.ndarray:
    """(N,) bool: returns that the static surfaces do not explain (module docstring).

    Args:
        t: (N,) each return's ray's first hit on the static surfaces, m (inf: none);
        cos: (N,) ``|cos θ|`` there; range_m: (N,) the measured range along the ray, m.
    """
    from .carve import across_gap

    return ~(np.isfinite(t) & (np.abs(across_gap(range_m, t, cos)) <= ON_SURFACE_M))


def moving_surfaces(xyz: np.ndarray, grid, rays: Rays, static_scene, frame: int, *, wrap: bool):
    """``(moving, hit)``: the :class:`MovingSurfaces` of one training frame and (N,) the static
    triangle each of its returns ends on (-1: none, or it does not explain the return).

    Args:
        xyz: (N, 3) the frame's returns, LiDAR frame, m; grid: their cells
            (:class:`.range_image.ScanGrid`).
        rays: the returns' rays in world coordinates (:func:`.beam_rays.return_rays`), in the
            order of ``xyz``.
        static_scene: the static surfaces (a ``mi.Scene``).
        frame: the frame's index; wrap: its scans are full revolutions.
    """
    from .carve import hit_depths

    t, prim, cos = hit_depths(static_scene, rays)
    free = unexplained_returns(t, cos, rays.range_m)
    hit = np.where(free, -1, prim)
    return surfaces_of(xyz, grid, rays, free, frame, wrap=wrap), hit


def surfaces_of(xyz: np.ndarray, grid, rays: Rays, free: np.ndarray, frame: int, *, wrap: bool):
    """The :class:`MovingSurfaces` of the returns ``free`` ((N,) bool) of one training frame:
    its range-image triangles whose three corners are free (arguments: :func:`moving_surfaces`)."""
    tris = scan_triangles(xyz, grid, wrap=wrap)
    tris = tris[free[tris].all(axis=1)] if len(tris) else tris.reshape(0, 3)
    used = np.unique(tris)
    remap = np.full(len(xyz), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    world = rays.origin[used] + rays.direction[used] * rays.range_m[used, None]
    return MovingSurfaces(frame, Mesh(world, remap[tris]), used.astype(np.int64))


def moving_rho(
    moving: MovingSurfaces, rays: Rays, intensity: np.ndarray, sensor, load_scene, partner=None
) -> np.ndarray:
    """(V,) the moving vertices' ρ from their own returns (module docstring), in
    [0, RHO_MAX]; with ``partner``, averaged with the second frame's return on the same surface.

    Args:
        moving: the surfaces; rays: the frame's return rays (world), in the order of its scan;
        intensity: (N,) the frame's measured intensities; sensor: the recovered
            :class:`.inversion.SensorFit` (gains, range response, offset);
        load_scene: ``load_scene(mesh) -> mi.Scene`` of a mesh alone
            (:func:`.build.scratch_scene`), whose vertex normals the renderer shades with.
        partner: ``(rays2, intensity2, shift)`` or None: the return rays (world) and (N2,)
            intensities of the frame that times the motion (:func:`partner_frame`) and (V, 3)
            each vertex's motion from this frame to that one, m. A vertex moved on by its
            shift with a return of that frame within :data:`ON_SURFACE_M` takes the mean of
            its own ρ and that return's, inverted on the same vertex normal: the surface seen
            twice, from two poses and most often by two lasers.
    """
    import mitsuba as mi

    from .surfaces import SHAPE_ID

    idx = moving.returns
    if len(moving.mesh.faces) == 0:
        return np.zeros(len(idx))
    params = mi.traverse(load_scene(moving.mesh))
    normals = np.asarray(params[f"{SHAPE_ID}.vertex_normals"].numpy(), np.float64).reshape(-1, 3)
    cos = np.abs(np.einsum("ij,ij->i", normals, rays.direction[idx]))
    y = np.asarray(intensity, np.float64)[idx]
    rho = sensor.reflectance_of(y, rays.ring[idx], rays.range_m[idx], cos)
    if partner is None or not len(partner[0].range_m):
        return rho
    from scipy.spatial import cKDTree

    rays2, intensity2, shift = partner
    seen = rays2.origin + rays2.direction * rays2.range_m[:, None]
    gap, near = cKDTree(seen).query(moving.mesh.vertices + shift)
    twice = gap <= ON_SURFACE_M
    n = near[twice]
    cos2 = np.abs(np.einsum("ij,ij->i", normals[twice], rays2.direction[n]))
    y2 = np.asarray(intensity2, np.float64)[n]
    rho2 = sensor.reflectance_of(y2, rays2.ring[n], rays2.range_m[n], cos2)
    rho[twice] = 0.5 * (rho[twice] + rho2)
    return rho


def partner_frame(k: int, j: int, train) -> int | None:
    """The second training frame that times the motion seen in frame ``j`` (the nearest to
    held-out frame ``k``): the nearest one on ``k``'s other side when ``k`` lies between
    training frames, else the nearest one on ``j``'s side away from ``k`` (the two before
    ``k`` past the drive's end); None when there is none."""
    train = [t for t in train if t != j]
    side = [t for t in train if (t - k) * (j - k) < 0] if j != k else []
    if not side:
        side = [t for t in train if (t - j) * (k - j) < 0]
    return min(side, key=lambda t: (abs(t - j), t)) if side else None


def object_labels(mesh: Mesh, gap_m: float = OBJECT_GAP_M) -> np.ndarray:
    """(V,) int: each vertex's object: the connected components of the mesh's triangles joined
    wherever two vertices lie within ``gap_m`` (a vehicle's surfaces come in many pieces)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(mesh.vertices)
    f = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    near = cKDTree(mesh.vertices).query_pairs(gap_m, output_type="ndarray") if n else []
    near = np.asarray(near, dtype=np.int64).reshape(-1, 2)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2], near[:, 0]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0], near[:, 1]])
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def track_shifts(moving: Mesh, target: Mesh, max_shift_m: float) -> np.ndarray:
    """(V,) 3-vectors: how far each object of ``moving`` went to be seen as ``target`` (the
    surfaces that moved, as the partner frame saw them), 0 where it is not found.

    Per object (:func:`object_labels`, at least :data:`TRACK_MIN_VERTICES` vertices), a
    translation, started at no motion and at the :data:`TRACK_STARTS` objects of ``target``
    nearest to it within ``max_shift_m`` (centroid to centroid), refined by point-to-point ICP (the median
    offset to the nearest target vertex within a shrinking radius, Besl and McKay, 1992,
    translation only); kept when at least :data:`TRACK_MIN_SHARE` of its vertices end within
    :data:`TRACK_INLIER_M` of a target vertex (the best start), and no farther than
    ``max_shift_m``.
    """
    from scipy.spatial import cKDTree

    shifts = np.zeros((len(moving.vertices), 3))
    if len(target.vertices) == 0 or len(moving.vertices) == 0:
        return shifts
    tree = cKDTree(target.vertices)
    t_lab = object_labels(target)
    t_centre = np.stack([np.bincount(t_lab, target.vertices[:, i]) for i in range(3)], 1)
    t_centre /= np.bincount(t_lab)[:, None]
    labels = object_labels(moving)
    for obj in np.flatnonzero(np.bincount(labels) >= TRACK_MIN_VERTICES):
        idx = np.flatnonzero(labels == obj)
        p = moving.vertices[idx]
        starts = t_centre - p.mean(axis=0)
        far = np.linalg.norm(starts, axis=1)
        near = np.argsort(far)[:TRACK_STARTS]
        starts = [np.zeros(3), *starts[near[far[near] <= max_shift_m]]]
        best, share = None, TRACK_MIN_SHARE
        for start in starts:
            s = _icp_translation(p, target.vertices, tree, start)
            inside = np.mean(
                tree.query(p + s, distance_upper_bound=TRACK_INLIER_M)[0] <= TRACK_INLIER_M
            )
            if inside >= share and np.linalg.norm(s) <= max_shift_m:
                best, share = s, inside
        if best is not None:
            shifts[idx] = best
    return shifts


def _icp_translation(p: np.ndarray, q: np.ndarray, tree, start: np.ndarray) -> np.ndarray:
    """The translation moving points ``p`` onto points ``q`` (``tree`` over them), from
    ``start``: the median offset to the nearest point, within radii shrinking to 0.2 m."""
    s = np.asarray(start, dtype=np.float64).copy()
    for radius in (1.0, 0.6, 0.4, 0.3, 0.2, 0.2, 0.2):
        d, i = tree.query(p + s, distance_upper_bound=radius)
        ok = np.isfinite(d)
        if ok.sum() < 3:
            break
        s += np.median(q[i[ok]] - (p[ok] + s), axis=0)
    return s


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """(V, 3) unit vertex normals, the area-weighted mean of the adjacent triangles' (zero where
    no triangle uses the vertex)."""
    v, f = mesh.vertices, np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    face = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    out = np.zeros_like(v, dtype=np.float64)
    for c in range(3):
        np.add.at(out, f[:, c], face)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def trail_faces(
    static: Mesh, moving: Mesh, velocity: np.ndarray, steps, at: float, static_normals=None
) -> np.ndarray:
    """(F,) bool: the static triangles that are a tracked object's trail (module docstring).

    Args:
        static: the static surfaces (world, m); moving: the moving surfaces as their frame saw
            them (world, m); velocity: (V, 3) each moving vertex's motion per frame step, m
            (0: not tracked); steps: the training frames' times, in frame steps from the moving
            surfaces' frame (0: that frame's own); at: the held-out frame's, likewise;
            static_normals: (V, 3) :func:`vertex_normals` of ``static`` when the caller keeps
            them (a drive's surfaces are scored against several held-out frames).

    A static vertex is on the trail when, at one of ``steps``, a tracked moving vertex stands
    within :data:`TRAIL_M` of it with a normal within :data:`TRAIL_COS` of its own, and no
    tracked vertex stands within :data:`TRAIL_M` of it at ``at`` (where the object is then); a
    triangle is on it when its three corners are.
    """
    from scipy.spatial import cKDTree

    faces = np.asarray(static.faces, dtype=np.int64).reshape(-1, 3)
    tracked = np.linalg.norm(velocity, axis=1) > 0
    steps = [s for s in steps if abs(s) <= TRAIL_FRAMES]
    if not tracked.any() or not steps or len(faces) == 0:
        return np.zeros(len(faces), dtype=bool)
    p, u = moving.vertices[tracked], velocity[tracked]
    trail = np.concatenate([p + s * u for s in steps])
    n_trail = np.tile(vertex_normals(moving)[tracked], (len(steps), 1))
    d, idx = cKDTree(trail).query(static.vertices, k=TRAIL_NEIGHBOURS, distance_upper_bound=TRAIL_M)
    near = np.isfinite(d)
    cos = np.zeros(d.shape)
    rows = np.nonzero(near)
    if static_normals is None:
        static_normals = vertex_normals(static)
    cos[rows] = np.abs(np.einsum("ij,ij->i", static_normals[rows[0]], n_trail[idx[rows]]))
    on = (near & (cos >= TRAIL_COS)).any(axis=1)
    now = cKDTree(p + at * u).query(static.vertices, distance_upper_bound=TRAIL_M)[0]
    on &= ~np.isfinite(now)
    return on[faces].all(axis=1)


def carried_velocity(grown: MovingSurfaces, moving: MovingSurfaces, velocity: np.ndarray):
    """(V', 3) the velocity of each vertex of ``grown`` (the surfaces of a frame grown from
    ``moving``'s, the same frame): a vertex's own where ``moving`` has its return, else that of
    the nearest tracked vertex of ``moving`` within :data:`OBJECT_GAP_M` (its object's), else 0."""
    from scipy.spatial import cKDTree

    out = np.zeros((len(grown.returns), 3))
    tracked = np.linalg.norm(velocity, axis=1) > 0
    if not tracked.any() or len(grown.returns) == 0:
        return out
    d, i = cKDTree(moving.mesh.vertices[tracked]).query(
        grown.mesh.vertices, distance_upper_bound=OBJECT_GAP_M
    )
    near = np.isfinite(d)
    out[near] = velocity[tracked][i[near]]
    pos = np.searchsorted(moving.returns, grown.returns)
    own = (pos < len(moving.returns)) & (
        moving.returns[np.minimum(pos, len(moving.returns) - 1)] == grown.returns
    )
    out[own] = velocity[pos[own]]
    return out
