"""Semantic classes of LiDAR points: names and ids, compatible with SemanticKITTI.

The ids are SemanticKITTI's raw label ids (Behley et al., "SemanticKITTI: A Dataset for Semantic
Scene Understanding of LiDAR Sequences", ICCV 2019; the label table is ``labels`` in
``config/semantic-kitti.yaml`` of the semantic-kitti-api repository), so a simulated cloud can be
scored with SemanticKITTI tools as it is. Names are SemanticKITTI's too. Id 0 (``unlabeled``) is
what a point gets whose shape the scene did not label. The moving-object ids (252-259) and
``outlier`` (1) describe measurements, not surfaces, and are not offered.

=====  =================  ===================================================================
id     name               what a scene labels with it
=====  =================  ===================================================================
0      unlabeled          (no label declared)
10     car                cars, vans: body, glass, wheels
11     bicycle            bicycles
13     bus                buses
15     motorcycle         motorcycles
16     on-rails           trams, trains
18     truck              trucks
20     other-vehicle      trailers, caravans, construction vehicles
30     person             pedestrians
31     bicyclist          a person riding a bicycle
32     motorcyclist       a person riding a motorcycle
40     road               drivable road surface
44     parking            parking bays and lots
48     sidewalk           sidewalks, kerbs
49     other-ground       other ground a vehicle or person moves on (paths, traffic islands)
50     building           buildings with their windows and doors
51     fence              fences, walls that enclose
52     other-structure    bridges, tunnels, shelves and other built structure
60     lane-marking       paint on the road
70     vegetation         tree crowns, bushes, hedges
71     trunk              tree trunks
72     terrain            grass, soil, sand
80     pole               poles of signs and lights, lamp posts
81     traffic-sign       sign faces and their back plates
99     other-object       everything else (bins, benches, crates, calibration panels)
=====  =================  ===================================================================
"""

from __future__ import annotations

from types import MappingProxyType

__all__ = ["CLASSES", "UNLABELED", "class_id", "class_name"]

#: Class name -> SemanticKITTI id.
CLASSES = MappingProxyType(
    {
        "unlabeled": 0,
        "car": 10,
        "bicycle": 11,
        "bus": 13,
        "motorcycle": 15,
        "on-rails": 16,
        "truck": 18,
        "other-vehicle": 20,
        "person": 30,
        "bicyclist": 31,
        "motorcyclist": 32,
        "road": 40,
        "parking": 44,
        "sidewalk": 48,
        "other-ground": 49,
        "building": 50,
        "fence": 51,
        "other-structure": 52,
        "lane-marking": 60,
        "vegetation": 70,
        "trunk": 71,
        "terrain": 72,
        "pole": 80,
        "traffic-sign": 81,
        "other-object": 99,
    }
)
#: The id of a point whose shape carries no label.
UNLABELED = 0
_NAMES = {v: k for k, v in CLASSES.items()}


def class_id(name: str) -> int:
    """SemanticKITTI id of a class name.

    Raises:
        ValueError: unknown name (the message lists the known ones).
    """
    try:
        return CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown label '{name}' (known: {', '.join(CLASSES)})") from None


def class_name(label_id: int) -> str:
    """Class name of a SemanticKITTI id.

    Raises:
        ValueError: an id this table does not hold.
    """
    try:
        return _NAMES[int(label_id)]
    except KeyError:
        raise ValueError(f"unknown label id {label_id}") from None
