"""A LightGBM regression's trees evaluated by one compiled loop: LightGBM's sums, faster.

``Booster.predict`` walks every tree of every row with a data-dependent branch per node; on a
``context`` profile's 400 trees of up to 63 leaves (depth 17 on average, up to 30) over the
~17 000 returns of a KITTI frame that is 0.8 to 0.9 s of CPU, most of it the branches the
processor mispredicts. :class:`Forest` holds the same trees as flat arrays and walks a block of
:data:`BLOCK` rows through one tree at a time in lock step until every row of the block has
reached its leaf, choosing each child by arithmetic rather than by a branch; a leaf is a node
whose two children are itself, so a row that reached its leaf stays there. That takes about
half the CPU (docs/BENCHMARKS.md, "NIDAR per frame with a ``context`` profile").

The rules are LightGBM's own (``Tree::NumericalDecision``, and the dense-row reading of its C
API): a value within :data:`ZERO` of zero is read as 0; a split sends ``x <= threshold`` left;
a missing value (NaN) goes the split's default way where the split's missing type is NaN and is
read as 0 where it is None; the leaf values are summed in float64 in tree order from 0. So every
row reaches LightGBM's leaves and its prediction equals ``Booster.predict``'s bit for bit
(tests/profiles/test_forest.py). Only what :func:`nidar_mi.profiles.gbm.load_booster` accepts
is read: a plain ``regression`` (identity output) of numerical splits; for any other model
:func:`compile_forest` gives None and the booster predicts.

The loop is compiled by numba (``nidar`` extra; cached on disk after the first compilation).
Compiled tree-evaluation libraries were weighed first: lleaves compiles one LLVM module per
model (seconds to minutes for 400 trees, at every new profile) and treelite needs a C compiler
at run time; numba compiles this one generic loop once for every model. Without numba
:func:`compile_forest` gives None (LightGBM predicts, the same values, slower).
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

__all__ = ["BLOCK", "ZERO", "Forest", "compile_forest"]

#: Rows walked through a tree together (their coordinates, BLOCK × features × 8 bytes, stay
#: in cache while every tree is walked).
BLOCK = 128
#: Magnitude at and below which LightGBM reads a value as zero (its ``kZeroThreshold``, the
#: float ``1e-35f`` as a double).
ZERO = float(np.float32(1e-35))


@dataclass(frozen=True)
class Forest:
    """The trees of a LightGBM regression as flat arrays over all trees' nodes (module
    docstring); leaves are nodes too.

    Attributes:
        feature: (M,) int64 the feature a node splits on (0 for a leaf).
        threshold: (M,) float64 the split value (``+inf`` for a leaf).
        nan_right: (M,) int64 1 where a missing value goes right.
        child: (2M,) int64 node ``k``'s left child at ``2k``, right at ``2k + 1`` (itself twice
            for a leaf).
        value: (M,) float64 the leaf values (0 for a split).
        root: (T,) int64 each tree's first node.
        depth: (T,) int64 each tree's depth (splits from the root to its deepest leaf).
        n_features: the number of input columns.
    """

    feature: np.ndarray
    threshold: np.ndarray
    nan_right: np.ndarray
    child: np.ndarray
    value: np.ndarray
    root: np.ndarray
    depth: np.ndarray
    n_features: int

    def __call__(self, x: np.ndarray, threads: int = 1) -> np.ndarray:
        """(N,) float64 predictions of (N, F) inputs (NaN: missing), ``threads`` threads each
        walking its own share of the rows (the rows are independent: the output does not
        depend on the split)."""
        walk = _compiled()
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(f"forest: expected (N, {self.n_features}) inputs, got {x.shape}")
        x = np.where(np.abs(x) <= ZERO, 0.0, x)  # C-contiguous, LightGBM's zeros
        out = np.empty(len(x))
        arrays = (self.feature, self.threshold, self.nan_right, self.child, self.value)
        arrays += (self.root, self.depth)
        blocks = -(-len(x) // BLOCK)
        cuts = np.linspace(0, blocks, min(max(int(threads), 1), blocks) + 1).astype(int) * BLOCK
        spans = [(a, min(b, len(x))) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
        if len(spans) <= 1:
            walk(x, arrays, out)
            return out
        with ThreadPoolExecutor(len(spans)) as pool:  # the compiled loop releases the GIL
            list(pool.map(lambda s: walk(x[s[0] : s[1]], arrays, out[s[0] : s[1]]), spans))
        return out


def _walk(x, trees, out):  # pragma: no cover
    """Fill (N,) ``out`` with the sums over the trees of the leaf each row of (N, F) ``x``
    reaches (compiled by :func:`_compiled`; ``trees``: :class:`Forest`'s arrays in order)."""
    feature, threshold, nan_right, child, value, root, depth = trees
    n = x.shape[0]
    acc = np.zeros(BLOCK)
    node = np.zeros(BLOCK, np.int64)
    for a in range(0, n, BLOCK):
        m = min(a + BLOCK, n) - a
        acc[:] = 0.0
        for t in range(root.shape[0]):
            for i in range(m):
                node[i] = root[t]
            for _ in range(depth[t]):
                moved = False
                for i in range(m):
                    k = node[i]
                    v = x[a + i, feature[k]]
                    # right: above the threshold, or missing and sent right (NaN compares false)
                    right = np.int64(v > threshold[k]) | (np.int64(v != v) & nan_right[k])
                    node[i] = child[2 * k + right]
                    moved |= node[i] != k
                if not moved:  # every row of the block at its leaf
                    break
            for i in range(m):
                acc[i] += value[node[i]]
        for i in range(m):
            out[a + i] = acc[i]


@functools.lru_cache(maxsize=1)
def _compiled():
    """The compiled :func:`_walk` (None without numba)."""
    try:
        import numba
    except ImportError:
        return None
    return numba.njit(nogil=True, cache=True)(_walk)


def compile_forest(text: str, n_features: int) -> Forest | None:
    """The :class:`Forest` of a LightGBM text model already checked by
    :func:`nidar_mi.profiles.gbm.load_booster` (``n_features`` inputs); None without numba, or
    for a model whose output is not the plain sum of its trees (an objective other than
    ``regression``)."""
    if _compiled() is None:
        return None
    body = text.partition("end of trees\n")[0]
    head, _, trees = body.partition("\n\n")
    if "\nobjective=regression\n" not in f"\n{head}\n":
        return None
    parts = {"feature": [], "threshold": [], "nan_right": [], "child": [], "value": []}
    root, depth = [], []
    for block in (b.strip("\n") for b in trees.split("\n\n")):
        if block.startswith("Tree="):
            root.append(len(parts["value"]))
            lines = (ln.split("=", 1) for ln in block.split("\n")[1:] if "=" in ln)
            depth.append(_add_tree(dict(lines), parts))
    ints = {"feature", "nan_right", "child"}
    arrays = {k: np.array(v, dtype=np.int64 if k in ints else np.float64) for k, v in parts.items()}
    return Forest(
        **arrays,
        root=np.array(root, dtype=np.int64),
        depth=np.array(depth, dtype=np.int64),
        n_features=int(n_features),
    )


def _add_tree(f: dict[str, str], parts: dict[str, list]) -> int:
    """Append one tree's nodes (its text fields ``f``) to ``parts``; its depth."""
    base = len(parts["value"])
    leaves = [float(v) for v in f["leaf_value"].split(" ")]
    n_split = len(leaves) - 1
    split = {k: f[k].split(" ") if n_split else [] for k in ("split_feature", "threshold")}
    kinds = [int(v) for v in f["decision_type"].split(" ")] if n_split else []
    left = [int(v) for v in f["left_child"].split(" ")] if n_split else []
    right = [int(v) for v in f["right_child"].split(" ")] if n_split else []
    node = lambda c: base + c if c >= 0 else base + n_split + ~c  # noqa: E731
    level = [0] * max(n_split, 1)
    deepest = 0
    for j in range(n_split):
        cut = float(split["threshold"][j])
        nan_left = bool(kinds[j] & 2) if (kinds[j] >> 2) & 3 == 2 else 0.0 <= cut
        parts["feature"].append(int(split["split_feature"][j]))
        parts["threshold"].append(cut)
        parts["nan_right"].append(0 if nan_left else 1)
        parts["child"] += [node(left[j]), node(right[j])]
        parts["value"].append(0.0)
        for c in (left[j], right[j]):  # children come after their parent
            if c >= 0:
                level[c] = level[j] + 1
            else:
                deepest = max(deepest, level[j] + 1)
    for v in leaves:
        k = len(parts["value"])
        parts["feature"].append(0)
        parts["threshold"].append(np.inf)
        parts["nan_right"].append(0)
        parts["child"] += [k, k]
        parts["value"].append(v)
    return deepest
