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
from relaff_jax.learn.experiment import PAPER_TABLE2, TABLE2_ROWS, analyse, categories_per_threshold, layout, load_results

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
    from relaff_jax.learn.experiment import average_bf

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


# ------------------------------------------------------------- full report (report.md / .html)
#
# ``write_full_report`` adds, on top of ``write_report``'s tables and figures, the reader's
# report of a whole run: dataset statistics, example scenes, every figure, Table II beside the
# paper's, the correlation clusters, the threshold study, best-after-ten, and a generated
# summary of which of the paper's findings the run reproduces. The document is built once as
# a list of blocks and rendered twice: ``report.md`` (images as relative links) and
# ``report.html`` (one self-contained page, images base64-embedded).

import base64
import dataclasses
import html as _html
import re
import time


@dataclasses.dataclass(frozen=True)
class FindingRules:
    """How the generated summary decides whether a paper finding is reproduced."""

    small_n: int = 10  # "small n": the training sizes up to this one
    well_above: float = 1.25  # "well above 1": an average bootstrap factor of at least this
    close: float = 0.9  # "close to" / "costs little": at least this fraction of the reference


def _nanmean(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.mean(x[np.isfinite(x)])) if np.any(np.isfinite(x)) else float("nan")


def _row(a: Mapping[str, Any], name: str) -> float:
    """Table II average (over affordances) of row ``name``."""
    return float(a["table2"][TABLE2_ROWS.index(name), 0])


def _verdict(ok: bool | None) -> str:
    return {True: "reproduced", False: "not reproduced", None: "not measurable"}[ok]


def _decide(cond, *values) -> bool | None:
    return None if not all(np.isfinite(v) for v in values) else bool(cond)


def findings(an: Mapping[str, Mapping[str, Any]], cfg, rules: FindingRules = FindingRules()) -> list[dict[str, Any]]:
    """Which of the paper's findings this run reproduces, each with the numbers behind it.

    ``an``: ``{space: analyse(...)}``. Returns a list of dicts ``{id, finding, paper, rule,
    numbers, values, reproduced}`` with ``reproduced`` True, False or None (not measurable:
    a space or condition was not run, or a number is undefined).
    """
    out: list[dict[str, Any]] = []

    def add(fid, finding, paper, rule, numbers, values, ok):
        out.append({"id": fid, "finding": finding, "paper": paper, "rule": rule, "numbers": numbers,
                    "values": values, "reproduced": ok})

    pca, rhf = an.get("pca"), an.get("rhf")
    # 1. RHF learns faster than PCA at small n (paper Fig. 7)
    rule = f"mean NB accuracy over the affordances, averaged over the sizes n <= {rules.small_n}, is higher in RHF than in PCA"
    if pca is not None and rhf is not None:
        small = [n for n in pca["sizes"] if n <= rules.small_n and n in rhf["sizes"]]
        p = [_nanmean(pca["mean"][:, 0, pca["sizes"].index(n)]) for n in small]
        r = [_nanmean(rhf["mean"][:, 0, rhf["sizes"].index(n)]) for n in small]
        diff = _nanmean(np.subtract(r, p)) if small else float("nan")
        numbers = (f"NB accuracy at n = {', '.join(map(str, small))}: PCA {', '.join(_fmt(v) for v in p)}; "
                   f"RHF {', '.join(_fmt(v) for v in r)}; mean difference RHF - PCA {diff:+.3f}")
        add("rhf_faster", "RHF learns faster than PCA at small n", "Fig. 7: RHF above PCA for the first samples",
            rule, numbers, {"sizes": small, "pca": p, "rhf": r, "difference": diff}, _decide(diff > 0, diff))
    else:
        add("rhf_faster", "RHF learns faster than PCA at small n", "Fig. 7: RHF above PCA for the first samples",
            rule, "needs both the PCA and the RHF sweep", {}, None)
    a = pca if pca is not None else next(iter(an.values()))
    space = "PCA" if pca is not None else next(iter(an)).upper()
    db1, cbn, dbn = _row(a, "DB1 best"), _row(a, "CBn"), _row(a, "DBn")
    p2 = dict(zip(("avg", "min", "max"), PAPER_TABLE2["DB1 best"])), dict(zip(("avg", "min", "max"), PAPER_TABLE2["CBn"]))
    # 2. DB1 best and CBn well above 1; with no category kept at CBn's threshold CBn is NB
    # itself (bf 1 by construction), so the finding is not measurable rather than failed
    th_t = [float(t) for t in a["thresholds"]["T"]]
    t_cbn = float(cfg.cbn_threshold)
    cbn_built = int(a["thresholds"]["count"][th_t.index(t_cbn)])
    cbn_note = f" (no category kept at T = {t_cbn:g}: CBn is NB)" if cbn_built == 0 else ""
    add("bootstrapping_helps", "DB1 best and CBn are well above 1",
        f"Table II: DB1 best {p2[0]['avg']:.3f}, CBn {p2[1]['avg']:.3f}",
        f"Table II ({space}) average of both rows >= {rules.well_above}",
        f"{space} Table II average: DB1 best {_fmt(db1)}, CBn {_fmt(cbn)}{cbn_note}",
        {"db1_best": db1, "cbn": cbn, "cbn_categories": cbn_built},
        _decide(db1 >= rules.well_above and cbn >= rules.well_above, db1,
                cbn if cbn_built != 0 else float("nan")))
    # 3. DBn below DB1 best
    add("dbn_below_db1", "DBn is below DB1 best", f"Table II: DBn {PAPER_TABLE2['DBn'][0]:.3f} < DB1 best {p2[0]['avg']:.3f}",
        f"Table II ({space}) average of DBn < that of DB1 best",
        f"{space} Table II average: DBn {_fmt(dbn)}, DB1 best {_fmt(db1)}",
        {"dbn": dbn, "db1_best": db1}, _decide(dbn < db1, dbn, db1))
    # 4. pruning at T = 0.5 costs little (threshold study, Fig. 12)
    th = a["thresholds"]
    ts = [float(t) for t in th["T"]]
    t_lo, t_hi = min(ts), (0.5 if 0.5 in ts else max(ts))
    avg_t = {t: _avg(c, a["sizes"], cfg) for t, c in zip(ts, th["best_curve"])}
    cnt = dict(zip(ts, th["count"]))
    lo, hi = avg_t[t_lo], avg_t[t_hi]
    k = len(a["actions"]) * (len(a["actions"]) - 1) // 2
    add("pruning_cheap", f"pruning categories at T = {t_hi:g} costs little",
        "Fig. 12: the best category above T = 0.5 is about as good as the best of all categories",
        f"average bf of the best category built at T = {t_hi:g} >= {rules.close} x that at T = {t_lo:g}",
        f"best category's average bf (mean over affordances): T = {t_lo:g} {_fmt(lo)} ({cnt[t_lo]} of {k} categories built), "
        f"T = {t_hi:g} {_fmt(hi)} ({cnt[t_hi]} built); ratio {_fmt(hi / lo if np.isfinite(lo) and lo else float('nan'), 2)}",
        {"T": [t_lo, t_hi], "avg_bf": [lo, hi], "built": [int(cnt[t_lo]), int(cnt[t_hi])]},
        _decide(hi >= rules.close * lo, lo, hi))
    # 5. best after ten close to best
    pairs = {fam: (_row(a, f"{fam} best after ten"), _row(a, f"{fam} best")) for fam in ("DB1", "CB1")}
    ratio = {fam: (t / b if np.isfinite(b) and b else float("nan")) for fam, (t, b) in pairs.items()}
    add("best_after_ten", "choosing the source after ten samples is close to the best choice",
        "Table II: best after ten 2.751 vs best 2.819 (DB1), 2.802 vs 2.889 (CB1)",
        f"Table II ({space}) average of 'best after ten' >= {rules.close} x 'best', for DB1 and CB1",
        "; ".join(f"{fam}: after ten {_fmt(t)} vs best {_fmt(b)} (ratio {_fmt(ratio[fam], 2)})" for fam, (t, b) in pairs.items()),
        {fam: {"after_ten": t, "best": b, "ratio": ratio[fam]} for fam, (t, b) in pairs.items()},
        _decide(all(r >= rules.close for r in ratio.values()), *ratio.values()))
    return out


def correlation_clusters(corr: np.ndarray, actions, threshold: float) -> list[list[str]]:
    """Groups of affordances linked by a chain of predictor correlations above ``threshold``
    (connected components; the categories the heuristic builds at that threshold), largest
    first; singletons included."""
    corr = np.asarray(corr, dtype=float)
    n = len(actions)
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if corr[i, j] > threshold:
                parent[root(i)] = root(j)
    groups: dict[int, list[str]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(str(actions[i]))
    return sorted(groups.values(), key=lambda g: (-len(g), [list(actions).index(x) for x in g]))


# -------------------------------------------------------------------------- documents


def _inline_html(text: str) -> str:
    s = _html.escape(text, quote=False)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)


def render_markdown(blocks: list[tuple]) -> str:
    """Markdown of a block list: ``("h", level, text)``, ``("p", text)``, ``("ul", [items])``,
    ``("table", header, rows)``, ``("img", relative_path, caption)``."""
    lines: list[str] = []
    for b in blocks:
        kind = b[0]
        if kind == "h":
            lines += ["#" * b[1] + " " + b[2], ""]
        elif kind == "p":
            lines += [b[1], ""]
        elif kind == "ul":
            lines += [f"- {x}" for x in b[1]] + [""]
        elif kind == "table":
            header, rows = b[1], b[2]
            lines.append("| " + " | ".join(header) + " |")
            lines.append("|" + "---|" * len(header))
            lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
            lines.append("")
        elif kind == "img":
            lines += [f"![{b[2]}]({b[1]})", "", f"*{b[2]}*", ""]
        else:
            raise ValueError(f"unknown block kind {kind!r}")
    return "\n".join(lines)


_CSS = """body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}table{border-collapse:collapse;margin:0.6em 0 1.2em;font-size:0.9em}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f2f2f2}td:first-child,th:first-child
{text-align:left}img{max-width:100%;border:1px solid #eee}figure{margin:1em 0}figcaption{font-size:0.85em;color:#555}
code{background:#f4f4f4;padding:0 3px}h1,h2,h3{border-bottom:1px solid #eee;padding-bottom:0.2em}"""


def render_html(blocks: list[tuple], base: Path, title: str) -> str:
    """One self-contained HTML page of a block list; images under ``base`` are embedded."""
    body: list[str] = []
    for b in blocks:
        kind = b[0]
        if kind == "h":
            body.append(f"<h{b[1]}>{_inline_html(b[2])}</h{b[1]}>")
        elif kind == "p":
            body.append(f"<p>{_inline_html(b[1])}</p>")
        elif kind == "ul":
            body.append("<ul>" + "".join(f"<li>{_inline_html(x)}</li>" for x in b[1]) + "</ul>")
        elif kind == "table":
            head = "".join(f"<th>{_inline_html(str(c))}</th>" for c in b[1])
            rows = "".join("<tr>" + "".join(f"<td>{_inline_html(str(c))}</td>" for c in r) + "</tr>" for r in b[2])
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")
        elif kind == "img":
            data = base64.b64encode((base / b[1]).read_bytes()).decode("ascii")
            body.append(f'<figure><img alt="{_html.escape(b[2])}" src="data:image/png;base64,{data}">'
                        f"<figcaption>{_inline_html(b[2])}</figcaption></figure>")
        else:
            raise ValueError(f"unknown block kind {kind!r}")
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{_html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")


# ----------------------------------------------------------------------- dataset parts


def _rate(r) -> str:
    return "-" if r is None else f"{100 * r:.0f} %"


def dataset_blocks(infos: Mapping[str, Mapping[str, Any]], fig: str | None) -> list[tuple]:
    """Dataset statistics per action from ``dataset.info`` dicts."""
    from relaff_jax.data.dataset import RELATIONS

    blocks: list[tuple] = [("h", 2, "Datasets"), (
        "p", "Per action: the balanced selection (half positive; negatives matched to the positives' distribution of the "
        "distance between the objects' centres of gravity) and every rollout simulated to find it. Positive rates by "
        "the settled spatial relation, over all rollouts (what the action does in each relation) and, with counts, "
        "over the selected samples.")]
    header = ["action", "samples", "rollouts", "rollout pos. rate"] + [f"rollouts {r}" for r in RELATIONS] \
        + [f"selected {r} (n)" for r in RELATIONS] + ["borrowed", "unseen"]
    rows = []
    for action, d in infos.items():
        sel = [f"{_rate(d['positive_rate_by_relation'][r])} ({d['count_by_relation'][r]['n']})" for r in RELATIONS]
        feats = d.get("features") or {}
        rows.append([action, d["n"], d["rollouts"], _rate(d["rollouts_positive_rate"])]
                    + [_rate(d["rollouts_positive_rate_by_relation"][r]) for r in RELATIONS] + sel
                    + [d.get("borrowed"), feats.get("unseen_samples", "-")])
    blocks.append(("table", header, rows))
    if fig:
        blocks.append(("img", fig, "Positive rate of every rollout by spatial relation, per action"))
    return blocks


def dataset_figure(infos: Mapping[str, Mapping[str, Any]], out: Path) -> Path:
    from relaff_jax.data.dataset import RELATIONS

    plt = _plt()
    acts = list(infos)
    fig, ax = plt.subplots(figsize=(10, 3.8))
    width = 0.8 / len(RELATIONS)
    for k, r in enumerate(RELATIONS):
        vals = [infos[a]["rollouts_positive_rate_by_relation"][r] for a in acts]
        ax.bar(np.arange(len(acts)) + (k - 1) * width, [np.nan if v is None else v for v in vals], width, label=r)
    ax.set_xticks(np.arange(len(acts)), acts)
    ax.set(ylabel="positive rate (all rollouts)", ylim=(0, 1), title="What each action does in each spatial relation")
    ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    rio.atomic_write_bytes(out, buf.getvalue())
    return out


def example_scenes(data_dirs: Mapping[str, str | os.PathLike], out: Path, per_action: int) -> list[tuple[str, str, str]]:
    """Draw ``per_action`` example scenes per action (positives and negatives alternating, in
    rollout order) with ``features.show_scene``; returns ``(action, file name, caption)``.
    Datasets without the scene fields (``pair``, ``qpos_settled``) get none."""
    from relaff_jax.data.dataset import load_dataset

    if per_action < 1:
        return []
    import jax

    from relaff_jax.perception.core import from_sim as F
    from relaff_jax.sim import world as wd

    world = None
    shown: list[tuple[str, str, str]] = []
    for action, d in data_dirs.items():
        ds = load_dataset(d, features=False)
        if not {"pair", "qpos_settled"} <= set(ds):
            continue
        world = world or wd.build_world()
        label = np.asarray(ds["label"], bool)
        pos, neg = list(np.flatnonzero(label)), list(np.flatnonzero(~label))
        order = [x for pair in zip(pos, neg) for x in pair] + pos[len(neg):] + neg[len(pos):]
        for i in order[:per_action]:
            rid = int(ds["rollout_id"][i]) if "rollout_id" in ds else int(ds["rollout"][i])
            caption = (f"{action}: {ds['toy'][i]} + {ds['other'][i]}, {ds['relation'][i]}, "
                       f"{'positive' if label[i] else 'negative'} (sample {i})")
            name = f"{action}_{i:05d}.png"
            F.show_scene(world, int(ds["pair"][i]), np.asarray(ds["qpos_settled"][i]), out / name,
                         jax.random.PRNGKey(rid % 2**31), title=caption)
            shown.append((action, f"{out.name}/{name}", caption))
    return shown


# ---------------------------------------------------------------------------- the report


def _fig_block(out: Path, name: str, caption: str) -> list[tuple]:
    return [("img", name, caption)] if (out / name).exists() else []


def write_full_report(results_dir: str | os.PathLike, out_dir: str | os.PathLike,
                      data_dirs: Mapping[str, str | os.PathLike] | None = None,
                      run_info: Mapping[str, Any] | None = None, examples_per_action: int = 2,
                      rules: FindingRules = FindingRules()) -> Path:
    """Write ``report.md``, a self-contained ``report.html`` and ``findings.json`` (plus every
    file of ``write_report``) for an experiment folder and, optionally, its dataset folders
    ``{action: DIR}`` (statistics, example scenes) and a run log (``run_info``: preset, seed,
    timings). Returns ``out_dir``."""
    out = Path(out_dir)
    write_report(results_dir, out)
    res = load_results(results_dir)
    cfg = res["config"]
    spaces = list(res["meta"]["spaces"])
    an = {s: analyse(res[s], cfg) for s in spaces}
    main = "pca" if "pca" in an else spaces[0]
    a = an[main]
    found = findings(an, cfg, rules)
    blocks: list[tuple] = [("h", 1, "Bootstrapping relational affordances: reproduction report")]
    intro = (f"Generated {time.strftime('%Y-%m-%d %H:%M')} from `{Path(results_dir)}`: actions {', '.join(res['meta']['actions'])}; "
             f"spaces {', '.join(s.upper() for s in spaces)}; seed {res['meta']['seed']}; training sizes "
             f"{', '.join(map(str, cfg.sizes)) if len(cfg.sizes) <= 12 else f'{min(cfg.sizes)}..{max(cfg.sizes)}'}; "
             f"repetitions PCA {cfg.reps_pca}, RHF {cfg.reps_rhf}.")
    if run_info:
        intro += f" Preset `{run_info.get('preset')}`."
    blocks += [("p", intro)]
    if any(str(d).startswith("synthetic") for d in res["meta"].get("data", [])):
        blocks.append(("p", "**These results come from synthetic features** (`relaff experiment --synthetic`): they test "
                            "the pipeline and say nothing about the paper."))

    # summary of findings
    blocks += [("h", 2, "Which of the paper's findings this run reproduces"),
               ("table", ["finding", "paper", "this run", "verdict"],
                [[f["finding"], f["paper"], f["numbers"], f"**{_verdict(f['reproduced'])}**"] for f in found]),
               ("p", "Rules: " + "; ".join(f"{f['finding']}: {f['rule']}" for f in found) + ".")]
    n_ok = sum(f["reproduced"] is True for f in found)
    blocks.append(("p", f"{n_ok} of {len(found)} findings reproduced, "
                        f"{sum(f['reproduced'] is False for f in found)} not, {sum(f['reproduced'] is None for f in found)} not measurable."))

    # datasets and example scenes
    infos = {}
    if data_dirs:
        from relaff_jax.data.dataset import info

        infos = {act: info(d) for act, d in data_dirs.items()}
        dataset_figure(infos, out / "fig_datasets.png")
        blocks += dataset_blocks(infos, "fig_datasets.png")
        ex = example_scenes(data_dirs, out / "examples", examples_per_action)
        if ex:
            blocks += [("h", 2, "Example scenes"),
                       ("p", "What the robot saw (`features.show_scene`): the simulated Kinect depth image, its "
                             "colour segmentation into the toy and the other object, and the two objects' voxel clouds "
                             "with their PCA frames.")]
            blocks += [("img", path, cap) for _, path, cap in ex]

    # learning curves
    blocks += [("h", 2, "Learning curves")]
    blocks += _fig_block(out, "fig06_nb_learning.png", f"Non-bootstrapped learning curves ({main.upper()}), paper Fig. 6")
    blocks += _fig_block(out, "fig07_nb_spaces.png", "NB per affordance in PCA and RHF, paper Fig. 7")
    blocks += _fig_block(out, "fig08_db1_best.png", "NB and the best DB1 learner per affordance, paper Fig. 8")
    blocks += _fig_block(out, "fig09_db1_best_bf.png", "Bootstrap factor of the best DB1 learner (average over the shaded n), paper Fig. 9")

    # Table II
    for space in spaces:
        x = an[space]
        paper = space == "pca"
        header = ["method", "avg", "min", "max"] + (["paper avg", "paper min", "paper max"] if paper else [])
        rows = [[name] + [_fmt(v) for v in row] + ([_fmt(v) for v in PAPER_TABLE2[name]] if paper else [])
                for name, row in zip(TABLE2_ROWS, x["table2"])]
        blocks += [("h", 2, f"Table II ({space.upper()})"),
                   ("p", f"Average bootstrap factor over n = {cfg.bf_sizes[0]}..{cfg.bf_sizes[1]}, avg / min / max over the "
                         f"{len(x['actions'])} affordances" + (", beside the paper's Table II." if paper else
                                                               " (the paper has no RHF table).")),
                   ("table", header, rows)]
        rows = [[name] + [_fmt(v, 2) for v in r] for name, r in zip(TABLE2_ROWS, x["table2_per_target"])
                if np.any(np.isfinite(r))]
        blocks += [("p", "Per affordance (paper Fig. 10 as numbers):"),
                   ("table", ["method"] + list(x["actions"]), rows)]
    blocks += _fig_block(out, "fig10_average_bf.png", "Average bootstrap factor per method and affordance, paper Fig. 10")

    # best after ten
    conds = a["conditions"]
    lay = layout(len(a["actions"]), len(cfg.thresholds))
    rows = []
    for fam in ("db1", "cb1"):
        if np.all(np.isnan(a["mean"][:, lay[fam.upper()]])):
            continue
        for ti, t in enumerate(a["actions"]):
            b, k = a[f"best_{fam}"][ti], a[f"ten_{fam}"][ti]
            rows.append([fam.upper(), t, conds[b].split(":")[1], _fmt(a["avg_bf"][ti, b]), conds[k].split(":")[1],
                         _fmt(a["avg_bf"][ti, k]), "yes" if b == k else "no"])
    if rows:
        blocks += [("h", 2, "Best after ten"),
                   ("p", f"'Best' is the source with the highest mean accuracy over n = {cfg.best_sizes[0]}..{cfg.best_sizes[1]}; "
                         f"'after ten' is the one an agent would keep after {cfg.select_size} samples ({main.upper()})."),
                   ("table", ["family", "target", "best source", "avg bf", "after-ten source", "avg bf", "same"], rows)]

    # correlation and clusters
    blocks += [("h", 2, "Correlation of the predictors and its clusters")]
    for space in spaces:
        corr = res[space]["corr"]
        acts = an[space]["actions"]
        cl = correlation_clusters(corr, acts, cfg.cbn_threshold)
        groups = [g for g in cl if len(g) > 1]
        blocks.append(("p", f"{space.upper()}: affordances linked by correlations above T = {cfg.cbn_threshold:g}: "
                            + ("; ".join("{" + ", ".join(g) + "}" for g in groups) if groups else "none")
                            + (f"; alone: {', '.join(g[0] for g in cl if len(g) == 1)}" if any(len(g) == 1 for g in cl) else "") + "."))
        blocks.append(("table", [""] + [SHORT.get(x, x) for x in acts],
                       [[SHORT.get(x, x)] + [f"{v:+.2f}" for v in corr[i]] for i, x in enumerate(acts)]))
    blocks += _fig_block(out, "fig11_correlation.png", "Correlation of the source predictors' outputs, paper Fig. 11")

    # threshold study
    th = a["thresholds"]
    if np.any(np.isfinite(th["overall_curve"])):
        k = len(a["actions"]) * (len(a["actions"]) - 1) // 2
        counts = categories_per_threshold(res[main]["corr"], cfg.thresholds)
        rows = [[f"{t:g}", counts[f"{t:g}"]["built"], _fmt(_avg(c, a["sizes"], cfg)),
                 _fmt(_nanmean(a["avg_bf"][:, lay["CBn"][i]]))]
                for i, (t, c) in enumerate(zip(th["T"], th["best_curve"]))]
        rows.append(["all categories (overall average)", k, _fmt(_avg(th["overall_curve"], a["sizes"], cfg)), "-"])
        blocks += [("h", 2, "Threshold study"),
                   ("p", f"Categories built at each correlation threshold T and the average bf ({main.upper()}, mean over "
                         "affordances) of each affordance's best category among them, and of CBn (all of them together)."),
                   ("table", ["T", f"categories built (of {k})", "best category avg bf", "CBn avg bf"], rows)]
        blocks += _fig_block(out, "fig12_thresholds.png", "Best category above each threshold, paper Fig. 12")

    # the run
    if run_info:
        blocks += [("h", 2, "The run")]
        items = [f"preset `{run_info.get('preset')}`, seed {run_info.get('seed')}"]
        for st, t in (run_info.get("timings") or {}).items():
            items.append(f"{st}: {t:.0f} s" if isinstance(t, (int, float)) else f"{st}: {t}")
        v = run_info.get("versions") or {}
        if v:
            items.append("versions: " + ", ".join(f"{k} {val}" for k, val in v.items() if val))
        blocks.append(("ul", items))

    rio.atomic_write_json(out / "findings.json", _finite({"findings": found, "rules": dataclasses.asdict(rules)}))
    rio.atomic_write_text(out / "report.md", render_markdown(blocks))
    rio.atomic_write_text(out / "report.html", render_html(blocks, out, "relaff_jax reproduction report"))
    return out
