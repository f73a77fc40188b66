"""Action benchmark: labelled rollouts per second and the label table of the nine actions.

Three parts (each optional):
  --labels N   N sampled scenes per action (scenes.py placement + settling, then the action):
               positive rate overall and by spatial relation, feasibility, rollouts/s.
  --replay K   the first K scenes of each action replayed in native MuJoCo C (mj_step,
               float64, same commands and grasp-lock rule): label agreement.
  --batches    MJX rollouts/s of one action at several batch sizes against native MuJoCo C on
               the same scenes and commands (mujoco.rollout, both cores; without the grasp-lock
               switching, which needs per-step Python logic), with ratios, and against the
               paper's ~1 minute per action simulation (IV-A).
Usage:
    python benchmarks/actions.py --labels 512 --replay 32 --batch 128 --batches 16 64 256
"""
from __future__ import annotations

import os
import argparse
import json
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from relaff_jax import actions as AC
from relaff_jax import scenes as sc
from relaff_jax import world as wd


def label_table(actions, n, batch, seed, replay, out_json=None):
    cfg = AC.ActionConfig()
    rows, agree = {}, {}
    for action in actions:
        fn = AC.make_rollout_fn(action, batch, cfg)
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
        rows[action] = row
        print(f"{action:10s} n={n} positive {row['positive_rate']:.3f} feasible {row['feasible']:.3f} "
              + "  ".join(f"{k} {row[k][0]:.3f} (n={row[k][1]})" for k in sc.RELATIONS)
              + f"  {rate:.1f} rollouts/s (first chunk incl. compile {t_first:.0f} s)", flush=True)
        if replay:
            # replay feasible programs only: an infeasible one is False in both by definition
            feas = np.flatnonzero(data["feasible"])
            k = min(replay, len(feas), batch)
            idx = np.resize(feas, batch) if k else np.arange(batch)
            res = AC.jitted_action_fn(cfg)(AC.action_id(action), jnp.asarray(data["pair"][idx]),
                                           jnp.asarray(data["qpos_settled"][idx]),
                                           jnp.zeros((batch, 12), jnp.float32))
            res = jax.device_get(res)
            nat = AC.replay_native(action, cfg, data["pair"][idx[:k]], data["qpos_settled"][idx[:k]],
                                   np.zeros((k, 12), np.float32),
                                   {kk: v if kk == "seg_steps" else v[:k] for kk, v in res.items()})
            agree[action] = (float(np.mean(nat["label"] == np.asarray(res["label"][:k]))), k,
                             int(np.asarray(res["label"][:k]).sum()))
            print(f"{'':10s} MJX vs MuJoCo C label agreement on {k} feasible scenes "
                  f"({agree[action][2]} positive in MJX): {agree[action][0]:.3f}", flush=True)
    print("\nPositive rate by relation (n per cell in brackets)")
    print(f"{'action':10s} {'all':>6s} " + " ".join(f"{r:>16s}" for r in sc.RELATIONS)
          + (f" {'C agree':>8s}" if replay else ""))
    for a, row in rows.items():
        cells = " ".join(f"{row[r][0]:9.3f} ({row[r][1]:4d})" for r in sc.RELATIONS)
        print(f"{a:10s} {row['positive_rate']:6.3f} {cells}" + (f" {agree[a][0]:8.3f}" if replay else ""))
    if out_json:
        with open(out_json, "w") as f:
            json.dump({"labels": rows, "c_agreement": agree}, f, indent=1)


def throughput(action, batches, seed):
    cfg = AC.ActionConfig()
    scene_world = wd.build_world(cfg.phys)
    place_fn, settle_fn, _ = sc.jitted_scene_fns(scene_world, cfg.scene)
    act = AC.jitted_action_fn(cfg)
    st = AC.setup(cfg)
    aid = AC.action_id(action)
    allowed = AC.allowed_pairs(scene_world, action)
    print(f"\n{action}: {AC.N_STEPS} control steps of {cfg.phys.timestep * 1e3:g} ms per rollout")
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
            lambda qw, gw, t: AC.A.program_ctrl(st.arm, qw, gw, jnp.asarray(res["seg_steps"]), t),
            in_axes=(None, None, 0)), in_axes=(0, 0, None)))
        ctrl = np.asarray(ctrl_fn(jnp.asarray(res["q_way"]), jnp.asarray(res["grip_way"]),
                                  jnp.arange(AC.N_STEPS)), np.float64)
        init = jax.jit(jax.vmap(lambda q, v: AC._initial_data(st, cfg, jnp.int32(aid), q, v)))(
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
        print(f"{b:5d} {mjx_rate:14.1f} {c_rate:12.1f} {mjx_rate / c_rate:6.2f} {mjx_rate * AC.N_STEPS:15.0f}"
              f" {mjx_rate * 60:15.0f}x", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--actions", nargs="+", default=list(AC.ACTIONS))
    ap.add_argument("--labels", type=int, default=0, help="scenes per action for the label table")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--replay", type=int, default=0, help="scenes per action replayed in MuJoCo C")
    ap.add_argument("--batches", type=int, nargs="*", default=[])
    ap.add_argument("--throughput-action", default="lift")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="write the label table here")
    args = ap.parse_args()
    print(f"jax {jax.__version__}, mujoco {mujoco.__version__}, XLA_FLAGS={os.environ['XLA_FLAGS']!r}")
    if args.labels:
        label_table(args.actions, args.labels, args.batch, args.seed, args.replay, args.json)
    if args.batches:
        throughput(args.throughput_action, args.batches, args.seed)


if __name__ == "__main__":
    main()
