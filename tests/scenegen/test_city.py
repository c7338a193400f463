"""City and suburb layouts: a street grid the drive can use, with structure along every street."""

import math

import numpy as np
import pytest

from nidar_mi.scenegen.city import sample_city
from nidar_mi.scenegen.primitives import Block, Cylinder, Sphere
from nidar_mi.scenegen.route import drive
from nidar_mi.scenegen.streets import CITY_KINDS, drive_route, sample_grid
from nidar_mi.scenegen.xml import scene_xml


def _footprint_distance(shape, p: np.ndarray) -> np.ndarray:
    """Horizontal distance (m) from points p (N, 2) to a shape's footprint (boxes exactly,
    cylinders and spheres as discs), for the parts that reach below 2.2 m."""
    if isinstance(shape, Block):
        if shape.center[2] - shape.half_size[2] > 2.2:
            return np.full(len(p), np.inf)
        a = math.radians(shape.yaw_deg)
        R = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        local = (p - np.array(shape.center[:2])) @ R.T
        d = np.maximum(np.abs(local) - np.array(shape.half_size[:2]), 0.0)
        return np.linalg.norm(d, axis=1)
    if isinstance(shape, Cylinder):
        if min(shape.p0[2], shape.p1[2]) > 2.2:
            return np.full(len(p), np.inf)
        q0, q1 = np.array(shape.p0[:2]), np.array(shape.p1[:2])
        seg = q1 - q0
        t = np.clip(((p - q0) @ seg) / max(seg @ seg, 1e-12), 0, 1) if seg @ seg > 0 else 0.0
        return (
            np.linalg.norm(p - (q0 + np.outer(t, seg) if np.ndim(t) else q0), axis=1) - shape.radius
        )
    if isinstance(shape, Sphere):
        if shape.center[2] - shape.radius > 2.2:
            return np.full(len(p), np.inf)
        return np.linalg.norm(p - np.array(shape.center[:2]), axis=1) - shape.radius
    return np.full(len(p), np.inf)


@pytest.mark.parametrize("kind", CITY_KINDS)
def test_the_drive_never_passes_through_an_object(kind):
    layout, grid = sample_city(np.random.default_rng(4), kind, (3, 2))
    traj = drive(grid, 700)
    p = traj.positions()[:, :2]
    # a car is ~1.9 m wide: nothing below roof height within 1.0 m of the LiDAR's path
    nearest = min(float(_footprint_distance(s, p).min()) for s in layout.shapes)
    assert nearest > 1.0


@pytest.mark.parametrize("kind", CITY_KINDS)
def test_every_street_side_has_structure_across_the_road(kind):
    layout, grid = sample_city(np.random.default_rng(2), kind, (3, 2))
    ids = [s.id for s in layout.shapes]
    for part in ("light", "bin", "car", "_b"):
        assert sum(part in i for i in ids) >= 6, part
    # every block side of the route's two blocks carries at least one upright object
    c, b = grid.nx // 2, (grid.ny - 1) // 2
    for bi in (c - 1, c):
        for side in "snwe":
            prefix = f"blk{bi}_{b}{side}_"
            assert any(i.startswith(prefix) for i in ids), prefix


def test_grid_geometry_and_kinds():
    g = sample_grid(np.random.default_rng(0), "city", (4, 3))
    assert 38.0 <= g.pitch <= 44.0 and g.road_half == pytest.approx(g.lane_w + g.park_w)
    x0, x1, y0, y1 = g.block_bounds(1, 2)
    assert x0 == pytest.approx(g.pitch + g.street_half) and y1 == pytest.approx(
        3 * g.pitch - g.street_half
    )
    s = sample_grid(np.random.default_rng(0), "suburb", (4, 3))
    assert 48.0 <= s.pitch <= 56.0
    with pytest.raises(ValueError, match="at least 2 x 1"):
        sample_grid(np.random.default_rng(0), "city", (1, 1))
    route = drive_route(g)
    assert route[0] == route[-1] == (2, 1) and route.count((2, 1)) == 3  # a figure eight


def test_layouts_are_deterministic_and_write_xml():
    a, _ = sample_city(np.random.default_rng(9), "suburb", (2, 1))
    b, _ = sample_city(np.random.default_rng(9), "suburb")  # default blocks differ
    c, _ = sample_city(np.random.default_rng(9), "suburb", (2, 1))
    assert a == c and a != b
    assert a.rig.lidar_preset == "hdl64e" and a.rig.lidar_position[2] == pytest.approx(1.73)
    text = scene_xml(a)
    assert text.count("<shape ") == len(a.shapes)


@pytest.mark.parametrize("kind", CITY_KINDS)
def test_every_city_shape_is_labelled(kind):
    from nidar_mi.labels import strip_labels

    layout, _ = sample_city(np.random.default_rng(1), kind, (2, 1))
    _, labels = strip_labels(scene_xml(layout))
    assert set(labels.classes) == {s.id for s in layout.shapes}
    assert "unlabeled" not in labels.classes.values()
    classes = set(labels.classes.values())
    assert {"road", "sidewalk", "building", "car", "pole", "fence", "other-object"} <= classes
    for sid, cls in labels.classes.items():
        if "_pilaster" in sid or "_window_" in sid:
            assert cls == "building"
            walls = sid.split("_window_")[0].split("_pilaster")[0] + "_walls"
            assert labels.instances[sid] == labels.instances[walls]
