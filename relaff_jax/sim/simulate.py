"""Execution of planned motor programs in MJX, with grasp locks, and their labels.

Takes an ``ActionConfig`` and plans (``planning.Plan``); gives ``make_prepare_fn`` (plan plus
unobstruct's reachability before the action) and ``make_simulate_fn`` (the waypoints become
actuator commands, ``arm.program_ctrl``, executed with ``lax.scan`` over ``N_STEPS`` control
steps, vmapped over scenes with per-pair models; then the outcome rules of ``labels.py``).
Also ``initial_data`` (the action world's data of one settled scene, arm at home) and
``welds`` (the hand's equality rows), shared with the MuJoCo C replay (``native/reference.py``).

Settled scenes map into the action world one to one: both worlds put the toy's and the other
object's free joints first (qpos 0..13), the arm's joints follow. The arm starts at its home
pose holding the rake's grip point (``PhysicsConfig.held_rake_pos``); in rake scenes the rake is
attached to the hand by the weld ``tool_grip`` (the paper: rakes are "attached to the robot arm
as a tool"); every other grasp is the pads' friction plus a grasp lock that engages only while
the fingers close with both pads' faces on the grasped body (``run_program_locked``). The toy is
never moved by script, only by contacts.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from . import arm as A
from . import guard as G
from . import world as wd
from .actions.registry import registry
from .actions.rules import goal_row
from .labels import Outcome, read_at_rest
from .planning import Setup, home_grip, make_plan_fn, setup
from .programs import toy_reachable
from .straight import corrections, stopped_corrections, straight_rows
from .actions.tables import run_steps, tables
from .templates import N_STEPS, ActionConfig


def _finger_home(held: jax.Array) -> jax.Array:
    """Finger joint value at the start: on the 2.5 cm handle of the held rake, else 6 cm."""
    return jnp.where(held, 0.0125, 0.06)


def initial_data(st: Setup, cfg: ActionConfig, action_id: jax.Array, qpos_obj: jax.Array,
                  qvel_obj: jax.Array):
    """Action-world data of one scene: settled objects (qpos[:14], qvel[:12]), arm at home."""
    d0 = mjx.make_data(st.world.mj_model)
    nqo, nvo = qpos_obj.shape[-1], qvel_obj.shape[-1]
    q_home = jnp.asarray(st.q_home, jnp.float32)
    held = jnp.asarray(tables(cfg).held)[action_id]  # the rake scenes'
    qpos = A.set_arm_qpos(st.arm, d0.qpos.at[:nqo].set(qpos_obj), q_home, _finger_home(held))
    qvel = d0.qvel.at[:nvo].set(qvel_obj)
    ctrl = A.make_ctrl(st.arm, q_home, jnp.asarray(home_grip(cfg, st.arm))[action_id])
    # the rake is attached to the hand (weld "tool_grip") only in rake scenes
    eq = jnp.zeros(d0.eq_active.shape, bool).at[welds(st.world).tool].set(held)
    return d0.replace(qpos=qpos, qvel=qvel, ctrl=ctrl, eq_active=eq)


class Welds(NamedTuple):
    """Equality rows of the action world's hand welds and the geoms the grasp test uses."""

    tool: int
    obj: int
    toy: int
    hand_body: int
    toy_geoms: np.ndarray
    obj_geoms: np.ndarray


def welds(world: wd.World) -> Welds:
    m = world.mj_model
    eq = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, n)
    geoms = lambda b: np.nonzero(np.asarray(m.geom_bodyid) == b)[0]
    return Welds(eq("tool_grip"), eq("grasp_obj"), eq("grasp_toy"),
                 mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "arm_hand"),
                 geoms(world.toy_body), geoms(world.obj_body))


def run_program_locked(st: Setup, cfg: ActionConfig, w: Welds, grasp: jax.Array, mx, d, q_way, grip_way,
              seg_steps, closed, observe, n_run=None, n_steps=N_STEPS, guard=None, corr=None):
    """Run a program on one scene (``lax.scan`` over ``N_STEPS`` control steps) with grasp locks.

    With ``n_run`` (scalar, may be traced but not batched) only the first ``n_run`` steps are
    simulated; the later ones keep the state (``lax.cond``: skipped, not computed and masked),
    so ``trace`` holds the final state from step ``n_run - 1`` on. Without it every step runs
    in a plain scan (the cond changes XLA's fusion, hence float32 bits, even when it is always
    true: ``templates.untuned`` keeps the bits of before the tuning).

    A grasp lock is the weld ``grasp_obj``/``grasp_toy`` (``grasp`` 1/2 selects which, 0 none):
    it engages only during a segment that closes the fingers and only once *both* finger pads
    touch the grasped body (``arm.finger_contacts``), with the relative pose the two bodies
    have at that moment; it releases when a segment opens the fingers. A closed gripper that
    misses holds nothing. Returns the final data and ``observe(d)`` per control step.

    ``guard`` (v2): (S,) bool guarded segments and (W,) bool waypoints of this action
    (``guard.guard_tables``): at the first guarded step where a pad lands on an object
    (``guard.pad_landing``) the waypoints become ``guard.stopped_way`` of the arm's joints.
    ``corr`` (v2): the straight segments' joint corrections (S, P - 1, 6)
    (``straight.corrections``); a stop zeroes those of the segments it holds still.
    """
    arm = st.arm
    toy_b, obj_b = st.world.toy_body, st.world.obj_body
    both = np.concatenate([w.toy_geoms, w.obj_geoms])

    def control_step(carry, t):
        d, eq_data = carry[:2]
        if guard is not None:  # v2: the descent stops where a pad lands (v1 traces as before)
            q_w, stopped, c_w = carry[2:]
            stop = ~stopped & jnp.asarray(guard[0])[A.segment_index(seg_steps, t)] & G.pad_landing(arm, cfg, d, both)
            q_w = jnp.where(stop, G.stopped_way(q_w, jnp.asarray(guard[1]), G.hold_joints(d.qpos[arm.qpos_arm], d.qvel[arm.qvel_arm])), q_w)
            c_w = jnp.where(stop, stopped_corrections(c_w, jnp.asarray(guard[1])), c_w)
            stopped = stopped | stop
        else:
            q_w, c_w = q_way, corr
        closing = jnp.asarray(closed)[A.segment_index(seg_steps, t)]
        touch_obj = jnp.all(A.finger_contacts(arm, cfg.arm, d, w.obj_geoms))
        touch_toy = jnp.all(A.finger_contacts(arm, cfg.arm, d, w.toy_geoms))
        active = d.eq_active
        lock_obj = closing & (grasp == 1) & (active[w.obj] | touch_obj)
        lock_toy = closing & (grasp == 2) & (active[w.toy] | touch_toy)
        new_obj = lock_obj & ~active[w.obj]
        new_toy = lock_toy & ~active[w.toy]
        rel_obj = A.weld_relpose(d.xpos[w.hand_body], d.xquat[w.hand_body], d.xpos[obj_b], d.xquat[obj_b])
        rel_toy = A.weld_relpose(d.xpos[w.hand_body], d.xquat[w.hand_body], d.xpos[toy_b], d.xquat[toy_b])
        eq_data = eq_data.at[w.obj, 3:10].set(jnp.where(new_obj, rel_obj, eq_data[w.obj, 3:10]))
        eq_data = eq_data.at[w.toy, 3:10].set(jnp.where(new_toy, rel_toy, eq_data[w.toy, 3:10]))
        active = active.at[w.obj].set(lock_obj).at[w.toy].set(lock_toy)
        d = d.replace(ctrl=A.program_ctrl(arm, q_w, grip_way, seg_steps, t, c_w), eq_active=active)
        d = mjx.step(mx.replace(eq_data=eq_data), d)
        out = (d, eq_data) if guard is None else (d, eq_data, q_w, stopped, c_w)
        return out, observe(d)

    def step_or_hold(carry, t):
        return jax.lax.cond(t < n_run, control_step, lambda c, _: (c, observe(c[0])), carry, t)

    body = control_step if n_run is None else step_or_hold
    init = (d, jnp.asarray(mx.eq_data))
    if guard is not None:
        init = init + (jnp.asarray(q_way, jnp.float32), jnp.asarray(False), corr)
    carry, trace = jax.lax.scan(body, init, jnp.arange(n_steps))
    return carry[0], trace


def make_prepare_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``prepare_fn(action_id (), pair (B,), qpos (B, 14)) -> (Plan, reach_before (B,))``: the
    motor program of every scene and, for unobstruct, whether the toy is reachable in the
    settled scene (False for the other actions). Pure; the caller jits."""
    st = setup(cfg)
    plan_fn = make_plan_fn(cfg)
    reach = jax.vmap(lambda p, q: toy_reachable(st.arm, cfg, st.geo, p, q))
    reads = jnp.asarray(tables(cfg).reach)

    def prepare_fn(action_id, pair, qpos):
        action_id = jnp.asarray(action_id, jnp.int32)
        before = jax.lax.cond(reads[action_id], lambda: reach(pair, qpos),
                              lambda: jnp.zeros(pair.shape, bool))
        return plan_fn(action_id, pair, qpos), before

    return prepare_fn


def make_simulate_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``simulate_fn(action_id (), pair (B,), qpos (B, 14), qvel (B, 12), plan, reach_before)
    -> dict``: execute planned programs in MJX and label the outcomes. Pure; caller jits.

    See ``make_action_fn`` for the inputs and the returned fields.
    """
    st = setup(cfg)
    world, arm = st.world, st.arm
    toy_b, obj_b = world.toy_body, world.obj_body
    tb = tables(cfg)
    v2 = cfg.programs != "v1"  # v2-v4 execute alike (v3 and v4 plan differently, their tables dwell)
    com_of = lambda d: jnp.stack([d.xipos[toy_b], d.xipos[obj_b]])
    nqo = 14  # the two free joints lead the action world's qpos (settled scenes' layout)
    # v2 reads the objects' state at a step found after the run, so the trace keeps qpos too
    observe = (lambda d: (com_of(d), d.qpos[:nqo])) if v2 else com_of
    at_rest = jax.vmap(lambda c: read_at_rest(c, cfg.rest_window, cfg.scene.rest_speed, cfg.phys.timestep))
    reach = jax.vmap(lambda p, q: toy_reachable(arm, cfg, st.geo, p, q))
    wl = welds(world)
    specs = registry()
    g_seg, g_rows = G.guard_tables(cfg)
    straight = straight_rows(cfg, tb.target)

    def simulate_fn(action_id, pair, qpos, qvel, plan, before):
        action_id = jnp.asarray(action_id, jnp.int32)
        # the MJX model stack is read here, when traced: a run in MuJoCo C never builds it
        forward = jax.vmap(mjx.forward, in_axes=(world.model_axes, 0))
        models = wd.scene_models(world, pair)
        data = jax.vmap(lambda q, v: initial_data(st, cfg, action_id, q, v))(qpos, qvel)
        data = forward(models, data)
        com0 = jnp.stack([data.xipos[:, toy_b], data.xipos[:, obj_b]], 1)
        grasp = jnp.asarray(tb.grasp)[action_id]
        closed = jnp.asarray(tb.closed)[action_id]
        # one value for the whole batch, so the cond stays a branch under vmap
        n_run = jnp.asarray(run_steps(cfg))[action_id] if cfg.stop_at_program_end else None
        guard = (jnp.asarray(g_seg)[action_id], jnp.asarray(g_rows)[action_id]) if v2 else None
        srow = jnp.asarray(straight)[action_id]
        # v2: the straight segments' corrections, from the planned waypoints (as the C engines)
        corr_of = lambda qw: corrections(arm, cfg, qw, srow)[0] if v2 else None
        run = lambda mx, d, qw, gw: run_program_locked(st, cfg, wl, grasp, mx, d, qw, gw, plan.seg_steps,
                                                         closed, observe, n_run, tb.n_steps, guard, corr_of(qw))
        final, trace = jax.vmap(run, in_axes=(world.model_axes, 0, 0, 0))(
            models, data, plan.q_way, plan.grip_way)
        measure = jnp.asarray(tb.measure)[action_id]
        com_tr = trace[0] if v2 else trace
        window = jax.lax.dynamic_slice_in_dim(com_tr, measure - cfg.rest_window, cfg.rest_window + 1 + tb.hold, axis=1)
        i_read, settled = at_rest(window)
        if v2:  # every goal and the final state at the first step at rest (or the hold's end)
            rows = jnp.arange(com_tr.shape[0])
            t_read = measure - cfg.rest_window + i_read
            com_m = com_end = com_tr[rows, t_read]
            qpos_final = trace[1][rows, t_read]
        else:  # v1: lift-type goals at the measuring step, the others at the end
            com_m, com_end = com_tr[:, measure], com_tr[:, -1]
            qpos_final = final.qpos[:, :qpos.shape[-1]]
        after = jax.lax.cond(jnp.asarray(tb.reach)[action_id], lambda: reach(pair, qpos_final),
                             lambda: jnp.zeros(pair.shape, bool))
        out = Outcome(com0, com_m, com_end, plan.direction, before, after)
        labels = jax.vmap(lambda o: goal_row(specs, cfg, o))(out)[:, action_id] & plan.feasible
        return dict(label=labels, feasible=plan.feasible, ik_error=plan.ik_error, com0=com0,
                    com_m=com_m, com_end=out.com_end, reach_before=before, reach_after=after,
                    qpos_final=qpos_final, settled=settled, q_way=plan.q_way, grip_way=plan.grip_way,
                    seg_steps=plan.seg_steps)

    return simulate_fn
