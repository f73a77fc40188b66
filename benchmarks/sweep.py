"""Forest throughput of the learning sweep, and the projected wall time of the paper protocol.

Measures affordance-classifier fits per second (fit on n samples + accuracy on 4000 test
samples, exactly the sweep's inner step ``learn.run_block``) at n = 4, 25, 100, in PCA
space with one bootstrap input (24 dims) and RHF space with one (348 dims), on one core and
on all cores (one worker process per core, each running its own blocks, as the sweep does).
Then projects the full paper protocol (sizes 2..100, 50 PCA / 25 RHF repetitions, every
condition) and the quick preset from the measured all-core rates, plus the one-off source
predictors and categories.

    PYTHONPATH=. python benchmarks/sweep.py [--calls 2] [--jobs 0]

The machine may be shared: numbers are wall-clock and include whatever else runs.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from relaff_jax import learn as E
from relaff_jax import learn as L

SIZES = (4, 25, 100)
DIMS = {"pca": 18, "rhf": 318}


def _block_inputs(space: str, m: int = 4100 + 100, seed: int = 0):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(m, DIMS[space])).astype(np.float32)
    y = X[:, 0] + X[:, 1] > 0
    boot = (rng.random((8, m)) < 0.5).astype(np.float32)
    test_idx, order = np.arange(4000), np.arange(4000, 4100)
    return X, y, boot, test_idx, order


def _one_call(space: str, n: int, k: int, seed: int) -> tuple[int, float]:
    """k DB1-style learners (one bootstrap input each) at size n; returns (fits, CPU seconds)."""
    cfg = E.ExperimentConfig()
    X, y, boot, test_idx, order = _block_inputs(space, seed=seed)
    plan = [(1 + s, (s,)) for s in range(k)]
    c = time.process_time()
    E.run_block(X, y, boot, plan, order, test_idx, [n], cfg.repeats(space), 20, cfg.forest, (seed, n))
    return k, time.process_time() - c


def measure(space: str, n: int, jobs: int, calls: int, k: int = 4) -> tuple[float, float]:
    """(fits per wall second, CPU seconds per fit) with ``jobs`` processes (1: in-process)."""
    from joblib import Parallel, delayed

    if jobs == 1:
        _one_call(space, n, 1, 99)  # warm caches
        t = time.perf_counter()
        out = [_one_call(space, n, k, c) for c in range(calls)]
    else:
        with Parallel(n_jobs=jobs) as par:
            par(delayed(_one_call)(space, n, 1, 99 + j) for j in range(jobs))  # start + warm the workers
            t = time.perf_counter()
            out = par(delayed(_one_call)(space, n, k, c) for c in range(calls * jobs))
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
        f = L.fit_forest(X, X[:, 0] > 0, seed=0)
        L.predict_class(f, rng.normal(size=(9 * 7500, d)).astype(np.float32))
    t_src_cat = time.perf_counter() - t  # one source + one category
    t = time.perf_counter()
    X = rng.normal(size=(2000, d)).astype(np.float32)
    f = L.fit_forest(X, X[:, 0] > 0, seed=0)
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


def learners_per_target(cfg: E.ExperimentConfig, space: str) -> int:
    """Distinct forests per (target, rep, size), for target 'move' with the paper-like
    correlations: NB + 8 DB1 + DBn + 28 CB1 + 3 distinct CBn sets = 41 in PCA."""
    return len({rows for _, rows in E.condition_plan(L.ACTIONS, 1, paper_like_corr(), E.check_config(cfg) or cfg, space)})


def project(cfg: E.ExperimentConfig, rates: dict, spaces=("pca", "rhf")) -> dict[str, float]:
    """Seconds of sweep per space from measured fits/s at SIZES (piecewise linear in n)."""
    out = {}
    for s in spaces:
        spf = np.interp(cfg.sizes, SIZES, [1.0 / rates[(s, n)] for n in SIZES])  # s per fit at each n
        out[s] = float(9 * learners_per_target(cfg, s) * cfg.reps(s) * spf.sum())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=2, help="calls of 4 fits per measurement and process")
    ap.add_argument("--jobs", type=int, default=0, help="processes for 'all cores' (default: all)")
    args = ap.parse_args()
    allj = args.jobs or os.cpu_count() or 1
    print(f"# relaff sweep benchmark: {os.cpu_count()} cores, all-cores = {allj} processes; "
          "one fit = forest fit on n samples + predict 4000 test samples; "
          f"load average before: {os.getloadavg()[0]:.2f}")
    print()
    print("| space (dims) | n | trees | fits/s one core | fits/s all cores | speed-up | CPU ms per fit (one core / all cores) |")
    print("|---|---|---|---|---|---|---|")
    rates, idle = {}, {}
    for s in ("pca", "rhf"):
        dims = DIMS[s] + E.ExperimentConfig().repeats(s)
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
    cfg0 = E.ExperimentConfig()
    prep = {s: prep_seconds(s, bool({"CB1", "CBn"} & set(cfg0.conditions(s)))) for s in ("pca", "rhf")}
    print("| preset | space | learners per (target, rep, n) | sizes | reps | forests | sweep, measured | sweep, idle | + sources & categories (one core) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("quick", "paper"):
        cfg = E.experiment_preset(name)
        proj, pidle = project(cfg, rates), project(cfg, idle)
        for s in ("pca", "rhf"):
            nf = 9 * learners_per_target(cfg, s) * len(cfg.sizes) * cfg.reps(s)
            print(f"| {name} | {s.upper()} | {learners_per_target(cfg, s)} | {len(cfg.sizes)} | {cfg.reps(s)} | {nf:,} | "
                  f"{_hms(proj[s])} | {_hms(pidle[s])} | {_hms(prep[s])} |")
        print(f"| {name} | total | | | | | **{_hms(sum(proj.values()) + sum(prep.values()))}** | "
              f"**{_hms(sum(pidle.values()) + sum(prep.values()))}** | |")
    cfg = E.experiment_preset("paper")
    both = E.ExperimentConfig(conditions_rhf=E.FAMILIES)
    print()
    print(f"Paper protocol (idle projection) with every condition also in RHF: {_hms(sum(project(both, idle).values()) + sum(prep.values()))}; "
          f"with the 36 categories including the target's own (categories_with_target): "
          f"{_hms(sum(project(E.ExperimentConfig(categories_with_target=True), idle).values()) + sum(prep.values()))}.")
    print(f"Paper: ~1.5 weeks of random forest learning on a 32-process cluster. "
          f"Load average after: {os.getloadavg()[0]:.2f}")


def _hms(sec: float) -> str:
    h, rem = divmod(int(round(sec)), 3600)
    m, s = divmod(rem, 60)
    return f"{h} h {m:02d} min" if h else f"{m} min {s:02d} s"


if __name__ == "__main__":
    main()
