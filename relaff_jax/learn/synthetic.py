"""Labelled synthetic features in the dataset stage's layout, one dataset per action.

Takes a sample count per action and a seed; gives ``{action: {label, relation, pca, rhf,
...}}`` like ``load_dataset``, so the whole learning stage runs (``relaff experiment
--synthetic N``, the tests, the benchmarks) without simulated datasets. Not a simulation.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.constants import ACTIONS, PCA_PER_OBJECT, RHF_BINS
from relaff_jax.learn.states import check_action
from relaff_jax.config import streams
from relaff_jax.learn.correlation import category_pairs
from relaff_jax.learn.protocol import layout


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
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), streams.SYNTHETIC]))
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
        }.get(action, near & (pca[:, 6] > -0.5))  # a user action: a relational rule of its own
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


def synthetic_outcomes(a: int, sizes: int, reps: int, n_test: Sequence[int], seed: int = 0,
                       n_thresholds: int = 3, not_run: Sequence[str] = (),
                       targets: Sequence[int] | None = None) -> dict:
    """Paper-shaped outcomes of one space, for the report's resampling paths (tests, benchmarks):
    ``acc (A', C, S, R)``, ``correct (A', C, S, R, N)`` bool (N = max ``n_test``, padding False),
    ``loo (A', C, R)`` in tenths (ties are common, as with ten samples) and ``n_test (A',)``
    over ``targets`` (A' of the A actions; default all; a paper-sized target's outcomes take
    1 GB). As in a sweep: a target's own DB1 and the categories built from it do not run, nor
    the families in ``not_run`` (RHF: DBn, CB1, CBn); conditions that did not run have NaN
    accuracies and leave-one-out and all-False outcomes; a target of ``n_test`` 0 keeps no
    outcomes, only accuracies. Not a simulation."""
    lay = layout(a, n_thresholds)
    targets = list(range(a)) if targets is None else [int(t) for t in targets]
    n_test = np.asarray(n_test, int)[targets]
    c, n = lay["n"], max(int(k) for k in n_test)
    rng = np.random.default_rng(seed)
    pairs = np.asarray(category_pairs(range(a))).reshape(-1, 2)
    ran = np.ones((len(targets), c), bool)
    for j, t in enumerate(targets):
        ran[j, lay["DB1"][t]] = False
        ran[j, lay["CB1"][(pairs == t).any(1)]] = False
    for fam in not_run:
        ran[:, lay[fam]] = False
    skill = rng.uniform(0.5, 0.9, (len(targets), c, sizes, reps))  # each learner's accuracy
    correct = np.zeros((len(targets), c, sizes, reps, n), bool)
    for j in range(len(targets)):
        for si in range(sizes):  # a size at a time: the uniform draws are 8x the outcomes
            correct[j, :, si, :, : n_test[j]] = rng.random((c, reps, n_test[j])) < skill[j, :, si, :, None]
    correct &= ran[:, :, None, None, None]
    if "CBn" not in not_run:
        correct[0, lay["CBn"][-1]] = correct[0, 0]  # a CBn with no category left is NB's learner
    nt = n_test.astype(float)[:, None, None, None]
    with np.errstate(invalid="ignore"):
        acc = np.where(nt > 0, correct.sum(-1) / nt, skill)
    acc = np.where(ran[:, :, None, None], acc, np.nan)
    loo = np.where(ran[:, :, None], rng.integers(5, 11, (len(targets), c, reps)) / 10.0, np.nan)
    return {"acc": acc, "correct": correct, "loo": loo, "n_test": n_test, "lay": lay}
