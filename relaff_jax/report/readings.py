"""Side by side: the same study in two or more readings (e.g. ``dataset.population=all`` and
``feasible``), from their report folders (``relaff compare``).

Takes ``{name: REPORT_DIR}`` written by ``write_report`` with datasets (``summary.json``,
``findings.json``, ``reach.json``); gives ``compare_readings``, a markdown page: what the
labels consist of per reading (infeasible share of negatives, the oracles), NB by test subset
at one size, PCA against RHF, the source predictors' correlations with feasible and stacked,
the correlation clusters, Table II's rows with their intervals, every finding's verdict, each
affordance's answer in every run (``compare_affordances.py``) and, last, the robustness table: each finding's verdict and intervals in every reading (the reports given
and each report's analysis-only readings) and whether it survives all of them.
Nothing is recomputed: every number is read from the report folders, so the page says what
the reports say.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.learn import TABLE2_ROWS
from relaff_jax.report import compare_affordances as CA
from relaff_jax.report import folder as F
from relaff_jax.report.findings import correlation_clusters
from relaff_jax.config.experiment import AFTER_TEN
from relaff_jax.report.robustness import robustness_table

FILES = F.JSON_FILES


def read_report(path: str | os.PathLike) -> dict[str, Any]:
    """The three JSON files of a report folder; a ``UserError`` naming the missing one."""
    p = Path(path)
    out = {}
    for f in FILES:
        if not (p / f).exists():
            raise UserError(f"{p} is not a report folder with datasets: {f} is missing (relaff report, or a "
                            f"report written by this version with the datasets)")
        out[f.split(".")[0]] = rio.read_json(p / f)
        need = _KEYS.get(f.split(".")[0], ())
        if not isinstance(out[f.split(".")[0]], dict) or not all(k in out[f.split(".")[0]] for k in need):
            raise UserError(f"{p / f}: not a relaff report file (expected a JSON object with {', '.join(need)}); "
                            "write the report again with relaff report")
    return out


_KEYS = {"reach": ("datasets", "spaces"), "findings": ("findings",), "summary": ()}


def _sizes(r: Mapping[str, Any]) -> set:
    return {x for sp in r["reach"]["spaces"].values() for x in sp.get("sizes", [])}


def _f(x: Any, nd: int = 3) -> str:
    return "-" if x is None or not np.isfinite(float(x)) else f"{float(x):.{nd}f}"


def _nb_overall(space: Mapping[str, Any], size: int) -> tuple[list[float], list[list[float]]]:
    """Per target NB accuracy at ``size`` (the subsets weighted by their test counts) and the
    subset accuracies, from ``reach.json``'s space entry."""
    i = space["sizes"].index(size)
    acc = np.array([[np.nan if v is None else v for v in t[i]] for t in space["nb_acc_subset"]], float)  # (T, 3)
    cnt = np.asarray(space["subset_count"], float)
    w = np.where(np.isfinite(acc), cnt, 0.0)
    overall = np.where(w.sum(1) > 0, np.nansum(acc * w, 1) / np.maximum(w.sum(1), 1), np.nan)
    return overall.tolist(), acc.tolist()


def compare(reports: Mapping[str, str | os.PathLike], out: str | os.PathLike | None = None, *,
            size: int = 10) -> str:
    """``relaff compare``'s one call: the page of ``compare_readings``; with ``out``, written
    there atomically (``out`` checked before any report is read). Returns the page."""
    if out is not None:
        rio.check_writable_file(out)
    try:
        page = compare_readings(reports, size=size)
    except (KeyError, TypeError, IndexError, AttributeError) as e:  # a file of the right shape, wrong content
        raise UserError(f"the reports {', '.join(map(str, reports.values()))} hold an entry this version cannot "
                        f"read ({type(e).__name__}: {e}); write them again with relaff report") from e
    if out is not None:
        rio.atomic_write_text(out, page)
    return page


def compare_readings(reports: Mapping[str, str | os.PathLike], size: int = 10, threshold: float = 0.5) -> str:
    """The markdown page comparing the readings ``{name: REPORT_DIR}``."""
    if len(reports) < 2:
        raise UserError("compare needs at least two readings NAME=REPORT_DIR")
    r = {name: read_report(p) for name, p in reports.items()}
    names = list(r)
    for n in names:
        if size not in _sizes(r[n]):
            raise UserError(f"--size {size} is not a training size of {reports[n]} (its sizes: "
                            f"{', '.join(map(str, sorted(_sizes(r[n])))) or 'none'})")
    CA.check({n: r[n]["summary"] for n in names}, reports)
    lines = ["# The same study in " + " and ".join(f"`{n}`" for n in names), ""]
    lines += [f"- `{n}`: `{reports[n]}`" for n in names] + [""]

    # what the labels consist of
    seen = {a for n in names for a in r[n]["reach"]["datasets"]}  # the JSON keys are sorted: the paper's order
    acts = [a for a in ACTIONS if a in seen] + sorted(seen - set(ACTIONS))
    lines += ["## What the labels consist of (balanced selection)", "",
              "| action | " + " | ".join(f"{n}: neg. infeasible / label=feasible / relation / borrowed" for n in names) + " |",
              "|---|" + "---|" * len(names)]
    for a in acts:
        cells = []
        for n in names:
            d = r[n]["reach"]["datasets"].get(a)
            cells.append("-" if d is None else
                         f"{_f(d['negatives_infeasible_share'], 2)} / {_f(d['oracle_feasible_acc'])} / "
                         f"{_f(d['oracle_relation_acc'])} / {_f(d['borrowed_share'], 2)}"
                         + ("" if d["matching_met"] is not False else " (not met)"))
        lines.append(f"| {a} | " + " | ".join(cells) + " |")

    # NB by space and subset
    lines += ["", f"## NB at n = {size}: PCA against RHF, and by test subset", "",
              "Accuracy on the whole test set, then on its positives / feasible negatives / infeasible negatives "
              "(mean over repetitions; '-' where a subset is empty).", ""]
    spaces = [s for s in ("pca", "rhf") if all(s in r[n]["reach"]["spaces"] for n in names)]
    head = [f"{n} {s.upper()}" for n in names for s in spaces]
    lines += ["| target | " + " | ".join(head) + " |", "|---|" + "---|" * len(head)]
    tabs = {(n, s): _nb_overall(r[n]["reach"]["spaces"][s], size) for n in names for s in spaces
            if size in r[n]["reach"]["spaces"][s]["sizes"]}
    targets = r[names[0]]["reach"]["spaces"][spaces[0]]["actions"] if spaces else []
    means = {k: float(np.nanmean(v[0])) for k, v in tabs.items()}
    for ti, t in enumerate(targets):
        cells = []
        for n in names:
            for s in spaces:
                if (n, s) not in tabs:
                    cells.append("-")
                    continue
                ov, sub = tabs[(n, s)]
                cells.append(f"{_f(ov[ti])} ({' / '.join(_f(v, 2) for v in sub[ti])})")
        lines.append(f"| {t} | " + " | ".join(cells) + " |")
    lines.append("| mean | " + " | ".join(_f(means.get((n, s))) for n in names for s in spaces) + " |")

    # predictors
    lines += ["", "## What each source predictor follows: r(feasible) / r(stacked) on the correlation scenes", "",
              "| predictor | " + " | ".join(f"{n} {s.upper()}" for n in names for s in spaces) + " |",
              "|---|" + "---|" * (len(names) * len(spaces))]
    for ti, t in enumerate(targets):
        cells = [f"{_f(r[n]['reach']['spaces'][s]['corr_feasible'][ti], 2)} / {_f(r[n]['reach']['spaces'][s]['corr_stacked'][ti], 2)}"
                 for n in names for s in spaces]
        lines.append(f"| {t} | " + " | ".join(cells) + " |")

    # clusters
    lines += ["", f"## Correlation clusters (linked above T = {threshold:g})", ""]
    for n in names:
        for s in spaces:
            x = r[n]["summary"][s]
            cl = correlation_clusters(np.asarray(x["corr"], float), x["actions"], threshold)
            lines.append(f"- {n} {s.upper()}: " + "; ".join("{" + ", ".join(g) + "}" for g in cl))

    # Table II
    lines += ["", "## Table II (average bootstrap factor over the window, avg over affordances, interval, rests on)", ""]
    rows = list(r[names[0]]["summary"]["pca"]["table2"]) if "pca" in r[names[0]]["summary"] else []
    rows = [x for x in TABLE2_ROWS if x in rows] + [x for x in rows if x not in TABLE2_ROWS]  # the paper's order
    lines += ["| row | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for row in rows:
        cells = []
        for n in names:
            v = r[n]["summary"]["pca"]["table2"].get(row, {})
            ci = v.get("ci")
            ci_s = f" [{_f(ci[0], 2)}, {_f(ci[1], 2)}]" if ci and None not in ci[:2] else ""
            cells.append(f"{_f(v.get('avg'))}{ci_s} ({v.get('n_targets', '-')})")
        lines.append(f"| {row} | " + " | ".join(cells) + " |")

    # findings
    lines += ["", "## Findings", "", "| finding | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    found = {n: {f["id"]: f for f in r[n]["findings"]["findings"]} for n in names}
    for fid, f in found[names[0]].items():
        cells = []
        for n in names:
            g = found[n].get(fid)
            if g is None:
                cells.append("-")
                continue
            verdict = g.get("verdict") or {True: "reproduced", False: "not reproduced", None: "not measurable"}[g["reproduced"]]
            cells.append(f"**{verdict}**: {g['numbers']}")
        lines.append(f"| {f['finding']} | " + " | ".join(cells) + " |")

    lines += [""] + CA.lines({n: r[n]["summary"] for n in names})[:-1]

    # robustness: every finding in every reading, the analysis-only ones of each report included
    every = {}
    for n in names:
        own = r[n]["findings"].get("readings") or {"": r[n]["findings"]["findings"]}
        order = [f"after_ten={x}" for x in AFTER_TEN]  # the default reading first (JSON sorts the keys)
        for k in sorted(own, key=lambda k: order.index(k) if k in order else len(order)):
            every[f"{n} {k}".strip()] = own[k]
    header, rows = robustness_table(every)
    lines += ["", "## Robustness: each finding in every reading", "",
              "Verdict, then each claim's estimate [interval]; the readings are the reports given and, within each, "
              "the analysis-only readings of its results (after_ten=whole / causal). A finding reproduced in only "
              "some readings is a finding about the reading.", "",
              "| " + " | ".join(header) + " |", "|---|" + "---|" * (len(header) - 1)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def affordance_verdicts(reports: Mapping[str, str | os.PathLike]) -> list[str]:
    """The terminal's lines of each affordance's verdict in every run (``compare_affordances.verdict_lines``)."""
    return CA.verdict_lines({n: read_report(p)["summary"] for n, p in reports.items()})
