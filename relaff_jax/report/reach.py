"""The report's "Reach or relation" section: how much of each label is reach, what each
learner gets right on which test scenes, and what each source predictor follows.

Takes the datasets' anatomies (``relaff_jax.data.anatomy``), the experiment's results
(``acc_subset``, ``subset_count``, ``corr_feasible``, ``corr_stacked``) and the report folder;
gives ``reach_figure`` (``fig_reach.png``), ``reach_json`` (``reach.json``) and the blocks of
the section (``reach_blocks``, ``subset_blocks``, ``predictor_blocks``).

Why: an infeasible motor program is labelled negative, so where the negatives are mostly out
of reach, "label = feasible" scores high and a learner can be right for the wrong reason. The
breakdown by test subset (positives, feasible negatives, infeasible negatives) shows whether
a learner tells the relation apart or only reach.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.figure import Figure

from relaff_jax.learn.blocks import SUBSETS
from relaff_jax.report import folder as F
from relaff_jax.report.figures import save_png
from relaff_jax.report.formatting import SHORT, fmt


def _pct(x: float | None) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{100 * x:.0f} %"


def reach_figure(anat: Mapping[str, Mapping[str, Any]], out: Path) -> Path:
    """``fig_reach.png``: per action, the selection's share of infeasible negatives and the
    three oracles' accuracies."""
    acts = list(anat)
    keys = [("negatives_infeasible_share", "negatives infeasible"), ("oracle_feasible_acc", "label = feasible"),
            ("oracle_relation_acc", "relation rule"), ("oracle_feasible_relation_acc", "feasible + relation")]
    fig = Figure(figsize=(10, 3.8))
    ax = fig.subplots()
    w = 0.8 / len(keys)
    for k, (key, label) in enumerate(keys):
        vals = [anat[a]["selection"][key] for a in acts]
        ax.bar(np.arange(len(acts)) + (k - 1.5) * w, [np.nan if v is None else v for v in vals], w, label=label)
    ax.axhline(0.5, color="k", lw=0.6, ls=":")
    ax.set_xticks(np.arange(len(acts)), acts)
    ax.set(ylim=(0, 1.02), ylabel="share / accuracy on the selection",
           title="Reach or relation: what the balanced selection's labels consist of")
    ax.legend(fontsize=7, ncol=4, loc="lower center")
    return save_png(fig, out, dpi=100)


def reach_blocks(anat: Mapping[str, Mapping[str, Any]], missing: Mapping[str, str], out: Path) -> list[tuple]:
    """The anatomy table of every action's selection (``anat``) and the figure."""
    blocks: list[tuple] = [("h", 2, "Reach or relation: what the labels consist of"), (
        "p", "An infeasible motor program (the arm cannot reach) is labelled negative. Per action, over the balanced "
             "selection: the population it was drawn from and how its negatives were drawn, the share of negatives "
             "that are infeasible, and three rules that each see one cause: label = feasible, each relation's majority "
             "label, and the majority label of each (feasible, relation) cell (`relaff anatomy DIR` prints the whole "
             "breakdown; `--set dataset.population=feasible` selects from feasible rollouts only).")]
    rows = []
    for a, d in anat.items():
        s = d["selection"]
        match = _pct(d["borrowed_share"]) + ("" if d["matching_met"] else " (not met)")
        refused = "-" if d.get("unsettled_refused") is None else str(d["unsettled_refused"])
        unsettled = f'{d.get("unsettled", "keep")} ({refused})'
        rows.append([a, d["population"], d["negatives"], unsettled, s["n"], match,
                     _pct(s["negatives_infeasible_share"]), fmt(s["oracle_feasible_acc"]), fmt(s["oracle_relation_acc"]),
                     fmt(s["oracle_feasible_relation_acc"])])
    blocks.append(("table", ["action", "population", "negatives", "unsettled (refused)", "samples", "borrowed",
                             "negatives infeasible", "label = feasible", "relation", "feasible + relation"], rows))
    if missing:
        blocks.append(("p", "No anatomy for " + "; ".join(f"{a} ({why})" for a, why in missing.items()) + "."))
    if (out / F.FIG_REACH).exists():
        blocks.append(("img", F.FIG_REACH, "Share of infeasible negatives and the three oracles, per action"))
    return blocks


def subset_table(x: Mapping[str, Any], cond: int, size_index: int) -> np.ndarray:
    """``(T, N_SUBSETS)`` mean accuracy over repetitions of condition ``cond`` at one size."""
    a = np.asarray(x["acc_subset"])[:, cond, size_index]  # (T, R, 3)
    ok = np.isfinite(a).any(1)
    with np.errstate(invalid="ignore"):
        return np.where(ok, np.nansum(a, 1) / np.maximum(np.isfinite(a).sum(1), 1), np.nan)


def subset_blocks(res: Mapping[str, Any], cfg: Any) -> list[tuple]:
    """NB's test accuracy by test subset at the selection size and the largest size, per space."""
    blocks: list[tuple] = [("h", 3, "What the standard learner gets right, by test subset"), (
        "p", "NB's test accuracy (mean over repetitions) on the positives, the feasible negatives and the infeasible "
             "negatives of each target's test set, with their counts. A learner that only sees reach is right on the "
             "positives and the infeasible negatives and wrong on the feasible ones.")]
    for space in res["meta"]["spaces"]:
        x = res[space]
        sizes = list(np.asarray(x["sizes"]))
        picks = [s for s in (cfg.select_size, sizes[-1]) if s in sizes]
        picks = list(dict.fromkeys(picks))
        head = ["target", "test scenes (pos / feas. neg / infeas. neg)"]
        tabs = [subset_table(x, 0, sizes.index(s)) for s in picks]
        for s in picks:
            head += [f"n={s} {k}" for k in ("pos", "feas. neg", "infeas. neg")]
        rows = []
        for ti, t in enumerate(np.asarray(x["actions"])):
            cnt = " / ".join(str(int(c)) for c in np.asarray(x["subset_count"])[ti])
            rows.append([SHORT.get(str(t), str(t)), cnt] + [fmt(v) for tab in tabs for v in tab[ti]])
        blocks += [("p", f"{space.upper()}:"), ("table", head, rows)]
    return blocks


def predictor_blocks(res: Mapping[str, Any]) -> list[tuple]:
    """Each source predictor's correlation with "feasible" and with "stacked" (Fig. 11's scenes)."""
    blocks: list[tuple] = [("h", 3, "What each source predictor follows"), (
        "p", "Pearson correlation of each source predictor's outputs on the correlation scenes (the scenes of Fig. 11) "
             "with whether the motor program was feasible and with whether the toy is stacked (on top or inside). "
             "A predictor that follows reach correlates with the first.")]
    rows, head = {}, ["predictor"]
    for space in res["meta"]["spaces"]:
        x = res[space]
        head += [f"{space.upper()} r(feasible)", f"{space.upper()} r(stacked)"]
        for ti, t in enumerate(np.asarray(x["actions"])):
            rows.setdefault(str(t), [SHORT.get(str(t), str(t))])
            rows[str(t)] += [f"{v:+.2f}" if np.isfinite(v) else "-"
                             for v in (x["corr_feasible"][ti], x["corr_stacked"][ti])]
    blocks.append(("table", head, list(rows.values())))
    return blocks


def reach_json(anat: Mapping[str, Mapping[str, Any]], res: Mapping[str, Any], cfg: Any) -> dict[str, Any]:
    """``reach.json``: the anatomies' selection figures and, per space, NB's subset accuracies
    at every size (mean over repetitions) and the predictors' correlations."""
    out: dict[str, Any] = {"subsets": list(SUBSETS), "datasets": {}, "spaces": {}}
    for a, d in anat.items():
        s = d["selection"]
        out["datasets"][a] = {k: d[k] for k in ("population", "negatives", "borrowed", "borrowed_share", "matching_met")}
        out["datasets"][a].update({k: d.get(k) for k in ("unsettled", "unsettled_refused")})
        out["datasets"][a].update({k: s[k] for k in ("n", "negatives_infeasible_share", "oracle_feasible_acc",
                                                     "oracle_relation_acc", "oracle_feasible_relation_acc")})
    for space in res["meta"]["spaces"]:
        x = res[space]
        sizes = [int(v) for v in np.asarray(x["sizes"])]
        nb = np.stack([subset_table(x, 0, i) for i in range(len(sizes))], 1)  # (T, S, 3)
        out["spaces"][space] = {
            "actions": [str(t) for t in np.asarray(x["actions"])], "sizes": sizes,
            "nb_acc_subset": nb.tolist(),  # NaN (empty subset) becomes null in finite()
            "subset_count": np.asarray(x["subset_count"]).tolist(),
            "corr_feasible": np.asarray(x["corr_feasible"]).tolist(),
            "corr_stacked": np.asarray(x["corr_stacked"]).tolist()}
    return out
