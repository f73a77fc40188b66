"""The forest engine the learning stages use: ``fast`` (default) or ``sklearn`` (reference).

Takes states ``X: (N, D)`` float32 and labels ``y: (N,)`` bool; gives fitted forests
(``fit``) and their 0/1 predictions, one forest (``predict``) or a block of forests on
shared test columns (``predict_many``). Both engines give bit-identical forests and
predictions (``tests/test_engine.py``): ``fast`` builds the trees with scikit-learn's own
Cython builder without the estimator (``engine_fit``) and evaluates many forests in one
jitted program (``engine_eval``); ``sklearn`` is ``RandomForestClassifier``
(``forests.fit_forest`` / ``predict_class``).

The engine is ``ForestConfig.engine`` (``--set experiment.forest.engine=sklearn``), part of
the config tree like every setting, although it changes no result.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.learn.engine_eval import predict_block
from relaff_jax.learn.engine_fit import Trees, fit_trees
from relaff_jax.learn.forests import ENGINES, ForestConfig, fit_forest, predict_class

__all__ = ["ENGINES", "Trees", "fit", "predict", "predict_many"]


def fit(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig(), engine: str | None = None):
    """A fitted forest on ``X: (N, D)``, ``y: (N,)`` bool (``Trees`` or ``RandomForestClassifier``);
    ``engine`` (default ``cfg.engine``) picks how it is built."""
    engine = engine or cfg.engine
    if engine not in ENGINES:
        raise UserError(f"forest engine {engine!r}: expected one of {', '.join(ENGINES)}")
    if engine == "sklearn":
        return fit_forest(X, y, seed, cfg)
    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y).astype(bool)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"fit_forest: X must be (N, D) and y (N,), got {X.shape} and {y.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("fit_forest: X contains NaN or inf")
    return fit_trees(X, y, seed, cfg)


def predict(forest, X: np.ndarray) -> np.ndarray:
    """Predicted class as 0/1 float32 ``(N,)`` of one forest from ``fit``."""
    if not isinstance(forest, Trees):
        return predict_class(forest, X)
    X = np.asarray(X, dtype=np.float32)
    if not np.all(np.isfinite(X)):
        raise ValueError("predict_class: X contains NaN or inf")
    return predict_block([forest], X.T, [np.arange(X.shape[1])])[0].astype(np.float32)


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
        raise ValueError("predict_class: X contains NaN or inf")
    if all(isinstance(f, Trees) for f in forests):
        return predict_block(forests, ZT, colmaps).astype(np.float32)
    return np.stack([predict(f, np.ascontiguousarray(ZT[np.asarray(cm)].T)) for f, cm in zip(forests, colmaps)])
