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

from relaff_jax.config import is_int
from relaff_jax.errors import UserError


# the forest builders (ForestConfig.engine)
ENGINES = ("fast", "sklearn", "compiled")
# readings of "each tree uses 2/3 of the samples" (ForestConfig.per_tree; docs/learning.md)
PER_TREE = ("bootstrap", "subsample")


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


def max_features_value(mf: str | None) -> str | int | float | None:
    """``ForestConfig.max_features`` as scikit-learn takes it: "sqrt" / "log2" / None as they
    are, a numeric string as an int (features per split) or a float (a fraction of them), so
    ``--set experiment.forest.max_features=0.5`` is the fraction 0.5."""
    if mf is None or mf in ("sqrt", "log2"):
        return mf
    try:
        return int(mf)
    except (TypeError, ValueError):
        pass
    try:
        return float(mf)
    except (TypeError, ValueError):
        return mf  # scikit-learn's validation names the problem (check_forest_config)


def check_forest_node(cfg: ForestConfig) -> None:
    """What a ``ForestConfig`` can check without scikit-learn (run when one is made): the
    engine, the gini-only rule of the fast and compiled engines (refused here rather than in a
    worker mid-sweep), and scikit-learn's constraints on each parameter."""
    if cfg.engine not in ENGINES:
        raise UserError(f"experiment.forest.engine {cfg.engine!r}: expected one of {', '.join(ENGINES)}")
    if cfg.engine != "sklearn" and cfg.criterion != "gini":
        raise UserError(f"experiment.forest.criterion {cfg.criterion!r}: the {cfg.engine} engine builds gini trees "
                        "only (the paper's); set experiment.forest.engine=sklearn for another criterion")
    if not cfg.bootstrap and cfg.max_samples is not None:
        raise UserError("experiment.forest.max_samples needs experiment.forest.bootstrap=true")
    if cfg.per_tree not in PER_TREE:
        raise UserError(f"experiment.forest.per_tree must be one of {PER_TREE}, got {cfg.per_tree!r}")
    if cfg.per_tree == "subsample" and (not cfg.bootstrap or cfg.max_samples is not None):
        raise UserError("experiment.forest.per_tree=subsample draws each tree's 2/3 itself: it needs "
                        "experiment.forest.bootstrap=true and max_samples=null")
    # scikit-learn's parameter constraints, without importing it (check_forest_config runs its own)
    for name in ("base_trees", "samples_per_extra_tree", "max_trees"):
        if not is_int(getattr(cfg, name), 1):
            raise UserError(f"experiment.forest.{name} must be an integer >= 1, got {getattr(cfg, name)!r}")
    if cfg.criterion not in ("gini", "entropy", "log_loss"):
        raise UserError(f"experiment.forest.criterion must be gini, entropy or log_loss, got {cfg.criterion!r}")
    if cfg.max_depth is not None and not is_int(cfg.max_depth, 1):
        raise UserError(f"experiment.forest.max_depth must be an integer >= 1 or null, got {cfg.max_depth!r}")
    leaf = cfg.min_samples_leaf
    if not (is_int(leaf, 1) or (_real(leaf) and 0.0 < leaf < 1.0)):
        raise UserError(f"experiment.forest.min_samples_leaf must be an integer >= 1 or a fraction in (0, 1), got {leaf!r}")
    mf = max_features_value(cfg.max_features)
    if not (mf in ("sqrt", "log2", None) or is_int(mf, 1) or (_real(mf) and 0.0 < mf <= 1.0)):
        raise UserError(f"experiment.forest.max_features must be sqrt, log2, null, an integer >= 1 or a fraction "
                        f"in (0, 1], got {cfg.max_features!r}")
    ms = cfg.max_samples
    if not (ms is None or is_int(ms, 1) or (_real(ms) and ms > 0.0)):
        raise UserError(f"experiment.forest.max_samples must be null, an integer >= 1 or a float > 0, got {ms!r}")
    if not isinstance(cfg.bootstrap, bool):
        raise UserError(f"experiment.forest.bootstrap must be true or false, got {cfg.bootstrap!r}")


def _real(v) -> bool:  # a float, not an int (scikit-learn's RealNotInt)
    return isinstance(v, (float, np.floating))


@dataclasses.dataclass(frozen=True)
class ForestConfig:
    """Random forest settings of paper section III-B (defaults are the paper's).

    ``max_samples`` is the reading of "each tree uses 2/3 of the samples": ``None`` (default)
    is Breiman's bootstrap of N draws with replacement, which leaves ~63 % distinct samples
    per tree ("about two thirds"); a float f draws max(1, floor(f N)) with replacement instead
    (f = 2/3 leaves only ~49 % distinct).
    """

    base_trees: int = 95
    samples_per_extra_tree: int = 20
    max_trees: int = 115
    criterion: str = "gini"
    max_depth: int = 200
    min_samples_leaf: int = 1
    max_features: str = "sqrt"
    bootstrap: bool = True
    max_samples: float | None = None
    # "bootstrap": N draws with replacement (Breiman's, ~63 % distinct: "2/3"); "subsample": 2/3
    # of the samples without replacement (``subsample_weights``), the other reading of III-B
    per_tree: str = "bootstrap"
    # "fast": the same trees built by scikit-learn's Cython builder without the estimator and
    # evaluated in one jitted program (learn/engine.py), bit-identical to "sklearn", the
    # RandomForestClassifier reference (tests/learn/test_engine.py); "compiled": the same trees and
    # predictions from scikit-learn's builder re-expressed in numba, many forests per call
    # (learn/compiled/, docs/learning.md)
    engine: str = "fast"

    def __post_init__(self):  # refused when the config is made; scikit-learn's own check: check_forest_config
        check_forest_node(self)


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
    """``check_forest_node``, then scikit-learn's own validation of the forest parameters as the
    reference, once per sweep (fits then skip re-validation)."""
    check_forest_node(cfg)
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
