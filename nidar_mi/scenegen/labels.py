"""The semantic class and instance of each generated shape (written as ``label`` / ``instance``).

The builders name their shapes systematically (``car_left_3_wheel_front_left``,
``tree_right_2_crown_1``, ``bldg_left_0_window_1_2``...); :func:`shape_label` maps those names
to a class of :mod:`nidar_mi.labels.classes` and groups the parts of one object into one
instance (a car's body, glass, roof and wheels; a building's walls, roof, windows and door).
Instances never mix classes: a tree's trunk (``trunk``) and crown (``vegetation``) are two.
Ground cover is ``terrain`` unless it is paved (``concrete``: ``other-ground``); clutter is
``other-object`` except a shrub (a sphere of a bush material: ``vegetation``).
"""

from __future__ import annotations

import re

from .objects import MATERIALS
from .primitives import Shape, Sphere

__all__ = ["shape_label"]

_PAVED = frozenset({"concrete", "asphalt_new", "asphalt_old"})

# (id pattern, class, instance template or None for the shape's own id); first match wins
_RULES: tuple[tuple[re.Pattern, str, str | None], ...] = tuple(
    (re.compile(p), c, i)
    for p, c, i in (
        (r"road|cross_road_(left|right)", "road", None),
        (r"(dash|line)_\d+_\d+|edge_(left|right)_\d+|zebra_\d+", "lane-marking", None),
        (r"sidewalk_(left|right)_\d+", "sidewalk", None),
        (r"path", "other-ground", None),
        (r"((bldg_(left|right)_\d+)|shed)_(walls|roof|door|window_\d+_\d+)", "building", r"\1"),
        (r"tree_((left|right)_)?\d+_trunk", "trunk", None),
        (r"(tree_((left|right)_)?\d+_crown)_\d+", "vegetation", r"\1"),
        (r"bush_\d+", "vegetation", None),
        (r"(light_((left|right)_)?\d+)_(pole|arm|lamp)", "pole", r"\1"),
        (r"sign_((left|right)_)?\d+_pole", "pole", None),
        (r"(sign_((left|right)_)?\d+)_(back|face)", "traffic-sign", r"\1"),
        (
            r"(car(_(lane|left|right)_\d+)?)_(body|cabin_glass|interior|roof|wheel_\w+)",
            "car",
            r"\1",
        ),
        (r"(clutter_\d+)_(seat|leg_\d+)", "other-object", r"\1"),
    )
)
_GROUND = re.compile(r"ground_base|ground_(left|right)(_\d+)?|patch_\d+")
_CLUTTER = re.compile(r"clutter_\d+")


def shape_label(shape: Shape) -> tuple[str, str | None] | None:
    """(class name, instance name or None for the shape's own id) of a generated shape; None
    for an id no rule knows (the shape is written without a label: ``unlabeled``)."""
    sid = shape.id
    if _GROUND.fullmatch(sid):
        return ("other-ground" if shape.material in _PAVED else "terrain"), None
    if _CLUTTER.fullmatch(sid):
        shrub = isinstance(shape, Sphere) and shape.material in MATERIALS["bush"]
        return ("vegetation" if shrub else "other-object"), None
    for pattern, cls, instance in _RULES:
        m = pattern.fullmatch(sid)
        if m:
            return cls, (m.expand(instance) if instance else None)
    return None
