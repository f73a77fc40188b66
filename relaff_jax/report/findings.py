"""Which of the paper's findings a run reproduces, and the correlation clusters.

Takes the analysis ``{space: analyse(...)}`` and the config; ``findings`` gives one dict per
finding (RHF learns faster at small n; DB1 best and CBn well above 1; DBn below DB1 best;
pruning at T = 0.5 costs little; best after ten close to best) with the numbers behind it
and a verdict decided from the quantity's bootstrap interval by ``FindingRules``
(reproduced / not reproduced / undecided at this scale / not measurable); ``correlation_clusters`` groups the affordances
whose predictors correlate above a threshold.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from relaff_jax.learn import ORACLE, PAPER_TABLE2, TABLE2_ROWS, bc_interval, checked_interval
from relaff_jax.learn.intervals import percentile_interval
from relaff_jax.learn.table2 import after_ten_row

AFTER_TEN_TEXT = {"whole": "the whole curve of the learner kept at n = {n}",
                  "causal": "nothing chosen before n = {n}: there an equal share of every candidate"}
from relaff_jax.report.formatting import fmt, interval, nanmean


@dataclasses.dataclass(frozen=True)
class FindingRules:
    """How the generated summary decides whether a paper finding is reproduced: each claim is
    a quantity compared with a bound; the claim is "reproduced" if the whole bootstrap interval
    of the quantity (``analyse``'s resamples, ``cfg.ci_level``, ``judge``) is on the claimed side of the
    bound, "not reproduced" if the whole interval is on the other side, and "undecided at this
    scale" if the interval contains the bound."""

    small_n: int = 10  # "small n": the training sizes up to this one
    well_above: float = 1.25  # "well above 1": an average bootstrap factor of at least this
    close: float = 0.9  # "close to" / "costs little": at least this fraction of the reference


VERDICTS = ("reproduced", "not reproduced", "undecided at this scale", "not measurable")


def _row(a: Mapping[str, Any], name: str) -> float:
    """Table II average (over affordances) of row ``name``."""
    return float(a["table2"][TABLE2_ROWS.index(name), 0])


def _boot(a: Mapping[str, Any], name: str) -> np.ndarray:
    """``(B,)`` resampled Table II average of row ``name`` (NaN without intervals)."""
    return np.asarray(a["table2_boot"])[:, TABLE2_ROWS.index(name)] if "table2_boot" in a else np.full(1, np.nan)


def _paper(a: Mapping[str, Any]) -> np.ndarray:
    """``(A,)`` the paper's targets of analysis ``a`` (every mean of a finding is over them)."""
    return np.asarray(a.get("paper", np.ones(len(a["actions"]), bool)), bool)


def _best(a: Mapping[str, Any], name: str) -> str:
    """The held-out row ``name``, or its in-sample oracle row where the run has no test halves."""
    return name if np.isfinite(_row(a, name)) else name + ORACLE


def verdict(ok: bool | None) -> str:
    """The verdict text of ``reproduced`` (True / False / None: undecided or not measurable)."""
    return {True: "reproduced", False: "not reproduced", None: "not measurable"}[ok]


def judge(est: float, boot: np.ndarray, bound: float, above: bool, level: float, tail: float = 0.0) -> dict[str, Any]:
    """One claim "est > bound" (``above``) or "est < bound": its verdict from the interval of
    ``boot (B,)`` resampled values (``checked_interval``: bias-corrected unless an end would
    leave less than ``tail`` of the resamples beyond it, then the percentile interval; both are
    kept). NaN estimate or no finite resample: not measurable."""
    b, e = np.asarray(boot, dtype=float).reshape(-1, 1), np.array([est], dtype=float)
    lo, hi, bc = (x[0] for x in checked_interval(b, e, level, tail))
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(est) and np.isfinite(lo) and np.isfinite(hi)):
        v = "not measurable"
    elif (lo > bound) if above else (hi < bound):
        v = "reproduced"
    elif (hi < bound) if above else (lo > bound):
        v = "not reproduced"
    else:
        v = "undecided at this scale"
    return {"estimate": float(est), "interval": [lo, hi], "bound": bound, "above": above, "verdict": v,
            "method": "BC" if bool(bc) else "percentile",
            "bc_interval": [float(x[0]) for x in bc_interval(b, e, level)],
            "percentile_interval": [float(x[0]) for x in percentile_interval(b, level)]}


def combine(parts: list[dict[str, Any]]) -> str:
    """All claims of a finding must hold: any not measurable -> not measurable; any not
    reproduced -> not reproduced; all reproduced -> reproduced; else undecided."""
    vs = [p["verdict"] for p in parts]
    for v in ("not measurable", "not reproduced"):
        if v in vs:
            return v
    return "reproduced" if all(v == "reproduced" for v in vs) else "undecided at this scale"


def _text(label: str, j: Mapping[str, Any], nd: int = 3) -> str:
    lo, hi = j["interval"]
    side = ">" if j["above"] else "<"
    ci = interval(lo, hi, nd)
    alt = (f", percentile interval: the bias-corrected one, {interval(*j['bc_interval'], nd)}, reads an end in the "
           "resamples' extreme tail" if j.get("method") == "percentile" else "")
    return f"{label} {fmt(j['estimate'], nd)}{'' if ci == '-' else ' ' + ci} (claim {side} {j['bound']:g}{alt})"


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.asarray(den) != 0, np.asarray(num) / np.where(np.asarray(den) != 0, den, 1.0), np.nan)


def findings(an: Mapping[str, Mapping[str, Any]], cfg, rules: FindingRules = FindingRules()) -> list[dict[str, Any]]:
    """Which of the paper's findings this run reproduces, each decided from its interval.

    ``an``: ``{space: analyse(...)}``. Returns a list of dicts ``{id, finding, paper, rule,
    numbers, values, claims, verdict, reproduced}``: ``claims`` the quantities with their
    interval and bound (``judge``), ``verdict`` one of ``VERDICTS`` (``combine``), and
    ``reproduced`` True / False / None (undecided or not measurable).
    """
    out: list[dict[str, Any]] = []
    level, tail = float(cfg.ci_level), float(getattr(cfg, "ci_tail", 0.0))
    pct = f"{100 * level:g} %"
    how = (f"decided by the {pct} bootstrap interval (bias-corrected, or the percentile interval where a bias-corrected end "
           f"leaves less than {100 * tail:g} % of the resamples beyond it): reproduced if it lies wholly on the claimed "
           "side of the bound, not reproduced if wholly on the other side, otherwise undecided at this scale")

    def add(fid, finding, paper, rule, numbers, values, claims, forced=None):
        v = forced or combine(claims)
        out.append({"id": fid, "finding": finding, "paper": paper, "rule": rule, "decision": how, "numbers": numbers,
                    "values": values, "claims": claims, "verdict": v,
                    "reproduced": {"reproduced": True, "not reproduced": False}.get(v)})

    pca, rhf = an.get("pca"), an.get("rhf")
    # 1. RHF learns faster than PCA at small n (paper Fig. 7); the two spaces' resamples share
    # their draws (same seed) wherever they have the same repetitions and test-set sizes: paired
    rule = f"mean NB accuracy over the paper's affordances, averaged over the sizes n <= {rules.small_n}: RHF - PCA > 0"
    if pca is not None and rhf is not None:
        small = [n for n in pca["sizes"] if n <= rules.small_n and n in rhf["sizes"]]
        p = [nanmean(pca["mean"][_paper(pca), 0, pca["sizes"].index(n)]) for n in small]
        r = [nanmean(rhf["mean"][_paper(rhf), 0, rhf["sizes"].index(n)]) for n in small]
        diff = nanmean(np.subtract(r, p)) if small else float("nan")
        if small and "nb_boot" in pca and "nb_boot" in rhf:
            bp = np.asarray(pca["nb_boot"])[:, [pca["sizes"].index(n) for n in small]]
            br = np.asarray(rhf["nb_boot"])[:, [rhf["sizes"].index(n) for n in small]]
            boot = (br - bp).mean(-1)
        else:
            boot = np.full(1, np.nan)
        j = judge(diff, boot, 0.0, True, level, tail)
        numbers = (f"NB accuracy at n = {', '.join(map(str, small))}: PCA {', '.join(fmt(v) for v in p)}; "
                   f"RHF {', '.join(fmt(v) for v in r)}; " + _text("mean difference RHF - PCA", j))
        add("rhf_faster", "RHF learns faster than PCA at small n", "Fig. 7: RHF above PCA for the first samples",
            rule, numbers, {"sizes": small, "pca": p, "rhf": r, "difference": diff}, [j])
    else:
        add("rhf_faster", "RHF learns faster than PCA at small n", "Fig. 7: RHF above PCA for the first samples",
            rule, "needs both the PCA and the RHF sweep", {}, [], forced="not measurable")
    a = pca if pca is not None else next(iter(an.values()))
    space = "PCA" if pca is not None else next(iter(an)).upper()
    db1_name = _best(a, "DB1 best")
    db1, cbn, dbn = _row(a, db1_name), _row(a, "CBn"), _row(a, "DBn")
    p2 = dict(zip(("avg", "min", "max"), PAPER_TABLE2["DB1 best"])), dict(zip(("avg", "min", "max"), PAPER_TABLE2["CBn"]))
    # 2. DB1 best and CBn well above 1; with no category kept at CBn's threshold CBn is not measured
    th_t = [float(t) for t in a["thresholds"]["T"]]
    t_cbn = float(cfg.cbn_threshold)
    cbn_built = int(a["thresholds"]["count"][th_t.index(t_cbn)])
    cbn_note = f" (no category passed T = {t_cbn:g}: CBn is not measurable)" if cbn_built == 0 else ""
    j_db1 = judge(db1, _boot(a, db1_name), rules.well_above, True, level, tail)
    j_cbn = judge(cbn if cbn_built else float("nan"), _boot(a, "CBn"), rules.well_above, True, level, tail)
    add("bootstrapping_helps", "DB1 best and CBn are well above 1",
        f"Table II: DB1 best {p2[0]['avg']:.3f}, CBn {p2[1]['avg']:.3f}",
        f"Table II ({space}) average of '{db1_name}' and of 'CBn' > {rules.well_above}",
        f"{space} Table II average: " + _text(db1_name, j_db1) + "; " + _text("CBn", j_cbn) + cbn_note,
        {"db1_best": db1, "db1_row": db1_name, "cbn": cbn, "cbn_categories": cbn_built}, [j_db1, j_cbn])
    # 3. DBn below DB1 best: the paired difference of the two rows in every resample
    j = judge(dbn - db1, _boot(a, "DBn") - _boot(a, db1_name), 0.0, False, level, tail)
    gain_note = ""
    if "gain_boot" in a:  # the same comparison on the gain, which has no ratio's tail (shown, not decided on)
        gi, gd = TABLE2_ROWS.index("DBn"), TABLE2_ROWS.index(db1_name)
        g = np.asarray(a["gain"], float)[[gi, gd], 0]
        gb = np.asarray(a["gain_boot"], float)
        jg = judge(g[0] - g[1], gb[:, gi] - gb[:, gd], 0.0, False, level, tail)
        gain_note = f"; on the window's mean gain over NB: DBn {fmt(g[0])}, {db1_name} {fmt(g[1])}, " + _text("difference", jg)
    add("dbn_below_db1", "DBn is below DB1 best", f"Table II: DBn {PAPER_TABLE2['DBn'][0]:.3f} < DB1 best {p2[0]['avg']:.3f}",
        f"Table II ({space}) average of DBn - that of '{db1_name}' < 0",
        f"{space} Table II average: DBn {fmt(dbn)}, {db1_name} {fmt(db1)}; " + _text("DBn - DB1 best", j) + gain_note,
        {"dbn": dbn, "db1_best": db1, "db1_row": db1_name}, [j])
    # 4. pruning at T = 0.5 costs little (threshold study, Fig. 12, on Table II's aggregation)
    th = a["thresholds"]
    ts = [float(t) for t in th["T"]]
    t_lo, t_hi = min(ts), (0.5 if 0.5 in ts else max(ts))
    i_lo, i_hi = ts.index(t_lo), ts.index(t_hi)
    avg_t = np.asarray(th["avg"], dtype=float)
    lo, hi = float(avg_t[i_lo]), float(avg_t[i_hi])
    cnt = dict(zip(ts, th["count"]))
    k = len(a["actions"]) * (len(a["actions"]) - 1) // 2
    tb = np.asarray(a["threshold_boot"]) if "threshold_boot" in a else np.full((1, len(ts)), np.nan)
    j = judge(float(_ratio(hi, lo)), _ratio(tb[:, i_hi], tb[:, i_lo]), rules.close, True, level, tail)
    add("pruning_cheap", f"pruning categories at T = {t_hi:g} costs little",
        "Fig. 12: the best category above T = 0.5 is about as good as the best of all categories",
        f"average bf of the best category built at T = {t_hi:g} / that at T = {t_lo:g} > {rules.close} "
        "(each chosen on one half of the test scenes, scored on the other, as Table II's CB1 best)",
        f"best category's average bf (mean over the paper's affordances): T = {t_lo:g} {fmt(lo)} ({cnt[t_lo]} of {k} categories built), "
        f"T = {t_hi:g} {fmt(hi)} ({cnt[t_hi]} built); " + _text("ratio", j, 2),
        {"T": [t_lo, t_hi], "avg_bf": [lo, hi], "built": [int(cnt[t_lo]), int(cnt[t_hi])]}, [j])
    # 5. best after ten close to best (both chosen without looking at the scores they report)
    claims, values, texts = [], {}, []
    reading = getattr(cfg, "after_ten", "whole")
    for fam in ("DB1", "CB1"):
        n_ten, n_best = _best(a, after_ten_row(f"{fam} best after ten", reading)), _best(a, f"{fam} best")
        t, b = _row(a, n_ten), _row(a, n_best)
        j = judge(float(_ratio(t, b)), _ratio(_boot(a, n_ten), _boot(a, n_best)), rules.close, True, level, tail)
        claims.append(j)
        values[fam] = {"after_ten": t, "best": b, "ratio": j["estimate"], "rows": [n_ten, n_best]}
        texts.append(f"{fam}: after ten {fmt(t)} vs best {fmt(b)}, " + _text("ratio", j, 2))
    add("best_after_ten", "choosing the source after ten samples is close to the best choice",
        "Table II: best after ten 2.751 vs best 2.819 (DB1), 2.802 vs 2.889 (CB1)",
        f"Table II ({space}) average of 'best after ten' ({AFTER_TEN_TEXT[reading].format(n=cfg.select_size)}) / 'best' > {rules.close}, for DB1 "
        "and CB1", "; ".join(texts),
        values, claims)
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
