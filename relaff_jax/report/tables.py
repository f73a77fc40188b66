"""Table II and the numbers beside it, as text: ``table2.csv``, ``table2.md``, ``summary.json``.

Takes the experiment (``load_results``) and its analysis ``{space: analyse(...)}``; gives the
CSV of Table II (``table2_csv``: columns ``method, avg, min, max, paper_avg, paper_min,
paper_max, n_targets, ci_low, ci_high, gain_avg, gain_ci_low, gain_ci_high``: ``n_targets``
affordances have a value in the row (avg/min/max are over them), ``ci_*`` the bias-corrected bootstrap
interval of ``avg``, ``gain_*`` the mean accuracy gain over the window and its interval,
``not_measurable`` why a row has no value (empty where it has one); no
paper numbers for RHF, the paper has no RHF table, nor for the online rows), the Markdown
tables (``table2_markdown``) and the ``summary.json`` dict (``summary``).
"""
from __future__ import annotations

import csv
import io
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.learn import PAPER_TABLE2, TABLE2_ROWS, categories_per_threshold, layout, paper_row
from relaff_jax.report import affordances as A
from relaff_jax.report import user as U
from relaff_jax.report.formatting import (
    SHORT,
    ci_text,
    curve_average,
    finite,
    fmt,
    rests_on,
    row_cells,
    rows_run,
    span,
)

CSV_COLUMNS = ("method", "avg", "min", "max", "paper_avg", "paper_min", "paper_max", "n_targets", "ci_low", "ci_high",
               "gain_avg", "gain_ci_low", "gain_ci_high", "not_measurable")


def table2_csv(a: Mapping[str, Any], paper: bool) -> str:
    """CSV text of Table II from one space's ``analyse`` output, rows in ``TABLE2_ROWS`` order."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    nan2 = np.full((len(TABLE2_ROWS), 2), np.nan)
    ci, gci = a.get("table2_ci", nan2), a.get("gain_ci", nan2)
    for i, (name, row) in enumerate(zip(TABLE2_ROWS, a["table2"])):
        ref = paper_row(name) if paper else (np.nan,) * 3
        w.writerow([name] + [fmt(v, 4) for v in row] + [fmt(v, 4) for v in ref] + [int(a["n_targets"][i])]
                   + [fmt(v, 4) for v in ci[i]] + [fmt(a["gain"][i, 0], 4)] + [fmt(v, 4) for v in gci[i]]
                   + [(a.get("unmeasurable") or {}).get(name, "")])
    for row in U.csv_rows(a):  # a user's conditions, after the paper's rows
        w.writerow(row)
    return buf.getvalue()


def table2_markdown(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]]) -> str:
    """``table2.md``: per space Table II (beside the paper's in PCA), the per-affordance average
    bootstrap factors, the chosen sources, the per-affordance answer (``affordances.py``), the
    correlation matrix, categories per threshold and the threshold study."""
    cfg = res["config"]
    meta = res["meta"]
    lines = ["# Learning and bootstrapping results", ""]
    lines += [
        f"Seed {meta['seed']}; actions: {', '.join(meta['actions'])}; training sizes {list(cfg.sizes)[:3]}...{max(cfg.sizes)} "
        f"({len(cfg.sizes)} sizes); repetitions PCA {cfg.reps_pca}, RHF {cfg.reps_rhf}; "
        f"average bootstrap factor over n = {span(cfg.sizes, *cfg.bf_sizes)}; 'best' = highest mean accuracy over "
        f"n = {span(cfg.sizes, *cfg.best_sizes)}, 'best after ten' = highest mean accuracy at n = {cfg.select_size}, both chosen "
        "on one half of each test set and scored on the other (both ways, averaged); '(in-sample oracle)' = the paper's "
        "choice, on the very scores it reports; '(online)' = per repetition, highest leave-one-out accuracy on its "
        f"{cfg.select_size} training samples; an 'after ten' row is the whole curve of the learner kept at "
        f"n = {cfg.select_size}, its '(causal)' row uses the choice from n = {cfg.select_size} on (before it: an equal "
        f"share of the candidates); the findings read `after_ten={cfg.after_ten}`; tied candidates share the choice "
        "equally.",
        "",
    ]
    for space, a in an.items():
        r = res[space]
        paper = space == "pca"
        n_aff = len(a["actions"])
        lines += [f"## Table II ({space.upper()})", "", rests_on(a, cfg), ""]
        head = "| method | avg | min | max | n | interval of avg | gain (accuracy) | interval of gain |"
        lines += [head + (" paper avg | paper min | paper max |" if paper else ""), "|---" * (8 + 3 * paper) + "|"]
        for i, (name, row) in enumerate(zip(TABLE2_ROWS, a["table2"])):
            if i not in rows_run(cfg, space):
                continue
            cells = row_cells(a, i) + [f"{int(a['n_targets'][i])} of {n_aff}", ci_text(a, "table2_ci", i),
                                             fmt(a["gain"][i, 0]), ci_text(a, "gain_ci", i)]
            cells += [fmt(v) for v in paper_row(name)] if paper else []
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += U.markdown_rows(a, sum(t in ACTIONS for t in a["actions"]), paper)
        lines += ["", "Sizes of the window with a bootstrap factor (NB above chance), per affordance: "
                  + ", ".join(f"{t} {int(d)} of {a['window_sizes']}" for t, d in zip(a["actions"], a["defined"])) + "."]
        lines += ["", f"### Average bootstrap factor per affordance ({space.upper()}, paper Fig. 10)", ""]
        acts = a["actions"]
        lines += ["| method | " + " | ".join(acts) + " |", "|---|" + "---|" * len(acts)]
        for name, row in zip(TABLE2_ROWS, a["table2_per_target"]):
            lines.append(f"| {name} | " + " | ".join(fmt(v, 2) for v in row) + " |")
        lines += ["| " + " | ".join(r) + " |" for r in U.per_target_rows(a)]
        conds = a["conditions"]
        lines += ["", "Chosen bootstrapping sources (target <- source):", ""]
        for fam in ("db1", "cb1"):
            if np.all(np.isnan(a["mean"][:, layout(len(acts), len(cfg.thresholds))[fam.upper()]])):
                continue
            best = ", ".join(f"{t} <- ({conds[i].split(':')[1]})" for t, i in zip(acts, a[f"best_{fam}"]))
            ten = ", ".join(f"{t} <- ({conds[i].split(':')[1]})" for t, i in zip(acts, a[f"ten_{fam}"]))
            lines += [f"- {fam.upper()} best: {best}", f"- {fam.upper()} best after ten: {ten}"]
        lines += U.source_lines(a)
        if "affordances" in a:
            lines += ["", f"### Per affordance: does what the robot knows help it? ({space.upper()})", "",
                      f"Gain of '{a['affordances']['best_row']}' over NB and its interval per affordance; verdict "
                      "from it (report.md, 'Per affordance'):", ""] + A.markdown_lines(a)
        lines += ["", f"### Correlation of the nine predictors' outputs ({space.upper()}, paper Fig. 11)", ""]
        corr = r["corr"]
        lines += ["| | " + " | ".join(SHORT.get(x, x) for x in acts) + " |", "|---|" + "---|" * len(acts)]
        for i, x in enumerate(acts):
            lines.append(f"| {SHORT.get(x, x)} | " + " | ".join(f"{v:+.2f}" for v in corr[i]) + " |")
        counts = categories_per_threshold(corr, cfg.thresholds)
        k = len(acts) * (len(acts) - 1) // 2
        lines += ["", f"Categories built per threshold T (of {k}; T = 0 is 'no heuristic', every pair): "
                  + "; ".join(f"T = {t}: {c['built']} (pairs with corr > T: {c['corr_above']})" for t, c in counts.items()), ""]
        th = a["thresholds"]
        lines += ["Threshold study (paper Fig. 12), average bf over n = "
                  f"{span(cfg.sizes, *cfg.bf_sizes)} of the best category built at T (chosen on one half of the test scenes, "
                  "scored on the other; Table II's aggregation: at T = 0 it is 'CB1 best'), mean over affordances: "
                  + "; ".join(f"T = {t:g}: {fmt(v)} (in-sample oracle {fmt(o)})" for t, v, o in zip(th["T"], th["avg"], th["avg_oracle"]))
                  + f"; all categories (overall average): {fmt(curve_average(th['overall_curve'], a['sizes'], cfg))}", ""]
        lines += [f"Test samples per affordance: {', '.join(f'{t} {int(n)}' for t, n in zip(acts, r['test_size']))}; "
                  f"sweep time {float(r['seconds']):.0f} s (of which source predictors/categories {float(r['seconds_prep']):.0f} s).", ""]
    return "\n".join(lines)


def summary(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]], figures: Sequence[str]) -> dict[str, Any]:
    """``summary.json``: Table II per space (avg/min/max, n_targets, intervals, the gain, per
    affordance values and intervals, the window sizes with a bf per affordance), per affordance
    whether DB1 helps it (``affordances``, ``report.affordances.summary``), the chosen
    sources, the correlation matrix and categories per threshold, the paper's Table II and
    the figure file names; NaN as None."""
    out = {
        s: {
            "actions": x["actions"],
            "table2": {name: dict(zip(("avg", "min", "max"), row), n_targets=int(n),
                                  ci=list(x["table2_ci"][i]) if "table2_ci" in x else None,
                                  gain=float(x["gain"][i, 0]), gain_ci=list(x["gain_ci"][i]) if "gain_ci" in x else None)
                       for i, (name, row, n) in enumerate(zip(TABLE2_ROWS, x["table2"], x["n_targets"]))},
            "table2_per_affordance_ci": ({name: dict(zip(x["actions"], (list(v) for v in ci)))
                                          for name, ci in zip(TABLE2_ROWS, x["per_target_ci"])} if "per_target_ci" in x else None),
            "gain_per_affordance": {name: dict(zip(x["actions"], row)) for name, row in zip(TABLE2_ROWS, x["gain_per_target"])},
            "window_sizes_defined": dict(zip(x["actions"], (int(d) for d in x["defined"]))),
            "window_sizes": x["window_sizes"],
            "test_size": x["test_size"], "test_positive": x["test_positive"],
            "ci": {"level": x.get("ci_level"), "resamples": x.get("ci_resamples"), "test_scenes_resampled": x["outcomes"],
                   "method": x.get("ci_method"), "target_set_held": x.get("table2_set_held")},
            "not_measurable": x.get("unmeasurable", {}),
            "chance_tolerance": x.get("tol"), "min_defined_sizes": x.get("min_defined"),
            "threshold_study": {"T": x["thresholds"]["T"], "avg": x["thresholds"]["avg"],
                                "avg_oracle": x["thresholds"]["avg_oracle"], "ci": x.get("threshold_ci")},
            "table2_per_affordance": {name: dict(zip(x["actions"], row)) for name, row in zip(TABLE2_ROWS, x["table2_per_target"])},
            "db1_best": {t: x["conditions"][i] for t, i in zip(x["actions"], x["best_db1"])},
            "db1_best_after_ten": {t: x["conditions"][i] for t, i in zip(x["actions"], x["ten_db1"])},
            "cb1_best": {t: x["conditions"][i] for t, i in zip(x["actions"], x["best_cb1"])},
            "cb1_best_after_ten": {t: x["conditions"][i] for t, i in zip(x["actions"], x["ten_cb1"])},
            "corr": res[s]["corr"],
            "against_nb": {k: v for k, v in x.get("methods", {}).items() if k != "weights"},
            "categories_per_threshold": categories_per_threshold(res[s]["corr"], res["config"].thresholds),
            "user_conditions": U.summary(x),
            "affordances": A.summary(x),
        }
        for s, x in an.items()
    }
    out["paper_table2"] = {k: dict(zip(("avg", "min", "max"), v)) for k, v in PAPER_TABLE2.items()}
    out["figures"] = list(figures)
    return finite(out)
