"""The paired quantities section VI's claims are decided on, and the per-pair error table.

Takes one space's raw results of ``experiments.run_space``; ``differences`` gives the paired
differences of accuracies (per repetition; across folders also with the test scenes
resampled) and of the standard deviations, each with an interval; ``pair_errors`` per real
test pair and classifier the share of the repetitions that tested it in which it was wrong;
and the resampling helpers they share with ``experiments`` (``interval`` over repetitions,
``scene_resamples`` of whole test scenes, ``_balanced`` accuracy of per-pair hit rates).
"""
from __future__ import annotations

import numpy as np

from relaff_jax.constants import BESIDE, ON_TOP, RELATIONS

HITS = ("real", "fair_to_real", "full_to_real")  # the accuracies measured on a fixed test folder


def _balanced(per_pair: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Balanced accuracy of per-pair hit rates ``(..., N)`` against ``y (N,)``: (...,)."""
    return 0.5 * (per_pair[..., y].mean(-1) + per_pair[..., ~y].mean(-1))


def scene_resamples(y: np.ndarray, scene: np.ndarray, rng: np.random.Generator, n_boot: int) -> list[np.ndarray]:
    """Index sets of test pairs, whole test scenes drawn with replacement; those without both
    relations are dropped (so fewer than ``n_boot`` may come back)."""
    y, scene = np.asarray(y).astype(bool), np.asarray(scene)
    names = np.unique(scene)
    rows = [np.flatnonzero(scene == s) for s in names]
    out = []
    for _ in range(n_boot):
        idx = np.concatenate([rows[i] for i in rng.integers(0, len(names), len(names))])
        if y[idx].any() and not y[idx].all():
            out.append(idx)
    return out


def interval(x: np.ndarray, rng: np.random.Generator, n_boot: int, level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``x`` (R,)."""
    x = np.asarray(x, float)
    means = x[rng.integers(0, len(x), (n_boot, len(x)))].mean(axis=1)
    lo, hi = np.quantile(means, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def differences(res: dict, rng: np.random.Generator, n_boot: int) -> dict:
    """The paired differences the claims are decided on: per repetition (the same draws make
    both), mean and percentile interval; with per-pair hits on a fixed test folder also the
    interval with the test scenes resampled. ``std real-sim_fair``: the difference of the
    standard deviations over repetitions, its interval with the repetitions resampled."""
    out = {}
    for a, b in (("sim_fair", "real"), ("full_to_real", "real")):
        d = np.asarray(res[a], float) - np.asarray(res[b], float)
        out[f"{a}-{b}"] = dict(mean=float(d.mean()), ci95=interval(d, rng, n_boot))
        if f"hits_{a}" in res and f"hits_{b}" in res:
            out[f"{a}-{b}"]["ci95_scenes"] = scene_interval_diff(res[f"hits_{a}"], res[f"hits_{b}"], res["test_y"],
                                                                 res["test_scene"], rng, n_boot)
    x, y = np.asarray(res["real"], float), np.asarray(res["sim_fair"], float)
    if len(x) > 1:
        i = rng.integers(0, len(x), (n_boot, len(x)))
        v = x[i].std(1, ddof=1) - y[i].std(1, ddof=1)
        out["std real-sim_fair"] = dict(mean=float(x.std(ddof=1) - y.std(ddof=1)),
                                        ci95=tuple(float(q) for q in np.quantile(v, [0.025, 0.975])))
    return out


def scene_interval_diff(hits_a: np.ndarray, hits_b: np.ndarray, y: np.ndarray, scene: np.ndarray,
                        rng: np.random.Generator, n_boot: int) -> tuple[float, float] | None:
    """``scene_interval`` of the difference of two balanced accuracies on the same test pairs
    (the same scenes drawn for both: paired)."""
    y = np.asarray(y).astype(bool)
    pa, pb = np.asarray(hits_a, float).mean(0), np.asarray(hits_b, float).mean(0)
    vals = [_balanced(pa[i], y[i]) - _balanced(pb[i], y[i]) for i in scene_resamples(y, scene, rng, n_boot)]
    if len(vals) < n_boot / 2:
        return None
    lo, hi = np.quantile(vals, [0.025, 0.975])
    return float(lo), float(hi)


def pair_errors(res: dict) -> list[dict]:
    """Per real test pair: scene, pair (object ids), relation, and per classifier of ``HITS``
    the share of the repetitions that tested it in which it was wrong (None: never tested);
    the pairs some classifier got wrong, most often wrong first. Empty for results made
    before the per-pair arrays were kept."""
    if "pairs_real" not in res:
        return []
    rows = []
    for j, (sc, ab, yv) in enumerate(zip(res["pairs_scene"], res["pairs_ab"], res["pairs_y"])):
        wrong, tested = {}, {}
        for k in HITS:
            col = np.asarray(res[f"pairs_{k}"], float)[:, j]
            n = int(np.isfinite(col).sum())
            tested[k] = n
            wrong[k] = None if n == 0 else float(1.0 - np.nanmean(col))
        if any(w for w in wrong.values() if w is not None):
            rows.append(dict(scene=str(sc), pair=str(ab), relation=RELATIONS[ON_TOP if bool(yv) else BESIDE],
                             wrong=wrong, tested=tested))
    return sorted(rows, key=lambda r: (-max(w or 0.0 for w in r["wrong"].values()), r["scene"], r["pair"]))
