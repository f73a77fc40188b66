"""The paper preset stage by stage: each stage's rate measured in one run on 2 cores, beside
its reference in the same run, and the paper preset's wall time, measured and projected (issue 26).

    python benchmarks/paper_stages.py [--actions lift ...] [--parts lift ...] [--batch 1024]
                                      [--batches 2] [--features 256] [--forests 16] [--smoke]
                                      [--write-figures]

- data: the native rollout function itself (``make_rollout_fn(..., engine="native")``: C
  settle, the default L-BFGS plans, C execution; what ``relaff generate --engine native``
  runs per chunk), labelled rollouts/s of the whole batch per action and the cores it kept
  busy, with the reach screen (the default, ``sim/reach_screen.py``) against without it,
  batches interleaved, every field checked equal but the screened scenes' ``ik_error``. ``--parts``: the batch part by part (place, settle in MJX and in C, plan by L-BFGS
  and by LM, C execution of each plan; the rates "today" = MJX settle, "C settle" = the
  engine now, "C settle + LM" = ``--set action.arm.ik_solver=lm``, other plans).
- forests: the compiled engine (``learn/forest/compiled``, the sweep's) against the fast one
  (scikit-learn's builder per tree + one JAX evaluation), fit + evaluation on 4,000 rows at
  n = 25 and 100, wall and CPU seconds (the experiment runs one worker per core, so CPU).
- features: the stage's feature function (``from_sim.make_feature_fn``: capacities sized per
  call) against the same at the config's capacities (``culled=False``), same scenes, same bits.
- quick: ``relaff reproduce --preset quick`` into a new folder, a subprocess whose JAX
  compilation cache is ``--xla-cache`` (so warm from this benchmark's second run on).
- report: its bootstrap over test scenes (``resampled_means`` + ``half_curves``), the
  reference path against the fast one, one paper-shaped PCA target (``--report-sizes`` sizes).

Projection: the paper preset on programs v4 (``PAPER_RUN_ROLLOUTS``, ``PAPER_RUN_S``: its datasets'
rollouts per action and its features, experiment and report stages measured on idle cores on
2026-12-07); the projected row takes those rollouts per action at this run's rates (actions not
timed at their mean) plus one compile, and the three later stages as measured (this run's
slices of them are printed as checks). One process, as run (the experiment's two workers
included).
``--smoke`` (lift, batch 64, two timed batches, 8 forests per cell, one chunk of 32 scenes,
a report target of 3 sizes) runs in under 5 minutes once JAX's persistent compilation cache
(``--xla-cache``) holds its programs; batch 64 is slower per rollout than the preset's 1024,
so its projection is pessimistic. The last line is ``native_per_s=<whole-batch labelled
rollouts/s, lift> forest_speedup=<compiled/fast CPU s per forest, n = 25, PCA>
paper_projected_h=<hours, projected> quick_s=<wall seconds of the quick preset's run>``
(``--no-quick``: ``quick_s=nan``; the quick run adds 2-4 minutes with a warm cache).
``--quick-only`` runs only the quick preset, twice on a new empty compilation cache (fresh,
then warm into a new folder), wall and CPU seconds of each; its last line is ``quick_s=<the
warm run's wall seconds>``, the line before it ``quick_fresh_s=... quick_fresh_cpu_s=...
quick_cpu_s=...``.
``--write-figures`` writes the quick run's time into ``docs/figures.json`` (record
``quick_native_s`` with ``--xla-cache ''``, compiles included; else ``quick_native_warm_s``).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from relaff_jax.constants import ACTIONS, action_id  # noqa: E402
from relaff_jax.sim import rollouts, templates  # noqa: E402
from relaff_jax.sim.native import settle as native_settle
from relaff_jax.sim import scenes as sc  # noqa: E402
from relaff_jax.sim import world as wd  # noqa: E402
from relaff_jax.sim.native.batch import default_threads, execute_native  # noqa: E402
from relaff_jax.sim.planning import Plan  # noqa: E402

# The paper preset on programs v4 (docs/journal/2026-12-07.md): rollouts per action of its datasets
# (seed 0, population feasible, 10,000 samples each; chunks of 1,024), and the seconds of its
# features, experiment and report stages measured in one stretch on two idle cores
# ("The paper preset's features, experiment and report stages on idle cores"). Its generate stage
# was not measured in one stretch (its datasets were made over three sessions).
PAPER_RUN_ROLLOUTS = {"lift": 23_552, "move": 47_104, "pull": 24_576, "push": 40_960, "rake": 50_176,
                      "take": 38_912, "pour": 65_536, "slide": 60_416, "unobstruct": 21_504}
PAPER_RUN_S = {"features": 327, "experiment": 1_118, "report": 287}
PAPER_SCENES = 90_000


def _execute(action, cfg, pair, s, plan, before, nthread):
    run = np.flatnonzero(plan.feasible)
    label = np.zeros(len(pair), bool)
    if len(run):
        sub = Plan(plan.q_way[run], plan.grip_way[run], plan.seg_steps, plan.feasible[run],
                   plan.direction[run], plan.ik_error[run])
        label[run] = execute_native(action, cfg, pair[run], np.asarray(s.qpos)[run], np.asarray(s.qvel)[run],
                                    sub, np.asarray(before)[run], nthread=nthread)["label"]
    return label


def data_stage(action: str, batch: int, batches: int, nthread: int) -> dict:
    """Seconds per batch of each part, summed over the timed batches, and the rates."""
    cfg = templates.ActionConfig()
    lm = dataclasses.replace(cfg, arm=dataclasses.replace(cfg.arm, ik_solver="lm"))
    sw = wd.build_world(cfg.phys)
    place_fn, settle_fn, _ = sc.jitted_scene_fns(sw, cfg.scene)
    plan_lbfgs, plan_lm = rollouts.jitted_stage_fns(cfg)[0], rollouts.jitted_stage_fns(lm)[0]
    allowed = rollouts.allowed_pairs(sw, action)
    aid = action_id(action)
    t = dict(place=0.0, settle_mjx=0.0, settle_c=0.0, plan_lbfgs=0.0, plan_lm=0.0, exec_lbfgs=0.0, exec_lm=0.0)
    agree = feasible = 0
    for b in range(batches + 1):
        tic = {}
        t0 = time.perf_counter()
        kp, ks = jax.random.split(rollouts.bench_batch_key(0, batch, b))[:2]
        pair = sc.sample_pairs(kp, allowed, sw, batch)
        qpos0, intended = jax.device_get(place_fn(ks, pair))
        pair = np.asarray(pair)
        tic["place"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        jax.block_until_ready(settle_fn(jnp.asarray(pair), jnp.asarray(qpos0), jnp.asarray(intended)))
        tic["settle_mjx"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        s = native_settle.settle_batch(sw, pair, qpos0, intended, cfg.scene, nthread)
        tic["settle_c"] = time.perf_counter() - t0
        labels = {}
        for name, fn, c in (("lbfgs", plan_lbfgs, cfg), ("lm", plan_lm, lm)):
            t0 = time.perf_counter()
            plan, before = jax.device_get(fn(aid, jnp.asarray(pair), jnp.asarray(s.qpos)))
            tic[f"plan_{name}"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            labels[name] = _execute(action, c, pair, s, plan, before, nthread)
            tic[f"exec_{name}"] = time.perf_counter() - t0
            feasible += int(np.sum(plan.feasible)) if name == "lm" and b else 0
        if b:  # the first batch compiles
            for k in t:
                t[k] += tic[k]
            agree += int(np.sum(labels["lm"] == labels["lbfgs"]))
    n = batch * batches
    # the two plans' executions are the same work to within a few scenes: each rate counts
    # their mean, so that the load's noise on one of them does not pass for a speed-up
    ex = (t["exec_lbfgs"] + t["exec_lm"]) / 2
    today = t["place"] + t["settle_mjx"] + t["plan_lbfgs"] + ex
    csettle = t["place"] + t["settle_c"] + t["plan_lbfgs"] + ex
    new = t["place"] + t["settle_c"] + t["plan_lm"] + ex
    return dict(action=action, n=n, seconds={k: v / batches for k, v in t.items()}, today=n / today,
                c_settle=n / csettle, new=n / new, agree=agree / n, feasible=feasible)


def rollout_stage(action: str, batch: int, batches: int, nthread: int) -> dict:
    """Whole-batch labelled rollouts/s of the native rollout function itself, what ``relaff
    generate --engine native`` runs per chunk (C settle, default L-BFGS plans, C execution),
    with the reach screen (``per_s``, the default) and without (``per_s_ref``, the reference):
    ``batches`` timed batches of each after one untimed call of each (``first_s``: the
    compiles), interleaved batch by batch on the same keys; every field of the two equal but
    the screened scenes' ``ik_error`` (NaN), checked. ``cores``: process CPU time over wall
    time, screened."""
    base = templates.ActionConfig()
    ref_cfg = dataclasses.replace(base, arm=dataclasses.replace(base.arm, reach_screen=False))
    fns = {name: rollouts.make_rollout_fn(action, batch, c, engine="native", nthread=nthread)
           for name, c in (("new", base), ("ref", ref_cfg))}
    key = lambda i: rollouts.bench_batch_key(1, batch, i)
    t0 = time.perf_counter()
    fns["new"](key(0), batch)
    first = time.perf_counter() - t0
    fns["ref"](key(0), batch)
    wall, cpu, screened = {"new": 0.0, "ref": 0.0}, 0.0, 0
    for i in range(batches):
        outs = {}
        for name in (("new", "ref") if i % 2 == 0 else ("ref", "new")):
            c0, t0 = os.times(), time.perf_counter()
            outs[name] = fns[name](key(1 + i), batch)
            wall[name] += time.perf_counter() - t0
            c1 = os.times()
            if name == "new":
                cpu += (c1.user - c0.user) + (c1.system - c0.system)
        skip = np.isnan(outs["new"]["ik_error"])
        screened += int(skip.sum())
        for k, v in outs["ref"].items():
            g = outs["new"][k]
            same = np.array_equal(g[~skip], v[~skip]) if k == "ik_error" else np.array_equal(g, v)
            if not same:
                raise AssertionError(f"{action}: the reach screen changed {k}")
    n = batches * batch
    return dict(action=action, n=n, batch=batch, per_s=n / wall["new"], per_s_ref=n / wall["ref"], first_s=first,
                cores=cpu / wall["new"], screened=screened / n)


def _forest_times(space: str, n: int, k: int, engine: str) -> tuple[float, float]:
    """(wall, CPU) seconds per forest of ``engine``: fit + evaluation on 4,000 rows
    (``predict_many``) of ``k`` DB1 learners at size n on ``benchmarks/sweep.py``'s inputs,
    after an untimed pass (compiles), and the predictions."""
    import sweep

    from relaff_jax import learn as E
    from relaff_jax.config.experiment import ExperimentConfig
    from relaff_jax.learn.forest import engine as G

    cfg = ExperimentConfig()
    rep = cfg.repeats(space)
    X, y, boot, test_idx, order = sweep._block_inputs(space)
    tr, d0 = order[:n], X.shape[1]
    ZT = np.concatenate([X[test_idx].T, boot[:, test_idx]])
    maps = [np.concatenate([np.arange(d0), d0 + np.repeat([s % len(boot)], rep)]) for s in range(k)]
    fits = [(E.augment(X[tr], boot[[s % len(boot)]][:, tr], rep), y[tr], 1000 + s) for s in range(k)]
    run = lambda: G.predict_many([G.fit(x, yy, sd, cfg.forest, engine=engine) for x, yy, sd in fits], ZT, maps)
    run()
    c0, t0 = time.process_time(), time.perf_counter()  # CPU time of every thread of the process
    pred = run()
    return (time.perf_counter() - t0) / k, (time.process_time() - c0) / k, pred


def forest_stage(k: int) -> dict:
    """Per forest (fit + evaluation on 4,000 rows) by (space, n): ``{(space, n): {engine:
    (wall s, CPU s)}}`` of the fast and the compiled engine, rounds interleaved; checks both
    predict the same. CPU seconds are what counts in the experiment stage, which runs one
    worker process per core: the fast engine's JAX evaluation spreads over both cores of an
    idle machine in one process, the compiled engine is one thread."""
    out = {}
    for space in ("pca", "rhf"):
        for n in (25, 100):
            fast, comp = _forest_times(space, n, k, "fast"), _forest_times(space, n, k, "compiled")
            if not np.array_equal(fast[2], comp[2]):
                raise AssertionError(f"{space} n={n}: the fast and compiled engines predicted differently")
            out[(space, n)] = {"fast": fast[:2], "compiled": comp[:2]}
    return out


def features_stage(n: int) -> dict:
    """Scenes/s of the stage's feature function (``from_sim.make_feature_fn``: capacities sized
    per call, ``perception.culled``) against the same function at the config's capacities
    (``culled=False``, the stage before issue 47), on the same n C-settled lift scenes in chunks
    of 32 (the paper preset's feature_batch), after an untimed pass over every chunk (compiles),
    chunks alternating which goes first; checks every output equal."""
    from relaff_jax.config.perception import PerceptionConfig
    from relaff_jax.perception import from_sim

    cfg = templates.ActionConfig()
    sw = wd.build_world(cfg.phys)
    place_fn, _, _ = sc.jitted_scene_fns(sw, cfg.scene)
    pair = np.asarray(sc.sample_pairs(jax.random.PRNGKey(7), rollouts.allowed_pairs(sw, "lift"), sw, n))
    q0, it = jax.device_get(place_fn(jax.random.PRNGKey(8), jnp.asarray(pair)))
    s = native_settle.settle_batch(sw, pair, q0, it, cfg.scene, default_threads())
    ids = np.arange(n, dtype=np.int64) + 2**33
    chunks = [{"pair": pair[lo:lo + 32], "qpos_settled": np.asarray(s.qpos)[lo:lo + 32], "rollout_id": ids[lo:lo + 32]}
              for lo in range(0, n, 32)]
    pcfg = PerceptionConfig()
    fns = {"today": from_sim.make_feature_fn(sw, pcfg, 0, culled=False), "new": from_sim.make_feature_fn(sw, pcfg, 0)}
    for f in fns.values():
        for c in chunks:
            f(c)
    t = {k: 0.0 for k in fns}
    outs = {"today": [], "new": []}
    for i, c in enumerate(chunks):
        for name in (("today", "new") if i % 2 == 0 else ("new", "today")):
            t0 = time.perf_counter()
            outs[name].append(fns[name](c))
            t[name] += time.perf_counter() - t0
    same = all(np.array_equal(a[k], b[k]) for a, b in zip(outs["today"], outs["new"]) for k in a)
    return dict(n=len(chunks) * 32, rates={k: len(chunks) * 32 / v for k, v in t.items()}, identical=same)


def quick_preset(cache: str) -> dict:
    """Wall seconds of ``relaff reproduce --preset quick`` into a new folder (a subprocess, the
    compilation cache in ``cache``: warm from the second run of this benchmark on), its CPU
    seconds (the process and its workers) and its stage seconds from the run log."""
    import json
    import resource
    import subprocess
    import tempfile

    env = dict(os.environ, RELAFF_COMPILE_CACHE=cache or "0")
    cpu = lambda: (lambda r: r.ru_utime + r.ru_stime)(resource.getrusage(resource.RUSAGE_CHILDREN))
    with tempfile.TemporaryDirectory(prefix="relaff_quick_") as tmp:
        t0, c0 = time.perf_counter(), cpu()
        subprocess.run([sys.executable, "-m", "relaff_jax.cli", "reproduce", "--preset", "quick", "--out",
                        os.path.join(tmp, "q"), "--no-progress"], env=env, check=True, capture_output=True)
        wall, cpu_s = time.perf_counter() - t0, cpu() - c0
        log = json.load(open(os.path.join(tmp, "q", "run.json")))
    run = log["runs"][-1]
    programs = log.get("config", {}).get("action", {}).get("programs")
    return dict(seconds=wall, cpu=cpu_s, stages={k: v["seconds"] for k, v in run["stages"].items()}, programs=programs)


def quick_fresh_and_warm() -> tuple[dict, dict]:
    """The quick preset twice on one new, empty compilation cache: fresh (every compile and
    trace), then warm (a new run folder, the cache the first run filled)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="relaff_quick_cache_") as cache:
        return quick_preset(cache), quick_preset(cache)


def print_quick(what: str, quick: dict) -> None:
    print(f"\nquick preset, `relaff reproduce --preset quick` into a new folder, compilation cache {what}: "
          f"{quick['seconds']:.0f} s wall, {quick['cpu']:.0f} s CPU, load average after {os.getloadavg()[0]:.2f}; "
          "stages (s): " + ", ".join(f"{k} {v:.0f}" for k, v in quick["stages"].items()), flush=True)


def project(rollout: list[dict]) -> dict:
    """Seconds per stage of the paper preset: ``measured`` (``PAPER_RUN_S``: the v4 run's
    features, experiment and report stages on idle cores) and ``projected``: data = the v4
    datasets' rollouts per action at this run's whole-batch rate of the native rollout function
    (an action not measured at the mean rate of those measured; one call after another, so an
    upper bound of the stage, which prepares the next chunk beside this one's execution) + one
    compile (programs are shared by the nine actions); features, experiment and report = the
    measured ones (this run's slices of them are printed as checks, not projected: a slice of
    the feature function on one thread understates the stage's two threads, and the
    experiment's and report's slices do not scale to the whole by a known factor)."""
    rate = {d["action"]: d["per_s"] for d in rollout}
    mean = float(np.mean(list(rate.values())))
    data = sum(r / rate.get(a, mean) for a, r in PAPER_RUN_ROLLOUTS.items())
    data += max(0.0, rollout[0]["first_s"] - rollout[0]["batch"] / rollout[0]["per_s"])
    new = {"data": data, **PAPER_RUN_S}
    out = {"measured": dict(PAPER_RUN_S), "projected": new}
    for v in out.values():
        v["total"] = sum(v.values())
    return out


def report_stage(sizes: int, resamples: int) -> dict:
    """Seconds of the report's two resampling functions, reference and fast, on one
    paper-shaped target (``benchmarks/report_resampling.py``'s ``measure``, R = 50, PCA)."""
    import report_resampling as rr

    row = rr.measure(50, sizes, resamples, ())
    ref = sum(v[0] for v in row.values())
    new = sum(v[1] for v in row.values())
    return dict(ref=ref, new=new, ratio=ref / new, identical=all(v[2] for v in row.values()), sizes=sizes,
                resamples=resamples)


def write_quick_figure(quick: dict, cache: str) -> None:
    """Update the quick preset's record in ``docs/figures.json`` from this run: its wall
    seconds and stage seconds, today's date and the machine (``benchmarks/figures.py``)."""
    import figures

    rid = "quick_native_warm_s" if cache else "quick_native_s"
    rec = figures.load()[rid]
    rec = dict(rec, value=round(quick["seconds"]), stages_s={k: round(v) for k, v in quick["stages"].items()})
    rec["rests_on"] = dict(rec["rests_on"], date=figures.today(), machine=figures.machine_line(),
                           programs=quick.get("programs") or "not recorded")
    figures.write_records([rec])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS),
                    help="actions whose native rollout function is timed (default: all nine)")
    ap.add_argument("--parts", nargs="*", default=["lift"],
                    help="actions whose batch is also timed part by part, today's MJX settle and the LM plans beside")
    ap.add_argument("--batch", type=int, default=1024, help="rollouts per batch (the paper preset's)")
    ap.add_argument("--batches", type=int, default=2,
                    help="timed batches per action (after one untimed); a batch's time varies by +-15 %%, so "
                         "use 16 or more for a projection (docs/benchmarks.md, \"Reading a benchmark's figure\")")
    ap.add_argument("--features", type=int, default=256, help="scenes for the features stage")
    ap.add_argument("--forests", type=int, default=16, help="forests per (space, n)")
    ap.add_argument("--report-sizes", type=int, default=20, help="training sizes of the report's resampling target")
    ap.add_argument("--no-quick", dest="quick", action="store_false",
                    help="skip the quick preset's run (quick_s=nan)")
    ap.add_argument("--quick-only", action="store_true",
                    help="only the quick preset: twice on a new empty compilation cache, fresh then warm "
                         "(prints quick_fresh_s and ends with quick_s = the warm run's seconds)")
    ap.add_argument("--smoke", action="store_true", help="lift, batch 64, 2 batches, few forests and scenes")
    ap.add_argument("--rollouts-only", action="store_true",
                    help="time the native rollout functions (with and without the reach screen) and stop")
    ap.add_argument("--write-figures", action="store_true",
                    help="write the quick preset's wall time into docs/figures.json: quick_native_s with "
                         "--xla-cache '' (compiles included), else quick_native_warm_s (warm cache from the "
                         "benchmark's second run; benchmarks/figures.py)")
    ap.add_argument("--xla-cache", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "relaff_paper_stages_xla"),
                    help="JAX's persistent compilation cache ('' for none): a rerun skips the ~2-5 min of compiles")
    args = ap.parse_args()
    if args.write_figures and (args.smoke or not args.quick or args.quick_only):
        ap.error("--write-figures records the quick preset's run: not with --smoke, --no-quick or --quick-only")
    if args.quick_only:
        print(f"machine: {platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}; load average before "
              f"{os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
        fresh, warm = quick_fresh_and_warm()
        print_quick("new and empty (fresh)", fresh)
        print_quick("the one the fresh run filled (warm)", warm)
        print(f"quick_fresh_s={fresh['seconds']:.0f} quick_fresh_cpu_s={fresh['cpu']:.0f} quick_cpu_s={warm['cpu']:.0f}")
        print(f"quick_s={warm['seconds']:.0f}")
        return
    resamples = 1000
    if args.smoke:
        args.actions, args.parts, args.batch, args.batches, args.features, args.forests = ["lift"], ["lift"], 64, 2, 32, 8
        args.report_sizes, resamples = 3, 200
    if args.xla_cache:
        jax.config.update("jax_compilation_cache_dir", args.xla_cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    t_start = time.perf_counter()
    stamp = lambda what: print(f"  [{time.perf_counter() - t_start:.0f} s: {what}]", flush=True)
    nthread = default_threads()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, C threads {nthread}; jax {jax.__version__}; "
          f"load average before {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
    print(f"\nnative rollout function (C settle, L-BFGS plans, C execution), batch {args.batch}, {args.batches} timed "
          "batches after one untimed:")
    print("| action | labelled rollouts/s (whole batch), reach screen | without (reference) | ratio | scenes screened "
          "| cores busy | first call s (compiles) |\n|---|---:|---:|---:|---:|---:|---:|")
    rollout = []
    for a in args.actions:
        d = rollout_stage(a, args.batch, args.batches, nthread)
        print(f"| {a} | {d['per_s']:.1f} | {d['per_s_ref']:.1f} | {d['per_s'] / d['per_s_ref']:.2f} "
              f"| {d['screened']:.1%} | {d['cores']:.2f} | {d['first_s']:.1f} |", flush=True)
        rollout.append(d)
    stamp("rollout functions done")
    if args.rollouts_only:
        return
    if args.parts:
        print("\n| action | batch | s/batch: place, MJX settle, C settle, plan L-BFGS, plan LM, exec (L-BFGS plans), "
              "exec (LM) | today /s | C settle /s | C settle + LM /s | labels LM = L-BFGS |")
        print("|---|---:|---|---:|---:|---:|---:|")
    for a in args.parts:
        d = data_stage(a, args.batch, args.batches, nthread)
        s = d["seconds"]
        parts = ", ".join(f"{s[k]:.2f}" for k in ("place", "settle_mjx", "settle_c", "plan_lbfgs", "plan_lm",
                                                   "exec_lbfgs", "exec_lm"))
        print(f"| {a} | {args.batch} | {parts} | {d['today']:.1f} | {d['c_settle']:.1f} | {d['new']:.1f} | "
              f"{100 * d['agree']:.2f} % of {d['n']} |", flush=True)
    stamp("data parts done")
    forest = forest_stage(args.forests)
    stamp("forest stage done")
    print(f"\nforests, compiled engine against the fast engine, {args.forests} per cell, fit + evaluation on 4,000 "
          "rows (same predictions); CPU seconds count in the experiment stage (one worker per core):")
    print("| space | n | fast ms wall / CPU | compiled ms wall / CPU | compiled / fast, wall | compiled / fast, CPU |")
    print("|---|---:|---:|---:|---:|---:|")
    for (space, n), e in forest.items():
        (fw, fc), (cw, cc) = e["fast"], e["compiled"]
        print(f"| {space} | {n} | {1e3 * fw:.2f} / {1e3 * fc:.2f} | {1e3 * cw:.2f} / {1e3 * cc:.2f} | {fw / cw:.2f} | "
              f"{fc / cc:.2f} |", flush=True)
    feats = features_stage(args.features)
    stamp("features stage done")
    r = feats["rates"]
    print(f"\nfeatures, {feats['n']} lift scenes in chunks of 32: at the config's capacities {r['today']:.1f} "
          f"scenes/s, capacities sized per call {r['new']:.1f} scenes/s, ratio {r['new'] / r['today']:.2f}, "
          f"bit-identical {feats['identical']}", flush=True)
    rep = report_stage(args.report_sizes, resamples)
    stamp("report stage done")
    print(f"\nreport resampling, one PCA target, {rep['sizes']} sizes, {rep['resamples']} resamples: reference "
          f"{rep['ref']:.1f} s, fast {rep['new']:.1f} s, reference / fast {rep['ratio']:.2f}, same bits {rep['identical']}")
    proj = project(rollout)
    print("\npaper preset on programs v4, seconds (measured: its features, experiment and report stages on idle "
          "cores, 2026-12-07; projected: data at this run's rates, the other stages as measured):")
    print("| | data (native) | features | experiment | report | total | hours |\n|---|---:|---:|---:|---:|---:|---:|")
    for which, p in proj.items():
        data = f"{p['data']:.0f}" if "data" in p else "not measured"
        print(f"| {which} | {data} | {p['features']:.0f} | {p['experiment']:.0f} | {p['report']:.0f} | "
              f"{p['total']:.0f} | {p['total'] / 3600:.2f} |")
    lift = next((d for d in rollout if d["action"] == "lift"), rollout[0])
    sp = forest[("pca", 25)]
    quick = quick_preset(args.xla_cache) if args.quick else {"seconds": float("nan"), "stages": {}}
    if args.quick:
        stamp("quick preset done")
        print_quick(args.xla_cache or "off", quick)
    if args.write_figures:
        write_quick_figure(quick, args.xla_cache)
    print(f"\nwall time of this benchmark {time.perf_counter() - t_start:.0f} s; load average after {os.getloadavg()[0]:.2f}")
    print(f"native_per_s={lift['per_s']:.1f} forest_speedup={sp['fast'][1] / sp['compiled'][1]:.2f} "
          f"paper_projected_h={proj['projected']['total'] / 3600:.2f} quick_s={quick['seconds']:.0f}")


if __name__ == "__main__":
    main()
