"""The user's conditions beside Table II: their rows, by the code that gives the paper's DB1 rows.

Takes one space's results (``results.load_results(RESULTS)[space]``: the built-in conditions,
then the user's learners ``NAME`` or ``NAME:variant`` on the condition axis,
``user_conditions.extend``) and the config; ``user_rows`` gives per registered condition its
rows, each condition measured against NB on its own:

* one learner (``NAME``): the row ``NAME``, its average bootstrap factor over the window;
* variants (``NAME:v``, one learner each, like DB1's sources): ``NAME average`` (over the
  variants), ``NAME best`` and ``NAME best after ten`` (chosen on one half of the test scenes
  and scored on the other, both ways), and per target the variant "best" and "best after
  ten" choose on the whole test set (for display, as ``analyse``'s ``best_db1``).

Each condition's learners and NB go through ``measures.table2_rows`` as DB1's candidates (a
layout whose DB1 is the variants), so a row means what the DB1 row of that name means; its
intervals come from ``intervals.resampled_means`` with the seed of Table II's (the draws depend
on the test sets and repetitions only: the same resamples as Table II's). Rows average the
paper's nine targets (Table II's rule), a user action's value is per target only.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from relaff_jax.config import streams
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.constants import ACTIONS
from relaff_jax.learn.analysis import CI_CHUNK, _fixed_mean, _outcomes, curves, half_curves, select_at, select_best
from relaff_jax.learn.intervals import half_sizes, interval_pairs, resampled_means, scene_halves, whole
from relaff_jax.learn.measures import chance_tolerance, summarise, table2_rows
from relaff_jax.learn.online import extend
from relaff_jax.learn.protocol import layout
from relaff_jax.learn.table2 import TABLE2_ROWS
from relaff_jax.provenance import derive_seed

# a row of a condition with variants -> the DB1 row of the same meaning
VARIANT_ROWS = {"average": "DB1 average", "best": "DB1 best", "best after ten": "DB1 best after ten"}
NOT_IN_PAPER = "not in the paper"


def groups(conditions, n_builtin: int) -> dict[str, list[int]]:
    """``{condition name: [indices on the condition axis]}`` of the learners after the built-ins."""
    out: dict[str, list[int]] = {}
    for i in range(n_builtin, len(conditions)):
        out.setdefault(str(conditions[i]).partition(":")[0], []).append(i)
    return out


def _sub(res: Mapping[str, Any], keep: list[int]) -> tuple[np.ndarray, Any]:
    """``acc (A, 1 + K, S, R)`` and the outcomes of NB and the learners ``keep`` (packed stays packed)."""
    acc = np.asarray(res["acc"], dtype=float)[:, keep]
    c = res["correct"] if "correct" in res.keys() else None
    if c is None:
        return acc, np.zeros(acc.shape + (0,), bool)
    if hasattr(c, "packed"):
        return acc, type(c)(c.packed[:, keep], c.n)
    return acc, np.asarray(c)[:, keep]


def _one(res, cfg, idx, variants, seed, intervals, reference, halves, tol, n_test):
    """Rows of one condition (its learners ``idx`` on the axis): point values per target and,
    with ``intervals``, the resampled ones."""
    sizes = [int(s) for s in res["sizes"]]
    k = len(idx)
    cand = np.arange(1, 1 + k)
    lay = {"NB": 0, "DB1": cand, "DBn": 0, "CB1": cand, "CBn": np.zeros(len(cfg.thresholds), int), "n": 1 + k}
    acc, correct = _sub(res, [0] + list(idx))
    a = acc.shape[0]
    acc_x, corr_x, _ = extend(acc, correct, np.full((a, 1 + k, acc.shape[-1]), np.nan), lay)  # no online choice
    mean, _ = curves(acc_x)
    outcomes = bool(corr_x.shape[-1])
    t2 = table2_rows(mean, sizes, cfg, lay, tol, half_curves(acc_x, corr_x, halves, reference=reference),
                     reference=reference)
    names = list(VARIANT_ROWS.values()) if variants else ["DB1 average"]
    pick = [TABLE2_ROWS.index(n) for n in names]
    out = {"bf": t2["bf"][pick], "gain": t2["gain"][pick]}
    if variants:
        ran = np.isfinite(mean[:, cand]).any(-1).any(-1)  # (A,)
        ten = select_at(mean[:, cand], sizes, cfg.select_size) if cfg.select_size in sizes else \
            select_best(mean[:, cand], sizes, *cfg.best_sizes)
        out["best"] = [int(i) if r else -1 for i, r in zip(select_best(mean[:, cand], sizes, *cfg.best_sizes), ran)]
        out["ten"] = [int(i) if r else -1 for i, r in zip(ten, ran)]
    if not intervals:
        return out
    hm = resampled_means(acc_x, corr_x, n_test, cfg.ci_resamples, derive_seed(seed, streams.INTERVALS), halves,
                         reference=reference)
    hs = half_sizes(n_test, halves)
    boot = {"bf": [], "gain": []}
    for b in range(0, len(hm), CI_CHUNK):
        h = hm[b : b + CI_CHUNK]
        tb = table2_rows(whole(h, hs), sizes, cfg, lay, tol, h if outcomes else None, min_cells=1, reference=reference)
        boot["bf"].append(tb["bf"][:, pick]), boot["gain"].append(tb["gain"][:, pick])
    out["boot"] = {key: np.concatenate(v) for key, v in boot.items()}  # (B, rows, A)
    return out


def user_rows(res: Mapping[str, Any], cfg: ExperimentConfig, seed: int = 0, intervals: bool = True,
              reference: bool = False) -> dict[str, Any]:
    """Rows of every user condition in ``res`` (none: ``names`` empty).

    Returns ``names`` (rows), ``condition`` (rows,) the condition of each, ``table2``
    ``(rows, 3)`` avg/min/max of the average bootstrap factor over the paper's targets with a
    value, ``n_targets (rows,)``, ``gain (rows, 3)``, ``table2_per_target`` and
    ``gain_per_target`` ``(rows, A)``, ``best`` / ``best_after_ten``: ``{condition: {target:
    variant}}`` for conditions with variants (None where the target ran none), and with
    ``intervals`` ``table2_ci``, ``gain_ci (rows, 2)``, ``per_target_ci`` and
    ``gain_per_target_ci (rows, A, 2)``
    (``intervals.checked_interval``, ``cfg.ci_level``, ``cfg.ci_tail``); ``note``: ``NOT_IN_PAPER``.
    """
    actions = [str(x) for x in res["actions"]]
    a = len(actions)
    conds = [str(c) for c in res["conditions"]]
    g = groups(conds, layout(a, len(cfg.thresholds))["n"])
    out: dict[str, Any] = {"names": [], "condition": [], "best": {}, "best_after_ten": {}, "note": NOT_IN_PAPER,
                           "actions": actions}
    if not g:
        return out
    acc = np.asarray(res["acc"], dtype=float)
    _, correct, n_test = _outcomes(res, acc)
    tol = chance_tolerance(cfg, n_test, a)
    halves = scene_halves(n_test, res["test_positive"] if "test_positive" in res.keys() else None, correct.shape[-1])
    paper = np.isin(np.asarray(actions), ACTIONS)
    per = {"bf": [], "gain": [], "boot_bf": [], "boot_gain": []}
    for name, idx in g.items():
        variants = ":" in conds[idx[0]]
        o = _one(res, cfg, idx, variants, seed, intervals, reference, halves, tol, n_test)
        rows = [f"{name} {r}" for r in VARIANT_ROWS] if variants else [name]
        out["names"] += rows
        out["condition"] += [name] * len(rows)
        per["bf"].append(o["bf"]), per["gain"].append(o["gain"])
        if intervals:
            per["boot_bf"].append(o["boot"]["bf"]), per["boot_gain"].append(o["boot"]["gain"])
        if variants:
            v = [conds[i].partition(":")[2] for i in idx]
            out["best"][name] = {t: (v[i] if i >= 0 else None) for t, i in zip(actions, o["best"])}
            out["best_after_ten"][name] = {t: (v[i] if i >= 0 else None) for t, i in zip(actions, o["ten"])}
    bf, gain = np.concatenate(per["bf"]), np.concatenate(per["gain"])  # (rows, A)
    out["table2_per_target"], out["gain_per_target"] = bf, gain
    out["table2"], out["n_targets"] = summarise(np.where(paper, bf, np.nan))
    out["gain"], out["gain_n_targets"] = summarise(np.where(paper, gain, np.nan))
    if intervals:
        level = cfg.ci_level
        ci = lambda vals, est: interval_pairs(vals, est, level, cfg.ci_tail)  # noqa: E731
        b_bf, b_gain = np.concatenate(per["boot_bf"], 1), np.concatenate(per["boot_gain"], 1)  # (B, rows, A)
        out["table2_ci"] = ci(_fixed_mean(b_bf, np.isfinite(bf) & paper)[0], out["table2"][:, 0])
        out["gain_ci"] = ci(_fixed_mean(b_gain, np.isfinite(gain) & paper)[0], out["gain"][:, 0])
        out["per_target_ci"], out["gain_per_target_ci"] = ci(b_bf, bf), ci(b_gain, gain)
        out["ci_level"] = level
    return out
