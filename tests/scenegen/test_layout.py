"""Layout sampling: determinism, variety, materials from the library, rig ranges."""

import math

import numpy as np
import pytest

from nidar_mi.materials import list_materials
from nidar_mi.scenegen.layout import KINDS, sample_layout
from nidar_mi.scenegen.objects import MATERIALS
from nidar_mi.scenegen.primitives import Cylinder, Sphere


def _layout(seed: int, kind=None):
    return sample_layout(np.random.default_rng(seed), kind)


@pytest.mark.parametrize("kind", KINDS)
def test_same_generator_state_same_layout(kind):
    assert _layout(7, kind) == _layout(7, kind)


def test_different_seeds_give_different_layouts_and_materials():
    layouts = [_layout(s, "urban") for s in range(4)] + [_layout(s, "vegetated") for s in range(4)]
    for i, a in enumerate(layouts):
        for b in layouts[i + 1 :]:
            assert a.shapes != b.shapes
            assert a.rig != b.rig
    assert len({tuple(x.materials()) for x in layouts}) == len(layouts)


def test_every_material_is_in_the_library():
    library = set(list_materials())
    assert {m for options in MATERIALS.values() for m in options} <= library
    for seed in range(6):
        assert set(_layout(seed).materials()) <= library


def test_shape_ids_are_unique():
    for seed in range(6):
        ids = [s.id for s in _layout(seed).shapes]
        assert len(ids) == len(set(ids))


@pytest.mark.parametrize("kind", KINDS)
def test_rig_within_documented_ranges(kind):
    for seed in range(10):
        rig = _layout(seed, kind).rig
        assert rig.lidar_preset in ("hdl64e", "vlp16")
        assert 1.6 <= rig.lidar_position[2] <= 2.0
        assert 70.0 <= rig.camera_fov_deg <= 90.0
        offset = np.subtract(rig.camera_position, rig.lidar_position)
        assert np.linalg.norm(offset[:2]) <= math.hypot(0.4, 0.15) + 1e-9
        assert -0.15 - 1e-9 <= offset[2] <= 1e-9
        assert abs(rig.camera_yaw_deg - rig.lidar_yaw_deg) <= 4.0 + 1e-6
        assert -6.0 <= rig.camera_pitch_deg <= 0.0


@pytest.mark.parametrize("kind", KINDS)
def test_nothing_stands_on_the_rig(kind):
    """No pole or trunk within 1 m of the rig's footprint, no crown or boulder within 1 m of
    either sensor."""
    for seed in range(40):
        layout = _layout(seed, kind)
        rig = layout.rig
        x0, y0, _ = rig.lidar_position
        for s in layout.shapes:
            if isinstance(s, Cylinder):
                d = math.hypot(s.p0[0] - x0, s.p0[1] - y0) - s.radius
            elif isinstance(s, Sphere):
                d = min(
                    math.dist(s.center, rig.lidar_position),
                    math.dist(s.center, rig.camera_position),
                )
                d -= s.radius
            else:
                continue
            assert d > 1.0, (seed, s.id)


def test_urban_layouts_hold_every_street_object():
    found = set()
    for seed in range(8):
        ids = " ".join(s.id for s in _layout(seed, "urban").shapes)
        for key in ("road", "dash", "edge", "sidewalk", "bldg", "car", "light", "sign", "tree"):
            if key in ids:
                found.add(key)
    assert found == {"road", "dash", "edge", "sidewalk", "bldg", "car", "light", "sign", "tree"}


def test_kind_mix_and_bad_kind():
    kinds = {_layout(s).kind for s in range(12)}
    assert kinds == set(KINDS)
    with pytest.raises(ValueError, match="unknown layout kind"):
        _layout(0, "desert")
