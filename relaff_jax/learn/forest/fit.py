"""The paper's forests built by scikit-learn's own Cython tree code, without the estimator.

Takes states ``X: (N, D)`` float32, labels ``y: (N,)`` and a seed; ``fit_trees`` gives a
``Trees``: the T fitted ``sklearn.tree._tree.Tree`` objects (node arrays) and the classes,
exactly the trees ``RandomForestClassifier(random_state=seed).fit(X, y)`` builds with the
settings of ``ForestConfig`` (scikit-learn 1.9.1, pinned; ``tests/learn/test_engine.py`` checks
the private API and compares predictions bit for bit).

What ``RandomForestClassifier.fit`` does, and what is kept here (sklearn/ensemble/_forest.py,
_base.py, tree/_classes.py):

- ``y`` is encoded as the indices of ``np.unique(y)`` in float64 ``(N, 1)``; every tree sees
  all N rows, so its classes are the forest's.
- Tree seeds: ``rs = RandomState(seed)``; for each tree in order ``_set_random_states`` draws
  ``rs.randint(2**31 - 1)`` (one draw per tree: its only ``random_state`` parameter).
- Tree i (``_parallel_build_trees``): bootstrap ``RandomState(s_i).randint(0, N, N_boot)``
  (``N_boot`` = N, or ``max(int(f * N), 1)`` for ``max_samples = f``), counted into the
  sample weights by ``np.bincount``; then ``DecisionTreeClassifier._fit`` makes a fresh
  ``RandomState(s_i)`` whose one draw (``BestSplitter.init``) seeds the splitter. Here one
  ``RandomState`` is reseeded instead of constructing new ones: the same streams.
- Builder: ``Gini(1, n_classes)``, ``BestSplitter(criterion, max_features, min_samples_leaf,
  min_weight_leaf = 0, rs, None)``, ``DepthFirstTreeBuilder(splitter, min_samples_split =
  max(2, 2 min_samples_leaf), min_samples_leaf, 0, max_depth, 0)``; no pruning (ccp_alpha 0).
- ``max_features = "sqrt"`` is ``max(1, int(sqrt(D)))``.

Leaf values are class fractions (``Gini.node_value``: weighted class counts / node weight).
"""
from __future__ import annotations

import dataclasses
import numbers
import warnings

import numpy as np
from sklearn.tree._criterion import Gini
from sklearn.tree._splitter import BestSplitter
from sklearn.tree._tree import DepthFirstTreeBuilder, Tree

from relaff_jax.config.experiment import ForestConfig, max_features_value
from relaff_jax.learn.forest.estimator import n_trees, subsample_weights

MAX_INT = np.iinfo(np.int32).max  # sklearn.ensemble._forest.MAX_INT
_RS = np.random.RandomState(0)  # reseeded per tree: constructing one costs ~100 us


@dataclasses.dataclass
class Trees:
    """One fitted forest: ``trees`` (T scikit-learn ``Tree`` objects, in the forest's order),
    ``classes: (K,)`` the sorted distinct labels (K = 1 if the forest saw one class)."""

    trees: list
    classes: np.ndarray
    n_features: int


def max_features_of(n_features: int, cfg: ForestConfig) -> int:
    """Features tried per split, as ``DecisionTreeClassifier._fit`` resolves ``max_features``."""
    mf = max_features_value(cfg.max_features)
    if mf == "sqrt":
        return max(1, int(np.sqrt(n_features)))
    if mf == "log2":
        return max(1, int(np.log2(n_features)))
    if mf is None:
        return n_features
    if isinstance(mf, numbers.Integral):
        return int(mf)
    return max(1, int(mf * n_features)) if mf > 0.0 else 0


def n_bootstrap(n_samples: int, cfg: ForestConfig) -> int:
    """Draws per tree, as ``sklearn.ensemble._bootstrap._get_n_samples_bootstrap``."""
    ms = cfg.max_samples
    if ms is None:
        return n_samples
    if isinstance(ms, numbers.Integral):
        return int(ms)
    nb = max(int(ms * n_samples), 1)
    if nb < max(10, n_samples ** (1 / 3)):
        warnings.warn(f"Using the fractional value max_samples={ms} when the number of samples is {n_samples} "
                      f"results in a low number ({nb}) of bootstrap samples. "
                      "We recommend passing `max_samples` as an integer instead.")
    return nb


def check_engine_config(cfg: ForestConfig) -> None:
    """The engine builds what ``make_forest`` configures only for these settings."""
    if cfg.criterion != "gini":
        raise ValueError(f"the fast and compiled forest engines build gini trees only, got criterion={cfg.criterion!r}")
    if not cfg.bootstrap and cfg.max_samples is not None:
        raise ValueError("`max_sample` cannot be set if `bootstrap=False`.")


def fit_trees(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig(),
              rs: np.random.RandomState | None = None) -> Trees:
    """The trees of ``RandomForestClassifier(random_state=seed)`` on ``X: (N, D)``, ``y: (N,)``.

    ``X`` must be finite (``fit_forest`` checks it); ``rs`` is a ``RandomState`` to reseed
    (default: this module's own, reseeded; one process fits one forest at a time).
    """
    check_engine_config(cfg)
    X = np.asfortranarray(X, dtype=np.float32)  # the layout the builder converts to per tree
    y = np.asarray(y)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"fit_trees: X must be (N, D) and y (N,), got {X.shape} and {y.shape}")
    n, d = X.shape
    classes, enc = np.unique(y, return_inverse=True)
    y_enc = np.ascontiguousarray(enc.reshape(-1, 1), dtype=np.float64)
    n_classes = np.asarray([len(classes)], dtype=np.intp)
    max_features = max_features_of(d, cfg)
    msl = cfg.min_samples_leaf
    msl = int(msl) if isinstance(msl, numbers.Integral) else int(np.ceil(msl * n))  # as _fit resolves it
    min_split = max(2, 2 * msl)
    max_depth = MAX_INT if cfg.max_depth is None else int(cfg.max_depth)
    nb = n_bootstrap(n, cfg) if cfg.bootstrap else None
    rs = _RS if rs is None else rs
    rs.seed(int(seed))
    seeds = [rs.randint(MAX_INT) for _ in range(n_trees(n, cfg))]  # _set_random_states, per tree
    trees = []
    for s in seeds:
        sw = None
        if cfg.per_tree == "subsample":
            sw = subsample_weights(rs, s, n)
        elif cfg.bootstrap:
            rs.seed(s)
            sw = np.bincount(rs.randint(0, n, nb), minlength=n).astype(np.float64)
        rs.seed(s)  # the splitter draws its seed from a fresh RandomState(s) in BestSplitter.init
        splitter = BestSplitter(Gini(1, n_classes), max_features, msl, 0.0, rs, None)
        tree = Tree(d, n_classes, 1)
        DepthFirstTreeBuilder(splitter, min_split, msl, 0.0, max_depth, 0.0).build(tree, X, y_enc, sw, None)
        trees.append(tree)
    return Trees(trees, classes, d)
