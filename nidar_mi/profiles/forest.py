"""A LightGBM regression's trees evaluated by one compiled loop: LightGBM's sums, faster.

``Booster.predict`` walks every tree of every row with a data-dependent branch per node; on a
``context`` profile's 400 trees of up to 63 leaves (depths of 16 to 17 on average, up to 30) over the
~17 000 returns of a KITTI frame that is 0.8 to 0.9 s of CPU, most of it the branches the
processor mispredicts. :class:`Forest` holds the same trees as flat arrays and walks a block of
:data:`BLOCK` rows through one tree at a time, a level per step, choosing each child by
arithmetic rather than by a branch and keeping in a list the rows still at a split (the rows
of a block are independent, so the processor overlaps their steps). That takes 0.3 to 0.35 s
of CPU, some 2.5 times less (docs/BENCHMARKS.md, "NIDAR per frame with a ``context`` profile").

The rules are LightGBM's own (``Tree::NumericalDecision``, and the dense-row reading of its C
API): a value within :data:`ZERO` of zero is read as 0; a split sends ``x <= threshold`` left;
a missing value (NaN) goes the split's default way where the split's missing type is NaN and is
read as 0 where it is None; the leaf values are summed in float64 in tree order from 0. So every
row reaches LightGBM's leaves and its prediction equals ``Booster.predict``'s bit for bit
(tests/profiles/test_forest.py). Only what :func:`nidar_mi.profiles.gbm.load_booster` accepts
is read: a plain ``regression`` (identity output) of numerical splits; for any other model
:func:`compile_forest` gives None and the booster predicts.

The loop is compiled by numba (``nidar`` extra; cached on disk after the first compilation).
Compiled tree-evaluation libraries were weighed first: lleaves (1.3.0, its latest release)
compiles one LLVM module per model but does not run on the llvmlite that numba 0.68 needs
(0.50: ``llvmlite.binding`` no longer has the ``PassManagerBuilder`` lleaves calls), and
treelite needs a C compiler at run time; numba compiles this one generic loop once for every
model. Without numba
:func:`compile_forest` gives None (LightGBM predicts, the same values, slower).
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

__all__ = ["BLOCK", "ZERO", "Forest", "compile_forest"]

#: Rows walked through a tree together (their inputs, BLOCK × features × 8 bytes, stay in
#: cache while every tree is walked).
BLOCK = 128
#: Magnitude at and below which LightGBM reads a value as zero (its ``kZeroThreshold``, the
#: float ``1e-35f`` as a double).
ZERO = float(np.float32(1e-35))


@dataclass(frozen=True)
class Forest:
    """The trees of a LightGBM regression as flat arrays over all trees' splits and leaves
    (module docstring).

    Attributes:
        split: (M,) int64 per split, ``2 × feature + nan_right``: the input column it reads and
            1 where a missing value goes right.
        threshold: (M,) float64 per split, the value at and below which a row goes left.
        child: (2M,) int64 split ``k``'s left child at ``2k``, its right at ``2k + 1``: a split's
            index, or ``~j`` (negative) for leaf ``j``.
        value: (L,) float64 the leaves' values.
        root: (T,) int64 each tree's first node (a split's index, or ``~j`` for a tree that is
            one leaf).
        n_features: the number of input columns.
    """

    split: np.ndarray
    threshold: np.ndarray
    child: np.ndarray
    value: np.ndarray
    root: np.ndarray
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
        arrays = (self.split, self.threshold, self.child, self.value, self.root)
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
    reaches (compiled by :func:`_compiled`; ``trees``: :class:`Forest`'s arrays in order).

    Per block of rows and tree, every step moves the rows still at a split one level down
    and keeps those that reached a split again, with that split, in the lists ``live`` and
    ``at`` (written without a branch), until none is left; ``node`` holds each row's leaf."""
    split, threshold, child, value, root = trees
    acc = np.zeros(BLOCK)
    node = np.zeros(BLOCK, np.int64)
    live = np.zeros(BLOCK, np.int64)  # the rows still at a split
    at = np.zeros(BLOCK, np.int64)  # and that split
    for a in range(0, x.shape[0], BLOCK):
        m = min(a + BLOCK, x.shape[0]) - a
        acc[:] = 0.0
        for t in range(root.shape[0]):
            k = root[t]
            if k < 0:  # a tree of one leaf
                for i in range(m):
                    acc[i] += value[~k]
                continue
            kept = 0
            left, right = child[2 * k], child[2 * k + 1]
            for i in range(m):  # the root's split, the same for every row
                v = x[a + i, split[k] >> 1]
                go = (v > threshold[k]) | ((v != v) & ((split[k] & 1) == 1))
                node[i] = right if go else left
                live[kept], at[kept] = i, node[i]
                kept += node[i] >= 0
            count = kept
            while count > 0:
                kept = 0
                for j in range(count):
                    i, k = live[j], at[j]
                    v = x[a + i, split[k] >> 1]
                    # right: above the threshold, or missing and sent right (NaN compares false)
                    go = np.int64(v > threshold[k]) | (np.int64(v != v) & (split[k] & 1))
                    node[i] = child[2 * k + go]
                    live[kept], at[kept] = i, node[i]
                    kept += node[i] >= 0
                count = kept
            for i in range(m):
                acc[i] += value[~node[i]]
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
    parts = {"split": [], "threshold": [], "child": [], "value": []}
    root = []
    for block in (b.strip("\n") for b in trees.split("\n\n")):
        if block.startswith("Tree="):
            lines = (ln.split("=", 1) for ln in block.split("\n")[1:] if "=" in ln)
            root.append(_add_tree(dict(lines), parts))
    return Forest(
        split=np.array(parts["split"], dtype=np.int64),
        threshold=np.array(parts["threshold"], dtype=np.float64),
        child=np.array(parts["child"], dtype=np.int64),
        value=np.array(parts["value"], dtype=np.float64),
        root=np.array(root, dtype=np.int64),
        n_features=int(n_features),
    )


def _add_tree(f: dict[str, str], parts: dict[str, list]) -> int:
    """Append one tree's splits and leaves (its text fields ``f``) to ``parts``; its root."""
    first, base = len(parts["threshold"]), len(parts["value"])
    leaves = [float(v) for v in f["leaf_value"].split(" ")]
    parts["value"] += leaves
    if len(leaves) == 1:
        return ~base
    fields = ("split_feature", "threshold", "decision_type", "left_child", "right_child")
    columns = zip(*(f[k].split(" ") for k in fields), strict=True)
    node = lambda c: first + c if c >= 0 else ~(base + ~c)  # noqa: E731
    for feature, cut, kind, left, right in columns:
        cut, kind = float(cut), int(kind)
        nan_left = bool(kind & 2) if (kind >> 2) & 3 == 2 else 0.0 <= cut
        parts["split"].append(2 * int(feature) + (0 if nan_left else 1))
        parts["threshold"].append(cut)
        parts["child"] += [node(int(left)), node(int(right))]
    return first
