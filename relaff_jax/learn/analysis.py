"""Section V's numbers from the raw accuracies, as array operations.

Takes one space's results (``results.load_results(RESULTS)[space]``: ``acc: (A, C, S, R)``
over target, condition, size and repetition, with ``loo`` and ``correct``) and the config;
``analyse`` gives the mean and standard-error curves ``(A, C + 2, S)`` (the sweep's conditions,
then the online "best after ten" learners of ``online.py``), bootstrap factors (paper III-D)
``(A, C + 2, S)``, average bootstrap factors over the window ``(A, C + 2)`` and how many of
its sizes each target has a bf for, the chosen sources ("best", "best after ten", offline
and online), Table II per target ``(rows, A)`` and as avg/min/max ``(rows, 3)`` with
``n_targets`` and bootstrap intervals (``intervals.py``), the same for the accuracy gain
(``measures.py``), bootstrap intervals of every mean curve, and the threshold study (paper
Fig. 12). ``categories_per_threshold`` counts the categories the heuristic builds.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.learn.config import TABLE2_ROWS, ExperimentConfig
from relaff_jax.learn.correlation import categories_above, category_pairs
from relaff_jax.learn.intervals import percentile_interval, resampled_means
from relaff_jax.learn.measures import (
    _quiet,
    bootstrap_factor,
    size_mask,
    summarise,
    table2_rows,
    tie_weights,
    window_mean,
)
from relaff_jax.learn.online import extend
from relaff_jax.learn.protocol import layout
from relaff_jax.provenance import derive_seed

CI_CHUNK = 100  # resamples analysed at once (bounds memory)


def curves(acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over repetitions: ``acc (..., S, R) -> (..., S), (..., S)``."""
    with np.errstate(invalid="ignore"), _quiet():
        mean = np.nanmean(acc, axis=-1)
        n = np.sum(np.isfinite(acc), axis=-1)
        sem = np.nanstd(acc, axis=-1, ddof=1) / np.sqrt(n) if acc.shape[-1] > 1 else np.zeros_like(mean)
    return mean, sem


def average_bf(bf: np.ndarray, sizes: Sequence[int], lo: int = 4, hi: int = 25) -> np.ndarray:
    """Average bootstrap factor: mean of the defined ``bf (..., S)`` over sizes lo <= n <= hi (paper V-C)."""
    return window_mean(bf, sizes, lo, hi)[0]


def select_best(p: np.ndarray, sizes: Sequence[int], lo: int = 2, hi: int = 100) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy over sizes lo..hi:
    ``p (..., K, S) -> (...,)``; NaN candidates never win; the first of tied ones (for
    display: Table II values share ties out, ``measures.tie_weights``)."""
    mask = size_mask(sizes, lo, hi)
    mask = mask if mask.any() else np.ones_like(mask)
    with _quiet():
        return _first(np.nanmean(np.asarray(p)[..., mask], axis=-1))


def select_at(p: np.ndarray, sizes: Sequence[int], n: int = 10) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy at training size n (the paper's
    offline "best after ten"); the first of tied ones."""
    return _first(np.asarray(p)[..., list(sizes).index(n)])


def _first(score: np.ndarray) -> np.ndarray:
    return np.argmax(tie_weights(score) > 0, axis=-1)


def _outcomes(res: Mapping[str, Any], acc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``loo (A, C, R)``, ``correct (A, C, S, R, N)`` and ``n_test (A,)``; results without
    them (hand-built in tests) get NaN / none."""
    a, c, s, r = acc.shape
    loo = np.asarray(_get(res, "loo", np.full((a, c, r), np.nan)), dtype=float)
    return loo, np.asarray(_get(res, "correct", np.zeros((a, c, s, r, 0), bool))), np.asarray(_get(res, "n_test", np.zeros(a, int)))


def _get(res: Mapping[str, Any], key: str, default: Any) -> Any:
    return res[key] if key in res.keys() else default


def analyse(res: Mapping[str, np.ndarray], cfg: ExperimentConfig, seed: int = 0, intervals: bool = True) -> dict[str, Any]:
    """Everything section V reports for one space, as arrays over (target, condition, size).

    Returns ``mean``/``sem`` curves ``(A, C + 2, S)``, ``bf`` curves, ``avg_bf (A, C + 2)``,
    ``defined (A,)`` (window sizes with a bf), the chosen candidates per target
    (``best_db1``, ``ten_db1``, ... condition indices, the first of tied ones; ``ties_*`` how
    many tied; ``online_db1`` / ``online_cb1`` the online weights ``(A, K, R)``), Table II
    per target ``table2_per_target (rows, A)``, ``table2 (rows, 3)`` avg/min/max,
    ``n_targets (rows,)``, the same for the accuracy gain (``gain_*``), and with
    ``intervals`` the bootstrap intervals ``table2_ci``/``gain_ci (rows, 2)`` of each row's
    avg, ``per_target_ci (rows, A, 2)`` and ``mean_ci (A, C + 2, S, 2)`` (``cfg.ci_level``,
    ``cfg.ci_resamples`` resamples, seeded by ``seed``), and the threshold study.
    """
    acc, sizes = np.asarray(res["acc"], dtype=float), [int(s) for s in res["sizes"]]
    actions = [str(a) for a in res["actions"]]
    a = len(actions)
    lay = layout(a, len(cfg.thresholds))
    loo, correct, n_test = _outcomes(res, acc)
    acc_x, corr_x, w_on = extend(acc, correct, loo, lay)
    mean, sem = curves(acc_x)  # (A, C + 2, S)
    bf = bootstrap_factor(mean, mean[:, lay["NB"]][:, None, :], cfg.chance)
    t2 = table2_rows(mean, sizes, cfg, lay)
    table2, n_targets = summarise(t2["bf"])
    gain, gain_n = summarise(t2["gain"])
    conds = [str(c) for c in res["conditions"]] + ["DB1 online after ten", "CB1 online after ten"]
    out: dict[str, Any] = {"actions": actions, "sizes": sizes, "mean": mean, "sem": sem, "bf": bf,
                           "avg_bf": window_mean(bf, sizes, *cfg.bf_sizes)[0], "defined": t2["defined"],
                           "window_sizes": int(size_mask(sizes, *cfg.bf_sizes).sum()), "conditions": conds,
                           "table2_rows": list(TABLE2_ROWS), "table2_per_target": t2["bf"], "table2": table2,
                           "n_targets": n_targets, "gain_per_target": t2["gain"], "gain": gain, "gain_n_targets": gain_n,
                           "test_size": _get(res, "test_size", None), "test_positive": _get(res, "test_positive", None),
                           "outcomes": bool(corr_x.shape[-1]), "reps": int(acc.shape[-1])}
    lo, hi = cfg.best_sizes
    for fam in ("DB1", "CB1"):
        idx = lay[fam]
        fam_mean = mean[:, idx]
        with _quiet():
            best_score = np.nanmean(np.where(size_mask(sizes, lo, hi), fam_mean, np.nan), -1)
        out[f"best_{fam.lower()}"] = idx[select_best(fam_mean, sizes, lo, hi)]
        out[f"ten_{fam.lower()}"] = idx[select_at(fam_mean, sizes, cfg.select_size)] if cfg.select_size in sizes else out[f"best_{fam.lower()}"]
        out[f"ties_{fam.lower()}"] = (tie_weights(best_score) > 0).sum(-1)
        out[f"online_{fam.lower()}"] = w_on[fam]
    if intervals:
        out.update(_intervals(acc_x, corr_x, n_test, sizes, cfg, lay, seed))
    out["thresholds"] = threshold_study(mean[:, : lay["n"]], bf[:, : lay["n"]], np.asarray(res["category_masks"], dtype=bool),
                                        sizes, cfg, lay)
    return out


def _intervals(acc_x, corr_x, n_test, sizes, cfg, lay, seed) -> dict[str, np.ndarray]:
    """Bootstrap intervals of Table II (bf and gain: each row's avg and every per target
    value) and of every mean curve."""
    means = resampled_means(acc_x, corr_x, n_test, cfg.ci_resamples, derive_seed(seed, 7))
    avg_bf, avg_gain, per_bf = [], [], []
    for b in range(0, len(means), CI_CHUNK):
        t2 = table2_rows(means[b : b + CI_CHUNK], sizes, cfg, lay)
        avg_bf.append(summarise(t2["bf"])[0][..., 0])
        avg_gain.append(summarise(t2["gain"])[0][..., 0])
        per_bf.append(t2["bf"])
    level = cfg.ci_level
    return {"table2_ci": np.stack(percentile_interval(np.concatenate(avg_bf), level), -1),
            "gain_ci": np.stack(percentile_interval(np.concatenate(avg_gain), level), -1),
            "per_target_ci": np.stack(percentile_interval(np.concatenate(per_bf), level), -1),
            "mean_ci": np.stack(percentile_interval(means, level), -1),
            "ci_level": level, "ci_resamples": int(cfg.ci_resamples)}


def threshold_study(mean: np.ndarray, bf: np.ndarray, masks: np.ndarray, sizes: Sequence[int],
                    cfg: ExperimentConfig, lay: dict) -> dict[str, Any]:
    """Paper Fig. 12: per threshold T the bf curve ``(S,)`` of each target's best category
    among those built at T (tied ones share; mean over targets), plus the overall average over all usable
    categories; ``masks: (T, A, K)``."""
    idx = lay["CB1"]
    cb_mean, cb_bf = mean[:, idx], bf[:, idx]  # (A, K, S)
    ran = np.any(np.isfinite(cb_mean), axis=-1)  # (A, K)
    t_idx = np.arange(mean.shape[0])
    out: dict[str, Any] = {"T": list(cfg.thresholds), "best_curve": [], "count": [], "best": []}
    with _quiet():
        for ti in range(len(cfg.thresholds)):
            m = masks[ti] & ran  # (A, K)
            cand = np.where(m[..., None], cb_mean, np.nan)
            best = select_best(cand, sizes, *cfg.best_sizes)
            mask = size_mask(sizes, *cfg.best_sizes)
            w = tie_weights(np.nanmean(cand[..., mask if mask.any() else slice(None)], -1))  # ties share (A, K)
            mixed = np.einsum("ak,aks->as", w, np.nan_to_num(cb_bf))  # bf is NaN where NB is: same for every k
            curve = np.where(m.any(1)[:, None] & np.isfinite(cb_bf[t_idx, best]), mixed, np.nan)  # (A, S)
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
