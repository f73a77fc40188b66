"""Native MuJoCo C references for cross-checking the MJX stages.

Takes the same per-pair models (``World.mj_models``) and placements / plans as the JAX code;
gives, computed by ``mujoco.mj_step`` (float64) and C contacts: settled states and relation
labels (``settle_native``, no JAX involved) and the replay of planned motor programs with their
labels (``replay_native``: the actuator commands, initial data and rules come from the JAX
code, ``native.program``), so tests and benchmarks can compare the implementations; the
replay is the reference of the batched native engine (``native.batch``).
"""
from __future__ import annotations

import copy
from typing import Callable

import mujoco
import numpy as np

from relaff_jax.sim import arm as A
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd
from relaff_jax.sim.guard import hold_joints, pad_landing_np
from relaff_jax.sim.native.program import (RestReader, _padded, native_labels, pad_hit, program_inputs, reachable,
                                           stop_descent, weld_relpose_np)
from relaff_jax.sim.actions.registry import action_id
from relaff_jax.sim.planning import setup
from relaff_jax.sim.reach_screen import jitted_screen_fn
from relaff_jax.sim.simulate import welds
from relaff_jax.sim.actions.tables import tables
from relaff_jax.sim.templates import ActionConfig


def relation_native(world: wd.World, pair: int, m: mujoco.MjModel, d: mujoco.MjData,
                    cfg: sc.SceneConfig) -> int:
    """Relation of a settled native scene from C contacts (same rule as ``scenes.relation_of``)."""
    toy, obj = world.toy_body, world.obj_body
    on_obj = on_table = False
    for c in d.contact[: d.ncon]:
        if c.dist >= cfg.contact_dist:
            continue
        bodies = {int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])}
        on_obj |= bodies == {toy, obj}
        on_table |= bodies == {toy, 0}
    if not on_obj or on_table:
        return sc.BESIDE
    spec = world.objects.get(world.pairs[pair][1])
    local = d.xmat[obj].reshape(3, 3).T @ (d.xipos[toy] - d.xpos[obj])
    if spec.inner is not None:
        ix, iy, rim = spec.inner
        if abs(local[0]) < ix and abs(local[1]) < iy and local[2] < rim:
            return sc.INSIDE
    return sc.ON_TOP


def settle_native(world: wd.World, pair: np.ndarray, qpos0: np.ndarray,
                  cfg: sc.SceneConfig = sc.SceneConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Settle scenes one by one with ``mujoco.mj_step`` (float64), holding rakes as MJX does.

    Args:
      pair: (B,) pair indices; qpos0: (B, nq) placements.
    Returns:
      qpos: (B, nq) settled states; relation: (B,) int labels.
    """
    out_q = np.zeros_like(qpos0, dtype=np.float64)
    out_r = np.zeros(len(pair), np.int32)
    oq, od = world.obj_qpos, world.obj_dof
    for i, (p, q0) in enumerate(zip(np.asarray(pair), np.asarray(qpos0, np.float64))):
        m = world.mj_models[int(p)]
        d = mujoco.MjData(m)
        d.qpos[:] = q0
        held = world.pairs[int(p)][2] == "toy+rake"
        for _ in range(cfg.settle_steps):
            mujoco.mj_step(m, d)
            if held:
                d.qpos[oq:oq + 7] = q0[oq:oq + 7]
                d.qvel[od:od + 6] = 0.0
        mujoco.mj_forward(m, d)
        out_q[i] = d.qpos
        out_r[i] = relation_native(world, int(p), m, d, cfg)
    return out_q, out_r


def _pad_contacts(d: mujoco.MjData, pad: int, geoms: set) -> tuple[np.ndarray, np.ndarray]:
    """(dist (k,), normal (k, 3)) of the contacts between geom ``pad`` and one of ``geoms``, in
    contact order, read from the contact arrays (the values of each ``d.contact[i]``)."""
    if not d.ncon:
        return np.zeros(0), np.zeros((0, 3))
    con = d.contact
    g = con.geom
    other = np.where(g[:, 0] == pad, g[:, 1], np.where(g[:, 1] == pad, g[:, 0], -1))
    rows = (other[:, None] == np.fromiter(geoms, np.int64, len(geoms))[None, :]).any(axis=1)
    return con.dist[rows], con.frame[rows, :3]


def both_pads(d: mujoco.MjData, arm: A.Arm, cfg: ActionConfig, geoms: set) -> bool:
    """Do both finger pads touch one of ``geoms`` with their gripping face (C contacts, the
    rule of ``arm.finger_contacts`` as ``native.program.pad_hit`` writes it)?"""
    for pad in arm.pad_geoms:
        dist, normal = _pad_contacts(d, pad, geoms)
        if not len(dist):
            return False
        axis = np.asarray(d.geom_xmat[pad], np.float64).reshape(3, 3)[:, 1]
        if not pad_hit(dist, normal, axis, np.ones(len(dist), bool), cfg):
            return False
    return True


def landing(d: mujoco.MjData, arm: A.Arm, cfg: ActionConfig, geoms: set) -> bool:
    """Does a pad land on one of ``geoms`` (C contacts, the rule of ``guard.pad_landing`` as
    ``guard.pad_landing_np`` writes it)?"""
    for pad in arm.pad_geoms:
        dist, normal = _pad_contacts(d, pad, geoms)
        if not len(dist):
            continue
        axis = np.asarray(d.geom_xmat[pad], np.float64).reshape(3, 3)[:, 1]
        if pad_landing_np(dist, normal, axis, np.ones(len(dist), bool), cfg):
            return True
    return False


def replay_native(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray,
                  qvel: np.ndarray, result: dict, record_every: int = 0,
                  observe: Callable[[int, int, mujoco.MjModel, mujoco.MjData], None] | None = None
                  ) -> dict[str, np.ndarray]:
    """Replay the planned programs of an ``action_fn`` result in native MuJoCo C (``mj_step``,
    float64), scene by scene, with the same actuator commands; label them with the same rules.

    The reference of the native engine (``native.batch.execute_native``), which must give the
    same results bit for bit. Inputs, weld relpose and labels: ``native.program``.

    Args: pair (B,), qpos (B, 14), qvel (B, 12) settled object states; ``result``: the action
    fn's output for these scenes (uses ``q_way``, ``grip_way``, ``feasible``, and
    ``direction`` if present, else a re-plan gives it). ``record_every`` > 0 also records
    every geom's pose before the first step and after every ``record_every``-th step (for
    animations). ``observe(b, t, m, d)``, if given, is called after every step t of scene b
    (the audit's ``native.probe.Probe``, ``native.forces``; it must not change ``d``).
    Returns ``label``, ``com_m``, ``com_end``, ``qpos_final``, ``reach_after`` as numpy arrays,
    and with ``record_every`` ``frames_xpos`` (B, F, G, 3) and ``frames_xmat`` (B, F, G, 9).
    """
    aid = action_id(action)
    st = setup(cfg)
    world = st.world
    pair = np.asarray(pair)
    if "direction" in result:
        direction = np.asarray(result["direction"])
    else:
        # the programs' direction, as the generation's reach screen draws them, rows padded to
        # a power of two >= 8: the shapes a run compiles, not one per call size
        screen_fn = jitted_screen_fn(cfg)
        direction = _padded(lambda p, q: screen_fn(aid, p, q)[2], pair.astype(np.int32),
                            np.asarray(qpos, np.float32))
    before = reachable(cfg, pair, qpos) if tables(cfg).reach[aid] else np.zeros(len(pair), bool)
    inp = program_inputs(cfg, aid, qpos, qvel, result["q_way"], result["grip_way"])
    nqo = qpos.shape[-1]
    wl = welds(world)
    obj_geoms, toy_geoms = set(wl.obj_geoms.tolist()), set(wl.toy_geoms.tolist())
    bodies = [world.toy_body, world.obj_body]
    com0, com_m, com_end, finals, frames, settled, read_step = [], [], [], [], [], [], []
    own: dict[int, mujoco.MjModel] = {}
    for b in range(len(pair)):
        p = int(pair[b])
        if p not in own:  # this replay's own copy: the grasp lock writes eq_data, and the world's
            own[p] = copy.copy(world.mj_models[p])  # models are shared (a generation beside an audit)
        m = own[p]  # kept for the whole replay: an observer may key its caches by id(m)
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.eq_active[:] = inp.qpos[b], inp.qvel[b], inp.eq_active[b]
        mujoco.mj_forward(m, d)
        com0.append(d.xipos[bodies].copy())
        eq_data0 = m.eq_data.copy()
        cm = None
        rest = RestReader(cfg, inp)
        shots = [(d.geom_xpos.copy(), d.geom_xmat.copy())] if record_every > 0 else []
        stopped = False
        for t in range(inp.n_run):
            if inp.guard[t] and not stopped and landing(d, st.arm, cfg, obj_geoms | toy_geoms):
                stopped = True  # the descent stops where a pad lands (guard.py)
                stop_descent(cfg, inp, b, t, hold_joints(d.qpos[st.arm.qpos_arm], d.qvel[st.arm.qvel_arm]))
            # the grasp lock of simulate.run_program_locked, on C contacts
            for row, body, geoms, kind in ((wl.obj, world.obj_body, obj_geoms, 1),
                                           (wl.toy, world.toy_body, toy_geoms, 2)):
                lock = bool(inp.closing[t]) and inp.grasp == kind and (
                    bool(d.eq_active[row]) or both_pads(d, st.arm, cfg, geoms))
                if lock and not d.eq_active[row]:
                    m.eq_data[row, 3:10] = weld_relpose_np(d.xpos[wl.hand_body], d.xquat[wl.hand_body],
                                                           d.xpos[body], d.xquat[body])
                d.eq_active[row] = lock
            d.ctrl[:] = inp.ctrl[b, t]
            mujoco.mj_step(m, d)
            if observe is not None:
                observe(b, t, m, d)
            if t == inp.measure:  # like MJX: the positions of the step's forward pass
                cm = d.xipos[bodies].copy()
            rest.add(t, d.xipos[bodies][None], d.qpos[None, :nqo])
            if inp.v2 and rest.done and record_every <= 0:  # the read step is known (as native_batch)
                break
            if record_every > 0 and (t + 1) % record_every == 0:
                shots.append((d.geom_xpos.copy(), d.geom_xmat.copy()))
        m.eq_data[:] = eq_data0
        com_r, q_r, ok = rest.result()
        settled.append(ok[0])
        read_step.append(int(rest.read_steps()[0]))
        if inp.v2:  # every goal and the final state at the read step
            cm, end, fin = com_r[0], com_r[0], q_r[0]
        else:
            end, fin = d.xipos[bodies].copy(), d.qpos[:nqo]
        com_m.append(cm)
        com_end.append(end)
        finals.append(fin.astype(np.float32))
        frames.append(shots)
    com0, com_m, com_end, qf = np.stack(com0), np.stack(com_m), np.stack(com_end), np.stack(finals)
    label, after = native_labels(cfg, aid, pair, com0, com_m, com_end, qf, direction, before,
                                 np.asarray(result["feasible"], bool))
    out = dict(label=label, com0=com0, com_m=com_m, com_end=com_end, qpos_final=qf, reach_after=after,
               settled=np.asarray(settled, bool), read_step=np.asarray(read_step, np.int32))
    if record_every > 0:
        out["frames_xpos"] = np.stack([np.stack([x for x, _ in f]) for f in frames])
        out["frames_xmat"] = np.stack([np.stack([r for _, r in f]) for f in frames])
    return out
