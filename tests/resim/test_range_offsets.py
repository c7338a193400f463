"""Each laser's range offset (:mod:`nidar_mi.resim.range_offsets`): the per-laser medians, the
correction along each return's ray, and the fit on scans of a room with known offsets."""

from __future__ import annotations

import numpy as np

from nidar_mi.resim.range_offsets import corrected_returns, laser_medians

#: The room (m, the sensor's world frame): x in [-8, 14], y in [-6, 5], floor 1.7 m below
#: the sensor, ceiling 2.5 m above.
LOW = np.array([-8.0, -6.0, -1.7])
HIGH = np.array([14.0, 5.0, 2.5])


def test_laser_medians_are_each_lasers_median_less_their_weighted_mean():
    residual = np.array([0.01, 0.03, 0.02, -0.02, -0.04, 0.5])
    ring = np.array([0, 0, 0, 1, 1, 2])
    out, counts = laser_medians(residual, ring, 4, min_returns=2)
    # medians 0.02 (3 returns) and -0.03 (2); ring 2 has too few, ring 3 none: 0
    mean = (3 * 0.02 + 2 * -0.03) / 5
    np.testing.assert_allclose(out, [0.02 - mean, -0.03 - mean, 0.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(counts, [3, 2, 1, 0])


def test_a_return_is_corrected_along_its_own_ray():
    """A laser 5 cm above the centre: the corrected return lies on the ray from the laser's
    origin through the measured one, ``o`` nearer to that origin."""
    from nidar_mi.resim.laser_layout import RingLayout
    from nidar_mi.resim.range_image import ScanGrid

    layout = RingLayout(np.array([-10.0, 2.0]), np.array([0.05, -0.02]), np.array([1, 1]))
    xyz = np.array([[8.0, 3.0, -1.5], [-4.0, 6.0, 0.3]])
    grid = ScanGrid(np.array([0, 1]), np.array([0, 0]), 2, 360, True)
    out = corrected_returns(xyz, grid, layout, np.array([0.03, -0.04]))
    for k, o in enumerate((0.03, -0.04)):
        phi = np.arctan2(xyz[k, 1], xyz[k, 0])
        th = np.radians(layout.elevation_deg[k])
        v = layout.vertical_offset_m[k]
        origin = v * np.array([-np.sin(th) * np.cos(phi), -np.sin(th) * np.sin(phi), np.cos(th)])
        d = np.linalg.norm(xyz[k] - origin)
        expected = origin + (xyz[k] - origin) * (d - o) / d
        np.testing.assert_allclose(out[k], expected, atol=1e-12)


def _room_frames(offsets: np.ndarray, centres, yaws):
    """Scans of the room from poses at ``centres`` (m) turned by ``yaws`` (rad): every beam of
    a 64-laser, 1440-column sensor (+2° to -24.8°, centres at the origin), laser r's ranges
    ``d + o_r``."""
    from nidar_mi.resim.frames import Frames
    from nidar_mi.resim.laser_layout import RingLayout
    from nidar_mi.resim.range_image import ScanGrid

    rings, columns = len(offsets), 1440
    elev = np.radians(np.linspace(2.0, -24.8, rings))
    az = np.radians(-180.0 + (np.arange(columns) + 0.5) * 360.0 / columns)
    th, ph = np.meshgrid(elev, az, indexing="ij")
    u0 = np.stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), np.sin(th)], -1)
    u0 = u0.reshape(-1, 3)
    ring, col = (
        g.ravel() for g in np.meshgrid(np.arange(rings), np.arange(columns), indexing="ij")
    )
    xyz, grids, poses = [], [], []
    for c, yaw in zip(centres, yaws):
        pose = np.eye(4)
        pose[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
        pose[:3, 3] = c
        u = u0 @ pose[:3, :3].T
        with np.errstate(divide="ignore"):
            t = np.where(u > 0, (HIGH - c) / u, (LOW - c) / u)
        d = np.min(np.where(np.isfinite(t) & (t > 0), t, np.inf), axis=1)
        xyz.append(u0 * (d + offsets[ring])[:, None])
        grids.append(ScanGrid(ring, col, rings, columns, True))
        poses.append(pose)
    layout = RingLayout(np.degrees(elev), np.zeros(rings), np.ones(rings, int))
    frames = Frames(
        xyz, [np.full(len(x), 0.3) for x in xyz], grids, columns, layout, np.ones(columns, bool)
    )
    return frames, np.stack(poses)


def test_the_offsets_of_a_room_are_recovered(variant, tmp_path):
    """Known offsets uniform in ±3 cm (sd 1.7 cm), six poses around the room: recovered, the
    lasers' mean taken out, within 2.5 mm at half the lasers and 6 mm at all (measured 1.0 mm
    and 3.3 mm; one round alone 2.1 mm and 10.0 mm: the rounds bring in the lasers the first
    one misses most), and the returns corrected by them lie where the room's walls put them
    within the same 6 mm (measured 3.3 mm).
    """
    from nidar_mi.resim.range_offsets import corrected_frames, fit_range_offsets
    from nidar_mi.resim.scene_files import write_surfaces_ply
    from nidar_mi.resim.surfaces import surface_scene

    truth = np.random.default_rng(4).uniform(-0.03, 0.03, 64)
    rng = np.random.default_rng(1)
    centres = np.column_stack([rng.uniform(-4, 8, 6), rng.uniform(-3, 3, 6), np.zeros(6)])
    yaws = rng.uniform(-np.pi, np.pi, 6)
    frames, poses = _room_frames(truth, centres, yaws)

    def load(mesh):
        write_surfaces_ply(tmp_path / "m.ply", mesh, {"rho": np.full(len(mesh.vertices), 0.5)})
        return surface_scene(tmp_path / "m.ply")

    fit = fit_range_offsets(frames, poses, range(6), load, 0.1)
    want = truth - truth.mean()
    error = np.abs(fit.offsets_m - fit.offsets_m.mean() - want)
    assert np.median(error) < 0.0025 and error.max() < 0.006
    one = fit_range_offsets(frames, poses, range(6), load, 0.1, rounds=1)
    assert np.abs(one.offsets_m - one.offsets_m.mean() - want).max() > 1.5 * error.max()
    assert len(fit.steps_sd_m) == 3 and fit.steps_sd_m[2] < fit.steps_sd_m[0] / 4
    assert fit.frames == 6 and (fit.returns >= 100).all()
    fixed = corrected_frames(frames, range(6), fit.offsets_m)
    shift = fit.offsets_m.mean() - truth.mean()  # the common part stays with the surfaces
    clean, _ = _room_frames(np.full(64, -shift), centres, yaws)
    for k in range(6):
        np.testing.assert_allclose(fixed.xyz[k], clean.xyz[k], atol=0.006)


def test_scans_without_a_surface_give_no_offsets():
    """Two returns per scan make no triangle: every offset stays 0, no laser has a return (the
    surfaces step refuses such a drive in one line)."""
    from nidar_mi.resim.range_offsets import fit_range_offsets

    frames, poses = _room_frames(np.zeros(64), np.zeros((2, 3)), np.zeros(2))
    frames.xyz = [x[:2] for x in frames.xyz]
    frames.grid = [
        type(g)(g.ring[:2], g.column[:2], g.rings, g.columns, g.ordered) for g in frames.grid
    ]

    def load(mesh):  # never reached: there is no surface
        raise AssertionError("no mesh to load")

    fit = fit_range_offsets(frames, poses, range(2), load, 0.1)
    np.testing.assert_array_equal(fit.offsets_m, np.zeros(64))
    assert fit.returns.sum() == 0 and len(fit.steps_sd_m) == 3


def test_the_frames_read_are_evenly_spread():
    from nidar_mi.resim.drive_folder import evenly_spread

    assert evenly_spread(list(range(10)), 4) == [0, 3, 6, 9]
    assert evenly_spread(list(range(78)), 16)[:3] == [0, 5, 10]
    assert (
        evenly_spread(list(range(78)), 16)[-1] == 77
        and len(evenly_spread(list(range(78)), 16)) == 16
    )
    assert evenly_spread([4, 7], 16) == [4, 7]
