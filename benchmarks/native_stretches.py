"""The native engine's stretches against stepping every control step alone, in the same run.

``native.batch._run_chunk`` steps only the steps that need a decision one at a time (a guarded
descent still going, a grasp not yet locked) and the stretches between them in one
``Batch.rollout`` call each. Two references: the same function with every step a decision
step (``_checks`` always true: one ``Batch.step`` per control step), and the function it
replaced (``former_run_chunk``, kept here verbatim: one step at a time, every pad sensor
looked up by name and read at every guarded or closing step).
For each action this captures the C execution's inputs of one native rollout batch
(``rollouts.make_rollout_fn(action, batch, engine="native")``, seed 3 as
``generate_cpu.py``), then runs ``execute_native`` on them the three ways, alternating, for
``--rounds`` rounds, asserts every output field equal, and prints the best CPU (process, all
threads) and wall seconds of each and the stretches' ratio to the former.

    python benchmarks/native_stretches.py [--actions lift pour ...] [--batch 64] [--rounds 3]
"""
from __future__ import annotations

import argparse
import copy
import os
import platform
import time

import mujoco
import mujoco.batch
import numpy as np

import relaff_jax  # noqa: F401  (XLA flags before JAX work)
from relaff_jax.constants import ACTIONS
from relaff_jax.sim import rollouts
from relaff_jax.sim.guard import hold_joints, pad_landing_np
from relaff_jax.sim.native import batch as native_batch
from relaff_jax.sim.native.batch import SLOTS
from relaff_jax.sim.native.program import RestReader, pad_hit, stop_descent, weld_relpose_np
from relaff_jax.sim.planning import setup
from relaff_jax.sim.simulate import welds
from relaff_jax.sim.templates import ActionConfig

def former_pad_contacts(sd: np.ndarray, gxmat: np.ndarray, m: mujoco.MjModel, pad: str, body: str):
    """One pad's contacts with ``body`` ("toy" / "obj") from ``sensordata`` (n, S) and
    ``geom_xmat`` (n, G, 9) of the same forward pass: dist (n, K), normal (n, K, 3), the pad's
    closing axis (n, 3), valid (n, K)."""
    n = sd.shape[0]
    s = m.sensor(f"{pad}_{body}")
    k = SLOTS[body]
    block = sd[:, s.adr[0]:s.adr[0] + 5 * k].reshape(n, k, 5)  # found, dist, normal (3)
    found = block[:, 0, 0]
    if np.any(found > k):
        raise RuntimeError(f"contact sensor {pad}_{body}: {int(found.max())} contacts > {k} slots")
    valid = np.arange(k)[None, :] < found[:, None]
    axis = gxmat[:, m.geom(pad).id].reshape(n, 3, 3)[:, :, 1]
    return block[:, :, 1], block[:, :, 2:5], axis, valid


def former_touching(sd: np.ndarray, gxmat: np.ndarray, m: mujoco.MjModel, body: str, cfg: ActionConfig) -> np.ndarray:
    """(n,) bool: do both pads grip ``body`` ("toy" / "obj")?"""
    hits = [pad_hit(*former_pad_contacts(sd, gxmat, m, pad, body), cfg) for pad in ("arm_pad_l", "arm_pad_r")]
    return hits[0] & hits[1]


def former_landing(sd: np.ndarray, gxmat: np.ndarray, m: mujoco.MjModel, cfg: ActionConfig) -> np.ndarray:
    """(n,) bool: does a pad land on either object (``guard.pad_landing_np``)?"""
    return np.any([pad_landing_np(*former_pad_contacts(sd, gxmat, m, pad, body), cfg)
                   for pad in ("arm_pad_l", "arm_pad_r") for body in ("toy", "obj")], axis=0)


def former_run_chunk(cfg: ActionConfig, models: list, inp, rows: np.ndarray, nthread: int, nqo: int) -> dict:
    """``_run_chunk`` before the stretches and the contact pre-checks (main at a42ab17), verbatim."""
    world = setup(cfg).world
    wl = welds(world)
    bodies = [world.toy_body, world.obj_body]
    own = [copy.copy(models[r]) for r in rows]  # each simulation owns its model: the lock's eq_data
    batch = mujoco.batch.Batch(own[0], nsim=len(rows), nthread=nthread)
    batch.set_models(own)
    qpos, qvel, ctrl, eq = (batch.bind(f) for f in ("qpos", "qvel", "ctrl", "eq_active"))
    xipos, xpos, xquat, gxmat, sd = (batch.bind(f) for f in ("xipos", "xpos", "xquat", "geom_xmat", "sensordata"))
    qpos[:], qvel[:], eq[:] = inp.qpos[rows], inp.qvel[rows], inp.eq_active[rows]
    batch.forward()
    com0 = xipos[:, bodies].copy()
    com_m = None
    rest = RestReader(cfg, inp)
    grasp = {1: (wl.obj, world.obj_body, "obj"), 2: (wl.toy, world.toy_body, "toy")}.get(inp.grasp)
    stopped = np.zeros(len(rows), bool)
    q_arm, v_arm = setup(cfg).arm.qpos_arm, setup(cfg).arm.qvel_arm
    for t in range(inp.n_run):
        if inp.guard[t]:  # the descent stops where a pad lands (guard.py)
            for i in np.flatnonzero(~stopped & former_landing(sd, gxmat, own[0], cfg)):
                stopped[i] = True
                stop_descent(cfg, inp, int(rows[i]), t, hold_joints(qpos[i, q_arm], qvel[i, v_arm]))
        # the grasp lock of simulate.run_program_locked, on the pads' contact sensors (the
        # other hand weld stays off: initial_data leaves it off and only the grasp row moves)
        if grasp is not None:
            row, body, name = grasp
            if inp.closing[t]:
                active = eq[:, row] != 0
                lock = active | former_touching(sd, gxmat, own[0], name, cfg)
                new = np.flatnonzero(lock & ~active)
                if len(new):
                    rel = weld_relpose_np(xpos[new, wl.hand_body], xquat[new, wl.hand_body], xpos[new, body],
                                          xquat[new, body])
                    for i, r in zip(new, rel):
                        own[i].eq_data[row, 3:10] = r
                    batch.set_models(own)
                eq[:, row] = lock
            else:
                eq[:, row] = 0.0
        ctrl[:] = inp.ctrl[rows, t]
        batch.step()
        if t == inp.measure:  # like MJX: the positions of the step's forward pass
            com_m = xipos[:, bodies].copy()
        rest.add(t, xipos[:, bodies], qpos[:, :nqo])
        if inp.v2 and rest.done:  # every scene's read step is known: the rest changes nothing
            break
    com_r, q_r, settled = rest.result()
    if inp.v2:  # every goal and the final state at the read step
        return dict(com0=com0, com_m=com_r, com_end=com_r, qpos_final=q_r.astype(np.float32), settled=settled)
    return dict(com0=com0, com_m=com_m, com_end=xipos[:, bodies].copy(),
                qpos_final=qpos[:, :nqo].astype(np.float32), settled=settled)


def captured(action: str, batch: int) -> tuple:
    """The arguments of the C execution in one native rollout batch of ``action``."""
    seen = []
    real = rollouts.execute_native

    def keep(*a, **k):
        seen.append((a, k))
        return real(*a, **k)
    rollouts.execute_native = keep
    try:
        fn = rollouts.make_rollout_fn(action, batch, engine="native")
        fn(rollouts.bench_batch_key(3, batch, 1), batch)
    finally:
        rollouts.execute_native = real
    return seen[-1]


WAYS = ("former", "one step", "stretches")


def timed(args, kwargs, way: str) -> tuple[float, float, dict]:
    checks, run = native_batch._checks, native_batch._run_chunk
    if way == "one step":
        native_batch._checks = lambda *a: True
    if way == "former":
        native_batch._run_chunk = former_run_chunk
    try:
        c0, t0 = time.process_time(), time.perf_counter()
        out = native_batch.execute_native(*args, **kwargs)
        return time.process_time() - c0, time.perf_counter() - t0, out
    finally:
        native_batch._checks, native_batch._run_chunk = checks, run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS), choices=ACTIONS)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average before {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; batch {args.batch}, best of {args.rounds} rounds")
    print("| action | executed | former: CPU s | wall s | one step: CPU s | wall s | stretches: CPU s | wall s "
          "| stretches / former, CPU | wall |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    tot = np.zeros(6)
    for a in args.actions:
        pos, kw = captured(a, args.batch)
        best = {w: [np.inf, np.inf] for w in WAYS}
        outs = {}
        for _ in range(args.rounds):
            for w in WAYS:
                cpu, wall, outs[w] = timed(pos, kw, w)
                best[w] = [min(best[w][0], cpu), min(best[w][1], wall)]
        for w in WAYS[:2]:
            for f in ("label", "com0", "com_m", "com_end", "qpos_final", "reach_after", "settled"):
                np.testing.assert_array_equal(outs["stretches"][f], outs[w][f], err_msg=f"{a} {f} {w}")
        row = np.array([x for w in WAYS for x in best[w]])
        tot += row
        print(f"| {a} | {len(pos[2])} | " + " | ".join(f"{x:.2f}" for x in row)
              + f" | {row[4] / row[0]:.2f} | {row[5] / row[1]:.2f} |", flush=True)
    print("| all | | " + " | ".join(f"{x:.2f}" for x in tot) + f" | {tot[4] / tot[0]:.2f} | {tot[5] / tot[1]:.2f} |")
    print(f"every output field equal all three ways; load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
