"""Semantic labels of simulated points: the classes (SemanticKITTI ids) and how a scene declares
them per shape. See :mod:`.classes` and :mod:`.scene_labels`."""

from .classes import CLASSES, UNLABELED, class_id, class_name
from .scene_labels import SceneLabels, ShapeLabels, shape_labels, strip_labels

__all__ = [
    "CLASSES",
    "UNLABELED",
    "SceneLabels",
    "ShapeLabels",
    "class_id",
    "class_name",
    "shape_labels",
    "strip_labels",
]
