"""The report section of the sim-to-real study: figures like paper Figs. 14-15, claims a-d.

Takes the raw results of ``experiments.run_space`` per space (``{space: dict of arrays}``),
their summaries (``experiments.summarise``) and context (labels counts, sensor, sim data
summary); ``write_report(folder, raw, summary, context)`` writes, atomically,
``fig14_<space>.png`` (box plots of SIM_fair, SIM_full, REAL, SIM_fair -> REAL,
SIM_full -> REAL over the repetitions), ``fig15_<space>.png`` (top: REAL and REAL <- SIM
learning curves, mean +- std; bottom: the bootstrap factor, sizes where it is undefined
marked and counted), ``results.json`` (everything) and ``results.md`` (tables and the claims
with verdicts). With a test folder (``cross_raw``, ``cross``: the same experiments trained on
the training folder and tested on the test folder) the figures come twice (``*_cross.png``),
``results.md`` puts the within-folder and cross-folder figures side by side and the claims are
decided on the cross-folder ones. ``claims(summary)`` states each claim with the test applied
to the numbers and their intervals; the thresholds are fixed here, before any result, and
never tuned to the paper.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from relaff_jax import io as rio
from . import folder as layout

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


def fig14(raw: dict, space: str, where: str = "") -> bytes:
    fig, ax = _figure(1, (7, 4))
    data = [np.asarray(raw[k]) for k, _ in BOXES]
    box = ax.boxplot(data, patch_artist=True)
    ax.set_xticks(range(1, len(BOXES) + 1), [n for _, n in BOXES], rotation=15)
    for patch, (k, _) in zip(box["boxes"], BOXES):
        patch.set_facecolor("tab:green" if k == "real" else "tab:blue")
    ax.axhline(0.5, color="0.5", ls=":", lw=1)
    ax.set_ylabel("accuracy (balanced for ->REAL)")
    ax.set_ylim(0.0, 1.02)
    ax.set_title(f"beside vs on top, {space.upper()} space{where}, {len(data[0])} repetitions")
    fig.tight_layout()
    return _png(fig)


def fig15(summary: dict, space: str, where: str = "") -> bytes:
    n = np.asarray(summary["sizes"])
    fig, (top, bot) = _figure(2, (7, 6), sharex=True)
    for key, label, colour in (("curve_sl", "REAL", "tab:green"), ("curve_bl", "REAL<-SIM", "tab:blue")):
        m, s = np.asarray(summary[key]), np.asarray(summary[key + "_std"])
        top.plot(n, m, color=colour, label=label)
        top.fill_between(n, m - s, m + s, color=colour, alpha=0.15)
    top.axhline(0.5, color="0.5", ls=":", lw=1)
    top.set_ylabel("accuracy")
    top.legend(loc="lower right")
    top.set_title(f"real learning curves, {space.upper()} space{where} (mean +- std)")
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


def _ci(a: dict) -> str:
    sc = a.get("ci95_scenes")
    extra = f"; test scenes resampled {sc[0]:.3f}-{sc[1]:.3f}" if sc else ""
    return f"{a['mean']:.3f} (CI {a['ci95'][0]:.3f}-{a['ci95'][1]:.3f}{extra})"


def _widest(a: dict) -> tuple[float, float]:
    """The interval a claim is decided on: over test scenes when measured (cross-folder), else over repetitions."""
    return tuple(a.get("ci95_scenes") or a["ci95"])


def split_note(sp: dict) -> str:
    """One line saying how the real pairs were split (``summarise``'s ``split``)."""
    kind = sp.get("kind", "pair")
    if kind == "cross":
        b, o = sp["real_test_counts"]
        return (f"Across folders: REAL trains on {sp['real_train_per_class']} pairs per class of the training folder "
                f"(all of its smaller class), every classifier is tested on the test folder's {b} beside + {o} "
                "on_top pairs (balanced accuracy)")
    if kind == "scene":
        return (f"Real split by scene (every pair of a scene on one side, a new grouping per repetition): train "
                f"{sp['real_train_per_class']} per class, test {sp['real_test']} per class")
    return (f"Real split by pair (pairs of one scene may fall on both sides): pool {sp['real_pool_per_class']} "
            f"per class, train {sp['real_train_per_class']}, test {sp['real_test']}")


VERDICTS = ("holds", "does not hold", "undecided", "not measurable")


def decide(iv, bound: float, above: bool) -> str:
    """A claim "x > bound" (``above``) or "x < bound" from the interval ``iv`` of x: holds if
    the whole interval is on the claimed side, does not hold if wholly on the other, else
    undecided; no interval: not measurable. Never decided on a point value."""
    if iv is None or not all(np.isfinite(v) for v in iv):
        return "not measurable"
    lo, hi = iv
    if (lo > bound) if above else (hi < bound):
        return "holds"
    if (hi < bound) if above else (lo > bound):
        return "does not hold"
    return "undecided"


def both(*verdicts: str) -> str:
    """All parts must hold (the order of ``VERDICTS`` after "holds": the worst wins)."""
    for v in ("not measurable", "does not hold", "undecided"):
        if v in verdicts:
            return v
    return "holds"


def _within(iv, lo: float, hi: float) -> str:
    """A claim "lo < x < hi" from the interval of x."""
    if iv is None:
        return "not measurable"
    return both(decide(iv, lo, True), decide(iv, hi, False))


def _iv(x: dict | None, scenes: bool = True):
    if not x:
        return None
    return tuple(x.get("ci95_scenes") or x["ci95"]) if scenes else tuple(x["ci95"])


def _d(x: dict | None) -> str:
    if not x:
        return "-"
    lo, hi = _iv(x)
    return f"{x['mean']:.3f} [{lo:.3f}, {hi:.3f}]"


def claims(summary: dict, space: str = "pca") -> list[dict]:
    """Claims a-d of paper VI-C (and the VI-B observations) in one space, each decided by an
    interval (``decide``: the one over test scenes when measured, across folders, else over
    repetitions): ``verdict`` one of ``VERDICTS``, ``holds`` True / False / None."""
    s = summary[space]
    acc, dif = s["accuracy"], s.get("differences", {})
    real, fair, full = acc["real"], acc["sim_fair"], acc["sim_full"]
    s2r = acc["full_to_real"]
    early = s["bf_early_sizes"]
    defined = [n for n in early if n not in s["bf_undefined_sizes"]]
    bf_iv = s.get("bf_early_ci95_scenes") or s.get("bf_early_ci95")
    d_fair, d_s2r = dif.get("sim_fair-real"), dif.get("full_to_real-real")
    d_std = dif.get("std real-sim_fair")
    lo, hi = (s.get("bf_window") or [early[0] if early else None, early[-1] if early else None])[:2]
    out = [
        dict(claim="a) PCA states give good results on noisy real data" if space == "pca" else
             f"a) {space.upper()} states give good results on noisy real data",
             test=f"REAL's 95 % interval above {GOOD}", numbers=f"REAL {_ci(real)}, std {real['std']:.3f}",
             verdict=decide(_widest(real), GOOD, True)),
        dict(claim="b) real and simulation classifiers do not differ by a large margin",
             test=f"the interval of SIM_fair - REAL (paired repetitions) within +-{MARGIN}",
             numbers=f"SIM_fair {_ci(fair)}, REAL {_ci(real)}; difference {_d(d_fair)}",
             verdict=_within(_iv(d_fair), -MARGIN, MARGIN)),
        dict(claim="c) simulation-trained classifiers apply to real scenes (good, competitive with REAL)",
             test=f"SIM_full->REAL's interval above {GOOD} and that of SIM_full->REAL - REAL above -{MARGIN}",
             numbers=f"SIM_full->REAL {_ci(s2r)} (std {s2r['std']:.3f}), REAL {_ci(real)}; difference {_d(d_s2r)}",
             verdict=both(decide(_widest(s2r), GOOD, True), decide(_iv(d_s2r), -MARGIN, True))),
        dict(claim="d) bootstrapping from simulation helps real learning early",
             test=f"the interval of the mean bootstrap factor over n = {lo}..{hi} above 1 (not measurable unless bf "
                  "is defined at most of those sizes)",
             numbers=f"bf {s['bf_early_mean']:.3f}{_bf_ci(s)} over n = {early}; defined at {len(defined)} of "
                     f"{len(early)}; undefined at n = {s['bf_undefined_sizes']}",
             # P_sl <= 0.5 (the real learner at chance) leaves bf undefined: a mean over the few
             # sizes where it is defined says nothing
             verdict="not measurable" if 2 * len(defined) <= len(early) else decide(bf_iv, 1.0, True)),
        dict(claim="VI-B: real classifiers lower and more variable than simulation ones",
             test="the interval of SIM_fair - REAL above 0 and that of std(REAL) - std(SIM_fair) above 0",
             numbers=f"REAL {real['mean']:.3f} +- {real['std']:.3f}; SIM_fair {fair['mean']:.3f} +- {fair['std']:.3f}; "
                     f"SIM_full {full['mean']:.3f} +- {full['std']:.3f}; SIM_fair - REAL {_d(d_fair)}; "
                     f"std difference {_d(d_std)}",
             verdict=both(decide(_iv(d_fair), 0.0, True), decide(_iv(d_std), 0.0, True))),
        dict(claim="VI-B: SIM->REAL drops significantly from SIM",
             test="SIM_full->REAL interval entirely below SIM_full's",
             numbers=f"SIM_full {_ci(full)}; SIM_full->REAL {_ci(s2r)}",
             verdict="holds" if _widest(s2r)[1] < full["ci95"][0] else
             "does not hold" if _widest(s2r)[0] > full["ci95"][1] else "undecided"),
    ]
    for c in out:
        c["holds"] = {"holds": True, "does not hold": False}.get(c["verdict"])
    return out


def terminal_lines(summary: dict, cross: dict | None = None) -> list[str]:
    """What the study prints: per space and folder setting every accuracy and the window's
    bootstrap factor with their intervals, then each claim's verdict in each space."""
    lines = []
    for where, per in (("within", summary), ("cross", cross or {})):
        for space, s in per.items():
            acc = ", ".join(f"{name} {_ci(s['accuracy'][k])}" for k, name in BOXES)
            w = s.get("bf_window") or [min(s["bf_early_sizes"] or [0]), max(s["bf_early_sizes"] or [0])]
            lines.append(f"{space} {where} ({s['split']['kind']}): {acc}; bf n = {w[0]}..{w[1]} "
                         f"{s['bf_early_mean']:.3f}{_bf_ci(s)}")
    decided = cross or summary
    for space in decided:
        for c in claims(decided, space):
            lines.append(f"{space} claim {c['claim']}: {c['verdict']} ({c['numbers']})")
    return lines


def pair_error_lines(s: dict) -> list[str]:
    """Markdown table of the pairs some classifier got wrong (``experiments.pair_errors``)."""
    if "pair_errors" not in s:  # a summary made before the per-pair arrays were kept
        return []
    rows = s["pair_errors"]
    if not rows:
        return ["", "No real test pair was misclassified in any repetition."]
    names = [n for k, n in BOXES if k in HITS_SHOWN]
    lines = ["", f"Real test pairs some classifier got wrong ({len(rows)}): share of the repetitions that tested "
                 "the pair in which it was wrong (times tested)", "",
             "| scene | pair | relation | " + " | ".join(names) + " |", "|---|---|---|" + "---:|" * len(names)]
    for r in rows:
        cells = ["-" if r["wrong"][k] is None else f"{r['wrong'][k]:.2f} ({r['tested'][k]})" for k in HITS_SHOWN]
        lines.append(f"| {r['scene']} | {r['pair']} | {r['relation']} | " + " | ".join(cells) + " |")
    return lines


HITS_SHOWN = ("real", "fair_to_real", "full_to_real")


def _bf_ci(s: dict) -> str:
    ci, sc = s.get("bf_early_ci95"), s.get("bf_early_ci95_scenes")
    extra = f"; test scenes resampled {sc[0]:.3f}-{sc[1]:.3f}" if sc else ""
    return f" (CI {ci[0]:.3f}-{ci[1]:.3f}{extra})" if ci else ""


def side_by_side(summary: dict, cross: dict) -> list[str]:
    """Markdown rows: each condition within the training folder and across folders, per space."""
    lines = ["| space | condition | within the training folder | across folders (test folder) |", "|---|---|---|---|"]
    for space in summary:
        for k, name in BOXES:
            lines.append(f"| {space.upper()} | {name} | {_ci(summary[space]['accuracy'][k])} | "
                         f"{_ci(cross[space]['accuracy'][k])} |")
        lines.append(f"| {space.upper()} | bf, early n | {summary[space]['bf_early_mean']:.3f}{_bf_ci(summary[space])} | "
                     f"{cross[space]['bf_early_mean']:.3f}{_bf_ci(cross[space])} |")
    return lines


def _space_section(space: str, s: dict, title: str) -> list[str]:
    sp = s["split"]
    lines = ["", f"## {title}{space.upper()} space ({s['reps']} repetitions)", "",
             f"{split_note(sp)}; SIM_fair trains on {sp['sim_fair_train']}, SIM_full on "
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
                  f"{s['bf_early_sizes']}: {s['bf_early_mean']:.3f}{_bf_ci(s)}"]
    return lines + pair_error_lines(s)


def markdown(summary: dict, context: dict, cross: dict | None = None) -> str:
    """``results.md``: context, (with a test folder) the side-by-side table, each space's
    tables within the training folder (and across folders), the claims."""
    lines = ["# Sim-to-real: relation classifiers (paper section VI)", ""]
    for key, value in context.items():
        lines.append(f"- {key}: {value}")
    if cross:
        lines += ["", "## Within the training folder and across folders", ""] + side_by_side(summary, cross)
    for space, s in summary.items():
        lines += _space_section(space, s, "Within the training folder, " if cross else "")
    for space, s in (cross or {}).items():
        lines += _space_section(space, s, "Across folders, ")
    decided = cross or summary
    for space in decided:
        where = "across folders (trained on the training folder, tested on the test folder)" if cross else \
            f"within one folder ({decided[space]['split'].get('kind', 'pair')} split)"
        lines += ["", f"## Claims of section VI-C ({space.upper()} space), decided {where}", "",
                  "Each verdict from an interval: holds if it lies wholly on the claimed side, does not hold if "
                  "wholly on the other, otherwise undecided.", "",
                  "| claim | test | numbers | verdict |", "|---|---|---|---|"]
        for c in claims(decided, space):
            lines.append(f"| {c['claim']} | {c['test']} | {c['numbers']} | **{c['verdict']}** |")
    return "\n".join(lines) + "\n"


def write_report(folder: str | Path, raw: dict, summary: dict, context: dict,
                 cross_raw: dict | None = None, cross: dict | None = None) -> list[Path]:
    """Write figures, ``results.json`` and ``results.md`` into ``folder``; returns the paths.
    With a test folder (``cross_raw``, ``cross``) its figures are ``fig14_<space>_cross.png``
    and ``fig15_<space>_cross.png`` and the claims are decided on them."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for across, r, sm in ((False, raw, summary), (True, cross_raw, cross)):
        for space in sm or {}:
            where = ", across folders" if across else ""
            for name, data in ((layout.figure(14, space, across), fig14(r[space], space, where)),
                               (layout.figure(15, space, across), fig15(sm[space], space, where))):
                rio.atomic_write_bytes(folder / name, data)
                paths.append(folder / name)
    decided = cross or summary
    doc = dict(context=context, summary=summary, cross=cross,
               claims=claims(decided) if "pca" in decided else [],
               claims_by_space={sp: claims(decided, sp) for sp in decided},
               claims_decided_on="cross" if cross else "within")
    rio.atomic_write_json(folder / layout.RESULTS_JSON, doc)
    rio.atomic_write_text(folder / layout.RESULTS_MD, markdown(summary, context, cross))
    return paths + [folder / layout.RESULTS_JSON, folder / layout.RESULTS_MD]
