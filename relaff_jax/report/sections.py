"""The sections of the report document, each a list of blocks (``document.py``).

Takes the experiment (``load_results``), its one analysis ``{space: analyse(...)}``, the
findings and the report folder (a figure block is only added when its PNG was written);
gives the blocks of: the findings summary, the learning curves, Table II per space, each
method against NB, best after ten, the correlation clusters and the threshold study. The
blocks about the datasets (``data_sections``: statistics, example scenes) and about the run
(``run_sections``: introduction, sizes of the protocol, the run) are re-exported here.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.report import folder as F
from relaff_jax.report import user as U
from relaff_jax.learn import categories_per_threshold, layout, paper_row, TABLE2_ROWS
from relaff_jax.report.findings import VERDICTS, correlation_clusters
from relaff_jax.report.formatting import (
    SHORT,
    ci_text,
    curve_average,
    fmt,
    nanmean,
    paper_basis,
    rests_on,
    row_cells,
    rows_run,
    span,
)
from relaff_jax.report.robustness import robustness_table
from relaff_jax.report.data_sections import dataset_blocks, example_blocks  # noqa: F401 (re-exported: write.py's S.*)
from relaff_jax.report.run_sections import intro_blocks, protocol_blocks, run_blocks  # noqa: F401 (re-exported)


def fig_block(out: Path, name: str, caption: str) -> list[tuple]:
    """An image block if ``out/name`` was written, else nothing."""
    return [("img", name, caption)] if (out / name).exists() else []


def findings_blocks(found: Sequence[Mapping[str, Any]]) -> list[tuple]:
    blocks: list[tuple] = [("h", 2, "Which of the paper's findings this run reproduces"),
                           ("table", ["finding", "paper", "this run", "verdict"],
                            [[f["finding"], f["paper"], f["numbers"], f"**{f['verdict']}**"] for f in found]),
                           ("p", "Rules: " + "; ".join(f"{f['finding']}: {f['rule']}" for f in found) + "."
                            + (f" Each verdict is {found[0]['decision']}; the interval is printed beside each number "
                               "(estimate [low, high]). Every mean behind a verdict is over the paper's affordances only "
                               "(a user action has its own rows); Table II's sentence says what it rests on." if found else ""))]
    count = {v: sum(f["verdict"] == v for f in found) for v in VERDICTS}
    blocks.append(("p", f"{count['reproduced']} of {len(found)} findings reproduced, {count['not reproduced']} not, "
                        f"{count['undecided at this scale']} undecided at this scale, {count['not measurable']} not measurable."))
    return blocks


def robustness_blocks(readings: Mapping[str, Sequence[Mapping[str, Any]]], cfg: Any) -> list[tuple]:
    """Every finding in each analysis-only reading of the same results (``robustness.by_reading``)."""
    header, rows = robustness_table(readings)
    return [("h", 3, "Each finding in every reading of the stored results"),
            ("p", f"The findings above read 'best after ten' as `after_ten={cfg.after_ten}`. The paper leaves open "
                  "whether its 'best after ten' row is the whole curve of the learner kept after ten samples "
                  "(`whole`) or has chosen nothing before ten (`causal`); both are computed from the same results "
                  "(no refit). Readings that change the fits (`dbn_repeats`, `forest.per_tree`, "
                  "`category_labels`) need a run each: `relaff compare NAME=REPORT ...` ends with this table over "
                  "them. Each cell: verdict, then each claim's estimate [interval] (docs/learning.md, 'The paper's "
                  "open choices')."),
            ("table", header, rows)]


def methods_blocks(a: Mapping[str, Any], cfg: Any, space: str) -> list[tuple]:
    """Beyond the paper's statistics (``learn.analysis.against_nb``): each method against NB."""
    m = a.get("methods")
    if not m:
        return []
    lo, hi = cfg.bf_sizes
    iv = lambda key, i, nd: (f" [{fmt(m[key][i][0], nd)}, {fmt(m[key][i][1], nd)}]" if key in m else "")  # noqa: E731
    rows = []
    for i, name in enumerate(m["names"]):
        cens = int(m["censored"][i])
        rows.append([name, fmt(m["area"][i], 2) + iv("area_ci", i, 2),
                     fmt(m["saved"][i], 1) + iv("saved_ci", i, 1) + (f" ({cens} censored)" if cens else ""),
                     fmt(m["poi"][i], 3) + iv("poi_ci", i, 3), fmt(m["poi_holm_p"][i], 3),
                     "yes" if m["poi_holm_reject"][i] else "no"])
    level = 100 * float(cfg.ci_level)
    return [("h", 3, f"Each method against NB ({space.upper()}), beyond the paper's statistics"),
            ("p", f"Area: the gain curve P_bl(n) - P_NB(n) integrated over n = {lo}..{hi} (accuracy x samples; "
                  f"a method 0.1 above NB throughout has {0.1 * (hi - lo):.1f}). Saved: the training samples NB needs "
                  f"to reach the method's accuracy at n = {cfg.select_size} (interpolated between the sizes run), "
                  f"minus {cfg.select_size}; where NB never gets there the largest size counts (a lower bound, "
                  "'censored'). Both are means over the paper's affordances, with the bias-corrected interval of Table II's "
                  "resamples. P(improvement): the probability that the method's mean window accuracy in a "
                  "repetition beats NB's in another, per affordance (Mann-Whitney U / (R x R)), averaged over the "
                  "paper's affordances, with its interval from stratified resamples of the repetitions (as rliable). "
                  f"Significant: P(improvement) differs from 0.5 at {100 - level:g} % after Holm's correction over "
                  "the methods. 'best' and 'after ten' choose their source as Table II's rows of the same name do: on one "
                  "half of the test scenes, scored on the other (each statistic from the two ways averaged, NB read on "
                  "the same halves); a row named '(in-sample oracle)' chose on the scores it reports (no test outcomes "
                  "kept). 'after ten' is the whole curve of the learner kept. " + paper_basis(a, cfg)),
            ("table", ["method", "area", "samples saved", "P(improvement)", "Holm p", "significant"], rows)]


def learning_blocks(out: Path, main: str) -> list[tuple]:
    blocks: list[tuple] = [("h", 2, "Learning curves")]
    blocks += fig_block(out, F.FIG_NB_LEARNING, f"Non-bootstrapped learning curves ({main.upper()}), paper Fig. 6")
    blocks += fig_block(out, F.FIG_NB_SPACES, "NB per affordance in PCA and RHF, paper Fig. 7")
    blocks += fig_block(out, F.FIG_DB1_BEST, "NB and the best DB1 learner per affordance, paper Fig. 8")
    blocks += fig_block(out, F.FIG_DB1_BEST_BF, "Bootstrap factor of the best DB1 learner (average over the shaded n), paper Fig. 9")
    return blocks


def table2_blocks(an: Mapping[str, Mapping[str, Any]], cfg: Any, out: Path, preset: str | None = None) -> list[tuple]:
    blocks: list[tuple] = []
    for space, x in an.items():
        paper = space == "pca"
        n_aff = sum(a in ACTIONS for a in x["actions"])  # Table II's rows: the paper's nine
        users = [a for a in x["actions"] if a not in ACTIONS]
        header = ["method", "avg", "min", "max", "n", "interval of avg", "gain", "interval of gain"] \
            + (["paper avg", "paper min", "paper max"] if paper else [])
        rows = [[name] + row_cells(x, i) + [f"{int(x['n_targets'][i])} of {n_aff}", ci_text(x, "table2_ci", i),
                                                  fmt(x["gain"][i, 0]), ci_text(x, "gain_ci", i)]
                + ([fmt(v) for v in paper_row(name)] if paper else [])
                for i, (name, row) in enumerate(zip(TABLE2_ROWS, x["table2"])) if i in rows_run(cfg, space)]
        rows += U.table_rows(x, n_aff, paper)
        blocks += [("h", 2, f"Table II ({space.upper()})"),
                   ("p", f"Average bootstrap factor over n = {span(x['sizes'], *cfg.bf_sizes)}, avg / min / max over the "
                         f"n affordances with a value" + (", beside the paper's Table II." if paper else
                                                          " (the paper has no RHF table).") + " " + rests_on(x, cfg)),
                   ("table", header, rows), ("p", comparability(x, paper, preset))] + U.note(x)
        if users:
            blocks += [("p", f"{', '.join(users)}: not in the paper (a user action, docs/extending.md): Table II's rows "
                             "average the paper's affordances only; its values per method are in the table below, "
                             "where it is a source for the others too.")]
        rows = [[name] + [fmt(v, 2) for v in r] for name, r in zip(TABLE2_ROWS, x["table2_per_target"])
                if np.any(np.isfinite(r))] + U.per_target_rows(x)
        rows.append(["sizes with a bf"] + [f"{int(d)} of {x['window_sizes']}" for d in x["defined"]])
        blocks += [("p", "Per affordance (paper Fig. 10 as numbers); the last row: how many sizes of the window "
                         "each average rests on (bf is undefined where NB is at most half a test scene above chance):"),
                   ("table", ["method"] + [a if a in ACTIONS else f"{a} (not in the paper)" for a in x["actions"]], rows)]
    blocks += fig_block(out, F.FIG_AVERAGE_BF, "Average bootstrap factor per method and affordance, paper Fig. 10")
    return blocks


def _median_width(x: Mapping[str, Any]) -> float:
    rows = [i for i, n in enumerate(TABLE2_ROWS) if n != "NB" and np.all(np.isfinite(x["table2_ci"][i]))]
    return float(np.median([np.diff(x["table2_ci"][i])[0] for i in rows])) if rows else float("nan")


def scale_caveat_blocks(x: Mapping[str, Any], preset: str | None) -> list[tuple]:
    """The scale caveat beside the verdicts, at the top: a run whose Table II intervals are
    too wide to compare with the paper (``comparability``'s test) says so before its first
    "reproduced" verdict, not only in the Table II section."""
    width = _median_width(x) if "table2_ci" in x else float("nan")
    if not (preset == "quick" or not np.isfinite(width) or width > 1.0):
        return []
    scale = " (the quick preset: 100 samples per action, 2 repetitions)" if preset == "quick" else ""
    why = (f"its Table II intervals are {fmt(width, 2)} wide in bootstrap factor (median), too wide to compare "
           "this run with the paper (whose rows span 1.36-2.90)" if np.isfinite(width) else
           "it has no Table II interval to compare with the paper by (too few sizes, repetitions or affordances)")
    return [("p", f"**Read these verdicts with this run's scale{scale}:** {why}. A verdict here says what this "
                  "run's numbers allow, and shows that the pipeline runs end to end; it does not say whether the "
                  "paper's findings hold (the study or paper preset does).")]


def comparability(x: Mapping[str, Any], paper: bool, preset: str | None) -> str:
    """Whether this Table II can be read beside the paper's: the widths of its intervals."""
    if "table2_ci" not in x:
        return "No intervals were computed, so these numbers cannot be compared with the paper's."
    rows = [i for i, n in enumerate(TABLE2_ROWS) if n != "NB" and np.all(np.isfinite(x["table2_ci"][i]))]
    width = _median_width(x)
    text = f"Median width of the rows' intervals: {fmt(width, 2)} in bootstrap factor"
    if paper:
        has = [i for i in rows if np.isfinite(paper_row(TABLE2_ROWS[i])[0])]
        inside = [i for i in has if x["table2_ci"][i][0] <= paper_row(TABLE2_ROWS[i])[0] <= x["table2_ci"][i][1]]
        text += f"; the paper's avg lies inside this run's interval for {len(inside)} of {len(has)} rows"
    text += (". A bootstrap factor's interval is wide where NB is near chance at some size of a resample (the ratio's "
             "denominator is small; it is bounded by the test-set size, see above); the gain's interval is better "
             "conditioned.")
    if preset == "quick" or not np.isfinite(width) or width > 1.0:
        text += (" **These intervals are too wide to compare this run with the paper** (the paper's rows span 1.36-2.90):"
                 " the numbers show that the pipeline runs end to end, not whether the paper's findings hold"
                 + (" (the quick preset: 100 samples per action, 2 repetitions)." if preset == "quick" else "."))
    return text


def best_after_ten_blocks(a: Mapping[str, Any], cfg: Any, main: str) -> list[tuple]:
    conds = a["conditions"]
    lay = layout(len(a["actions"]), len(cfg.thresholds))
    rows = []
    for fam in ("db1", "cb1"):
        if np.all(np.isnan(a["mean"][:, lay[fam.upper()]])):
            continue
        for ti, t in enumerate(a["actions"]):
            b, k = a[f"best_{fam}"][ti], a[f"ten_{fam}"][ti]
            w = a[f"online_{fam}"][ti]  # (K, R) online weights
            agree = float(np.mean(w[list(lay[fam.upper()]).index(k)] > 0)) if w.sum() else float("nan")
            on = lay["n"] + (fam == "cb1")
            rows.append([fam.upper(), t, conds[b].split(":")[1] + (f" (+{a[f'ties_{fam}'][ti] - 1} tied)" if a[f"ties_{fam}"][ti] > 1 else ""),
                         fmt(a["avg_bf"][ti, b]), conds[k].split(":")[1], fmt(a["avg_bf"][ti, k]),
                         fmt(a["avg_bf"][ti, on]), f"{100 * agree:.0f} %" if np.isfinite(agree) else "-"])
    if not rows:
        return []
    return [("h", 2, "Best after ten"),
            ("p", f"The sources shown are the in-sample choices (the paper's oracle rows of Table II): 'best' is the source "
                  f"with the highest mean accuracy over n = {span(a['sizes'], *cfg.best_sizes)}; 'after ten (offline)' the "
                  f"source with the highest mean *test* accuracy at n = {cfg.select_size} over all repetitions, scored on "
                  "the same test sets. Table II's 'best' and 'best after ten' rows make the same choices on one half of "
                  "each test set and score them on the other. "
                  f"'Online' is what an agent could choose: per repetition, the source with the highest leave-one-out "
                  f"accuracy on its own {cfg.select_size} training samples; candidates tied at the top share the choice "
                  f"equally (a uniform random pick), here and in Table II ({main.upper()})."),
            ("table", ["family", "target", "best source", "avg bf", "offline after-ten source", "avg bf",
                       "online avg bf", "repetitions whose online pick includes the offline source"], rows)]


def correlation_blocks(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]], cfg: Any, out: Path) -> list[tuple]:
    blocks: list[tuple] = [("h", 2, "Correlation of the predictors and its clusters")]
    for space, x in an.items():
        corr = res[space]["corr"]
        acts = x["actions"]
        cl = correlation_clusters(corr, acts, cfg.cbn_threshold)
        groups = [g for g in cl if len(g) > 1]
        blocks.append(("p", f"{space.upper()}: affordances linked by correlations above T = {cfg.cbn_threshold:g}: "
                            + ("; ".join("{" + ", ".join(g) + "}" for g in groups) if groups else "none")
                            + (f"; alone: {', '.join(g[0] for g in cl if len(g) == 1)}" if any(len(g) == 1 for g in cl) else "") + "."))
        blocks.append(("table", [""] + [SHORT.get(x, x) for x in acts],
                       [[SHORT.get(x, x)] + [f"{v:+.2f}" for v in corr[i]] for i, x in enumerate(acts)]))
    blocks += fig_block(out, F.FIG_CORRELATION, "Correlation of the source predictors' outputs, paper Fig. 11")
    return blocks


def threshold_blocks(corr: np.ndarray, a: Mapping[str, Any], cfg: Any, main: str, out: Path) -> list[tuple]:
    th = a["thresholds"]
    if not np.any(np.isfinite(th["overall_curve"])):
        return []
    lay = layout(len(a["actions"]), len(cfg.thresholds))
    k = len(a["actions"]) * (len(a["actions"]) - 1) // 2
    counts = categories_per_threshold(corr, cfg.thresholds)
    paper = np.asarray(a.get("paper", [True] * len(a["actions"])), bool)  # the means: the paper's affordances
    rows = [[f"{t:g}", counts[f"{t:g}"]["built"], fmt(th["avg"][i]),
             ci_text(a, "threshold_ci", i) if "threshold_ci" in a else "-", fmt(th["avg_oracle"][i]),
             fmt(nanmean(np.where(a["built"][i] & paper, a["avg_bf"][:, lay["CBn"][i]], np.nan)))]
            for i, t in enumerate(th["T"])]
    rows.append(["all categories (overall average)", k, fmt(curve_average(th["overall_curve"], a["sizes"], cfg)), "-", "-", "-"])
    blocks: list[tuple] = [("h", 2, "Threshold study"),
                           ("p", f"Categories built at each correlation threshold T and the average bf ({main.upper()}, mean over the "
                                 "paper's affordances) of each affordance's best category among them, aggregated as Table II (per "
                                 "affordance over the window, then over the affordances with a value; at T = 0 this is "
                                 "Table II's 'CB1 best'): chosen on one half of the test scenes and scored on the other, "
                                 "and the in-sample oracle; and of CBn (all of them together; over the affordances with a "
                                 "category built at T: without one CBn is NB's learner). The figure shows the "
                                 "in-sample best category's curve."),
                           ("table", ["T", f"categories built (of {k})", "best category avg bf", "interval",
                                      "in-sample oracle", "CBn avg bf"], rows)]
    return blocks + fig_block(out, F.FIG_THRESHOLDS, "Best category above each threshold, paper Fig. 12")
