"""Many forests per call, compiled (numba): scikit-learn 1.9.1's ``DepthFirstTreeBuilder``
for each tree of each ``RandomForestClassifier`` (``rng.py`` for the draws, ``split.py`` for
a node's split).

``build_tree`` is ``DepthFirstTreeBuilder.build`` without monotonic constraints or missing
values: a stack of ``(start, end, depth, parent, is_left, impurity, n_constant_features)``,
the right child pushed before the left (node ids are depth-first preorder, left first); a
node is a leaf when ``depth >= max_depth``, ``n < min_samples_split``, ``n < 2
min_samples_leaf``, its impurity is ``<= EPSILON`` (the root's from ``node_impurity``, a
child's from its parent's split), no split is valid, or ``improvement + EPSILON <
min_impurity_decrease`` (0). Leaves get feature -2, threshold -2.0, children -1, as
``Tree._add_node``; every node gets its value ``class counts / weight`` (``node_value``).
``n`` counts a node's samples of positive weight (the splitter drops the others).

``build_forests`` loops over forests and trees: forest seeds, bootstrap counts
(``np.bincount`` of the draws) and the splitter seed as ``rng.py`` describes, then
``build_tree``; the trees' streams are seeded four at a time (``mt_seed4``: one seeding is a
latency-bound chain, four interleave) and the bootstrap drawn by ``draw_bootstrap``. Output node arrays are flat over all trees of all forests, children ids
local to their tree (as ``Tree.children_left``), ``tree_start: (T_all + 1,)`` the first
node of each tree.

``build_tree`` is compiled without numba's reference counting (``_nrt=False``): it allocates
nothing (every array comes from ``build_forests``, which outlives the call), and with it
numba counted references to the arrays each inlined split-search function binds, per node
and per drawn feature (numba's pruning of those counts failed here: LLVM merges the decrefs
of two call sites into one on a phi of pointers); ``perf`` put ~a third of the fit's
samples at N = 100 in ``NRT_incref`` / ``NRT_decref``, and without them the fit takes ~0.9x.
An allocation (or numba's sort, which returns its array) added to ``build_tree`` fails to
compile, it cannot run uncounted; so forests of N > COUNT_SORT have every feature sorted
before their trees (``split.presort_all``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from relaff_jax.learn.forest.compiled.rng import (MAX_INT, RAND_R_MAX, draw_bootstrap, draw_subsample, first_randint, mt_seed,
                                           mt_seed4, randint)
from relaff_jax.learn.forest.compiled.split import COUNT_SORT, best_split, node_impurity, presort_all

EPSILON = np.finfo(np.float64).eps  # sklearn/tree/_tree.pyx
LEAF = -1  # _TREE_LEAF
UNDEFINED = -2  # _TREE_UNDEFINED


@njit(cache=True, _nrt=False)
def build_tree(fo, sc, stk_i, stk_f, y1, w, K, max_features, min_leaf, min_split, max_depth, state, out, base):
    """One tree on the forest ``fo`` (``split.py``) with weights ``w: (N,)``; nodes written
    to ``out = (feature, threshold, left, right, value)`` from ``base``. ``stk_i: (N + 2, 6)``
    int64 and ``stk_f: (N + 2,)`` float64 are the stack. Returns the tree's node count."""
    samples, features, wy = sc[0], sc[3], sc[5]
    feature_o, thr_o, left_o, right_o, value_o = out
    n = y1.shape[0]
    m = 0
    w_all = 0.0
    for i in range(n):
        if w[i] != 0.0:
            samples[m] = i
            m += 1
        w_all += w[i]
        wy[i] = w[i] * y1[i]
    for j in range(features.shape[0]):
        features[j] = j
    # stack rows: start, end, depth, parent, is_left, n_constant | impurity
    stk_i[0, 0], stk_i[0, 1], stk_i[0, 2], stk_i[0, 3], stk_i[0, 4], stk_i[0, 5] = 0, m, 0, -1, 0, 0
    stk_f[0] = np.inf
    top = 1
    count = 0
    first = True
    pos, feat, thr, imp_l, imp_r, improvement = 0, 0, 0.0, 0.0, 0.0, 0.0
    while top > 0:
        top -= 1
        start, end, depth, parent, is_left, n_const = (stk_i[top, 0], stk_i[top, 1], stk_i[top, 2],
                                                      stk_i[top, 3], stk_i[top, 4], stk_i[top, 5])
        impurity = stk_f[top]
        nn = end - start
        wn = 0.0
        t1 = 0.0
        for p in range(start, end):
            s = samples[p]
            wn += w[s]
            t1 += wy[s]
        t0 = wn - t1
        is_leaf = depth >= max_depth or nn < min_split or nn < 2 * min_leaf
        if first:
            impurity = node_impurity(t0, t1, wn)
            first = False
        is_leaf = is_leaf or impurity <= EPSILON
        if not is_leaf:
            pos, feat, thr, imp_l, imp_r, improvement, n_const = best_split(
                fo, sc, wy, w, start, end, t0, t1, wn, w_all, impurity, n_const, max_features, min_leaf, state)
            is_leaf = pos >= end or improvement + EPSILON < 0.0
        node = base + count
        if parent >= 0:
            if is_left:
                left_o[base + parent] = count
            else:
                right_o[base + parent] = count
        if is_leaf:
            feature_o[node] = UNDEFINED
            thr_o[node] = UNDEFINED
            left_o[node] = LEAF
            right_o[node] = LEAF
        else:
            feature_o[node] = feat
            thr_o[node] = thr
        value_o[node, 0] = t0 / wn
        if K == 2:
            value_o[node, 1] = t1 / wn
        if not is_leaf:
            stk_i[top, 0], stk_i[top, 1], stk_i[top, 2], stk_i[top, 3], stk_i[top, 4], stk_i[top, 5] = (
                pos, end, depth + 1, count, 0, n_const)
            stk_f[top] = imp_r
            top += 1
            stk_i[top, 0], stk_i[top, 1], stk_i[top, 2], stk_i[top, 3], stk_i[top, 4], stk_i[top, 5] = (
                start, pos, depth + 1, count, 1, n_const)
            stk_f[top] = imp_l
            top += 1
        count += 1
    return count


@njit(cache=True)
def _grow_i(a, size):
    b = np.empty(size, np.int32)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_f(a, size):
    b = np.empty(size, np.float64)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_v(a, size):
    b = np.zeros((size, 2), np.float64)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def build_forests(xs, x_start, ns, ds, ys, ks, seeds, n_trees, n_boot, max_features,
                  min_leaf, min_split, max_depth, bootstrap):
    """Every tree of F >= 1 forests. Forest f: ``XT = xs[x_start[f]:][:d n].reshape(d, n)``
    (features by row), class codes ``ys[sum(ns[:f]):][:n]`` in [0, ks[f]) (ks <= 2), seed
    ``seeds[f]`` in [0, 2**32), ``n_trees[f]`` trees of ``n_boot[f]`` draws each (``bootstrap``
    0: none, 1: with replacement, 2: ``n_boot[f]`` distinct samples, ``rng.draw_subsample``),
    ``max_features[f]`` features per split. Returns ``(feature, threshold, left, right,
    value, tree_start)``: ``(M,)`` int32, float64, int32, int32, ``(M, 2)`` float64 (class
    k in column k < ks[f]) and ``(sum(n_trees) + 1,)`` int64."""
    F = ns.shape[0]
    n_max = ns.max()
    d_max = ds.max()
    cap = 0
    for f in range(F):
        cap += n_trees[f] * (min(ns[f], n_boot[f]) + 1)
    feature_o = np.empty(cap, np.int32)
    thr_o = np.empty(cap, np.float64)
    left_o = np.empty(cap, np.int32)
    right_o = np.empty(cap, np.int32)
    value_o = np.zeros((cap, 2), np.float64)
    tree_start = np.zeros(n_trees.sum() + 1, np.int64)
    order_all = np.empty(d_max * n_max, np.int32)
    rank_all = np.empty(d_max * n_max, np.int32)
    sv_all = np.empty(d_max * n_max, np.float32)
    ready = np.zeros(d_max, np.uint8)
    keys = np.empty(n_max, np.int64)
    sc = (np.empty(n_max, np.int64), np.empty(n_max, np.int64), np.zeros((n_max + 63) // 64, np.uint64),
          np.empty(d_max, np.int64), np.empty(d_max, np.int64), np.empty(n_max, np.float64))
    stk_i = np.empty((n_max + 2, 6), np.int64)
    stk_f = np.empty(n_max + 2, np.float64)
    mt = np.zeros(625, np.int64)
    mt2 = np.zeros(625, np.int64)
    tree_seeds = np.zeros(n_trees.max() + 3, np.int64)
    mts = np.zeros((4, 625), np.int64)
    state = np.zeros(1, np.int64)
    w = np.empty(n_max, np.float64)
    y1 = np.empty(n_max, np.float64)
    used = 0
    t_all = 0
    y0 = 0
    for f in range(F):
        n, d, K = ns[f], ds[f], ks[f]
        XT = xs[x_start[f]: x_start[f] + d * n].reshape(d, n)
        yf = y1[:n]
        for i in range(n):
            yf[i] = np.float64(ys[y0 + i])
        y0 += n
        rf = ready[:d]
        rf[:] = 0
        fo = (XT, order_all[: d * n].reshape(d, n), rank_all[: d * n].reshape(d, n), sv_all[: d * n].reshape(d, n),
              rf, keys[:n])  # C-contiguous
        scf = (sc[0][:n], sc[1][:n], sc[2][: (n + 63) // 64], sc[3][:d], sc[4][:d], sc[5][:n])
        if n > COUNT_SORT:  # sorted here: build_tree cannot call numba's sort (no reference counting)
            presort_all(fo)
        mt_seed(mt, seeds[f])
        for t in range(n_trees[f]):  # _set_random_states: one draw per tree
            tree_seeds[t] = randint(mt, 0, MAX_INT)
        for t in range(n_trees[f]):
            if t % 4 == 0:  # the next four trees' streams seeded together (past the last tree: unused)
                mt_seed4(mts, tree_seeds[t], tree_seeds[t + 1], tree_seeds[t + 2], tree_seeds[t + 3])
            mtt = mts[t % 4]
            state[0] = first_randint(mtt, 0, RAND_R_MAX)  # the splitter's fresh RandomState(s_i)
            if state[0] < 0:
                mt_seed(mt2, tree_seeds[t])
                state[0] = randint(mt2, 0, RAND_R_MAX)
            wt = w[:n]
            if bootstrap == 2:  # the subsample reading: n_boot[f] distinct samples
                draw_subsample(mtt, wt, n, n_boot[f])
            elif bootstrap:
                wt[:] = 0.0
                draw_bootstrap(mtt, wt, n, n_boot[f])
            else:
                wt[:] = 1.0
            m = 0
            for i in range(n):
                if wt[i] != 0.0:
                    m += 1
            need = used + 2 * m - 1
            if need > feature_o.shape[0]:
                size = max(need, 2 * feature_o.shape[0])
                feature_o, left_o, right_o = _grow_i(feature_o, size), _grow_i(left_o, size), _grow_i(right_o, size)
                thr_o, value_o = _grow_f(thr_o, size), _grow_v(value_o, size)
            out = (feature_o, thr_o, left_o, right_o, value_o)
            used += build_tree(fo, scf, stk_i, stk_f, yf, wt, K, max_features[f], min_leaf, min_split, max_depth,
                               state, out, used)
            t_all += 1
            tree_start[t_all] = used
    return feature_o[:used], thr_o[:used], left_o[:used], right_o[:used], value_o[:used], tree_start
