"""Report of an experiment folder: Table II beside the paper's, and the figures of section V.

Takes ``RESULTS`` written by ``relaff experiment`` (``experiment.json`` + ``<space>/results.npz``)
and writes to ``REPORT``:

* ``table2.csv`` (PCA; columns ``method, avg, min, max, paper_avg, paper_min, paper_max``),
  ``table2_rhf.csv`` when RHF was run (no paper columns: the paper has no RHF table);
* ``table2.md``: Table II side by side with the paper, the per-affordance average bootstrap
  factors (paper Fig. 10), the chosen bootstrapping sources, the correlation matrix and how
  many categories survive each threshold;
* ``summary.json``: the same numbers for programs;
* PNG figures like paper Figs. 6-12 (matplotlib, Agg backend).
"""
from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.experiment import PAPER_TABLE2, TABLE2_ROWS, analyse, categories_per_threshold, layout, load_results

CSV_COLUMNS = ("method", "avg", "min", "max", "paper_avg", "paper_min", "paper_max")
SHORT = {"unobstruct": "unob"}


def _fmt(x: float, nd: int = 3) -> str:
    return "nan" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def table2_csv(table: np.ndarray, paper: bool) -> str:
    """CSV text of Table II: ``table (rows, 3)`` avg/min/max in ``TABLE2_ROWS`` order."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for name, row in zip(TABLE2_ROWS, table):
        ref = PAPER_TABLE2[name] if paper else (np.nan,) * 3
        w.writerow([name] + [_fmt(v, 4) for v in row] + [_fmt(v, 4) for v in ref])
    return buf.getvalue()


def _markdown(res: Mapping[str, Any], an: Mapping[str, Any]) -> str:
    cfg = res["config"]
    meta = res["meta"]
    lines = ["# Learning and bootstrapping results", ""]
    lines += [
        f"Seed {meta['seed']}; actions: {', '.join(meta['actions'])}; training sizes {list(cfg.sizes)[:3]}...{max(cfg.sizes)} "
        f"({len(cfg.sizes)} sizes); repetitions PCA {cfg.reps_pca}, RHF {cfg.reps_rhf}; "
        f"average bootstrap factor over n = {cfg.bf_sizes[0]}..{cfg.bf_sizes[1]}; 'best' = highest mean accuracy over "
        f"n = {cfg.best_sizes[0]}..{cfg.best_sizes[1]}; 'best after ten' = highest accuracy at n = {cfg.select_size}.",
        "",
    ]
    for space, a in an.items():
        r = res[space]
        paper = space == "pca"
        lines += [f"## Table II ({space.upper()})", ""]
        if paper:
            lines += ["| method | avg | min | max | paper avg | paper min | paper max |", "|---|---|---|---|---|---|---|"]
        else:
            lines += ["| method | avg | min | max |", "|---|---|---|---|"]
        for name, row in zip(TABLE2_ROWS, a["table2"]):
            cells = [_fmt(v) for v in row] + ([_fmt(v) for v in PAPER_TABLE2[name]] if paper else [])
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += ["", f"### Average bootstrap factor per affordance ({space.upper()}, paper Fig. 10)", ""]
        acts = a["actions"]
        lines += ["| method | " + " | ".join(acts) + " |", "|---|" + "---|" * len(acts)]
        for name, row in zip(TABLE2_ROWS, a["table2_per_target"]):
            lines.append(f"| {name} | " + " | ".join(_fmt(v, 2) for v in row) + " |")
        conds = a["conditions"]
        lines += ["", "Chosen bootstrapping sources (target <- source):", ""]
        for fam in ("db1", "cb1"):
            if np.all(np.isnan(a["mean"][:, layout(len(acts), len(cfg.thresholds))[fam.upper()]])):
                continue
            best = ", ".join(f"{t} <- ({conds[i].split(':')[1]})" for t, i in zip(acts, a[f"best_{fam}"]))
            ten = ", ".join(f"{t} <- ({conds[i].split(':')[1]})" for t, i in zip(acts, a[f"ten_{fam}"]))
            lines += [f"- {fam.upper()} best: {best}", f"- {fam.upper()} best after ten: {ten}"]
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
                  f"{cfg.bf_sizes[0]}..{cfg.bf_sizes[1]} of the best category built at T, mean over affordances: "
                  + "; ".join(f"T = {t:g}: {_fmt(_avg(c, a['sizes'], cfg))}" for t, c in zip(th["T"], th["best_curve"]))
                  + f"; all categories (overall average): {_fmt(_avg(th['overall_curve'], a['sizes'], cfg))}", ""]
        lines += [f"Test samples per affordance: {', '.join(f'{t} {int(n)}' for t, n in zip(acts, r['test_size']))}; "
                  f"sweep time {float(r['seconds']):.0f} s (of which source predictors/categories {float(r['seconds_prep']):.0f} s).", ""]
    return "\n".join(lines)


def _avg(curve: np.ndarray, sizes, cfg) -> float:
    from relaff_jax.experiment import average_bf

    return float(average_bf(np.asarray(curve), sizes, *cfg.bf_sizes))


# ------------------------------------------------------------------------------- figures


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _grid(plt, n: int):
    cols = 3
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes.flat[:n]:
        ax.set_xlabel("training samples n")
    return fig, axes.flat


def _logx(ax, sizes) -> None:
    """Log-scaled n axis with plain tick labels at round sizes."""
    from matplotlib.ticker import FixedLocator, NullLocator, ScalarFormatter

    ax.set_xscale("log")
    ticks = [t for t in (2, 4, 10, 25, 50, 100, 250, 1000) if min(sizes) <= t <= max(sizes)]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_locator(NullLocator())


def _curve(ax, sizes, mean, sem, label, **kw):
    line, = ax.plot(sizes, mean, label=label, **kw)
    ax.fill_between(sizes, mean - sem, mean + sem, alpha=0.2, color=line.get_color())


def figures(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]], out: Path) -> list[Path]:
    """Write the PNG figures; return their paths."""
    plt = _plt()
    written: list[Path] = []
    cfg = res["config"]

    def save(fig, name):
        p = out / name
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        plt.close(fig)
        rio.atomic_write_bytes(p, buf.getvalue())
        written.append(p)

    spaces = list(an)
    # Fig. 6: NB learning curves in PCA (or the first space)
    s0 = "pca" if "pca" in an else spaces[0]
    a = an[s0]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for ti, t in enumerate(a["actions"]):
        _curve(ax, a["sizes"], a["mean"][ti, 0], a["sem"][ti, 0], t)
    ax.set(xlabel="training samples n", ylabel="accuracy", title=f"{s0.upper()} - non-bootstrapped (NB)")
    _logx(ax, a["sizes"])
    ax.legend(fontsize=7, ncol=3)
    save(fig, "fig06_nb_learning.png")

    # Fig. 7: NB early learning per affordance, PCA vs RHF
    fig, axes = _grid(plt, len(a["actions"]))
    for ti, t in enumerate(a["actions"]):
        for s in spaces:
            _curve(axes[ti], an[s]["sizes"], an[s]["mean"][ti, 0], an[s]["sem"][ti, 0], f"{s.upper()} NB")
        axes[ti].set(title=t, ylabel="accuracy")
        axes[ti].legend(fontsize=7)
    save(fig, "fig07_nb_spaces.png")

    # Fig. 8 and 9: best DB1 per affordance (accuracy and bootstrap factor)
    db_spaces = [s for s in spaces if np.any(np.isfinite(an[s]["mean"][:, 1:1 + len(an[s]["actions"])]))]
    if db_spaces:
        fig, axes = _grid(plt, len(a["actions"]))
        for ti, t in enumerate(a["actions"]):
            for s in db_spaces:
                b = an[s]["best_db1"][ti]
                src = an[s]["conditions"][b].split(":")[1]
                _curve(axes[ti], an[s]["sizes"], an[s]["mean"][ti, 0], an[s]["sem"][ti, 0], f"{s.upper()} NB", linestyle="--")
                _curve(axes[ti], an[s]["sizes"], an[s]["mean"][ti, b], an[s]["sem"][ti, b], f"{s.upper()} {t} <- ({src})")
            axes[ti].set(title=t, ylabel="accuracy")
            axes[ti].legend(fontsize=6)
        save(fig, "fig08_db1_best.png")
        fig, axs = plt.subplots(1, len(db_spaces), figsize=(6 * len(db_spaces), 4.5), squeeze=False)
        for ax, s in zip(axs.flat, db_spaces):
            x = an[s]
            for ti, t in enumerate(x["actions"]):
                b = x["best_db1"][ti]
                ax.plot(x["sizes"], x["bf"][ti, b], label=f"{t} <- ({x['conditions'][b].split(':')[1]})")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.axvspan(*cfg.bf_sizes, color="0.9", zorder=0)
            ax.set(xlabel="training samples n", ylabel="bootstrap factor", title=f"{s.upper()} - DB1 best")
            _logx(ax, x["sizes"])
            ax.legend(fontsize=6, ncol=2)
        save(fig, "fig09_db1_best_bf.png")

    # Fig. 10: average bootstrap factor per method and affordance (PCA)
    rows = [r for r in range(1, len(TABLE2_ROWS)) if np.any(np.isfinite(a["table2_per_target"][r]))]
    if rows:
        fig, ax = plt.subplots(figsize=(12, 4.5))
        groups = a["actions"] + ["average"]
        width = 0.8 / len(rows)
        for k, r in enumerate(rows):
            vals = np.append(a["table2_per_target"][r], a["table2"][r, 0])
            ax.bar(np.arange(len(groups)) + (k - (len(rows) - 1) / 2) * width, np.nan_to_num(vals), width, label=TABLE2_ROWS[r])
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xticks(np.arange(len(groups)), groups)
        ax.set(ylabel=f"average bf (n = {cfg.bf_sizes[0]}..{cfg.bf_sizes[1]})", title=f"{s0.upper()} - average bootstrap factors")
        ax.legend(fontsize=7, ncol=4)
        save(fig, "fig10_average_bf.png")

    # Fig. 11: correlation matrices
    fig, axs = plt.subplots(1, len(spaces), figsize=(5.5 * len(spaces), 5), squeeze=False)
    for ax, s in zip(axs.flat, spaces):
        corr, acts = res[s]["corr"], an[s]["actions"]
        im = ax.imshow(corr, vmin=-1, vmax=1, cmap="RdBu_r")
        names = [SHORT.get(x, x) for x in acts]
        ax.set_xticks(range(len(acts)), names, rotation=45)
        ax.set_yticks(range(len(acts)), names)
        for i in range(len(acts)):
            for j in range(len(acts)):
                ax.text(j, i, f"{corr[i, j]:.2f}", ha="center", va="center", fontsize=6)
        ax.set_title(f"{s.upper()} - predictor output correlation")
        fig.colorbar(im, ax=ax, shrink=0.8)
    save(fig, "fig11_correlation.png")

    # Fig. 12: best category above each threshold, averaged over affordances
    th = a["thresholds"]
    if np.any(np.isfinite(th["overall_curve"])):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for t, c, n in zip(th["T"], th["best_curve"], th["count"]):
            ax.plot(a["sizes"], c, label=f"best category, T = {t:g} ({n} built)")
        ax.plot(a["sizes"], th["overall_curve"], "k--", label="overall average (all categories)")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set(xlabel="training samples n", ylabel="bootstrap factor", title=f"{s0.upper()} - correlation thresholds")
        _logx(ax, a["sizes"])
        ax.legend(fontsize=7)
        save(fig, "fig12_thresholds.png")
    return written


def write_report(results_dir: str | os.PathLike, out_dir: str | os.PathLike) -> Path:
    """Write Table II (CSV + Markdown), summary.json and figures; return ``out_dir``."""
    res = load_results(results_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    an = {s: analyse(res[s], res["config"]) for s in res["meta"]["spaces"]}
    main = "pca" if "pca" in an else next(iter(an))
    rio.atomic_write_text(out / "table2.csv", table2_csv(an[main]["table2"], paper=main == "pca"))
    if main == "pca" and "rhf" in an:
        rio.atomic_write_text(out / "table2_rhf.csv", table2_csv(an["rhf"]["table2"], paper=False))
    rio.atomic_write_text(out / "table2.md", _markdown(res, an))
    figs = figures(res, an, out)
    summary = {
        s: {
            "actions": x["actions"],
            "table2": {name: dict(zip(("avg", "min", "max"), row)) for name, row in zip(TABLE2_ROWS, x["table2"])},
            "table2_per_affordance": {name: dict(zip(x["actions"], row)) for name, row in zip(TABLE2_ROWS, x["table2_per_target"])},
            "db1_best": {t: x["conditions"][i] for t, i in zip(x["actions"], x["best_db1"])},
            "db1_best_after_ten": {t: x["conditions"][i] for t, i in zip(x["actions"], x["ten_db1"])},
            "cb1_best": {t: x["conditions"][i] for t, i in zip(x["actions"], x["best_cb1"])},
            "cb1_best_after_ten": {t: x["conditions"][i] for t, i in zip(x["actions"], x["ten_cb1"])},
            "corr": res[s]["corr"],
            "categories_per_threshold": categories_per_threshold(res[s]["corr"], res["config"].thresholds),
        }
        for s, x in an.items()
    }
    summary["paper_table2"] = {k: dict(zip(("avg", "min", "max"), v)) for k, v in PAPER_TABLE2.items()}
    summary["figures"] = [p.name for p in figs]
    rio.atomic_write_json(out / "summary.json", _finite(summary))
    return out


def _finite(obj):
    """JSON has no NaN: turn non-finite floats into None."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
