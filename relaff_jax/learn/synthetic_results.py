"""A synthetic experiment folder in the sweep's layout, for the report stage (tests, benchmarks).

``write_synthetic_results(OUT, cfg, ...)`` writes ``experiment.json`` and ``<space>/results.npz``
with the arrays and shapes ``sweep.run_space`` writes (outcomes bit-packed), without fitting a
forest: accuracies and outcomes from ``synthetic.synthetic_outcomes``' rule (each learner a
random skill, each test scene a coin of that skill), one target and size at a time so that a
paper-shaped folder (9 x 50 x 99 x 50 x 4,000 outcomes, 1.1 GB packed) is built in memory of
its packed size. Not a simulation: the numbers only have the right shapes, NaNs and ties.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import to_dict
from relaff_jax.constants import ACTIONS
from relaff_jax.learn import folder as L
from relaff_jax.learn.blocks import SUBSETS
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.correlation import category_pairs
from relaff_jax.learn.protocol import category_masks, condition_names, layout
from relaff_jax.learn.results import FORMAT_VERSION

RHF_NOT_RUN = ("DBn", "CB1", "CBn")  # the paper's RHF runs NB and DB1 only


def _ran(a: int, lay: dict, not_run: Sequence[str]) -> np.ndarray:
    """``(A, C)`` which conditions a sweep runs for each target (not its own DB1, nor the
    categories built from it, nor the families ``not_run``)."""
    pairs = np.asarray(category_pairs(range(a))).reshape(-1, 2)
    ran = np.ones((a, lay["n"]), bool)
    for t in range(a):
        ran[t, lay["DB1"][t]] = False
        ran[t, lay["CB1"][(pairs == t).any(1)]] = False
    for fam in not_run:
        ran[:, lay[fam]] = False
    return ran


def _space(cfg: ExperimentConfig, actions: Sequence[str], reps: int, not_run: Sequence[str], seed: int) -> dict:
    a, s, n = len(actions), len(cfg.sizes), int(cfg.test_size)
    lay = layout(a, len(cfg.thresholds))
    c = lay["n"]
    rng = np.random.default_rng(seed)
    ran = _ran(a, lay, not_run)
    corr = rng.uniform(-0.3, 0.9, (a, a))
    corr = (corr + corr.T) / 2
    np.fill_diagonal(corr, 1.0)
    k, feas = n // 2, n // 4  # balanced test set: positives first, then feasible, infeasible negatives
    parts = (slice(0, k), slice(k, k + feas), slice(k + feas, n))
    acc = np.full((a, c, s, reps), np.nan)
    acc_subset = np.full((a, c, s, reps, len(SUBSETS)), np.nan)
    packed = np.zeros((a, c, s, reps, (n + 7) // 8), np.uint8)
    for t in range(a):
        skill = rng.uniform(0.5, 0.9, (c, s, reps))
        thr = np.round(skill * 256).astype(np.uint16)
        for si in range(s):  # one size at a time: the draws are 8x the packed outcomes
            bits = rng.integers(0, 256, (c, reps, n), dtype=np.uint8) < thr[:, si, :, None]
            bits &= ran[t][:, None, None]
            if "CBn" not in not_run and t == 0:
                bits[lay["CBn"][-1]] = bits[0]  # a CBn with no category left is NB's learner
            packed[t, :, si] = np.packbits(bits, axis=-1)
            acc[t, :, si] = bits.sum(-1) / n
            for j, p in enumerate(parts):
                acc_subset[t, :, si, :, j] = bits[..., p].mean(-1)
    acc = np.where(ran[:, :, None, None], acc, np.nan)
    acc_subset = np.where(ran[:, :, None, None, None], acc_subset, np.nan)
    loo = np.where(ran[:, :, None], rng.integers(5, 11, (a, c, reps)) / 10.0, np.nan)
    return dict(
        acc=acc, sizes=np.asarray(cfg.sizes), actions=np.asarray(actions),
        conditions=np.asarray(condition_names(actions, cfg.thresholds)),
        thresholds=np.asarray(cfg.thresholds, dtype=float), corr=corr,
        category_masks=category_masks(corr, actions, cfg), test_size=np.full(a, n), test_positive=np.full(a, k),
        loo=loo, acc_subset=acc_subset, subset_count=np.tile([k, feas, n - k - feas], (a, 1)),
        corr_feasible=rng.uniform(-1, 1, a), corr_stacked=rng.uniform(-1, 1, a), correct=packed,
        n_test=np.full(a, n), seconds=np.asarray(0.0), seconds_prep=np.asarray(0.0), new_fits=np.asarray(0))


def write_synthetic_results(out: str | os.PathLike, cfg: ExperimentConfig, actions: Sequence[str] = ACTIONS,
                            spaces: Sequence[str] = ("pca", "rhf"), seed: int = 0) -> Path:
    """Write a synthetic experiment folder of ``cfg``'s shapes (``cfg.keep_outcomes`` is taken
    as set) to ``out``; return ``out``. RHF runs NB and DB1 only, as the paper's."""
    out = Path(out)
    for i, space in enumerate(spaces):
        arrays = _space(cfg, list(actions), cfg.reps(space), RHF_NOT_RUN if space == "rhf" else (), seed + i)
        L.space_dir(out, space).mkdir(parents=True, exist_ok=True)
        np.savez(L.results(out, space), **arrays)  # not via a buffer: the paper's PCA outcomes are 1.1 GB
    pools = {t: {"source": cfg.source_size, "corr": cfg.corr_scenes, "test": cfg.test_size} for t in actions}
    rio.atomic_write_json(L.meta(out), {
        "format": FORMAT_VERSION, "config": to_dict(cfg), "seed": int(seed), "actions": list(actions),
        "spaces": list(spaces), "fingerprint": {}, "data": [f"data/{t}" for t in actions], "pool_sizes": pools,
        "started": time.strftime("%Y-%m-%d %H:%M:%S")})
    return out
