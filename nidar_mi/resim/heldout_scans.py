"""The held-out frames re-simulated from the written scene, scored with the baselines
(:mod:`.scan_scores`), and written as ``heldout/<id>.bin``.

Methods, all scored on the same matched returns of a frame:

* ``resim``: the recovered scene and sensor (the written ``scene.xml``);
* ``without_laser_gains``: ρ and sensor fitted with every laser's gain held at 1;
* ``constant_rho``: every vertex at the median fitted ρ, the recovered sensor;
* ``nidar_rho``: NIDAR's R scaled to ρ (the median ratio over the vertices it sees; unseen
  vertices at the median), the recovered sensor (when the drive has images);
* ``copy_all``: the intensity of the nearest training return of any frame (world frame);
* ``copy_nearest_frame``: the same from the training frame whose pose is nearest.

The re-simulated scans are the expected scans: no noise draw, detection where ``E >= T``. Each
is cast into the static surfaces and, unless ``moving`` is off, the surfaces that moved as the
training frame nearest in time saw them, each object moved on at the velocity a second
training frame gives it (:mod:`.moving`; their ρ per method: the returns inverted through the
method's sensor, or the method's constant where it has none). Unless ``holes`` is off, the
returns that fall in the holes of the training scans beside the frame are dropped from every
method's scan (:mod:`.holes`: surfaces too dark to return), and unless ``through`` is off,
the static triangles the same scans saw through are hidden from its cast (:mod:`.seen_through`:
layers that are not there).
"""

from __future__ import annotations

import os
from dataclasses import replace
from functools import partial
from types import SimpleNamespace

import numpy as np

from .drive_folder import Drive
from .frames import MIN_RANGE_M, Frames
from .mesh import Mesh
from .scan_scores import copy_intensity, drop_metrics, geometry_metrics, intensity_metrics, matches

__all__ = ["evaluate_heldout", "METHODS"]

METHODS = (
    "resim",
    "without_laser_gains",
    "constant_rho",
    "nidar_rho",
    "copy_all",
    "copy_nearest_frame",
)


def _variants(cfg, inv) -> dict:
    """Method -> (per-vertex ρ, sensor configuration, the :class:`.inversion.SensorFit` that
    inverts a moving surface's returns or None: the median ρ there) of the re-simulated
    methods; ``cfg``: the written scene's recovered sensor, whose per-laser gains carry the
    albedo scale (:func:`.write.albedo_scale`): the methods' ρ are the fitted ones, so their
    sensor takes the fitted gains (the same product)."""
    quiet = {"receiver_noise_std": 0.0, "noise_intensity_std": 0.0, "noise_range_std": 0.0}
    gains = None if cfg.laser_gains is None else tuple(float(g) for g in inv.sensor.gains)
    det = replace(cfg, laser_gains=gains, dropout=0.0, **quiet)
    s = inv.sensor_flat
    flat = replace(
        det,
        laser_gains=None,
        laser_range_response=None,
        laser_offsets=None,
        range_response=tuple(zip(s.knots_m, (float(v) for v in s.response))),
        intensity_offset=s.offset,
        detection_threshold=s.threshold,
    )
    out = {
        "resim": (inv.rho, det, inv.sensor),
        "without_laser_gains": (inv.rho_flat, flat, inv.sensor_flat),
        "constant_rho": (np.full_like(inv.rho, np.median(inv.rho)), det, None),
    }
    if inv.prior is not None and np.isfinite(inv.prior_scale):
        r = inv.prior_scale * inv.prior
        out["nidar_rho"] = (np.where(np.isfinite(r), r, np.median(inv.rho)), det, None)
    return out


def _sim_scan(scene, cfg, pose, frames: Frames, drop=None):
    """(M, 3) LiDAR-frame points, (M,) intensity, (R, C) occupancy of a re-simulated scan,
    inside the drive's coverage and past MIN_RANGE_M; ``drop``: a function of (M, 3) points
    giving the (M,) returns to leave out as well (:mod:`.holes`), or None."""
    from ..datasets.kitti_rings import azimuth_deg
    from ..lidar.scan import scan

    r = scan(scene, SimpleNamespace(config=cfg), to_world=pose)
    xyz = r.range[..., None] * r.directions
    if r.origins is not None:
        xyz = xyz + r.origins
    col = np.floor((azimuth_deg(xyz.reshape(-1, 3)) + 180.0) * frames.columns / 360.0)
    col = col.astype(np.int64).reshape(r.valid.shape) % frames.columns
    keep = r.valid & frames.coverage[col] & (r.range >= MIN_RANGE_M)
    if drop is not None and keep.any():
        kept = np.flatnonzero(keep)
        keep.flat[kept[drop(xyz[keep])]] = False
    occ = np.zeros((cfg.rings, frames.columns), bool)
    ring = np.broadcast_to(np.arange(cfg.rings)[:, None], keep.shape)
    occ[ring[keep], col[keep]] = True
    return xyz[keep].astype(np.float64), r.intensity[keep].astype(np.float64), occ


def _training_world(drive: Drive, frames: Frames, poses):
    """Per training frame its returns in world coordinates and their intensities."""
    out = {}
    for fid in drive.train:
        k = drive.index(fid)
        T = poses[k]
        out[k] = (frames.xyz[k] @ T[:3, :3].T + T[:3, 3], frames.intensity[k])
    return out


def _copy_predictions(real_world, k: int, poses, train: dict) -> dict:
    """The two copy baselines' intensities at (K, 3) world points of frame ``k``."""
    allw = np.concatenate([w for w, _ in train.values()])
    alli = np.concatenate([i for _, i in train.values()])
    near = min(train, key=lambda j: np.linalg.norm(poses[j][:3, 3] - poses[k][:3, 3]))
    return {
        "copy_all": copy_intensity(real_world, allw, alli),
        "copy_nearest_frame": copy_intensity(real_world, *train[near]),
    }


def _score_frame(k: int, scans: dict, frames: Frames, poses, train: dict) -> dict:
    """Every method's metrics on frame ``k`` (``scans``: method -> its re-simulated scan)."""
    real, y = frames.xyz[k], frames.intensity[k]
    sim, sim_i, occ = scans["resim"]
    ok, idx = matches(real, sim)
    out = {"returns_real": len(real), "returns_resim": len(sim), "matched": float(ok.mean())}
    out |= geometry_metrics(real, sim)
    out |= drop_metrics(frames.grid[k].occupancy(), occ, frames.coverage)
    methods = {"resim": sim_i[idx[ok]]}
    for name, (pts, vals, _) in scans.items():
        if name != "resim" and len(pts):
            methods[name] = vals[_nearest_index(real[ok], pts)]
    T = poses[k]
    methods |= _copy_predictions(real[ok] @ T[:3, :3].T + T[:3, 3], k, poses, train)
    out["intensity"] = {name: intensity_metrics(p, y[ok]) for name, p in methods.items()}
    return out


def _nearest_index(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    return cKDTree(b).query(a, k=1)[1]


def _mean(per_frame: dict) -> dict:
    """The mean of every metric over the frames (NaN-aware)."""
    if not per_frame:
        return {}
    frames = list(per_frame.values())
    keys = [k for k, v in frames[0].items() if isinstance(v, (int, float))]
    out = {k: float(np.nanmean([f[k] for f in frames])) for k in keys}
    methods = {m for f in frames for m in f["intensity"]}
    out["intensity"] = {
        m: {
            q: float(np.nanmean([f["intensity"][m][q] for f in frames if m in f["intensity"]]))
            for q in ("spearman", "rmse")
        }
        for m in sorted(methods, key=lambda m: METHODS.index(m))
    }
    return out


def _frame_moving(j: int, frames: Frames, poses, static):
    """``(moving, hit, rays)`` of training frame ``j``: the surfaces that moved as it saw them
    (:mod:`.moving`), the static triangle each return ends on (-1: none that explains it) and
    its return rays."""
    from .beam_rays import return_rays
    from .moving import moving_surfaces

    rays = return_rays(frames.xyz[j], frames.grid[j], frames.layout, poses[j], j)
    moving, hit = moving_surfaces(
        frames.xyz[j], frames.grid[j], rays, static, j, wrap=not frames.cut
    )
    return moving, hit, rays


class _Moving:
    """The surfaces that moved, at each held-out frame's time (module docstring), the
    training frames' moving surfaces and their ρ computed once."""

    def __init__(self, drive: Drive, frames: Frames, poses, mesh, static, stage, variants):
        from .build import scratch_scene

        self.drive, self.frames, self.poses, self.mesh = drive, frames, poses, mesh
        self.static, self.stage, self.variants = static, stage, variants
        self.load = scratch_scene(stage)
        self.train = [drive.index(i) for i in drive.train]
        self.seen: dict[int, tuple] = {}
        self.shifts: dict[tuple[int, int], np.ndarray] = {}
        self.rho: tuple[int, dict] = (-1, {})
        self.normals: np.ndarray | None = None  # the static surfaces' vertex normals, once

    def _frame(self, j: int):
        """Training frame ``j``'s moving surfaces and return rays."""
        if j not in self.seen:
            if len(self.seen) >= 3:  # memory: the last few frames only
                self.seen.pop(next(iter(self.seen)))
            self.seen[j] = _frame_moving(j, self.frames, self.poses, self.static)
        return self.seen[j]

    def _rho_of(self, mv, rays, j: int, inv, partner=None) -> dict:
        """The ρ per method of moving surfaces ``mv`` of frame ``j`` (``rays``: its returns';
        ``partner``: ``(j2, shift)``, the frame that times their motion and (V, 3) each
        vertex's motion to it, or None: :func:`.moving.moving_rho`)."""
        from .moving import moving_rho

        seen = None
        if partner is not None:
            j2, shift = partner
            seen = (self._frame(j2)[2], self.frames.intensity[j2], shift)
        return {
            name: moving_rho(mv, rays, self.frames.intensity[j], fitted, self.load, seen)
            if fitted is not None and len(mv.mesh.faces)
            else np.full(len(mv.returns), np.median(inv.rho))
            for name, (_, _, fitted) in self.variants.items()
        }

    def _rho(self, j: int, inv) -> dict:
        """Frame ``j``'s moving surfaces' ρ per method, from its returns alone (the frame they
        come from when no other frame times their motion)."""
        if self.rho[0] != j:
            mv, _, rays = self._frame(j)
            self.rho = (j, self._rho_of(mv, rays, j, inv))
        return self.rho[1]

    def _velocity(self, j: int, j2: int) -> np.ndarray:
        """(V, 3) frame ``j``'s moving vertices' motion per frame step, timed by frame ``j2``."""
        from .moving import MAX_STEP_M, track_shifts

        if (j, j2) not in self.shifts:  # held-out frames between the same two share it
            mv, target = self._frame(j)[0].mesh, self._frame(j2)[0].mesh
            self.shifts = {(j, j2): track_shifts(mv, target, MAX_STEP_M * abs(j2 - j))}
        return self.shifts[(j, j2)] / (j2 - j)

    def _whole(self, j: int, j2: int, k: int, velocity, inv):
        """``(mv, velocity, trail, rho)``: frame ``j``'s tracked objects whole at held-out frame
        ``k`` (:mod:`.moving`: the returns its own trail explained join them, moving alike),
        the static triangles of their trail and their ρ, each vertex's return averaged with
        frame ``j2``'s where that frame saw it (:func:`.moving.moving_rho`)."""
        from .moving import carried_velocity, surfaces_of, trail_faces, vertex_normals

        mv, hit, rays = self._frame(j)
        steps = [i - j for i in self.train]
        if self.normals is None:
            self.normals = vertex_normals(self.mesh)
        trail = trail_faces(self.mesh, mv.mesh, velocity, steps, k - j, self.normals)
        if not trail.any():
            return mv, velocity, trail, self._rho_of(mv, rays, j, inv, (j2, velocity * (j2 - j)))
        free = (hit < 0) | trail[np.maximum(hit, 0)]
        grown = surfaces_of(
            self.frames.xyz[j], self.frames.grid[j], rays, free, j, wrap=not self.frames.cut
        )
        velocity = carried_velocity(grown, mv, velocity)
        trail |= trail_faces(self.mesh, grown.mesh, velocity, steps, k - j, self.normals)
        partner = (j2, velocity * (j2 - j))
        return grown, velocity, trail, self._rho_of(grown, rays, j, inv, partner)

    def at(self, k: int, inv, hidden=None):
        """``(scene, extra, keep, record, moved)`` at held-out frame ``k``: the static surfaces
        without the tracked objects' trails and the triangles ``hidden`` ((F,) bool over the
        static faces, or None; :mod:`.seen_through`) and with the surfaces that moved, their ρ
        per method, the static vertices the scene keeps (in its order; the moving ones follow;
        None: all), what ``report.json`` records of them and the (V, 3) world vertices of the
        surfaces that moved, where they stand at ``k`` (None: none)."""
        from .moving import nearest_frame, partner_frame

        j = nearest_frame(k, self.train)
        mv = self._frame(j)[0]
        record = {"from": self.drive.ids[j], "triangles": len(mv.mesh.faces), "partner": None}
        gone = np.zeros(len(self.mesh.faces), bool) if hidden is None else hidden.copy()
        velocity = np.zeros((len(mv.mesh.vertices), 3))
        j2 = partner_frame(k, j, self.train) if len(mv.mesh.faces) else None
        if j2 is None:  # its own returns alone
            extra = self._rho(j, inv)
        else:
            velocity = self._velocity(j, j2)
            tracked = float((np.linalg.norm(velocity, axis=1) > 0).mean())
            mv, velocity, trail, extra = self._whole(j, j2, k, velocity, inv)
            gone |= trail
            record.update(
                partner=self.drive.ids[j2], tracked=tracked, trail=int(trail.sum()),
                triangles=len(mv.mesh.faces),
            )  # fmt: skip
        moved = Mesh(mv.mesh.vertices + velocity * (k - j), mv.mesh.faces)
        scene, keep = without_faces(self.load, self.mesh, gone, moved)
        if scene is None:
            return self.static, extra, None, record, None
        return scene, extra, keep, record, moved.vertices if len(moved.faces) else None


def without_faces(load, mesh, gone: np.ndarray, moved=None):
    """``(scene, keep)``: the static ``mesh`` without the faces ``gone`` ((F,) bool) and with
    the ``moved`` mesh after it, loaded with ``load`` (:func:`.build.scratch_scene`), and the
    static vertices kept, in their order (None: all); ``(None, None)`` when nothing is to
    change."""
    from .mesh import compact_index, merge_meshes

    static, keep = mesh, None
    if gone.any():
        static, keep = compact_index(Mesh(mesh.vertices, mesh.faces[~gone]))
    parts = [static] + ([moved] if moved is not None and len(moved.faces) else [])
    if keep is None and len(parts) == 1:
        return None, None
    return load(merge_meshes(parts)), keep


def evaluate_heldout(
    scene_path: str,
    drive: Drive,
    frames: Frames,
    poses,
    inv,
    stage: str,
    mesh=None,
    moving: bool = True,
    holes: bool = True,
    through: bool = True,
):
    """Re-simulate, write and score every held-out frame; ``{"frames": {id: metrics},
    "mean": ...}``. ``mesh``: the static surfaces of ``scene_path`` (:class:`.mesh.Mesh`),
    needed with ``moving`` and ``through``; ``holes``: drop the returns in the holes of the
    training scans next to each frame; ``through``: hide the static triangles they saw through
    (module docstring)."""
    import mitsuba as mi

    from ..io.kitti import write_kitti_bin
    from ..scene import load_scene
    from .build import drop_scratch, scratch_scene
    from .holes import Holes, hole_frames
    from .seen_through import SeenThrough
    from .surfaces import RHO_KEY

    if not drive.holdout:
        return {"frames": {}, "mean": {}}
    if (moving or through) and mesh is None:
        raise ValueError("evaluate_heldout: moving surfaces and the see-through test need the mesh")
    loaded = load_scene(scene_path)
    static = loaded.scene
    sensor = next(s for s in static.sensors() if hasattr(s, "config"))
    variants = _variants(sensor.config, inv)
    train = _training_world(drive, frames, poses)
    os.makedirs(os.path.join(stage, "heldout"), exist_ok=True)
    per_frame = {}
    motion = _Moving(drive, frames, poses, mesh, static, stage, variants) if moving else None
    train_ids = [drive.index(i) for i in drive.train]
    hole_test = Holes(frames, poses, train_ids) if holes else None
    seen = SeenThrough(frames, poses, train_ids) if through else None
    try:
        for fid in drive.holdout:
            k = drive.index(fid)
            scene, record, keep, moved = static, None, None, None
            hidden = None if seen is None else seen.faces(k, mesh.vertices, mesh.faces)
            if motion is not None:
                scene, extra, keep, record, moved = motion.at(k, inv, hidden)
            elif hidden is not None and hidden.any():
                scene, keep = without_faces(scratch_scene(stage), mesh, hidden)
                extra = {name: np.zeros(0) for name in variants}
            drop = None if hole_test is None else partial(hole_test.mask, k, moving=moved)
            params = mi.traverse(scene)
            scans = {}
            for name, (rho, cfg, _) in variants.items():
                if scene is not static:
                    rho = np.concatenate([rho if keep is None else rho[keep], extra[name]])
                params[RHO_KEY] = mi.Float(np.asarray(rho, dtype=np.float32))
                params.update()
                scans[name] = _sim_scan(scene, cfg, poses[k], frames, drop)
            sim, sim_i, _ = scans["resim"]
            path = os.path.join(stage, "heldout", f"{fid}.bin")
            write_kitti_bin(path, sim, np.clip(sim_i, 0.0, 1.0))
            per_frame[fid] = _score_frame(k, scans, frames, poses, train)
            if record is not None:
                per_frame[fid]["moving"] = record
            if hole_test is not None or seen is not None:
                per_frame[fid]["holes"] = {
                    "from": [drive.ids[j] for j in hole_frames(k, train_ids)],
                    "dropped": 0 if hole_test is None else hole_test.dropped.get(k, 0),
                    "seen_through": 0 if seen is None else seen.hidden.get(k, 0),
                }
    finally:
        drop_scratch(stage)
    return {"frames": per_frame, "mean": _mean(per_frame)}
