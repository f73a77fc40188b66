"""Memory per worker (issue 15): ``python benchmarks/cluster.py --memory [--engine mjx,native]``.

For each engine a fresh ``local:1`` Dask worker (``relaff_jax.cluster.connect``, spawned, one
task thread) runs, as separate tasks in this order: one dataset chunk of ``--batch`` rollouts
of each of the nine actions (``constants.ACTIONS``, ``data.tasks.rollout_chunk`` with
``default_rollout_factory(action, batch, None, engine)`` shipped as a ``Remote`` recipe, as
``relaff reproduce --cluster`` does), then one feature chunk of ``--feature-batch`` of those
scenes (``data.tasks.feature_chunk``, the real perception), then the quick PCA and RHF sweep
on ``--synthetic`` samples per action (its prep forests and blocks, ``learn.run_experiment``
given the client). After each step the worker reports its own resident set size from
``/proc/self/status``: ``VmRSS`` (now) and ``VmHWM`` (the peak since the process started),
and the step's wall and CPU time (a chunk's CPU s / batch: the nine actions' cost per rollout,
which ``cluster.py --nine-actions`` uses in its projection). The place, settle and plan (and
MJX's simulate) programs are compiled once for all actions, in a warm-up chunk of the first.
Prints one table per engine (and writes ``--json``, if given).
"""
from __future__ import annotations

import json
import platform
import sys
import tempfile
import time
from pathlib import Path


def rss_mb() -> dict:
    """This process's resident set size now and its peak (MB), from /proc/self/status."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out[key] = int(rest.split()[0]) / 1024  # kB
    return out


def _status(what: str) -> dict:
    t0 = time.perf_counter()
    if what == "imports":
        import importlib

        for name in ("jax", "mujoco", "sklearn", "relaff_jax.data.tasks", "relaff_jax.stages.generate",
                     "relaff_jax.sim.rollouts"):
            importlib.import_module(name)
    return {**rss_mb(), "s": time.perf_counter() - t0}


def _chunk(roll, batch: int, folder: str, k: int = 0) -> dict:
    from relaff_jax.data.tasks import rollout_chunk

    t0, c0 = time.perf_counter(), time.process_time()
    r = rollout_chunk(roll, 7, k, batch, None, folder)
    return {**rss_mb(), "s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
            "positives": int(r["label"].sum())}


def _features(feat, folder: str, batch: int, out: str) -> dict:
    import numpy as np

    from relaff_jax.data.store import chunk_path, read_chunk
    from relaff_jax.data.tasks import feature_chunk

    t0 = time.perf_counter()
    arrays = read_chunk(chunk_path(Path(folder), 0))[0]
    n = len(arrays["pair"])
    idx = np.minimum(np.arange(batch), n - 1)
    samples = {k: arrays[k][idx] for k in ("pair", "qpos_settled", "rollout_id", "rollout")}
    feature_chunk(feat, samples, 0, batch, 0, min(batch, n), out)
    return {**rss_mb(), "s": time.perf_counter() - t0}


def measure(engine: str, args, work: Path) -> list[dict]:
    """The steps of one fresh worker with ``engine``: ``[{step, VmRSS, VmHWM, s}, ...]``."""
    from relaff_jax import cluster as C
    from relaff_jax.config import override
    from relaff_jax.constants import ACTIONS
    from relaff_jax.config.experiment import experiment_preset
    from relaff_jax.learn import synthetic_datasets
    from relaff_jax.learn.sweep import run_experiment
    from relaff_jax.stages.features import default_feature_factory
    from relaff_jax.stages.generate import default_rollout_factory

    rows = []

    def step(name, fn, *a):
        r = client.submit(fn, *a, pure=False).result()
        rows.append({"step": name, **r})
        print(f"  {engine} {name}: VmRSS {r['VmRSS']:.0f} MB, VmHWM {r['VmHWM']:.0f} MB, {r['s']:.1f} s "
              f"({time.strftime('%H:%M:%S', time.gmtime())} UTC)", file=sys.stderr, flush=True)

    with C.connect("local:1", folder=work) as client:
        step("worker started (connect's check imported jax)", _status, "")
        step("+ mujoco, scikit-learn, relaff_jax.sim", _status, "imports")
        for i, action in enumerate(ACTIONS):
            roll = C.Remote(default_rollout_factory, action, args.batch, None, engine, pick=0)
            if i == 0:  # the programs are compiled once for all nine actions: apart, not in lift's time
                step(f"warm-up: compile, one {action} chunk", _chunk, roll, args.batch, str(work / f"{engine}-warm"), 1)
            step(f"chunk {action}", _chunk, roll, args.batch, str(work / f"{engine}-{action}"))
        feat = C.Remote(default_feature_factory, 0, pick=0)
        step(f"feature chunk ({args.feature_batch} scenes)", _features, feat, str(work / f"{engine}-{ACTIONS[-1]}"),
             args.feature_batch, str(work / f"{engine}-features"))
        cfg = override(experiment_preset("quick"), {"sizes": (2, 10, 25, 50, 75, 100)})
        data = synthetic_datasets(args.synthetic, seed=0)
        t0 = time.perf_counter()
        run_experiment(data, work / f"{engine}-sweep", cfg, ["pca", "rhf"], seed=0, jobs=1, progress=False,
                       client=client)
        blocks = sum(len(list((work / f"{engine}-sweep" / s / "blocks").iterdir())) for s in ("pca", "rhf"))
        r = {**client.submit(rss_mb, pure=False).result(), "s": time.perf_counter() - t0}
        rows.append({"step": f"sweep, PCA + RHF ({blocks} blocks)", **r})
    return rows


def table(engine: str, rows: list[dict], batch: int) -> str:
    lines = [f"\n{engine} engine, one local:1 worker, chunks of {batch} rollouts:",
             "| step (in order, one worker) | VmRSS MB | VmHWM (peak) MB | step s | CPU ms per rollout | positives |",
             "|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['step']} | {r['VmRSS']:.0f} | {r['VmHWM']:.0f} | {r['s']:.1f} | "
              + (f"{1000 * r['cpu_s'] / batch:.0f} | {r['positives']} |" if "cpu_s" in r else "| |") for r in rows]
    chunks = [r for r in rows if r["step"].startswith("chunk ")]
    if chunks:
        cpu, wall = per_rollout(rows, batch)
        lines.append(f"\nnine actions' mean: {1000 * cpu:.0f} ms CPU, {1000 * wall:.0f} ms wall per rollout "
                     f"({batch * wall:.1f} s wall per chunk of {batch})")
    return "\n".join(lines)


def per_rollout(rows: list[dict], batch: int) -> tuple[float, float]:
    """Mean (CPU s, wall s) per rollout over the nine actions' chunks (warm-up excluded)."""
    chunks = [r for r in rows if r["step"].startswith("chunk ")]
    return tuple(sum(r[k] for r in chunks) / (len(chunks) * batch) for k in ("cpu_s", "s"))


def main(args) -> int:
    engines = (args.engine or "mjx,native").split(",")
    bad = [e for e in engines if e not in ("mjx", "native")]
    if bad:
        raise SystemExit(f"--engine: unknown {bad}; valid: mjx, native")
    out = {"machine": platform.platform(), "batch": args.batch, "feature_batch": args.feature_batch,
           "synthetic": args.synthetic, "engines": {}}
    if args.from_json:  # the tables of a saved run
        out = json.loads(args.from_json.read_text())
        engines = []
    with tempfile.TemporaryDirectory(prefix="relaff-cluster-memory-") as tmp:
        for engine in engines:
            out["start_utc"] = out.get("start_utc", time.strftime("%H:%M", time.gmtime()))
            t0 = time.perf_counter()
            out["engines"][engine] = measure(engine, args, Path(tmp))
            print(f"{engine}: {time.perf_counter() - t0:.0f} s in all", file=sys.stderr, flush=True)
            if args.json:
                args.json.write_text(json.dumps(out, indent=1) + "\n")
    print(f"\n{platform.platform()}, resident set size of the worker process after each step")
    for engine, rows in out["engines"].items():
        print(table(engine, rows, out["batch"]))
    return 0
