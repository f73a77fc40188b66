"""Bootstrap intervals: resampled mean accuracy curves (whole test sets and their two halves),
and bias-corrected intervals of any statistic.

Takes one space's accuracies with the online learners appended (``online.extend``):
``acc: (A, C', S, R)``, the outcome of every test scene ``correct: (A, C', S, R, N)`` float
(N = 0 when the run kept none) with ``n_test: (A,)`` scenes per target and ``halves: (A, N)``
int (0 or 1: the half of the test set each scene is in, ``scene_halves``), a resample count B
and a seed; ``resampled_means`` gives B resampled mean curves of each half ``(B, 2, A, C', S)``
float64 (``whole`` averages them back into the whole test set's):

* repetitions are drawn with replacement (the same draw for every target: a repetition is one
  training draw of every target, with the same source predictors);
* with outcomes, each target's test scenes are drawn with replacement within each half
  (a stratified bootstrap: the halves keep their sizes, so a choice made on one half can be
  scored on the other in every resample), independently per target, and every condition,
  size and repetition is scored on the same resampled scenes (the comparison stays paired);
* without outcomes (``keep_outcomes`` false) only the repetitions are resampled, both
  "halves" are the whole test set, and the interval leaves out the test set's own sampling
  error (at 4000 test scenes, a standard error of about 0.008 in accuracy).

With outcomes as ``online.Outcomes`` of 0/1 outcomes, each block's half is read from the bits
(``halfrows``); ``reference=True`` takes the float copy of every block, the same bits.

Everything is float64: a resampled NB mean exactly at chance stays exactly at chance (float32
put it 6e-8 above, and its bootstrap factor near 1e6). Conditions that did not run stay NaN.
``bc_interval`` turns B values of a statistic ``(B, ...)`` and its estimate into the
bias-corrected percentile interval (Efron's BC: the percentiles moved by how far the estimate
sits from the resamples' median); ``percentile_interval`` is the plain one; ``checked_interval``
is the one the report uses: BC unless an end would rest on fewer than a share ``tail`` of the
resamples beyond it, then the percentile interval.
"""
from __future__ import annotations

from statistics import NormalDist

import numpy as np

from relaff_jax.learn import halfrows
from relaff_jax.learn.measures import _quiet


def scene_halves(n_test: np.ndarray, n_positive: np.ndarray | None, width: int) -> np.ndarray:
    """``(A, width)`` int: the half of each target's test set every scene is in. A balanced test
    set (``draws.draw_test``: its k positives first, then k negatives) is split into two
    balanced halves of k scenes (alternate scenes within each class; with k odd the negatives
    start on the other half); any other into alternate scenes. Padding scenes (past ``n_test``)
    get -1."""
    out = np.full((len(n_test), width), -1, int)
    for t, n in enumerate(np.asarray(n_test, dtype=int)):
        j = np.arange(n)
        k = n // 2
        if n_positive is not None and k > 0 and 2 * int(n_positive[t]) == n:
            neg = j >= k
            out[t, :n] = (j - k * neg + neg * (k % 2)) % 2
        else:
            out[t, :n] = j % 2
    return out


def target_blocks(correct, t: int):
    """``(sizes slice, (C', s, R, N) block)`` pairs covering target ``t``'s outcomes: the
    blocks of an ``online.Outcomes`` (too large to hold whole at the paper's scale), or an
    array's one whole slice."""
    if hasattr(correct, "block"):
        for sl in correct.size_blocks():
            yield sl, correct.block(t, sl)
    else:
        yield slice(None), np.asarray(correct[t])


def fast_outcomes(correct) -> bool:
    """Whether ``correct`` is an ``online.Outcomes`` of 0/1 outcomes, which ``halfrows`` reads
    half by half without the float copies of its blocks (anything else takes the reference path)."""
    return hasattr(correct, "half_parts") and np.dtype(getattr(correct.correct, "dtype", None)) == bool


def resampled_means(acc: np.ndarray, correct: np.ndarray, n_test: np.ndarray, resamples: int, seed: int,
                    halves: np.ndarray | None = None, reference: bool = False,
                    means: np.ndarray | None = None, rep_means: np.ndarray | None = None) -> np.ndarray:
    """``(B, 2, A, C', S)`` float64 mean accuracy curves of each test half in ``resamples``
    bootstrap resamples (both entries the whole test set without outcomes). ``reference``:
    the float copy of every block (the fast path, ``halfrows``, is checked against it).
    ``means (2, A, C', S)``: on the fast path, filled with ``analysis.half_curves``' values
    (before its NaN of what did not run) from the halves read for the resampling, so that the
    outcomes are unpacked and mixed once (NaN where a half is empty or a target kept none);
    ``rep_means (2, A, C', S, R)`` the same before the mean over repetitions."""
    acc = np.asarray(acc, dtype=np.float64)
    a, c, s, r = acc.shape
    rng = np.random.default_rng(seed)
    v = rng.multinomial(r, np.full(r, 1.0 / r), size=resamples) / r  # (B, R) float64
    ran = np.isfinite(acc).any(-1)  # (A, C', S)
    out = np.empty((resamples, 2, a, c, s), np.float64)
    n_test = np.asarray(n_test, dtype=int)
    n_max = np.shape(correct)[-1]
    if halves is None:
        halves = scene_halves(n_test, None, n_max)
    work: dict = {}  # the fast path's arrays, reused across blocks
    for t in range(a):
        n = int(n_test[t]) if n_max else 0
        if n > 0:
            draws = []  # (half, scenes, the resamples' scene counts (B, m)), drawn in the order (target, half)
            for h in range(2):
                idx = np.flatnonzero(halves[t, :n] == h)
                m = len(idx)
                if m == 0:  # a test set of one scene: its other half is empty
                    out[:, h, t] = np.nan
                    continue
                draws.append((h, idx, halfrows.SceneCounts(rng.multinomial(m, np.full(m, 1.0 / m), size=resamples))))
            if not reference and fast_outcomes(correct):
                for sl in correct.size_blocks():  # the reference's blocks of sizes
                    parts = correct.half_parts(t, sl, [idx for _, idx, _ in draws])
                    for (h, _, w), (bits, on) in zip(draws, parts):
                        if means is not None or rep_means is not None:
                            rm = halfrows.row_means(bits, on)  # (C', s, R)
                            if means is not None:
                                means[h, t, :, sl] = rm.mean(-1)
                            if rep_means is not None:
                                rep_means[h, t, :, sl] = rm
                        out[:, h, t, :, sl] = halfrows.resampled(bits, on, w, v, work)
                continue
            for sl, blk in target_blocks(correct, t):
                blk = np.asarray(blk, dtype=np.float64)  # (C', s, R, N)
                for h, idx, w in draws:
                    x = blk[..., idx].reshape(-1, len(idx))  # (C' s R, m)
                    # accuracy per repetition and resample: each row's exact sum of counts, over m
                    per_rep = ((x @ w.f64.T) / w.m).reshape(c, -1, r, resamples)
                    out[:, h, t, :, sl] = np.einsum("csrb,br->bcs", per_rep, v)
        else:
            out[:, :, t] = np.einsum("csr,br->bcs", np.nan_to_num(acc[t]), v)[:, None]
    return np.where(ran[None, None], out, np.nan)


def half_sizes(n_test: np.ndarray, halves: np.ndarray) -> np.ndarray:
    """``(2, A)`` scenes in each half (1 each where a target kept no outcomes)."""
    n = np.stack([(halves == h).sum(-1) for h in range(2)]).astype(float)
    return np.where(n.sum(0) > 0, n, 1.0)


def whole(half_means: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """``(..., 2, A, C', S)`` half curves and ``sizes (2, A)`` -> the whole test set's ``(..., A, C', S)``."""
    w = sizes / sizes.sum(0)
    return np.einsum("...hacs,ha->...acs", half_means, w)


def percentile_interval(values: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """``values (B, ...)`` -> the (low, high) percentiles at ``level`` over the finite
    resamples (NaN where none is finite)."""
    q = 100 * (1 - level) / 2
    with _quiet():
        lo, hi = np.nanpercentile(np.asarray(values, dtype=float), [q, 100 - q], axis=0)
    return lo, hi


def bc_percentiles(values: np.ndarray, estimate: np.ndarray, level: float):
    """The percentiles (0-100) at which the bias-corrected interval of ``values (B, ...)``
    around ``estimate (...)`` reads its ends, and the finite resamples: ``(q_lo, q_hi, n)``.

    z0 = Phi^-1(share of finite resamples below the estimate, ties counted half); the ends are
    the percentiles Phi(2 z0 -+ z_level) (Efron 1987 with acceleration 0)."""
    v = np.asarray(values, dtype=float)
    counts = bc_counts(v, np.broadcast_to(np.asarray(estimate, dtype=float), v.shape[1:]))
    return _bc_q(*counts, level) + (counts[2],)


def bc_counts(values: np.ndarray, estimate: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(below, equal, finite)`` int counts of ``values (B, ...)`` against ``estimate (...)``:
    all a bias-corrected interval's percentiles rest on; the counts of resamples seen in
    chunks add up to those of all of them."""
    ok = np.isfinite(values)
    return np.where(ok, values < estimate, False).sum(0), np.where(ok, values == estimate, False).sum(0), ok.sum(0)


def _bc_q(below: np.ndarray, equal: np.ndarray, n: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    share = (below + 0.5 * equal) / np.maximum(n, 1)
    nd = NormalDist()
    eps = 0.5 / np.maximum(n, 1)  # keep z0 finite when the estimate is outside every resample
    z0 = np.vectorize(nd.inv_cdf, otypes=[float])(np.clip(share, eps, 1 - eps))
    za = nd.inv_cdf(0.5 + level / 2)
    cdf = np.vectorize(nd.cdf, otypes=[float])
    return 100 * cdf(2 * z0 - za), 100 * cdf(2 * z0 + za)


def bc_tally(counts: tuple[np.ndarray, np.ndarray, np.ndarray], estimate: np.ndarray, level: float,
             tail: float) -> tuple[int, int]:
    """What ``interval_pairs`` appends to its ``tally`` for these intervals, from ``bc_counts``
    alone (no interval made): how many are bias-corrected (each end leaves at least ``tail``
    of the finite resamples beyond it) and defined (a finite estimate and a finite resample)."""
    q_lo, q_hi = _bc_q(*counts, level)
    defined = (counts[2] > 0) & np.isfinite(estimate)
    bc = (q_lo / 100 >= tail) & (1 - q_hi / 100 >= tail)
    return int((bc & defined).sum()), int(defined.sum())


def bc_interval(values: np.ndarray, estimate: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Bias-corrected percentile interval: ``values (B, ...)``, ``estimate (...)`` -> (low, high),
    read at ``bc_percentiles`` (the jackknife acceleration would need a refit per left-out
    scene and repetition). NaN where the estimate or every resample is undefined."""
    return _bc_read(values, estimate, level)[:2]


def _bc_read(values: np.ndarray, estimate: np.ndarray, level: float):
    """``bc_interval``'s ``(low, high)`` and the percentiles it read them at, ``(q_lo, q_hi)``."""
    v = np.asarray(values, dtype=float)
    est = np.broadcast_to(np.asarray(estimate, dtype=float), v.shape[1:])
    q_lo, q_hi, n = bc_percentiles(v, est, level)
    srt = np.sort(np.where(np.isfinite(v), v, np.inf), axis=0)  # finite values first
    lo, hi = (_pick(srt, n, q) for q in (q_lo, q_hi))
    bad = (n == 0) | ~np.isfinite(est)
    return np.where(bad, np.nan, lo), np.where(bad, np.nan, hi), q_lo, q_hi


def checked_interval(values: np.ndarray, estimate: np.ndarray, level: float,
                     tail: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The interval every statistic of the report shows and decides on: ``(low, high, bc)``.

    The bias-corrected interval where each of its ends leaves at least the share ``tail`` of
    the finite resamples beyond it (``bc`` True), else the percentile interval (``bc`` False):
    a large z0 reads an end in the resamples' extreme tail (z0 = 0.62 reads the 99.93rd
    percentile, 0.7 of 1,000 resamples beyond it), where one or two resamples place it.
    ``tail = 0`` keeps the bias-corrected interval everywhere. Shapes as ``bc_interval``."""
    v = np.asarray(values, dtype=float)
    est = np.broadcast_to(np.asarray(estimate, dtype=float), v.shape[1:])
    lo, hi, q_lo, q_hi = _bc_read(v, est, level)
    bc = (q_lo / 100 >= tail) & (1 - q_hi / 100 >= tail)
    if bc.all():
        return lo, hi, bc
    p_lo, p_hi = percentile_interval(v, level)
    bad = ~np.isfinite(est)
    return (np.where(bc, lo, np.where(bad, np.nan, p_lo)), np.where(bc, hi, np.where(bad, np.nan, p_hi)),
            bc | bad | ~np.isfinite(lo))


def interval_pairs(values: np.ndarray, estimate: np.ndarray, level: float, tail: float,
                   tally: list | None = None) -> np.ndarray:
    """``checked_interval`` as ``(..., 2)`` [low, high] pairs; ``tally`` (a list) gets the
    ``(bias-corrected, defined)`` counts of the call appended."""
    lo, hi, bc = checked_interval(values, estimate, level, tail)
    if tally is not None:
        defined = np.isfinite(lo) & np.isfinite(hi)
        tally.append((int((bc & defined).sum()), int(defined.sum())))
    return np.stack([lo, hi], -1)


def _pick(srt: np.ndarray, n: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The q-th percentile (linear interpolation, as ``np.percentile``) of the first n sorted values."""
    pos = np.clip(q / 100 * (n - 1), 0, np.maximum(n - 1, 0))
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, np.maximum(n - 1, 0))
    a = np.take_along_axis(srt, i0[None], 0)[0]
    b = np.take_along_axis(srt, i1[None], 0)[0]
    f = pos - i0
    with np.errstate(invalid="ignore"):
        return np.where(n > 0, a + f * np.where(np.isfinite(b), b - a, 0.0), np.nan)


def drawn_intervals(boot: np.ndarray, estimate: np.ndarray, drawn: np.ndarray, counts, level: float, tail: float,
                    tally: list, reference: bool = False) -> np.ndarray:
    """``(A, C', S, 2)`` intervals (``interval_pairs``) of the curves ``estimate (A, C', S)``
    marked ``drawn (A, C')``, NaN elsewhere, from their resamples ``boot (B, drawn, S)``;
    ``tally`` gets the count of every curve's interval, from the ``bc_counts`` of all their
    resamples, ``counts`` (``bc_tally``). ``reference``: ``boot (B, A, C', S)`` holds every
    curve's resamples, and every interval is made (the same bits, slower)."""
    out = np.full(estimate.shape + (2,), np.nan)
    if reference:
        out[drawn] = interval_pairs(boot, estimate, level, tail, tally)[drawn]
        return out
    out[drawn] = interval_pairs(boot, estimate[drawn], level, tail)
    tally.append(bc_tally(counts, estimate, level, tail))
    return out
