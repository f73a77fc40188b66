"""The planner's first call in a new process with a warm compilation cache: ``jax.jit`` (traces
and lowers the planner every run) against ``traced_cache.stored_jit`` (reads the stored traced
program), CPU seconds, same bits.

    python benchmarks/planner_trace.py [--batch 64] [--rounds 2] [--cache DIR]

The planner, as the generate stage calls it on each batch: the reach screen
(``reach_screen.make_screen_fn``, which draws all nine actions' programs in one ``lax.switch``),
then the plan of the programs it drew (``planning.make_plan_of_fn``: their IK); in the run the
plan is called in chunks of up to 128 scenes, here on the whole batch. One process first fills a
new compilation cache (``--cache``, default a temporary folder) with both paths' programs; then
each round starts two new processes, one per path, each timing (CPU and wall) its first call on
the same settled lift scenes, which traces (or reads), lowers and loads the compiled programs
from the cache, then a second call (the programs' own run). Outputs are compared bit for bit between the paths (and with the first
process's). Prints a table and ends with ``planner_first_call_cpu_s=<jit> stored=<stored>``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

CHILD = r"""
import json, os, sys, time
c0, w0 = time.process_time(), time.perf_counter()
from relaff_jax import compile_cache
compile_cache.enable_traces(compile_cache.configure())
import jax, jax.numpy as jnp, numpy as np
from relaff_jax.sim import templates
from relaff_jax.sim.planning import make_plan_of_fn
from relaff_jax.sim.reach_screen import make_screen_fn
from relaff_jax.sim.traced_cache import stored_jit
mode, data, out = sys.argv[1], sys.argv[2], sys.argv[3]
z = np.load(data)
pair, qpos = z["pair"], z["qpos"]
cfg = templates.ActionConfig()
screen, plan_of = make_screen_fn(cfg), make_plan_of_fn(cfg)
modes = ["jit", "stored"] if mode == "both" else [mode]
res, times = {}, {"import_cpu": time.process_time() - c0, "import_wall": time.perf_counter() - w0}
for m in modes:
    if m == "jit":
        s, p = jax.jit(screen), jax.jit(plan_of)
    else:
        s, p = stored_jit(screen, "screen", cfg), stored_jit(plan_of, "plan_of", cfg)
    f = lambda a, pr, q, s=s, p=p: p(a, *s(a, pr, q)[3])
    c, w = time.process_time(), time.perf_counter()
    r = jax.device_get(f(0, pair, qpos))
    times[m + "_first_cpu"], times[m + "_first_wall"] = time.process_time() - c, time.perf_counter() - w
    c, w = time.process_time(), time.perf_counter()
    jax.block_until_ready(f(0, pair, qpos))
    times[m + "_second_cpu"], times[m + "_second_wall"] = time.process_time() - c, time.perf_counter() - w
    leaves = jax.tree.leaves(r)
    res.update({f"{m}_{i}": np.asarray(x) for i, x in enumerate(leaves)})
np.savez(out, **res)
print(json.dumps(times))
"""


def settled_scenes(batch: int) -> dict:
    """``batch`` settled lift scenes (placed as the generate stage places them, settled in MuJoCo
    C), seed 0: no planner in this process."""
    import jax

    from relaff_jax.sim import rollouts, templates
    from relaff_jax.sim import scenes as sc
    from relaff_jax.sim import world as wd
    from relaff_jax.sim.native.settle import settle_batch

    cfg = templates.ActionConfig()
    world = wd.build_world(cfg.phys)
    place_fn, _, _ = sc.jitted_scene_fns(world, cfg.scene)
    kp, ks = jax.random.split(jax.random.PRNGKey(0))
    pair = sc.sample_pairs(kp, rollouts.allowed_pairs(world, "lift"), world, batch)
    s = settle_batch(world, *jax.device_get((pair, *place_fn(ks, pair))), cfg.scene, 1)
    return dict(pair=np.asarray(pair, np.int32), qpos=np.asarray(s.qpos, np.float32))


def child(mode: str, data: str, out: str, cache: str) -> dict:
    env = dict(os.environ, RELAFF_COMPILE_CACHE=cache)
    r = subprocess.run([sys.executable, "-c", CHILD, mode, data, out], env=env, check=True, capture_output=True,
                       text=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch", type=int, default=64, help="scenes per call (the quick preset's batch)")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of one new process per path")
    ap.add_argument("--cache", default="", help="compilation cache folder (default: a new temporary one)")
    args = ap.parse_args()
    print(f"load average before {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}",
          flush=True)
    with tempfile.TemporaryDirectory(prefix="relaff_planner_trace_") as tmp:
        cache = args.cache or os.path.join(tmp, "cache")
        data = os.path.join(tmp, "scenes.npz")
        np.savez(data, **settled_scenes(args.batch))
        t0 = time.perf_counter()
        fill = child("both", data, os.path.join(tmp, "fill.npz"), cache)
        print(f"filling the cache (both paths, one process): {time.perf_counter() - t0:.0f} s wall; first calls "
              f"jit {fill['jit_first_cpu']:.1f} s CPU, stored {fill['stored_first_cpu']:.1f} s CPU", flush=True)
        ref = np.load(os.path.join(tmp, "fill.npz"))
        keys = sorted(k[4:] for k in ref.files if k.startswith("jit_"))
        same = all(np.array_equal(ref["jit_" + k], ref["stored_" + k], equal_nan=True) for k in keys)
        rows = []
        for r in range(args.rounds):
            for m in (("jit", "stored") if r % 2 == 0 else ("stored", "jit")):
                out = os.path.join(tmp, f"{m}{r}.npz")
                t = child(m, data, out, cache)
                got = np.load(out)
                same &= all(np.array_equal(ref[f"jit_{k}"], got[f"{m}_{k}"], equal_nan=True) for k in keys)
                rows.append((m, t))
                print(f"  round {r} {m}: first call {t[m + '_first_cpu']:.2f} s CPU, {t[m + '_first_wall']:.2f} s wall",
                      flush=True)
    print(f"\nplanner, batch {args.batch}, first call in a new process, warm compilation cache ({args.rounds} "
          "rounds, mean):")
    print("| path | first call CPU s | first call wall s | second call CPU s | import CPU s |\n|---|---:|---:|---:|---:|")
    mean = {}
    for m in ("jit", "stored"):
        ts = [t for mm, t in rows if mm == m]
        mean[m] = {k: float(np.mean([t[f"{m}_{k}"] for t in ts])) for k in
                   ("first_cpu", "first_wall", "second_cpu")}
        imp = float(np.mean([t["import_cpu"] for t in ts]))
        print(f"| {m} | {mean[m]['first_cpu']:.2f} | {mean[m]['first_wall']:.2f} | {mean[m]['second_cpu']:.3f} | "
              f"{imp:.2f} |")
    print(f"every output equal bit for bit (both paths, every process): {same}; load average after "
          f"{os.getloadavg()[0]:.2f}")
    print(f"planner_first_call_cpu_s={mean['jit']['first_cpu']:.2f} stored={mean['stored']['first_cpu']:.2f}")


if __name__ == "__main__":
    main()
