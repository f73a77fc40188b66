"""Per affordance: does what the robot knows (its other predictors, DB1) help this one?

Takes one space's analysis (``analysis.analyse``) and, inside its resampling loop, each chunk
of resampled mean curves; gives per target, for the paper's nine and any user action alike:

* ``bf_average`` / ``bf_best``: Table II's "DB1 average" and "DB1 best" average bootstrap
  factors (``best_row``: the held-out "DB1 best", or its in-sample oracle where the run kept
  no test outcomes and has no halves to choose on);
* ``source``: the in-sample best DB1 source (``analyse``'s ``best_db1``) and ``source_share``
  the share of resamples whose in-sample choice is the same source;
* ``gain``: the mean accuracy gain of ``best_row`` over NB in the window, and ``verdict`` from
  its interval (``verdict``);
* ``saved``: the samples ``best_row``'s learner saves at ``select_size`` (the methods-against-NB
  block's "DB1 best", ``gains.samples_saved``, on the same held-out choice as ``bf_best`` and
  ``gain``: ``heldout.py``; ``saved_censored`` where NB never reaches it: a lower bound);

each with its bias-corrected interval from Table II's resamples (``resampled`` collects the
values of a chunk, ``intervals`` turns them into intervals: no second resampling scheme, so a
target's interval here is the one of Table II's per target values). ``in_paper`` marks the
paper's nine: a user action's row is "not in the paper" and enters no mean.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from relaff_jax.learn.intervals import interval_pairs
from relaff_jax.learn.table2 import ORACLE, TABLE2_ROWS

BOOT = ("gain_per", "area_per", "saved_per", "choice")  # what each chunk of resamples gives
VERDICTS = ("helps", "no evidence", "hurts", "not measurable")
SAVED_METHOD = "DB1 best"  # gains.METHODS: the best source's whole curve, held-out as best_row (or its oracle)


def resampled(t2: Mapping[str, np.ndarray], st: Mapping[str, np.ndarray], choice: np.ndarray) -> dict[str, np.ndarray]:
    """One chunk of b resamples: Table II's per target gains ``t2["gain"] (b, rows, A)``, the
    methods' per target area and samples saved ``(b, M, A)`` (``gains.curve_stats``) and the
    in-sample best DB1 source ``choice (b, A)`` (condition indices)."""
    return {"gain_per": t2["gain"], "area_per": st["area_per_target"], "saved_per": st["saved_per_target"],
            "choice": np.asarray(choice)}


def intervals(bt: Mapping[str, np.ndarray], pt: dict[str, Any], level: float, tail: float = 0.0,
              tally: list | None = None) -> dict[str, Any]:
    """From all resamples ``bt`` (``BOOT`` keys, concatenated over chunks) and the point
    estimates ``pt``: ``gain_per_target_ci (rows, A, 2)``, ``best_db1_share (A,)`` (NaN
    where no DB1 source ran for the target), and in ``pt["methods"]`` ``area_per_target_ci``
    and ``saved_per_target_ci (M, A, 2)``; ``tail``, ``tally``: ``intervals.interval_pairs``."""
    ci = lambda vals, est: interval_pairs(vals, est, level, tail, tally)  # noqa: E731
    meth = pt["methods"]
    meth["area_per_target_ci"] = ci(bt["area_per"], meth["area_per_target"])
    meth["saved_per_target_ci"] = ci(bt["saved_per"], meth["saved_per_target"])
    share = (np.asarray(bt["choice"]) == np.asarray(pt["best_db1"])[None]).mean(0)
    return {"gain_per_target_ci": ci(bt["gain_per"], pt["gain_per_target"]),
            "best_db1_share": np.where(_source_ran(pt), share, np.nan)}


def _source_ran(a: Mapping[str, Any]) -> np.ndarray:
    """``(A,)``: the in-sample best DB1 source of each target ran (no DB1 source ran: False)."""
    return np.array([np.isfinite(a["mean"][t, c]).any() for t, c in enumerate(a["best_db1"])], bool)


def verdict(lo: float, hi: float) -> str:
    """"helps" (the interval of the gain above 0), "hurts" (below 0), "no evidence" (it holds
    0), "not measurable" (no interval)."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "not measurable"
    return "helps" if lo > 0 else "hurts" if hi < 0 else "no evidence"


def answers(a: Mapping[str, Any]) -> dict[str, Any]:
    """Per target of analysis ``a`` (lists over ``a["actions"]``): ``in_paper``,
    ``bf_average``, ``bf_best``, ``gain``, ``saved`` with ``*_ci`` ``[low, high]`` (NaN
    without intervals), ``saved_censored``, ``source`` (a condition name, None where no DB1
    source ran), ``source_share``, ``verdict``; and ``best_row``, ``saved_method``, ``level``."""
    acts = [str(t) for t in a["actions"]]
    n = len(acts)
    best_row = "DB1 best" if a["outcomes"] else "DB1 best" + ORACLE
    i_avg, i_best = TABLE2_ROWS.index("DB1 average"), TABLE2_ROWS.index(best_row)
    m = a["methods"]
    k = [str(x).replace(ORACLE, "") for x in m["names"]].index(SAVED_METHOD)  # held-out, or its oracle
    nan2 = np.full((n, 2), np.nan)

    def ci(src: Mapping[str, Any], key: str, i: int) -> np.ndarray:
        return np.asarray(src[key][i]) if key in src else nan2

    gain_ci = ci(a, "gain_per_target_ci", i_best)
    ran = _source_ran(a)
    share = a.get("best_db1_share", np.full(n, np.nan))
    return {"actions": acts, "in_paper": [bool(p) for p in a["paper"]], "best_row": best_row,
            "saved_method": m["names"][k], "level": a.get("ci_level"),
            "bf_average": a["table2_per_target"][i_avg], "bf_average_ci": ci(a, "per_target_ci", i_avg),
            "bf_best": a["table2_per_target"][i_best], "bf_best_ci": ci(a, "per_target_ci", i_best),
            "gain": a["gain_per_target"][i_best], "gain_ci": gain_ci,
            "saved": m["saved_per_target"][k], "saved_ci": ci(m, "saved_per_target_ci", k),
            "saved_censored": np.asarray(m["censored_per_target"][k], bool),
            "source": [a["conditions"][c] if r else None for c, r in zip(a["best_db1"], ran)],
            "source_share": np.asarray(share, float), "verdict": [verdict(lo, hi) for lo, hi in gain_ci]}
