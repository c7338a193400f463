"""Scan Context descriptors and loop detection on hand-made scans."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nidar_mi.eval.drive.loops import Matches, match_drive, pr_curve, pr_summary
from nidar_mi.eval.drive.scan_context import (
    descriptor,
    geometry_similarity,
    normalise,
    ring_key,
    value_similarity,
)


def test_descriptor_bins_points_by_range_and_azimuth():
    # ring width 2 m, sector width 90 deg counted from -x: (+x) lies in sector 2, (+y) in 3
    xyz = np.array(
        [[3.0, 0.0, 0.0], [3.5, 0.1, 1.0], [0.0, 5.0, 0.0], [-1.0, -0.5, 0.0], [50, 0, 0]]
    )
    vals = np.array([0.2, 0.7, 0.4, 0.9, 1.0])
    grid, occ = descriptor(xyz, vals, rings=4, sectors=4, max_range=8.0)
    expected = np.zeros((4, 4), np.float32)
    expected[1, 2] = 0.7  # the max of 0.2 and 0.7 (both 3-3.5 m ahead)
    expected[2, 3] = 0.4
    expected[0, 0] = 0.9  # (-1, -0.5): atan2 = -153 deg -> 27 deg from -x
    np.testing.assert_array_equal(grid, expected)
    np.testing.assert_array_equal(occ, expected > 0)
    np.testing.assert_allclose(ring_key(grid), expected.mean(1))


def _scene(rng, n=4000):
    r = rng.uniform(2, 39, n)
    a = rng.uniform(-np.pi, np.pi, n)
    return np.stack([r * np.cos(a), r * np.sin(a), rng.uniform(-1.5, 3, n)], -1), rng.uniform(
        0, 1, n
    )


def test_a_rotated_scan_matches_itself_at_the_rotation():
    rng = np.random.default_rng(0)
    xyz, v = _scene(rng)
    S = 60
    R = Rotation.from_euler("z", 90.0, degrees=True).as_matrix()  # 15 sectors
    g1, o1 = descriptor(xyz, v, sectors=S)
    g2, o2 = descriptor(xyz @ R.T, v, sectors=S)
    geo, k = geometry_similarity(o1, o2)
    assert geo == 1.0 and k == 15
    np.testing.assert_array_equal(np.roll(g2, -k, axis=1), g1)
    assert value_similarity(g1, g2, k) == pytest.approx(1.0)
    np.testing.assert_allclose(ring_key(g1), ring_key(g2), rtol=1e-6)


def test_value_similarity_is_one_minus_the_mean_difference():
    a = np.zeros((2, 4), np.float32)
    b = np.zeros((2, 4), np.float32)
    a[0, 0], b[0, 0] = 1.0, 0.6  # one bin of 8 differs by 0.4 at shift 0
    assert value_similarity(a, b, 0, window=1) == pytest.approx(1 - 0.4 / 8)
    # the occupancy of a half-empty grid agrees with an empty one on 7 of 8 bins
    assert geometry_similarity(a > 0, np.zeros((2, 4), bool)) == (pytest.approx(7 / 8), 0)


def test_normalise_clips_and_removes_nan():
    np.testing.assert_allclose(normalise(np.array([0.5, 3.0, np.nan, -1.0]), 2.0), [0.25, 1, 0, 0])


def test_match_drive_finds_the_revisit_and_scores_it():
    # a drive along x and back: frames 0..9 at x = 0, 10, ..., 90; frames 10..19 return along
    # the same places in reverse. Each place has its own random scene; the return sees it turned
    # round (yaw 180 deg), so scan context must match it through the column shift.
    rng = np.random.default_rng(3)
    places = [_scene(rng, 1500) for _ in range(10)]
    R = Rotation.from_euler("z", 180.0, degrees=True).as_matrix()
    frames = [places[k] for k in range(10)] + [
        (places[k][0] @ R.T, places[k][1]) for k in range(9, -1, -1)
    ]
    pos = np.array(
        [[10.0 * k, 0, 0] for k in range(10)] + [[10.0 * k, 0.5, 0] for k in range(9, -1, -1)]
    )
    dist = np.arange(20) * 10.0
    desc = [descriptor(x, v) for x, v in frames]
    m = match_drive(
        np.stack([d[0] for d in desc]), np.stack([d[1] for d in desc]), pos, dist, skip_m=20.0
    )
    # queries 11..19 revisit places 8..0; query 10 (place 9) has only frames 0..8 in its
    # database (frame 9 was driven 10 m before it, less than skip_m)
    assert m.revisit.tolist() == [False] * 11 + [True] * 9
    assert m.correct[11:].all()
    assert np.all(m.match[11:] == np.arange(8, -1, -1))
    assert np.all(m.score[11:] == pytest.approx(1.0))
    summary = pr_summary(m)
    assert summary["correct_loop_rate"] == 1.0 and summary["revisits"] == 9
    assert summary["recall_at_p100"] == 1.0


def test_pr_curve_counts_by_hand():
    # four matched queries with scores 0.9 (correct), 0.8 (wrong), 0.7 (correct), 0.6 (wrong);
    # three revisits in all
    m = Matches(
        match=np.array([1, 2, 3, 4, -1]),
        score=np.array([0.9, 0.8, 0.7, 0.6, -np.inf]),
        shift=np.zeros(5, int),
        revisit=np.array([True, False, True, True, False]),
        correct=np.array([True, False, True, False, False]),
    )
    thr, p, r = pr_curve(m)
    np.testing.assert_allclose(thr, [0.9, 0.8, 0.7, 0.6])
    np.testing.assert_allclose(p, [1, 1 / 2, 2 / 3, 2 / 4])
    np.testing.assert_allclose(r, [1 / 3, 1 / 3, 2 / 3, 2 / 3])
    s = pr_summary(m)
    assert s["average_precision"] == pytest.approx(1 / 3 * 1 + 1 / 3 * 2 / 3)
    assert s["max_f1"] == pytest.approx(2 * (2 / 3) * (2 / 3) / (4 / 3))
    assert s["recall_at_p100"] == pytest.approx(1 / 3)
    assert s["correct_loop_rate"] == pytest.approx(2 / 3)
