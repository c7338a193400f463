"""The mounting's shadow from the training samples (:mod:`nidar_mi.resim.shadow`): evidence
counted once per frame and beam, the rule, the frames that count, each ray's column, and the
intervals read back by the plugin to the same beams."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nidar_mi.resim.shadow import (
    beam_evidence,
    evidence_frames,
    ray_columns,
    shadow_intervals,
    shadow_mask,
    shadow_value,
)


def test_evidence_counts_each_frame_once_per_beam():
    # beam (1, 2): frame 0 twice (a return and a miss), frame 1 a miss; beam (0, 0): a return
    ring = np.array([1, 1, 1, 0])
    column = np.array([2, 2, 2, 0])
    frame = np.array([0, 0, 1, 0])
    detected = np.array([True, False, False, True])
    hits, returned = beam_evidence(ring, column, frame, detected, (2, 4))
    assert hits[1, 2] == 2 and returned[1, 2] == 1 and hits[0, 0] == 1 and returned[0, 0] == 1
    assert hits.sum() == 3 and returned.sum() == 2


def test_the_rule_needs_the_surfaces_twice_and_almost_no_return():
    hits = np.array([[1, 2, 10, 10, 0]])
    returned = np.array([[0, 0, 1, 2, 0]])
    np.testing.assert_array_equal(shadow_mask(hits, returned), [[False, True, True, False, False]])


def test_a_car_that_stops_adds_no_evidence():
    x = np.array([0.0, 0.1, 0.2, 0.6, 0.7, 1.2, 1.2, 1.2])
    positions = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    np.testing.assert_array_equal(evidence_frames(positions), [0, 3, 5])


def test_a_ray_gets_the_column_of_where_it_ends_in_its_frame():
    """A frame turned 90° about z and moved: a miss along the sensor's column centre and a
    return from an offset origin come back to their columns of a 360-column grid."""
    from nidar_mi.resim.beam_rays import Rays

    c = np.cos(np.pi / 2)
    T = np.eye(4)
    T[:3, :3] = [[c, -1, 0], [1, c, 0], [0, 0, 1]]
    T[:3, 3] = [5.0, -2.0, 1.7]
    poses = np.stack([np.eye(4), T])
    # in the sensor frame: a miss at azimuth 30.5° (column 210), a return 10 m away at -100.5°
    # (column 79) measured from an origin 3 cm off the sensor's centre
    local_dir = np.array([[np.cos(np.radians(30.5)), np.sin(np.radians(30.5)), 0.0]])
    end = 10.0 * np.array([np.cos(np.radians(-100.5)), np.sin(np.radians(-100.5)), -0.1])
    origin = np.array([0.03, 0.0, 0.0])
    d = (end - origin) / np.linalg.norm(end - origin)
    R, t = T[:3, :3], T[:3, 3]
    rays = Rays(
        origin=np.stack([t, R @ origin + t]),
        direction=np.stack([R @ local_dir[0], R @ d]),
        range_m=np.array([np.inf, np.linalg.norm(end - origin)]),
        ring=np.array([3, 4]),
        frame=np.array([1, 1]),
    )
    np.testing.assert_array_equal(ray_columns(rays, poses, 360), [210, 79])


def test_intervals_read_back_by_the_plugin_shadow_the_same_beams():
    """Runs at the first and the last column, a whole ring, an odd column count (a beam at
    exactly 180°, the grid's column 0): the plugin's shadow of the written text, at every
    column's centre and at 180°, is the mask."""
    from nidar_mi.lidar.config import LidarConfig
    from nidar_mi.lidar.scan import shadowed_beams

    columns = 37
    mask = np.zeros((3, columns), bool)
    mask[0, :3] = mask[0, -2:] = True
    mask[1, :] = True
    mask[2, 10:12] = True
    intervals = shadow_intervals(mask, columns)
    assert len(intervals) == 4
    cfg = LidarConfig.from_mapping(
        "l", {"elevation_angles": "0, -5, -10", "laser_shadow": shadow_value(intervals)}
    )
    az = np.radians(-180.0 + (np.arange(columns) + 0.5) * 360.0 / columns)
    directions = np.zeros((3, columns, 3))
    directions[..., 0], directions[..., 1] = np.cos(az), np.sin(az)
    np.testing.assert_array_equal(shadowed_beams(cfg, directions), mask)
    back = np.zeros((3, 1, 3))
    back[..., 0] = -1.0  # azimuth 180°: column 0 of the grid
    assert shadowed_beams(SimpleNamespace(laser_shadow=cfg.laser_shadow), back)[:, 0].tolist() == [
        True,
        True,
        False,
    ]
