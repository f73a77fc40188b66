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
all bits set and, at every internal node where it goes right, clears the bits of that
node's left subtree; its exit leaf is the lowest remaining bit. The loop over rows has no
branch and vectorises. Larger trees are walked node by node. Trees of <= 32 leaves use
32-bit masks and float32 compares (twice the rows per vector): ``x > t`` iff ``x > t32``
for float32 ``x``, t32 the largest float32 <= t (``round_down_f32``; as ``evaluate``).

A forest whose leaves are all pure (values exactly (1, 0) or (0, 1), the usual fully grown
tree) adds exactly 0.0 or 1.0 per tree, so its float64 sums are the integer vote counts c
(<= T, exact in any order): ``forest_sums`` counts them in int32 (``add_votes``) and gives
``(T - c, c)``, the same bits as the additions in tree order (a stump in one pass over the
rows). Other forests add each tree's leaf values in tree order (``add_tree``).

Arrays: ``ZT: (Dz, N)`` float32 test columns; ``colmap: (D,)`` int64 forest features to rows
of ``ZT``; node arrays as ``forest.Forest`` (flat over a forest's trees, ``tree_start: (T +
1,)``); ``value: (M, 2)`` float64 (column 1 unused for a forest of one class).
"""
from __future__ import annotations

import numpy as np
from numba import njit

FULL = np.uint64(0xFFFFFFFFFFFFFFFF)
ONE = np.uint64(1)
FULL32 = np.uint32(0xFFFFFFFF)
ONE32 = np.uint32(1)
ZERO32 = np.uint32(0)
DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
SHIFT = np.uint64(58)
WIDTH = 64  # leaves per bitmask
WIDTH32 = 32  # leaves per 32-bit bitmask


def _debruijn_table() -> np.ndarray:
    t = np.zeros(64, np.int64)
    for i in range(64):
        t[((int(DEBRUIJN) << i) & 0xFFFFFFFFFFFFFFFF) >> 58] = i
    return t


CTZ = _debruijn_table()  # index of the lowest set bit of b: CTZ[((b & -b) * DEBRUIJN) >> 58]


@njit(cache=True, inline="always")
def round_down_f32(t):
    """The largest float32 <= t (float64 ``t``, finite)."""
    t32 = np.float32(t)
    if np.float64(t32) > t:
        t32 = np.nextafter(t32, np.float32(-np.inf))
    return t32


@njit(cache=True, inline="always")
def leaf_ranks(left, value, a, b, rank, leaf_of):
    """Leaves of the tree of nodes ``[a, b)`` numbered left to right: ``rank[i - a]`` the
    leaves before node i, ``leaf_of[k]`` leaf k's node. Returns (leaves, all pure, ones: bits
    of the leaves < 64 of value exactly (0, 1))."""
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
    return n_leaves, pure, ones


@njit(cache=True, inline="always")
def exit_bits32(feature, threshold, left, right, a, b, ZT, colmap, rank, alive32):
    """Every row's surviving leaf bits (``alive32: (N,)`` uint32) for a tree of <= 32 leaves."""
    n = ZT.shape[1]
    for r in range(n):
        alive32[r] = FULL32
    for i in range(a, b):
        if left[i] == -1:
            continue
        lo = np.uint32(rank[left[i]])
        hi = np.uint32(rank[right[i]])  # < 32: the right subtree holds a leaf
        m = ~(((ONE32 << hi) - ONE32) ^ ((ONE32 << lo) - ONE32))
        row = ZT[colmap[feature[i]]]
        t = round_down_f32(threshold[i])
        for r in range(n):
            alive32[r] &= m if row[r] > t else FULL32


@njit(cache=True, inline="always")
def exit_bits64(feature, threshold, left, right, a, b, ZT, colmap, rank, alive):
    """Every row's surviving leaf bits (``alive: (N,)`` uint64) for a tree of <= 64 leaves."""
    n = ZT.shape[1]
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


@njit(cache=True)
def add_tree(feature, threshold, left, right, value, a, b, ZT, colmap, alive, alive32, rank, leaf_of, out):
    """Add the leaf value of every row's exit leaf, for the tree of nodes ``[a, b)``, to
    ``out: (2, N)``. Scratch: ``alive: (N,)`` uint64, ``alive32: (N,)`` uint32, ``rank,
    leaf_of: (M_t,)`` int64."""
    n = ZT.shape[1]
    n_leaves, pure, ones = leaf_ranks(left, value, a, b, rank, leaf_of)
    if n_leaves == 1:
        for r in range(n):
            out[0, r] += value[a, 0]
            out[1, r] += value[a, 1]
        return
    if n_leaves <= WIDTH32:
        exit_bits32(feature, threshold, left, right, a, b, ZT, colmap, rank, alive32)
        for r in range(n):
            v = np.uint64(alive32[r])
            leaf = leaf_of[CTZ[((v & (~v + ONE)) * DEBRUIJN) >> SHIFT]]
            out[0, r] += value[leaf, 0]
            out[1, r] += value[leaf, 1]
        return
    if n_leaves <= WIDTH:
        exit_bits64(feature, threshold, left, right, a, b, ZT, colmap, rank, alive)
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
def add_votes(feature, threshold, left, right, value, a, b, ZT, colmap, alive, alive32, rank, leaf_of, votes):
    """Add 1 to ``votes: (N,)`` int32 for every row whose exit leaf, in the tree of nodes
    ``[a, b)`` with pure leaves only, has value (0, 1). Scratch as ``add_tree``."""
    n = ZT.shape[1]
    n_leaves, _, ones = leaf_ranks(left, value, a, b, rank, leaf_of)
    if n_leaves == 1:
        if value[a, 1] == 1.0:
            for r in range(n):
                votes[r] += 1
        return
    if n_leaves == 2:  # a stump: one pass
        row = ZT[colmap[feature[a]]]
        t = round_down_f32(threshold[a])
        vl = np.int32(value[a + left[a], 1] == 1.0)
        vr = np.int32(value[a + right[a], 1] == 1.0)
        for r in range(n):
            votes[r] += vr if row[r] > t else vl
        return
    if n_leaves <= WIDTH32:
        exit_bits32(feature, threshold, left, right, a, b, ZT, colmap, rank, alive32)
        ones32 = np.uint32(ones)
        for r in range(n):
            v = alive32[r]
            votes[r] += (v & (~v + ONE32) & ones32) != ZERO32
        return
    if n_leaves <= WIDTH:
        exit_bits64(feature, threshold, left, right, a, b, ZT, colmap, rank, alive)
        for r in range(n):
            v = alive[r]
            votes[r] += (v & (~v + ONE) & ones) != np.uint64(0)
        return
    for r in range(n):
        node = a
        while left[node] != -1:
            if np.float64(ZT[colmap[feature[node]], r]) <= threshold[node]:
                node = a + left[node]
            else:
                node = a + right[node]
        votes[r] += value[node, 1] == 1.0


@njit(cache=True)
def forest_sums(feature, threshold, left, right, value, tree_start, ZT, colmap):
    """``(2, N)`` float64 sums of the trees' leaf values in tree order, class by row
    (divide by T for ``predict_proba``); the vote counts of a forest of pure leaves."""
    n = ZT.shape[1]
    T = tree_start.shape[0] - 1
    out = np.zeros((2, n), np.float64)
    big = 1
    for t in range(T):
        big = max(big, tree_start[t + 1] - tree_start[t])
    alive = np.empty(n, np.uint64)
    alive32 = np.empty(n, np.uint32)
    rank = np.empty(big, np.int64)
    leaf_of = np.empty(big, np.int64)
    pure = True
    for i in range(tree_start[0], tree_start[T]):
        if left[i] == -1 and not ((value[i, 0] == 1.0 and value[i, 1] == 0.0) or (value[i, 0] == 0.0 and value[i, 1] == 1.0)):
            pure = False
            break
    if pure:
        votes = np.zeros(n, np.int32)
        for t in range(T):
            add_votes(feature, threshold, left, right, value, tree_start[t], tree_start[t + 1], ZT, colmap, alive,
                      alive32, rank, leaf_of, votes)
        for r in range(n):
            out[0, r] = np.float64(T - votes[r])
            out[1, r] = np.float64(votes[r])
        return out
    for t in range(T):
        add_tree(feature, threshold, left, right, value, tree_start[t], tree_start[t + 1], ZT, colmap, alive, alive32,
                 rank, leaf_of, out)
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
