"""The forest engine the learning stages use: ``fast`` (default), ``compiled`` or ``sklearn`` (reference).

Takes states ``X: (N, D)`` float32 and labels ``y: (N,)`` bool; gives fitted forests
(``fit``) and their 0/1 predictions, one forest (``predict``) or a block of forests on
shared test columns (``predict_many``). All three engines give bit-identical forests and
predictions (``tests/learn/test_engine.py``): ``fast`` builds the trees with scikit-learn's own
Cython builder without the estimator (``fit``) and evaluates many forests in one
jitted program (``evaluate``); ``sklearn`` is ``RandomForestClassifier``
(``estimator.fit_forest`` / ``predict_class``); ``compiled`` builds the same trees with
scikit-learn's algorithm re-expressed in numba, many forests per kernel call
(``fit_many``), and predicts them in one compiled call (``learn/forest/compiled/``).

The engine is ``ForestConfig.engine`` (``--set experiment.forest.engine=sklearn``), part of
the config tree like every setting, although it changes no result.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.learn.forest import compiled
from relaff_jax.learn.forest.evaluate import predict_block
from relaff_jax.learn.forest.fit import Trees, fit_trees
from relaff_jax.config.experiment import ENGINES, ForestConfig
from relaff_jax.learn.forest.estimator import checked_inputs, checked_states, fit_checked, predict_checked

__all__ = ["ENGINES", "Trees", "fit", "fit_many", "predict", "predict_many"]


def _engine(cfg: ForestConfig, engine: str | None) -> str:
    engine = engine or cfg.engine
    if engine not in ENGINES:
        raise UserError(f"forest engine {engine!r}: expected one of {', '.join(ENGINES)}")
    return engine


def fit(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig(), engine: str | None = None):
    """A fitted forest on ``X: (N, D)``, ``y: (N,)`` bool (``Trees``, ``compiled.Forest`` or
    ``RandomForestClassifier``); ``engine`` (default ``cfg.engine``) picks how it is built."""
    return _fit_many([X], [y], [seed], cfg, engine, lambda f: "engine.fit")[0]


def fit_many(Xs: Sequence[np.ndarray], ys: Sequence[np.ndarray], seeds: Sequence[int],
             cfg: ForestConfig = ForestConfig(), engine: str | None = None) -> list:
    """F fitted forests, forest f on ``Xs[f]: (N_f, D_f)``, ``ys[f]: (N_f,)`` bool with seed
    ``seeds[f]``: what F calls of ``fit`` give. The compiled engine builds them in one kernel
    call per distinct N (its settings resolve per N); the others one by one."""
    return _fit_many(Xs, ys, seeds, cfg, engine, lambda f: f"engine.fit_many: forest {f}")


def _fit_many(Xs, ys, seeds, cfg, engine, who) -> list:
    """``fit_many``; ``who(f)`` names forest f in an input error (the function called)."""
    engine = _engine(cfg, engine)
    pairs = [checked_inputs(X, y, who(f)) for f, (X, y) in enumerate(zip(Xs, ys))]
    if engine == "sklearn":
        return [fit_checked(X, y, s, cfg) for (X, y), s in zip(pairs, seeds)]
    if engine == "fast":
        return [fit_trees(X, y, s, cfg) for (X, y), s in zip(pairs, seeds)]
    out: list = [None] * len(pairs)
    by_n: dict[int, list[int]] = {}
    for i, (X, _) in enumerate(pairs):
        by_n.setdefault(X.shape[0], []).append(i)
    for ids in by_n.values():
        for i, f in zip(ids, compiled.fit_many([pairs[i][0] for i in ids], [pairs[i][1] for i in ids],
                                               [seeds[i] for i in ids], cfg)):
            out[i] = f
    return out


def predict(forest, X: np.ndarray) -> np.ndarray:
    """Predicted class as 0/1 float32 ``(N,)`` of one forest from ``fit``."""
    n_features = forest.n_features if isinstance(forest, compiled.Forest) else None
    return _predict_one(forest, checked_states(X, "engine.predict", n_features))


def predict_many(forests: Sequence, ZT: np.ndarray, colmaps: Sequence[np.ndarray]) -> np.ndarray:
    """Predicted classes ``(F, N)`` 0/1 float32 of F forests from ``fit`` on shared columns.

    ZT: (Dz, N) float32 test columns; ``colmaps[f]: (D_f,)`` the rows of ``ZT`` that are
    forest f's features, in order. Only referenced columns need be finite.
    """
    ZT = np.asarray(ZT, dtype=np.float32)
    if not forests:
        return np.zeros((0, ZT.shape[1]), np.float32)
    used = np.unique(np.concatenate([np.asarray(cm, dtype=np.intp) for cm in colmaps]))
    if not np.all(np.isfinite(ZT[used])):
        raise ValueError("engine.predict_many: ZT contains NaN or inf in the columns the forests use")
    if all(isinstance(f, Trees) for f in forests):
        return predict_block(forests, ZT, colmaps).astype(np.float32)
    if all(isinstance(f, compiled.Forest) for f in forests):
        return compiled.predict_block(forests, ZT, colmaps).astype(np.float32)
    return np.stack([_predict_one(f, np.ascontiguousarray(ZT[np.asarray(cm)].T)) for f, cm in zip(forests, colmaps)])


def _predict_one(forest, X: np.ndarray) -> np.ndarray:
    """``predict`` of one forest on float32 states ``checked_states`` gave."""
    if isinstance(forest, compiled.Forest):
        return compiled.predict_block([forest], X.T, [np.arange(forest.n_features)])[0].astype(np.float32)
    if isinstance(forest, Trees):
        return predict_block([forest], X.T, [np.arange(X.shape[1])])[0].astype(np.float32)
    return predict_checked(forest, X)
