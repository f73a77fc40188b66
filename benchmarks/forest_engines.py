"""Per-forest time of the three forest engines, same run: ``compiled`` (numba, issue 26),
``fast`` (scikit-learn's Cython builder called directly, the default) and ``sklearn``
(``RandomForestClassifier``), at the sweep's learner shapes.

A forest = fit on n samples + evaluation on 4000 test rows, with the paper's settings
(``ForestConfig``) and the sweep's DB1 learners: the state plus one bootstrap input column
repeated 6x (PCA, 18 + 6 = 24 columns) or 30x (RHF, 318 + 30 = 348 columns); synthetic
labels ``x0 + x1 > 0``. ``fast`` and ``compiled`` fit and evaluate blocks of forests as the
sweep does (``engine.fit_many`` + ``engine.predict_many``); ``sklearn`` one forest at a time.
Each engine is timed in ``--rounds`` interleaved rounds and its best round is kept (the
machine may be shared: the ratios come from the same run); the engines' predictions are
checked equal. The compiled kernels are compiled (or loaded from numba's cache) before timing.

    PYTHONPATH=. python benchmarks/forest_engines.py [--forests 128] [--rounds 3] [--sizes 25 100] [--learner nb]

The last line is ``forest_speedup=<compiled / fast per forest, fit + evaluation, n = 25, PCA>``.
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from relaff_jax import learn as L
from relaff_jax.config.experiment import ExperimentConfig, ForestConfig
from relaff_jax.learn.forest import compiled
from relaff_jax.learn.forest import engine as G

DIMS = {"pca": 18, "rhf": 318}
ENGINES = ("compiled", "fast", "sklearn")


def inputs(space: str, n: int, k: int, seed: int = 0, learner: str = "db1"):
    """k learners at size n: (fits [(X, y, seed)], ZT (D0 + k, 4000), colmaps); ``nb``: the
    state alone (18 or 318 columns)."""
    rng = np.random.default_rng(seed)
    cfg = ExperimentConfig()
    rep = cfg.repeats(space) if learner == "db1" else 0
    m = 4000 + n
    X = rng.normal(size=(m, DIMS[space])).astype(np.float32)
    y = X[:, 0] + X[:, 1] > 0
    boot = (rng.random((k, m)) < 0.5).astype(np.float32)
    tr, test = np.arange(4000, m), np.arange(4000)
    d0 = X.shape[1]
    fits = [(L.augment(X[tr], boot[[s]][:, tr], rep), y[tr], 1000 + s) for s in range(k)]
    maps = [np.concatenate([np.arange(d0), d0 + np.repeat([s], rep)]) for s in range(k)]
    ZT = np.concatenate([X[test].T, boot[:, test]])
    return fits, ZT, maps


def time_engine(engine: str, fits, ZT, maps, chunk: int = 256) -> tuple[float, float, np.ndarray]:
    """(fit s, evaluation s, predictions (k, 4000)) for the k forests."""
    cfg = ForestConfig(engine=engine)
    t_fit = t_eval = 0.0
    preds = []
    step = 1 if engine == "sklearn" else chunk
    for a in range(0, len(fits), step):
        part = fits[a: a + step]
        t = time.perf_counter()
        forests = G.fit_many([f[0] for f in part], [f[1] for f in part], [f[2] for f in part], cfg)
        t_fit += time.perf_counter() - t
        t = time.perf_counter()
        preds.append(G.predict_many(forests, ZT, maps[a: a + step]))
        t_eval += time.perf_counter() - t
    return t_fit, t_eval, np.concatenate(preds)


def measure(space: str, n: int, k: int, k_sklearn: int, rounds: int, learner: str = "db1") -> dict[str, tuple[float, float]]:
    """Best-round seconds per forest ``{engine: (fit, eval)}``; checks the predictions agree."""
    fits, ZT, maps = inputs(space, n, k, learner=learner)
    for e in ("compiled", "fast"):  # warm: JAX program shapes (fast), numba kernels (compiled)
        time_engine(e, fits[:8], ZT, maps[:8])
    best: dict[str, tuple[float, float]] = {}
    preds = {}
    for _ in range(rounds):
        for e in ENGINES:
            kk = k_sklearn if e == "sklearn" else k
            f, v, p = time_engine(e, fits[:kk], ZT, maps[:kk])
            if e not in best or (f + v) / kk < sum(best[e]):
                best[e] = (f / kk, v / kk)
            preds[e] = p
    for e in ("fast", "sklearn"):
        kk = len(preds[e])
        if not np.array_equal(preds["compiled"][:kk], preds[e]):
            raise AssertionError(f"{space} n={n}: compiled and {e} predicted differently")
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--forests", type=int, default=128, help="forests per round (fast, compiled)")
    ap.add_argument("--sklearn-forests", type=int, default=6, help="forests per round (sklearn)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--sizes", type=int, nargs="+", default=[25, 100])
    ap.add_argument("--spaces", nargs="+", default=["pca", "rhf"])
    ap.add_argument("--learner", choices=["db1", "nb"], default="db1",
                    help="db1: state + one bootstrap input repeated (the sweep's usual learner); nb: the state alone")
    args = ap.parse_args()
    t = time.perf_counter()
    compiled.kernels()
    X = np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32)
    compiled.predict_proba(compiled.fit(X, X[:, 0] > 0, 0), X)
    print(f"# forest engines, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.machine()}, "
          f"{os.cpu_count()} cores, load average before {os.getloadavg()[0]:.2f}; numba kernels ready in "
          f"{time.perf_counter() - t:.1f} s; per forest: fit on n samples + evaluation on 4000 rows; "
          f"best of {args.rounds} rounds of {args.forests} forests ({args.sklearn_forests} for sklearn)")
    print()
    print("| space (columns) | n | trees | compiled fit ms | compiled eval ms | fast fit ms | fast eval ms | "
          "sklearn ms | compiled / fast, fit | compiled / fast, fit + eval | compiled / sklearn |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    res = {}
    for s in args.spaces:
        cols = DIMS[s] + (ExperimentConfig().repeats(s) if args.learner == "db1" else 0)
        for n in args.sizes:
            r = res[(s, n)] = measure(s, n, args.forests, args.sklearn_forests, args.rounds, args.learner)
            (cf, ce), (ff, fe), (sf, se) = r["compiled"], r["fast"], r["sklearn"]
            print(f"| {s.upper()} ({cols}) | {n} | {L.n_trees(n)} | {1e3 * cf:.2f} | {1e3 * ce:.2f} | {1e3 * ff:.2f} | "
                  f"{1e3 * fe:.2f} | {1e3 * (sf + se):.1f} | {ff / cf:.1f}x | {(ff + fe) / (cf + ce):.1f}x | "
                  f"{(sf + se) / (cf + ce):.0f}x |", flush=True)
    print()
    print(f"load average after {os.getloadavg()[0]:.2f}")
    key = ("pca", 25) if ("pca", 25) in res else next(iter(res))
    (cf, ce), (ff, fe) = res[key]["compiled"], res[key]["fast"]
    print(f"forest_speedup={(ff + fe) / (cf + ce):.2f}")


if __name__ == "__main__":
    main()
