"""The heavy stages as Dask tasks (issue 15): no cluster vs ``local:1`` vs ``local:2``, in one run.

    python benchmarks/cluster.py [--action push] [--chunks 6] [--batch 16] [--feature-batch 8]
                                 [--modes none,local:1,local:2] [--json OUT.json]
    python benchmarks/cluster.py --from-json OUT.json      # the tables of a saved run again

A fixed slice of the real pipeline per mode, each after a warm-up (every process has built
and compiled its programs, timed apart as ``compile``):

- generate: ``--chunks`` dataset chunks of ``--batch`` rollouts of one action, the real MJX
  simulation (``data.tasks.rollout_chunk``, as ``generate_dataset`` runs them);
- features: the real perception (Kinect, voxels, PCA, RHF) of those scenes in chunks of
  ``--feature-batch`` (``data.tasks.feature_chunk``);
- sweep: the quick experiment's PCA sweep on synthetic data (``learn.run_experiment``: one
  task per block).

Per stage and mode: wall time, the tasks' own compute time (Dask's task stream; the pieces
timed in-process without a cluster), the scheduler's overhead per task, ``(wall x slots -
compute) / tasks`` (the driver's own work between tasks and idle slots included), and the
speed-up over no cluster. Then the paper preset's wall time projected on 8, 32 and 128
single-thread workers from the per-task times (docs/cluster.md explains the model).
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _warm_rollouts(fn, batch):
    import jax

    t0 = time.perf_counter()
    fn(jax.random.PRNGKey(10**6), batch)
    return time.perf_counter() - t0


def _warm_features(fn, samples):
    t0 = time.perf_counter()
    fn(samples)
    return time.perf_counter() - t0


def _on_every_worker(client, fn, *args) -> dict:
    """``fn(*args)`` once on each worker, as a task (``client.run`` would block the worker's
    event loop: a compile of minutes then misses the heartbeats and the worker is restarted)."""
    futures = {w: client.submit(fn, *args, workers=[w], allow_other_workers=False, pure=False) for w in client.nthreads()}
    return {w: f.result() for w, f in futures.items()}


def _timed(client, body):
    """``body() -> tasks`` timed: (wall s, the tasks' compute s, tasks). With a client the
    compute comes from Dask's task stream; without one it is the wall time itself."""
    t0 = time.perf_counter()
    if client is None:
        n = body()
        wall = time.perf_counter() - t0
        return wall, wall, n
    from distributed import get_task_stream

    with get_task_stream(client) as ts:
        body()
    wall = time.perf_counter() - t0
    spans = [[s for s in t["startstops"] if s["action"] == "compute"] for t in ts.data]
    spans = [sp for sp in spans if sp]
    return wall, sum(s["stop"] - s["start"] for sp in spans for s in sp), len(spans)


def run_mode(mode, args, work: Path) -> dict:
    from relaff_jax import cluster as C
    from relaff_jax.config import override
    from relaff_jax.data.store import chunk_path, read_chunk
    from relaff_jax.data.tasks import feature_chunk, rollout_chunk
    from relaff_jax.learn import experiment_preset, run_experiment, synthetic_datasets
    from relaff_jax.reproduce.features import default_feature_factory
    from relaff_jax.reproduce.generate import default_rollout_factory

    tag = mode.replace(":", "")
    ctx = C.connect(mode, folder=work) if mode != "none" else None
    client = ctx.__enter__() if ctx else None
    try:
        out = {"mode": mode, "slots": C.nthreads(client) if client else 1}
        roll = C.Remote(default_rollout_factory, args.action, args.batch, pick=0)
        feat = C.Remote(default_feature_factory, 0, pick=0)
        warm = _on_every_worker(client, _warm_rollouts, roll, args.batch) if client else {"driver": _warm_rollouts(roll, args.batch)}
        out["compile_generate_s"] = max(warm.values())
        gen_dir = work / f"gen-{tag}"

        def generate():
            runner = C.Ordered(client, lambda k: (rollout_chunk, (roll, 7, k, args.batch, None, str(gen_dir))), args.chunks)
            for k in range(args.chunks):
                runner.get(k)
            return args.chunks

        out["generate"] = _timed(client, generate)
        parts = [read_chunk(chunk_path(gen_dir, k))[0] for k in range(args.chunks)]
        samples = {k: np.concatenate([p[k] for p in parts]) for k in ("pair", "qpos_settled", "rollout_id", "rollout")}
        fb, n = args.feature_batch, len(samples["pair"])
        first = {k: v[:fb] for k, v in samples.items()}
        warm = _on_every_worker(client, _warm_features, feat, first) if client else {"driver": _warm_features(feat, first)}
        out["compile_features_s"] = max(warm.values())

        def task(f):
            lo, hi = f * fb, min((f + 1) * fb, n)
            idx = np.minimum(np.arange(lo, lo + fb), hi - 1)
            return feature_chunk, (feat, {k: v[idx] for k, v in samples.items()}, f, fb, lo, hi, str(work / f"feat-{tag}"))

        def features():
            runner = C.Ordered(client, task, math.ceil(n / fb))
            for f in range(math.ceil(n / fb)):
                runner.get(f)
            return math.ceil(n / fb)

        out["features"] = _timed(client, features)
        # sizes spread over 2..100 (10: 'best after ten'): the mean cost of a fit near the paper's
        cfg = override(experiment_preset("quick"), {"sizes": (2, 10, 25, 50, 75, 100), "conditions_pca": ("NB", "DB1", "DBn")})
        data = synthetic_datasets(args.synthetic, seed=0)

        def sweep(name):
            with C.active(client):
                run_experiment(data, work / f"sweep-{name}-{tag}", cfg, ["pca"], seed=0, jobs=1, progress=False)
            with np.load(work / f"sweep-{name}-{tag}" / "pca" / "results.npz") as z:
                out["fits"] = int(z["new_fits"])
            return len(list((work / f"sweep-{name}-{tag}" / "pca" / "blocks").iterdir())) + 9  # + 9 source predictors

        sweep("warm")  # every worker compiles the forest engine's programs
        out["sweep"] = _timed(client, lambda: sweep("timed"))
        return out
    finally:
        if ctx:
            ctx.__exit__(None, None, None)


PAPER = {"actions": 9, "n": 10_000, "rollouts_per_sample": 3.70, "rollout_batch": 1024, "feature_batch": 32,
         "report_s": 90.0, "prep_s": 40.0}


def project(row: dict) -> str:
    """The paper preset's wall time on W single-thread workers from one worker's task times
    (``row``: the ``local:1`` mode): every action's chunks at once; ``ceil(tasks / W)`` rounds
    of one task's time per stage, plus the compile each worker pays once per stage. Generation
    also simulates up to ``ceil(W / 9) - 1`` chunks per action past its stopping point."""
    from relaff_jax.learn import experiment_preset, forests_per_space

    p = PAPER
    over = lambda st: (row[st][0] - row[st][1]) / row[st][2]  # noqa: E731 - s per task, local:1
    t_roll = row["generate"][1] / (row["generate"][2] * row["batch"])
    t_scene = row["features"][1] / (row["features"][2] * row["feature_batch"])
    t_fit = row["sweep"][1] / row["fits"]
    cfg = experiment_preset("paper")
    fits = sum(forests_per_space(cfg, p["actions"], s) for s in ("pca", "rhf"))
    blocks = sum(p["actions"] * cfg.reps(s) * math.ceil(len(cfg.sizes) / cfg.sizes_per_block) for s in ("pca", "rhf"))
    chunks = p["actions"] * math.ceil(p["n"] * p["rollouts_per_sample"] / p["rollout_batch"])
    fchunks = p["actions"] * math.ceil(p["n"] / p["feature_batch"])
    stages = {  # (tasks, seconds per task, fixed seconds)
        "generate": (chunks, p["rollout_batch"] * t_roll + over("generate"), row["compile_generate_s"]),
        "features": (fchunks, p["feature_batch"] * t_scene + over("features"), row["compile_features_s"]),
        "experiment": (blocks, fits / blocks * t_fit + over("sweep"), p["prep_s"]),
    }
    lines = [f"\nPaper preset projected (per task from local:1: {1000 * t_roll:.0f} ms per rollout, "
             f"{1000 * t_scene:.0f} ms per scene, {1000 * t_fit:.1f} ms per fit; {fits:,} fits in {blocks:,} blocks):",
             "| workers | generate | features | experiment | report | total | limit |", "|---:|---:|---:|---:|---:|---:|---|"]
    for w in (8, 32, 128):
        extra = {"generate": p["actions"] * (math.ceil(w / p["actions"]) - 1)}
        walls = {st: fixed + math.ceil((n + extra.get(st, 0)) / w) * t for st, (n, t, fixed) in stages.items()}
        total = sum(walls.values()) + p["report_s"]
        worst = max(stages, key=lambda st: walls[st])
        n, t, _ = stages[worst]
        limit = (f"{worst}: one task ({t:.0f} s) per worker" if n <= w else f"{worst}: {math.ceil(n / w)} rounds of {t:.0f} s")
        lines.append(f"| {w} | " + " | ".join(f"{walls[st] / 60:.1f} min" for st in stages)
                     + f" | {p['report_s'] / 60:.1f} min | **{total / 60:.1f} min** | {limit} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--action", default="push")
    ap.add_argument("--chunks", type=int, default=6)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--feature-batch", type=int, default=8)
    ap.add_argument("--synthetic", type=int, default=300, help="synthetic samples per action for the sweep")
    ap.add_argument("--modes", default="none,local:1,local:2")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--from-json", type=Path, help="print the tables of a saved run, run nothing")
    args = ap.parse_args(argv)
    rows = []
    if args.from_json:
        saved = json.loads(args.from_json.read_text())
        rows = saved["rows"]
        for k in ("action", "chunks", "batch", "feature_batch", "synthetic"):
            setattr(args, k, saved["args"][k])
    with tempfile.TemporaryDirectory(prefix="relaff-cluster-bench-") as tmp:
        for mode in [] if args.from_json else args.modes.split(","):
            t0 = time.perf_counter()
            rows.append(run_mode(mode, args, Path(tmp)))
            print(f"{mode}: {time.perf_counter() - t0:.0f} s in all: {rows[-1]}", file=sys.stderr, flush=True)
            if args.json:  # after every mode, so a failure keeps what was measured
                args.json.write_text(json.dumps({"machine": platform.platform(), "args": {
                    k: v for k, v in vars(args).items() if k not in ("json", "from_json")}, "rows": rows},
                    indent=1, default=str) + "\n")
    base = {st: rows[0][st][0] for st in ("generate", "features", "sweep")} if rows[0]["mode"] == "none" else {}
    print(f"\n{platform.platform()}, {args.chunks} chunks x {args.batch} rollouts of {args.action}, features in "
          f"chunks of {args.feature_batch}, PCA sweep on {args.synthetic} synthetic samples per action")
    print("\n| stage | mode | tasks | wall s | task compute s | per task s | overhead ms/task | overhead % | speed-up |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        r.update(batch=args.batch, feature_batch=args.feature_batch)
        for st in ("generate", "features", "sweep"):
            wall, compute, n = r[st]
            per, over = compute / n, (wall * r["slots"] - compute) / n
            sp = base[st] / wall if st in base else float("nan")
            print(f"| {st} | {r['mode']} | {n} | {wall:.1f} | {compute:.1f} | {per:.3f} | "
                  f"{'-' if r['mode'] == 'none' else f'{1000 * over:.0f}'} | "
                  f"{'-' if r['mode'] == 'none' else f'{100 * over / per:.1f}'} | {sp:.2f}x |")
    print("\ncompile per process (s): " + "; ".join(
        f"{r['mode']}: generate {r['compile_generate_s']:.0f}, features {r['compile_features_s']:.0f}" for r in rows))
    one = [r for r in rows if r["mode"] == "local:1"]
    if one:
        print(project(one[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
