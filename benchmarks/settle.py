"""Settled scenes per second: MJX (vmapped, jitted, CPU) against native MuJoCo C on the
same scenes, in one run, with the ratio; optionally the MJX-vs-C cross-check.

    python benchmarks/settle.py [--batches 64 256 1024 4096] [--crosscheck 300] [--agreement 2000]

Native reference: ``mujoco.rollout.rollout`` with one MjModel per scene (its pair's model)
on a thread pool of ``--threads`` threads (default: all cores). The held rake is not
pinned in the native throughput run (rollout is open loop); the cost per step is the same.
The cross-check (``--crosscheck N``) settles N mixed scenes in MJX and with
``native.reference.settle_native`` (mj_step, rake pinned exactly as in MJX) and reports the relation
agreement and position differences. ``--agreement N`` settles the same N placements per
pairing group in MJX and with the native engine's settle (``native.settle.settle_batch``) and
reports relation agreement and pose differences per group (docs/scenes.md, "Native settle").
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import mujoco
import numpy as np
from mujoco import rollout

from relaff_jax import config
from relaff_jax.sim.native import reference as native, settle as native_settle
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd


def mjx_rate(w, cfg, batch, reps=2):
    place, settle, _ = sc.jitted_scene_fns(w, cfg)
    pair = sc.sample_pairs(jax.random.PRNGKey(batch), np.arange(w.n_pairs), w, batch)
    t0 = time.perf_counter()
    out = settle(pair, *place(jax.random.PRNGKey(0), pair))
    jax.block_until_ready(out)
    compile_s = time.perf_counter() - t0
    best = np.inf
    for r in range(reps):
        qpos0, intended = place(jax.random.PRNGKey(r + 1), pair)
        jax.block_until_ready(qpos0)
        t0 = time.perf_counter()
        jax.block_until_ready(settle(pair, qpos0, intended))
        best = min(best, time.perf_counter() - t0)
    return batch / best, compile_s, np.asarray(pair), np.asarray(qpos0)


def native_rate(w, cfg, pair, qpos0, threads):
    models = [w.mj_models[p] for p in pair]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    datas = [mujoco.MjData(w.mj_model) for _ in range(threads)]
    d = mujoco.MjData(w.mj_model)
    state = np.zeros((len(pair), mujoco.mj_stateSize(w.mj_model, spec)))
    for i, q in enumerate(qpos0):
        d.qpos[:] = q
        d.qvel[:] = 0
        mujoco.mj_getState(w.mj_model, d, state[i], spec)
    t0 = time.perf_counter()
    rollout.rollout(models, datas, state, nstep=cfg.settle_steps)
    return len(pair) / (time.perf_counter() - t0)


def crosscheck(w, cfg, n, batch=64):
    place, settle, _ = sc.jitted_scene_fns(w, cfg)
    rel, rel_c, err = [], [], []
    for c in range(-(-n // batch)):
        pair = sc.sample_pairs(jax.random.PRNGKey(1000 + c), np.arange(w.n_pairs), w, batch)
        qpos0, intended = place(jax.random.PRNGKey(2000 + c), pair)
        out = jax.device_get(settle(pair, qpos0, intended))
        q_c, r_c = native.settle_native(w, np.asarray(pair), np.asarray(qpos0), cfg)
        rel.append(out.relation)
        rel_c.append(r_c)
        for q in (w.toy_qpos, w.obj_qpos):
            err.append(np.linalg.norm(out.qpos[:, q:q + 3] - q_c[:, q:q + 3], axis=-1))
    rel, rel_c = np.concatenate(rel)[:n], np.concatenate(rel_c)[:n]
    err = np.concatenate(err)
    print(f"\ncross-check, {n} mixed scenes: relation agreement {100 * np.mean(rel == rel_c):.1f} %")
    for name, k in zip(sc.RELATIONS, range(3)):
        m = rel_c == k
        print(f"  C says {name:7s}: {m.sum():4d} scenes, MJX agrees on {100 * np.mean(rel[m] == k):.1f} %")
    print(f"  body position |MJX - C|: median {1000 * np.median(err):.2f} mm, "
          f"95th pct {1000 * np.percentile(err, 95):.1f} mm, within 1 cm: {100 * np.mean(err < 0.01):.1f} %")


def _angle(qa, qb):
    """(n,) rotation angle (rad) between unit quaternions (n, 4)."""
    dot = np.abs(np.sum(qa * qb, axis=-1) / np.linalg.norm(qa, axis=-1) / np.linalg.norm(qb, axis=-1))
    return 2 * np.arccos(np.clip(dot, 0.0, 1.0))


def agreement(w, cfg, n, threads, batch=250):
    """MJX settle against the native engine's C settle on the same n placements per pairing."""
    place, settle, _ = sc.jitted_scene_fns(w, cfg)
    pairing = np.asarray([pg for _, _, pg in w.pairs])
    print(f"\nnative (C, {threads} threads) vs MJX settle, the same {n} placements per pairing group")
    for g, pg in enumerate(dict.fromkeys(pairing)):
        allowed = np.flatnonzero(pairing == pg)
        rel, rel_c, rest, rest_c, dcog, dpos, dang, t_mjx, t_c = [], [], [], [], [], [], [], 0.0, 0.0
        for c in range(-(-n // batch)):
            pair = sc.sample_pairs(jax.random.PRNGKey(3000 + 100 * g + c), allowed, w, batch)
            qpos0, intended = place(jax.random.PRNGKey(4000 + 100 * g + c), pair)
            t0 = time.perf_counter()
            out = jax.device_get(settle(pair, qpos0, intended))
            t1 = time.perf_counter()
            nat = native_settle.settle_batch(w, *jax.device_get((pair, qpos0, intended)), cfg, threads)
            t_c += time.perf_counter() - t1
            t_mjx += t1 - t0 if c else 0.0  # the first call compiles
            rel.append(out.relation)
            rel_c.append(nat.relation)
            rest.append(out.at_rest)
            rest_c.append(nat.at_rest)
            dcog.append(np.abs(out.cog_distance - nat.cog_distance))
            # per scene: the toy's and the other object's differences side by side (B, 2)
            dpos.append(np.stack([np.linalg.norm(out.qpos[:, q:q + 3] - nat.qpos[:, q:q + 3], axis=-1)
                                  for q in (w.toy_qpos, w.obj_qpos)], 1))
            dang.append(np.stack([_angle(out.qpos[:, q + 3:q + 7], nat.qpos[:, q + 3:q + 7])
                                  for q in (w.toy_qpos, w.obj_qpos)], 1))
        rel, rel_c = np.concatenate(rel)[:n], np.concatenate(rel_c)[:n]
        rest, rest_c = np.concatenate(rest)[:n], np.concatenate(rest_c)[:n]
        dcog = np.concatenate(dcog)[:n]
        dpos = np.concatenate(dpos)[:n].ravel()  # both objects of the n scenes
        dang = np.degrees(np.concatenate(dang)[:n].ravel())
        conf = " ".join(f"{a}->{b}:{int(np.sum((rel == i) & (rel_c == j)))}" for i, a in enumerate(sc.RELATIONS)
                        for j, b in enumerate(sc.RELATIONS) if i != j and np.any((rel == i) & (rel_c == j)))
        um = lambda x: f"median {1e6 * np.median(x):.1f} um, 95th {1e6 * np.percentile(x, 95):.1f} um, max {1e3 * np.max(x):.2f} mm"
        print(f"  {pg:13s} {n} scenes: relation agreement {100 * np.mean(rel == rel_c):.2f} % "
              f"(MJX->C differing: {conf or 'none'}); |dpos| (both objects) {um(dpos)}, <1 cm {100 * np.mean(dpos < 0.01):.2f} %; "
              f"|dangle| median {np.median(dang):.4f} deg, 95th {np.percentile(dang, 95):.4f} deg, max {np.max(dang):.2f} deg; "
              f"|dcog| {um(dcog)}; "
              f"at rest: MJX {100 * np.mean(rest):.2f} %, C {100 * np.mean(rest_c):.2f} %, agree {100 * np.mean(rest == rest_c):.2f} %; "
              f"settle s/1000 scenes: MJX {1000 * t_mjx / max(batch * (c), 1):.1f}, C {1000 * t_c / (batch * (c + 1)):.2f}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batches", type=int, nargs="+", default=[64, 256, 1024, 4096])
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--crosscheck", type=int, default=0, help="scenes for the MJX-vs-C check")
    ap.add_argument("--agreement", type=int, default=0, help="placements per pairing group, MJX vs C settle")
    ap.add_argument("--iterations", type=int, default=None, help="solver iterations override")
    ap.add_argument("--wall-table-contacts", action="store_true",
                    help="let all container walls touch the table (A/B of that exclusion)")
    args = ap.parse_args()
    phys = wd.PhysicsConfig(wall_table_contacts=args.wall_table_contacts)
    if args.iterations is not None:
        phys = config.override(phys, {"iterations": args.iterations})
    w = wd.build_world(phys)
    cfg = sc.SceneConfig()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}, "
          f"mujoco {mujoco.__version__}; {cfg.settle_steps} steps of {phys.timestep * 1000:g} ms, "
          f"solver {phys.solver} x{phys.iterations}, "
          f"wall-table contacts {'on' if phys.wall_table_contacts else 'off'}")
    print(f"{'batch':>6s} {'MJX scenes/s':>13s} {'MJX steps/s':>12s} {'compile s':>10s} "
          f"{'C scenes/s':>11s} {'MJX/C':>6s}")
    if args.agreement:
        agreement(w, cfg, args.agreement, args.threads)
        return
    for b in args.batches:
        rate, compile_s, pair, qpos0 = mjx_rate(w, cfg, b)
        c_rate = native_rate(w, cfg, pair, qpos0, args.threads)
        print(f"{b:6d} {rate:13.1f} {rate * cfg.settle_steps:12.0f} {compile_s:10.1f} "
              f"{c_rate:11.1f} {rate / c_rate:6.2f}", flush=True)
    if args.crosscheck:
        crosscheck(w, cfg, args.crosscheck)


if __name__ == "__main__":
    main()
