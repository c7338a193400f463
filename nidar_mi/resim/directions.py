"""The returns of one scan around a direction seen from its sensor: unit directions, a k-d tree
over them (scipy's ``cKDTree``: the nearest by chord, which orders as the angle does) and every
return within an angle of a direction. Shared by the tests of the training scans beside a
held-out frame (:mod:`.holes`, :mod:`.seen_through`)."""

from __future__ import annotations

import numpy as np

__all__ = [
    "RADIUS_NEIGHBOURS",
    "unit_directions",
    "direction_tree",
    "chord",
    "around",
    "TreeCache",
]

#: Returns looked at within the radius of a direction (an HDL-64E has about 20 within 0.7° on a
#: surface that returns everywhere); a direction with this many is taken as full.
RADIUS_NEIGHBOURS = 64


def unit_directions(xyz: np.ndarray) -> np.ndarray:
    """(N, 3) the unit directions of (N, 3) points from the sensor (the origin)."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    n = np.linalg.norm(xyz, axis=1, keepdims=True)
    return xyz / np.maximum(n, 1e-12)


def direction_tree(real: np.ndarray):
    """A k-d tree (scipy's ``cKDTree``) of the unit directions of (N, 3) returns."""
    from scipy.spatial import cKDTree

    return cKDTree(unit_directions(real))


def chord(radius_deg: float) -> float:
    """The chord between two unit directions ``radius_deg`` degrees apart."""
    return 2.0 * np.sin(np.radians(radius_deg) / 2.0)


def around(tree, unit: np.ndarray, chord_len: float, n_real: int):
    """``(hit, idx, full)`` of the returns within ``chord_len`` of each of the (M, 3) unit
    directions: (M, K) bool and (M, K) int (the return's index where ``hit``; clipped into
    range elsewhere), K = min(:data:`RADIUS_NEIGHBOURS`, ``n_real``), and (M,) bool where all
    :data:`RADIUS_NEIGHBOURS` slots hold a return (more may lie within the radius)."""
    k = min(RADIUS_NEIGHBOURS, n_real)
    d, i = tree.query(unit, k=k, distance_upper_bound=chord_len)
    d, i = np.reshape(d, (len(unit), k)), np.reshape(i, (len(unit), k))
    hit = np.isfinite(d)
    full = hit[:, -1] & (k == RADIUS_NEIGHBOURS)
    return hit, np.minimum(i, n_real - 1), full


class TreeCache:
    """``cache(j)``: :func:`direction_tree` of scan ``scans[j]``, built once, the last ``keep``
    kept (a held-out frame's evidence scans serve every re-simulated scan of it)."""

    def __init__(self, scans, keep: int = 4):
        self.scans, self.keep = scans, keep
        self._trees: dict[int, object] = {}

    def __call__(self, j: int):
        if j not in self._trees:
            if len(self._trees) >= self.keep:
                self._trees.pop(next(iter(self._trees)))
            self._trees[j] = direction_tree(self.scans[j])
        return self._trees[j]
