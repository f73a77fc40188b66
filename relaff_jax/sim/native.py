"""Native MuJoCo C references for cross-checking the MJX stages.

Takes the same per-pair models (``World.mj_models``) and placements / plans as the JAX code;
gives, computed by ``mujoco.mj_step`` (float64) and C contacts: settled states and relation
labels (``settle_native``, no JAX involved) and the replay of planned motor programs with their
labels (``replay_native``: the actuator commands, initial data and rules come from the JAX
code), so tests and benchmarks can compare the two implementations.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from . import arm as A
from . import objects as lib
from . import scenes as sc
from . import world as wd
from .labels import Outcome, goals
from .planning import make_plan_fn, setup
from .programs import toy_reachable
from .simulate import initial_data, welds
from .templates import GRASPS, N_STEPS, TPL_CLOSED, TPL_MEASURE, TPL_STEPS, UNOBSTRUCT_ID, ActionConfig

from relaff_jax.constants import action_id


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
    spec = lib.get(world.pairs[pair][1])
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


def both_pads(d: mujoco.MjData, arm: A.Arm, cfg: ActionConfig, geoms: set) -> bool:
    """Do both finger pads touch one of ``geoms`` with their gripping face (C contacts, the
    rule of ``arm.finger_contacts``)?"""
    hit = [False, False]
    for c in d.contact[:d.ncon]:
        if c.dist >= cfg.arm.contact_dist:
            continue
        for i, pad in enumerate(arm.pad_geoms):
            if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms):
                axis = d.geom_xmat[pad].reshape(3, 3)[:, 1]
                if abs(float(np.dot(c.frame[:3], axis))) >= cfg.arm.contact_face_cos:
                    hit[i] = True
    return hit[0] and hit[1]


def replay_native(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray,
                  qvel: np.ndarray, result: dict, record_every: int = 0) -> dict[str, np.ndarray]:
    """Replay the planned programs of an ``action_fn`` result in native MuJoCo C (``mj_step``,
    float64), scene by scene, with the same actuator commands; label them with the same rules.

    Args: pair (B,), qpos (B, 14), qvel (B, 12) settled object states; ``result``: the action
    fn's output for these scenes (uses ``q_way``, ``grip_way``, ``feasible``; directions come
    from a re-plan). ``record_every`` > 0 also records every geom's pose before the first step
    and after every ``record_every``-th step (for animations).
    Returns ``label``, ``com_m``, ``com_end``, ``qpos_final`` as numpy arrays, and with
    ``record_every`` ``frames_xpos`` (B, F, G, 3) and ``frames_xmat`` (B, F, G, 9).
    """
    aid = action_id(action)
    st = setup(cfg)
    arm, world = st.arm, st.world
    measure = int(TPL_MEASURE[aid])
    seg = jnp.asarray(TPL_STEPS[aid])
    ctrl_fn = jax.jit(jax.vmap(lambda qw, gw, t: A.program_ctrl(arm, qw, gw, seg, t), in_axes=(None, None, 0)))
    reach = jax.jit(lambda p, q: toy_reachable(arm, cfg, st.geo, p, q))
    init = jax.jit(lambda q, v: initial_data(st, cfg, jnp.int32(aid), q, v))
    plan = jax.jit(make_plan_fn(cfg))(aid, jnp.asarray(pair), jnp.asarray(qpos, jnp.float32))
    labels, com_m, com_end, finals, frames = [], [], [], [], []
    nqo = qpos.shape[-1]
    wl = welds(world)
    obj_geoms, toy_geoms = set(wl.obj_geoms.tolist()), set(wl.toy_geoms.tolist())
    grasp = int(GRASPS[aid])
    closed = np.asarray(TPL_CLOSED[aid])
    segment = np.asarray(A.segment_index(seg, jnp.arange(N_STEPS)))
    for b in range(len(pair)):
        m = world.mj_models[int(pair[b])]
        d = mujoco.MjData(m)
        d0 = init(jnp.asarray(qpos[b], jnp.float32), jnp.asarray(qvel[b], jnp.float32))
        d.qpos[:] = np.concatenate([np.asarray(qpos[b], np.float64), np.asarray(d0.qpos[nqo:], np.float64)])
        d.qvel[:] = 0.0
        d.qvel[:qvel.shape[-1]] = qvel[b]
        d.ctrl[:] = np.asarray(d0.ctrl)
        d.eq_active[:] = np.asarray(d0.eq_active)
        mujoco.mj_forward(m, d)
        com0 = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
        ctrl = np.asarray(ctrl_fn(jnp.asarray(result["q_way"][b]), jnp.asarray(result["grip_way"][b]),
                                  jnp.arange(N_STEPS)))
        eq_data0 = m.eq_data.copy()
        cm = None
        shots = [(d.geom_xpos.copy(), d.geom_xmat.copy())] if record_every > 0 else []
        for t in range(N_STEPS):
            # the grasp lock of simulate.run_program_locked, on C contacts
            closing = bool(closed[segment[t]])
            for row, body, geoms, kind in ((wl.obj, world.obj_body, obj_geoms, 1),
                                           (wl.toy, world.toy_body, toy_geoms, 2)):
                lock = closing and grasp == kind and (bool(d.eq_active[row]) or both_pads(d, arm, cfg, geoms))
                if lock and not d.eq_active[row]:
                    m.eq_data[row, 3:10] = np.asarray(A.weld_relpose(
                        jnp.asarray(d.xpos[wl.hand_body]), jnp.asarray(d.xquat[wl.hand_body]),
                        jnp.asarray(d.xpos[body]), jnp.asarray(d.xquat[body])))
                d.eq_active[row] = lock
            d.ctrl[:] = ctrl[t]
            mujoco.mj_step(m, d)
            if t == measure:  # like MJX: the positions of the step's forward pass
                cm = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
            if record_every > 0 and (t + 1) % record_every == 0:
                shots.append((d.geom_xpos.copy(), d.geom_xmat.copy()))
        ce = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
        qf = d.qpos[:nqo].astype(np.float32)
        if aid == UNOBSTRUCT_ID:
            rb = bool(reach(jnp.asarray(pair[b]), jnp.asarray(qpos[b], jnp.float32)))
            ra = bool(reach(jnp.asarray(pair[b]), jnp.asarray(qf)))
        else:
            rb = ra = False
        o = Outcome(jnp.asarray(com0), jnp.asarray(cm), jnp.asarray(ce), plan.direction[b],
                    jnp.asarray(rb), jnp.asarray(ra))
        m.eq_data[:] = eq_data0
        labels.append(bool(goals(cfg, o)[aid]) and bool(result["feasible"][b]))
        com_m.append(cm)
        com_end.append(ce)
        finals.append(qf)
        frames.append(shots)
    out = dict(label=np.asarray(labels), com_m=np.stack(com_m), com_end=np.stack(com_end),
               qpos_final=np.stack(finals))
    if record_every > 0:
        out["frames_xpos"] = np.stack([np.stack([x for x, _ in f]) for f in frames])
        out["frames_xmat"] = np.stack([np.stack([r for _, r in f]) for f in frames])
    return out
