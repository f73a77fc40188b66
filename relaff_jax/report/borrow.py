"""What one source can lend each affordance: why the DB1 bootstrap factor splits the actions.

DB1 adds one other action's predicted output to the state. It can only help where that output
says something about the target's label, so per affordance this puts the DB1 average
bootstrap factor (with its interval) beside the strongest correlation of the target's
predictor with another action's (``corr (A, A)``, the Fig. 11 matrix), which action that is,
the correlation of the target's predictor with "stacked" (on top or inside: the relation) and
NB's accuracy at both ends of the window (how much room there was to help). The rank
correlation over the affordances (Spearman, ties averaged) says how far the first column
orders the second. ``borrow_rows`` gives the numbers, ``borrow_blocks`` the report blocks.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from relaff_jax.learn import TABLE2_ROWS, layout
from relaff_jax.report.formatting import SHORT, fmt, interval

ROW = "DB1 average"


def ranks(x: np.ndarray) -> np.ndarray:
    """``(N,)`` -> ``(N,)`` float ranks from 1, tied values sharing their mean rank."""
    x = np.asarray(x, dtype=float)
    order = np.argsort(x, kind="stable")
    r = np.empty(len(x))
    r[order] = np.arange(1, len(x) + 1)
    for v in np.unique(x):
        tie = x == v
        r[tie] = r[tie].mean()
    return r


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of the pairs where both are finite (NaN under 3 pairs)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return float("nan")
    rx, ry = ranks(x[ok]), ranks(y[ok])
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def borrow_rows(res_space: Mapping[str, Any], a: Mapping[str, Any], cfg: Any) -> dict[str, Any]:
    """Per affordance of one space: ``db1_avg (A,)`` and ``db1_ci (A, 2)``, ``best_corr (A,)``
    (largest |corr| with another action's predictor, signed) and ``best_with`` its action,
    ``corr_stacked (A,)``, ``nb_lo``/``nb_hi (A,)`` NB's mean accuracy at the window's first
    and last size that ran, and ``spearman`` of |best_corr| against ``db1_avg``."""
    acts = list(a["actions"])
    i = TABLE2_ROWS.index(ROW)
    db1 = np.asarray(a["table2_per_target"][i], dtype=float)
    ci = np.asarray(a["per_target_ci"][i], dtype=float) if "per_target_ci" in a else np.full((len(acts), 2), np.nan)
    corr = np.asarray(res_space["corr"], dtype=float)
    off = np.where(np.eye(len(acts), dtype=bool), np.nan, np.abs(corr))
    j = np.nanargmax(np.nan_to_num(off, nan=-1.0), axis=1)
    best = corr[np.arange(len(acts)), j]
    sizes = np.asarray(a["sizes"])
    win = np.flatnonzero((sizes >= cfg.bf_sizes[0]) & (sizes <= cfg.bf_sizes[1]))
    nb = np.asarray(a["mean"])[:, layout(len(acts), len(cfg.thresholds))["NB"]]  # (A, S)
    stacked = np.asarray(res_space.get("corr_stacked", np.full(len(acts), np.nan)), dtype=float)
    return {"actions": acts, "db1_avg": db1, "db1_ci": ci, "best_corr": best, "best_with": [acts[k] for k in j],
            "corr_stacked": stacked, "nb_sizes": [int(sizes[win[0]]), int(sizes[win[-1]])],
            "nb_lo": nb[:, win[0]], "nb_hi": nb[:, win[-1]], "spearman": spearman(np.abs(best), db1)}


def borrow_blocks(rows: Mapping[str, Any], space: str) -> list[tuple]:
    """The report's table of ``borrow_rows`` and the sentence with the rank correlation."""
    lo, hi = rows["nb_sizes"]
    header = ["affordance", f"{ROW} bf", "interval", "strongest corr with another predictor", "corr with stacked",
              f"NB at n = {lo}", f"NB at n = {hi}"]
    table = []
    for k, t in enumerate(rows["actions"]):
        c_lo, c_hi = rows["db1_ci"][k]
        table.append([t, fmt(rows["db1_avg"][k], 2), interval(c_lo, c_hi, 2),
                      f"{rows['best_corr'][k]:+.2f} ({SHORT.get(rows['best_with'][k], rows['best_with'][k])})",
                      "-" if not np.isfinite(rows["corr_stacked"][k]) else f"{rows['corr_stacked'][k]:+.2f}",
                      fmt(rows["nb_lo"][k]), fmt(rows["nb_hi"][k])])
    n = int(np.isfinite(rows["db1_avg"]).sum())
    text = (f"What one source can lend ({space.upper()}): DB1 adds another action's predicted output to the state, "
            "so it can only help an affordance whose label that output predicts. Per affordance: the DB1 average "
            "bootstrap factor and its interval, the strongest correlation of its predictor with another action's "
            "(Fig. 11) and the correlation with 'stacked' (on top or inside), and NB's accuracy at the window's ends. "
            f"Rank correlation of |strongest corr| with the DB1 average over the {n} affordances with a value: "
            f"Spearman {fmt(rows['spearman'], 2)}.")
    return [("p", text), ("table", header, table)]
