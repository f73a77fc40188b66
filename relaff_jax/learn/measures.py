"""Table II from mean accuracy curves, for one estimate or a batch of bootstrap resamples.

Takes mean accuracy curves ``mean: (..., A, C + 2, S)`` over target, condition and size (the
sweep's C conditions, then the two online "best after ten" learners of ``online.py``), the
sizes, the config and the condition layout; ``table2_rows`` gives, per Table II row and
target, two measures over the window ``cfg.bf_sizes`` (paper V-C: n = 4..25):

* ``bf``: the average bootstrap factor, the mean of bf(n) = (P_bl - P_c) / (P_sl - P_c) over
  the sizes of the window where it is defined (P_sl > P_c); ``defined``: how many sizes that
  was per target (0: the target has no value, and is left out of the row's average);
* ``gain``: the mean accuracy gain over the window, mean of P_bl(n) - P_sl(n) (a difference of
  accuracies, defined wherever both ran, linear in the accuracies: well conditioned where bf
  is not, i.e. where P_sl is near chance).

Choices ("best", "best after ten") use ``tie_weights``: every candidate tied at the highest
score gets an equal share, so a tie counts as a uniform random choice among the tied
candidates (its expected value), never as "whichever comes first". ``summarise`` gives each
row's avg/min/max over the targets with a value and how many those are (``n_targets``).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from relaff_jax.learn.config import TABLE2_ROWS, ExperimentConfig

TIE_TOL = 1e-12  # scores closer than this are tied (accuracies are multiples of 1/T)


def size_mask(sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    """``(S,)`` bool: lo <= n <= hi."""
    s = np.asarray(sizes)
    return (s >= lo) & (s <= hi)


def bootstrap_factor(p_bl: np.ndarray, p_sl: np.ndarray, chance: float = 0.5) -> np.ndarray:
    """bf = (P_bl - P_c) / (P_sl - P_c) (paper III-D), broadcast; NaN where P_sl <= P_c
    (the standard learner is at or below chance and the ratio has no meaning)."""
    p_bl, p_sl = np.asarray(p_bl, dtype=float), np.asarray(p_sl, dtype=float)
    den = p_sl - chance
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (p_bl - chance) / np.where(den > 0, den, 1.0), np.nan)


def window_mean(x: np.ndarray, sizes: Sequence[int], lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the finite values of ``x (..., S)`` over lo <= n <= hi, and how many there were."""
    w = np.asarray(x, dtype=float)[..., size_mask(sizes, lo, hi)]
    ok = np.isfinite(w)
    n = ok.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.where(ok, w, 0.0).sum(-1) / np.maximum(n, 1), np.nan), n


def tie_weights(score: np.ndarray) -> np.ndarray:
    """``score (..., K) -> (..., K)``: 1/m on the m candidates tied at the maximum, 0 elsewhere;
    NaN scores never win; all NaN gives all 0."""
    s = np.where(np.isfinite(score), score, -np.inf)
    top = s.max(-1, keepdims=True)
    win = np.isfinite(top) & (s >= top - TIE_TOL)
    return win / np.maximum(win.sum(-1, keepdims=True), 1)


def weighted(values: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``sum_k w_k values_k`` over the last axis; NaN where the weights are all 0."""
    v = np.where(w > 0, values, 0.0)
    return np.where(w.sum(-1) > 0, (v * w).sum(-1), np.nan)


def table2_rows(mean: np.ndarray, sizes: Sequence[int], cfg: ExperimentConfig, lay: dict) -> dict[str, Any]:
    """Per target values of every Table II row, ``bf`` and ``gain`` ``(..., rows, A)`` (rows in
    ``TABLE2_ROWS`` order), and ``defined (..., A)``: the window's sizes where bf is defined
    (P_sl > chance; the same for every row). ``mean: (..., A, C + 2, S)`` as in the module
    docstring."""
    mean = np.asarray(mean, dtype=float)
    nb = mean[..., lay["NB"], :][..., None, :]  # (..., A, 1, S)
    bf = bootstrap_factor(mean, nb, cfg.chance)
    lo, hi = cfg.bf_sizes
    avg, defined = window_mean(bf, sizes, lo, hi)  # (..., A, C + 2)
    gain, _ = window_mean(mean - nb, sizes, lo, hi)
    on = {"DB1": lay["n"], "CB1": lay["n"] + 1}
    b_lo, b_hi = cfg.best_sizes
    best_mask = size_mask(sizes, b_lo, b_hi)
    best_mask = best_mask if best_mask.any() else np.ones_like(best_mask)
    at = list(sizes).index(cfg.select_size) if cfg.select_size in sizes else None
    out: dict[str, Any] = {}
    for key, val in (("bf", avg), ("gain", gain)):
        rows: dict[str, np.ndarray] = {"NB": val[..., lay["NB"]]}
        for fam in ("DB1", "CB1"):
            idx = lay[fam]
            fam_mean = mean[..., idx, :]  # (..., A, K, S)
            ran = np.any(np.isfinite(fam_mean), -1)
            with _quiet():
                score_best = np.nanmean(np.where(best_mask, fam_mean, np.nan), -1)
                rows[f"{fam} average"] = np.nanmean(np.where(ran, val[..., idx], np.nan), -1)
            w_ten = tie_weights(fam_mean[..., at]) if at is not None else tie_weights(score_best)
            rows[f"{fam} best"] = weighted(val[..., idx], tie_weights(score_best))
            rows[f"{fam} best after ten"] = weighted(val[..., idx], w_ten)
            rows[f"{fam} best after ten (online)"] = val[..., on[fam]]
            if fam == "DB1":
                rows["DBn"] = val[..., lay["DBn"]]
            else:
                rows["CBn"] = val[..., lay["CBn"][list(cfg.thresholds).index(cfg.cbn_threshold)]]
        out[key] = np.stack([rows[r] for r in TABLE2_ROWS], axis=-2)
    # bf(n) is defined where P_sl(n) > chance: the same sizes for every row of a target
    out["defined"] = defined[..., lay["NB"]]
    return out


def summarise(per_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(..., rows, A) -> (..., rows, 3)`` avg/min/max over the finite targets, and
    ``n_targets (..., rows)`` how many targets were finite."""
    ok = np.isfinite(per_target)
    with _quiet():
        stats = np.stack([np.nanmean(per_target, -1), np.nanmin(per_target, -1), np.nanmax(per_target, -1)], -1)
    return stats, ok.sum(-1)


class _quiet:
    """Silence numpy's 'mean of empty slice' warnings for all-NaN slices (they give NaN)."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)
