"""Programs beyond the arm's reach, found without solving their IK (``ArmConfig.reach_screen``).

Takes the arm's tables (``arm.Arm``) and the IK's tolerances (``ArmConfig``); gives
``reach_bound`` and ``beyond_reach(bound, target)``, True only when no joint configuration
meets ``target`` within the tolerances ``kinematics.solve_ik`` calls reachable; the screen of a
batch (``make_screen_fn``); and ``prepare_screened``, which solves the IK of the other scenes
only. About half of all sampled scenes lie beyond the arm's reach (docs/arm.md) and the
screen finds 88-98 % of the infeasible ones, so the plan costs about what the feasible
scenes need.

Why a screened program is infeasible whatever the solver does (a proof, not a fit):
- Joint 2's anchor ``J2`` lies on joint 1's axis, so it is the same point for every q (the
  shoulder). Each later anchor is a fixed point of the body before it, so ``|J6 - J2|`` is at
  most the sum of the anchor-to-anchor lengths (``links``: upper arm + forearm, 1.22 m).
- The tcp is ``J6 + R_tcp v`` with ``v`` fixed in the tcp frame; write ``v = lever e_z + w``
  (``lever`` 0.19 m along the approach axis z, ``w`` the rest, 0 for this arm).
- For a target ``(p, a)``: ``p - lever a - J2 = (p - tcp) + R_tcp w + lever (z - a) + (J6 - J2)``.
  A reachable solution has ``|p - tcp| < ik_pos_tol`` and the angle between z and ``a`` below
  ``ik_ang_tol``, so ``|z - a| <= 2 sin(ik_ang_tol / 2) + ||a| - 1|``.
- Hence ``|p - lever a - J2| > links + |w| + |lever| (2 sin(ik_ang_tol / 2) + ||a| - 1|) +
  ik_pos_tol`` rules out every q. The test adds ``POS_MARGIN`` and ``ANG_MARGIN`` for the float32
  rounding of the IK's own residuals (~1e-6).

A program is infeasible if one of the targets its template uses is beyond reach
(``planning.make_plan_fn``), and unobstruct's toy is unreachable before the action if its grasp
target is (``programs.toy_reachable``); unobstruct's two are screened apart. The screened
scenes' plans are what the plan function gives every infeasible scene (home waypoints,
``feasible`` False); only their ``ik_error``, never solved, is NaN. The other scenes are planned by the same jitted function in calls of
``PLAN_CHUNK`` rows; a scene's plan does not depend on the other rows of its call
(``tests/sim/test_reach_screen.py`` checks the whole batch against ``make_prepare_fn``
compiled as one program, unscreened).
"""
from __future__ import annotations

from typing import Any, Callable, Iterator, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import arm as A
from relaff_jax.config.action import ArmConfig
from .planning import Plan, home_grip, make_plan_of_fn, program_branches, setup
from .actions.registry import per_action_list
from .programs import toy_grasp_target, toy_reachable
from .actions.tables import tables
from .templates import N_TARGETS, ActionConfig
from .traced_cache import stored_jit

POS_MARGIN = 2e-3  # m, beyond ik_pos_tol
ANG_MARGIN = 2e-3  # rad, beyond ik_ang_tol
PLAN_CHUNK = 128  # scenes per call of the plan function: one compiled shape for every batch


class ReachBound(NamedTuple):
    """``shoulder`` (3,) a world point fixed for every q; ``lever`` (m) the tcp's offset from
    the last anchor along the approach axis; ``base`` (m) the radius for a unit approach;
    ``tilt`` (m per unit of ``||a| - 1|``) what a non-unit approach adds."""

    shoulder: np.ndarray
    lever: float
    base: float
    tilt: float


def _anchors(arm: A.Arm) -> tuple[np.ndarray, np.ndarray]:
    """World positions of the six joint anchors at q = 0 (6, 3) and joint 1's world axis (3,),
    float64 (``kinematics.fk_chain``'s recursion)."""
    pos, mat = np.asarray(arm.base_pos, np.float64), np.asarray(arm.base_mat, np.float64)
    out, axis1 = [], None
    for i in range(6):
        pos = pos + mat @ arm.body_pos[i]
        mat = mat @ arm.body_mat[i]
        out.append(pos + mat @ arm.jnt_pos[i])
        if i == 0:
            axis1 = mat @ arm.jnt_axis[0]
        pos = out[-1] - mat @ arm.jnt_pos[i]  # q = 0: no rotation
    return np.stack(out), axis1 / np.linalg.norm(axis1)


def reach_bound(arm: A.Arm, cfg: ArmConfig) -> ReachBound:
    """The screen's constants for this arm and these tolerances (the module's proof)."""
    J, axis1 = _anchors(arm)
    # joint 2's anchor is fixed if it lies on joint 1's axis; else start from joint 1's anchor
    first = 1 if np.linalg.norm(np.cross(axis1, J[1] - J[0])) < 1e-9 else 0
    links = float(sum(np.linalg.norm(J[k + 1] - J[k]) for k in range(first, 5)))
    v = np.asarray(arm.site_mat, np.float64).T @ (np.asarray(arm.site_pos, np.float64) - arm.jnt_pos[5])
    lever = float(v[2])
    w = float(np.linalg.norm(v[:2]))
    turn = 2.0 * np.sin((cfg.ik_ang_tol + ANG_MARGIN) / 2.0)
    base = links + w + abs(lever) * turn + cfg.ik_pos_tol + POS_MARGIN
    return ReachBound(J[first], lever, float(base), abs(lever))


def beyond_reach(bound: ReachBound, target: A.IKTarget) -> jax.Array:
    """() bool: no q reaches ``target`` within the IK's tolerances (one target; vmap)."""
    a = target.approach
    c = target.pos - bound.lever * a - jnp.asarray(bound.shoulder, jnp.float32)
    radius = bound.base + bound.tilt * jnp.abs(jnp.sqrt(jnp.sum(a * a)) - 1.0)
    return jnp.sqrt(jnp.sum(c * c)) > radius


def make_screen_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``screen_fn(action_id (), pair (B,), qpos (B, 14)) -> (infeasible (B,) bool, unreachable
    (B,) bool, direction (B, 3), program)``: ``infeasible`` where the program is provably
    infeasible, so its plan needs no IK; ``unreachable`` where unobstruct's toy is provably
    unreachable before the action, so ``reach_before`` needs none (True for the other actions,
    whose ``reach_before`` is False); ``direction`` is the program's (what the plan function
    returns); ``program`` the tuple of the scenes' ``programs.Program`` leaves (each (B, ...),
    ``planning.PROGRAM_TREE``'s order), which ``planning.make_plan_of_fn`` plans. Pure; the
    caller jits."""
    st = setup(cfg)
    bound = reach_bound(st.arm, cfg.arm)
    branches = program_branches(cfg)
    reads = jnp.asarray(tables(cfg).reach)
    far = jax.vmap(lambda t: beyond_reach(bound, t))

    def one(action_id, pair, qpos):
        prog = jax.lax.switch(action_id, branches, pair, qpos)
        used = jnp.arange(N_TARGETS) < jnp.max(jnp.asarray(tables(cfg).target)[action_id]) + 1
        infeasible = jnp.any(far(prog.targets) & used)
        grasp, _ = toy_grasp_target(st.arm, cfg, st.geo, pair, qpos)
        unreachable = jnp.where(reads[action_id], beyond_reach(bound, grasp), True)
        return infeasible, unreachable, prog.direction, tuple(jax.tree_util.tree_leaves(prog))

    def screen_fn(action_id, pair, qpos):
        return jax.vmap(one, in_axes=(None, 0, 0))(jnp.asarray(action_id, jnp.int32), pair, qpos)

    return screen_fn


@per_action_list(maxsize=4)
def jitted_screen_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``make_screen_fn(cfg)`` jitted, cached (one compile per batch shape, all actions), its
    trace kept on disk with the compilation cache (``traced_cache.stored_jit``)."""
    return stored_jit(make_screen_fn(cfg), "screen", cfg)


@per_action_list(maxsize=4)
def jitted_parts(cfg: ActionConfig = ActionConfig()) -> tuple[Callable, Callable]:
    """The two halves of ``simulate.make_prepare_fn`` apart, jitted and cached, their traces
    kept on disk (``traced_cache.stored_jit``): ``plan_of(action_id, *program) -> Plan``
    (``planning.make_plan_of_fn``, every action's planner, of the programs ``jitted_screen_fn``
    returns) and ``reach_fn(pair (B,), qpos (B, 14)) -> (B,) bool``, unobstruct's
    ``toy_reachable``. Every plan of a run comes from them (``prepare_screened``,
    ``rollouts.jitted_stage_fns``)."""
    st = setup(cfg)
    reach = jax.vmap(lambda p, q: toy_reachable(st.arm, cfg, st.geo, p, q))
    return stored_jit(make_plan_of_fn(cfg), "plan_of", cfg), stored_jit(reach, "toy_reach", cfg)


def _in_chunks(fn: Callable, rows: np.ndarray, chunk: int, *arrays: np.ndarray) -> Iterator[tuple[np.ndarray, Any]]:
    """``(rows of the call, fn's host output)`` for ``fn(*arrays[idx])`` over ``rows`` in calls
    of ``chunk`` rows, the last padded with repeats (one compiled shape): the output's first
    ``len(rows of the call)`` entries are theirs."""
    for lo in range(0, len(rows), chunk):
        part = rows[lo:lo + chunk]
        idx = np.resize(part, chunk)
        yield part, jax.device_get(fn(*(jnp.asarray(a[idx]) for a in arrays)))


def prepare_screened(cfg: ActionConfig, aid: int, pair: np.ndarray,
                     qpos: np.ndarray) -> tuple[Plan, np.ndarray]:
    """``simulate.make_prepare_fn``'s ``(Plan, before)`` for B scenes, solving the IK only of
    the scenes the screen cannot rule out: the plan (``jitted_parts``' plan of the programs
    the screen drew) of the scenes whose program may be reachable and, for unobstruct, the
    toy's reach of the scenes whose toy may be, each in calls of ``PLAN_CHUNK`` rows (the last
    padded with repeats; a batch up to ``PLAN_CHUNK`` is one call of its own size). Host arrays: pair
    (B,), qpos (B, 14) float32. Returns numpy arrays: every field equal to the unscreened
    call's except ``ik_error``, NaN where the program was screened."""
    pair, qpos = np.asarray(pair), np.asarray(qpos, np.float32)
    n = len(pair)
    infeasible, unreachable, direction, program = jax.device_get(
        jitted_screen_fn(cfg)(aid, jnp.asarray(pair), jnp.asarray(qpos)))
    infeasible, unreachable = np.asarray(infeasible, bool), np.asarray(unreachable, bool)
    st = setup(cfg)
    seg = np.asarray(tables(cfg).steps, np.int32)[aid]
    q_way = np.broadcast_to(np.asarray(st.q_home, np.float32), (n, len(seg) + 1, 6)).copy()
    grip_way = np.full((n, len(seg) + 1), home_grip(cfg)[aid], np.float32)
    feasible, before = np.zeros(n, bool), np.zeros(n, bool)
    ik_error = np.full(n, np.nan, np.float32)
    direction = np.asarray(direction, np.float32).copy()
    chunk = min(n, PLAN_CHUNK)
    plan_fn, reach_fn = jitted_parts(cfg)
    for rows, plan in _in_chunks(lambda *leaves: plan_fn(aid, *leaves), np.flatnonzero(~infeasible), chunk, *program):
        k = len(rows)
        q_way[rows], grip_way[rows], feasible[rows] = plan.q_way[:k], plan.grip_way[:k], plan.feasible[:k]
        direction[rows], ik_error[rows] = plan.direction[:k], plan.ik_error[:k]
    if tables(cfg).reach[aid]:  # else reach_before is False, as make_prepare_fn's
        for rows, b in _in_chunks(reach_fn, np.flatnonzero(~unreachable), chunk, pair, qpos):
            before[rows] = b[:len(rows)]
    return Plan(q_way, grip_way, seg, feasible, direction, ik_error), before
