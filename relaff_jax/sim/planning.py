"""Planning: the joint-space waypoints of a batch of motor programs.

Takes an ``ActionConfig``; gives ``setup(cfg)`` (the action world with the arm, its tables, the
pairs' geometry and the arm's home pose; built once and cached) and
``make_plan_fn(cfg) -> plan_fn(action_id (), pair (B,), qpos (B, 14)) -> Plan``: the tcp
targets of ``programs.program`` solved by the batched IK (``arm.solve_ik_path``) from the home
pose. If any waypoint is unreachable or badly conditioned, or the object does not fit the
gripper, or (v2) the tcp cannot follow a straight segment's line (``straight.py``), or (v3, the
held rake) the base joint turns more than ``branch.BASE_TURN_MAX`` between waypoints after the
transit (the waypoints first put on one IK branch, ``branch.one_branch``), the action is
*infeasible*: the arm stays home and the label is False.
"""
from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import arm as A
from . import world as wd
from .bodies import Geometry, geometry, tool_squeeze
from .actions.tables import tables
from .templates import N_TARGETS, ActionConfig, is_v3
from .actions.registry import registry
from .actions.rules import plan_program
from .branch import BASE_TURN_MAX, base_turn, one_branch
from .programs import Program
from .straight import corrections, straight_rows
from .traced_cache import stored_jit


class Setup(NamedTuple):
    """Static pieces shared by planning, simulation and replay (built once in Python)."""

    world: wd.World
    arm: A.Arm
    geo: Geometry
    q_home: np.ndarray  # (6,) home pose: the tcp at the held rake's grip point


@functools.lru_cache(maxsize=4)
def setup(cfg: ActionConfig = ActionConfig()) -> Setup:
    world = wd.build_world(cfg.phys, arm=True)
    arm = A.arm_from_model(world.mj_model)
    held = jnp.asarray(cfg.phys.held_rake_pos, jnp.float32)
    # a stored trace (traced_cache.py): tracing this IK took ~1.5 s of every run's start
    home = stored_jit(functools.partial(_home_ik, arm, cfg.arm), "home_ik", (cfg.phys, cfg.arm))
    q, reachable = home(*A.tool_tcp_target(held, jnp.eye(3)), jnp.zeros(6))
    if not bool(reachable):
        raise RuntimeError(f"the held rake pose {cfg.phys.held_rake_pos} is not reachable by the arm")
    return Setup(world, arm, geometry(world), np.asarray(q))


def _home_ik(arm: A.Arm, arm_cfg: Any, *target_and_q0: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``solve_ik``'s (q (6,), reachable ()) for the ``IKTarget``'s five arrays and q0 (6,)."""
    *target, q0 = target_and_q0
    res = A.solve_ik(arm, arm_cfg, A.IKTarget(*target), q0)
    return res.q, res.reachable


def home_grip(cfg: ActionConfig, arm: Any = None) -> np.ndarray:
    """(A,) finger command at the start: closed on the held rake's handle
    (``bodies.tool_squeeze``), else half open. ``arm``: ``setup(cfg).arm``, passed by a
    function being traced (``setup`` jits its own IK, which must not run inside a trace: the
    cached setup may have been evicted since the function was built)."""
    arm = setup(cfg).arm if arm is None else arm
    return np.where(tables(cfg).held, tool_squeeze(arm, cfg), 0.06).astype(np.float32)


class Plan(NamedTuple):
    """Joint-space program of a batch: ``q_way`` (B, S+1, 6), ``grip_way`` (B, S+1),
    ``seg_steps`` (S,) segment lengths, ``feasible`` (B,) bool, ``direction`` (B, 3) the
    action's horizontal direction, ``ik_error`` (B,) largest tcp residual of the IK (m)."""

    q_way: jax.Array
    grip_way: jax.Array
    seg_steps: jax.Array
    feasible: jax.Array
    direction: jax.Array
    ik_error: jax.Array


# a Plan can leave a traced program stored on disk (relaff_jax/traced_cache.py)
jax.export.register_namedtuple_serialization(Plan, serialized_name="relaff_jax.sim.planning.Plan")

# the order of a Program's leaves (``make_plan_of_fn``'s arguments, the reach screen's outputs)
PROGRAM_TREE = jax.tree_util.tree_structure(Program(A.IKTarget(*range(5)), 0, 0, 0, 0))


def program_branches(cfg: ActionConfig) -> list[Callable]:
    """The run's actions' target rules, ``branch(pair (), qpos (nq,)) -> Program`` (one scene;
    ``actions.rules.plan_program``), in ``registry()`` order: the branches of the planner's
    and the reach screen's ``lax.switch``."""
    st = setup(cfg)
    return [functools.partial(plan_program, s, st.arm, cfg, st.geo) for s in registry()]


def make_plan_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``plan_fn(action_id (), pair (B,), qpos (B, nq)) -> Plan`` for any of the run's actions
    (``action_id`` indexes ``actions.names()``; traced, so one compile serves all; the target
    rules are the specs'). Pure; caller jits."""
    branches = program_branches(cfg)
    one = _plan_one(cfg)
    tb = tables(cfg)

    def plan_fn(action_id, pair, qpos):
        action_id = jnp.asarray(action_id, jnp.int32)
        q_way, grip_way, feasible, direction, err = jax.vmap(
            lambda p, q: one(action_id, jax.lax.switch(action_id, branches, p, q)))(pair, qpos)
        return Plan(q_way, grip_way, jnp.asarray(tb.steps)[action_id], feasible, direction, err)

    return plan_fn


def make_plan_of_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``plan_of(action_id (), *leaves) -> Plan``: ``make_plan_fn``'s plan of programs already
    drawn (``leaves``: ``jax.tree_util.tree_leaves`` of a ``programs.Program`` whose leaves
    have a leading (B,) axis, as the reach screen returns them), so a screened generation
    computes each scene's targets once (in the screen) and its planner compiles no target
    rule. Pure; caller jits."""
    one = _plan_one(cfg)
    tb = tables(cfg)

    def plan_of(action_id, *leaves):
        action_id = jnp.asarray(action_id, jnp.int32)
        prog = jax.tree_util.tree_unflatten(PROGRAM_TREE, list(leaves))
        q_way, grip_way, feasible, direction, err = jax.vmap(lambda p: one(action_id, p))(prog)
        return Plan(q_way, grip_way, jnp.asarray(tb.steps)[action_id], feasible, direction, err)

    return plan_of


def _plan_one(cfg: ActionConfig) -> Callable:
    """``one(action_id (), prog: Program) -> (q_way, grip_way, feasible, direction, ik_error)``
    of one scene (the IK of its targets from the home pose, and the refusals)."""
    st = setup(cfg)
    tb = tables(cfg)
    q_home = jnp.asarray(st.q_home, jnp.float32)
    grip_home = jnp.asarray(home_grip(cfg, st.arm))
    straight = straight_rows(cfg, tb.target)
    v3 = is_v3(cfg)

    def one(action_id, prog):
        # only the targets the template uses are solved and count (the padding repeats the
        # last one); one value for the whole batch, so the cond stays a branch under vmap
        n_used = jnp.max(jnp.asarray(tb.target)[action_id]) + 1
        res = A.solve_ik_path(st.arm, cfg.arm, prog.targets, q_home, n_used)
        used = jnp.arange(N_TARGETS) < n_used
        turned = jnp.asarray(False)
        if v3:
            # v3, the held rake: the waypoints on one IK branch, and a base turn beyond the bound
            # after the transit refused (branch.py: the tool swung over the table)
            held = jnp.asarray(tb.held)[action_id]
            res = jax.lax.cond(held, lambda r: one_branch(st.arm, cfg.arm, prog.targets, r, n_used),
                               lambda r: r, res)
            turned = held & (base_turn(res.q, n_used) > BASE_TURN_MAX)
        feasible = jnp.all(res.reachable | ~used) & prog.ok & ~turned
        q_way = jnp.concatenate([q_home[None], res.q[jnp.asarray(tb.target)[action_id]]])
        # v2: a straight segment whose line the arm cannot follow makes the program infeasible
        _, line_err = corrections(st.arm, cfg, q_way, jnp.asarray(straight)[action_id])
        feasible = feasible & (line_err < cfg.arm.ik_pos_tol)
        opening = jnp.clip(prog.opening, 0.0, float(st.arm.finger_range[1]))
        # closing: v1 commands grip_closed (the 60 N limit squeezes); v2 a squeeze from the
        # held weight (programs.squeeze_command)
        grip = jnp.where(jnp.asarray(tb.closed)[action_id], prog.grip_closed, opening)
        g0 = grip_home[action_id]
        grip_way = jnp.concatenate([g0[None], grip])
        # an infeasible program is not executed: the arm holds its home pose
        q_way = jnp.where(feasible, q_way, q_home[None])
        grip_way = jnp.where(feasible, grip_way, g0)
        return q_way, grip_way, feasible, prog.direction, jnp.maximum(jnp.max(jnp.where(used, res.pos_err, 0.0)), line_err)

    return one
