"""Labels: the class table against SemanticKITTI, the scene declaration, and labels per point."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.labels import CLASSES, class_id, class_name, strip_labels


def test_class_ids_are_semantic_kitti_ids():
    # config/semantic-kitti.yaml (semantic-kitti-api), the raw label ids of SemanticKITTI
    reference = {
        "car": 10, "bicycle": 11, "bus": 13, "motorcycle": 15, "on-rails": 16, "truck": 18,
        "other-vehicle": 20, "person": 30, "bicyclist": 31, "motorcyclist": 32, "road": 40,
        "parking": 44, "sidewalk": 48, "other-ground": 49, "building": 50, "fence": 51,
        "other-structure": 52, "lane-marking": 60, "vegetation": 70, "trunk": 71,
        "terrain": 72, "pole": 80, "traffic-sign": 81, "other-object": 99, "unlabeled": 0,
    }  # fmt: skip
    assert dict(CLASSES) == reference
    assert all(class_name(i) == n for n, i in reference.items())
    with pytest.raises(ValueError, match="unknown label 'lamp'"):
        class_id("lamp")


def test_strip_labels_reads_and_removes_the_attributes():
    xml = (
        '<scene version="3.0.0"><shape type="cube" id="body" label="car" instance="car_1"/>'
        '<shape type="sphere" id="wheel" label="car" instance="car_1"/>'
        '<shape type="rectangle" id="road" label="road"/><shape type="sphere" id="x"/></scene>'
    )
    out, labels = strip_labels(xml)
    assert "label=" not in out and "instance=" not in out and 'id="body"' in out
    assert labels.classes == {"body": "car", "wheel": "car", "road": "road"}
    assert labels.instances == {"body": "car_1", "wheel": "car_1"}
    plain = '<scene version="3.0.0"><shape type="sphere" id="x"/></scene>'
    assert strip_labels(plain) == (plain, type(labels)())


@pytest.mark.parametrize(
    "shape, message",
    [
        ('<shape type="cube" id="a" label="lamp"/>', "shape 'a': unknown label 'lamp'"),
        ('<shape type="cube" label="road"/>', "needs an id"),
        ('<shape type="cube" id="a" label="$cls"/>', "must be a literal name"),
        (
            '<shape type="cube" id="a" label="car" instance="i"/>'
            '<shape type="cube" id="b" label="road" instance="i"/>',
            "instance 'i' has shapes of two classes",
        ),
    ],
)
def test_strip_labels_refuses_bad_declarations(shape, message):
    with pytest.raises(NidarError, match=message):
        strip_labels(f'<scene version="3.0.0">{shape}</scene>')


SCENE = """
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="-10, -30"/>
        <integer name="horizontal_resolution" value="8"/>
        <transform name="to_world"><translate z="2"/></transform>
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="0.5"/></bsdf>
    <shape type="rectangle" id="road" label="road">
        <transform name="to_world"><scale value="100"/></transform><ref id="grey"/></shape>
    <shape type="cube" id="zz_body" label="car" instance="car_7">
        <transform name="to_world"><translate x="3.234" y="1.339" z="1"/></transform>
        <ref id="grey"/></shape>
    <shape type="cube" id="aa_part" label="car" instance="car_7">
        <transform name="to_world"><translate x="-1.339" y="3.234" z="1"/></transform>
        <ref id="grey"/></shape>
    <shape type="cube" id="crate">
        <transform name="to_world"><translate x="-3.234" y="-1.339" z="1"/></transform>
        <ref id="grey"/></shape>
"""


def test_points_carry_the_label_and_instance_of_the_shape_hit(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    loaded = load_scene(write_scene(SCENE))
    r = scan(loaded.scene, loaded.lidars[0], labels=loaded.labels)
    pts = r.points()
    names = list(pts["instance_names"])
    assert names == ["", "car_7", "crate", "road"]  # sorted names, 0 = none
    # the geometry: 8 columns at azimuth (j + 0.5) * 45 deg; 2 m cubes centred 3.5 m out at
    # 22.5 (zz_body), 112.5 (aa_part) and 202.5 deg (crate) stop both rings of columns 0, 2, 4;
    # every other beam meets the road (at 11.3 m and 3.5 m)
    want_shape = {0: "zz_body", 2: "aa_part", 4: "crate"}
    ids = [s.id() for s in loaded.scene.shapes()]
    for ring, col, label, inst in zip(pts["ring"], pts["column"], pts["label"], pts["instance"]):
        shape = ids[r.shape_index[ring, col]]
        assert shape == want_shape.get(int(col), "road")
        want = {"road": (40, "road"), "crate": (0, "crate")}.get(shape, (10, "car_7"))
        assert (label, names[inst]) == want, (ring, col, shape)
    assert pts["label"].dtype == np.uint16 and pts["instance"].dtype == np.uint32
    assert len(pts["label"]) == 16 and sorted(pts["label"]) == [0] * 2 + [10] * 4 + [40] * 10
    assert np.all(r.shape_index[~r.hit] == -1)


def test_scan_without_labels_leaves_points_unlabelled(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    loaded = load_scene(write_scene(SCENE))
    pts = scan(loaded.scene, loaded.lidars[0]).points()
    assert np.all(pts["label"] == 0)
    # every shape is its own instance, named by its id
    assert set(pts["instance_names"][pts["instance"]]) <= {"road", "zz_body", "aa_part", "crate"}


@pytest.mark.parametrize("name", ["street", "park", "parking_lot", "warehouse", "target"])
def test_hand_made_scenes_label_every_shape(name):
    import os
    import xml.etree.ElementTree as ET

    path = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", f"{name}.xml")
    with open(path, encoding="utf-8") as f:
        text = f.read()
    ids = [el.get("id") for el in ET.fromstring(text).iter("shape")]
    _, labels = strip_labels(text)
    assert sorted(labels.classes) == sorted(ids)
