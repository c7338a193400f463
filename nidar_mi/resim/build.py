"""The drive's poses and surfaces: poses from the drive or KISS-ICP (:mod:`.poses`), then the
training scans meshed, fused, carved and cleared of moving objects (:mod:`.mesh`,
:mod:`.carve`, :mod:`.transient`)."""

from __future__ import annotations

import os

import numpy as np

from .beam_rays import concat, return_rays
from .drive_folder import Drive
from .frames import Frames
from .mesh import Mesh, compact, fuse_meshes, scan_triangles

__all__ = [
    "drive_poses",
    "build_surfaces",
    "drive_splats",
    "training_rays",
    "scratch_scene",
    "drop_scratch",
]


def drive_poses(drive: Drive, frames: Frames, *, progress: bool = False) -> np.ndarray:
    """(F, 4, 4) every frame's LiDAR pose in frame 0's LiDAR frame: the drive's poses file, or
    KISS-ICP odometry refined against the training frames' returns (:mod:`.poses`)."""
    from .poses import odometry_poses, refine_poses

    if drive.poses is not None:
        poses = drive.poses
    else:
        poses = odometry_poses(lambda k: frames.xyz[k], len(drive.ids), progress=progress)
        train = np.isin(np.arange(len(drive.ids)), [drive.index(i) for i in drive.train])
        poses = refine_poses(lambda k: frames.xyz[k], poses, train, progress=progress)
    return np.linalg.inv(poses[0]) @ poses


def training_rays(drive: Drive, frames: Frames, poses: np.ndarray):
    """The rays of every training return, and their intensities."""
    idx = [drive.index(i) for i in drive.train]
    rays = concat(
        [return_rays(frames.xyz[k], frames.grid[k], frames.layout, poses[k], k) for k in idx]
    )
    return rays, np.concatenate([frames.intensity[k] for k in idx])


def scratch_scene(stage: str):
    """``load(mesh) -> mi.Scene`` of a mesh alone, through a PLY file in ``stage`` (removed by
    the caller with :func:`drop_scratch`)."""
    from .scene_files import write_surfaces_ply
    from .surfaces import surface_scene

    path = os.path.join(stage, ".scratch.ply")

    def load(mesh: Mesh, rho: np.ndarray | None = None):
        values = np.full(len(mesh.vertices), 0.5) if rho is None else rho
        write_surfaces_ply(path, mesh, {"rho": values})
        return surface_scene(path)

    return load


def drop_scratch(stage: str) -> None:
    """Remove the scratch PLY of :func:`scratch_scene`."""
    path = os.path.join(stage, ".scratch.ply")
    if os.path.exists(path):
        os.remove(path)


def _subgrid(grid, idx: np.ndarray):
    """The :class:`.range_image.ScanGrid` of the returns ``idx`` of ``grid``'s scan."""
    from .range_image import ScanGrid

    return ScanGrid(grid.ring[idx], grid.column[idx], grid.rings, grid.columns, grid.ordered)


def _off_mesh(xyz, grid, layout, pose, tree, scene) -> np.ndarray:
    """(N,) bool: returns of a scan (LiDAR frame, m; ``grid``: their cells) that the fused mesh
    does not hold: farther than :data:`.splats.OFF_MESH_M` from its vertices (``tree``), or
    nearer but passed by their own rays (:func:`.splats.passed_by`, cast into ``scene``, the
    mesh's)."""
    from .carve import hit_depths
    from .splats import OFF_MESH_M, passed_by

    world = xyz @ pose[:3, :3].T + pose[:3, 3]
    off = tree.query(world, distance_upper_bound=OFF_MESH_M)[0] > OFF_MESH_M
    near = np.flatnonzero(~off)
    if len(near):
        rays = return_rays(xyz[near], _subgrid(grid, near), layout, pose, -1)  # frame unused
        t, _, cos = hit_depths(scene, rays)
        off[near] = passed_by(rays.range_m, t, cos)
    return off


def drive_splats(drive: Drive, frames: Frames, poses: np.ndarray, mesh: Mesh, unmeshed: list, load):
    """The splats of every training frame's returns that its range-image mesh left out
    (``unmeshed``: per training frame, in ``drive.train``'s order, (N,) bool; narrowed in place
    to the returns splatted) and that the fused ``mesh`` does not hold (:mod:`.splats`), world
    coordinates; ``load``: :func:`scratch_scene`."""
    from scipy.spatial import cKDTree

    from .splats import Splats, local_normals, ring_spacing_rad, scan_splats

    spacing = ring_spacing_rad(frames.layout.elevation_deg)
    tree = cKDTree(mesh.vertices)
    scene = load(mesh)
    parts = []
    for fid, alone in zip(drive.train, unmeshed):
        k = drive.index(fid)
        xyz, grid, pose = frames.xyz[k], frames.grid[k], poses[k]
        idx = np.flatnonzero(alone)
        alone[idx] = _off_mesh(xyz[idx], _subgrid(grid, idx), frames.layout, pose, tree, scene)
        normals = local_normals(xyz, np.flatnonzero(alone))
        p = xyz[alone]
        d = np.linalg.norm(p, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", p / d[:, None], np.nan_to_num(normals, nan=0.0)))
        cos = np.where(np.isfinite(normals[:, 0]), cos, 1.0)
        splat = scan_splats(p, grid.ring[alone], grid.columns, spacing, normals)
        four = {  # four corners per splat, each standing for its return
            "ring": grid.ring[alone],
            "range_m": d,
            "intensity": frames.intensity[k][alone],
            "cos": cos,
        }
        parts.append(
            Splats(splat.transformed(pose), **{f: np.repeat(v, 4) for f, v in four.items()})
        )
    return Splats.join(parts)


def build_surfaces(drive: Drive, frames: Frames, poses: np.ndarray, options, stage: str):
    """The carved mesh of the training frames (world = frame 0's LiDAR frame) and the carved
    splats of the returns it left out.

    Returns:
        ``(mesh, splats, carved, transient)``: the mesh, the splats (:class:`.splats.Splats`,
        none unless ``options.splats``), the triangles each carving pass removed (``mesh``
        and ``splats``) and the transient triangles removed (:mod:`.transient`).
    """
    from ..errors import NidarError
    from .splats import Splats, unmeshed_returns

    meshes, unmeshed = [], []
    for fid in drive.train:
        k = drive.index(fid)
        xyz = np.asarray(frames.xyz[k], dtype=np.float64)
        tris = scan_triangles(xyz, frames.grid[k], wrap=not frames.cut)
        meshes.append(compact(Mesh(xyz, tris)).transformed(poses[k]))  # scan_mesh's mesh
        unmeshed.append(unmeshed_returns(len(xyz), tris))
    mesh = fuse_meshes(meshes, options.voxel_m)
    if len(mesh.faces) == 0:
        raise NidarError(f"{drive.root}: the training scans gave no surface to mesh")
    rays = None
    carved = {"mesh": [], "splats": []}
    splats = Splats.join([])
    if options.splats:
        splats = drive_splats(drive, frames, poses, mesh, unmeshed, scratch_scene(stage))
    if options.carve_passes > 0:
        from .carve import carve, carved_faces

        rays, _ = training_rays(drive, frames, poses)
        load = scratch_scene(stage)
        mesh, carved["mesh"] = carve(mesh, rays, load, passes=options.carve_passes)
        if len(splats.mesh.faces):
            keep, carved["splats"] = carved_faces(
                splats.mesh, rays, load, passes=options.carve_passes
            )
            splats = splats.kept(keep)
    transient = []
    if options.transient_frames > 0:
        from .transient import remove_transient

        rays = training_rays(drive, frames, poses)[0] if rays is None else rays
        mesh, transient = remove_transient(
            mesh, rays, scratch_scene(stage), run=options.transient_frames
        )
    drop_scratch(stage)
    return mesh, splats, carved, transient
