"""Generated scenes declare a semantic class for every shape and group object parts."""

from __future__ import annotations

import re
from collections import Counter

import pytest

from nidar_mi.labels import strip_labels
from nidar_mi.scenegen.generate import generate_scene
from nidar_mi.scenegen.labels import shape_label
from nidar_mi.scenegen.primitives import Block


@pytest.mark.parametrize("k", range(12))
def test_every_generated_shape_is_labelled(k):
    layout, text = generate_scene(3, k)
    _, labels = strip_labels(text)  # validates names and one class per instance
    ids = [s.id for s in layout.shapes]
    assert set(labels.classes) == set(ids)
    assert "unlabeled" not in labels.classes.values()
    for sid, cls in labels.classes.items():
        if re.fullmatch(r"car(_\w+_\d+)?_(body|roof|wheel_\w+)", sid):
            assert cls == "car" and labels.instances[sid].startswith("car")


def test_object_parts_share_one_instance():
    classes: Counter = Counter()
    for k in range(12):
        layout, text = generate_scene(5, k)
        _, labels = strip_labels(text)
        for s in layout.shapes:
            classes[labels.classes[s.id]] += 1
            if s.id.startswith("car") and "_wheel_" in s.id:
                body = s.id.split("_wheel_")[0] + "_body"
                assert labels.instances[s.id] == labels.instances[body]
            if "_window_" in s.id:
                walls = s.id.split("_window_")[0] + "_walls"
                assert labels.instances[s.id] == labels.instances[walls]
    # urban and vegetated scenes together use the main classes
    assert {"road", "sidewalk", "building", "vegetation", "trunk", "car", "pole"} <= set(classes)


def test_unknown_part_names_stay_unlabelled():
    assert shape_label(Block("ufo", "concrete", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))) is None
    assert shape_label(Block("patch_3", "concrete", (0.0, 0.0, 0.0), (1.0, 1.0, 0.0)))[0] == (
        "other-ground"
    )
