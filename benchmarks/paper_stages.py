"""The paper preset stage by stage: today's rate and the new one in the same run, and the
projected wall time of each stage and of the whole preset (issue 26).

    python benchmarks/paper_stages.py [--actions lift ...] [--batch 1024] [--batches 2]
                                      [--features 256] [--forests 16] [--smoke]

Stages, each measured on the same inputs for today's code path and the new one, interleaved:
- data (``--engine native``): one prepared batch = sample + place (shared), settle, plan,
  execute in MuJoCo C, labelled rollouts/s of the whole batch per action. Today: MJX settle
  (``scenes.jitted_scene_fns``) + the L-BFGS plan; "C settle": the native engine's settle of
  this branch (``native_settle.settle_batch``) + the L-BFGS plan (what ``--engine native``
  does by default now); new: C settle + ``ArmConfig.ik_solver="lm"`` (an option: other
  plans, recorded in the sidecar). Plans of both solvers are made on the C-settled scenes and
  each is executed (every rate counts the mean of the two executions: the same work to within
  a few scenes); the label agreement of the two is printed. The first batch (compiles) is
  not timed.
- forests: fit + evaluation on 4,000 rows per forest at n = 25 and 100, PCA and RHF
  (``benchmarks/sweep.py``'s ``engine_times``), with ``ForestConfig``'s current engine; a
  "compiled" engine is used for "new" if ``learn.forests.ENGINES`` has one, else the new rate
  is today's (``forest_speedup=1.0``).
- features: the perception of stored scenes (``from_sim.make_feature_fn``) with the chunk of
  ``feature_batch`` = 32 in one call (today) and in calls of ``from_sim.SUB_BATCH`` (new),
  against the chain alone (``make_batched_features``' jitted program on precomputed inputs).

Projection (the paper preset, ``docs/reproduce.md``): ~500,000 rollouts (take ~194,000, the
other eight ~38,250 each) at the measured per-action rates (an action not measured takes the
mean of the measured ones); 90,000 scenes of features; the sweep's 2 h 05 min measured with
two workers (``docs/learning.md``) divided by the forest speedup; 0.1 h for the report. One
process, as measured (the cluster's second worker is not assumed).
``--smoke`` (lift, batch 64, two timed batches, 2 forests per cell, one chunk of 32 scenes)
runs in under 5 minutes once JAX's persistent compilation cache (``--xla-cache``, default
``$TMPDIR/relaff_paper_stages_xla``) holds its programs; the first run also compiles (the
L-BFGS plan alone ~40-100 s on 2 cores; docs/benchmarks.md gives both times). The last line is ``native_per_s=<new whole-batch labelled rollouts/s, lift>
forest_speedup=<new/today per forest, n = 25, PCA> paper_projected_h=<hours, new>``.
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
from relaff_jax.sim import native_settle, rollouts, templates  # noqa: E402
from relaff_jax.sim import scenes as sc  # noqa: E402
from relaff_jax.sim import world as wd  # noqa: E402
from relaff_jax.sim.native_batch import default_threads, execute_native  # noqa: E402
from relaff_jax.sim.planning import Plan  # noqa: E402

PAPER_ROLLOUTS = {a: (194_000 if a == "take" else 38_250) for a in ACTIONS}  # docs/reproduce.md
PAPER_SCENES = 90_000
SWEEP_TODAY_H = 2 + 5 / 60  # docs/learning.md: two workers, the fast engine
REPORT_H = 0.1


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


def _compiled_times(space: str, n: int, k: int) -> float:
    """Seconds per forest of a "compiled" engine (fit, then ``predict_many`` on 4,000 rows),
    through ``learn.engine.fit(..., engine="compiled")`` on sweep.py's inputs."""
    import sweep

    from relaff_jax import learn as E
    from relaff_jax.learn import engine as G

    cfg = E.ExperimentConfig()
    rep = cfg.repeats(space)
    X, y, boot, test_idx, order = sweep._block_inputs(space)
    tr, d0 = order[:n], X.shape[1]
    ZT = np.concatenate([X[test_idx].T, boot[:, test_idx]])
    maps = [np.concatenate([np.arange(d0), d0 + np.repeat([s % len(boot)], rep)]) for s in range(k)]
    fits = [(E.augment(X[tr], boot[[s % len(boot)]][:, tr], rep), y[tr], 1000 + s) for s in range(k)]
    G.predict_many([G.fit(x, yy, sd, cfg.forest, engine="compiled") for x, yy, sd in fits], ZT, maps)
    t = time.perf_counter()
    G.predict_many([G.fit(x, yy, sd, cfg.forest, engine="compiled") for x, yy, sd in fits], ZT, maps)
    return (time.perf_counter() - t) / k


def forest_stage(k: int) -> dict:
    """Seconds per forest (fit + evaluation on 4,000 rows) by (space, n), today and new."""
    import sweep

    from relaff_jax.learn import forests as F

    compiled = "compiled" in F.ENGINES
    out = {}
    for space in ("pca", "rhf"):
        for n in (25, 100):
            today = sum(sweep.engine_times(space, n, k_old=2, k_new=k)["fast"])
            out[(space, n)] = (today, _compiled_times(space, n, k) if compiled else today)
    return dict(times=out, compiled=compiled)


def features_stage(n: int) -> dict:
    """Scenes/s of today's and the new feature computation and of the chain alone, on the same
    n C-settled lift scenes in chunks of 32 (the paper preset's feature_batch)."""
    from relaff_jax import perception as pc
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
    pcfg = pc.PerceptionConfig()
    fns = {"today": from_sim.make_feature_fn(sw, pcfg, 0, sub_batch=32), "new": from_sim.make_feature_fn(sw, pcfg, 0)}
    feats = pc.make_batched_features(sw.mj_model.geom_type, sw.geom_seg, pcfg)
    geoms = from_sim._jitted_geoms(sw)
    inputs = []
    for c in chunks:
        g = geoms(jnp.asarray(c["pair"], jnp.int32), jnp.asarray(c["qpos_settled"], jnp.float32))
        inputs.append(jax.block_until_ready((*g, from_sim.rollout_keys(jax.random.PRNGKey(0), c["rollout_id"]))))
    sb = from_sim.SUB_BATCH
    chain = {32: lambda g: jax.block_until_ready(feats.jitted(*g)),
             sb: lambda g: jax.block_until_ready([feats.jitted(*(x[i:i + sb] for x in g)) for i in range(0, 32, sb)])}
    for f in fns.values():
        f(chunks[0])
    for f in chain.values():
        f(inputs[0])
    t = {k: 0.0 for k in ("today", "new", "chain32", "chain_sub")}
    outs = {"today": [], "new": []}
    for i, (c, g) in enumerate(zip(chunks, inputs)):
        order = ("today", "new") if i % 2 == 0 else ("new", "today")
        for name in order:
            t0 = time.perf_counter()
            outs[name].append(fns[name](c))
            t[name] += time.perf_counter() - t0
        for name, bs in (("chain32", 32), ("chain_sub", sb)):
            t0 = time.perf_counter()
            chain[bs](g)
            t[name] += time.perf_counter() - t0
    same = all(np.array_equal(a[k], b[k]) for a, b in zip(outs["today"], outs["new"]) for k in a)
    return dict(n=len(chunks) * 32, rates={k: len(chunks) * 32 / v for k, v in t.items()}, identical=same, sub_batch=sb)


def project(data: list[dict], forest: dict, feats: dict) -> dict:
    """Hours per stage of the paper preset, today and new."""
    out = {}
    for which in ("today", "c_settle", "new"):
        rate = {d["action"]: d[which] for d in data}
        mean = float(np.mean(list(rate.values())))
        out[which] = {"data": sum(r / rate.get(a, mean) for a, r in PAPER_ROLLOUTS.items()) / 3600}
    sp = forest["times"][("pca", 25)]
    for which, speed in (("today", 1.0), ("c_settle", 1.0), ("new", sp[0] / sp[1])):
        out[which]["experiment"] = SWEEP_TODAY_H / speed
        fr = feats["rates"]["today" if which == "today" else "new"]
        out[which]["features"] = PAPER_SCENES / fr / 3600
        out[which]["report"] = REPORT_H
        out[which]["total"] = sum(out[which].values())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=["lift"])
    ap.add_argument("--batch", type=int, default=1024, help="rollouts per batch (the paper preset's)")
    ap.add_argument("--batches", type=int, default=2, help="timed batches per action (after one untimed)")
    ap.add_argument("--features", type=int, default=256, help="scenes for the features stage")
    ap.add_argument("--forests", type=int, default=16, help="forests per (space, n)")
    ap.add_argument("--smoke", action="store_true", help="lift, batch 64, 2 batches, few forests and scenes")
    ap.add_argument("--xla-cache", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "relaff_paper_stages_xla"),
                    help="JAX's persistent compilation cache ('' for none): a rerun skips the ~2-5 min of compiles")
    args = ap.parse_args()
    if args.smoke:
        args.actions, args.batch, args.batches, args.features, args.forests = ["lift"], 64, 2, 32, 2
    if args.xla_cache:
        jax.config.update("jax_compilation_cache_dir", args.xla_cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    t_start = time.perf_counter()
    stamp = lambda what: print(f"  [{time.perf_counter() - t_start:.0f} s: {what}]", flush=True)
    nthread = default_threads()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, C threads {nthread}; jax {jax.__version__}; "
          f"load average before {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
    data = []
    print("\n| action | batch | s/batch: place, MJX settle, C settle, plan L-BFGS, plan LM, exec (L-BFGS plans), exec (LM) "
          "| today /s | C settle /s | new (C settle + LM) /s | new / today | labels LM = L-BFGS |")
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for a in args.actions:
        d = data_stage(a, args.batch, args.batches, nthread)
        s = d["seconds"]
        parts = ", ".join(f"{s[k]:.2f}" for k in ("place", "settle_mjx", "settle_c", "plan_lbfgs", "plan_lm",
                                                   "exec_lbfgs", "exec_lm"))
        print(f"| {a} | {args.batch} | {parts} | {d['today']:.1f} | {d['c_settle']:.1f} | {d['new']:.1f} | "
              f"{d['new'] / d['today']:.2f} | {100 * d['agree']:.2f} % of {d['n']} |", flush=True)
        data.append(d)
    stamp("data stage done")
    forest = forest_stage(args.forests)
    stamp("forest stage done")
    print(f"\nforests ({'compiled engine' if forest['compiled'] else 'no compiled engine in learn.forests.ENGINES: new = today, the fast engine'}), "
          f"{args.forests} per cell, fit + evaluation on 4,000 rows:")
    print("| space | n | today forests/s | new forests/s | new / today |\n|---|---:|---:|---:|---:|")
    for (space, n), (today, new) in forest["times"].items():
        print(f"| {space} | {n} | {1 / today:.1f} | {1 / new:.1f} | {today / new:.2f} |", flush=True)
    feats = features_stage(args.features)
    stamp("features stage done")
    r = feats["rates"]
    print(f"\nfeatures, {feats['n']} lift scenes in chunks of 32: today (one call of 32) {r['today']:.1f} scenes/s, "
          f"new (calls of {feats['sub_batch']}) {r['new']:.1f} scenes/s, new / today {r['new'] / r['today']:.2f}, "
          f"bit-identical {feats['identical']}; the chain alone: {r['chain32']:.1f} scenes/s in calls of 32, "
          f"{r['chain_sub']:.1f} in calls of {feats['sub_batch']}; chain / new features "
          f"{r['chain_sub'] / r['new']:.2f}", flush=True)
    proj = project(data, forest, feats)
    print("\nprojected paper preset, one process (hours):")
    print("| path | data (native) | features | experiment | report | total |\n|---|---:|---:|---:|---:|---:|")
    for which, label in (("today", "today (MJX settle, L-BFGS)"), ("c_settle", "C settle, L-BFGS (the default now)"),
                         ("new", "C settle, LM plans (option), sub-batched features")):
        p = proj[which]
        print(f"| {label} | {p['data']:.2f} | {p['features']:.2f} | {p['experiment']:.2f} | {p['report']:.2f} | "
              f"{p['total']:.2f} |")
    lift = next((d for d in data if d["action"] == "lift"), data[0])
    sp = forest["times"][("pca", 25)]
    print(f"\nwall time of this benchmark {time.perf_counter() - t_start:.0f} s; load average after {os.getloadavg()[0]:.2f}")
    print(f"native_per_s={lift['new']:.1f} forest_speedup={sp[0] / sp[1]:.2f} paper_projected_h={proj['new']['total']:.2f}")


if __name__ == "__main__":
    main()
