"""Learners as plugins: the paper's random forest (default) or any scikit-learn classifier.

``ExperimentConfig.learner`` is ``"forest"`` (the paper's forest, built by
``ForestConfig.engine``: ``engine.py``, the same bits as before learners were plugins) or the
import path of a scikit-learn-compatible classifier (``"sklearn.ensemble.ExtraTreesClassifier"``),
constructed with ``ExperimentConfig.learner_params`` and ``random_state`` = the fit's own seed
(the same ``derive_seed`` every forest gets), so a run is reproducible from its seed. The
learner learns everything the agent learns: the source predictors, the categories and every
condition's classifier (NB and every bootstrapping condition).

Takes states ``X: (N, D)`` float32 and labels ``y: (N,)`` bool, as ``engine.py``; ``fit`` /
``fit_many`` give fitted models, ``predict`` 0/1 float32 ``(N,)``. A training set holding one
class gives a model that predicts that class (what the forest does; many classifiers refuse
one class). ``check_learner`` imports, constructs and fits the learner once on a few rows, so a
bad path, a class that is not a classifier or bad parameters is one ``UserError`` before any work.
"""
from __future__ import annotations

import dataclasses
import importlib
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.config.experiment import FOREST, ForestConfig
from relaff_jax.learn.forest.estimator import _fast, checked_inputs



@dataclasses.dataclass(frozen=True, eq=False)
class SklearnLearner:
    """A scikit-learn classifier by import path and constructor parameters (picklable: worker
    processes import the class themselves)."""

    path: str
    params: Mapping[str, Any]
    engine = "plugin"  # read by the sweep's blocks (batching): not the forest's sklearn engine

    def make(self, seed: int):
        """An unfitted estimator; ``random_state`` = ``seed`` where the class takes one."""
        cls = import_learner(self.path)
        est = cls(**dict(self.params))
        if "random_state" in est.get_params(deep=False):
            est.set_params(random_state=int(seed))
        return est


@dataclasses.dataclass(frozen=True)
class OneClass:
    """The model of a training set holding one class: predicts it everywhere."""

    label: bool

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.full(len(X), self.label)


@dataclasses.dataclass(frozen=True)
class OneThread:
    """A fitted estimator whose ``predict`` runs on one thread (``fit_many``'s rule)."""

    model: Any

    def predict(self, X: np.ndarray) -> np.ndarray:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(1):
            return self.model.predict(X)


def learner_of(cfg: Any) -> ForestConfig | SklearnLearner:
    """The learner an ``ExperimentConfig`` names: its ``ForestConfig`` for the paper's forest
    (the engines' path, unchanged), else a ``SklearnLearner``."""
    if cfg.learner == FOREST:
        return cfg.forest
    return SklearnLearner(cfg.learner, dict(cfg.learner_params))


def fit_many(Xs: Sequence[np.ndarray], ys: Sequence[np.ndarray], seeds: Sequence[int],
             learner: ForestConfig | SklearnLearner) -> list:
    """F fitted models, model f on ``Xs[f]: (N_f, D_f)``, ``ys[f]: (N_f,)`` bool, seed
    ``seeds[f]`` (forests: ``engine.fit_many``)."""
    if isinstance(learner, ForestConfig):
        # scikit-learn loads with the first fit: reproduce --status reads this module
        from relaff_jax.learn.forest import engine  # here: the config imports this module without JAX

        return engine.fit_many(Xs, ys, seeds, learner)
    from threadpoolctl import threadpool_limits

    out = []
    # one thread per fit: parallelism is over fits (worker processes), as for the forest; an
    # OpenMP learner (HistGradientBoosting) left to spin over busy cores was ~70x slower here
    with threadpool_limits(1), _fast():  # parameters checked once (check_learner), inputs below
        for f, (X, y, s) in enumerate(zip(Xs, ys, seeds)):
            X, y = checked_inputs(X, y, f"learners.fit_many: model {f}")
            out.append(OneClass(bool(y[0])) if np.all(y == y[0]) else OneThread(learner.make(s).fit(X, y)))
    return out


def fit(X: np.ndarray, y: np.ndarray, seed: int, learner: ForestConfig | SklearnLearner):
    """One fitted model (``fit_many`` of one)."""
    return fit_many([X], [y], [seed], learner)[0]


def predict(model, X: np.ndarray) -> np.ndarray:
    """0/1 float32 ``(N,)`` predictions of a model from ``fit`` (``engine.predict`` for every
    kind: a model that is no forest is asked for ``predict``)."""
    # scikit-learn loads with the first fit: reproduce --status reads this module
    from relaff_jax.learn.forest import engine

    return engine.predict(model, X)


def import_learner(path: str) -> type:
    """The class at ``path`` (``package.module.Class``); ``UserError`` if it cannot be imported."""
    mod, _, name = path.rpartition(".")
    if not mod or not name:
        raise UserError(f"experiment.learner {path!r}: expected 'forest' or an import path package.module.Class")
    try:
        cls = getattr(importlib.import_module(mod), name)
    except ImportError as e:
        raise UserError(f"experiment.learner {path!r}: cannot import module {mod!r} ({e})") from e
    except AttributeError:
        raise UserError(f"experiment.learner {path!r}: module {mod!r} has no {name!r}") from None
    if not isinstance(cls, type):
        raise UserError(f"experiment.learner {path!r} is not a class")
    return cls


def check_learner(learner: str, params: Mapping[str, Any], min_size: int = 2) -> None:
    """Import the learner, construct it with ``params``, and fit and predict once on
    ``min_size`` rows of both classes (the smallest training size of the protocol), so a bad
    import path, a class that is not a classifier, bad parameters or one that cannot learn from
    the protocol's smallest training sets is one ``UserError`` before any work."""
    if learner == FOREST:  # the node checked its values when it was built
        return
    from sklearn.base import is_classifier

    cls = import_learner(learner)
    where = f"experiment.learner {learner}"
    try:
        est = cls(**dict(params))
    except TypeError as e:
        raise UserError(f"{where}: bad experiment.learner_params {dict(params)} ({e})") from e
    if not (hasattr(est, "fit") and hasattr(est, "predict") and hasattr(est, "get_params")):
        raise UserError(f"{where} is not a scikit-learn estimator (needs fit, predict and get_params)")
    try:
        ok = is_classifier(est)
    except Exception:  # an object scikit-learn cannot read tags from
        ok = False
    if not ok:
        raise UserError(f"{where} is not a classifier (scikit-learn's is_classifier is false)")
    n = max(2, int(min_size))
    rng = np.random.default_rng(0)
    X = rng.normal(size=(n, 4)).astype(np.float32)
    y = np.arange(n) % 2 == 1
    try:
        model = SklearnLearner(learner, dict(params)).make(0).fit(X, y)
        p = np.asarray(model.predict(X))
    except Exception as e:  # scikit-learn's parameter validation, or a learner that needs more rows
        raise UserError(f"{where} with experiment.learner_params {dict(params)} cannot fit {n} training samples "
                        f"(the smallest of experiment.sizes): {type(e).__name__}: {e}") from e
    if p.shape != (n,) or not np.all(np.isin(p, (0, 1))):
        raise UserError(f"{where}: predict must give one 0/1 (or bool) label per row, got shape {p.shape}")
