"""Categories and the correlation heuristic that prunes them (paper sections III-C, V-F).

Takes the actions (A of them) and the 0/1 outputs ``(A, N)`` of their source predictors on
the same scenes; gives the A(A-1)/2 categories (``category_pairs``: 36 for nine actions),
the predictors' correlation matrix ``(A, A)``, each predictor's correlation with a scene
property such as "feasible" or "stacked" (``correlation_with``: ``(A,)``) and which
categories a threshold T keeps (``categories_above``: ``(K,)`` bool).
"""
from __future__ import annotations

import itertools
from typing import Sequence

import numpy as np

from relaff_jax.constants import ACTIONS


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


def correlation_with(outputs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Pearson correlation ``(A,)`` of each predictor's outputs ``(A, N)`` with ``x: (N,)``;
    NaN where either is constant or ``x`` has a NaN (a property the data do not hold)."""
    o = np.asarray(outputs, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if o.shape[-1] != x.shape[0]:
        raise ValueError(f"outputs (A, N) and x (N,) disagree: {o.shape} and {x.shape}")
    if not np.all(np.isfinite(x)):
        return np.full(o.shape[0], np.nan)
    c, d = o - o.mean(axis=1, keepdims=True), x - x.mean()
    den = np.sqrt((c * c).sum(axis=1) * (d * d).sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (c @ d) / np.where(den > 0, den, 1.0), np.nan)


def categories_above(corr: np.ndarray, pairs: Sequence[tuple[int, int]], threshold: float) -> np.ndarray:
    """Which categories the heuristic builds: ``(K,)`` bool, corr > T.

    T <= 0 is the paper's "heuristic not used" (section V-F, T = 0.0): every pair is kept,
    also a pair whose outputs happen to be anti-correlated.
    """
    if threshold <= 0:
        return np.ones(len(pairs), dtype=bool)
    i, j = np.asarray(pairs, dtype=int).reshape(-1, 2).T
    return corr[i, j] > threshold
