"""Arm benchmark: IK accuracy/speed and the grasp-lift program in MJX vs native MuJoCo C.

Prints two tables: (1) IK on random top-down and tilted targets (residuals re-measured with
MuJoCo C mj_kinematics, time per batch); (2) env-steps/s of a reach-grasp-lift program on the
arm test world in MJX at several batch sizes and in MuJoCo C (one core), with the MJX-vs-C gap
in the final box and tcp positions. Usage:
    python benchmarks/arm.py [--batches 4 16 64] [--ik-batch 256]
"""
from __future__ import annotations

import os
import argparse
import functools
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from relaff_jax.sim import arm as A
from relaff_jax.config.action import ArmConfig

SEG = (200, 50, 150, 75, 200, 50)  # home->above, dwell, ->down, close, ->lift, dwell


def c_tcp(m, arm, q):
    d = mujoco.MjData(m)
    d.qpos[arm.qpos_arm] = q
    mujoco.mj_kinematics(m, d)
    return d.site_xpos[arm.tcp_site].copy(), d.site_xmat[arm.tcp_site].reshape(3, 3).copy()


def ik_table(m, arm, n, seed=0):
    rng = np.random.default_rng(seed)
    cfg = ArmConfig()
    r, th = rng.uniform(0.25, 1.15, n), rng.uniform(-np.pi / 2, np.pi / 2, n)
    pos = np.stack([r * np.cos(th), r * np.sin(th), rng.uniform(0.03, 0.5, n)], 1)
    tilt, az = rng.uniform(0, np.radians(60), n), rng.uniform(-np.pi, np.pi, n)
    a = np.stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)], 1)
    c = rng.normal(size=(n, 3))
    c -= (c * a).sum(1, keepdims=True) * a
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    sets = {
        "top-down, random yaw": jax.vmap(A.top_down_target)(jnp.asarray(pos), jnp.asarray(az)),
        "tilted <= 60 deg": A.IKTarget(jnp.asarray(pos), jnp.asarray(a), jnp.asarray(c), jnp.ones(n), jnp.zeros(n)),
    }
    ik = jax.jit(jax.vmap(lambda t, q: A.solve_ik(arm, cfg, t, q)))
    print(f"\nIK, batch {n}, targets r in [0.25, 1.15] m, z in [0.03, 0.5] m (residuals by MuJoCo C)")
    print(f"{'targets':22s} {'reachable':>9s} {'pos p50 mm':>10s} {'pos p99 mm':>10s} {'ang p99 deg':>11s} {'ms/batch':>9s}")
    for name, tg in sets.items():
        res = jax.block_until_ready(ik(tg, jnp.zeros((n, 6))))
        t0 = time.perf_counter()
        res = jax.block_until_ready(ik(tg, jnp.zeros((n, 6))))
        ms = 1e3 * (time.perf_counter() - t0)
        ok = np.asarray(res.reachable)
        pe, ae = [], []
        for i in np.nonzero(ok)[0]:
            p, rm = c_tcp(m, arm, np.asarray(res.q[i]))
            pe.append(np.linalg.norm(p - np.asarray(tg.pos[i])))
            ae.append(np.degrees(np.arccos(np.clip(rm[:, 2] @ np.asarray(tg.approach[i]), -1, 1))))
        print(f"{name:22s} {ok.mean():9.3f} {1e3 * np.median(pe):10.4f} {1e3 * np.percentile(pe, 99):10.4f} "
              f"{np.percentile(ae, 99):11.4f} {ms:9.1f}")


def program_table(m, arm, batches):
    cfg = ArmConfig()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    oq = m.jnt_qposadr[m.joint("obj_free").id]
    obj = m.body("obj").id
    q0 = jnp.asarray(d.qpos[arm.qpos_arm], jnp.float32)
    mx, dx0 = mjx.put_model(m), mjx.put_data(m, d)
    total = sum(SEG)
    print(f"\nGrasp-and-lift program, {total} steps of {m.opt.timestep * 1e3:g} ms, 1 kg box; "
          f"MJX vs MuJoCo C (float64, one core)")
    print(f"{'engine':8s} {'batch':>5s} {'compile s':>9s} {'env-steps/s':>12s} {'lifted':>6s} "
          f"{'|box C-MJX| mm':>15s} {'|tcp C-MJX| mm':>15s}")
    for b in batches:
        rng = np.random.default_rng(b)
        r, th = rng.uniform(0.4, 1.0, b), rng.uniform(-1.0, 1.0, b)
        xy = np.stack([r * np.cos(th), r * np.sin(th)], 1)
        pts = lambda z: np.c_[xy, np.full(b, z)]
        tg = A.IKTarget(*[jnp.stack(v, 1) for v in zip(*[
            jax.vmap(A.top_down_target)(jnp.asarray(pts(z)), jnp.zeros(b)) for z in (0.25, 0.045, 0.045, 0.35)])])
        ik = jax.jit(jax.vmap(lambda t: A.solve_ik_path(arm, cfg, t, q0)))(tg)
        q_way = jnp.concatenate([jnp.broadcast_to(q0, (b, 1, 6)), ik.q[:, [0, 0, 1, 2, 3, 3]]], 1)
        o, c = cfg.grip_open, cfg.grip_closed
        grip_way = jnp.broadcast_to(jnp.array([0.06, o, o, o, c, c, c]), (b, 7))
        data = jax.vmap(lambda p: dx0.replace(qpos=dx0.qpos.at[oq:oq + 3].set(p)))(
            jnp.asarray(pts(0.04), jnp.float32))
        run = jax.jit(jax.vmap(functools.partial(A.run_program, arm, mx, seg_steps=SEG)))
        t0 = time.perf_counter()
        jax.block_until_ready(run(data, q_way, grip_way))
        comp = time.perf_counter() - t0
        t0 = time.perf_counter()
        out, _ = jax.block_until_ready(run(data, q_way, grip_way))
        sps = b * total / (time.perf_counter() - t0)
        lifted = np.mean(np.asarray(out.xpos[:, obj, 2]) > 0.14)
        # native C replay of the same commands, one scene after the other
        ctrl_fn = jax.jit(jax.vmap(lambda qw, gw, t: A.program_ctrl(arm, qw, gw, SEG, t), in_axes=(None, None, 0)))
        gap_box, gap_tcp, c_time = [], [], 0.0
        for i in range(b):
            ctrl = np.asarray(ctrl_fn(q_way[i], grip_way[i], jnp.arange(total)))
            dc = mujoco.MjData(m)
            mujoco.mj_resetDataKeyframe(m, dc, 0)
            dc.qpos[oq:oq + 3] = pts(0.04)[i]
            t0 = time.perf_counter()
            for t in range(total):
                dc.ctrl[:] = ctrl[t]
                mujoco.mj_step(m, dc)
            c_time += time.perf_counter() - t0
            gap_box.append(np.linalg.norm(dc.xpos[obj] - np.asarray(out.xpos[i, obj])))
            gap_tcp.append(np.linalg.norm(dc.site_xpos[arm.tcp_site] - np.asarray(out.site_xpos[i, arm.tcp_site])))
        print(f"{'MJX':8s} {b:5d} {comp:9.1f} {sps:12.0f} {lifted:6.2f} {1e3 * max(gap_box):15.3f} "
              f"{1e3 * max(gap_tcp):15.3f}")
        print(f"{'C':8s} {b:5d} {'-':>9s} {b * total / c_time:12.0f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, nargs="+", default=[4, 16, 64])
    ap.add_argument("--ik-batch", type=int, default=256)
    args = ap.parse_args()
    m = mujoco.MjModel.from_xml_path(str(A.arm_test_xml_path()))
    arm = A.arm_from_model(m)
    print(f"jax {jax.__version__}, mujoco {mujoco.__version__}, XLA_FLAGS={os.environ['XLA_FLAGS']!r}")
    ik_table(m, arm, args.ik_batch)
    program_table(m, arm, args.batches)


if __name__ == "__main__":
    main()
