"""The paper's random forests (section III-B) as scikit-learn estimators at the numpy edge.

Takes states ``X: (N, D)`` float32 and labels ``y: (N,)`` bool; gives fitted forests
(``fit_forest``) and their 0/1 predictions (``predict_class``). ``ForestConfig`` holds the
paper's settings: trees from the sample count (``n_trees``), Gini, depth 200, min leaf 1,
sqrt(M) features per split, Breiman's bootstrap. One forest runs in one process; the sweeps
parallelise over forests (``sweep.py``), never inside one. These estimators are the reference
the fast engine (``engine.py``) is tested against bit for bit.
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sklearn.ensemble import RandomForestClassifier

from relaff_jax.config.experiment import ForestConfig, max_features_value
from relaff_jax.errors import UserError


def subsample_size(n: int) -> int:
    """Distinct samples per tree in the ``subsample`` reading: 2/3 of ``n`` (floor), at least 1."""
    return max(1, (2 * int(n)) // 3)


def subsample_weights(rs: np.random.RandomState, seed: int, n: int) -> np.ndarray:
    """``(n,)`` float64 0/1 weights of one tree's subsample without replacement: a partial
    Fisher-Yates shuffle of 0..n-1 by ``RandomState(seed).randint(i, n)`` for i < m (m =
    ``subsample_size(n)``), the first m kept. The one definition every engine draws (the
    compiled engine's ``rng.draw_subsample``): a zero weight leaves a sample out of the tree,
    as if the tree were fitted on the m kept rows alone (scikit-learn's splitter skips them)."""
    rs.seed(int(seed))
    idx = np.arange(n)
    m = subsample_size(n)
    for i in range(m):
        j = rs.randint(i, n)
        idx[i], idx[j] = idx[j], idx[i]
    w = np.zeros(n, np.float64)
    w[idx[:m]] = 1.0
    return w


def n_trees(n_samples: int, cfg: ForestConfig = ForestConfig()) -> int:
    """T = min(115, 95 + N // 20) trees for N training samples (paper III-B)."""
    if n_samples < 1:
        raise ValueError(f"a forest needs at least one training sample, got {n_samples}")
    return int(min(cfg.max_trees, cfg.base_trees + n_samples // cfg.samples_per_extra_tree))


def make_forest(n_samples: int, seed: int, cfg: ForestConfig = ForestConfig()) -> RandomForestClassifier:
    """An unfitted forest for ``n_samples`` training samples; one process, seeded."""
    from sklearn.ensemble import RandomForestClassifier  # here: the config is read without it (CLI checks)

    return RandomForestClassifier(
        n_estimators=n_trees(n_samples, cfg),
        criterion=cfg.criterion,
        max_depth=cfg.max_depth,
        min_samples_leaf=cfg.min_samples_leaf,
        max_features=max_features_value(cfg.max_features),
        bootstrap=cfg.bootstrap,
        max_samples=cfg.max_samples,
        n_jobs=1,  # parallelism is over forests (sweep.py), never inside one
        random_state=int(seed),
    )


def checked_states(X: np.ndarray, who: str, n_features: int | None = None) -> np.ndarray:
    """``X`` as float32 ``(N, D)`` (``D = n_features`` if given), all finite: the one input
    check of every forest engine; a ``ValueError`` naming ``who`` (the function the caller
    called) otherwise. Checked once, so scikit-learn need not re-check per tree."""
    X = np.asarray(X, dtype=np.float32)
    if X.ndim != 2 or (n_features is not None and X.shape[1] != n_features):
        raise ValueError(f"{who}: X must be (N, {'D' if n_features is None else n_features}), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{who}: X contains NaN or inf")
    return X


def checked_inputs(X: np.ndarray, y: np.ndarray, who: str) -> tuple[np.ndarray, np.ndarray]:
    """``(X, y)`` as float32 ``(N, D)`` and bool ``(N,)``, X finite (``checked_states``); a
    ``ValueError`` naming ``who`` otherwise."""
    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y).astype(bool)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"{who}: X must be (N, D) and y (N,), got {X.shape} and {y.shape}")
    return checked_states(X, who), y


def fit_checked(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig()) -> RandomForestClassifier:
    """``fit_forest`` on inputs ``checked_inputs`` gave (not checked again). The ``subsample``
    reading: the forest scikit-learn builds without a bootstrap, each tree then refitted by
    scikit-learn's ``DecisionTreeClassifier.fit`` on its own 2/3 subsample (``subsample_weights``
    from the tree's seed, the one scikit-learn gave it)."""
    if cfg.per_tree == "subsample":
        forest = make_forest(len(y), seed, dataclasses.replace(cfg, bootstrap=False, per_tree="bootstrap"))
        with _fast():
            forest.fit(X, y)  # the tree seeds (each estimator's random_state) and the fitted attributes
            rs = np.random.RandomState()
            for est in forest.estimators_:
                est.fit(X, y, sample_weight=subsample_weights(rs, est.random_state, len(y)))
        return forest
    forest = make_forest(len(y), seed, cfg)
    with _fast():
        return forest.fit(X, y)


def fit_forest(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig()) -> RandomForestClassifier:
    """Fit a forest. ``X: (N, D)`` state, ``y: (N,)`` bool labels."""
    return fit_checked(*checked_inputs(X, y, "fit_forest"), seed, cfg)


def predict_checked(forest: RandomForestClassifier, X: np.ndarray) -> np.ndarray:
    """``predict_class`` on states ``checked_states`` gave (not checked again)."""
    with _fast():
        return np.asarray(forest.predict(X), dtype=np.float32)


def predict_class(forest: RandomForestClassifier, X: np.ndarray) -> np.ndarray:
    """Predicted class as 0/1 float32 ``(N,)``; a forest that saw one class predicts it."""
    return predict_checked(forest, checked_states(X, "predict_class"))




def check_forest_config(cfg: ForestConfig = ForestConfig()) -> None:
    """scikit-learn's own validation of the forest parameters, the reference of the node's
    declared constraints (``config.experiment.SKLEARN_FOREST``), once per sweep (fits then skip
    re-validation)."""
    try:
        make_forest(2, 0, cfg)._validate_params()
    except ValueError as e:
        raise UserError(f"bad forest config: {e}") from e


def _fast():
    """Skip scikit-learn's per-tree input and parameter re-validation (inputs are checked
    finite above, parameters by ``check_forest_config``): the same trees, ~10-30 % less
    Python overhead per tree, which dominates at the paper's small training sizes."""
    import sklearn

    return sklearn.config_context(assume_finite=True, skip_parameter_validation=True)
