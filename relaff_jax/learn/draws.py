"""Step 3's draws: each target's test set and each repetition's training order.

Takes the labels of a target pool ``labels: (M,)`` bool, the requested test size, the
largest training size and the seed; gives

* ``draw_test``: the target's test scenes ``(T,)``, drawn once per target and shared by every
  repetition (and by PCA and RHF). Balanced by class by default: ``T // 2`` positives and as
  many negatives (fewer if the pool lacks them; ``T`` is then even and smaller);
* ``draw_train``: one repetition's training order ``(max_size,)`` from the scenes left
  after the test set; size n trains on its first n (nested). ``balanced=True`` alternates the
  classes (first class chosen at random per repetition) so that every prefix holds
  ``floor(n/2)`` or ``ceil(n/2)`` of each while both last: a deviation from the paper, which
  draws training samples at random from its ~50 % positive data;
* ``draw_rep``: both at once.

Because the test set is fixed and training orders come from the rest, no repetition's
training sample is ever another repetition's test scene. What varies between repetitions
is the training draw (and the forests' seeds); the test set's own sampling error is covered
by resampling its scenes (``intervals.py``). Training sets of different repetitions overlap
when the pool left after the test set is not much larger than ``max_size`` (the quick
preset: 26 scenes for n up to 25), and then nearly coincide at the largest n.
"""
from __future__ import annotations

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.provenance import derive_seed
from relaff_jax.config import streams


def draw_test(labels: np.ndarray, test_size: int, seed: int, target_index: int, balanced: bool = True) -> np.ndarray:
    """Test indices ``(T,)`` into the target pool; the same for every repetition."""
    labels = np.asarray(labels).astype(bool)
    perm = np.random.default_rng(derive_seed(seed, streams.TEST_DRAW, target_index)).permutation(len(labels))
    if not balanced:
        return perm[: int(test_size)]
    pos, neg = perm[labels[perm]], perm[~labels[perm]]
    k = min(int(test_size) // 2, len(pos), len(neg))
    if k < 1:
        raise UserError(f"target pool of {len(labels)} scenes ({len(pos)} positive): a balanced test set needs both "
                        "classes (use more data, or --set experiment.balanced_test=false)")
    return np.concatenate([pos[:k], neg[:k]])


def draw_train(labels: np.ndarray, test_idx: np.ndarray, max_size: int, seed: int, target_index: int, rep: int,
               balanced: bool = False) -> np.ndarray:
    """One repetition's training order ``(max_size,)``: scenes of the pool not in ``test_idx``."""
    labels = np.asarray(labels).astype(bool)
    rest = np.setdiff1d(np.arange(len(labels)), test_idx)
    if len(rest) < max_size:
        raise UserError(f"target pool: {len(rest)} scenes left after the test set, but training needs {max_size}")
    rng = np.random.default_rng(derive_seed(seed, streams.TRAIN_DRAW, target_index, rep))
    order = rest[rng.permutation(len(rest))]
    if balanced:
        pos, neg = order[labels[order]], order[~labels[order]]
        first, second = (pos, neg) if rng.integers(2) else (neg, pos)
        k = min(len(pos), len(neg))
        pairs = np.stack([first[:k], second[:k]], axis=1).reshape(-1)
        order = np.concatenate([pairs, first[k:], second[k:]])
    return order[:max_size]


def draw_rep(labels: np.ndarray, test_size: int, max_size: int, seed: int, target_index: int, rep: int,
             balanced_test: bool = True, balanced_train: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Test indices ``(T,)`` and training order ``(max_size,)`` of one repetition."""
    test = draw_test(labels, test_size, seed, target_index, balanced_test)
    return test, draw_train(labels, test, max_size, seed, target_index, rep, balanced_train)
