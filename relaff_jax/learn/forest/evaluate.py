"""Predictions of fitted forests (``fit.Trees``), bit-identical to scikit-learn's.

Takes forests and test rows; gives ``predict_proba`` ``(N, K)`` float64 and predicted
classes. Two exact paths:

- ``predict_proba`` / ``predict_labels``: scikit-learn's own traversal (``Tree.predict``,
  float32 rows against float64 thresholds) and its summation: per-tree leaf fractions added
  in tree order into float64 zeros, then divided by T (``ForestClassifier.predict_proba``);
  the class is ``classes[argmax]`` (first maximum).
- ``predict_block``: many small forests at once in one jitted JAX program (QuickScorer
  bitmasks). Each tree's internal nodes ``(I,)`` carry a feature column, a float32
  threshold and a 32-bit mask of the leaves NOT in their left subtree; a row's exit leaf
  is the lowest bit of the AND of the masks of the nodes it goes right at (leaves numbered
  left to right: node ids are depth-first preorder, left first). Used for forests whose
  trees have <= 32 leaves, all pure (leaf fractions 0 or 1); others take the first path.

Exactness. scikit-learn tests ``x <= t`` with x float32 promoted to double and t float64.
With t32 the largest float32 <= t (``round_down_f32``), ``x <= t`` iff ``x <= t32`` for
every float32 x: x <= t implies x <= t32 as t32 is the largest float32 <= t, and x <= t32
implies x <= t. With pure leaves each tree adds exactly 0.0 or 1.0, so scikit-learn's
float64 sums are the integer vote counts c (<= 115, exact in any order) and its proba is
(T - c) / T, c / T: class 1 iff c > T - c (distinct integers over T <= 115 stay distinct
after rounding; a tie is class 0, numpy's first maximum).

Arrays: ``ZT: (Dz, N)`` float32 test columns shared by a block's forests (each forest maps
its features to columns of ``ZT`` with ``colmap: (D,)``).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.learn.forest.fit import Trees

WORD = 32  # leaves per bitmask word; deeper trees take the scikit-learn path
FULL = np.uint32(0xFFFFFFFF)


def round_down_f32(t: np.ndarray) -> np.ndarray:
    """The largest float32 <= t, elementwise, for float64 ``t``."""
    t = np.asarray(t, dtype=np.float64)
    t32 = t.astype(np.float32)
    return np.where(t32.astype(np.float64) > t, np.nextafter(t32, np.float32(-np.inf)), t32).astype(np.float32)


def predict_proba(forest: Trees, X: np.ndarray) -> np.ndarray:
    """``(N, K)`` float64 class probabilities, as ``RandomForestClassifier.predict_proba``."""
    X = np.asarray(X, dtype=np.float32)
    k = len(forest.classes)
    out = np.zeros((X.shape[0], k), dtype=np.float64)
    for tree in forest.trees:
        out += tree.predict(X)[:, :k]
    out /= len(forest.trees)
    return out


def predict_labels(forest: Trees, X: np.ndarray) -> np.ndarray:
    """Predicted labels ``(N,)`` (dtype of the training labels), as ``predict``."""
    return forest.classes.take(np.argmax(predict_proba(forest, X), axis=1), axis=0)


def pack_forest(forest: Trees, colmap: np.ndarray | None = None) -> dict | None:
    """One forest as bitmask arrays, or None if it needs the scikit-learn path.

    Returns ``feat: (T, I)`` int32 columns of ``ZT`` (``colmap[feature]``), ``thr: (T, I)``
    float32 (rounded down), ``mask: (T, I)`` uint32, ``ones: (T,)`` uint32 (bits of the
    class-1 leaves). Forests that saw one class are not packed (they predict it everywhere).
    """
    if len(forest.classes) != 2:
        return None
    trees = forest.trees
    counts = np.asarray([t.node_count for t in trees])
    start = np.concatenate([[0], np.cumsum(counts)])  # (T + 1,) first node of each tree
    left = np.concatenate([t.children_left for t in trees])  # local ids, -1 at leaves
    right = np.concatenate([t.children_right for t in trees])
    leaf = left == -1
    n_leaves = np.add.reduceat(leaf, start[:-1])
    if n_leaves.max() > WORD:
        return None
    val = np.concatenate([t.value[:, 0, 1] for t in trees])
    if np.any(leaf & (val != 0.0) & (val != 1.0)):
        return None  # an impure leaf: exact float64 sums need the scikit-learn path
    tree_of = np.repeat(np.arange(len(trees)), counts)
    local = np.arange(len(left)) - start[tree_of]
    inner = np.flatnonzero(~leaf)
    ti = tree_of[inner]
    if np.any(left[inner] != local[inner] + 1) or np.any(right[inner] <= left[inner]):
        raise RuntimeError("scikit-learn tree nodes are not in depth-first preorder (API changed?)")
    rank = np.concatenate([[0], np.cumsum(leaf)])  # leaves before each (global) node
    base = rank[start[ti]]
    a = (rank[start[ti] + left[inner]] - base).astype(np.uint64)  # the left subtree's leaves: bits [a, b)
    b = (rank[start[ti] + right[inner]] - base).astype(np.uint64)
    cleared = (np.uint64(1) << b) - (np.uint64(1) << a)
    lf = np.flatnonzero(leaf & (val == 1.0))  # class-1 leaves: their bits, summed per tree (distinct bits)
    ones = np.zeros(len(trees), np.uint64)
    np.add.at(ones, tree_of[lf], np.uint64(1) << (rank[lf] - rank[start[tree_of[lf]]]).astype(np.uint64))
    n_inner = counts - n_leaves
    slot = np.arange(len(inner)) - np.concatenate([[0], np.cumsum(n_inner)])[ti]
    width = max(1, int(n_inner.max()))
    cmap = np.arange(forest.n_features) if colmap is None else np.asarray(colmap)
    feat = np.zeros((len(trees), width), np.int32)
    thr = np.full((len(trees), width), np.inf, np.float32)  # padding nodes: every row goes left
    mask = np.full((len(trees), width), FULL, np.uint32)
    feat[ti, slot] = cmap[np.concatenate([t.feature for t in trees])[inner]]
    thr[ti, slot] = round_down_f32(np.concatenate([t.threshold for t in trees])[inner])
    mask[ti, slot] = (~cleared & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    return dict(feat=feat, thr=thr, mask=mask, ones=ones.astype(np.uint32), classes=forest.classes)


WIDTHS = (4, 8, 12, 16, 24, 32)  # padded internal nodes per tree: few shapes, few compiles


def _width(x: int) -> int:
    return next(w for w in WIDTHS if w >= x)


def _bucket(x: int, step: int) -> int:
    return max(step, -(-x // step) * step)


_VOTES = []  # the jitted program, built on first use (importing learn does not load JAX)


def _votes(ZT, feat, thr, mask, ones):
    """Class-1 votes ``(F, N)`` int32. ZT: (Dz, N); feat, thr, mask: (F, T, I); ones: (F, T)."""
    if not _VOTES:
        import jax
        import jax.numpy as jnp

        def votes(ZT, feat, thr, mask, ones):
            def one(feat, thr, mask, ones):
                right = ZT[feat] > thr[..., None]  # (T, I, N): the row goes right at this node
                m = jnp.where(right, mask[..., None], jnp.uint32(0xFFFFFFFF))
                alive = jax.lax.reduce(m, jnp.uint32(0xFFFFFFFF), jax.lax.bitwise_and, (1,))  # (T, N)
                exit_bit = alive & (jnp.uint32(0) - alive)  # lowest set bit: the exit leaf
                return ((exit_bit & ones[:, None]) != 0).sum(0, dtype=jnp.int32)

            return jax.vmap(one)(feat, thr, mask, ones)

        _VOTES.append(jax.jit(votes))
    return _VOTES[0](ZT, feat, thr, mask, ones)


def predict_block(forests: Sequence[Trees], ZT: np.ndarray, colmaps: Sequence[np.ndarray],
                  chunk: int = 8) -> np.ndarray:
    """Predicted labels ``(F, N)`` of F forests on the N test rows of ``ZT: (Dz, N)``.

    ``colmaps[f]: (D_f,)`` maps forest f's feature j to row ``colmaps[f][j]`` of ``ZT``.
    Small pure forests run through the jitted bitmask program in chunks of ``chunk``
    (padded to fixed shapes, sorted by size); the rest through ``predict_labels``.
    """
    ZT = np.ascontiguousarray(ZT, dtype=np.float32)
    n = ZT.shape[1]
    labels: list = [None] * len(forests)
    packed = {}
    for i, (f, cm) in enumerate(zip(forests, colmaps)):
        if len(f.classes) == 1:
            labels[i] = np.repeat(f.classes, n)
            continue
        p = pack_forest(f, cm)
        if p is None:
            labels[i] = predict_labels(f, np.ascontiguousarray(ZT[np.asarray(cm)].T))
        else:
            packed[i] = p
    order = sorted(packed, key=lambda i: packed[i]["feat"].shape[1])
    if order:
        import jax.numpy as jnp

        ZT = jnp.asarray(ZT)  # on the device once for all chunks
    for s in range(0, len(order), chunk):
        ids = order[s : s + chunk]
        t = _bucket(max(packed[i]["feat"].shape[0] for i in ids), 8)
        w = _width(max(packed[i]["feat"].shape[1] for i in ids))
        feat = np.zeros((chunk, t, w), np.int32)
        thr = np.full((chunk, t, w), np.inf, np.float32)
        mask = np.full((chunk, t, w), FULL, np.uint32)
        ones = np.zeros((chunk, t), np.uint32)  # padding trees vote for class 0: add nothing
        for j, i in enumerate(ids):
            p = packed[i]
            tt, ww = p["feat"].shape
            feat[j, :tt, :ww], thr[j, :tt, :ww], mask[j, :tt, :ww], ones[j, :tt] = p["feat"], p["thr"], p["mask"], p["ones"]
        votes = np.asarray(_votes(ZT, feat, thr, mask, ones))
        for j, i in enumerate(ids):
            t_i = packed[i]["feat"].shape[0]
            labels[i] = packed[i]["classes"].take((2 * votes[j] > t_i).astype(np.intp))
    return np.stack(labels) if labels else np.zeros((0, n))
