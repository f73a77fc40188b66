"""Per affordance: does what the robot knows help it? The report's table, CSV and JSON.

Takes the analysis ``{space: analyse(...)}`` (its ``affordances`` entry, ``learn.per_target``:
per target the DB1 average and best bootstrap factors, the best source, the gain of DB1 best
over NB in the window and the samples it saves, each with its interval, and a verdict from
the gain's interval) and the config; gives the report's blocks (``blocks``), the rows of
``affordances.csv`` (``csv_text``: columns ``CSV_COLUMNS``, one row per space and affordance)
and ``summary.json``'s ``affordances`` of one space (``summary``). A user action's row is
labelled "not in the paper"; none of these values enters a mean beside a paper number.
"""
from __future__ import annotations

import csv
import io
from typing import Any, Mapping

import numpy as np

from relaff_jax.learn.user_rows import NOT_IN_PAPER
from relaff_jax.report.formatting import fmt, interval, span

CSV_COLUMNS = ("space", "affordance", "in_paper", "bf_average", "bf_average_ci_low", "bf_average_ci_high", "bf_best",
               "bf_best_ci_low", "bf_best_ci_high", "best_source", "best_source_share", "gain", "gain_ci_low",
               "gain_ci_high", "samples_saved", "samples_saved_ci_low", "samples_saved_ci_high", "samples_saved_censored",
               "verdict")
_MEASURES = ("bf_average", "bf_best", "gain", "saved")


def _source(name: str | None) -> str:
    """A DB1 condition name ``DB1:SOURCE`` as ``SOURCE``; "-" where none ran."""
    return "-" if name is None else str(name).partition(":")[2] or str(name)


def label(target: str, in_paper: bool) -> str:
    return target if in_paper else f"{target} ({NOT_IN_PAPER})"


def table(x: Mapping[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of one space's per-affordance table (paper's affordances first, in run order)."""
    f = x["affordances"]
    header = ["affordance", "DB1 average bf", f"{f['best_row']} bf", "best source (share of resamples)",
              "gain over NB", "samples saved", "verdict"]
    rows = []
    order = [i for i, p in enumerate(f["in_paper"]) if p] + [i for i, p in enumerate(f["in_paper"]) if not p]
    for i in order:
        cell = lambda key, nd: fmt(f[key][i], nd) + _ci(f[f"{key}_ci"][i], nd)  # noqa: E731
        share = f["source_share"][i]
        saved = cell("saved", 1) + (" (censored: a lower bound)" if f["saved_censored"][i] else "")
        rows.append([label(f["actions"][i], f["in_paper"][i]), cell("bf_average", 2), cell("bf_best", 2),
                     _source(f["source"][i]) + (f" ({100 * share:.0f} %)" if np.isfinite(share) else ""),
                     cell("gain", 3), saved, f"**{f['verdict'][i]}**"])
    return header, rows


def markdown_lines(x: Mapping[str, Any]) -> list[str]:
    """``table2.md``'s lines of one space's per-affordance table (none without it)."""
    if "affordances" not in x:
        return []
    header, rows = table(x)
    return ["| " + " | ".join(r) + " |" for r in [header, ["---"] * len(header)] + rows]


def _ci(lohi, nd: int) -> str:
    text = interval(lohi[0], lohi[1], nd)
    return "" if text == "-" else " " + text


def blocks(an: Mapping[str, Mapping[str, Any]], cfg: Any) -> list[tuple]:
    """The report's section: per space the table and what each figure rests on."""
    out: list[tuple] = [("h", 2, "Per affordance: does what the robot knows help it?")]
    for space, x in an.items():
        if "affordances" not in x:
            continue
        f = x["affordances"]
        lo, hi = cfg.bf_sizes
        level = f"{100 * float(f['level']):g} %" if f.get("level") is not None else None
        users = [t for t, p in zip(f["actions"], f["in_paper"]) if not p]
        text = (f"{space.upper()}: for each affordance, whether the learner given one other action's predicted output "
                f"(DB1) learns it faster than NB. Bootstrap factors: Table II's 'DB1 average' and '{f['best_row']}' "
                f"rows for this affordance alone, averaged over the sizes n = {span(x['sizes'], lo, hi)} where NB is "
                f"above chance. Best source: the DB1 source with the highest mean accuracy over "
                f"n = {span(x['sizes'], *cfg.best_sizes)} on the whole test set, and the share of resamples whose "
                f"choice is the same. Gain: '{f['best_row']}' minus NB in accuracy, averaged over the same window. "
                f"Samples saved: the training samples NB needs to reach the accuracy of '{f['best_row']}' (the same "
                f"choice as its bf and gain) at n = {cfg.select_size}, minus {cfg.select_size} (censored: NB never gets "
                "there within the sizes run). "
                f"Each value rests on this affordance's {x['reps']} repetitions and test scenes; "
                + (f"its {level} bias-corrected interval comes from Table II's {x['ci_resamples']} resamples (the same "
                   "draws: a value's interval here is its interval in Table II's per-affordance values). Verdict, from "
                   "the gain's interval: 'helps' if it lies above 0, 'hurts' if below, 'no evidence' if it holds 0."
                   if level else "no intervals were computed, so no verdict (not measurable).")
                + (f" {', '.join(users)}: {NOT_IN_PAPER} (a user action); its row enters none of the means shown "
                   "beside the paper's numbers." if users else ""))
        header, rows = table(x)
        out += [("p", text), ("table", header, rows)]
    return out if len(out) > 1 else []


def csv_text(an: Mapping[str, Mapping[str, Any]]) -> str:
    """``affordances.csv``: one row per space and affordance (``CSV_COLUMNS``; "-" where undefined)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for space, x in an.items():
        f = x.get("affordances")
        for i, t in enumerate(f["actions"] if f else ()):
            share = f["source_share"][i]
            vals = []
            for key in _MEASURES:
                vals += [fmt(f[key][i], 4), fmt(f[f"{key}_ci"][i][0], 4), fmt(f[f"{key}_ci"][i][1], 4)]
                if key == "bf_best":
                    vals += [_source(f["source"][i]), fmt(share, 4)]
            w.writerow([space, t, "yes" if f["in_paper"][i] else "no"] + vals
                       + ["yes" if f["saved_censored"][i] else "no", f["verdict"][i]])
    return buf.getvalue()


def summary(x: Mapping[str, Any]) -> dict[str, Any]:
    """``summary.json``'s ``affordances`` of one space: ``{target: {in_paper, bf_average,
    bf_average_ci, bf_best, bf_best_ci, best_source, best_source_share, gain, gain_ci,
    samples_saved, samples_saved_ci, samples_saved_censored, verdict}}`` with ``best_row``,
    ``samples_saved_method`` and ``ci_level``; empty without it."""
    f = x.get("affordances")
    if not f:
        return {}
    rows = {}
    for i, t in enumerate(f["actions"]):
        rows[t] = {"in_paper": f["in_paper"][i], "note": None if f["in_paper"][i] else NOT_IN_PAPER,
                   "bf_average": f["bf_average"][i], "bf_average_ci": list(f["bf_average_ci"][i]),
                   "bf_best": f["bf_best"][i], "bf_best_ci": list(f["bf_best_ci"][i]),
                   "best_source": _source(f["source"][i]) if f["source"][i] else None,
                   "best_source_share": f["source_share"][i], "gain": f["gain"][i], "gain_ci": list(f["gain_ci"][i]),
                   "samples_saved": f["saved"][i], "samples_saved_ci": list(f["saved_ci"][i]),
                   "samples_saved_censored": bool(f["saved_censored"][i]), "verdict": f["verdict"][i]}
    return {"best_row": f["best_row"], "samples_saved_method": f["saved_method"], "ci_level": f["level"], "rows": rows}
