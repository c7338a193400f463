"""Loop-closure detection along a drive and its precision / recall.

For every frame ``i`` (the query), the database is every frame driven at least ``skip_m`` m
earlier (the reference implementation of Intensity Scan Context skips the last 20 m). The
``candidates`` database frames with the nearest :func:`~.scan_context.ring_key` are matched in
full (:func:`~.scan_context.geometry_similarity`, then
:func:`~.scan_context.value_similarity` around the best shift); the candidate with the highest
value similarity among those passing the geometry gate is the query's match, its similarity the
score.

Ground truth: a query is a *revisit* when some database frame lies within ``radius_m`` of it (true
positions); a match is *correct* when it does. At a threshold τ, a query with score ≥ τ is a
detected loop: a true positive when its match is correct, else a false positive. Precision =
TP / detected, recall = TP / revisits. :func:`pr_summary` gives the average precision (area under
the stepwise PR curve), the best F1, the recall at 100 % precision and the *correct-loop rate*:
the fraction of revisits whose match is correct (no threshold).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scan_context import geometry_similarity, ring_key, value_similarity

__all__ = ["GEOMETRY_GATE", "Matches", "match_drive", "pr_curve", "pr_summary"]

#: The reference implementation's geometry threshold.
GEOMETRY_GATE = 0.67


@dataclass
class Matches:
    """The best match of every query of a drive.

    Attributes:
        match: (N,) int, index of the matched frame; -1 where there was no candidate.
        score: (N,) float, its value similarity (-inf where none).
        shift: (N,) int, the column shift of the match (sectors).
        revisit: (N,) bool, the query has a database frame within the radius.
        correct: (N,) bool, the match lies within the radius.
    """

    match: np.ndarray
    score: np.ndarray
    shift: np.ndarray
    revisit: np.ndarray
    correct: np.ndarray


def match_drive(
    grids: np.ndarray,
    occupied: np.ndarray,
    positions: np.ndarray,
    distance: np.ndarray,
    *,
    skip_m: float = 20.0,
    radius_m: float = 5.0,
    candidates: int = 10,
    gate: float = GEOMETRY_GATE,
) -> Matches:
    """Match every frame of a drive against the frames driven before it.

    Args:
        grids: (N, rings, sectors) descriptors (values in [0, 1]).
        occupied: (N, rings, sectors) bool occupancy.
        positions: (N, 3) true positions, m (ground truth only).
        distance: (N,) distance driven up to each frame, m (odometry is enough).
        skip_m: the database ends this far back along the drive.
        radius_m: a match within this distance is correct.
        candidates: database frames matched in full, by nearest ring key.
        gate: geometry similarity a candidate needs.
    """
    n = len(grids)
    keys = np.stack([ring_key(g) for g in grids])
    match = np.full(n, -1)
    score = np.full(n, -np.inf)
    shift = np.zeros(n, dtype=int)
    revisit = np.zeros(n, dtype=bool)
    correct = np.zeros(n, dtype=bool)
    for i in range(n):
        db = np.nonzero(distance <= distance[i] - skip_m)[0]
        if len(db) == 0:
            continue
        near = np.linalg.norm(positions[db] - positions[i], axis=1) < radius_m
        revisit[i] = bool(near.any())
        order = np.argsort(np.linalg.norm(keys[db] - keys[i], axis=1), kind="stable")
        for j in db[order[:candidates]]:
            geo, k = geometry_similarity(occupied[i], occupied[j])
            if geo < gate:
                continue
            s = value_similarity(grids[i], grids[j], k)
            if s > score[i]:
                match[i], score[i], shift[i] = j, s, k
        if match[i] >= 0:
            correct[i] = bool(np.linalg.norm(positions[match[i]] - positions[i]) < radius_m)
    return Matches(match, score, shift, revisit, correct)


def pr_curve(m: Matches) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision and recall at every threshold (the scores of the matched queries, descending).

    Returns:
        (thresholds, precision, recall), each (K,); empty when nothing matched or nothing is a
        revisit.
    """
    has = m.match >= 0
    revisits = int(m.revisit.sum())
    if not has.any() or revisits == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    order = np.argsort(-m.score[has], kind="stable")
    s = m.score[has][order]
    tp = np.cumsum(m.correct[has][order])
    k = np.arange(1, len(s) + 1)
    last = np.r_[s[1:] != s[:-1], True]  # one point per distinct threshold
    return s[last], (tp / k)[last], (tp / revisits)[last]


def pr_summary(m: Matches) -> dict:
    """Average precision, best F1, recall at 100 % precision, correct-loop rate and counts."""
    thr, p, r = pr_curve(m)
    revisits = int(m.revisit.sum())
    out = {
        "queries": int((m.match >= -1).sum()),
        "revisits": revisits,
        "correct_loop_rate": float(m.correct[m.revisit].mean()) if revisits else None,
    }
    if len(thr) == 0:
        return out | {"average_precision": None, "max_f1": None, "recall_at_p100": None}
    ap = float(np.sum(np.diff(np.r_[0.0, r]) * p))
    f1 = np.where(p + r > 0, 2 * p * r / np.maximum(p + r, 1e-12), 0.0)
    full = p >= 1.0
    return out | {
        "average_precision": ap,
        "max_f1": float(f1.max()),
        "recall_at_p100": float(r[full].max()) if full.any() else 0.0,
    }
