"""How a scene declares the semantic class and instance of its shapes, and the per-shape tables.

A scene labels a shape with attributes on its ``<shape>`` element::

    <shape type="cube" id="car_body" label="car" instance="car_1"> ... </shape>
    <shape type="cylinder" id="wheel_fl" label="car" instance="car_1"> ... </shape>
    <shape type="rectangle" id="road" label="road"> ... </shape>

``label`` is a class name of :data:`nidar_mi.labels.classes.CLASSES` (SemanticKITTI names);
``instance`` (optional, a name) groups shapes into one object, and defaults to the shape's own
id. Mitsuba refuses attributes it does not know, so :func:`strip_labels` (run by
:func:`nidar_mi.scene.load_scene` before Mitsuba parses the XML) reads and removes them; the
declaration is a literal (no ``$parameter``). A labelled shape needs an ``id``.

Per point, ``label`` is the SemanticKITTI id of its shape's class (0 = ``unlabeled``: the shape
has no ``label``) and ``instance`` numbers the instance names 1..K in sorted order (0 = no
instance: no surface, or an anonymous shape); ``instance_names[k]`` is the name of instance
``k`` (``instance_names[0] = ""``). Numbering by sorted name keeps ids independent of
``scene.shapes()`` order, which is not the declaration order.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from ..errors import NidarError
from .classes import class_id

__all__ = ["SceneLabels", "ShapeLabels", "strip_labels", "shape_labels"]

_ATTRS = ("label", "instance")


@dataclass(frozen=True)
class SceneLabels:
    """What a scene declares, by shape id.

    Attributes:
        classes: shape id -> class name (only shapes with a ``label``).
        instances: shape id -> instance name (only shapes with an ``instance``).
    """

    classes: dict[str, str] = field(default_factory=dict)
    instances: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ShapeLabels:
    """Per-shape lookup tables, indexed like ``scene.shapes()``.

    Attributes:
        label: (S,) uint16 SemanticKITTI id of each shape.
        instance: (S,) uint32 instance id of each shape (0 = none).
        instance_names: (K+1,) str, ``instance_names[k]`` names instance k; ``[0] = ""``.
    """

    label: np.ndarray
    instance: np.ndarray
    instance_names: np.ndarray

    def lookup(self, shape_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(label uint16, instance uint32) of hits given their shape index (-1 = no hit)."""
        idx = np.asarray(shape_index)
        hit = idx >= 0
        safe = np.where(hit, idx, 0)
        if self.label.size == 0:
            return np.zeros(idx.shape, np.uint16), np.zeros(idx.shape, np.uint32)
        label = np.where(hit, self.label[safe], 0).astype(np.uint16)
        instance = np.where(hit, self.instance[safe], 0).astype(np.uint32)
        return label, instance


def strip_labels(xml_text: str) -> tuple[str, SceneLabels]:
    """Read and remove the ``label`` / ``instance`` attributes of every ``<shape>``.

    Args:
        xml_text: Mitsuba scene XML (after the material pass).

    Returns:
        (the XML without those attributes, the declaration). The text is returned unchanged
        when no shape carries them.

    Raises:
        NidarError: malformed XML, an unknown class name, a label on a shape without an id, a
            ``$parameter`` value, or one instance name used by shapes of different classes.
    """
    if not any(f' {a}="' in xml_text or f" {a}='" in xml_text for a in _ATTRS):
        return xml_text, SceneLabels()
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.fromstring(xml_text, parser=parser)
    except ET.ParseError as e:
        raise NidarError(f"scene XML does not parse: {e}") from None
    classes: dict[str, str] = {}
    instances: dict[str, str] = {}
    changed = False
    for el in root.iter("shape"):
        values = {a: el.attrib.pop(a) for a in _ATTRS if a in el.attrib}
        if not values:
            continue
        changed = True
        sid = el.get("id")
        if not sid:
            raise NidarError("a <shape> with a label or instance needs an id")
        for attr, value in values.items():
            if not value or value.startswith("$"):
                raise NidarError(f"shape '{sid}': {attr} must be a literal name (got '{value}')")
        if "label" in values:
            try:
                class_id(values["label"])
            except ValueError as e:
                raise NidarError(f"shape '{sid}': {e}") from None
            classes[sid] = values["label"]
        if "instance" in values:
            instances[sid] = values["instance"]
    _check_instances(classes, instances)
    if not changed:
        return xml_text, SceneLabels()
    return ET.tostring(root, encoding="unicode"), SceneLabels(classes, instances)


def _check_instances(classes: dict[str, str], instances: dict[str, str]) -> None:
    """One instance, one class."""
    seen: dict[str, tuple[str, str]] = {}
    for sid, inst in instances.items():
        cls = classes.get(sid, "unlabeled")
        if inst in seen and seen[inst][0] != cls:
            other = seen[inst][1]
            raise NidarError(
                f"instance '{inst}' has shapes of two classes: '{other}' is "
                f"{seen[inst][0]}, '{sid}' is {cls}"
            )
        seen.setdefault(inst, (cls, sid))


def shape_labels(scene, labels: SceneLabels | None = None) -> ShapeLabels:
    """Per-shape class and instance tables of a loaded scene.

    Args:
        scene: a loaded ``mi.Scene``.
        labels: its declaration (:attr:`nidar_mi.scene.LoadedScene.labels`); None: every shape
            is ``unlabeled`` and its own instance.

    Returns:
        Tables indexed like ``scene.shapes()`` (the shape index of
        :attr:`nidar_mi.lidar.scan.ScanResult.shape_index`).
    """
    labels = labels or SceneLabels()
    ids = [shape.id() for shape in scene.shapes()]
    names = [labels.instances.get(sid, sid) if sid else "" for sid in ids]
    order = sorted({n for n in names if n})
    number = {name: k + 1 for k, name in enumerate(order)}
    return ShapeLabels(
        label=np.array([class_id(labels.classes.get(sid, "unlabeled")) for sid in ids], np.uint16),
        instance=np.array([number.get(n, 0) for n in names], np.uint32),
        instance_names=np.array([""] + order, dtype=np.str_),
    )
