"""Forest throughput of the learning sweep, and the projected wall time of the paper protocol.

Measures affordance-classifier fits per second (fit on n samples + accuracy on 4000 test
samples, exactly the sweep's inner step ``learn.run_block``) at n = 4, 25, 100, in PCA
space with one bootstrap input (24 dims) and RHF space with one (348 dims), on one core and
on all cores (one worker process per core, each running its own blocks, as the sweep does).
Then projects the full paper protocol (sizes 2..100, 50 PCA / 25 RHF repetitions, every
condition) and the quick preset from the measured all-core rates, plus the one-off source
predictors and categories.

Before that, per forest and in the same run, the two forest engines (``relaff_jax.learn.forest.engine``):
``sklearn`` (``RandomForestClassifier`` fit + ``predict`` on 4000 rows, one forest at a time)
and ``fast`` (scikit-learn's Cython builder called directly + all forests of a block evaluated
in one jitted program), their ratio, and the paper protocol's sweep projected on 2 cores from
``learn.forests_per_space`` with each engine. ``--smoke`` measures PCA only with few forests
(under 2 minutes); the last line is always ``speedup=<fast / sklearn forests per second, fit +
evaluation, n = 25, PCA>``.

    PYTHONPATH=. python benchmarks/sweep.py [--calls 2] [--jobs 0] [--smoke]

The machine may be shared: numbers are wall-clock and include whatever else runs.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from relaff_jax import learn as E
from relaff_jax.learn.blocks import run_block
from relaff_jax.config.experiment import ExperimentConfig, experiment_preset
from relaff_jax.learn.checks import check_config
from relaff_jax import learn as L
from relaff_jax.learn.forest import engine as G

SIZES = (4, 25, 100)
DIMS = {"pca": 18, "rhf": 318}


def _block_inputs(space: str, m: int = 4100 + 100, seed: int = 0):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(m, DIMS[space])).astype(np.float32)
    y = X[:, 0] + X[:, 1] > 0
    boot = (rng.random((40, m)) < 0.5).astype(np.float32)
    test_idx, order = np.arange(4000), np.arange(4000, 4100)
    return X, y, boot, test_idx, order


def _one_call(space: str, n: int, k: int, seed: int, engine: str = "fast") -> tuple[int, float]:
    """k DB1-style learners (one bootstrap input each) at size n; returns (fits, CPU seconds)."""
    from relaff_jax.config import override

    cfg = override(ExperimentConfig(), {"forest.engine": engine})  # the engine travels in the config
    X, y, boot, test_idx, order = _block_inputs(space, seed=seed)
    plan = [(1 + s, (s,)) for s in range(k)]
    c = time.process_time()
    run_block(X, y, boot, plan, order, test_idx, [n], cfg.repeats(space), 1 + k, cfg.forest, (seed, n))
    return k, time.process_time() - c


def measure(space: str, n: int, jobs: int, calls: int, k: int = 32, engine: str = "fast") -> tuple[float, float]:
    """(fits per wall second, CPU seconds per fit) with ``jobs`` processes (1: in-process);
    each call is a block of ``k`` forests (the sweep's blocks hold ~1000)."""
    from joblib import Parallel, delayed

    if jobs == 1:
        for c in range(calls):
            _one_call(space, n, k, c, engine)  # warm caches and compile the timed calls' shapes
        t = time.perf_counter()
        out = [_one_call(space, n, k, c, engine) for c in range(calls)]
    else:
        with Parallel(n_jobs=jobs) as par:
            # start and warm the workers, compiling the timed calls' shapes (a compile is ~0.3 s)
            par(delayed(_one_call)(space, n, k, c, engine) for c in range(calls * jobs))
            t = time.perf_counter()
            out = par(delayed(_one_call)(space, n, k, c, engine) for c in range(calls * jobs))
    wall = time.perf_counter() - t
    fits = sum(f for f, _ in out)
    return fits / wall, sum(c for _, c in out) / fits


def prep_seconds(space: str, categories: bool) -> float:
    """One-off cost per space: 9 source predictors (2000 samples) + 36 categories (4000) if
    the space uses them, each predicting 9 target pools of ~7500 scenes (one core)."""
    rng = np.random.default_rng(1)
    d = DIMS[space]
    t = time.perf_counter()
    for n in (2000, 4000):
        X = rng.normal(size=(n, d)).astype(np.float32)
        f = G.fit(X, X[:, 0] > 0, 0)
        G.predict(f, rng.normal(size=(9 * 7500, d)).astype(np.float32))
    t_src_cat = time.perf_counter() - t  # one source + one category
    t = time.perf_counter()
    X = rng.normal(size=(2000, d)).astype(np.float32)
    f = G.fit(X, X[:, 0] > 0, 0)
    t_src = time.perf_counter() - t
    t_cat = max(t_src_cat - t_src, 0.0)
    return 9 * t_src + (36 * t_cat if categories else 0.0)


def paper_like_corr() -> np.ndarray:
    """Two clusters as in paper Fig. 11: {lift, pull, push, pour, slide} strongly correlated,
    {move, take, rake, unobstruct} weakly, the two anti-correlated."""
    on_top = np.array([a in ("lift", "pull", "push", "pour", "slide") for a in L.ACTIONS])
    corr = np.where(np.equal.outer(on_top, on_top), np.where(on_top[:, None], 0.7, 0.3), -0.3)
    np.fill_diagonal(corr, 1.0)
    return corr


def learners_per_target(cfg: ExperimentConfig, space: str) -> int:
    """Distinct forests per (target, rep, size), for target 'move' with the paper-like
    correlations: NB + 8 DB1 + DBn + 28 CB1 + 3 distinct CBn sets = 41 in PCA."""
    return len({rows for _, rows in E.condition_plan(L.ACTIONS, 1, paper_like_corr(), check_config(cfg) or cfg, space)})


def project(cfg: ExperimentConfig, rates: dict, spaces=("pca", "rhf")) -> dict[str, float]:
    """Seconds of sweep per space from measured fits/s at SIZES (piecewise linear in n)."""
    out = {}
    for s in spaces:
        spf = np.interp(cfg.sizes, SIZES, [1.0 / rates[(s, n)] for n in SIZES])  # s per fit at each n
        out[s] = float(9 * learners_per_target(cfg, s) * cfg.reps(s) * spf.sum())
    return out


def engine_times(space: str, n: int, k_old: int, k_new: int, seed: int = 0) -> dict[str, tuple[float, float]]:
    """Seconds per forest ``{engine: (fit, evaluation on 4000 rows)}`` in this process, for the
    sweep's DB1 learners (one bootstrap input) at size n; checks both predict the same."""
    cfg = ExperimentConfig()
    rep = cfg.repeats(space)
    X, y, boot, test_idx, order = _block_inputs(space, seed=seed)
    tr, d0 = order[:n], X.shape[1]
    ZT = np.concatenate([X[test_idx].T, boot[:, test_idx]])
    maps = [np.concatenate([np.arange(d0), d0 + np.repeat([s % len(boot)], rep)]) for s in range(max(k_old, k_new))]
    fits = [(E.augment(X[tr], boot[[s % len(boot)]][:, tr], rep), y[tr], 1000 + s) for s in range(max(k_old, k_new))]
    out, preds = {}, {}
    # sklearn: fit, then predict the forest's own 4000 x D test matrix (as the old sweep did)
    tests = [np.ascontiguousarray(ZT[m].T) for m in maps[:k_old]]
    t_fit = t_eval = 0.0
    preds["sklearn"] = []
    for (x, yy, sd), xt in zip(fits[:k_old], tests):
        t = time.perf_counter()
        f = G.fit(x, yy, sd, cfg.forest, engine="sklearn")
        t_fit += time.perf_counter() - t
        t = time.perf_counter()
        preds["sklearn"].append(L.predict_class(f, xt))
        t_eval += time.perf_counter() - t
    out["sklearn"] = (t_fit / k_old, t_eval / k_old)
    # fast: fit every forest, then evaluate them all at once (compiled in a first, untimed pass)
    forests = [G.fit(x, yy, sd, cfg.forest, engine="fast") for x, yy, sd in fits[:k_new]]
    G.predict_many(forests, ZT, maps[:k_new])
    t = time.perf_counter()
    forests = [G.fit(x, yy, sd, cfg.forest, engine="fast") for x, yy, sd in fits[:k_new]]
    t_fit = time.perf_counter() - t
    t = time.perf_counter()
    pred = G.predict_many(forests, ZT, maps[:k_new])
    t_eval = time.perf_counter() - t
    out["fast"] = (t_fit / k_new, t_eval / k_new)
    k = min(k_old, k_new)
    if not np.array_equal(pred[:k], np.stack(preds["sklearn"])[:k]):
        raise AssertionError(f"{space} n={n}: the engines predicted differently")
    return out


def engine_table(spaces, k_old: int, k_new: int) -> dict:
    """Print the per-forest table; return {(space, n): {engine: (fit, eval)}}."""
    print("| space (dims) | n | trees | sklearn fit ms | sklearn eval ms | fast fit ms | fast eval ms | "
          "sklearn forests/s | fast forests/s | speed-up |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    res = {}
    for s in spaces:
        dims = DIMS[s] + ExperimentConfig().repeats(s)
        for n in SIZES:
            r = res[(s, n)] = engine_times(s, n, k_old, k_new)
            (of, oe), (nf, ne) = r["sklearn"], r["fast"]
            print(f"| {s.upper()} ({dims}) | {n} | {L.n_trees(n)} | {1e3 * of:.1f} | {1e3 * oe:.1f} | {1e3 * nf:.2f} | "
                  f"{1e3 * ne:.2f} | {1 / (of + oe):.1f} | {1 / (nf + ne):.1f} | {(of + oe) / (nf + ne):.1f}x |", flush=True)
    return res


def project_engines(res: dict, spaces, cores: int = 2, measured: dict | None = None) -> None:
    """The paper protocol's sweep on ``cores`` cores: forests_per_space x seconds per forest
    (piecewise linear in n, averaged over the sizes) / cores (one process per core)."""
    cfg = experiment_preset("paper")
    print(f"| space | forests (forests_per_space) | sklearn, {cores} cores | fast, {cores} cores"
          + (" | fast, measured on all cores |" if measured else " |"))
    print("|---|---:|---:|---:|" + ("---:|" if measured else ""))
    tot = {"sklearn": 0.0, "fast": 0.0, "measured": 0.0}
    for s in spaces:
        count = L.forests_per_space(cfg, 9, s)
        row = f"| {s.upper()} | {count:,} |"
        for eng in ("sklearn", "fast"):
            spf = np.interp(cfg.sizes, SIZES, [sum(res[(s, n)][eng]) for n in SIZES]).mean()
            tot[eng] += count * spf / cores
            row += f" {_hms(count * spf / cores)} |"
        if measured:
            spf = np.interp(cfg.sizes, SIZES, [1.0 / measured[(s, n)] for n in SIZES]).mean()
            tot["measured"] += count * spf
            row += f" {_hms(count * spf)} |"
        print(row)
    print(f"| total | | **{_hms(tot['sklearn'])}** | **{_hms(tot['fast'])}** |" + (f" **{_hms(tot['measured'])}** |" if measured else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=2, help="blocks of 32 fits per measurement and process")
    ap.add_argument("--jobs", type=int, default=0, help="processes for 'all cores' (default: all)")
    ap.add_argument("--smoke", action="store_true", help="PCA only, few forests, no all-core runs (< 2 min)")
    args = ap.parse_args()
    allj = args.jobs or os.cpu_count() or 1
    print(f"# forest engines, one process, {os.cpu_count()} cores; fit on n samples + evaluation on 4000 rows "
          f"per forest (fast: evaluated together); load average before: {os.getloadavg()[0]:.2f}")
    print()
    spaces = ("pca",) if args.smoke else ("pca", "rhf")
    eng = engine_table(spaces, k_old=6 if args.smoke else 10, k_new=128 if args.smoke else 256)
    print()
    if args.smoke:
        project_engines(eng, spaces, cores=allj)
        print()
        _print_speedup(eng)
        return
    print(f"# relaff sweep benchmark (fast engine, blocks of 32 forests): {os.cpu_count()} cores, all-cores = {allj} processes; "
          "one fit = forest fit on n samples + predict 4000 test samples; "
          f"load average before: {os.getloadavg()[0]:.2f}")
    print()
    print("| space (dims) | n | trees | fits/s one core | fits/s all cores | speed-up | CPU ms per fit (one core / all cores) |")
    print("|---|---|---|---|---|---|---|")
    rates, idle = {}, {}
    for s in ("pca", "rhf"):
        dims = DIMS[s] + ExperimentConfig().repeats(s)
        for n in SIZES:
            one, cpu1 = measure(s, n, 1, args.calls)
            many, cpun = measure(s, n, allj, args.calls)
            rates[(s, n)] = many
            idle[(s, n)] = allj / cpun  # what all cores would do if nothing else ran
            print(f"| {s.upper()} ({dims}) | {n} | {L.n_trees(n)} | {one:.2f} | {many:.2f} | {many / one:.2f}x | "
                  f"{1e3 * cpu1:.0f} / {1e3 * cpun:.0f} |", flush=True)
    print()
    print("Projections: 'measured' uses the all-core wall rates above (as loaded as the machine was); "
          "'idle' uses CPU time per fit spread over all cores (an unshared machine).")
    print()
    cfg0 = ExperimentConfig()
    prep = {s: prep_seconds(s, bool({"CB1", "CBn"} & set(cfg0.conditions(s)))) for s in ("pca", "rhf")}
    print("| preset | space | learners per (target, rep, n) | sizes | reps | forests | sweep, measured | sweep, idle | + sources & categories (one core) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("quick", "paper"):
        cfg = experiment_preset(name)
        proj, pidle = project(cfg, rates), project(cfg, idle)
        for s in ("pca", "rhf"):
            nf = 9 * learners_per_target(cfg, s) * len(cfg.sizes) * cfg.reps(s)
            print(f"| {name} | {s.upper()} | {learners_per_target(cfg, s)} | {len(cfg.sizes)} | {cfg.reps(s)} | {nf:,} | "
                  f"{_hms(proj[s])} | {_hms(pidle[s])} | {_hms(prep[s])} |")
        print(f"| {name} | total | | | | | **{_hms(sum(proj.values()) + sum(prep.values()))}** | "
              f"**{_hms(sum(pidle.values()) + sum(prep.values()))}** | |")
    cfg = experiment_preset("paper")
    both = ExperimentConfig(conditions_rhf=E.FAMILIES)
    print()
    print(f"Paper protocol (idle projection) with every condition also in RHF: {_hms(sum(project(both, idle).values()) + sum(prep.values()))}; "
          f"with the 36 categories including the target's own (categories_with_target): "
          f"{_hms(sum(project(ExperimentConfig(categories_with_target=True), idle).values()) + sum(prep.values()))}.")
    print(f"Paper: ~1.5 weeks of random forest learning on a 32-process cluster. "
          f"Load average after: {os.getloadavg()[0]:.2f}")
    print()
    print("Paper protocol's sweep by engine (one-process seconds per forest / cores; measured: the "
          "fast engine's all-core rates above):")
    print()
    project_engines(eng, ("pca", "rhf"), cores=allj, measured=rates)
    print()
    _print_speedup(eng)


def _print_speedup(eng: dict) -> None:
    (of, oe), (nf, ne) = eng[("pca", 25)]["sklearn"], eng[("pca", 25)]["fast"]
    print(f"speedup={(of + oe) / (nf + ne):.2f}")


def _hms(sec: float) -> str:
    h, rem = divmod(int(round(sec)), 3600)
    m, s = divmod(rem, 60)
    return f"{h} h {m:02d} min" if h else f"{m} min {s:02d} s"


if __name__ == "__main__":
    main()
