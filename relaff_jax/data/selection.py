"""Balanced selection of N rollouts with COG-distance-matched negatives (paper IV-D).

Takes the labels and COG distances of every rollout, N and a seed; gives a ``Selection``
(sorted rollout indices and the bin counts) or None when a class has too few rollouts.
Positives are drawn uniformly; negatives are drawn so that their histogram of the distance
between the two objects' centres of gravity matches the positives' (otherwise a classifier
learns "small distance => positive" and never the on-top/inside relation).
"""
from __future__ import annotations

import dataclasses

import numpy as np

SELECT_SALT = 0x5E1EC7  # separates the selection's RNG stream from anything else seeded by `seed`


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
    label: np.ndarray, cog_distance: np.ndarray, n: int, seed: int, bins: int = 20
) -> Selection | None:
    """Pick ``n`` rollouts: ``n // 2`` positives uniformly, the rest COG-distance-matched negatives.

    label: (R,) bool; cog_distance: (R,) float. Returns ``None`` when there are fewer than
    ``n // 2`` positives or ``n - n // 2`` negatives. Scheme (docs/datasets.md):
    1. positives: ``n_pos`` drawn uniformly without replacement;
    2. ``bins`` equal-width bins over [min, max] of the selected positives' distances; each
       bin's negative quota is its positive count (scaled by largest remainder when N is odd);
    3. each bin's quota is drawn uniformly from the negatives in that bin;
    4. a bin with too few negatives takes all it has, and its deficit is filled, bins in
       order, with the remaining negatives nearest to the bin's interval (random tie-break);
       their number is ``borrowed``.
    All draws come from one numpy Generator seeded by ``(seed, SELECT_SALT)``.
    """
    label = np.asarray(label, bool)
    dist = np.asarray(cog_distance, np.float64)
    n_pos, n_neg = n // 2, n - n // 2
    pos, neg = np.flatnonzero(label), np.flatnonzero(~label)
    if len(pos) < n_pos or len(neg) < n_neg:
        return None
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), SELECT_SALT]))
    sel_pos = np.sort(rng.choice(pos, n_pos, replace=False))
    d_pos = dist[sel_pos]
    edges = np.linspace(d_pos.min(), d_pos.max(), bins + 1)
    pos_counts = np.bincount(_bin_index(d_pos, edges), minlength=bins)
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
