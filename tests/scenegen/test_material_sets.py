"""Material sets: training scenes without the held-out materials, test scenes made of them."""

from __future__ import annotations

import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials.library import list_materials
from nidar_mi.scenegen.generate import generate_scene
from nidar_mi.scenegen.objects import HELDOUT_MATERIALS, MATERIALS, material_set, part_options


def test_every_part_keeps_a_training_material_and_the_held_out_ones_exist():
    assert HELDOUT_MATERIALS <= set(list_materials())
    for part in MATERIALS:
        assert part_options(part, "train"), part
        assert not set(part_options(part, "train")) & HELDOUT_MATERIALS
        held = set(part_options(part, "heldout"))
        assert held <= HELDOUT_MATERIALS or not set(MATERIALS[part]) & HELDOUT_MATERIALS
    used = {m for part in MATERIALS for m in MATERIALS[part]}
    assert HELDOUT_MATERIALS <= used  # every held-out material can appear in a test scene


def test_train_and_heldout_scenes():
    train = set().union(
        *(generate_scene(7, k, materials="train")[0].materials() for k in range(12))
    )
    held = set().union(
        *(generate_scene(7, k, materials="heldout")[0].materials() for k in range(12))
    )
    assert not train & HELDOUT_MATERIALS
    assert len(held & HELDOUT_MATERIALS) >= 8  # most held-out materials appear in 12 scenes
    # the default draws exactly as before (one generator, all options)
    assert generate_scene(7, 3)[1] == generate_scene(7, 3, materials="all")[1]
    with pytest.raises(NidarError, match="material set"), material_set("some"):
        pass
