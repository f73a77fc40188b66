"""Predictions of compiled forests (``forest.Forest``), compiled (numba), exactly as
scikit-learn's ``RandomForestClassifier.predict_proba`` and ``predict``.

scikit-learn sends a row left at a node when ``x <= threshold`` (float32 ``x`` promoted to
float64, ``Tree.apply``), adds each tree's leaf value (class fractions) into float64 zeros
in tree order, divides by T (``ForestClassifier.predict_proba``) and predicts the class of
the first maximum. ``forest_sums`` does the same additions in the same order (the division
is left to the caller), so the probabilities are bit-identical; ``block_sums`` gives them
for many forests on shared columns in one call.

A tree's exit leaf for all rows is found QuickScorer-style when it has <= 64 leaves: leaves
are numbered left to right (node ids are depth-first preorder, left first, so a node's left
subtree holds the consecutive leaves ``[rank(left), rank(right))``); each row starts with
all 64 bits set and, at every internal node where it goes right, clears the bits of that
node's left subtree; its exit leaf is the lowest remaining bit. The loop over rows has no
branch and vectorises. Larger trees are walked node by node.

Arrays: ``ZT: (Dz, N)`` float32 test columns; ``colmap: (D,)`` int64 forest features to rows
of ``ZT``; node arrays as ``forest.Forest`` (flat over a forest's trees, ``tree_start: (T +
1,)``); ``value: (M, 2)`` float64 (column 1 unused for a forest of one class).
"""
from __future__ import annotations

import numpy as np
from numba import njit

FULL = np.uint64(0xFFFFFFFFFFFFFFFF)
ONE = np.uint64(1)
DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
SHIFT = np.uint64(58)
WIDTH = 64  # leaves per bitmask


def _debruijn_table() -> np.ndarray:
    t = np.zeros(64, np.int64)
    for i in range(64):
        t[((int(DEBRUIJN) << i) & 0xFFFFFFFFFFFFFFFF) >> 58] = i
    return t


CTZ = _debruijn_table()  # index of the lowest set bit of b: CTZ[((b & -b) * DEBRUIJN) >> 58]


@njit(cache=True)
def add_tree(feature, threshold, left, right, value, a, b, ZT, colmap, alive, rank, leaf_of, out):
    """Add the leaf value of every row's exit leaf, for the tree of nodes ``[a, b)``, to
    ``out: (2, N)``. Scratch: ``alive: (N,)`` uint64, ``rank, leaf_of: (M_t,)`` int64. A tree
    whose leaves are all pure (values exactly (1, 0) or (0, 1)) adds 1.0 to one column from
    its exit bit alone (the same float64 additions without looking the leaf up)."""
    n = ZT.shape[1]
    n_leaves = 0
    pure = True
    ones = np.uint64(0)
    for i in range(a, b):
        rank[i - a] = n_leaves
        if left[i] == -1:
            leaf_of[n_leaves] = i
            v0, v1 = value[i, 0], value[i, 1]
            if v0 == 0.0 and v1 == 1.0:
                if n_leaves < WIDTH:
                    ones |= ONE << np.uint64(n_leaves)
            elif not (v0 == 1.0 and v1 == 0.0):
                pure = False
            n_leaves += 1
    if n_leaves == 1:
        for r in range(n):
            out[0, r] += value[a, 0]
            out[1, r] += value[a, 1]
        return
    if n_leaves <= WIDTH:
        for r in range(n):
            alive[r] = FULL
        for i in range(a, b):
            if left[i] == -1:
                continue
            lo = np.uint64(rank[left[i]])
            hi = np.uint64(rank[right[i]])  # < 64: the right subtree holds a leaf
            m = ~(((ONE << hi) - ONE) ^ ((ONE << lo) - ONE))
            row = ZT[colmap[feature[i]]]
            t = threshold[i]
            for r in range(n):
                alive[r] &= m if np.float64(row[r]) > t else FULL
        if pure:
            for r in range(n):
                v = alive[r]
                c1 = (v & (~v + ONE) & ones) != np.uint64(0)
                out[0, r] += 0.0 if c1 else 1.0
                out[1, r] += 1.0 if c1 else 0.0
            return
        for r in range(n):
            v = alive[r]
            leaf = leaf_of[CTZ[((v & (~v + ONE)) * DEBRUIJN) >> SHIFT]]
            out[0, r] += value[leaf, 0]
            out[1, r] += value[leaf, 1]
        return
    for r in range(n):
        node = a
        while left[node] != -1:
            if np.float64(ZT[colmap[feature[node]], r]) <= threshold[node]:
                node = a + left[node]
            else:
                node = a + right[node]
        out[0, r] += value[node, 0]
        out[1, r] += value[node, 1]


@njit(cache=True)
def forest_sums(feature, threshold, left, right, value, tree_start, ZT, colmap):
    """``(2, N)`` float64 sums of the trees' leaf values in tree order, class by row
    (divide by T for ``predict_proba``)."""
    n = ZT.shape[1]
    out = np.zeros((2, n), np.float64)
    big = 1
    for t in range(tree_start.shape[0] - 1):
        big = max(big, tree_start[t + 1] - tree_start[t])
    alive = np.empty(n, np.uint64)
    rank = np.empty(big, np.int64)
    leaf_of = np.empty(big, np.int64)
    for t in range(tree_start.shape[0] - 1):
        add_tree(feature, threshold, left, right, value, tree_start[t], tree_start[t + 1], ZT, colmap, alive, rank,
                 leaf_of, out)
    return out


@njit(cache=True)
def block_sums(feature, threshold, left, right, value, tree_start, forest_trees, colmaps, colmap_start, ZT):
    """``(F, 2, N)`` leaf-value sums (``forest_sums``) of F forests: forest f's trees are
    ``forest_trees[f]:forest_trees[f + 1]`` of ``tree_start`` (node ids global over the
    block), its features ``colmaps[colmap_start[f]:colmap_start[f + 1]]``. The class code
    is 1 iff ``s1 / T > s0 / T`` (numpy's first maximum of ``predict_proba``)."""
    F = forest_trees.shape[0] - 1
    out = np.empty((F, 2, ZT.shape[1]), np.float64)
    for f in range(F):
        t0 = forest_trees[f]
        t1 = forest_trees[f + 1]
        a = tree_start[t0]
        b = tree_start[t1]
        out[f] = forest_sums(feature[a:b], threshold[a:b], left[a:b], right[a:b], value[a:b],
                             tree_start[t0: t1 + 1] - a, ZT, colmaps[colmap_start[f]: colmap_start[f + 1]])
    return out
