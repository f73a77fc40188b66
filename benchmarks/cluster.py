"""The heavy stages as Dask tasks (issue 15): no cluster vs ``local:1`` vs ``local:2``, in one run.

    python benchmarks/cluster.py [--engine mjx|native] [--action push] [--chunks 6] [--batch 16]
                                 [--feature-batch 8] [--modes none,local:1,local:2] [--json OUT.json]
    python benchmarks/cluster.py --from-json OUT.json      # the tables of a saved run again
    python benchmarks/cluster.py --memory [--engine mjx,native] [--batch 16]  # memory per worker

A fixed slice of the real pipeline per mode, each after a warm-up (every process has built
and compiled its programs, timed apart as ``compile``):

- generate: ``--chunks`` dataset chunks of ``--batch`` rollouts of one action, the real
  simulation with ``--engine`` (``data.tasks.rollout_chunk``, as ``generate_dataset`` runs
  them; ``native`` runs MuJoCo C on the process's CPUs without a cluster, on the worker's one
  task thread in a worker, ``native.batch.default_threads``);
- features: the real perception (Kinect, voxels, PCA, RHF) of those scenes in chunks of
  ``--feature-batch`` (``data.tasks.feature_chunk``);
- sweep: the quick experiment's PCA sweep on synthetic data (``learn.run_experiment``: one
  task per block).

Per stage and mode: wall time, the tasks' own compute time (Dask's task stream; the pieces
timed in-process without a cluster), the CPU time of the processes that ran them (so "cores"
= CPU / compute: XLA and MuJoCo may use more than one core inside one task), the scheduler's
overhead per task, ``(wall x slots - compute) / tasks`` (the driver's own work between tasks
and idle slots included), and the speed-up over no cluster. Then the paper preset's wall time
projected on 8, 32 and 128 workers of one core each, from the ``local:1`` per-task CPU times
(and, for comparison, from its wall times) (docs/cluster.md explains the model).
``--memory``: ``cluster_memory.py``, the resident set size of one worker after each action.
"""
from __future__ import annotations

import argparse
import json
import math
import os
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


def _cpu_s() -> float:
    """CPU seconds (user + system, all threads) of this process so far."""
    return time.process_time()


def _timed(client, body):
    """``body() -> tasks`` timed: (wall s, the tasks' compute s, tasks, CPU s). With a client
    the compute comes from Dask's task stream and the CPU time is the workers' processes'
    (their event loops included); without one both are this process's own."""
    cpu = (lambda: sum(client.run(_cpu_s).values())) if client else _cpu_s
    c0, t0 = cpu(), time.perf_counter()
    if client is None:
        n = body()
        wall = time.perf_counter() - t0
        return wall, wall, n, cpu() - c0
    from distributed import get_task_stream

    with get_task_stream(client) as ts:
        body()
    wall = time.perf_counter() - t0
    spent = cpu() - c0
    spans = [[s for s in t["startstops"] if s["action"] == "compute"] for t in ts.data]
    spans = [sp for sp in spans if sp]
    return wall, sum(s["stop"] - s["start"] for sp in spans for s in sp), len(spans), spent


def run_mode(mode, args, work: Path) -> dict:
    from relaff_jax import cluster as C
    from relaff_jax.config import override
    from relaff_jax.data.store import chunk_path, read_chunk
    from relaff_jax.data.tasks import feature_chunk, rollout_chunk
    from relaff_jax.config.experiment import experiment_preset
    from relaff_jax.learn import synthetic_datasets
    from relaff_jax.learn.sweep import run_experiment
    from relaff_jax.stages.features import default_feature_factory
    from relaff_jax.stages.generate import default_rollout_factory

    tag = mode.replace(":", "")
    ctx = C.connect(mode, folder=work) if mode != "none" else None
    client = ctx.__enter__() if ctx else None
    try:
        out = {"mode": mode, "slots": C.nthreads(client) if client else 1, "engine": args.engine}
        roll = C.Remote(default_rollout_factory, args.action, args.batch, None, args.engine, pick=0)
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
            run_experiment(data, work / f"sweep-{name}-{tag}", cfg, ["pca"], seed=0, jobs=1, progress=False,
                           client=client)
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


def project(row: dict, nine: tuple | None = None) -> str:
    """The paper preset's wall time on W workers of one core each (one task thread; a native
    worker's MuJoCo runs on that one thread) from one worker's task times (``row``: the
    ``local:1`` mode): every action's chunks at once; ``ceil(tasks / W)`` rounds of one task's
    time per stage, plus the compile each worker pays once per stage. Generation also
    simulates up to ``ceil(W / 9) - 1`` chunks per action past its stopping point. A task's
    time on one core is its CPU time (XLA may spread a task over both cores here, and the
    machine's other load stretches its wall time); the wall-time basis is given beside it.
    ``nine``: (CPU s, wall s) per rollout to use instead of the one action's (``--nine-actions``)."""
    from relaff_jax.config.experiment import experiment_preset
    from relaff_jax.learn import forests_per_space

    p = PAPER
    cfg = experiment_preset("paper")
    fits = sum(forests_per_space(cfg, p["actions"], s) for s in ("pca", "rhf"))
    blocks = sum(p["actions"] * cfg.reps(s) * math.ceil(len(cfg.sizes) / cfg.sizes_per_block) for s in ("pca", "rhf"))
    chunks = p["actions"] * math.ceil(p["n"] * p["rollouts_per_sample"] / p["rollout_batch"])
    fchunks = p["actions"] * math.ceil(p["n"] / p["feature_batch"])
    over = lambda st: (row[st][0] - row[st][1]) / row[st][2]  # noqa: E731 - s per task, local:1

    def walls(basis, w):
        col = 3 if basis == "cpu" else 1
        per_roll = row["generate"][col] / (row["generate"][2] * row["batch"])
        unit = {"generate": nine[0 if basis == "cpu" else 1] if nine else per_roll,
                "features": row["features"][col] / (row["features"][2] * row["feature_batch"]),
                "sweep": row["sweep"][col] / row["fits"]}
        stages = {  # (tasks, seconds per task, fixed seconds)
            "generate": (chunks, p["rollout_batch"] * unit["generate"] + over("generate"), row["compile_generate_s"]),
            "features": (fchunks, p["feature_batch"] * unit["features"] + over("features"), row["compile_features_s"]),
            "experiment": (blocks, fits / blocks * unit["sweep"] + over("sweep"), p["prep_s"]),
        }
        extra = {"generate": p["actions"] * (math.ceil(w / p["actions"]) - 1)}
        rounds = {st: math.ceil((n + extra.get(st, 0)) / w) for st, (n, _, _) in stages.items()}
        return unit, stages, {st: fixed + rounds[st] * t for st, (_, t, fixed) in stages.items()}, rounds

    basis = "cpu" if len(row["generate"]) > 3 and row["generate"][3] == row["generate"][3] else "wall"
    unit, stages, _, _ = walls(basis, 1)
    lines = [f"\nPaper preset projected, {row.get('engine', 'mjx')} engine; a worker = one process with one task thread "
             f"on one core (per task from local:1 {'CPU' if basis == 'cpu' else 'wall'} time: "
             f"{1000 * unit['generate']:.0f} ms per rollout{' (nine actions: --nine-actions)' if nine else ''}, "
             f"{1000 * unit['features']:.0f} ms per scene, "
             f"{1000 * unit['sweep']:.1f} ms per fit; {fits:,} fits in {blocks:,} blocks):",
             "| workers (cores) | generate | features | experiment | report | total | total, wall-time basis | limit |",
             "|---:|---:|---:|---:|---:|---:|---:|---|"]
    for w in (8, 32, 128):
        _, _, wl, rounds = walls(basis, w)
        total = sum(wl.values()) + p["report_s"]
        alt = sum(walls("wall", w)[2].values()) + p["report_s"]
        worst = max(stages, key=lambda st: wl[st])
        t = stages[worst][1]
        limit = (f"{worst}: one task ({t:.0f} s) per worker" if rounds[worst] == 1 else f"{worst}: {rounds[worst]} rounds of {t:.0f} s")
        lines.append(f"| {w} | " + " | ".join(f"{wl[st] / 60:.1f} min" for st in stages)
                     + f" | {p['report_s'] / 60:.1f} min | **{total / 60:.1f} min** | {alt / 60:.1f} min | {limit} |")
    return "\n".join(lines)


def refusal_seconds(timeout: float = 1.0) -> float:
    """Seconds until ``cluster.connect`` refuses a scheduler that is not there (port 9, the
    discard port: nothing listens), with ``timeout``: a bad ``--cluster`` must fail at once,
    not hang (was a timed assertion in tests/cluster/test_cluster.py)."""
    from relaff_jax import cluster as C
    from relaff_jax.errors import UserError

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            with C.connect("tcp://127.0.0.1:9", folder=Path(tmp), timeout=timeout):
                pass
        except UserError:
            return time.perf_counter() - t0
    raise RuntimeError("connected to a scheduler on port 9")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--engine", help="mjx (default) or native; with --memory a comma list (default mjx,native)")
    ap.add_argument("--action", default="push")
    ap.add_argument("--chunks", type=int, default=6)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--feature-batch", type=int, default=8)
    ap.add_argument("--synthetic", type=int, default=300, help="synthetic samples per action for the sweep")
    ap.add_argument("--modes", default="none,local:1,local:2")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--from-json", type=Path, help="print the tables of a saved run, run nothing")
    ap.add_argument("--memory", action="store_true", help="memory per worker: cluster_memory.py")
    ap.add_argument("--nine-actions", type=Path, metavar="MEMORY.json",
                    help="project with the nine actions' mean CPU per rollout of a --memory run (same engine)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).parent))
    if args.memory:
        import cluster_memory

        return cluster_memory.main(args)
    args.engine = args.engine or "mjx"
    if args.engine not in ("mjx", "native"):
        ap.error(f"--engine must be mjx or native, got {args.engine!r}")
    rows = []
    if args.from_json:
        saved = json.loads(args.from_json.read_text())
        rows = saved["rows"]
        for k in ("action", "chunks", "batch", "feature_batch", "synthetic"):
            setattr(args, k, saved["args"][k])
        args.engine = saved["args"].get("engine", "mjx")
    with tempfile.TemporaryDirectory(prefix="relaff-cluster-bench-") as tmp:
        for mode in [] if args.from_json else args.modes.split(","):
            t0, load, utc = time.perf_counter(), os.getloadavg()[0], time.strftime("%H:%M", time.gmtime())
            rows.append(run_mode(mode, args, Path(tmp)))
            rows[-1].update(load=[load, os.getloadavg()[0]], utc=utc)
            print(f"{mode}: {time.perf_counter() - t0:.0f} s in all: {rows[-1]}", file=sys.stderr, flush=True)
            if args.json:  # after every mode, so a failure keeps what was measured
                args.json.write_text(json.dumps({"machine": platform.platform(), "args": {
                    k: v for k, v in vars(args).items() if k not in ("json", "from_json")}, "rows": rows},
                    indent=1, default=str) + "\n")
    base = {st: rows[0][st][0] for st in ("generate", "features", "sweep")} if rows[0]["mode"] == "none" else {}
    print(f"\n{platform.platform()}, {args.engine} engine, {args.chunks} chunks x {args.batch} rollouts of {args.action}, features in "
          f"chunks of {args.feature_batch}, PCA sweep on {args.synthetic} synthetic samples per action")
    print("\n| stage | mode | tasks | wall s | task compute s | per task s | CPU s | cores | overhead ms/task | overhead % "
          "| speed-up |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        r.update(batch=args.batch, feature_batch=args.feature_batch)
        for st in ("generate", "features", "sweep"):
            wall, compute, n, cpu = (list(r[st]) + [float("nan")])[:4]  # runs before the CPU column: nan
            per, over = compute / n, (wall * r["slots"] - compute) / n
            sp = f"{base[st] / wall:.2f}x" if st in base else "-"
            print(f"| {st} | {r['mode']} | {n} | {wall:.1f} | {compute:.1f} | {per:.3f} | {cpu:.1f} | {cpu / compute:.2f} | "
                  f"{'-' if r['mode'] == 'none' else f'{1000 * over:.0f}'} | "
                  f"{'-' if r['mode'] == 'none' else f'{100 * over / per:.1f}'} | {sp} |")
    print("\ncompile per process (s): " + "; ".join(
        f"{r['mode']}: generate {r['compile_generate_s']:.0f}, features {r['compile_features_s']:.0f}" for r in rows))
    if all("load" in r for r in rows):
        print("load average (1 min) before/after each mode: " + "; ".join(
            f"{r['mode']} ({r['utc']} UTC) {r['load'][0]:.1f}/{r['load'][1]:.1f}" for r in rows))
    if not args.from_json:
        print(f"unreachable scheduler (tcp://127.0.0.1:9) refused in {refusal_seconds(1.0):.2f} s with a 1 s timeout")
    one = [r for r in rows if r["mode"] == "local:1"]
    if one:
        print(project(one[0]))
    if one and args.nine_actions:
        import cluster_memory

        mem = json.loads(args.nine_actions.read_text())
        if args.engine not in mem["engines"]:
            ap.error(f"{args.nine_actions} has no {args.engine} run (it has {', '.join(mem['engines'])})")
        print(project(one[0], cluster_memory.per_rollout(mem["engines"][args.engine], mem["batch"])))  # (cpu, wall)
    return 0


if __name__ == "__main__":
    sys.exit(main())
