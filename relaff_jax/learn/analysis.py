"""Section V's numbers from the raw accuracies, as array operations.

Takes one space's results (``results.load_results(RESULTS)[space]``: ``acc: (A, C, S, R)``
over target, condition, size and repetition, with ``loo`` and ``correct``) and the config;
``analyse`` gives the mean and standard-error curves ``(A, C + 2, S)`` (the sweep's conditions,
then the online "best after ten" learners of ``online.py``), bootstrap factors (paper III-D)
``(A, C + 2, S)``, average bootstrap factors over the window ``(A, C + 2)`` and how many of
its sizes each target has a bf for, the chosen sources ("best", "best after ten", offline
and online), Table II per target ``(rows, A)`` and as avg/min/max ``(rows, 3)`` with
``n_targets`` and bootstrap intervals (``intervals.py``), the same for the accuracy gain
(``measures.py``), bootstrap intervals of the mean curves the figures draw, and the threshold study (paper
Fig. 12); every average over targets is over the paper's nine (``paper``), and per target the
answers of ``per_target.py``. ``categories_per_threshold`` counts the categories the
heuristic builds.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.learn.table2 import ORACLE, TABLE2_ROWS
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.user_conditions import builtin_results
from relaff_jax.learn.correlation import categories_above, category_pairs
from relaff_jax.learn import gains as G
from relaff_jax.learn import heldout as H
from relaff_jax.learn import per_target
from relaff_jax.learn.intervals import (
    bc_counts,
    checked_interval,
    drawn_intervals,
    fast_outcomes,
    half_sizes,
    interval_pairs,
    resampled_means,
    scene_halves,
    whole,
)
from relaff_jax.learn.measures import (
    _quiet,
    bootstrap_factor,
    chance_tolerance,
    min_defined,
    size_mask,
    summarise,
    table2_rows,
    tie_weights,
    window_mean,
)
from relaff_jax.learn.online import extend
from relaff_jax.learn.protocol import layout
from relaff_jax.provenance import derive_seed
from relaff_jax.config import streams

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
    correct = _get(res, "correct", None)
    correct = np.zeros((a, c, s, r, 0), bool) if correct is None else correct  # packed stays packed
    return loo, correct, np.asarray(_get(res, "n_test", np.zeros(a, int)))


def _get(res: Mapping[str, Any], key: str, default: Any) -> Any:
    return res[key] if key in res.keys() else default


def half_curves(acc_x: np.ndarray, corr_x: np.ndarray, halves: np.ndarray,
                reference: bool = False) -> np.ndarray | None:
    """``(2, A, C', S)`` mean accuracy on each half of every test set (None without outcomes):
    the mean over repetitions of ``heldout.half_rep_curves``. ``reference``: the float copy of
    every block (the fast path, ``halfrows``, is checked against it)."""
    reps = H.half_rep_curves(acc_x, corr_x, halves, reference=reference)
    return None if reps is None else reps.mean(-1)


def analyse(res: Mapping[str, np.ndarray], cfg: ExperimentConfig, seed: int = 0, intervals: bool = True,
            reference: bool = False) -> dict[str, Any]:
    """Everything section V reports for one space, as arrays over (target, condition, size).

    Returns ``mean``/``sem`` curves ``(A, C + 2, S)``, ``bf`` curves, ``avg_bf (A, C + 2)``,
    ``defined (A,)`` (window sizes with a bf; ``min_defined`` of them needed), ``built (T, A)``
    (a category built at T for the target), ``tol (A,)`` the
    at-chance tolerance, the in-sample chosen candidates per target (``best_db1``, ``ten_db1``,
    ... condition indices, the first of tied ones; ``ties_*`` how many tied; ``online_db1`` /
    ``online_cb1`` the online weights ``(A, K, R)``), Table II per target
    ``table2_per_target (rows, A)``, ``table2 (rows, 3)`` avg/min/max, ``n_targets (rows,)``,
    ``unmeasurable {row: reason}``, the same for the accuracy gain (``gain_*``), and with
    ``intervals`` (``_intervals``) bias-corrected bootstrap intervals and the resampled values
    behind them, and the threshold study; ``paper (A,)`` the paper's targets (every average is
    over them) and ``affordances`` (``per_target.answers``). ``reference``: the reference paths
    (the same bits, slower; kept to check the default ones against).
    """
    # Table II reads the built-in conditions (a user's conditions follow them on the axis)
    res = builtin_results(res, layout(len(res["actions"]), len(cfg.thresholds))["n"])
    acc, sizes = np.asarray(res["acc"], dtype=float), [int(s) for s in res["sizes"]]
    actions = [str(a) for a in res["actions"]]
    a = len(actions)
    lay = layout(a, len(cfg.thresholds))
    loo, correct, n_test = _outcomes(res, acc)
    acc_x, corr_x, w_on = extend(acc, correct, loo, lay)
    mean, sem = curves(acc_x)  # (A, C + 2, S)
    tol = chance_tolerance(cfg, n_test, a)
    masks = np.asarray(res["category_masks"], dtype=bool)  # (T, A, K)
    cbn_ok = masks[list(cfg.thresholds).index(cfg.cbn_threshold)].any(-1)  # (A,)
    halves = scene_halves(n_test, _get(res, "test_positive", None), corr_x.shape[-1])
    hm = None  # the resampled half curves, made with the half curves where one pass reads both
    if intervals and not reference and corr_x.shape[-1] and fast_outcomes(corr_x):
        half_means, hm, half_reps = _fused(acc_x, corr_x, n_test, halves, cfg, seed)
    else:
        half_reps = H.half_rep_curves(acc_x, corr_x, halves, reference=reference)  # (2, A, C', S, R)
        half_means = None if half_reps is None else half_reps.mean(-1)
    bf = bootstrap_factor(mean, mean[:, lay["NB"]][:, None, :], cfg.chance, tol[:, None, None])
    t2 = table2_rows(mean, sizes, cfg, lay, tol, half_means, cbn_ok, masks, reference=reference)
    paper = np.isin(np.asarray(actions), ACTIONS)  # Table II's rows average the paper's nine (a user action: per target only)
    table2, n_targets = summarise(np.where(paper, t2["bf"], np.nan))
    gain, gain_n = summarise(np.where(paper, t2["gain"], np.nan))
    conds = [str(c) for c in res["conditions"]] + ["DB1 online after ten", "CB1 online after ten"]
    out: dict[str, Any] = {"actions": actions, "sizes": sizes, "mean": mean, "sem": sem, "bf": bf, "tol": tol,
                           "avg_bf": window_mean(bf, sizes, *cfg.bf_sizes)[0], "defined": t2["defined"],
                           "min_defined": min_defined(cfg, sizes), "cbn_ok": cbn_ok, "built": masks.any(-1),
                           "window_sizes": int(size_mask(sizes, *cfg.bf_sizes).sum()), "conditions": conds,
                           "table2_rows": list(TABLE2_ROWS), "table2_per_target": t2["bf"], "table2": table2,
                           "n_targets": n_targets, "gain_per_target": t2["gain"], "gain": gain, "gain_n_targets": gain_n,
                           "test_size": _get(res, "test_size", None), "test_positive": _get(res, "test_positive", None),
                           "n_test": n_test, "outcomes": bool(corr_x.shape[-1]), "reps": int(acc.shape[-1])}
    out["unmeasurable"] = unmeasurable(out, cfg)
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
    out["paper"] = paper
    out["thresholds"] = threshold_study(mean[:, : lay["n"]], bf[:, : lay["n"]], masks, sizes, cfg, lay, t2, paper)
    out["methods"] = against_nb(acc_x, mean, sizes, cfg, lay, cbn_ok, seed, paper, half_means, half_reps)
    if intervals:
        out.update(_intervals(acc_x, corr_x, n_test, halves, sizes, cfg, lay, seed, tol, cbn_ok, masks, out, reference, hm))
    out["affordances"] = per_target.answers(out)
    return out


def against_nb(acc_x: np.ndarray, mean: np.ndarray, sizes: Sequence[int], cfg: ExperimentConfig, lay: dict,
               cbn_ok: np.ndarray, seed: int, paper: np.ndarray | None = None, half_means: np.ndarray | None = None,
               half_reps: np.ndarray | None = None) -> dict[str, Any]:
    """Each of ``gains.METHODS`` against NB (``gains.py``): the gain curve's area over the
    window and the samples saved at ``select_size`` (mean over the targets ``paper (A,)``,
    all where None; per target ``*_per_target (M, A)``; intervals added by ``_intervals``
    from the same resamples as Table II's), and the probability of improvement over NB of
    the per-repetition window accuracies across those affordances and repetitions, its
    interval from ``cfg.ci_resamples`` stratified resamples, its p-value against 0.5 and the
    Holm correction over the methods (``holm_reject`` at 1 - ``ci_level``). With the half curves
    ``half_means (2, A, C', S)`` and ``half_reps (2, A, C', S, R)`` every statistic of a "best"
    or "after ten" method rests on Table II's held-out choice (``heldout.py``), else on the
    in-sample one (its name then ends in "(in-sample oracle)")."""
    w = G.method_weights(mean, lay, cfg, sizes, cbn_ok)
    paper = np.ones(mean.shape[0], bool) if paper is None else np.asarray(paper, bool)
    st = G.curve_stats(mean, w, lay, sizes, cfg, paper, halves=half_means)
    x, y = G.rep_scores(acc_x, w, lay, sizes, cfg, None if half_means is None else (half_reps, half_means))
    rng = np.random.default_rng(derive_seed(seed, streams.IMPROVEMENT))
    poi, ci, p = [], [], []
    for k in range(len(G.METHODS)):
        keep = np.isfinite(x[k]).any(-1) & np.isfinite(y[k]).any(-1) & paper  # the paper's tasks the method ran for
        if not keep.any():
            poi.append(np.nan), ci.append((np.nan, np.nan)), p.append(np.nan)
            continue
        est = G.probability_of_improvement(x[k][keep], y[k][keep])
        boot = G.stratified_poi(x[k][keep], y[k][keep], cfg.ci_resamples, rng)
        poi.append(est)
        ci.append(tuple(float(v[0]) for v in checked_interval(boot[:, None], np.array([est]), cfg.ci_level, cfg.ci_tail)[:2]))
        p.append(G.bootstrap_p(boot, 0.5))
    adj, rej = G.holm(p, 1 - cfg.ci_level)
    return {"names": H.method_names(G.METHODS, half_means is not None), "weights": w, "area": st["area"], "saved": st["saved"],
            "censored": st["censored"], "poi": np.asarray(poi), "poi_ci": np.asarray(ci), "poi_p": np.asarray(p),
            "poi_holm_p": adj, "poi_holm_reject": rej} | {k: st[k] for k in st if k.endswith("_per_target")}


def unmeasurable(a: Mapping[str, Any], cfg: ExperimentConfig) -> dict[str, str]:
    """``{row: reason}`` for every Table II row without a single target: never shown as a number."""
    why: dict[str, str] = {}
    for i, name in enumerate(TABLE2_ROWS):
        if a["n_targets"][i] > 0:
            continue
        if name == "CBn" and not np.any(a["cbn_ok"]):
            why[name] = f"no category passed T = {cfg.cbn_threshold:g} (CBn would be NB relabelled)"
        elif ("best" in name and "oracle" not in name and "online" not in name) and not a["outcomes"]:
            why[name] = "no test outcomes kept: no half of the test scenes to choose on"
        elif name + ORACLE in TABLE2_ROWS and a["n_targets"][TABLE2_ROWS.index(name + ORACLE)] > 0:
            why[name] = ("no affordance has a bootstrap factor on half of its test set (NB on a half at most "
                         f"{cfg.chance_tol_scenes:g} of its scenes above chance at every size)")
        elif np.all(np.isnan(a["gain_per_target"][i])):
            why[name] = "the condition did not run"
        else:
            why[name] = (f"no affordance has a bootstrap factor at >= {a['min_defined']} of the window's "
                         f"{a['window_sizes']} sizes (NB more than {cfg.chance_tol_scenes:g} test scene above chance)")
    return why


def _fixed_mean(per_target: np.ndarray, fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over the targets of the point estimate ``fixed (rows, A)`` (no other target ever
    enters) in each resample ``per_target (B, rows, A)``, over those of them with a value in
    it, and whether all of them had one ``(B, rows)`` (reported as ``table2_set_held``)."""
    held = np.all(np.isfinite(per_target) | ~fixed, -1)
    with _quiet():
        return np.nanmean(np.where(fixed, per_target, np.nan), -1), held


def _fused(acc_x, corr_x, n_test, halves, cfg, seed) -> tuple[np.ndarray, np.ndarray]:
    """``half_curves`` and ``_intervals``' resampled means from one read of the outcomes (the
    same bits as the two apart: each block's halves unpacked and mixed once, not twice)."""
    means = np.full((2,) + corr_x.shape[:3], np.nan)
    reps = np.full(means.shape + acc_x.shape[-1:], np.nan)  # per repetition (P(improvement)'s held-out scores)
    hm = resampled_means(acc_x, corr_x, n_test, cfg.ci_resamples, derive_seed(seed, streams.INTERVALS), halves,
                         means=means, rep_means=reps)
    ran = np.isfinite(acc_x).any(-1)[None]
    return np.where(ran, means, np.nan), hm, np.where(ran[..., None], reps, np.nan)


def _intervals(acc_x, corr_x, n_test, halves, sizes, cfg, lay, seed, tol, cbn_ok, masks, pt, reference=False,
               hm=None) -> dict[str, Any]:
    """Bootstrap intervals (``intervals.checked_interval``: bias-corrected unless an end would
    rest on fewer than ``cfg.ci_tail`` of the resamples) of Table II (bf and gain:
    each row's avg over the point estimate's targets, held fixed, and every per target
    value), of the threshold study's averages and of the mean curves the figures draw
    (``mean_ci (A, C', S, 2)``: NB's and each target's in-sample best DB1 source's, NaN
    elsewhere; ``ci_bc_count`` still counts every mean curve's interval, from the resamples'
    counts, ``intervals.drawn_intervals``); the resampled values (``*_boot``, for the findings'
    paired differences) and the share of resamples in which each row's set of targets kept a
    value (``table2_set_held (rows,)``). ``reference``: every mean curve's interval made, the
    drawn ones kept (the same bits)."""
    if hm is None:
        hm = resampled_means(acc_x, corr_x, n_test, cfg.ci_resamples, derive_seed(seed, streams.INTERVALS), halves, reference=reference)
    hs = half_sizes(n_test, halves)
    outcomes = bool(corr_x.shape[-1])
    paper = pt["paper"]  # every average: the paper's nine
    fixed_bf, fixed_gain = np.isfinite(pt["table2_per_target"]) & paper, np.isfinite(pt["gain_per_target"]) & paper
    fixed_thr = np.isfinite(pt["thresholds"]["per_target"]) & paper
    drawn = np.zeros(pt["mean"].shape[:2], bool)  # (A, C'): the curves Figs. 7 and 8 draw with their bands
    drawn[:, lay["NB"]] = True
    drawn[np.arange(len(drawn)), pt["best_db1"]] = True
    counts = [0, 0, 0]  # every mean curve's bc_counts, resample chunk by chunk
    boot: dict[str, list] = {k: [] for k in ("bf", "held", "gain", "per", "thr", "nb", "mean", "area", "saved")}
    boot.update({k: [] for k in per_target.BOOT})
    for b in range(0, len(hm), CI_CHUNK):
        h = hm[b : b + CI_CHUNK]
        m = whole(h, hs)
        t2 = table2_rows(m, sizes, cfg, lay, tol, h if outcomes else None, cbn_ok, masks, min_cells=1, reference=reference)
        v, held = _fixed_mean(t2["bf"], fixed_bf)
        boot["bf"].append(v), boot["held"].append(held)
        boot["gain"].append(_fixed_mean(t2["gain"], fixed_gain)[0])
        boot["per"].append(t2["bf"])
        boot["thr"].append(_fixed_mean(t2["thr_bf"], fixed_thr)[0])
        with _quiet():
            boot["nb"].append(np.nanmean(m[:, paper, lay["NB"]], 1))  # (b, S) mean NB over the paper's targets
        boot["mean"].append(m if reference else m[:, drawn])
        counts = [c + k for c, k in zip(counts, bc_counts(m, pt["mean"]))]
        st = G.curve_stats(m, pt["methods"]["weights"], lay, sizes, cfg, paper, halves=h if outcomes else None)
        boot["area"].append(st["area"]), boot["saved"].append(st["saved"])
        choice = lay["DB1"][select_best(m[:, :, lay["DB1"]], sizes, *cfg.best_sizes)]  # (b, A) in-sample best source
        for k, v in per_target.resampled(t2, st, choice).items():
            boot[k].append(v)
    bt = {k: np.concatenate(v) for k, v in boot.items()}
    meth = pt["methods"]
    level, tail, tally = cfg.ci_level, cfg.ci_tail, []
    ci = lambda vals, est: interval_pairs(vals, est, level, tail, tally)  # noqa: E731
    meth["area_ci"], meth["saved_ci"] = ci(bt["area"], meth["area"]), ci(bt["saved"], meth["saved"])
    out = {"table2_ci": ci(bt["bf"], pt["table2"][:, 0]), "gain_ci": ci(bt["gain"], pt["gain"][:, 0]),
           "per_target_ci": ci(bt["per"], pt["table2_per_target"]), "mean_ci": drawn_intervals(bt["mean"], pt["mean"], drawn, counts, level, tail, tally, reference),
           "threshold_ci": ci(bt["thr"], pt["thresholds"]["avg"]),
           "table2_boot": bt["bf"], "gain_boot": bt["gain"], "threshold_boot": bt["thr"], "nb_boot": bt["nb"],
           "table2_set_held": bt["held"].mean(0), "ci_level": level, "ci_resamples": int(cfg.ci_resamples),
           "ci_tail": tail, "ci_method": "bias-corrected percentile (BC), percentile where a BC end leaves less "
           f"than {100 * tail:g} % of the resamples beyond it"} | per_target.intervals(bt, pt, level, tail, tally)
    # (bias-corrected, defined) over every interval above: how often the percentile one stood in
    out["ci_bc_count"] = tuple(int(x) for x in np.sum(tally, 0)) if tally else (0, 0)
    return out


def threshold_study(mean: np.ndarray, bf: np.ndarray, masks: np.ndarray, sizes: Sequence[int],
                    cfg: ExperimentConfig, lay: dict, t2: Mapping[str, np.ndarray],
                    paper: np.ndarray | None = None) -> dict[str, Any]:
    """Paper Fig. 12. Its numbers use Table II's aggregation (``t2 = table2_rows(..., masks)``):
    per threshold T, each target's best category among those built at T, chosen on one half
    of the test scenes and scored on the other (``per_target (T, A)``, ``avg (T,)``, over the
    targets with a value, ``n_targets (T,)``; at T = 0 it is Table II's "CB1 best"), and the
    in-sample oracle (``avg_oracle``). For the figure: per T the in-sample best category's bf
    curve ``best_curve (T, S)`` (tied ones share; mean over targets) and the average over all
    usable categories ``overall_curve (S,)``; ``masks: (T, A, K)``. Every mean is over the
    targets ``paper (A,)`` (all where None); ``per_target`` holds every target."""
    paper = np.ones(mean.shape[0], bool) if paper is None else np.asarray(paper, bool)
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
            out["best_curve"].append(np.nanmean(np.where(paper[:, None], curve, np.nan), axis=0))
            out["best"].append(idx[best])
            out["count"].append(int(masks[ti].any(0).sum()))
        out["overall_curve"] = np.nanmean(np.where((ran & paper[:, None])[..., None], cb_bf, np.nan), axis=(0, 1))
        out["per_target"], out["per_target_oracle"] = t2["thr_bf"], t2["thr_oracle_bf"]
        out["avg"] = np.nanmean(np.where(paper, t2["thr_bf"], np.nan), -1)
        out["avg_oracle"] = np.nanmean(np.where(paper, t2["thr_oracle_bf"], np.nan), -1)
    out["n_targets"] = (np.isfinite(t2["thr_bf"]) & paper).sum(-1)
    out["best_curve"] = np.stack(out["best_curve"])
    return out


def categories_per_threshold(corr: np.ndarray, thresholds: Sequence[float]) -> dict[str, int]:
    """How many of the A(A-1)/2 categories the heuristic builds at each T (and how many pairs
    literally have corr > T, which differs from the kept count only at T <= 0)."""
    pairs = category_pairs(range(corr.shape[0]))
    i, j = np.asarray(pairs).T
    return {f"{t:g}": {"built": int(categories_above(corr, pairs, t).sum()), "corr_above": int((corr[i, j] > t).sum())}
            for t in thresholds}
