"""Affordance learning: the paper's random forests, state spaces, bootstrapping inputs and
the correlation heuristic (paper sections III-A to III-C).

Takes per-action numpy feature arrays (the dataset stage's canonical layout: PCA ``(N, 18)``
with the toy's nine values first, RHF ``(N, 300)`` with toy = A, other = B) and gives

* ``state_features``: the state of an action in its own order (manipulated object first),
  ``(N, 18)`` in PCA space or ``(N, 318)`` in RHF space;
* ``make_forest`` / ``fit_forest`` / ``predict_class``: scikit-learn forests parameterised
  as in section III-B (trees from the sample count, Gini, depth 200, min leaf 1, sqrt(M));
* ``augment``: a state extended with bootstrap inputs (0/1 predicted classes of other
  affordance or category predictors), each repeated 6 (PCA) or 30 (RHF) times;
* ``category_pairs`` / ``correlation_matrix`` / ``categories_above``: the 36 categories
  and the correlation heuristic that prunes them;
* ``synthetic_datasets``: labelled synthetic features in the dataset stage's layout, so the
  whole learning stage runs (and is tested) before the simulated datasets exist.

Everything here is plain numpy / scikit-learn at the numpy edge (REFERENCE section 7); the
sweeps over sizes and repetitions live in ``experiment.py``.
"""
from __future__ import annotations

import dataclasses
import itertools
from typing import Sequence

import numpy as np
import sklearn
from sklearn.ensemble import RandomForestClassifier

# The nine actions, in the order used everywhere (arrays, tables, figures).
from relaff_jax.constants import ACTIONS, PCA_PER_OBJECT, RHF_BINS, SPACES  # noqa: F401 (re-exported)
# Actions whose manipulated object is the toy; for the others it is the base / obstacle /
# rake (paper Table I), whose nine PCA values then come first in the state.
TOY_MANIPULATED = frozenset({"move", "take"})


@dataclasses.dataclass(frozen=True)
class ForestConfig:
    """Random forest settings of paper section III-B (defaults are the paper's).

    ``max_samples`` is the reading of "each tree uses 2/3 of the samples": ``None`` (default)
    is Breiman's bootstrap of N draws with replacement, which leaves ~63 % distinct samples
    per tree ("about two thirds"); a float f draws round(f N) with replacement instead
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


def n_trees(n_samples: int, cfg: ForestConfig = ForestConfig()) -> int:
    """T = min(115, 95 + N // 20) trees for N training samples (paper III-B)."""
    if n_samples < 1:
        raise ValueError(f"a forest needs at least one training sample, got {n_samples}")
    return int(min(cfg.max_trees, cfg.base_trees + n_samples // cfg.samples_per_extra_tree))


def make_forest(n_samples: int, seed: int, cfg: ForestConfig = ForestConfig()) -> RandomForestClassifier:
    """An unfitted forest for ``n_samples`` training samples; one process, seeded."""
    return RandomForestClassifier(
        n_estimators=n_trees(n_samples, cfg),
        criterion=cfg.criterion,
        max_depth=cfg.max_depth,
        min_samples_leaf=cfg.min_samples_leaf,
        max_features=cfg.max_features,
        bootstrap=cfg.bootstrap,
        max_samples=cfg.max_samples,
        n_jobs=1,  # parallelism is over forests (experiment.py), never inside one
        random_state=int(seed),
    )


def fit_forest(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig()) -> RandomForestClassifier:
    """Fit a forest. ``X: (N, D)`` state, ``y: (N,)`` bool labels."""
    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y).astype(bool)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"fit_forest: X must be (N, D) and y (N,), got {X.shape} and {y.shape}")
    if not np.all(np.isfinite(X)):  # checked once here, so sklearn need not re-check per tree
        raise ValueError("fit_forest: X contains NaN or inf")
    forest = make_forest(len(y), seed, cfg)
    with _fast():
        return forest.fit(X, y)


def predict_class(forest: RandomForestClassifier, X: np.ndarray) -> np.ndarray:
    """Predicted class as 0/1 float32 ``(N,)``; a forest that saw one class predicts it."""
    X = np.asarray(X, dtype=np.float32)
    if not np.all(np.isfinite(X)):
        raise ValueError("predict_class: X contains NaN or inf")
    with _fast():
        return np.asarray(forest.predict(X), dtype=np.float32)


def check_forest_config(cfg: ForestConfig = ForestConfig()) -> None:
    """Let scikit-learn validate the forest parameters once (fits then skip re-validation)."""
    try:
        make_forest(2, 0, cfg)._validate_params()
    except ValueError as e:
        raise ValueError(f"bad forest config: {e}") from e


def _fast():
    """Skip scikit-learn's per-tree input and parameter re-validation (inputs are checked
    finite above, parameters by ``check_forest_config``): the same trees, ~10-30 % less
    Python overhead per tree, which dominates at the paper's small training sizes."""
    return sklearn.config_context(assume_finite=True, skip_parameter_validation=True)


# ----------------------------------------------------------------------------- state spaces


def manipulated_first_order(action: str) -> np.ndarray:
    """Column order ``(18,)`` that turns canonical PCA (toy first) into the action's order
    (manipulated object first)."""
    check_action(action)
    toy, other = np.arange(PCA_PER_OBJECT), np.arange(PCA_PER_OBJECT, 2 * PCA_PER_OBJECT)
    return np.concatenate([toy, other] if action in TOY_MANIPULATED else [other, toy])


def state_features(pca: np.ndarray, rhf: np.ndarray | None, action: str | None, space: str) -> np.ndarray:
    """The state of scenes as seen by an ``action``'s predictor.

    pca: (N, 18) canonical PCA (toy's 9 values, then the other object's 9).
    rhf: (N, 300) relational histogram (toy = A, other = B); unused in PCA space.
    action: whose order to use (its manipulated object first); ``None`` keeps the canonical
      order (used by category predictors, whose training data mixes two actions).
    Returns (N, 18) in PCA space, (N, 318) in RHF space, float32.
    """
    pca = np.asarray(pca, dtype=np.float32)
    if pca.ndim != 2 or pca.shape[1] != 2 * PCA_PER_OBJECT:
        raise ValueError(f"pca features must be (N, 18), got {pca.shape}")
    state = pca if action is None else pca[:, manipulated_first_order(action)]
    if space == "pca":
        return np.ascontiguousarray(state)
    if space == "rhf":
        if rhf is None:
            raise ValueError("RHF space needs the rhf features, got None")
        rhf = np.asarray(rhf, dtype=np.float32)
        if rhf.shape != (pca.shape[0], RHF_BINS):
            raise ValueError(f"rhf features must be (N, {RHF_BINS}) matching pca's N={pca.shape[0]}, got {rhf.shape}")
        return np.concatenate([state, rhf], axis=1)
    raise ValueError(f"unknown state space {space!r}; expected one of {SPACES}")


def check_action(action: str) -> None:
    if action not in ACTIONS:
        raise ValueError(f"unknown action {action!r}; expected one of {ACTIONS}")


# ---------------------------------------------------------------------- bootstrap inputs


def augment(X: np.ndarray, outputs: np.ndarray, repeats: int) -> np.ndarray:
    """State extended with bootstrap inputs.

    X: (N, D) state; outputs: (K, N) 0/1 predicted classes of K predictors on the same scenes.
    Returns (N, D + K * repeats): each predictor's column repeated ``repeats`` times
    (paper V-B: repetition makes the input more likely to be among the sqrt(M) tried
    features at a split).
    """
    outputs = np.asarray(outputs, dtype=np.float32).reshape(-1, X.shape[0])
    if outputs.shape[0] == 0:
        return np.asarray(X, dtype=np.float32)
    return np.concatenate([np.asarray(X, dtype=np.float32), np.repeat(outputs.T, repeats, axis=1)], axis=1)


def category_pairs(actions: Sequence[str] = ACTIONS) -> list[tuple[int, int]]:
    """All unordered pairs (i < j) of action indices: 36 categories for nine actions."""
    return list(itertools.combinations(range(len(actions)), 2))


def correlation_matrix(outputs: np.ndarray) -> np.ndarray:
    """Pearson correlation ``(A, A)`` of A predictors' outputs ``(A, N)`` on the same scenes.

    A predictor with constant output has no defined correlation; it gets 0 off the diagonal
    (it carries no information about any other) and 1 on it.
    """
    o = np.asarray(outputs, dtype=np.float64)
    c = o - o.mean(axis=1, keepdims=True)
    norm = np.sqrt((c * c).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = (c @ c.T) / np.outer(norm, norm)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    return np.clip(corr, -1.0, 1.0)


def categories_above(corr: np.ndarray, pairs: Sequence[tuple[int, int]], threshold: float) -> np.ndarray:
    """Which categories the heuristic builds: ``(K,)`` bool, corr > T.

    T <= 0 is the paper's "heuristic not used" (section V-F, T = 0.0): every pair is kept,
    also a pair whose outputs happen to be anti-correlated.
    """
    if threshold <= 0:
        return np.ones(len(pairs), dtype=bool)
    i, j = np.asarray(pairs, dtype=int).reshape(-1, 2).T
    return corr[i, j] > threshold


# ----------------------------------------------------------------------- synthetic data


def synthetic_datasets(
    n_per_action: int,
    seed: int = 0,
    actions: Sequence[str] = ACTIONS,
    label_noise: float = 0.1,
) -> dict[str, dict]:
    """Labelled synthetic scenes in ``load_dataset``'s layout, one dataset per action.

    Not a simulation: a stand-in with the paper's structure so that the learning stage can
    be run and tested end to end. Every action has its own scenes (like the real datasets).
    Two latent relations drive the labels: ``near`` (toy's xy close to the other object's:
    'on top'/'inside') and ``side`` (toy reachable beside). Lift, pull, push (and, with an
    extra condition, pour and slide) need ``near``; move, take, rake, unobstruct need
    ``side`` and not ``near``. Labels are flipped with probability ``label_noise`` and then
    balanced to 50 % positive. RHF carries a noisy histogram of the toy-other distance.
    Returns ``{action: {label, relation, cog_distance, toy, other, pca, rhf, unseen, action}}``.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    out: dict[str, dict] = {}
    for action in actions:
        check_action(action)
        # draw 3x candidates, then balance like the dataset stage does (50 % positives)
        m = 3 * n_per_action
        pca = rng.normal(size=(m, 2 * PCA_PER_OBJECT)).astype(np.float32)
        dxy = pca[:, 0:2] - pca[:, 9:11]
        dist = np.linalg.norm(dxy, axis=1)
        near = dist < 1.1
        side = (pca[:, 0] + 0.5 * pca[:, 3] > -0.3) & ~near
        tall = pca[:, 17] > 0.0
        rule = {
            "lift": near, "pull": near, "push": near,
            "pour": near & tall, "slide": near & ~tall,
            "move": side, "take": side & (pca[:, 5] > -0.5), "rake": side, "unobstruct": side & (pca[:, 4] < 0.5),
        }[action]
        label = rule ^ (rng.random(m) < label_noise)
        pos, neg = np.flatnonzero(label), np.flatnonzero(~label)
        k = min(n_per_action // 2, len(pos), len(neg))
        keep = np.concatenate([rng.choice(pos, k, replace=False), rng.choice(neg, n_per_action - k, replace=False)])
        keep = rng.permutation(keep)
        centres = np.linspace(0.0, 4.0, RHF_BINS // 6)
        hist = np.exp(-((dist[keep, None] - centres[None, :]) ** 2) / 0.1)
        rhf = np.tile(hist, (1, 6)) + 0.3 * rng.random((len(keep), RHF_BINS))
        rhf = (rhf / rhf.sum(axis=1, keepdims=True)).astype(np.float32)
        relation = np.where(near[keep], "on_top", "beside")
        out[action] = {
            "label": label[keep],
            "relation": relation,
            "cog_distance": dist[keep].astype(np.float64),
            "toy": np.full(len(keep), "ball", dtype=object),
            "other": np.full(len(keep), "plate", dtype=object),
            "pca": pca[keep],
            "rhf": rhf,
            "unseen": np.zeros(len(keep), dtype=bool),
            "action": action,
        }
    return out
