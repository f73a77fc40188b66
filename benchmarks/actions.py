"""Action benchmark: labelled rollouts per second and the label table of the nine actions.

Three parts (each optional):
  --labels N   N sampled scenes per action (scenes.py placement + settling, then the action):
               positive rate overall and by spatial relation, feasibility, rollouts/s.
  --replay K   the first K feasible scenes of each action replayed in native MuJoCo C
               (mj_step, float64, same commands and grasp-lock rule): label agreement.
  --json F     save the label table per finished action; the same command skips them.
  --batches    MJX rollouts/s of one action at several batch sizes against native MuJoCo C on
               the same scenes and commands (mujoco.rollout, both cores; without the grasp-lock
               switching, which needs per-step Python logic), with ratios, and against the
               paper's ~1 minute per action simulation (IV-A).
  --engines B...  per action, labelled rollouts/s (``make_rollout_fn``'s two halves: sample,
               settle, plan once per batch, then each executor: execute, label) of today's MJX
               (``templates.untuned``), the tuned MJX (the default config) and the native
               engine (``mujoco.batch``, all CPUs; tuned and untuned config) at each batch
               size B, on the same scenes, with the ratios and the label agreements
               (``--agree N`` scenes per action and batch; the first batch, with its
               compiles, is timed apart). Resumable with ``--json``.
  --smoke      lift, batch 32, two timed batches (< 5 min); the last line is
               ``mjx_speedup=<tuned / today's MJX> native_per_s=<native labelled rollouts/s>
               native_over_mjx=<native / tuned MJX>``.
Usage:
    python benchmarks/actions.py --labels 512 --replay 32 --batch 128 --batches 16 64 256
    python benchmarks/actions.py --engines 64 256 --agree 512 --json engines.json
    python benchmarks/actions.py --smoke
"""
from __future__ import annotations

import os
import argparse
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.sim import arm as A
from relaff_jax.sim import planning, rollouts, simulate, templates
from relaff_jax.sim.native import reference as native
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd
from relaff_jax.io import atomic_write_json, read_json


def _replay(action, cfg, data, k, batch):
    """Replay the first ``k`` feasible scenes of ``data`` in native MuJoCo C; return
    (agreement, k, MJX positives among them). The plans are recomputed with the jitted
    prepare stage (cheap, already compiled at ``batch``); the MJX labels are the rollouts'.
    C starts the objects from rest; MJX started them from the settled state's residual
    velocities (below the settle stage's at-rest threshold)."""
    prepare_fn, _ = rollouts.jitted_stage_fns(cfg)
    feas = np.flatnonzero(data["feasible"])[:k]
    if not len(feas):
        return float("nan"), 0, 0
    plans = []
    for lo in range(0, len(feas), batch):
        rows = feas[lo:lo + batch]
        idx = np.resize(rows, batch)  # pad with repeats: the compiled batch shape
        plan, _ = jax.device_get(prepare_fn(action_id(action), jnp.asarray(data["pair"][idx]),
                                            jnp.asarray(data["qpos_settled"][idx])))
        plans.append({f: getattr(plan, f)[:len(rows)] for f in ("q_way", "grip_way", "feasible")})
    res = {f: np.concatenate([p[f] for p in plans]) for f in plans[0]}
    nat = native.replay_native(action, cfg, data["pair"][feas], data["qpos_settled"][feas],
                           np.zeros((len(feas), 12), np.float32), res)["label"]
    mjx_label = np.asarray(data["label"][feas])
    return float(np.mean(nat == mjx_label)), len(feas), int(mjx_label.sum())


def label_table(actions, n, batch, seed, replay, out_json=None):
    """Label table of ``n`` sampled scenes per action (and a C replay of ``replay`` feasible
    ones). With ``out_json`` every finished action is saved at once (atomically) and skipped
    when the same command runs again, so a killed run loses at most the action in progress."""
    cfg = templates.ActionConfig()
    setting = {"n": n, "batch": batch, "seed": seed, "replay": replay}
    done = {}
    if out_json and os.path.exists(out_json):
        prev = read_json(out_json)
        if prev.get("setting") == setting:
            done = prev.get("actions", {})
    for action in actions:
        if action in done:
            print(f"{action:10s} (done in {out_json}, skipped)", flush=True)
            continue
        fn = rollouts.make_rollout_fn(action, batch, cfg)
        chunks, t_first = [], None
        t0 = time.perf_counter()
        for c in range(-(-n // batch)):
            chunks.append(fn(jax.random.fold_in(jax.random.PRNGKey(seed), c), batch))
            if t_first is None:
                t_first = time.perf_counter() - t0
                t0 = time.perf_counter()
        steady = time.perf_counter() - t0
        data = {k: np.concatenate([ch[k] for ch in chunks])[:n] for k in chunks[0]}
        rate = (len(chunks) - 1) * batch / steady if len(chunks) > 1 else float("nan")
        rel = data["relation"]
        row = {"n": n, "positive_rate": float(data["label"].mean()),
               "feasible": float(data["feasible"].mean()), "rollouts_per_s": rate,
               "first_chunk_s": t_first}
        for r, name in enumerate(sc.RELATIONS):
            m = rel == r
            row[name] = (float(data["label"][m].mean()) if m.any() else float("nan"), int(m.sum()))
            mf = m & data["feasible"]
            row[name + "_feasible"] = (float(data["label"][mf].mean()) if mf.any() else float("nan"),
                                       int(mf.sum()))
        print(f"{action:10s} n={n} positive {row['positive_rate']:.3f} feasible {row['feasible']:.3f} "
              + "  ".join(f"{k} {row[k][0]:.3f} (n={row[k][1]})" for k in sc.RELATIONS)
              + f"  {rate:.1f} rollouts/s (first chunk incl. compile {t_first:.0f} s)", flush=True)
        if replay:
            # feasible programs only: an infeasible one is False in both by definition
            t0 = time.perf_counter()
            row["c_agreement"] = _replay(action, cfg, data, replay, batch)
            agree, k, pos = row["c_agreement"]
            print(f"{'':10s} MJX vs MuJoCo C label agreement on {k} feasible scenes "
                  f"({pos} positive in MJX): {agree:.3f} ({time.perf_counter() - t0:.0f} s)", flush=True)
        done[action] = row
        if out_json:
            atomic_write_json(out_json, {"setting": setting, "actions": done})
    rows = {a: done[a] for a in actions}
    print("\nPositive rate by relation, all sampled scenes (n per cell in brackets)")
    print(f"{'action':10s} {'all':>6s} {'feasible':>8s} " + " ".join(f"{r:>16s}" for r in sc.RELATIONS)
          + (f" {'C agree (n)':>14s}" if replay else ""))
    for a, row in rows.items():
        cells = " ".join(f"{row[r][0]:9.3f} ({row[r][1]:4d})" for r in sc.RELATIONS)
        c = row.get("c_agreement")
        print(f"{a:10s} {row['positive_rate']:6.3f} {row['feasible']:8.3f} {cells}"
              + (f" {c[0]:8.3f} ({c[1]:3d})" if replay else ""))
    print("\nPositive rate by relation among feasible programs (reachable, the object fits the gripper)")
    for a, row in rows.items():
        cells = " ".join(f"{row[r + '_feasible'][0]:9.3f} ({row[r + '_feasible'][1]:4d})"
                         for r in sc.RELATIONS)
        print(f"{a:10s} {cells}")


def throughput(action, batches, seed):
    cfg = templates.ActionConfig()
    scene_world = wd.build_world(cfg.phys)
    place_fn, settle_fn, _ = sc.jitted_scene_fns(scene_world, cfg.scene)
    act = rollouts.jitted_action_fn(cfg)
    st = planning.setup(cfg)
    aid = action_id(action)
    allowed = rollouts.allowed_pairs(scene_world, action)
    print(f"\n{action}: {templates.N_STEPS} control steps of {cfg.phys.timestep * 1e3:g} ms per rollout")
    print(f"{'batch':>5s} {'MJX rollouts/s':>14s} {'C rollouts/s':>12s} {'MJX/C':>6s} {'MJX env-steps/s':>15s}"
          f" {'vs paper (1/min)':>16s}")
    for b in batches:
        key = jax.random.PRNGKey(seed + b)
        pair = sc.sample_pairs(key, allowed, scene_world, b)
        qpos0, intended = place_fn(key, pair)
        s = settle_fn(pair, qpos0, intended)
        jax.block_until_ready(act(aid, pair, s.qpos, s.qvel))  # compile
        t0 = time.perf_counter()
        res = jax.device_get(act(aid, pair, s.qpos, s.qvel))
        t_mjx = time.perf_counter() - t0
        # native C on both cores: the same initial states and command sequences
        ctrl_fn = jax.jit(jax.vmap(jax.vmap(
            lambda qw, gw, t: A.program_ctrl(st.arm, qw, gw, jnp.asarray(res["seg_steps"]), t),
            in_axes=(None, None, 0)), in_axes=(0, 0, None)))
        ctrl = np.asarray(ctrl_fn(jnp.asarray(res["q_way"]), jnp.asarray(res["grip_way"]),
                                  jnp.arange(templates.N_STEPS)), np.float64)
        init = jax.jit(jax.vmap(lambda q, v: simulate.initial_data(st, cfg, jnp.int32(aid), q, v)))(
            s.qpos, s.qvel)
        models = [st.world.mj_models[int(p)] for p in np.asarray(pair)]
        datas = [mujoco.MjData(models[0]) for _ in range(2)]
        state = np.zeros((b, mujoco.mj_stateSize(models[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)))
        for i in range(b):
            d = mujoco.MjData(models[i])
            d.qpos[:] = np.asarray(init.qpos[i])
            d.qvel[:] = np.asarray(init.qvel[i])
            d.eq_active[:] = np.asarray(init.eq_active[i])
            mujoco.mj_getState(models[i], d, state[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        from mujoco import rollout
        t0 = time.perf_counter()
        rollout.rollout(models, datas, state, ctrl)
        t_c = time.perf_counter() - t0
        mjx_rate, c_rate = b / t_mjx, b / t_c
        print(f"{b:5d} {mjx_rate:14.1f} {c_rate:12.1f} {mjx_rate / c_rate:6.2f} {mjx_rate * templates.N_STEPS:15.0f}"
              f" {mjx_rate * 60:15.0f}x", flush=True)


EXECUTORS = (  # (name, engine, tuned config?): today's MJX first, the reference of the ratios
    ("mjx_today", "mjx", False), ("mjx", "mjx", True), ("native", "native", True), ("native_today", "native", False))


def _agree(a, b, feas):
    return float(np.mean(a == b)), float(np.mean(a[feas] == b[feas]))


def engines(actions, batches, n, seed, out_json=None, nthread=None):
    """Per action and batch size, on the same scenes (same keys): labelled rollouts/s of
    today's MJX (``templates.untuned``), the tuned MJX and the native engine (tuned and
    untuned), each = (sample + settle + plan, shared) + its own execution, over
    ``ceil(n / batch)`` batches after one untimed batch (it compiles); label agreement of
    tuned vs today's MJX, native vs tuned MJX, and native vs MJX untuned (the reference for
    "C agreement no worse than today's"). Returns {action: {batch: row}}."""
    tuned = templates.ActionConfig()
    today = templates.untuned(tuned)
    setting = {"n": n, "batches": list(batches), "seed": seed, "executors": [e[0] for e in EXECUTORS]}
    done = {}
    if out_json and os.path.exists(out_json):
        prev = read_json(out_json)
        done = prev.get("actions", {}) if prev.get("setting") == setting else {}
    print(f"{'action':10s} {'batch':>5s} {'today /s':>8s} {'tuned /s':>8s} {'native /s':>9s} {'tuned/today':>11s} "
          f"{'native/tuned':>12s} {'agree tuned~today':>17s} {'native~tuned':>12s} {'native~today (untuned)':>22s}",
          flush=True)
    for action in actions:
        for b in batches:
            if str(b) in done.get(action, {}):
                r = done[action][str(b)]
            else:
                r = _engine_row(action, b, n, seed, tuned, today, nthread)
                done.setdefault(action, {})[str(b)] = r
                if out_json:
                    atomic_write_json(out_json, {"setting": setting, "actions": done})
            ps = r["per_s"]
            print(f"{action:10s} {b:5d} {ps['mjx_today']:8.1f} {ps['mjx']:8.1f} {ps['native']:9.1f} "
                  f"{ps['mjx'] / ps['mjx_today']:11.2f} {ps['native'] / ps['mjx']:12.2f} "
                  f"{r['agree']['mjx~mjx_today'][1]:17.3f} {r['agree']['native~mjx'][1]:12.3f} "
                  f"{r['agree']['native_today~mjx_today'][1]:22.3f}  (feasible {r['n_feasible']} of {r['n']}; "
                  f"positives {r['positives']}; s per batch: prepare {r['prepare_s']:.2f}, execute "
                  + ", ".join(f"{k} {v:.2f}" for k, v in r["execute_s"].items()) + ")", flush=True)
    return {a: done[a] for a in actions}


def _engine_row(action, b, n, seed, tuned, today, nthread):
    """One (action, batch) row of ``engines``: every executor on the same prepared batches."""
    prepare = rollouts.make_batch_prepare_fn(action, tuned)
    cfgs = {False: today, True: tuned}
    keys = [rollouts.bench_batch_key(seed, b, c) for c in range(-(-n // b) + 1)]
    outs = {e[0]: [] for e in EXECUTORS}
    t_prep, t_exec, first = [], {e[0]: [] for e in EXECUTORS}, {}
    for i, key in enumerate(keys):
        t0 = time.perf_counter()
        prep = prepare(key, b)
        t_prep.append(time.perf_counter() - t0)
        for name, engine, is_tuned in EXECUTORS:
            t0 = time.perf_counter()
            out = rollouts.execute_batch(prep, cfgs[is_tuned], engine, rollouts.default_sim_batch(b), nthread)
            dt = time.perf_counter() - t0
            if i == 0:
                first[name] = dt + t_prep[0]
            else:
                t_exec[name].append(dt)
            outs[name].append(out)
    cat = {k: {f: np.concatenate([o[f] for o in v]) for f in ("label", "feasible", "pair")} for k, v in outs.items()}
    feas = cat["mjx"]["feasible"]
    lab = {k: v["label"] for k, v in cat.items()}
    prep_s = sum(t_prep[1:])
    timed = b * (len(keys) - 1)
    agree = {f"{x}~{y}": _agree(lab[x], lab[y], feas) for x, y in
             (("mjx", "mjx_today"), ("native", "mjx"), ("native_today", "mjx_today"), ("native", "native_today"))}
    # every disagreeing row (index into the concatenated batches, so the scene can be rebuilt
    # from its batch key) with its pair and both labels, for the examination in docs/actions.md
    differ = {k: [[int(i), int(cat["mjx"]["pair"][i]), int(lab[k.split("~")[0]][i]), int(lab[k.split("~")[1]][i])]
                  for i in np.flatnonzero(lab[k.split("~")[0]] != lab[k.split("~")[1]])] for k in agree}
    return {"n": int(len(feas)), "n_feasible": int(feas.sum()), "positives": {k: int(v.sum()) for k, v in lab.items()},
            "per_s": {k: timed / (prep_s + sum(v)) for k, v in t_exec.items()},
            "execute_only_per_s": {k: timed / sum(v) for k, v in t_exec.items()},
            "prepare_s": prep_s / (len(keys) - 1), "execute_s": {k: sum(v) / len(v) for k, v in t_exec.items()},
            "first_s": first, "agree": agree, "differ_rows": differ,
            # every row's label per executor (0/1 string, the concatenated batches' order), so a
            # later run can be compared with this one without re-running it
            "labels": {k: "".join(map(str, v.astype(int))) for k, v in lab.items()},
            "feasible": "".join(map(str, feas.astype(int)))}


def smoke() -> None:
    """lift, batch 32, one warm-up and two timed batches; the summary line last."""
    r = engines(["lift"], [32], 64, seed=0)["lift"]["32"]
    ps = r["per_s"]
    print(f"mjx_speedup={ps['mjx'] / ps['mjx_today']:.2f} native_per_s={ps['native']:.1f} "
          f"native_over_mjx={ps['native'] / ps['mjx']:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS))
    ap.add_argument("--labels", type=int, default=0, help="scenes per action for the label table")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--replay", type=int, default=0, help="scenes per action replayed in MuJoCo C")
    ap.add_argument("--batches", type=int, nargs="*", default=[])
    ap.add_argument("--throughput-action", default="lift")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="label table file (resumable: finished actions are skipped)")
    ap.add_argument("--engines", type=int, nargs="*", default=[], help="batch sizes of the engine table")
    ap.add_argument("--agree", type=int, default=256, help="scenes per action and batch in the engine table")
    ap.add_argument("--threads", type=int, default=None, help="native engine threads (default: all CPUs)")
    ap.add_argument("--smoke", action="store_true", help="lift only, < 5 min; prints the summary line last")
    args = ap.parse_args()
    if args.smoke:
        print(f"jax {jax.__version__}, mujoco {mujoco.__version__}", flush=True)
        smoke()
        return
    print(f"jax {jax.__version__}, mujoco {mujoco.__version__}, XLA_FLAGS={os.environ['XLA_FLAGS']!r}")
    if args.labels:
        label_table(args.actions, args.labels, args.batch, args.seed, args.replay, args.json)
    if args.batches:
        throughput(args.throughput_action, args.batches, args.seed)
    if args.engines:
        engines(args.actions, args.engines, args.agree, args.seed, args.json, args.threads)


if __name__ == "__main__":
    main()
