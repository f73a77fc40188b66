"""Number formatting shared by the report's tables, findings and document.

``fmt`` (a float as text, ``-`` for undefined), ``interval``, ``finite`` (a JSON-ready copy with NaN as
None), ``curve_average`` (a bootstrap factor curve ``(S,)`` averaged over the config's bf
interval), ``nanmean`` (mean of the finite values), ``ci_text`` (an interval as
``[lo, hi]``), ``rests_on`` (what a Table II rests on: affordances, sizes, repetitions, test
scenes, how the intervals were made), ``paper_basis`` (the same for a block of means) and
``SHORT`` (short action names).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from relaff_jax.learn import average_bf, TABLE2_ROWS

SHORT = {"unobstruct": "unob"}


def fmt(x: float, nd: int = 3) -> str:
    """``x`` with ``nd`` decimals; "-" where it is undefined (None, NaN): a cell that was not
    measured reads as absent, never as the word ``nan``."""
    return "-" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def interval(lo: float, hi: float, nd: int = 3) -> str:
    """An interval as ``[lo, hi]``; "-" when neither end is defined (no interval)."""
    if (lo is None or not np.isfinite(lo)) and (hi is None or not np.isfinite(hi)):
        return "-"
    return f"[{fmt(lo, nd)}, {fmt(hi, nd)}]"


def rows_run(cfg: Any, space: str) -> list[int]:
    """Indices of the Table II rows whose condition family the space ran (RHF: NB and DB1)."""
    return [i for i, name in enumerate(TABLE2_ROWS) if name.split()[0] in cfg.conditions(space)]


def ci_text(a: Any, key: str, i: int, nd: int = 3) -> str:
    """Row ``i`` of the interval ``a[key] (rows, 2)`` as ``[lo, hi]``, ``-`` if not computed."""
    if key not in a:
        return "-"
    lo, hi = a[key][i]
    return interval(lo, hi, nd)


def row_cells(a: Any, i: int, nd: int = 3) -> list[str]:
    """avg / min / max of Table II row ``i`` as text; a row without a single target reads
    "not measurable: <reason>" (``analyse``'s ``unmeasurable``), never a number."""
    why = (a.get("unmeasurable") or {}).get(TABLE2_ROWS[i])
    if why:
        return [f"not measurable: {why}", "-", "-"]
    return [fmt(v, nd) for v in a["table2"][i]]


def span(sizes: Sequence[int], lo: int, hi: int) -> str:
    """The sizes of ``lo..hi`` that ran, as ``a..b`` (what a window really covered)."""
    ran = [int(n) for n in sizes if lo <= n <= hi]
    return f"{ran[0]}..{ran[-1]}" if ran else "none"


def rests_on(a: Any, cfg: Any) -> str:
    """One sentence: what the Table II of analysis ``a`` rests on."""
    lo, hi = cfg.bf_sizes
    ran = [n for n in a["sizes"] if lo <= n <= hi]
    tests = a.get("test_size")
    pos = a.get("test_positive")
    t = (f"; test scenes per affordance {min(tests)}-{max(tests)}" + (f" ({min(pos)}-{max(pos)} positive)" if pos is not None else "")
         if tests is not None else "")
    held = a.get("table2_set_held")
    ci = (f" Intervals: {100 * a['ci_level']:.0f} % bias-corrected (BC) bootstrap, {a['ci_resamples']} resamples of the repetitions"
          + (" and of each affordance's test scenes (within each half of its test set)" if a["outcomes"] else
             " (test scenes not resampled: outcomes not kept)")
          + (f"; the percentile interval where a BC end would leave less than {100 * a['ci_tail']:g} % of the resamples "
             f"beyond it ({a['ci_bc_count'][1] - a['ci_bc_count'][0]} of the {a['ci_bc_count'][1]} intervals of this analysis)"
             if a.get("ci_tail") else "")
          + "; a row's average in a resample is over the affordances of its estimate only"
          + (f" (all of them had a value in {100 * np.nanmin(held):.0f}-{100 * np.nanmax(held):.0f} % of the resamples, by row)"
             if held is not None and np.any(np.isfinite(held)) else "") + "."
          if "ci_level" in a else " No intervals computed.")
    tol = a.get("tol")
    rule = (f" bf(n) is undefined where NB is at most {cfg.chance_tol_scenes:g} test scene above chance "
            f"(so |bf| <= {int(round(float(np.max(0.5 / tol))))} here, the largest test set); an affordance enters a bf row only with bf defined at "
            f">= {a['min_defined']} of the window's {a['window_sizes']} sizes."
            if tol is not None and "min_defined" in a else "")
    n = [int(v) for v, row in zip(a["n_targets"], a["table2"]) if np.isfinite(row[0])] if "n_targets" in a else []
    rows_n = f"{min(n)}-{max(n)}" if n and min(n) != max(n) else (str(n[0]) if n else "none")
    paper = np.asarray(a.get("paper", [True] * len(a["actions"])), bool)
    users = [t for t, p in zip(a["actions"], paper) if not p]
    who = f"{int(paper.sum())} affordances" + (f" (the paper's; {', '.join(users)}: not in the paper, left out)" if users else "")
    return (f"Rests on {rows_n} of {who}, by row (column n); {len(ran)} of the {hi - lo + 1} sizes n = {lo}..{hi} run "
            f"({', '.join(map(str, ran)) if len(ran) <= 6 else f'{ran[0]}..{ran[-1]}'}); {a['reps']} repetitions{t}. "
            "avg/min/max are over the affordances with a value (n); a bootstrap factor is averaged over the sizes "
            "where it is defined (NB above chance); the gain is the mean accuracy difference to NB over the same window."
            + rule + ci)


def paper_basis(a: Any, cfg: Any) -> str:
    """One sentence: a block of means (the methods against NB) rests on the paper's affordances
    of analysis ``a`` only, its repetitions, window and intervals; a user action is elsewhere."""
    paper = np.asarray(a.get("paper", [True] * len(a["actions"])), bool)
    users = [t for t, p in zip(a["actions"], paper) if not p]
    return (f"Every column rests on the paper's affordances only ({int(paper.sum())} of {len(paper)}; {a['reps']} "
            f"repetitions; sizes n = {span(a['sizes'], *cfg.bf_sizes)}"
            + (f"; {100 * float(a['ci_level']):g} % intervals from {a['ci_resamples']} resamples" if "ci_level" in a else "")
            + ")" + (f"; {', '.join(users)} (not in the paper): its own row in 'Per affordance: does what the "
                     "robot knows help it?'" if users else "") + ".")


def curve_average(curve: np.ndarray, sizes: Sequence[int], cfg: Any) -> float:
    """Average of a bootstrap factor curve over ``cfg.bf_sizes`` (paper V-C)."""
    return float(average_bf(np.asarray(curve), sizes, *cfg.bf_sizes))


def nanmean(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.mean(x[np.isfinite(x)])) if np.any(np.isfinite(x)) else float("nan")


def finite(obj):
    """JSON has no NaN: turn non-finite floats into None."""
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
