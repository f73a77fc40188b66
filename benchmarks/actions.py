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
Usage:
    python benchmarks/actions.py --labels 512 --replay 32 --batch 128 --batches 16 64 256
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
from relaff_jax.sim import native, planning, rollouts, simulate, templates
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
    args = ap.parse_args()
    print(f"jax {jax.__version__}, mujoco {mujoco.__version__}, XLA_FLAGS={os.environ['XLA_FLAGS']!r}")
    if args.labels:
        label_table(args.actions, args.labels, args.batch, args.seed, args.replay, args.json)
    if args.batches:
        throughput(args.throughput_action, args.batches, args.seed)


if __name__ == "__main__":
    main()
