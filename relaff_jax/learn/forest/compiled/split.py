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

Why the order of samples inside a node does not matter, so no node is ever sorted in place
(scikit-learn sorts with its own introsort, which is not stable): the sorted feature values
are the same for every order, the thresholds depend only on them, the children are the sets
``x <= t`` / ``x > t``, and the weighted class counts are sums of integer bootstrap counts,
exact in float64 in any order. Only the sets of samples per node, the persistent
``features`` array and the ``rand_r`` state carry from node to node.

How a drawn feature is searched: each feature of the forest is sorted once, on first use
(``presort``: its samples in ascending order, their ranks and the sorted values); a node's
samples are turned into their ranks in ascending order (``node_ranks``: a bitmap of ranks
read back lowest bit first, or an insertion sort for small nodes), and the scan walks them,
reading values and weights through the presorted arrays: one pass, no moving of samples. A
feature of exactly two values (``two_valued``: a bootstrap input's 0/1) is never sorted; its
one candidate, after the node's samples of the lower value, comes from one pass over the node
(``two_counts``) and is scored by the same ``offer`` as the scan's. A
candidate's Gini (two float64 divisions) is computed only when an exact, division-free form
of its proxy says it may beat the best so far (``may_win``, with a margin far above rounding):
a candidate that could win is always computed and compared as scikit-learn does it, in its
order, so the best split is the same. The partition of the best
split is branch-free through scratch, and the left child's counts are the scan's.

Arrays: ``XT: (D, N)`` float32 features by row; ``w: (N,)`` float64 integer weights; ``wy:
(N,)`` float64 ``w * y`` (class-1 weights, ``y`` 1.0 for class 1, else 0.0). ``fo = (XT,
order, rank, sv, ready, keys)``: the forest's features presorted on first use (``order,
rank: (D, N)`` int32 samples in ascending order of each feature and their ranks, ``sv: (D,
N)`` float32 the sorted values, ``ready: (D,)`` uint8, ``keys: (N,)`` int64 scratch). ``sc =
(samples, rk, bm, features, constant, wy)``: the splitter's ``samples: (N,)`` int64 (the
node's at ``[start, end)``), scratch ``rk: (N,)`` int64 a node's ranks and ``bm: (ceil(N /
64),)`` uint64 zeros, the persistent ``features, constant: (D,)`` int64, and ``wy``. Splits
are searched for binary nodes only (a node of one class has impurity 0 and is a leaf), so
counts are scalars.

Small functions called per drawn feature or per random draw are ``inline="always"``: a
numba call that passes arrays costs reference counting on every call.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from numba.cpython.unsafe.numbers import leading_zeros, trailing_zeros

from relaff_jax.learn.forest.compiled.rng import rand_int

FEATURE_THRESHOLD = np.float32(1e-7)  # sklearn/tree/_partitioner.pxd
COUNT_SORT = 256  # presort: ranks by counting up to this N (keys are distinct), else a sort
MARGIN = 1e-9  # of wn: far above the proxy's rounding error (< 10 * 2**-53 * wn), see may_win
INSERTION = 12  # nodes up to this size get their ranks by insertion sort
ONE = np.uint64(1)
ZERO = np.uint64(0)
SIGN = np.uint32(0x80000000)
TWO = 2  # ready[j] of a two-valued feature (presort)


@njit(cache=True, inline="always")
def ctz(b):
    """Index of the lowest set bit of ``b != 0`` (uint64), as int64 (int64 + uint64 is float64 in numba)."""
    return np.int64(trailing_zeros(b))


@njit(cache=True, inline="always")
def clz(b):
    """Leading zero bits of ``b != 0`` (uint64), as int64."""
    return np.int64(leading_zeros(b))


@njit(cache=True, inline="always")
def two_valued(fo, j):
    """Whether feature j of the forest holds exactly two values lo < hi more than
    FEATURE_THRESHOLD apart (a bootstrap input's 0/1); then ``ready[j] = TWO`` and ``sv[j,
    :2] = lo, hi``, and the feature is never sorted (``two_counts`` searches it)."""
    XT, sv, ready = fo[0], fo[3], fo[4]
    n = XT.shape[1]
    a = XT[j, 0]
    b = a
    for i in range(n):  # at most two distinct values (-0.0 and 0.0 are one: so they are for every split)
        x = XT[j, i]
        if x != a and x != b:
            if a == b:
                b = x
            else:
                return False
    lo = min(a, b)
    hi = max(a, b)
    if not hi > lo + FEATURE_THRESHOLD:
        return False
    sv[j, 0] = lo
    sv[j, 1] = hi
    ready[j] = TWO
    return True


@njit(cache=True, inline="always")
def sort_keys(fo, j):
    """``keys[i]``: feature j's float32 order as unsigned keys, the sample in the low word."""
    XT, keys = fo[0], fo[5]
    bits = XT[j].view(np.uint32)
    for i in range(XT.shape[1]):
        b = bits[i]
        k = ~b if b & SIGN else b | SIGN
        keys[i] = ((np.int64(k) - 0x80000000) << 32) | i  # high word signed: no overflow


@njit(cache=True, inline="always")
def presort(fo, j):
    """Sort feature j of the forest once (``order[j]``, ``rank[j]``, ``sv[j]``), on first use,
    for N <= COUNT_SORT (``presort_all`` sorted every feature of a larger forest before its
    trees); a two-valued feature is not sorted (``two_valued``)."""
    XT, order, rank, sv, ready, keys = fo
    if ready[j] or two_valued(fo, j):
        return
    n = XT.shape[1]
    sort_keys(fo, j)
    for s in range(n):  # rank = how many keys are smaller: n^2 compares, vectorised, beat the sort here
        ks = keys[s]
        r = 0
        for i in range(n):
            r += keys[i] < ks
        order[j, r] = s
        rank[j, s] = r
        sv[j, r] = XT[j, s]
    ready[j] = 1


@njit(cache=True)
def presort_all(fo):
    """Every feature of a forest of N > COUNT_SORT samples sorted (or found two-valued) before
    its trees, by ``keys.sort()``: numba's sort needs its reference counting, which the tree
    builder runs without (``build.py``)."""
    XT, order, rank, sv, ready, keys = fo
    n = XT.shape[1]
    for j in range(XT.shape[0]):
        if two_valued(fo, j):
            continue
        sort_keys(fo, j)
        keys.sort()
        for r in range(n):
            s = keys[r] & 0xFFFFFFFF
            order[j, r] = s
            rank[j, s] = r
            sv[j, r] = XT[j, s]
        ready[j] = 1


@njit(cache=True, inline="always")
def two_counts(fo, sc, w, wy, j, start, end):
    """For a two-valued feature j (``ready[j] == TWO``): ``(c, wl, l1)``, how many of
    ``samples[start:end]`` hold the lower value and their weight and class-1 weight (the
    only candidate split of such a feature is after them, at position ``start + c``)."""
    XT, sv = fo[0], fo[3]
    samples = sc[0]
    lo = sv[j, 0]
    c = 0
    wl = 0.0
    l1 = 0.0
    for p in range(start, end):  # branch-free (the values come in no order): w * 1.0 or w * 0.0 is exact
        s = samples[p]
        a = XT[j, s] == lo
        c += a
        f = np.float64(a)
        wl += w[s] * f
        l1 += wy[s] * f
    return c, wl, l1


@njit(cache=True, inline="always")
def node_ranks(fo, sc, j, start, end):
    """The ranks (in the forest's presorted order of feature j) of ``samples[start:end]``,
    ascending, into ``rk[:end - start]``, unless feature j is constant at the node (returns
    True then, and ``rk`` may be unfilled). N <= 128: the ranks set in a two-word bitmap
    held in registers (no loop-carried memory, and a constant feature is seen from the
    lowest and highest bits before reading them out); else an insertion sort for small
    nodes (or when the bitmap would be long for the node) or a bitmap in memory read back
    lowest bit first, O(m + N / 64). Ranks are distinct, so all give the same list."""
    rank, sv = fo[2], fo[3]
    samples, rk, bm = sc[0], sc[1], sc[2]
    m = end - start
    nw = bm.shape[0]
    if nw <= 2:
        b0 = ZERO
        b1 = ZERO
        for p in range(start, end):
            r = rank[j, samples[p]]  # 2-D indexing, no row views (each costs reference counting)
            bit = ONE << np.uint64(r & 63)
            hi = np.uint64(r >> 6)  # 0 or 1: branch-free choice of the word
            b0 |= bit & (hi - ONE)
            b1 |= bit & (ZERO - hi)
        lo = ctz(b0) if b0 != ZERO else 64 + ctz(b1)
        top = 127 - clz(b1) if b1 != ZERO else 63 - clz(b0)
        if sv[j, top] <= sv[j, lo] + FEATURE_THRESHOLD:
            return True
        k = 0
        while b0 != ZERO:
            rk[k] = ctz(b0)
            k += 1
            b0 &= b0 - ONE
        while b1 != ZERO:
            rk[k] = 64 + ctz(b1)
            k += 1
            b1 &= b1 - ONE
        return False
    if m <= INSERTION or nw > m:
        for i in range(m):
            r = rank[j, samples[start + i]]
            k = i - 1
            while k >= 0 and rk[k] > r:
                rk[k + 1] = rk[k]
                k -= 1
            rk[k + 1] = r
    else:
        for p in range(start, end):
            r = rank[j, samples[p]]
            bm[r >> 6] |= ONE << np.uint64(r & 63)
        k = 0
        for wi in range(nw):
            v = bm[wi]
            if v == ZERO:
                continue
            bm[wi] = ZERO
            base = wi * 64
            while v != ZERO:
                rk[k] = base + ctz(v)
                k += 1
                v &= v - ONE
    return sv[j, rk[m - 1]] <= sv[j, rk[0]] + FEATURE_THRESHOLD


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
def cut_of(best_proxy, wn):
    """The bound ``may_win`` compares with once the best proxy is ``best_proxy``."""
    return best_proxy + wn - MARGIN * wn


@njit(cache=True)
def may_win(l0, l1, r0, r1, wl, wr, cut):
    """Whether a candidate of left counts (l0, l1) and right (r0, r1) may have a proxy above
    the best one (``cut = cut_of(best_proxy, wn)``), with multiplications only. In exact
    arithmetic the proxy is ``-wn + q / (wl wr)``, ``q = (r0^2 + r1^2) wl + (l0^2 + l1^2)
    wr``; the computed proxy (``gini_pair``) is within ~10 * 2**-53 * wn of it, and q and the
    product within a few 2**-53 relative, all far below MARGIN * wn: a candidate whose
    computed proxy is above the best one always passes (tests/learn/test_engine.py checks it on
    mirrored candidates, whose exact proxies are equal)."""
    q = (r0 * r0 + r1 * r1) * wl + (l0 * l0 + l1 * l1) * wr
    return q > cut * (wl * wr)


@njit(cache=True)
def node_impurity(t0, t1, wn):
    """``Gini.node_impurity`` of a node with class counts (t0, t1) (t1 = 0 for one class)."""
    g = 0.0
    g += 1.0 - (t0 * t0 + t1 * t1) / (wn * wn)
    return g / 1.0


@njit(cache=True, inline="always")
def offer(best, wl, l1, t0, t1, wn, pos, feat, prev, v):
    """The best split so far ``best = (proxy, cut, pos, feature, threshold, wl, l1)`` after
    the candidate at ``pos`` of feature ``feat`` (left weight ``wl``, class-1 weight ``l1``,
    between values ``prev < v``): replaced when its proxy is strictly greater (scikit-learn's
    rule), computed only when ``may_win`` says it may be."""
    wr = wn - wl
    l0 = wl - l1
    if may_win(l0, l1, t0 - l0, t1 - l1, wl, wr, best[1]):  # else no divisions: it cannot beat the best
        gl, gr = gini_pair(l0, l1, t0, t1, wl, wr)
        proxy = -wr * gr - wl * gl
        if proxy > best[0]:
            return proxy, cut_of(proxy, wn), pos, feat, prev / 2.0 + v / 2.0, wl, l1
    return best


@njit(cache=True, inline="always")
def best_split(fo, sc, wy, w, start, end, t0, t1, wn, w_all, impurity, n_known, max_features, min_leaf,
               state):
    """``node_split_best`` on ``samples[start:end]`` of class-count totals (t0, t1) and
    weight ``wn`` (``samples`` partitioned in place when a split is found). Returns ``(pos,
    feature, threshold, impurity_left, impurity_right, improvement, n_constant)``; ``pos ==
    end`` when no split is valid."""
    XT, order, sv, ready = fo[0], fo[1], fo[3], fo[4]
    samples, rk, features, constant = sc[0], sc[1], sc[3], sc[4]
    n_features = XT.shape[0]
    m = end - start
    # (proxy, cut_of(proxy, wn) for may_win, pos, feature, threshold, wl, l1) of the best split so far
    best = (-np.inf, -np.inf, end, 0, 0.0, 0.0, 0.0)
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
        presort(fo, feat)
        two = ready[feat] == TWO
        if two:
            c, wl, l1 = two_counts(fo, sc, w, wy, feat, start, end)
            is_constant = c == 0 or c == m
        else:
            is_constant = node_ranks(fo, sc, feat, start, end)
        if is_constant:
            features[f_j] = features[n_total]
            features[n_total] = feat
            n_found += 1
            n_total += 1
            continue
        f_i -= 1
        t = features[f_i]
        features[f_i] = features[f_j]
        features[f_j] = t
        if two:  # one candidate: after the c samples of the lower value
            if c >= min_leaf and m - c >= min_leaf:
                best = offer(best, wl, l1, t0, t1, wn, start + c, feat, sv[feat, 0], sv[feat, 1])
            continue
        prev = sv[feat, rk[0]]
        s = order[feat, rk[0]]
        wl = w[s]
        l1 = wy[s]
        for i in range(1, m):  # candidate p = start + i, wl and l1 the sums over positions < p
            r = rk[i]
            v = sv[feat, r]
            if not (v <= prev + FEATURE_THRESHOLD) and i >= min_leaf and m - i >= min_leaf:
                best = offer(best, wl, l1, t0, t1, wn, start + i, feat, prev, v)
            s = order[feat, r]
            wl += w[s]
            l1 += wy[s]
            prev = v
    best_pos, best_feature, best_thr, best_wl, best_l1 = best[2], best[3], best[4], best[5], best[6]
    if best_pos < end:  # partition_samples_final, branch-free through rk (any order will do)
        lo = 0
        hi = m - 1
        for p in range(start, end):
            s = samples[p]
            left = np.float64(XT[best_feature, s]) <= best_thr
            rk[lo] = s
            rk[hi] = s
            lo += left
            hi -= not left
        for i in range(m):
            samples[start + i] = rk[i]
        wl = best_wl  # the left child's counts, as the scan summed them (integers: exact in any order)
        l1 = best_l1
        wr = wn - wl
        imp_l, imp_r = gini_pair(wl - l1, l1, t0, t1, wl, wr)
        improvement = (wn / w_all) * (impurity - (wr / wn * imp_r) - (wl / wn * imp_l))
    for i in range(n_known):
        features[i] = constant[i]
    for i in range(n_known, n_known + n_found):
        constant[i] = features[i]
    return best_pos, best_feature, best_thr, imp_l, imp_r, improvement, n_total
