"""Section V's numbers from the raw accuracies, as array operations.

Takes one space's results (``results.load_results(RESULTS)[space]``: ``acc: (A, C, S, R)``
over target, condition, size and repetition) and the config; ``analyse`` gives the mean and
standard-error curves ``(A, C, S)``, bootstrap factors (paper III-D) ``(A, C, S)``, average
bootstrap factors over n = 4..25 ``(A, C)``, the chosen sources ("best", "best after ten"),
Table II per target ``(rows, A)`` and as avg/min/max ``(rows, 3)``, and the threshold study
(paper Fig. 12). ``categories_per_threshold`` counts the categories the heuristic builds.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.learn.config import TABLE2_ROWS, ExperimentConfig
from relaff_jax.learn.correlation import categories_above, category_pairs
from relaff_jax.learn.protocol import layout


def curves(acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over repetitions: ``acc (..., S, R) -> (..., S), (..., S)``."""
    with np.errstate(invalid="ignore"), _quiet():
        mean = np.nanmean(acc, axis=-1)
        n = np.sum(np.isfinite(acc), axis=-1)
        sem = np.nanstd(acc, axis=-1, ddof=1) / np.sqrt(n) if acc.shape[-1] > 1 else np.zeros_like(mean)
    return mean, sem


def bootstrap_factor(p_bl: np.ndarray, p_sl: np.ndarray, chance: float = 0.5) -> np.ndarray:
    """bf = (P_bl - P_c) / (P_sl - P_c) (paper III-D), broadcast; NaN where P_sl <= P_c
    (the standard learner is at or below chance and the ratio has no meaning)."""
    p_bl, p_sl = np.asarray(p_bl, dtype=float), np.asarray(p_sl, dtype=float)
    den = p_sl - chance
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (p_bl - chance) / np.where(den > 0, den, 1.0), np.nan)


def size_mask(sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    s = np.asarray(sizes)
    return (s >= lo) & (s <= hi)


def average_bf(bf: np.ndarray, sizes: Sequence[int], lo: int = 4, hi: int = 25) -> np.ndarray:
    """Average bootstrap factor: mean of ``bf (..., S)`` over sizes lo <= n <= hi (paper V-C)."""
    with _quiet():
        return np.nanmean(np.asarray(bf)[..., size_mask(sizes, lo, hi)], axis=-1)


def select_best(p: np.ndarray, sizes: Sequence[int], lo: int = 2, hi: int = 100) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy over sizes lo..hi:
    ``p (..., K, S) -> (...,)``; NaN candidates (not run / not allowed) never win."""
    mask = size_mask(sizes, lo, hi)
    mask = mask if mask.any() else np.ones_like(mask)
    with _quiet():
        return _nanargmax(np.nanmean(np.asarray(p)[..., mask], axis=-1))


def select_at(p: np.ndarray, sizes: Sequence[int], n: int = 10) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy at training size n ("best after ten")."""
    return _nanargmax(np.asarray(p)[..., list(sizes).index(n)])


def _nanargmax(score: np.ndarray) -> np.ndarray:
    s = np.where(np.isfinite(score), score, -np.inf)
    return np.argmax(s, axis=-1)


class _quiet:
    """Silence numpy's 'mean of empty slice' warnings for all-NaN slices (they give NaN)."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def analyse(res: Mapping[str, np.ndarray], cfg: ExperimentConfig) -> dict[str, Any]:
    """Everything section V reports for one space, as arrays over (target, condition, size).

    Returns mean/sem curves ``(A, C, S)``, bf curves ``(A, C, S)``, average bf ``(A, C)``,
    the chosen candidates per target (``best_db1``, ``ten_db1``, ... as condition indices),
    the Table II rows per target ``(rows, A)`` and their avg/min/max ``(rows, 3)``, and the
    threshold study (paper Fig. 12).
    """
    acc, sizes = np.asarray(res["acc"], dtype=float), [int(s) for s in res["sizes"]]
    actions = [str(a) for a in res["actions"]]
    a = len(actions)
    lay = layout(a, len(cfg.thresholds))
    mean, sem = curves(acc)  # (A, C, S)
    bf = bootstrap_factor(mean, mean[:, lay["NB"]][:, None, :], cfg.chance)  # (A, C, S)
    avg = average_bf(bf, sizes, *cfg.bf_sizes)  # (A, C)
    t_idx = np.arange(a)
    lo, hi = cfg.best_sizes
    out: dict[str, Any] = {"actions": actions, "sizes": sizes, "mean": mean, "sem": sem, "bf": bf, "avg_bf": avg,
                           "conditions": [str(c) for c in res["conditions"]]}
    rows: dict[str, np.ndarray] = {"NB": avg[:, lay["NB"]]}
    for fam in ("DB1", "CB1"):
        idx = lay[fam]
        fam_mean = mean[:, idx]  # (A, K, S)
        best = idx[select_best(fam_mean, sizes, lo, hi)]
        ten = idx[select_at(fam_mean, sizes, cfg.select_size)] if cfg.select_size in sizes else best
        ran = np.any(np.isfinite(fam_mean), axis=-1)  # (A, K)
        with _quiet():
            rows[f"{fam} average"] = np.nanmean(np.where(ran, avg[:, idx], np.nan), axis=1)
        rows[f"{fam} best"] = np.where(ran.any(1), avg[t_idx, best], np.nan)
        rows[f"{fam} best after ten"] = np.where(ran.any(1), avg[t_idx, ten], np.nan)
        out[f"best_{fam.lower()}"], out[f"ten_{fam.lower()}"] = best, ten
        if fam == "DB1":
            rows["DBn"] = avg[:, lay["DBn"]]
        else:
            rows["CBn"] = avg[:, lay["CBn"][list(cfg.thresholds).index(cfg.cbn_threshold)]]
    per_target = np.stack([rows[r] for r in TABLE2_ROWS])  # (rows, A)
    with _quiet():
        summary = np.stack([np.nanmean(per_target, 1), np.nanmin(per_target, 1), np.nanmax(per_target, 1)], axis=1)
    out["table2_rows"] = list(TABLE2_ROWS)
    out["table2_per_target"] = per_target
    out["table2"] = summary
    out["thresholds"] = threshold_study(mean, bf, np.asarray(res["category_masks"], dtype=bool), sizes, cfg, lay)
    return out


def threshold_study(mean: np.ndarray, bf: np.ndarray, masks: np.ndarray, sizes: Sequence[int],
                    cfg: ExperimentConfig, lay: dict) -> dict[str, Any]:
    """Paper Fig. 12: per threshold T the bf curve ``(S,)`` of each target's best category
    among those built at T (mean over targets), plus the overall average over all usable
    categories; ``masks: (T, A, K)``."""
    idx = lay["CB1"]
    cb_mean, cb_bf = mean[:, idx], bf[:, idx]  # (A, K, S)
    ran = np.any(np.isfinite(cb_mean), axis=-1)  # (A, K)
    t_idx = np.arange(mean.shape[0])
    out: dict[str, Any] = {"T": list(cfg.thresholds), "best_curve": [], "count": [], "best": []}
    with _quiet():
        for ti in range(len(cfg.thresholds)):
            m = masks[ti] & ran  # (A, K)
            best = select_best(np.where(m[..., None], cb_mean, np.nan), sizes, *cfg.best_sizes)
            curve = np.where(m.any(1)[:, None], cb_bf[t_idx, best], np.nan)  # (A, S)
            out["best_curve"].append(np.nanmean(curve, axis=0))
            out["best"].append(idx[best])
            out["count"].append(int(masks[ti].any(0).sum()))
        out["overall_curve"] = np.nanmean(np.where(ran[..., None], cb_bf, np.nan), axis=(0, 1))
    out["best_curve"] = np.stack(out["best_curve"])
    return out


def categories_per_threshold(corr: np.ndarray, thresholds: Sequence[float]) -> dict[str, int]:
    """How many of the A(A-1)/2 categories the heuristic builds at each T (and how many pairs
    literally have corr > T, which differs from the kept count only at T <= 0)."""
    pairs = category_pairs(range(corr.shape[0]))
    i, j = np.asarray(pairs).T
    return {f"{t:g}": {"built": int(categories_above(corr, pairs, t).sum()), "corr_above": int((corr[i, j] > t).sum())}
            for t in thresholds}
