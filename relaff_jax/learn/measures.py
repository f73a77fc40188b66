"""Table II from mean accuracy curves, for one estimate or a batch of bootstrap resamples.

Takes mean accuracy curves ``mean: (..., A, C + 2, S)`` over target, condition and size (the
sweep's C conditions, then the two online "best after ten" learners of ``online.py``), the
same curves on the two halves of every test set ``(..., 2, A, C + 2, S)``, the sizes, the
config, the condition layout and the at-chance tolerance ``tol (A,)``; ``table2_rows`` gives,
per Table II row and target, two measures over the window ``cfg.bf_sizes`` (paper V-C:
n = 4..25):

* ``bf``: the average bootstrap factor, the mean of bf(n) = (P_bl - P_c) / (P_sl - P_c) over
  the sizes of the window where it is defined (P_sl - P_c > tol, ``chance_tolerance``: half a
  test scene by default, so |bf| <= T); ``defined``: how many sizes that was per target; a
  target defined at fewer than ``min_defined`` sizes has no bf in any row (left out of the
  row's average, which says how many it rests on);
* ``gain``: the mean accuracy gain over the window, mean of P_bl(n) - P_sl(n) (a difference of
  accuracies, defined wherever both ran, linear in the accuracies: well conditioned where bf
  is not, i.e. where P_sl is near chance).

Choices use ``tie_weights``: every candidate tied at the highest score gets an equal share
(a uniform random choice among them). "best" and "best after ten" are chosen on one half of
the test scenes and scored on the other, both ways, averaged (cross-fitting: a choice never
scores itself); the paper's choice on the very scores it reports is kept as the "(in-sample
oracle)" rows. Each "after ten" learner (offline, oracle, online) is given in two readings of
the paper (config ``after_ten`` says which the findings use), from the same curves: its rows
without a suffix are the whole curve of the learner kept at n = ``select_size`` (``whole``);
its "(causal)" rows have chosen nothing before n = ``select_size``, and are there an equal
share of every candidate (``causal``). ``summarise`` gives each
row's avg/min/max over the targets with a value and how many those are (``n_targets``).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from relaff_jax.learn.table2 import CAUSAL, ONLINE, ORACLE, TABLE2_ROWS
from relaff_jax.config.experiment import ExperimentConfig

TIE_TOL = 1e-12  # scores closer than this are tied (accuracies are multiples of 1/T)
ROUND = 1e-12  # float64 round-off of a mean of k/T: far below one scene (1/T)


def size_mask(sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    """``(S,)`` bool: lo <= n <= hi."""
    s = np.asarray(sizes)
    return (s >= lo) & (s <= hi)


def bootstrap_factor(p_bl: np.ndarray, p_sl: np.ndarray, chance: float = 0.5, tol: float | np.ndarray = 0.0) -> np.ndarray:
    """bf = (P_bl - P_c) / (P_sl - P_c) (paper III-D), broadcast, float64; NaN where
    P_sl - P_c <= tol (the standard learner is at chance and the ratio has no meaning), so
    |bf| <= 1/2 / tol. ``ROUND`` absorbs the round-off of means of k/T."""
    p_bl, p_sl = np.asarray(p_bl, dtype=np.float64), np.asarray(p_sl, dtype=np.float64)
    den = p_sl - chance
    ok = den > np.asarray(tol, dtype=np.float64) + ROUND
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, (p_bl - chance) / np.where(ok, den, 1.0), np.nan)


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


def _curves(mean: np.ndarray, tol: np.ndarray, chance: float) -> tuple[np.ndarray, np.ndarray]:
    """Per size bf and gain cells ``(..., A, C + 2, S)`` against NB; ``tol (A,)`` at-chance tolerances."""
    nb = mean[..., :1, :]  # NB is condition 0
    return bootstrap_factor(mean, nb, chance, np.asarray(tol, dtype=float)[:, None, None]), mean - nb


def _score(fam_mean: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(..., A, K, S) -> (..., A, K)`` mean accuracy over the sizes of ``mask``."""
    with _quiet():
        return np.nanmean(np.where(mask, fam_mean, np.nan), -1)


def _mix(cells: np.ndarray, w: np.ndarray, reference: bool = False) -> np.ndarray:
    """``cells (..., A, K, S)``, weights ``(..., A, K)`` -> ``(..., A, S)`` (NaN where all weights are 0).

    The weighted sum is ``mix_kernel.weighted_sums`` where the two share their leading shape
    and ``S >= 2`` (the same bits in one pass); ``reference`` (or any other shape): numpy's."""
    cells, w = np.asarray(cells, dtype=float), np.asarray(w, dtype=float)
    ok = w.sum(-1)[..., None] > 0
    lead = cells.shape[:-2]
    compiled = cells.ndim >= 3 and cells.shape[-1] >= 2 and cells.shape[-2] >= 1 and w.shape == cells.shape[:-1]
    if compiled and not reference:
        from relaff_jax.learn.mix_kernel import weighted_sums  # noqa: PLC0415 (numba, on first use)

        n = int(np.prod(lead[:-1]))  # the leading axes as one (an explicit count: -1 is ambiguous on empty arrays)
        out = weighted_sums(cells.reshape((n,) + cells.shape[-3:]), w.reshape((n,) + w.shape[-2:]))
        out = out.reshape(lead[:-1] + out.shape[1:])
    else:
        ws = w[..., None]
        out = (np.where(ws > 0, cells, 0.0) * ws).sum(-2)
    return np.where(ok, out, np.nan)


def compile_mix_kernel() -> None:
    """Load ``_mix``'s compiled sum from numba's cache, or compile it into the cache (a new
    install). ``reproduce`` runs it in a process beside the generate stage (``stages/audits.py``)."""
    from relaff_jax.learn.mix_kernel import weighted_sums  # noqa: F401, PLC0415 (compiled on import)


def _from_ten(cells_k: np.ndarray, chosen: np.ndarray, ran: np.ndarray, after: np.ndarray,
              reference: bool = False) -> np.ndarray:
    """A learner that chooses at n = select_size: before it, an equal share of every candidate
    that ran (no choice yet); from it on, ``chosen (..., A, S)``."""
    return np.where(after, chosen, _mix(cells_k, ran / np.maximum(ran.sum(-1, keepdims=True), 1), reference))


def table2_rows(mean: np.ndarray, sizes: Sequence[int], cfg: ExperimentConfig, lay: dict, tol: np.ndarray,
                halves: np.ndarray | None = None, cbn_ok: np.ndarray | None = None,
                masks: np.ndarray | None = None, min_cells: int | None = None, reference: bool = False) -> dict[str, Any]:
    """Per target values of every Table II row, ``bf`` and ``gain`` ``(..., rows, A)`` (rows in
    ``TABLE2_ROWS`` order), ``defined (..., A)``: the window's sizes where bf is defined (NB
    more than ``tol`` above chance; the same for every row), and with ``masks (T, A, K)`` the
    threshold study's best category per T, held-out and oracle, ``thr_bf``/``thr_bf_oracle``
    ``(..., T, A)`` (the CB1 best rows restricted to the categories built at T: one aggregation).

    ``mean: (..., A, C + 2, S)`` as in the module docstring; ``halves: (..., 2, A, C + 2, S)``
    the same curves on the two halves of each test set (``intervals.scene_halves``; None: the
    held-out rows are NaN); ``tol (A,)`` the whole test set's at-chance tolerance (a half has
    half the scenes: twice it); ``cbn_ok (A,)`` whether the target had a category at CBn's
    threshold (False: CBn is NB relabelled, so NaN). A target whose bf is defined at fewer than
    ``min_cells`` (default ``min_defined(cfg, sizes)``) sizes of the window has no bf in any row
    (resamples pass 1: which targets a row rests on is the estimate's decision). ``reference``:
    bf and gain cells made for every size, not the window's only, and each set of allowed
    candidates scored apart, not masked from its family's scores (the same bits, slower)."""
    mean = np.asarray(mean, dtype=float)
    tol = np.asarray(tol, dtype=float)
    lo, hi = cfg.bf_sizes
    # Every bf and gain cell is read through the window's mean: they are made for its sizes only
    # (the same bits: each cell's arithmetic is per size). The choices read every size of ``mean``.
    win = _window_columns(sizes, lo, hi) if not reference else np.ones(len(sizes), bool)
    wm = lambda x: window_mean(x, np.asarray(sizes)[win], lo, hi)[0]  # noqa: E731
    bf, gain = _curves(mean[..., win], tol, cfg.chance)
    split = [_curves(halves[..., h, :, :, :][..., win], 2 * tol, cfg.chance) if halves is not None else None for h in range(2)]
    b_lo, b_hi = cfg.best_sizes
    best_mask = size_mask(sizes, b_lo, b_hi)
    best_mask = best_mask if best_mask.any() else np.ones_like(best_mask)
    sz = np.asarray(sizes)
    after = (sz >= cfg.select_size)[win]
    at = list(sizes).index(cfg.select_size) if cfg.select_size in sizes else None
    on = {"DB1": lay["n"], "CB1": lay["n"] + 1}
    nan = np.full(mean.shape[:-2], np.nan)  # (..., A)

    seen: dict = {}  # values per (curves, candidates[, allowed]) and per cells: the same for bf and gain

    def once(key, make):
        if key not in seen:
            seen[key] = make()
        return seen[key]

    def family(m, idx, allowed, h=None):
        """Which candidates ran, and the 'best' / 'at ten' weights ``(..., A, K)`` of the curves
        ``m`` (``h``: which of them, the whole test set's or a half's). The scores are made once
        per family and masked per ``allowed`` (a row's mean is its own: the same bits)."""
        own = (np.shape(allowed), np.asarray(allowed).tobytes()) if reference else ()  # the reference: each set apart
        ran0, score0, at0 = once(("scores", h, idx.tobytes()) + own,
                                 lambda: _family(np.where(allowed[..., None], m[..., idx, :], np.nan) if reference else m[..., idx, :]))
        key = ("family", h, idx.tobytes(), np.shape(allowed), np.asarray(allowed).tobytes())
        return once(key, lambda: _allowed(ran0 & allowed, score0, at0))

    def _family(fm):
        score = _score(fm, best_mask)
        return np.any(np.isfinite(fm), -1), score, fm[..., at] if at is not None else score

    def _allowed(ran, score, at_score):
        return ran, tie_weights(np.where(ran, score, np.nan)), tie_weights(np.where(ran, at_score, np.nan))

    def choices(key_i, idx, allowed):
        """(best held-out, best oracle, ten held-out, ten oracle, average, ran) of one family, ``(..., A)``."""
        cells = once(("cells", key_i, idx.tobytes()), lambda: (bf, gain)[key_i][..., idx, :])
        ran, w_best, w_ten = family(mean, idx, allowed)
        best_o = wm(_mix(cells, w_best, reference))
        kept = _mix(cells, w_ten, reference)  # the learner kept at n = select_size, its whole curve
        ten_o, ten_c = wm(kept), wm(_from_ten(cells, kept, ran, after, reference))
        with _quiet():
            avg = np.nanmean(np.where(ran, once(("window", key_i, idx.tobytes()), lambda: wm(cells)), np.nan), -1)
        if halves is None:
            return {"best": nan, "best_o": best_o, "ten": nan, "ten_o": ten_o, "ten_c": nan, "ten_co": ten_c,
                    "avg": avg, "ran": ran}
        held_b, held_t, held_c = [], [], []
        for h in range(2):  # choose on half h, score on the other half
            ran_h, wb_h, wt_h = family(halves[..., h, :, :, :], idx, allowed, h)
            other = once(("other", key_i, h, idx.tobytes()), lambda: split[1 - h][key_i][..., idx, :])
            held_b.append(wm(_mix(other, wb_h, reference)))
            kept_h = _mix(other, wt_h, reference)
            held_t.append(wm(kept_h))
            held_c.append(wm(_from_ten(other, kept_h, ran_h, after, reference)))
        with _quiet():
            return {"best": np.nanmean(held_b, 0), "best_o": best_o, "ten": np.nanmean(held_t, 0), "ten_o": ten_o,
                    "ten_c": np.nanmean(held_c, 0), "ten_co": ten_c, "avg": avg, "ran": ran}

    defined = window_mean(bf[..., lay["NB"], :], np.asarray(sizes)[win], lo, hi)[1]  # (..., A)
    enough = defined >= (min_defined(cfg, sizes) if min_cells is None else min_cells)
    out: dict[str, Any] = {}
    for key_i, key in enumerate(("bf", "gain")):
        cells = (bf, gain)[key_i]
        rows: dict[str, np.ndarray] = {"NB": wm(cells[..., lay["NB"], :])}
        for fam in ("DB1", "CB1"):
            idx = lay[fam]
            c = choices(key_i, idx, np.ones(len(idx), bool))
            online = cells[..., on[fam], :]  # per repetition the learner kept at select_size, its whole curve
            ten, causal = f"{fam} best after ten", f"{fam} best after ten{CAUSAL}"
            rows.update({f"{fam} average": c["avg"], f"{fam} best": c["best"], f"{fam} best{ORACLE}": c["best_o"],
                         ten: c["ten"], ten + ORACLE: c["ten_o"], ten + ONLINE: wm(online),
                         causal: c["ten_c"], causal + ORACLE: c["ten_co"],
                         causal + ONLINE: wm(_from_ten(cells[..., idx, :], online, c["ran"], after, reference))})
        rows["DBn"] = wm(cells[..., lay["DBn"], :])
        cbn = wm(cells[..., lay["CBn"][list(cfg.thresholds).index(cfg.cbn_threshold)], :])
        rows["CBn"] = cbn if cbn_ok is None else np.where(cbn_ok, cbn, np.nan)
        val = np.stack([rows[r] for r in TABLE2_ROWS], axis=-2)
        out[key] = np.where(enough[..., None, :], val, np.nan) if key == "bf" else val
        if masks is not None:
            per_t = [choices(key_i, lay["CB1"], np.asarray(m, bool)) for m in masks]  # m: (A, K)
            for name, j in (("thr", "best"), ("thr_oracle", "best_o")):
                v = np.stack([c[j] for c in per_t], -2)  # (..., T, A)
                out[f"{name}_{key}"] = np.where(enough[..., None, :], v, np.nan) if key == "bf" else v
    # bf(n) is defined where P_sl(n) > chance + tol: the same sizes for every row of a target
    out["defined"] = defined
    out["enough"] = enough
    return out


def _window_columns(sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    """``(S,)`` bool: the sizes ``table2_rows`` makes bf and gain cells for, the window's. All of
    them where the window has fewer than two: with one column left numpy would sum ``_mix``'s
    candidates pairwise instead of one by one, and the last bits could differ."""
    win = size_mask(sizes, lo, hi)
    return win if win.sum() >= 2 else np.ones_like(win)


def min_defined(cfg: ExperimentConfig, sizes: Sequence[int]) -> int:
    """Sizes of the window at which a target's bf must be defined for it to enter a row:
    ``cfg.min_defined_share`` of the window's sizes that ran (at least 1)."""
    k = int(size_mask(sizes, *cfg.bf_sizes).sum())
    return max(1, int(np.ceil(cfg.min_defined_share * k - 1e-9)))


def chance_tolerance(cfg: ExperimentConfig, n_test: np.ndarray | None, a: int) -> np.ndarray:
    """``(A,)``: P_sl - P_c at or below this is "at chance" (bf undefined): ``cfg.chance_tol_scenes``
    test scenes' worth of accuracy, k / T (``cfg.test_size`` where the run kept no counts).
    With k = 1/2 no bf can exceed T / (2 k) = T in size: |P_bl - P_c| <= 1/2."""
    n = np.asarray(n_test if n_test is not None and np.size(n_test) else np.full(a, cfg.test_size), dtype=float)
    n = np.where(n > 0, n, cfg.test_size)
    return cfg.chance_tol_scenes / n


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
