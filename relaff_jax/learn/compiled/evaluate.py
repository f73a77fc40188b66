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
def tree_exits(feature, threshold, left, right, a, b, ZT, colmap, alive, rank, leaf_of, exits):
    """Exit leaf (global node id) of every row for the tree of nodes ``[a, b)``, into
    ``exits: (N,)``. Scratch: ``alive: (N,)`` uint64, ``rank, leaf_of: (M_t,)`` int64."""
    n = ZT.shape[1]
    n_leaves = 0
    for i in range(a, b):
        rank[i - a] = n_leaves
        if left[i] == -1:
            leaf_of[n_leaves] = i
            n_leaves += 1
    if n_leaves == 1:
        for r in range(n):
            exits[r] = a
        return
    if n_leaves <= WIDTH:
        for r in range(n):
            alive[r] = FULL
        for i in range(a, b):
            if left[i] == -1:
                continue
            lo = np.uint64(rank[left[i]])
            hi = np.uint64(rank[right[i]])
            clear = ((ONE << hi) - ONE) if hi < np.uint64(64) else FULL
            clear ^= (ONE << lo) - ONE
            m = ~clear
            row = ZT[colmap[feature[i]]]
            t = threshold[i]
            for r in range(n):
                alive[r] &= m if np.float64(row[r]) > t else FULL
        for r in range(n):
            v = alive[r]
            low = v & (~v + ONE)
            exits[r] = leaf_of[CTZ[(low * DEBRUIJN) >> SHIFT]]
        return
    for r in range(n):
        node = a
        while left[node] != -1:
            if np.float64(ZT[colmap[feature[node]], r]) <= threshold[node]:
                node = a + left[node]
            else:
                node = a + right[node]
        exits[r] = node


@njit(cache=True)
def forest_sums(feature, threshold, left, right, value, tree_start, ZT, colmap):
    """``(N, 2)`` float64 sums of the trees' leaf values in tree order (divide by T for
    ``predict_proba``)."""
    n = ZT.shape[1]
    out = np.zeros((n, 2), np.float64)
    big = 1
    for t in range(tree_start.shape[0] - 1):
        big = max(big, tree_start[t + 1] - tree_start[t])
    alive = np.empty(n, np.uint64)
    rank = np.empty(big, np.int64)
    leaf_of = np.empty(big, np.int64)
    exits = np.empty(n, np.int64)
    for t in range(tree_start.shape[0] - 1):
        a = tree_start[t]
        b = tree_start[t + 1]
        tree_exits(feature, threshold, left, right, a, b, ZT, colmap, alive, rank, leaf_of, exits)
        for r in range(n):
            out[r, 0] += value[exits[r], 0]
            out[r, 1] += value[exits[r], 1]
    return out


@njit(cache=True)
def block_sums(feature, threshold, left, right, value, tree_start, forest_trees, colmaps, colmap_start, ZT):
    """``(F, N, 2)`` leaf-value sums (``forest_sums``) of F forests: forest f's trees are
    ``forest_trees[f]:forest_trees[f + 1]`` of ``tree_start`` (node ids global over the
    block), its features ``colmaps[colmap_start[f]:colmap_start[f + 1]]``. The class code
    is 1 iff ``s1 / T > s0 / T`` (numpy's first maximum of ``predict_proba``)."""
    F = forest_trees.shape[0] - 1
    out = np.empty((F, ZT.shape[1], 2), np.float64)
    for f in range(F):
        t0 = forest_trees[f]
        t1 = forest_trees[f + 1]
        a = tree_start[t0]
        b = tree_start[t1]
        out[f] = forest_sums(feature[a:b], threshold[a:b], left[a:b], right[a:b], value[a:b],
                             tree_start[t0: t1 + 1] - a, ZT, colmaps[colmap_start[f]: colmap_start[f + 1]])
    return out
