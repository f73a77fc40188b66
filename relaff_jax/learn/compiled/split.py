"""One node's best split, compiled (numba): scikit-learn 1.9.1's ``node_split_best`` with a
dense partitioner and the Gini criterion, for finite float32 features and integer weights.

Read from sklearn/tree/_splitter.pyx, _partitioner.pyx, _criterion.pyx and kept here:

- Features are drawn by ``rand_int`` in the Fisher-Yates order over the splitter's
  ``features`` array, which persists from node to node of a tree, with the bookkeeping of
  known, drawn and newly found constant features (``n_known_constants``,
  ``n_drawn_constants``, ``n_found_constants``) and the stopping rule (stop when every
  remaining feature is constant; go on past ``max_features`` until one drawn feature is
  not constant). A feature is constant when ``max <= min + FEATURE_THRESHOLD`` in float32.
- Candidate positions skip ties up to FEATURE_THRESHOLD (float32 ``x[p] <= x[p-1] + 1e-7``)
  and splits leaving fewer than ``min_samples_leaf`` samples on a side; ``min_weight_leaf``
  is 0 (the forest's). The threshold is ``x[p-1] / 2.0 + x[p] / 2.0`` in float64 (1.9.1
  has no ``threshold == x[p]`` fallback any more; the midpoint of two distinct float32 is
  always strictly between them in float64). The best split is the first strictly greater
  Gini proxy ``-w_R g_R - w_L g_L``, in the order features are drawn and positions scanned.
- Children impurities and the improvement use the criterion's formulas in its operation
  order (``children_impurity``, ``impurity_improvement``).

Why the order of samples inside a node does not matter, so any sort will do (scikit-learn
sorts with its own introsort, which is not stable): the sorted feature values are the same
for every order, the thresholds depend only on them, the children are the sets ``x <= t`` /
``x > t``, and the weighted class counts are sums of integer bootstrap counts, exact in
float64 in any order. Only the sets of samples per node, the persistent ``features`` array
and the ``rand_r`` state carry from node to node.

Arrays: ``XT: (D, N)`` float32 features by row; ``y1: (N,)`` float64 1.0 for class 1, else
0.0; ``w: (N,)`` float64 integer weights. ``fo = (XT, order, rank, ready)``: the forest's
features presorted on first use (``order, rank: (D, N)`` int64 samples in ascending order of
each feature and their ranks, ``ready: (D,)`` uint8). ``sc = (samples, fv, ws, wy, bm,
features, constant)``: the splitter's ``samples: (N,)`` int64 (the node's at
``[start, end)``), and scratch: ``fv: (N,)`` float32 the sorted values, ``ws, wy: (N,)``
float64 their weights and class-1 weights, ``bm: (ceil(N / 64),)`` uint64 zeros, and the
persistent ``features, constant: (D,)`` int64. Splits are searched for binary
nodes only (a node of one class has impurity 0 and is a leaf), so counts are scalars.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from relaff_jax.learn.compiled.rng import rand_int

FEATURE_THRESHOLD = np.float32(1e-7)  # sklearn/tree/_partitioner.pxd
INSERTION = 12  # nodes up to this size are insertion-sorted
ONE = np.uint64(1)
DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
SHIFT = np.uint64(58)
CTZ = np.zeros(64, np.int64)  # index of the lowest set bit b: CTZ[(b * DEBRUIJN) >> 58]
for _i in range(64):
    CTZ[((int(DEBRUIJN) << _i) & 0xFFFFFFFFFFFFFFFF) >> 58] = _i
SIGN = np.uint32(0x80000000)


@njit(cache=True)
def presort(fo, j):
    """Sort feature j of the forest once (``order[j]``, ``rank[j]``), on first use."""
    XT, order, rank, ready = fo
    if ready[j]:
        return
    n = XT.shape[1]
    bits = XT[j].view(np.uint32)
    keys = np.empty(n, np.int64)
    for i in range(n):  # float32 order as unsigned keys, the sample in the low word
        b = bits[i]
        k = ~b if b & SIGN else b | SIGN
        keys[i] = ((np.int64(k) - 0x80000000) << 32) | i  # high word signed: no overflow
    keys.sort()
    for r in range(n):
        s = keys[r] & 0xFFFFFFFF
        order[j, r] = s
        rank[j, s] = r
    ready[j] = 1


@njit(cache=True)
def sort_node(fo, sc, j, y1, w, start, end):
    """``samples[start:end]`` in ascending order of feature j (ties in any order), with
    ``fv``, ``ws``, ``wy`` along: insertion sort for small nodes; else the node's ranks in
    the forest's presorted order are set in a bitmap and read back in order (lowest set bit
    first), O(m + N / 64)."""
    XT, order, rank, ready = fo
    samples, fv, ws, wy, bm = sc[0], sc[1], sc[2], sc[3], sc[4]
    m = end - start
    if m <= INSERTION:
        for p in range(start, end):
            fv[p] = XT[j, samples[p]]
        for i in range(start + 1, end):
            v = fv[i]
            s = samples[i]
            k = i - 1
            while k >= start and fv[k] > v:
                fv[k + 1] = fv[k]
                samples[k + 1] = samples[k]
                k -= 1
            fv[k + 1] = v
            samples[k + 1] = s
    else:
        presort(fo, j)
        for p in range(start, end):  # 2-D indexing, no row views (each costs reference counting)
            r = rank[j, samples[p]]
            bm[r >> 6] |= ONE << np.uint64(r & 63)
        k = start
        for wi in range(bm.shape[0]):
            v = bm[wi]
            bm[wi] = np.uint64(0)
            while v != np.uint64(0):
                low = v & (~v + ONE)
                s = order[j, wi * 64 + CTZ[(low * DEBRUIJN) >> SHIFT]]
                samples[k] = s
                fv[k] = XT[j, s]
                k += 1
                v ^= low
    for p in range(start, end):
        s = samples[p]
        ws[p] = w[s]
        wy[p] = w[s] * y1[s]


@njit(cache=True)
def gini_pair(l0, l1, t0, t1, wl, wr):
    """``children_impurity`` for left class counts (l0, l1) of totals (t0, t1)."""
    r0 = t0 - l0
    r1 = t1 - l1
    gl = 0.0
    gl += 1.0 - (l0 * l0 + l1 * l1) / (wl * wl)
    gr = 0.0
    gr += 1.0 - (r0 * r0 + r1 * r1) / (wr * wr)
    return gl / 1.0, gr / 1.0


@njit(cache=True)
def node_impurity(t0, t1, wn):
    """``Gini.node_impurity`` of a node with class counts (t0, t1) (t1 = 0 for one class)."""
    g = 0.0
    g += 1.0 - (t0 * t0 + t1 * t1) / (wn * wn)
    return g / 1.0


@njit(cache=True)
def best_split(fo, sc, y1, w, start, end, t0, t1, wn, w_all, impurity, n_known, max_features, min_leaf,
               state):
    """``node_split_best`` on ``samples[start:end]`` of class-count totals (t0, t1) and
    weight ``wn`` (``samples`` partitioned in place when a split is found). Returns ``(pos,
    feature, threshold, impurity_left, impurity_right, improvement, n_constant)``; ``pos ==
    end`` when no split is valid."""
    XT = fo[0]
    samples, fv, ws, wy, features, constant = sc[0], sc[1], sc[2], sc[3], sc[5], sc[6]
    n_features = XT.shape[0]
    best_pos = end
    best_feature = 0
    best_thr = 0.0
    best_proxy = -np.inf
    imp_l = np.inf
    imp_r = np.inf
    improvement = -np.inf
    f_i = n_features
    n_visited = 0
    n_found = 0
    n_drawn = 0
    n_total = n_known
    while f_i > n_total and (n_visited < max_features or n_visited <= n_found + n_drawn):
        n_visited += 1
        f_j = rand_int(state, n_drawn, f_i - n_found)
        if f_j < n_known:
            t = features[n_drawn]
            features[n_drawn] = features[f_j]
            features[f_j] = t
            n_drawn += 1
            continue
        f_j += n_found
        feat = features[f_j]
        sort_node(fo, sc, feat, y1, w, start, end)
        if fv[end - 1] <= fv[start] + FEATURE_THRESHOLD:
            features[f_j] = features[n_total]
            features[n_total] = feat
            n_found += 1
            n_total += 1
            continue
        f_i -= 1
        t = features[f_i]
        features[f_i] = features[f_j]
        features[f_j] = t
        wl = 0.0
        l1 = 0.0
        for i in range(start, end - 1):  # candidate p = i + 1: positions not tied with p - 1
            wl += ws[i]
            l1 += wy[i]
            p = i + 1
            if fv[p] <= fv[i] + FEATURE_THRESHOLD:
                continue
            if p - start < min_leaf or end - p < min_leaf:
                continue
            wr = wn - wl
            gl, gr = gini_pair(wl - l1, l1, t0, t1, wl, wr)
            proxy = -wr * gr - wl * gl
            if proxy > best_proxy:
                best_proxy = proxy
                best_pos = p
                best_feature = feat
                best_thr = fv[i] / 2.0 + fv[p] / 2.0
    if best_pos < end:
        a = start
        b = end
        while a < b:  # partition_samples_final
            if np.float64(XT[best_feature, samples[a]]) <= best_thr:
                a += 1
            else:
                b -= 1
                t = samples[a]
                samples[a] = samples[b]
                samples[b] = t
        wl = 0.0
        l1 = 0.0
        for q in range(start, best_pos):
            s = samples[q]
            wl += w[s]
            l1 += w[s] * y1[s]
        wr = wn - wl
        imp_l, imp_r = gini_pair(wl - l1, l1, t0, t1, wl, wr)
        improvement = (wn / w_all) * (impurity - (wr / wn * imp_r) - (wl / wn * imp_l))
    for i in range(n_known):
        features[i] = constant[i]
    for i in range(n_known, n_known + n_found):
        constant[i] = features[i]
    return best_pos, best_feature, best_thr, imp_l, imp_r, improvement, n_total
