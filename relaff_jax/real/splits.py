"""Train / test splits of the real pairs for the REAL -> REAL and REAL <- SIM experiments.

Takes the pairs' relations ``y (N,)`` (1 = on_top) and, for the grouped split, their scenes
``scene (N,)``; gives per repetition ``(train, test)`` index arrays, train interleaved by class
(on_top, beside, on_top, ...) so that its first n indices are a balanced training set of
size n (the learning curves of REAL <- SIM read them so).

- ``split_sizes``: per-class pool, train and test counts (the paper's 100 of 160);
- ``pair_split``: pairs drawn one by one (pairs of one scene may fall on both sides);
- ``scene_splits``: every pair of a scene on one side, a fresh grouping per repetition: scenes
  in random order go to the test side while it still lacks pairs of a class they hold, the
  rest to train; then ``test`` pairs of each class are drawn from the test side and the same
  number ``n_train`` of each class from the train side for every repetition (the least any
  repetition leaves, at most the pair split's), so the curves share their sizes;
- ``train_pool``: the whole of a training folder, balanced (cross-folder studies).
"""
from __future__ import annotations

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.provenance import derive_seed
from relaff_jax.config import streams


def split_sizes(y: np.ndarray, train_fraction: float) -> dict:
    """Per-class pool, train and test counts of the real data: the pool is the smaller class
    count m, train round(train_fraction * m) per class (>= 1), test the rest (>= 1)."""
    y = np.asarray(y)
    m = int(min((y == 0).sum(), (y == 1).sum()))
    if m < 2:
        raise UserError(f"the real data need >= 2 pairs of each relation, have {int((y == 0).sum())} beside "
                        f"and {int((y == 1).sum())} on_top")
    train = int(min(max(1, round(train_fraction * m)), m - 1))
    return dict(pool=m, train=train, test=m - train)


def balanced_take(rng: np.random.Generator, idx0: np.ndarray, idx1: np.ndarray, k: int) -> np.ndarray:
    """k indices of each class, interleaved (class 1, class 0, class 1, ...), shuffled within class."""
    a, b = rng.permutation(idx1)[:k], rng.permutation(idx0)[:k]
    if len(a) < k or len(b) < k:
        raise UserError(f"need {k} samples of each class, have {len(idx1)} and {len(idx0)}")
    return np.stack([a, b], axis=1).ravel()


def pair_split(rng: np.random.Generator, y: np.ndarray, sz: dict) -> tuple[np.ndarray, np.ndarray]:
    """A balanced pool of ``sz['pool']`` pairs per class, its first ``sz['train']`` per class to train."""
    y = np.asarray(y).astype(bool)
    pool = balanced_take(rng, np.flatnonzero(~y), np.flatnonzero(y), sz["pool"])
    return pool[: 2 * sz["train"]], pool[2 * sz["train"]:]


def _group(rng: np.random.Generator, y: np.ndarray, scene: np.ndarray, k_test: int) -> np.ndarray:
    """(N,) bool, True = test side: whole scenes, until the test side has ``k_test`` of each class."""
    names = np.unique(scene)
    test = np.zeros(len(y), bool)
    have = np.zeros(2, int)
    for s in rng.permutation(names):
        rows = scene == s
        holds = np.bincount(y[rows], minlength=2) > 0
        if np.any(holds & (have < k_test)):
            test |= rows
            have += np.bincount(y[rows], minlength=2)
    return test


def scene_splits(y: np.ndarray, scene: np.ndarray, sz: dict, seed: int, reps: int,
                 code: int = 0) -> tuple[list[tuple[np.ndarray, np.ndarray]], int]:
    """``reps`` grouped splits (see the module docstring) and ``n_train`` per class.
    Raises ``UserError`` when the scenes cannot give a test side with ``sz['test']`` pairs of
    each class and a train side with >= 1 of each (e.g. every on_top pair in one scene)."""
    y, scene = np.asarray(y).astype(int), np.asarray(scene).astype(str)
    sides = []
    for r in range(reps):
        rng = np.random.default_rng(derive_seed(seed, streams.REAL_SPLIT, code, r))
        test = _group(rng, y, scene, sz["test"])
        sides.append((rng, test))
    left = [min(int(((~t) & (y == c)).sum()) for c in (0, 1)) for _, t in sides]
    n_train = min(sz["train"], min(left))
    if n_train < 1 or any(min(int((t & (y == c)).sum()) for c in (0, 1)) < sz["test"] for _, t in sides):
        per = {c: len(np.unique(scene[y == c])) for c in (0, 1)}
        raise UserError(f"a split by scene needs whole scenes giving >= {sz['test']} test pairs and >= 1 training "
                        f"pair of each relation; the pairs lie in {per[0]} scenes with beside and {per[1]} with "
                        "on_top pairs (use real.experiment.split=pair, labelled as such, or label more scenes)")
    out = []
    for rng, test in sides:
        tr = balanced_take(rng, np.flatnonzero(~test & (y == 0)), np.flatnonzero(~test & (y == 1)), n_train)
        te = balanced_take(rng, np.flatnonzero(test & (y == 0)), np.flatnonzero(test & (y == 1)), sz["test"])
        out.append((tr, te))
    return out, n_train


def train_pool(rng: np.random.Generator, y: np.ndarray) -> np.ndarray:
    """All pairs of the smaller class and as many drawn from the larger, interleaved (a training
    folder used whole, tested on another folder)."""
    y = np.asarray(y).astype(bool)
    m = int(min(y.sum(), (~y).sum()))
    if m < 2:
        raise UserError(f"the training folder needs >= 2 pairs of each relation, have {int((~y).sum())} beside "
                        f"and {int(y.sum())} on_top")
    return balanced_take(rng, np.flatnonzero(~y), np.flatnonzero(y), m)
