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

Arrays: ``XT: (D, N)`` float32 features by row; ``y: (N,)`` int64 class codes; ``w: (N,)``
float64 integer weights; ``samples: (N,)`` int64 the node's samples at ``[start, end)``;
``fv: (N,)`` float32 scratch; ``features, constant: (D,)`` int64 splitter state;
``total: (K,)`` the node's weighted class counts; ``left: (K,)`` scratch.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from relaff_jax.learn.compiled.rng import rand_int

FEATURE_THRESHOLD = np.float32(1e-7)  # sklearn/tree/_partitioner.pxd
INSERTION = 24  # segments up to this length are insertion-sorted


@njit(cache=True)
def sort_segment(fv, samples, start, end):
    """Sort ``fv[start:end]`` ascending, moving ``samples`` along (ties in any order)."""
    m = end - start
    if m <= INSERTION:
        for i in range(start + 1, end):
            v = fv[i]
            s = samples[i]
            j = i - 1
            while j >= start and fv[j] > v:
                fv[j + 1] = fv[j]
                samples[j + 1] = samples[j]
                j -= 1
            fv[j + 1] = v
            samples[j + 1] = s
        return
    order = np.argsort(fv[start:end])
    v = fv[start:end].copy()
    s = samples[start:end].copy()
    for i in range(m):
        fv[start + i] = v[order[i]]
        samples[start + i] = s[order[i]]


@njit(cache=True)
def gini_pair(left, total, wl, wr):
    """``children_impurity``: (impurity_left, impurity_right) for left counts ``left``."""
    sql = 0.0
    sqr = 0.0
    for c in range(total.shape[0]):
        cl = left[c]
        sql += cl * cl
        cr = total[c] - cl
        sqr += cr * cr
    gl = 0.0
    gl += 1.0 - sql / (wl * wl)
    gr = 0.0
    gr += 1.0 - sqr / (wr * wr)
    return gl / 1.0, gr / 1.0


@njit(cache=True)
def node_impurity(total, wn):
    """``Gini.node_impurity`` of a node with class counts ``total`` and weight ``wn``."""
    sq = 0.0
    for c in range(total.shape[0]):
        sq += total[c] * total[c]
    g = 0.0
    g += 1.0 - sq / (wn * wn)
    return g / 1.0


@njit(cache=True)
def best_split(XT, y, w, samples, fv, features, constant, left, total, start, end, wn, w_all,
               impurity, n_known, max_features, min_leaf, state):
    """``node_split_best`` on ``samples[start:end]`` (partitioned in place when a split is
    found). Returns ``(pos, feature, threshold, impurity_left, impurity_right, improvement,
    n_constant)``; ``pos == end`` when no split is valid."""
    n_features = XT.shape[0]
    K = total.shape[0]
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
        row = XT[feat]
        for p in range(start, end):
            fv[p] = row[samples[p]]
        sort_segment(fv, samples, start, end)
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
        for c in range(K):
            left[c] = 0.0
        wl = 0.0
        pos = start  # the criterion's position: samples [start, pos) are in left
        p = start
        while p < end:
            p += 1
            while p < end and fv[p] <= fv[p - 1] + FEATURE_THRESHOLD:
                p += 1
            if p == end:
                continue
            if p - start < min_leaf or end - p < min_leaf:
                continue
            for q in range(pos, p):
                s = samples[q]
                left[y[s]] += w[s]
                wl += w[s]
            pos = p
            wr = wn - wl
            gl, gr = gini_pair(left, total, wl, wr)
            proxy = -wr * gr - wl * gl
            if proxy > best_proxy:
                best_proxy = proxy
                best_pos = p
                best_feature = feat
                best_thr = fv[p - 1] / 2.0 + fv[p] / 2.0
    if best_pos < end:
        row = XT[best_feature]
        a = start
        b = end
        while a < b:  # partition_samples_final
            if np.float64(row[samples[a]]) <= best_thr:
                a += 1
            else:
                b -= 1
                t = samples[a]
                samples[a] = samples[b]
                samples[b] = t
        for c in range(K):
            left[c] = 0.0
        wl = 0.0
        for q in range(start, best_pos):
            s = samples[q]
            left[y[s]] += w[s]
            wl += w[s]
        wr = wn - wl
        imp_l, imp_r = gini_pair(left, total, wl, wr)
        improvement = (wn / w_all) * (impurity - (wr / wn * imp_r) - (wl / wn * imp_l))
    for i in range(n_known):
        features[i] = constant[i]
    for i in range(n_known, n_known + n_found):
        constant[i] = features[i]
    return best_pos, best_feature, best_thr, imp_l, imp_r, improvement, n_total
