"""The features stage with the chain's programs compiled with XLA:CPU's fusion emitters (the
default, ``perception.culled.CHAIN_COMPILER_OPTIONS``) against without them (the process's
own setting, off: ``relaff_jax/__init__.py``), the whole stage (load, perception, writes).

    python benchmarks/features_emitters.py DATASET [--threads 2] [--rounds 2] [--work DIR]

DATASET is a dataset folder (``relaff generate``; its own features are never touched). Each
round computes the features of every sample into fresh copies of its rollouts, once each way,
the order alternating between rounds, after an untimed run each way (compiles). Prints wall
seconds, scenes/s, CPU seconds (this process, all threads) and the ratio to the run without
the emitters in the same round, and checks every feature array equal both ways.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from features_threads import cpu_s, fresh_copy


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--threads", type=int, default=2, help="compute threads of the stage (default: 2, as on two cores)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--work", type=Path, default=None, help="folder for the copies (default: a temporary one)")
    args = ap.parse_args()

    from relaff_jax import data as D
    from relaff_jax.config import RunConfig
    from relaff_jax.data.store import read_sidecar
    from relaff_jax.perception import from_sim
    from relaff_jax.sim.object_library import use_recorded
    from relaff_jax.sim.world import build_world
    from relaff_jax.stages.features import feature_config

    work = Path(args.work or tempfile.mkdtemp(prefix="features_emitters_"))
    use_recorded(read_sidecar(args.dataset))
    tree = RunConfig()
    world = build_world()
    fns = {"without": from_sim.make_feature_fn(world, tree.perception, 0, compiler_options={}),
           "with": from_sim.make_feature_fn(world, tree.perception, 0)}
    config = feature_config(0, tree.perception)
    batch = tree.dataset.feature_batch

    def run(mode: str) -> tuple[float, float, dict]:
        p = fresh_copy(args.dataset, work / mode)
        c0, t0 = cpu_s(), time.perf_counter()
        D.add_features(p, fns[mode], batch, False, config, threads=args.threads)
        wall, cpu = time.perf_counter() - t0, cpu_s() - c0
        d = D.load_dataset(p)
        return wall, cpu, {k: d[k] for k in ("pca", "rhf", "unseen", "n_points")}

    t0 = time.perf_counter()
    ref = {m: run(m)[2] for m in fns}  # untimed: every program compiled
    n = len(ref["without"]["pca"])
    print(f"{args.dataset}: {n} scenes, chunks of {batch}, {args.threads} compute threads; untimed first runs "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    rows = []
    for r in range(args.rounds):
        got = {m: run(m) for m in (("without", "with") if r % 2 == 0 else ("with", "without"))}
        for m, (_, _, arrays) in got.items():
            for k, a in arrays.items():
                if not np.array_equal(a, ref["without"][k]):
                    raise SystemExit(f"{m} the emitters: {k} differs from the run without them")
        for m in fns:
            wall, cpu, _ = got[m]
            rows.append((r, m, wall, n / wall, cpu, wall / got["without"][0], cpu / got["without"][1]))
    print("| round | fusion emitters | wall s | scenes/s | CPU s | wall / without (same round) | CPU / without |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for r, m, wall, rate, cpu, rw, rc in rows:
        print(f"| {r} | {m} | {wall:.1f} | {rate:.0f} | {cpu:.1f} | {rw:.2f} | {rc:.2f} |")
    print("every feature array equal both ways")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
