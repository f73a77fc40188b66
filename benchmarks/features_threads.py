"""The features stage on one stored dataset: chunks computed on one thread (the reference) against
several (``data.add_features(threads=...)``), the whole stage (load, perception, writes).

    python benchmarks/features_threads.py DATASET [--threads 2 3] [--rounds 2] [--work DIR]

DATASET is a dataset folder (``relaff generate``; its own features are never touched). Each
round computes the features of every sample into fresh copies of its rollouts, once per thread
count, the order alternating between rounds; after an untimed run (compiles). Prints a table
of wall seconds, scenes/s, CPU seconds (this process, all threads) and the ratio to one thread
in the same round, and checks every feature array equal to one thread's.
"""
from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def fresh_copy(src: Path, dst: Path) -> Path:
    """The dataset's rollouts without its features (what the stage starts from)."""
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("features", "features.json", "status*.json"))
    return dst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--threads", type=int, nargs="+", default=[2])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--work", type=Path, default=None, help="folder for the copies (default: a temporary one)")
    args = ap.parse_args()

    from relaff_jax import data as D
    from relaff_jax.config import RunConfig
    from relaff_jax.data.store import read_sidecar
    from relaff_jax.sim.object_library import use_recorded
    from relaff_jax.stages.features import default_feature_factory

    work = Path(args.work or tempfile.mkdtemp(prefix="features_threads_"))
    use_recorded(read_sidecar(args.dataset))
    compute = default_feature_factory(0)
    batch = RunConfig().dataset.feature_batch
    modes = [1] + [t for t in args.threads if t != 1]

    def run(threads: int) -> tuple[float, float, dict]:
        p = fresh_copy(args.dataset, work / f"t{threads}")
        c0, t0 = cpu_s(), time.perf_counter()
        D.add_features(p, compute[0], batch, False, compute[1], threads=threads)
        wall, cpu = time.perf_counter() - t0, cpu_s() - c0
        d = D.load_dataset(p)
        return wall, cpu, {k: d[k] for k in ("pca", "rhf", "unseen", "n_points")}

    t0 = time.perf_counter()
    _, _, ref = run(1)  # untimed: every program compiled
    n = len(ref["pca"])
    print(f"{args.dataset}: {n} scenes, chunks of {batch}; untimed first run {time.perf_counter() - t0:.0f} s",
          file=sys.stderr)
    rows = []
    for r in range(args.rounds):
        got = {}
        for t in (modes if r % 2 == 0 else modes[::-1]):
            got[t] = run(t)
            for k, a in got[t][2].items():
                if not np.array_equal(a, ref[k]):
                    raise SystemExit(f"threads={t}: {k} differs from one thread's")
        for t in modes:
            wall, cpu, _ = got[t]
            rows.append((r, t, wall, n / wall, cpu, got[1][0] / wall))
    print("| round | threads | wall s | scenes/s | CPU s | x one thread (same round) |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r, t, wall, rate, cpu, ratio in rows:
        print(f"| {r} | {t} | {wall:.1f} | {rate:.0f} | {cpu:.1f} | {ratio:.2f} |")
    print("every feature array equal to one thread's")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
