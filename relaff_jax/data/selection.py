"""Balanced selection of N rollouts with COG-distance-matched negatives (paper IV-D).

Takes the labels and COG distances of every rollout, N, a seed, which rollouts may be chosen
(``eligible``: the dataset's *population*) and how negatives are drawn; gives a ``Selection``
(sorted rollout indices and the bin counts) or None when a class has too few rollouts.
Positives are drawn uniformly; negatives are drawn so that their histogram of the distance
between the two objects' centres of gravity matches the positives' (``"cog"``, the paper's:
otherwise a classifier learns "small distance => positive" and never the on-top/inside
relation), or uniformly (``"uniform"``).

Why the population is a setting: with this scene sampler the COG-matched negatives of a
stacking action are mostly stacked pairs the arm cannot reach (an infeasible program is
labelled negative), so in the population "all" a label mostly says "reachable"; the
population "feasible" keeps only rollouts whose motor program was executable
(docs/datasets.md, "Population", and ``relaff anatomy``).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from relaff_jax.config import streams
from relaff_jax.config.dataset import NEGATIVES



@dataclasses.dataclass(frozen=True)
class Selection:
    """A balanced selection. ``selected``: (N,) sorted rollout indices."""

    selected: np.ndarray
    n_positive: int
    n_negative: int
    bin_edges: np.ndarray
    positive_bin_counts: np.ndarray
    negative_bin_counts: np.ndarray
    borrowed: int


def _bin_index(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin of each value for bins [e0,e1), ..., [e_{m-1}, e_m] (last closed); -1 outside."""
    nb = len(edges) - 1
    idx = np.searchsorted(edges, x, side="right") - 1
    idx = np.where(x == edges[-1], nb - 1, idx)
    return np.where((x < edges[0]) | (x > edges[-1]), -1, idx)


def _allocate(counts: np.ndarray, total: int) -> np.ndarray:
    """Scale integer ``counts`` to sum to ``total`` (largest remainder, ties to lower bins)."""
    exact = counts * (total / counts.sum())
    base = np.floor(exact).astype(np.int64)
    rest = total - int(base.sum())
    order = np.lexsort((np.arange(len(counts)), -(exact - base)))
    base[order[:rest]] += 1
    return base


def select_balanced(
    label: np.ndarray, cog_distance: np.ndarray, n: int, seed: int, bins: int = 20, *,
    eligible: np.ndarray | None = None, negatives: str = "cog",
) -> Selection | None:
    """Pick ``n`` rollouts: ``n // 2`` positives uniformly, the rest COG-distance-matched negatives.

    label: (R,) bool; cog_distance: (R,) float; eligible: (R,) bool, the rollouts that may be
    chosen (None: all); negatives: ``"cog"`` (steps 2-4 below) or ``"uniform"`` (the
    negatives drawn uniformly from the eligible ones; the bin counts are still reported, and
    ``borrowed`` is 0). Returns ``None`` when there are fewer than ``n // 2`` eligible
    positives or ``n - n // 2`` eligible negatives. With every rollout eligible and
    ``"cog"`` the draws are those of the selection before these options. Scheme
    (docs/datasets.md):
    1. positives: ``n_pos`` drawn uniformly without replacement;
    2. ``bins`` equal-width bins over [min, max] of the selected positives' distances; each
       bin's negative quota is its positive count (scaled by largest remainder when N is odd);
    3. each bin's quota is drawn uniformly from the negatives in that bin;
    4. a bin with too few negatives takes all it has, and its deficit is filled, bins in
       order, with the remaining negatives nearest to the bin's interval (random tie-break);
       their number is ``borrowed``.
    All draws come from one numpy Generator seeded by ``(seed, SELECT_SALT)``.
    """
    if negatives not in NEGATIVES:
        raise ValueError(f"negatives must be one of {NEGATIVES}, got {negatives!r}")
    label = np.asarray(label, bool)
    dist = np.asarray(cog_distance, np.float64)
    ok = np.ones(label.shape, bool) if eligible is None else np.asarray(eligible, bool)
    if ok.shape != label.shape:
        raise ValueError(f"eligible must have the labels' shape {label.shape}, got {ok.shape}")
    n_pos, n_neg = n // 2, n - n // 2
    pos, neg = np.flatnonzero(label & ok), np.flatnonzero(~label & ok)
    if len(pos) < n_pos or len(neg) < n_neg:
        return None
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), streams.SELECT_SALT]))
    sel_pos = np.sort(rng.choice(pos, n_pos, replace=False))
    d_pos = dist[sel_pos]
    edges = np.linspace(d_pos.min(), d_pos.max(), bins + 1)
    pos_counts = np.bincount(_bin_index(d_pos, edges), minlength=bins)
    if negatives == "uniform":
        sel_neg = rng.choice(neg, n_neg, replace=False)
        b = _bin_index(dist[sel_neg], edges)
        neg_counts = np.bincount(b[b >= 0], minlength=bins)
        return Selection(np.sort(np.concatenate([sel_pos, sel_neg])), n_pos, n_neg, edges, pos_counts, neg_counts, 0)
    quota = pos_counts.copy() if n_neg == n_pos else _allocate(pos_counts, n_neg)
    neg_bin = _bin_index(dist[neg], edges)
    taken = np.zeros(len(neg), bool)
    deficit = np.zeros(bins, np.int64)
    for b in range(bins):
        cand = np.flatnonzero(neg_bin == b)
        k = min(int(quota[b]), len(cand))
        taken[rng.choice(cand, k, replace=False)] = True
        deficit[b] = quota[b] - k
    neg_counts = quota - deficit
    for b in np.flatnonzero(deficit):
        pool = np.flatnonzero(~taken)
        x = dist[neg[pool]]
        gap = np.maximum(np.maximum(edges[b] - x, x - edges[b + 1]), 0.0)
        order = np.lexsort((rng.random(len(pool)), gap))
        taken[pool[order[: deficit[b]]]] = True
    selected = np.sort(np.concatenate([sel_pos, neg[taken]]))
    return Selection(selected, n_pos, n_neg, edges, pos_counts, neg_counts, int(deficit.sum()))
