"""Which of the paper's findings a run reproduces, and the correlation clusters.

Takes the analysis ``{space: analyse(...)}`` and the config; ``findings`` gives one dict per
finding (RHF learns faster at small n; DB1 best and CBn well above 1; DBn below DB1 best;
pruning at T = 0.5 costs little; best after ten close to best) with the numbers behind it
and a verdict decided by ``FindingRules``; ``correlation_clusters`` groups the affordances
whose predictors correlate above a threshold.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from relaff_jax.learn import PAPER_TABLE2, TABLE2_ROWS
from relaff_jax.report.formatting import curve_average, fmt, nanmean


@dataclasses.dataclass(frozen=True)
class FindingRules:
    """How the generated summary decides whether a paper finding is reproduced."""

    small_n: int = 10  # "small n": the training sizes up to this one
    well_above: float = 1.25  # "well above 1": an average bootstrap factor of at least this
    close: float = 0.9  # "close to" / "costs little": at least this fraction of the reference


def _row(a: Mapping[str, Any], name: str) -> float:
    """Table II average (over affordances) of row ``name``."""
    return float(a["table2"][TABLE2_ROWS.index(name), 0])


def verdict(ok: bool | None) -> str:
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
        p = [nanmean(pca["mean"][:, 0, pca["sizes"].index(n)]) for n in small]
        r = [nanmean(rhf["mean"][:, 0, rhf["sizes"].index(n)]) for n in small]
        diff = nanmean(np.subtract(r, p)) if small else float("nan")
        numbers = (f"NB accuracy at n = {', '.join(map(str, small))}: PCA {', '.join(fmt(v) for v in p)}; "
                   f"RHF {', '.join(fmt(v) for v in r)}; mean difference RHF - PCA {diff:+.3f}")
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
        f"{space} Table II average: DB1 best {fmt(db1)}, CBn {fmt(cbn)}{cbn_note}",
        {"db1_best": db1, "cbn": cbn, "cbn_categories": cbn_built},
        _decide(db1 >= rules.well_above and cbn >= rules.well_above, db1,
                cbn if cbn_built != 0 else float("nan")))
    # 3. DBn below DB1 best
    add("dbn_below_db1", "DBn is below DB1 best", f"Table II: DBn {PAPER_TABLE2['DBn'][0]:.3f} < DB1 best {p2[0]['avg']:.3f}",
        f"Table II ({space}) average of DBn < that of DB1 best",
        f"{space} Table II average: DBn {fmt(dbn)}, DB1 best {fmt(db1)}",
        {"dbn": dbn, "db1_best": db1}, _decide(dbn < db1, dbn, db1))
    # 4. pruning at T = 0.5 costs little (threshold study, Fig. 12)
    th = a["thresholds"]
    ts = [float(t) for t in th["T"]]
    t_lo, t_hi = min(ts), (0.5 if 0.5 in ts else max(ts))
    avg_t = {t: curve_average(c, a["sizes"], cfg) for t, c in zip(ts, th["best_curve"])}
    cnt = dict(zip(ts, th["count"]))
    lo, hi = avg_t[t_lo], avg_t[t_hi]
    k = len(a["actions"]) * (len(a["actions"]) - 1) // 2
    add("pruning_cheap", f"pruning categories at T = {t_hi:g} costs little",
        "Fig. 12: the best category above T = 0.5 is about as good as the best of all categories",
        f"average bf of the best category built at T = {t_hi:g} >= {rules.close} x that at T = {t_lo:g}",
        f"best category's average bf (mean over affordances): T = {t_lo:g} {fmt(lo)} ({cnt[t_lo]} of {k} categories built), "
        f"T = {t_hi:g} {fmt(hi)} ({cnt[t_hi]} built); ratio {fmt(hi / lo if np.isfinite(lo) and lo else float('nan'), 2)}",
        {"T": [t_lo, t_hi], "avg_bf": [lo, hi], "built": [int(cnt[t_lo]), int(cnt[t_hi])]},
        _decide(hi >= rules.close * lo, lo, hi))
    # 5. best after ten close to best
    pairs = {fam: (_row(a, f"{fam} best after ten"), _row(a, f"{fam} best")) for fam in ("DB1", "CB1")}
    ratio = {fam: (t / b if np.isfinite(b) and b else float("nan")) for fam, (t, b) in pairs.items()}
    add("best_after_ten", "choosing the source after ten samples is close to the best choice",
        "Table II: best after ten 2.751 vs best 2.819 (DB1), 2.802 vs 2.889 (CB1)",
        f"Table II ({space}) average of 'best after ten' >= {rules.close} x 'best', for DB1 and CB1",
        "; ".join(f"{fam}: after ten {fmt(t)} vs best {fmt(b)} (ratio {fmt(ratio[fam], 2)})" for fam, (t, b) in pairs.items()),
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
