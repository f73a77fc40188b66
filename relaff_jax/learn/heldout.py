"""The methods against NB that choose a source on test scores, chosen as Table II chooses.

``gains.METHODS``' "best" and "best after ten" rows pick one source per target from the test
accuracies. With the per test scene outcomes kept, Table II's bf and gain of those rows are
held-out: chosen on one half of the test scenes, scored on the other, the two ways averaged
(``measures.table2_rows``). This module gives the same choice for the rest of the methods'
statistics, so that the area, the samples saved and P(improvement) of a "best" row rest on
the learner whose bf and gain the report prints beside them:

* ``choice_weights``: the choice made on one set of curves (Table II's ``_family``: ties share);
* ``heldout_curves``: per choosing method the curve of the source chosen on half h, scored on
  half 1 - h, averaged over h (NaN-aware), and NB's curve read the same way;
* ``half_rep_curves``: per repetition the accuracy on each half (what P(improvement) compares);
* ``heldout_rep_scores``: per repetition the held-out window accuracy of each choosing method
  and NB's on the same halves.

Without outcomes (no halves) the methods keep their in-sample choice, named with
``table2.ORACLE`` (``method_names``).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.learn import halfrows
from relaff_jax.learn.intervals import fast_outcomes, target_blocks
from relaff_jax.learn.measures import _mix, _quiet, _score, size_mask, tie_weights
from relaff_jax.learn.table2 import ORACLE

# gains.METHODS (kept apart: gains imports nothing of this module's)
_CHOOSE_SUFFIXES = ("best", "best after ten")


def choosing(methods: Sequence[str]) -> list[int]:
    """Indices of the methods that choose on test scores ("... best", "... best after ten")."""
    return [i for i, m in enumerate(methods) if m.endswith(_CHOOSE_SUFFIXES)]


def method_names(methods: Sequence[str], heldout: bool) -> list[str]:
    """The methods' names as the report prints them: a choosing method is Table II's held-out
    row with halves, its in-sample oracle (``ORACLE`` appended) without."""
    ch = set(choosing(methods))
    return [m + ("" if heldout or i not in ch else ORACLE) for i, m in enumerate(methods)]


def _family(method: str) -> str:
    return method.split()[0]


def choice_weights(curves: np.ndarray, methods: Sequence[str], lay: dict, sizes: Sequence[int], cfg) -> np.ndarray:
    """``curves (..., A, C', S)`` -> ``(..., K, A, C')`` weights of each of the K choosing
    methods' choice on these curves: "best" the highest mean over ``cfg.best_sizes`` (every size
    if none is inside), "best after ten" the highest at ``cfg.select_size``; ties share, a
    candidate that did not run never wins (``measures.table2_rows``' choice)."""
    curves = np.asarray(curves, float)
    best = size_mask(sizes, *cfg.best_sizes)
    best = best if best.any() else np.ones_like(best)
    at = list(sizes).index(cfg.select_size) if cfg.select_size in sizes else None
    ch = choosing(methods)
    out = np.zeros(curves.shape[:-3] + (len(ch),) + curves.shape[-3:-1])
    for j, k in enumerate(ch):
        idx = lay[_family(methods[k])]
        fm = curves[..., idx, :]
        ran = np.isfinite(fm).any(-1)
        fm = np.where(ran[..., None], fm, np.nan)
        score = fm[..., at] if (methods[k].endswith("after ten") and at is not None) else _score(fm, best)
        sub = out[..., j, :, :]  # a view: (..., A, C')
        sub[..., idx] = tie_weights(score)
    return out


def heldout_curves(halves: np.ndarray, methods: Sequence[str], lay: dict, sizes: Sequence[int],
                   cfg) -> tuple[np.ndarray, np.ndarray]:
    """``halves (..., 2, A, C', S)`` mean curves on each half of the test scenes -> ``(..., K,
    A, S)`` per choosing method the curve of the source chosen on half h scored on half
    1 - h, the mean over h of those with a value, and NB's ``(..., K, A, S)`` over the same
    halves (its curve minus NB's is the mean of Table II's two held-out gain curves)."""
    halves = np.asarray(halves, float)
    wh = [choice_weights(halves[..., h, :, :, :], methods, lay, sizes, cfg) for h in range(2)]
    ch = choosing(methods)
    cur, nbs = [], []
    for h in range(2):
        other = halves[..., 1 - h, :, :, :]  # (..., A, C', S)
        parts = []
        for j, k in enumerate(ch):
            idx = lay[_family(methods[k])]
            parts.append(_mix(other[..., idx, :], wh[h][..., j, :, :][..., idx]))  # (..., A, S)
        c = np.stack(parts, -3)  # (..., K, A, S)
        nb = np.broadcast_to(other[..., None, :, lay["NB"], :], c.shape)
        cur.append(c), nbs.append(np.where(np.isfinite(c), nb, np.nan))
    with _quiet():
        return np.nanmean(np.stack(cur), 0), np.nanmean(np.stack(nbs), 0)


def half_rep_curves(acc_x: np.ndarray, corr_x, halves: np.ndarray, reference: bool = False) -> np.ndarray | None:
    """``(2, A, C', S, R)`` accuracy of every repetition on each half of every test set (None
    without outcomes; NaN where a condition did not run or a half is empty): the values whose
    mean over R is ``analysis.half_curves``."""
    if not corr_x.shape[-1]:
        return None
    a, r = acc_x.shape[0], acc_x.shape[-1]
    ran = np.isfinite(acc_x).any(-1)
    out = np.full((2, a) + tuple(corr_x.shape[1:3]) + (r,), np.nan)
    if not reference and fast_outcomes(corr_x):
        for t in range(a):
            cols = [np.flatnonzero(halves[t] == h) for h in range(2)]
            for sl in corr_x.size_blocks():
                for h, (bits, on) in enumerate(corr_x.half_parts(t, sl, cols)):
                    out[h, t, :, sl] = halfrows.row_means(bits, on)
    else:
        with _quiet():  # an empty half (a one-scene test set) is NaN
            for t in range(a):
                for sl, blk in target_blocks(corr_x, t):
                    for h in range(2):
                        out[h, t, :, sl] = blk[..., halves[t] == h].astype(float).mean(-1)
    return np.where(ran[None, ..., None], out, np.nan)


def heldout_rep_scores(half_reps: np.ndarray, half_means: np.ndarray, methods: Sequence[str], lay: dict,
                       sizes: Sequence[int], cfg) -> tuple[np.ndarray, np.ndarray]:
    """Per repetition the mean window accuracy of each choosing method's held-out learner,
    ``(K, A, R)`` (chosen on half h's mean curves ``half_means (2, A, C', S)``, its repetitions
    scored on half 1 - h ``half_reps (2, A, C', S, R)``, the mean over h of those with a
    value), and NB's ``(K, A, R)`` on the same halves."""
    m = size_mask(sizes, *cfg.bf_sizes)
    with _quiet():
        win = np.asarray(half_reps, float)[..., m, :].mean(-2)  # (2, A, C', R)
    ch = choosing(methods)
    xs, ys = [], []
    for h in range(2):
        w = choice_weights(half_means[h], methods, lay, sizes, cfg)  # (K, A, C')
        other = win[1 - h]  # (A, C', R)
        x = np.stack([_mix(other[:, lay[_family(methods[k])]], w[j][:, lay[_family(methods[k])]])
                      for j, k in enumerate(ch)])  # (K, A, R): the repetitions stand where _mix has sizes
        xs.append(x), ys.append(np.where(np.isfinite(x), other[None, :, lay["NB"]], np.nan))
    with _quiet():
        return np.nanmean(np.stack(xs), 0), np.nanmean(np.stack(ys), 0)
