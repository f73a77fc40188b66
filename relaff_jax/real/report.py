"""The report section of the sim-to-real study: figures like paper Figs. 14-15, claims a-d.

Takes the raw results of ``experiments.run_space`` per space (``{space: dict of arrays}``),
their summaries (``experiments.summarise``) and context (labels counts, sensor, sim data
summary); ``write_report(folder, raw, summary, context)`` writes, atomically,
``fig14_<space>.png`` (box plots of SIM_fair, SIM_full, REAL, SIM_fair -> REAL,
SIM_full -> REAL over the repetitions), ``fig15_<space>.png`` (top: REAL and REAL <- SIM
learning curves, mean +- std; bottom: the bootstrap factor, sizes where it is undefined
marked and counted), ``results.json`` (everything) and ``results.md`` (tables and the claims
with verdicts). ``claims(summary)`` states each claim with the test applied to the numbers;
the thresholds are fixed here, before any result, and never tuned to the paper.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from relaff_jax import io as rio

GOOD = 0.75  # "good performance": mean accuracy at least this, and the 95 % interval above chance
MARGIN = 0.10  # "not a large margin" / "competitive": within 10 accuracy points
BOXES = (("sim_fair", "SIM_fair"), ("sim_full", "SIM_full"), ("real", "REAL"),
         ("fair_to_real", "SIM_fair->REAL"), ("full_to_real", "SIM_full->REAL"))


def _figure(rows: int, size: tuple[float, float], sharex: bool = False):
    """A matplotlib ``Figure`` on the Agg canvas (never pyplot: no global state) and its axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, 1, sharex=sharex)


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


def fig14(raw: dict, space: str) -> bytes:
    fig, ax = _figure(1, (7, 4))
    data = [np.asarray(raw[k]) for k, _ in BOXES]
    box = ax.boxplot(data, patch_artist=True)
    ax.set_xticks(range(1, len(BOXES) + 1), [n for _, n in BOXES], rotation=15)
    for patch, (k, _) in zip(box["boxes"], BOXES):
        patch.set_facecolor("tab:green" if k == "real" else "tab:blue")
    ax.axhline(0.5, color="0.5", ls=":", lw=1)
    ax.set_ylabel("accuracy (balanced for ->REAL)")
    ax.set_ylim(0.0, 1.02)
    ax.set_title(f"beside vs on top, {space.upper()} space, {len(data[0])} repetitions")
    fig.tight_layout()
    return _png(fig)


def fig15(summary: dict, space: str) -> bytes:
    n = np.asarray(summary["sizes"])
    fig, (top, bot) = _figure(2, (7, 6), sharex=True)
    for key, label, colour in (("curve_sl", "REAL", "tab:green"), ("curve_bl", "REAL<-SIM", "tab:blue")):
        m, s = np.asarray(summary[key]), np.asarray(summary[key + "_std"])
        top.plot(n, m, color=colour, label=label)
        top.fill_between(n, m - s, m + s, color=colour, alpha=0.15)
    top.axhline(0.5, color="0.5", ls=":", lw=1)
    top.set_ylabel("accuracy")
    top.legend(loc="lower right")
    top.set_title(f"real learning curves, {space.upper()} space (mean +- std)")
    bf = np.array([np.nan if v is None else v for v in summary["bf"]], float)
    bot.plot(n, bf, "o-", color="tab:blue", label="bootstrap factor")
    und = ~np.isfinite(bf)
    if und.any():
        bot.plot(n[und], np.ones(und.sum()), "x", color="tab:red",
                 label=f"undefined (P_sl <= 0.5): {int(und.sum())} sizes")
    bot.axhline(1.0, color="0.5", ls=":", lw=1)
    bot.set_xlabel("real training samples n")
    bot.set_ylabel("bf")
    bot.legend(loc="upper right")
    fig.tight_layout()
    return _png(fig)


def claims(summary: dict) -> list[dict]:
    """Claims a-d of paper VI-C (and the VI-B observations) on the PCA space, with verdicts."""
    acc = summary["pca"]["accuracy"]
    real, fair, full = acc["real"], acc["sim_fair"], acc["sim_full"]
    s2r = acc["full_to_real"]
    good = lambda a: a["mean"] >= GOOD and a["ci95"][0] > 0.5
    bfe = summary["pca"]["bf_early_mean"]
    out = [
        dict(claim="a) PCA states give good results on noisy real data",
             test=f"REAL mean >= {GOOD} and its 95 % interval above 0.5",
             numbers=f"REAL {real['mean']:.3f} (std {real['std']:.3f}, CI {real['ci95'][0]:.3f}-{real['ci95'][1]:.3f})",
             holds=bool(good(real))),
        dict(claim="b) real and simulation classifiers do not differ by a large margin",
             test=f"abs(SIM_fair - REAL) <= {MARGIN}",
             numbers=f"SIM_fair {fair['mean']:.3f}, REAL {real['mean']:.3f}",
             holds=bool(abs(fair["mean"] - real["mean"]) <= MARGIN)),
        dict(claim="c) simulation-trained classifiers apply to real scenes (good, competitive with REAL)",
             test=f"SIM_full->REAL good and >= REAL - {MARGIN}",
             numbers=f"SIM_full->REAL {s2r['mean']:.3f} (std {s2r['std']:.3f}), REAL {real['mean']:.3f}",
             holds=bool(good(s2r) and s2r["mean"] >= real["mean"] - MARGIN)),
        dict(claim="d) bootstrapping from simulation helps real learning early",
             test="mean bootstrap factor over the early sizes > 1",
             numbers=f"bf {bfe:.3f} over n = {summary['pca']['bf_early_sizes']}; undefined at n = "
                     f"{summary['pca']['bf_undefined_sizes']}",
             holds=bool(np.isfinite(bfe) and bfe > 1.0)),
        dict(claim="VI-B: real classifiers lower and more variable than simulation ones",
             test="REAL mean < SIM_fair mean and REAL std > SIM_fair std",
             numbers=f"REAL {real['mean']:.3f} +- {real['std']:.3f}; SIM_fair {fair['mean']:.3f} +- {fair['std']:.3f}; "
                     f"SIM_full {full['mean']:.3f} +- {full['std']:.3f}",
             holds=bool(real["mean"] < fair["mean"] and real["std"] > fair["std"])),
        dict(claim="VI-B: SIM->REAL drops significantly from SIM",
             test="SIM_full->REAL interval entirely below SIM_full's",
             numbers=f"SIM_full {full['mean']:.3f} (CI {full['ci95'][0]:.3f}-{full['ci95'][1]:.3f}); "
                     f"SIM_full->REAL {s2r['mean']:.3f} (CI {s2r['ci95'][0]:.3f}-{s2r['ci95'][1]:.3f})",
             holds=bool(s2r["ci95"][1] < full["ci95"][0])),
    ]
    return out


def markdown(summary: dict, context: dict) -> str:
    lines = ["# Sim-to-real: relation classifiers (paper section VI)", ""]
    for key, value in context.items():
        lines.append(f"- {key}: {value}")
    for space, s in summary.items():
        sp = s["split"]
        lines += ["", f"## {space.upper()} space ({s['reps']} repetitions)", "",
                  f"Real split per class: pool {sp['real_pool_per_class']}, train {sp['real_train_per_class']}, "
                  f"test {sp['real_test_per_class']}; SIM_fair trains on {sp['sim_fair_train']}, SIM_full on "
                  f"{sp['sim_full_train']} (each tested on as many other simulated scenes).", "",
                  "| condition | mean | std | 95 % CI of the mean |", "|---|---:|---:|---|"]
        for k, name in BOXES:
            a = s["accuracy"][k]
            lines.append(f"| {name} | {a['mean']:.3f} | {a['std']:.3f} | {a['ci95'][0]:.3f}-{a['ci95'][1]:.3f} |")
        if s.get("sim_only"):
            lines += ["", "Simulation only (SIM -> SIM, every pair of relations):", "",
                      "| relations | train = test scenes | mean | std | 95 % CI |", "|---|---:|---:|---:|---|"]
            for k, a in s["sim_only"].items():
                lines.append(f"| {k.replace('_vs_', ' vs ')} | {a['n_train']} | {a['mean']:.3f} | {a['std']:.3f} | "
                             f"{a['ci95'][0]:.3f}-{a['ci95'][1]:.3f} |")
        lines += ["", "| n | REAL | REAL<-SIM | bf |", "|---:|---:|---:|---:|"]
        for n, a, b, f in zip(s["sizes"], s["curve_sl"], s["curve_bl"], s["bf"]):
            lines.append(f"| {n} | {a:.3f} | {b:.3f} | {'undefined' if f is None else f'{f:.3f}'} |")
        lines += ["", f"bf undefined (P_sl <= 0.5) at n = {s['bf_undefined_sizes']} "
                      f"({len(s['bf_undefined_sizes'])} of {len(s['sizes'])} sizes); mean bf over n = "
                      f"{s['bf_early_sizes']}: {s['bf_early_mean']:.3f}"]
    if "pca" in summary:
        lines += ["", "## Claims of section VI-C (PCA space)", "", "| claim | test | numbers | verdict |",
                  "|---|---|---|---|"]
        for c in claims(summary):
            lines.append(f"| {c['claim']} | {c['test']} | {c['numbers']} | {'holds' if c['holds'] else 'does not hold'} |")
    return "\n".join(lines) + "\n"


def write_report(folder: str | Path, raw: dict, summary: dict, context: dict) -> list[Path]:
    """Write figures, ``results.json`` and ``results.md`` into ``folder``; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for space in summary:
        for name, data in ((f"fig14_{space}.png", fig14(raw[space], space)),
                           (f"fig15_{space}.png", fig15(summary[space], space))):
            rio.atomic_write_bytes(folder / name, data)
            paths.append(folder / name)
    doc = dict(context=context, summary=summary, claims=claims(summary) if "pca" in summary else [])
    rio.atomic_write_json(folder / "results.json", doc)
    rio.atomic_write_text(folder / "results.md", markdown(summary, context))
    return paths + [folder / "results.json", folder / "results.md"]
