"""Step 3 of the protocol, one block: a (target, repetition, chunk of sizes) of the sweep.

Takes a target pool's states ``X: (M, D)``, labels ``y: (M,)``, bootstrap inputs ``boot: (R,
M)``, the target's condition plan and one repetition's draw; ``run_block`` fits one forest per
distinct bootstrap input set and size (``engine.fit``), predicts the test set with all of
them at once (``engine.predict_many``) and returns the test accuracies ``(C, sizes)``.
``run_block_to_file`` also saves them atomically; ``read_block`` reads a finished block back
(None if missing or corrupt, so a killed sweep resumes with the finished blocks).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.learn.engine import Trees, fit, predict_many
from relaff_jax.learn.forests import ForestConfig
from relaff_jax.learn.states import augment
from relaff_jax.provenance import derive_seed

FLUSH = 256  # fast-engine forests evaluated together (bounds the trees held in memory)


def run_block(X: np.ndarray, y: np.ndarray, boot: np.ndarray, plan: Sequence[tuple[int, tuple[int, ...]]],
              train_order: np.ndarray, test_idx: np.ndarray, sizes: Sequence[int], repeats: int,
              n_conditions: int, forest: ForestConfig, seed_keys: Sequence[int]) -> np.ndarray:
    """Accuracies ``(C, len(sizes))`` of one (target, repetition) over a chunk of sizes.

    X: (M, D) target-pool states in the target's order; y: (M,) labels; boot: (R, M) 0/1
    bootstrap inputs on the same scenes; plan: ``[(condition, rows of boot)]``; train_order:
    (>= max(sizes),) training sample order (size n uses its first n); test_idx: (T,).
    Conditions not in the plan stay NaN. Conditions with the same rows share one learner.
    Forest seeds come from ``seed_keys`` + (n, first condition with these rows).
    """
    acc = np.full((n_conditions, len(sizes)), np.nan)
    first: dict[tuple[int, ...], int] = {}
    y = np.asarray(y).astype(bool)
    X = np.asarray(X, dtype=np.float32)
    d0 = X.shape[1]
    boot = np.asarray(boot, dtype=np.float32)
    y_test = y[test_idx]
    # the test rows' columns, shared by every forest of the block: the state, then every
    # bootstrap input row once; forest features map to them (augment repeats input columns)
    ZT = np.concatenate([X[test_idx].T, boot[:, test_idx]])
    forests, colmaps, slots = [], [], []

    def flush():  # predict the fitted forests at once (the sklearn engine one by one)
        for (c, si), p in zip(slots, predict_many(forests, ZT, colmaps)):
            acc[c, si] = np.mean(p.astype(bool) == y_test)
        forests.clear(), colmaps.clear(), slots.clear()

    for cond, rows in plan:
        if rows in first:
            continue
        first[rows] = cond
        inputs = boot[list(rows)]
        if not np.all(np.isfinite(inputs)):
            raise ValueError(f"condition {cond}: bootstrap inputs {rows} were not computed for this space")
        colmap = np.concatenate([np.arange(d0), d0 + np.repeat(np.asarray(rows, dtype=np.intp), repeats)])
        for si, n in enumerate(sizes):
            tr = train_order[:n]
            forests.append(fit(augment(X[tr], inputs[:, tr], repeats), y[tr], derive_seed(*seed_keys, n, cond), forest))
            colmaps.append(colmap)
            slots.append((cond, si))
            if len(forests) >= (FLUSH if isinstance(forests[0], Trees) else 1):
                flush()
    flush()
    for cond, rows in plan:
        if first[rows] != cond:
            acc[cond] = acc[first[rows]]
    return acc


def run_block_to_file(path: str, X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys):
    """``run_block``, then its accuracies and sizes saved atomically to ``path`` (a finished block)."""
    acc = run_block(X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys)
    rio.atomic_save_npz(path, acc=acc, sizes=np.asarray(sizes))
    return acc


def read_block(path: Path, n_conditions: int, sizes: Sequence[int]) -> np.ndarray | None:
    """A finished block, or None if missing or unreadable (then it is recomputed)."""
    if not path.exists():
        return None
    try:
        with np.load(path) as z:
            acc, s = z["acc"], z["sizes"]
    except Exception:  # a corrupt file cannot be a finished block (writes are atomic)
        return None
    if acc.shape != (n_conditions, len(sizes)) or list(s) != list(sizes):
        return None
    return acc
