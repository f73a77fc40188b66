"""The user's conditions in the report, beside Table II's rows and marked "not in the paper".

Takes one space's analysis with its ``user`` entry (``learn.user_rows.user_rows``: rows
``NAME`` or ``NAME average`` / ``NAME best`` / ``NAME best after ten``, avg/min/max of the
average bootstrap factor over the paper's targets, the gain, intervals, per target values and
the chosen variants) and gives the rows of ``table2.csv`` (``csv_rows``), of ``table2.md``
(``markdown_rows``, ``per_target_rows``, ``source_lines``), of ``summary.json``
(``summary``) and the report's (``table_rows``, ``note``). Nothing when no user condition ran.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from relaff_jax.learn.user_rows import NOT_IN_PAPER
from relaff_jax.report.formatting import fmt, interval


def rows_of(a: Mapping[str, Any]) -> Mapping[str, Any]:
    """The analysis' user rows (an empty mapping without them)."""
    u = a.get("user") or {}
    return u if u.get("names") else {}


def _ci(u: Mapping[str, Any], key: str, i: int, nd: int = 3) -> str:
    return interval(*u[key][i], nd) if key in u else "-"


def label(name: str) -> str:
    return f"{name} ({NOT_IN_PAPER})"


def cells(u: Mapping[str, Any], i: int, n_paper: int) -> list[str]:
    """avg, min, max, n, interval of avg, gain, interval of gain of user row ``i``."""
    row = u["table2"][i]
    vals = ([fmt(v) for v in row] if np.isfinite(row[0]) else
            ["not measurable: no paper affordance has a bootstrap factor (or the condition did not run)", "-", "-"])
    return vals + [f"{int(u['n_targets'][i])} of {n_paper}", _ci(u, "table2_ci", i), fmt(u["gain"][i, 0]),
                   _ci(u, "gain_ci", i)]


def csv_rows(a: Mapping[str, Any]) -> list[list[str]]:
    """``table2.csv`` rows (its columns; no paper numbers) of the user rows."""
    u = rows_of(a)
    nan2 = np.full((len(u.get("names", ())), 2), np.nan)
    out = []
    for i, name in enumerate(u.get("names", ())):
        ci, gci = u.get("table2_ci", nan2)[i], u.get("gain_ci", nan2)[i]
        out.append([name] + [fmt(v, 4) for v in u["table2"][i]] + [fmt(np.nan, 4)] * 3 + [int(u["n_targets"][i])]
                   + [fmt(v, 4) for v in ci] + [fmt(u["gain"][i, 0], 4)] + [fmt(v, 4) for v in gci]
                   + ["" if np.isfinite(u["table2"][i, 0]) else NOT_IN_PAPER + "; no paper affordance has a value"])
    return out


def markdown_rows(a: Mapping[str, Any], n_paper: int, paper: bool) -> list[str]:
    """Markdown rows of Table II's table (``paper``: its three paper columns, empty here)."""
    return ["| " + " | ".join(r) + " |" for r in table_rows(a, n_paper, paper)]


def per_target_rows(a: Mapping[str, Any]) -> list[list[str]]:
    """Rows ``[label, value per target...]`` of the per-affordance bootstrap factors."""
    u = rows_of(a)
    return [[label(name)] + [fmt(v, 2) for v in row]
            for name, row in zip(u.get("names", ()), u.get("table2_per_target", ())) if np.any(np.isfinite(row))]


def source_lines(a: Mapping[str, Any]) -> list[str]:
    """"NAME best: target <- (variant), ..." lines of the conditions with variants."""
    u = rows_of(a)
    out = []
    for key, what in (("best", "best"), ("best_after_ten", "best after ten")):
        for name, chosen in u.get(key, {}).items():
            out.append(f"- {name} {what} ({NOT_IN_PAPER}): "
                       + ", ".join(f"{t} <- ({v})" for t, v in chosen.items() if v is not None))
    return out


def summary(a: Mapping[str, Any]) -> dict[str, Any]:
    """``summary.json``'s ``user_conditions`` of one space: per row avg/min/max, n_targets,
    intervals, gain and per affordance values; the chosen variants."""
    u = rows_of(a)
    if not u:
        return {}
    acts = u["actions"]
    rows = {}
    for i, name in enumerate(u["names"]):
        rows[name] = dict(zip(("avg", "min", "max"), u["table2"][i]), n_targets=int(u["n_targets"][i]),
                          condition=u["condition"][i], ci=list(u["table2_ci"][i]) if "table2_ci" in u else None,
                          gain=float(u["gain"][i, 0]), gain_ci=list(u["gain_ci"][i]) if "gain_ci" in u else None,
                          per_affordance=dict(zip(acts, u["table2_per_target"][i])),
                          per_affordance_ci=(dict(zip(acts, (list(v) for v in u["per_target_ci"][i])))
                                             if "per_target_ci" in u else None),
                          gain_per_affordance=dict(zip(acts, u["gain_per_target"][i])))
    return {"note": NOT_IN_PAPER, "rows": rows, "best": u["best"], "best_after_ten": u["best_after_ten"]}


def table_rows(a: Mapping[str, Any], n_paper: int, paper: bool) -> list[list[str]]:
    """The report's Table II rows of the user rows (``paper``: its three paper columns, empty)."""
    u = rows_of(a)
    return [[label(name)] + cells(u, i, n_paper) + (["-"] * 3 if paper else []) for i, name in enumerate(u.get("names", ()))]


def note(a: Mapping[str, Any]) -> list[tuple]:
    """The report's paragraph on the user rows (nothing without them): what they are, and the
    chosen variants."""
    u = rows_of(a)
    if not u:
        return []
    src = source_lines(a)
    return [("p", f"Rows marked '{NOT_IN_PAPER}' are conditions a user registered (docs/extending.md, \"Conditions\"): "
                  "each against NB by the code of the paper's DB1 rows, one learner giving its row, variants their "
                  "average, 'best' and 'best after ten' (chosen on one half of each test set, scored on the other); "
                  "the same window, rule, affordances and resamples as Table II."
                  + (" Chosen variants (target <- variant, on the whole test set): " + "; ".join(x[2:] for x in src) + "."
                     if src else ""))]
