"""The report's figures (paper Figs. 6-12 and the datasets), drawn without pyplot.

Takes the experiment (``load_results``) and its analysis ``{space: analyse(...)}``;
``write_figures`` writes ``fig06_nb_learning.png`` ... ``fig12_thresholds.png`` (those the run
has data for) and returns their paths; accuracy curves carry their bootstrap intervals as bands; ``dataset_figure`` writes ``fig_datasets.png`` from
``relaff_jax.data.info`` dicts. Figures are ``matplotlib.figure.Figure`` objects rendered
straight to PNG: no pyplot, no global backend change, so a notebook importing the package
keeps its own backend.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.figure import Figure

from relaff_jax import io as rio
from relaff_jax.constants import RELATIONS
from relaff_jax.learn import TABLE2_ROWS
from relaff_jax.report import folder as F
from relaff_jax.report import user as U
from relaff_jax.report.formatting import SHORT


def save_png(fig: Figure, path: Path, dpi: int) -> Path:
    """Lay out ``fig`` and write it as PNG to ``path`` atomically; return ``path``."""
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    rio.atomic_write_bytes(path, buf.getvalue())
    return path


def _grid(n: int):
    cols = 3
    rows = int(np.ceil(n / cols))
    fig = Figure(figsize=(4 * cols, 3 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes.flat[:n]:
        ax.set_xlabel("training samples n")
    return fig, axes.flat


def _colours(n: int) -> list:
    """n distinguishable colours (tab10 repeats after ten; tab20 holds the 15 Table II rows)."""
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def _logx(ax, sizes) -> None:
    """Log-scaled n axis with plain tick labels at round sizes."""
    from matplotlib.ticker import FixedLocator, NullLocator, ScalarFormatter

    ax.set_xscale("log")
    ticks = [t for t in (2, 4, 10, 25, 50, 100, 250, 1000) if min(sizes) <= t <= max(sizes)]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_locator(NullLocator())


def _curve(ax, a, ti, c, label, **kw):
    """Mean accuracy curve of target ti, condition c, with its bootstrap interval as a band
    (mean +- standard error when the analysis has no intervals)."""
    mean = a["mean"][ti, c]
    lo, hi = (a["mean_ci"][ti, c, :, 0], a["mean_ci"][ti, c, :, 1]) if "mean_ci" in a else (mean - a["sem"][ti, c], mean + a["sem"][ti, c])
    line, = ax.plot(a["sizes"], mean, label=label, **kw)
    ax.fill_between(a["sizes"], lo, hi, alpha=0.2, color=line.get_color())


def write_figures(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]], out: Path) -> list[Path]:
    """Write the PNG figures of paper Figs. 6-12 that the run has data for; return their paths."""
    written: list[Path] = []
    cfg = res["config"]

    def save(fig, name):
        written.append(save_png(fig, out / name, dpi=110))

    spaces = list(an)
    # Fig. 6: NB learning curves in PCA (or the first space)
    s0 = "pca" if "pca" in an else spaces[0]
    a = an[s0]
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    # Means only: nine overlapping bands hide each other; each curve's interval is in Fig. 7.
    for ti, t in enumerate(a["actions"]):
        ax.plot(a["sizes"], a["mean"][ti, 0], label=t, linestyle=("-", "--", ":")[ti // 10 % 3])
    ax.set(xlabel="training samples n", ylabel="accuracy",
           title=f"{s0.upper()} - non-bootstrapped (NB); intervals per affordance in Fig. 7")
    _logx(ax, a["sizes"])
    ax.legend(fontsize=7, ncol=3)
    save(fig, F.FIG_NB_LEARNING)

    # Fig. 7: NB early learning per affordance, PCA vs RHF
    fig, axes = _grid(len(a["actions"]))
    for ti, t in enumerate(a["actions"]):
        for s in spaces:
            _curve(axes[ti], an[s], ti, 0, f"{s.upper()} NB")
        axes[ti].set(title=t, ylabel="accuracy")
        axes[ti].legend(fontsize=7)
    save(fig, F.FIG_NB_SPACES)

    # Fig. 8 and 9: best DB1 per affordance (accuracy and bootstrap factor)
    db_spaces = [s for s in spaces if np.any(np.isfinite(an[s]["mean"][:, 1:1 + len(an[s]["actions"])]))]
    if db_spaces:
        fig, axes = _grid(len(a["actions"]))
        for ti, t in enumerate(a["actions"]):
            for s in db_spaces:
                b = an[s]["best_db1"][ti]
                src = an[s]["conditions"][b].split(":")[1]
                _curve(axes[ti], an[s], ti, 0, f"{s.upper()} NB", linestyle="--")
                _curve(axes[ti], an[s], ti, b, f"{s.upper()} {t} <- ({src})")
            axes[ti].set(title=t, ylabel="accuracy")
            axes[ti].legend(fontsize=6)
        save(fig, F.FIG_DB1_BEST)
        fig = Figure(figsize=(6 * len(db_spaces), 4.5))
        axs = fig.subplots(1, len(db_spaces), squeeze=False)
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
        save(fig, F.FIG_DB1_BEST_BF)

    # Fig. 10: average bootstrap factor per method and affordance (PCA)
    rows = [(TABLE2_ROWS[r], a["table2_per_target"][r], a["table2"][r, 0], None) for r in range(1, len(TABLE2_ROWS))
            if np.any(np.isfinite(a["table2_per_target"][r]))]
    u = U.rows_of(a)  # a user's conditions, beside the paper's rows, hatched
    rows += [(U.label(n), v, m, "//") for n, v, m in zip(u.get("names", ()), u.get("table2_per_target", ()),
                                                         np.asarray(u.get("table2", np.zeros((0, 3))))[:, 0])
             if np.any(np.isfinite(v))]
    if rows:
        fig = Figure(figsize=(12, 6))
        ax = fig.subplots()
        groups = a["actions"] + ["average"]
        width = 0.8 / len(rows)
        colours = _colours(len(rows))
        missing = []
        for k, (name, per, avg, hatch) in enumerate(rows):
            vals = np.append(per, avg)
            x = np.arange(len(groups)) + (k - (len(rows) - 1) / 2) * width
            ax.bar(x, np.nan_to_num(vals), width, label=name, color=colours[k], hatch=hatch)
            # an undefined cell is marked where its bar would stand, not left as a silent gap
            gone = ~np.isfinite(vals)
            ax.plot(x[gone], np.zeros(gone.sum()), "x", color="k", ms=4)
            missing += [groups[i] for i in np.flatnonzero(gone[:-1])]
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xticks(np.arange(len(groups)), groups)
        ax.set(ylabel=f"average bf (n = {cfg.bf_sizes[0]}..{cfg.bf_sizes[1]})", title=f"{s0.upper()} - average bootstrap factors")
        if missing:
            ax.set_xlabel("x: not measurable (NB at chance over too many sizes; Table II gives the reason) in "
                          + ", ".join(sorted(set(missing), key=groups.index)))
        # below the axes: the legend of 15 rows would cover the tallest bars
        ax.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12 if not missing else -0.18))
        save(fig, F.FIG_AVERAGE_BF)
    else:  # say why the figure is empty rather than leave it out (tiny runs: no row is measurable)
        fig = Figure(figsize=(8, 2.5))
        ax = fig.subplots()
        ax.axis("off")
        ax.text(0.5, 0.5, f"{s0.upper()}: no bootstrap-factor row is measurable in this run\n(too few test scenes "
                f"or sizes with NB above chance; Table II gives each row's reason)", ha="center", va="center")
        save(fig, F.FIG_AVERAGE_BF)

    # Fig. 11: correlation matrices
    fig = Figure(figsize=(5.5 * len(spaces), 5))
    axs = fig.subplots(1, len(spaces), squeeze=False)
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
    save(fig, F.FIG_CORRELATION)

    # Fig. 12: best category above each threshold, averaged over affordances
    th = a["thresholds"]
    if np.any(np.isfinite(th["overall_curve"])):
        fig = Figure(figsize=(7, 4.5))
        ax = fig.subplots()
        styles = ("-", "--", ":", "-.")
        for k, (t, c, n) in enumerate(zip(th["T"], th["best_curve"], th["count"])):
            if n == 0 or not np.any(np.isfinite(c)):  # a legend entry without a line misleads
                ax.plot([], [], " ", label=f"T = {t:g}: no category built")
                continue
            # distinct styles and widths: thresholds that keep the same best category coincide
            ax.plot(a["sizes"], c, linestyle=styles[k % 4], lw=2.4 - 0.5 * (k % 3),
                    label=f"best category, T = {t:g} ({n} built)")
        ax.plot(a["sizes"], th["overall_curve"], "k--", label="overall average (all categories)")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set(xlabel="training samples n", ylabel="bootstrap factor", title=f"{s0.upper()} - correlation thresholds")
        _logx(ax, a["sizes"])
        ax.legend(fontsize=7)
        save(fig, F.FIG_THRESHOLDS)
    return written


def dataset_figure(infos: Mapping[str, Mapping[str, Any]], out: Path) -> Path:
    """``fig_datasets.png``: positive rate of every rollout per action and spatial relation,
    from ``{action: relaff_jax.data.info(DIR)}``."""
    acts = list(infos)
    fig = Figure(figsize=(10, 3.8))
    ax = fig.subplots()
    width = 0.8 / len(RELATIONS)
    for k, r in enumerate(RELATIONS):
        vals = [infos[a]["rollouts_positive_rate_by_relation"][r] for a in acts]
        ax.bar(np.arange(len(acts)) + (k - 1) * width, [np.nan if v is None else v for v in vals], width, label=r)
    ax.set_xticks(np.arange(len(acts)), acts)
    ax.set(ylabel="positive rate (all rollouts)", ylim=(0, 1), title="What each action does in each spatial relation")
    ax.legend(fontsize=8)
    return save_png(fig, out, dpi=100)
