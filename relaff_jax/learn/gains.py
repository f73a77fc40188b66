"""Beyond the paper's statistics: each bootstrapping method against NB (issue 44).

Pure functions over numpy arrays:

* ``window_area``: the area of the gain curve P_bl(n) - P_nb(n) over the window (trapezoids in
  n, accuracy x samples: a method 0.1 above NB over n = 4..25 has area 2.1);
* ``samples_needed`` / ``samples_saved``: the training samples NB needs to reach the
  bootstrapped learner's accuracy at n = ``at`` (linear interpolation between the sizes run,
  at the first size where NB reaches it), minus ``at``; where NB never reaches it within the
  sizes run the count is censored: the largest size is a lower bound (``censored`` says where);
* ``probability_of_improvement``: P(X > Y) + P(X = Y) / 2 of a method's per-repetition scores
  X against NB's Y on each task (the Mann-Whitney U statistic over n_x n_y, as rliable's
  ``probability_of_improvement``), averaged over tasks; ``stratified_poi`` its resamples,
  the repetitions of each task drawn with replacement, each method's independently (rliable's
  ``StratifiedIndependentBootstrap``);
* ``bootstrap_p`` a two-sided p-value of "value = null" from resamples, and ``holm`` the
  Holm step-down correction over several conditions.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from relaff_jax.learn import heldout as H
from relaff_jax.learn.measures import _quiet, _score, size_mask, tie_weights


def window_area(gain: np.ndarray, sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    """``gain (..., S)`` -> ``(...,)`` trapezoidal area over lo <= n <= hi (NaN where any size
    of the window is NaN; 0 with one size)."""
    m = size_mask(sizes, lo, hi)
    n = np.asarray(sizes, float)[m]
    g = np.asarray(gain, float)[..., m]
    if len(n) < 2:
        return np.where(np.isfinite(g).all(-1), 0.0, np.nan)
    return (0.5 * (g[..., 1:] + g[..., :-1]) * np.diff(n)).sum(-1)


def samples_needed(nb: np.ndarray, sizes: Sequence[int], target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``nb (..., S)``, ``target (...)`` -> (n NB needs, censored): the first size at which NB
    reaches ``target``, interpolated linearly from the size before it (NB's first size itself
    if it starts there); censored (True, n = the largest size) where NB never reaches it;
    NaN where the target or NB's curve is NaN."""
    nb = np.asarray(nb, float)
    s = np.asarray(sizes, float)
    t = np.asarray(target, float)[..., None]
    reach = nb >= t - 1e-12
    first = np.argmax(reach, -1)
    ever = reach.any(-1)
    i = np.maximum(first - 1, 0)
    take = lambda a, j: np.take_along_axis(a, j[..., None], -1)[..., 0]  # noqa: E731
    y0, y1 = take(nb, i), take(nb, first)
    x0, x1 = s[i], s[first]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(y1 > y0, (t[..., 0] - y0) / np.where(y1 > y0, y1 - y0, 1.0), 1.0)
    n = np.where(first == 0, s[0], x0 + np.clip(frac, 0.0, 1.0) * (x1 - x0))
    n = np.where(ever, n, s[-1])
    bad = ~np.isfinite(t[..., 0]) | ~np.isfinite(nb).all(-1)
    return np.where(bad, np.nan, n), ever == False  # noqa: E712


def samples_saved(bl: np.ndarray, nb: np.ndarray, sizes: Sequence[int], at: int) -> tuple[np.ndarray, np.ndarray]:
    """``bl, nb (..., S)`` -> (samples NB needs to reach ``bl`` at n = ``at``, minus ``at``;
    censored): how many training samples the bootstrapped learner saves at n = ``at``."""
    j = list(sizes).index(at)
    n, cens = samples_needed(nb, sizes, np.asarray(bl, float)[..., j])
    return n - at, cens


def poi_task(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``x (..., Rx)``, ``y (..., Ry)`` -> ``(...)`` P(X > Y) + P(X = Y) / 2 over every pair
    (the Mann-Whitney U of x over y, divided by Rx Ry); NaN values are left out."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    gt = (x[..., :, None] > y[..., None, :]).astype(float)
    eq = (x[..., :, None] == y[..., None, :]).astype(float)
    ok = np.isfinite(x)[..., :, None] & np.isfinite(y)[..., None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, gt + 0.5 * eq, 0.0).sum((-1, -2)) / np.where(ok.sum((-1, -2)) > 0, ok.sum((-1, -2)), np.nan)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """``x, y (tasks, reps)``: the mean over tasks of ``poi_task`` (tasks with no value left out)."""
    p = poi_task(x, y)
    return float(np.nanmean(p)) if np.isfinite(p).any() else float("nan")


POI_CELLS = 200_000  # pairs compared at once by stratified_poi (2e6 left the cache: no faster than the loop at R = 50)


def stratified_poi(x: np.ndarray, y: np.ndarray, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """``(n_boot,)`` resampled ``probability_of_improvement``: per task the repetitions drawn
    with replacement, x's and y's independently (per resample x's draw, then y's, from ``rng``).
    The resamples are compared many at once: the bits of ``probability_of_improvement`` on each
    (a task's pairs sum to a multiple of 1/2, exactly; each resample's mean over tasks is the
    same reduction)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    t, rx = x.shape
    ry = y.shape[1]
    ix, iy = np.empty((n_boot, t, rx), np.int64), np.empty((n_boot, t, ry), np.int64)
    for b in range(n_boot):  # the draws in the order of one resample at a time
        ix[b], iy[b] = rng.integers(0, rx, (t, rx)), rng.integers(0, ry, (t, ry))
    rows = np.arange(t)[:, None]
    out = np.empty(n_boot)
    step = max(1, POI_CELLS // max(1, t * rx * ry))
    for b in range(0, n_boot, step):
        p = poi_task(x[rows, ix[b : b + step]], y[rows, iy[b : b + step]])  # (b, t)
        with np.errstate(invalid="ignore"), _quiet():
            out[b : b + step] = np.where(np.isfinite(p).any(-1), np.nanmean(p, -1), np.nan)
    return out


def bootstrap_p(boot: np.ndarray, null: float) -> float:
    """Two-sided p-value of "the value is ``null``" from resampled values: twice the smaller
    share of resamples on either side of it (a tie counts half), at most 1."""
    b = np.asarray(boot, float)
    b = b[np.isfinite(b)]
    if not len(b):
        return float("nan")
    below = np.mean(b < null) + 0.5 * np.mean(b == null)
    return float(min(1.0, 2 * min(below, 1 - below)))


def holm(p: Sequence[float], alpha: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Holm's step-down correction: (adjusted p-values, rejected at ``alpha``). Sorted
    ascending, p_(i) is multiplied by m - i + 1 (i from 1), made monotone, capped at 1; NaN
    p-values take no part (adjusted NaN, not rejected)."""
    p = np.asarray(p, float)
    ok = np.flatnonzero(np.isfinite(p))
    adj = np.full(p.shape, np.nan)
    m = len(ok)
    order = ok[np.argsort(p[ok], kind="stable")]
    run = 0.0
    for i, k in enumerate(order):
        run = max(run, min(1.0, (m - i) * p[k]))
        adj[k] = run
    return adj, np.where(np.isfinite(adj), adj <= alpha, False)


# the learners compared with NB; "best" / "after ten" choose their source on the test scores: on one
# half of the test scenes, scored on the other, where the outcomes are kept (Table II's held-out
# rows, heldout.py), else in-sample on the whole test set (the paper's); "after ten" the whole
# curve of the learner kept at select_size
METHODS = ("DB1 average", "DB1 best", "DB1 best after ten", "DB1 best after ten (online)", "DBn",
           "CB1 average", "CB1 best", "CB1 best after ten", "CB1 best after ten (online)", "CBn")


def method_weights(mean: np.ndarray, lay: dict, cfg, sizes: Sequence[int], cbn_ok: np.ndarray) -> np.ndarray:
    """``(M, A, C + 2)`` weights over the conditions (and the two online learners) of each of
    ``METHODS`` per target, from the mean curves ``mean (A, C + 2, S)`` (ties share); all 0
    where a method did not run for a target."""
    a, c2, _ = mean.shape
    w = np.zeros((len(METHODS), a, c2))
    ran = np.isfinite(mean).any(-1)  # (A, C + 2)
    best = size_mask(sizes, *cfg.best_sizes)
    at = list(sizes).index(cfg.select_size) if cfg.select_size in sizes else None
    for f, fam in enumerate(("DB1", "CB1")):
        idx, base = lay[fam], 5 * f
        r = ran[:, idx]
        fm = np.where(r[..., None], mean[:, idx], np.nan)
        w[base, :, idx] = (r / np.maximum(r.sum(-1, keepdims=True), 1)).T
        w[base + 1, :, idx] = tie_weights(_score(fm, best if best.any() else np.ones_like(best))).T
        w[base + 2, :, idx] = tie_weights(fm[..., at] if at is not None else _score(fm, best)).T
        w[base + 3, :, lay["n"] + f] = ran[:, lay["n"] + f]
    w[4, :, lay["DBn"]] = ran[:, lay["DBn"]]
    cbn = lay["CBn"][list(cfg.thresholds).index(cfg.cbn_threshold)]
    w[9, :, cbn] = ran[:, cbn] & np.asarray(cbn_ok, bool)
    return w


def method_curves(mean: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``mean (..., A, C', S)``, ``w (M, A, C')`` -> ``(..., M, A, S)`` (NaN where a method has no weight)."""
    m = np.nan_to_num(np.asarray(mean, float))
    out = np.einsum("mac,...acs->...mas", w, m)
    return np.where(w.sum(-1)[..., None] > 0, out, np.nan)


def per_target_stats(mean: np.ndarray, w: np.ndarray, lay: dict, sizes: Sequence[int], cfg,
                     halves: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per method and target: the gain curve's area over the window ``area (..., M, A)``, the
    samples saved at ``select_size`` ``saved (..., M, A)`` (a censored target counts with the
    largest size: a lower bound) and ``censored (..., M, A)``; NaN where a method did not run.
    With the half curves ``halves (..., 2, A, C', S)`` the choosing methods' curves and NB's
    beside them are the held-out ones (``heldout.heldout_curves``: Table II's choice), else the
    in-sample ``w``'s."""
    curves = method_curves(mean, w)  # (..., M, A, S)
    nb = np.array(np.broadcast_to(np.asarray(mean, float)[..., None, :, lay["NB"], :], curves.shape))
    if halves is not None:
        ch = H.choosing(METHODS)
        curves[..., ch, :, :], nb[..., ch, :, :] = H.heldout_curves(halves, METHODS, lay, sizes, cfg)
    area = window_area(curves - nb, sizes, *cfg.bf_sizes)
    if cfg.select_size in sizes:
        saved, cens = samples_saved(curves, nb, sizes, cfg.select_size)
    else:
        saved, cens = np.full(area.shape, np.nan), np.zeros(area.shape, bool)
    return {"area": area, "saved": saved, "censored": cens & np.isfinite(saved)}


def curve_stats(mean: np.ndarray, w: np.ndarray, lay: dict, sizes: Sequence[int], cfg,
                keep: np.ndarray | None = None, halves: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """``per_target_stats`` (``halves``: its held-out choice) averaged over the targets
    ``keep (A,)`` (all: None) a method ran for: ``area (..., M)``, ``saved (..., M)`` and
    ``censored (..., M)`` how many of them were censored; the per target values as
    ``*_per_target (..., M, A)``."""
    st = per_target_stats(mean, w, lay, sizes, cfg, halves)
    k = np.ones(st["area"].shape[-1], bool) if keep is None else np.asarray(keep, bool)
    with np.errstate(invalid="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return {"area": np.nanmean(np.where(k, st["area"], np.nan), -1),
                    "saved": np.nanmean(np.where(k, st["saved"], np.nan), -1),
                    "censored": (st["censored"] & k).sum(-1),
                    "area_per_target": st["area"], "saved_per_target": st["saved"],
                    "censored_per_target": st["censored"]}


def rep_scores(acc_x: np.ndarray, w: np.ndarray, lay: dict, sizes: Sequence[int], cfg,
               halves: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per repetition the mean accuracy over the window: methods ``(M, A, R)`` and NB beside
    each ``(M, A, R)`` (the scores the probability of improvement compares) from ``acc_x (A,
    C', S, R)``. With ``halves = (half_reps (2, A, C', S, R), half_means (2, A, C', S))`` the
    choosing methods' scores and NB's beside them are the held-out ones
    (``heldout.heldout_rep_scores``), else the in-sample ``w``'s on the whole test set."""
    m = size_mask(sizes, *cfg.bf_sizes)
    with np.errstate(invalid="ignore", divide="ignore"):  # no size in the window: NaN scores
        win = np.asarray(acc_x, float)[:, :, m].mean(2)  # (A, C', R)
    x = np.einsum("mac,acr->mar", w, np.nan_to_num(win))
    x = np.where(w.sum(-1)[..., None] > 0, x, np.nan)
    y = np.array(np.broadcast_to(win[:, lay["NB"]], x.shape))
    if halves is not None:
        ch = H.choosing(METHODS)
        x[ch], y[ch] = H.heldout_rep_scores(halves[0], halves[1], METHODS, lay, sizes, cfg)
    return x, y
