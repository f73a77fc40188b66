"""The arm's forward and inverse kinematics (one sample; batch with ``jax.vmap``, caller jits).

Takes the ``Arm`` tables (``arm_model.arm_from_model``) and joint angles or tcp targets; gives:

- ``fk_chain`` / ``fk_tcp``: body and tcp poses from the six arm joint angles, a
  differentiable JAX chain (checked against MuJoCo C ``mj_kinematics`` in the tests).
- ``solve_ik(arm, cfg, target, q_init)``: inverse kinematics of one ``IKTarget``: projected
  L-BFGS (optax; or Levenberg-Marquardt with ``ArmConfig.ik_solver="lm"``, ``ik_lm.py``) on
  the tcp pose error from two seeds (a closed-form geometric guess and the
  current joints); returns an ``IKResult``: the joints, the residuals, the task Jacobian's
  conditioning and a ``reachable`` flag. There is no path planning (paper IV-D): an
  unreachable or badly conditioned target is a failed action, and that failure is data.
- ``solve_ik_path``: a sequence of targets, each warm-started from the previous solution.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from relaff_jax.config.action import ArmConfig

from .arm_model import Arm
from .geometry import axis_rotation
from .ik_lm import descend_lm


def fk_chain(arm: Arm, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """World poses of the six arm bodies: ``q`` (6,) -> pos (6, 3), mat (6, 3, 3).

    Same recursion as MuJoCo's ``mj_kinematics`` for one hinge per body: the body frame is
    placed in its parent, then rotated about the joint axis through the joint anchor.
    """
    pos, mat = jnp.asarray(arm.base_pos), jnp.asarray(arm.base_mat)
    out_pos, out_mat = [], []
    for i in range(6):
        pos = pos + mat @ arm.body_pos[i]
        mat = mat @ arm.body_mat[i]
        anchor = pos + mat @ arm.jnt_pos[i]
        mat = mat @ axis_rotation(jnp.asarray(arm.jnt_axis[i]), q[i])
        pos = anchor - mat @ arm.jnt_pos[i]
        out_pos.append(pos)
        out_mat.append(mat)
    return jnp.stack(out_pos), jnp.stack(out_mat)


def fk_tcp(arm: Arm, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """tcp pose in the world: ``q`` (6,) -> pos (3,), mat (3, 3) (columns = tcp x, y, z axes)."""
    pos, mat = fk_chain(arm, q)
    return pos[-1] + mat[-1] @ arm.site_pos, mat[-1] @ arm.site_mat


# ------------------------------------------------------------------------------------ IK


class IKTarget(NamedTuple):
    """A tcp goal. ``pos`` (3,) world position; ``approach`` (3,) unit direction the tcp z must
    point along; ``closing`` (3,) unit direction of the finger closing axis (tcp y);
    ``closing_weight`` () 0 = free yaw about the approach, 1 = closing axis enforced;
    ``closing_signed`` () 0 = the closing axis is sign-free (the gripper is symmetric), 1 = the
    tcp y must point along +closing (a tool attached to the hand is not symmetric)."""

    pos: jax.Array
    approach: jax.Array
    closing: jax.Array
    closing_weight: jax.Array
    closing_signed: jax.Array


class IKResult(NamedTuple):
    """``q`` (6,) joint solution inside the limits; ``pos_err`` () m and ``ang_err`` () rad
    tcp residuals; ``sigma`` () smallest singular value of the task Jacobian (m/rad; small =
    near a singularity); ``reachable`` () bool: all three within the config's tolerances."""

    q: jax.Array
    pos_err: jax.Array
    ang_err: jax.Array
    sigma: jax.Array
    reachable: jax.Array


def top_down_target(pos: jax.Array, yaw: jax.Array | None = None) -> IKTarget:
    """Target with the approach straight down; ``yaw`` (rad, about world z) of the closing
    axis, or ``None`` for a free yaw. ``pos`` (3,)."""
    pos = jnp.asarray(pos, dtype=jnp.float32)
    if yaw is None:
        closing, weight = jnp.array([0.0, 1.0, 0.0]), jnp.asarray(0.0)
    else:
        closing = jnp.stack([jnp.cos(yaw), jnp.sin(yaw), jnp.zeros_like(yaw)])
        weight = jnp.asarray(1.0)
    return IKTarget(pos, jnp.array([0.0, 0.0, -1.0]), closing, weight, jnp.asarray(0.0))


def _residual(arm: Arm, cfg: ArmConfig, q: jax.Array, target: IKTarget) -> jax.Array:
    """(9,) residual: position (m), approach and closing axis errors scaled to metres."""
    pos, mat = fk_tcp(arm, q)
    z, y = mat[:, 2], mat[:, 1]
    free_sign = jnp.where(jnp.dot(y, target.closing) >= 0, 1.0, -1.0)  # symmetric gripper
    sign = jnp.where(target.closing_signed > 0, 1.0, free_sign)
    w = jnp.sqrt(target.closing_weight)
    return jnp.concatenate(
        [pos - target.pos, cfg.ik_orient_length * (z - target.approach),
         cfg.ik_orient_length * w * (y - sign * target.closing)]
    )


def _errors(arm: Arm, q: jax.Array, target: IKTarget) -> tuple[jax.Array, jax.Array]:
    pos, mat = fk_tcp(arm, q)
    pos_err = jnp.linalg.norm(pos - target.pos)
    ang_a = jnp.arccos(jnp.clip(jnp.dot(mat[:, 2], target.approach), -1.0, 1.0))
    dot_c = jnp.dot(mat[:, 1], target.closing)
    dot_c = jnp.where(target.closing_signed > 0, dot_c, jnp.abs(dot_c))
    ang_c = jnp.arccos(jnp.clip(dot_c, -1.0, 1.0))
    return pos_err, jnp.maximum(ang_a, jnp.where(target.closing_weight > 0, ang_c, 0.0))


def task_sigma(arm: Arm, cfg: ArmConfig, q: jax.Array, target: IKTarget) -> jax.Array:
    """Smallest singular value of the constrained task's Jacobian at ``q``.

    The task has 5 dimensions with a free yaw (position + approach direction) and 6 with a
    fixed closing axis; the residual Jacobian (9, 6) has that rank away from singularities.
    """
    jac = jax.jacfwd(lambda qq: _residual(arm, cfg, qq, target))(q)
    s = jnp.linalg.svd(jac, compute_uv=False)  # descending
    return jnp.where(target.closing_weight > 0, s[5], s[4])


def _wrap(angle: jax.Array) -> jax.Array:
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def analytic_seed(arm: Arm, target: IKTarget, q6: jax.Array) -> jax.Array:
    """Geometric first guess for this arm family (yaw, 2-link shoulder/elbow, spherical wrist).

    Used only to start the optimiser; clipped to the limits. ``q6`` () is the tool yaw used
    when the closing axis is free.
    """
    shoulder = arm.base_pos + arm.base_mat @ (arm.body_pos[0] + arm.body_pos[1])
    up, fore = arm.body_pos[2], arm.body_pos[3]  # upper arm (link2 frame), forearm (link3)
    l1, l2 = float(np.linalg.norm(up)), float(np.linalg.norm(fore))
    a_u, a_f = math.atan2(up[0], up[2]), math.atan2(fore[0], fore[2])  # angles from vertical
    reach_tcp = float(np.linalg.norm(arm.site_pos))  # hand origin = wrist centre
    wrist = target.pos - reach_tcp * target.approach
    rel = wrist - shoulder
    j1 = jnp.arctan2(rel[1], rel[0])
    r = jnp.hypot(rel[0], rel[1])
    dist = jnp.clip(jnp.hypot(r, rel[2]), abs(l1 - l2) + 1e-3, l1 + l2 - 1e-4)
    cos_g = (l1 ** 2 + l2 ** 2 - dist ** 2) / (2 * l1 * l2)
    phi = jnp.pi - jnp.arccos(jnp.clip(cos_g, -1.0, 1.0))  # bend between arm directions
    beta = jnp.arctan2(r, rel[2])
    alpha = jnp.arctan2(l2 * jnp.sin(phi), l1 + l2 * jnp.cos(phi))
    j2 = beta - alpha - a_u
    j3 = phi - a_f + a_u
    # wrist: approach in the arm plane's frame -> pitch sum and lateral roll
    c1, s1 = jnp.cos(j1), jnp.sin(j1)
    a = target.approach
    ax, ay, az = c1 * a[0] + s1 * a[1], -s1 * a[0] + c1 * a[1], a[2]
    j5 = jnp.arcsin(jnp.clip(ay, -1.0, 1.0))
    j4 = jnp.arctan2(-ax, -az) - j2 - j3
    q = jnp.stack([j1, j2, j3, j4, j5, jnp.zeros_like(j1)])
    # tool yaw: turn the tcp y axis onto the closing axis (mod pi if the gripper is symmetric)
    _, mat = fk_tcp(arm, q)
    c = mat.T @ target.closing
    turn = jnp.arctan2(c[0], c[1])
    j6 = jnp.where(target.closing_signed > 0, turn, _wrap(2.0 * turn) / 2.0)
    j6 = jnp.where(target.closing_weight > 0, j6, q6)
    q = q.at[5].set(j6)
    return jnp.clip(q, arm.q_lo, arm.q_hi)


def _descend(arm: Arm, cfg: ArmConfig, q0: jax.Array, target: IKTarget) -> jax.Array:
    """L-BFGS (optax, zoom line search) on the squared pose residual from ``q0`` (6,): a fixed
    number of steps under ``lax.scan``, each projected onto the joint limits by clipping."""
    loss = lambda q: jnp.sum(_residual(arm, cfg, q, target) ** 2)
    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)

    def step(carry, _):
        q, state = carry
        value, grad = value_and_grad(q, state=state)
        updates, state = opt.update(grad, state, q, value=value, grad=grad, value_fn=loss)
        q = jnp.clip(optax.apply_updates(q, updates), arm.q_lo, arm.q_hi)
        return (q, state), None

    (q, _), _ = jax.lax.scan(step, (q0, opt.init(q0)), None, length=cfg.ik_steps)
    return q


def solve_ik(arm: Arm, cfg: ArmConfig, target: IKTarget, q_init: jax.Array) -> IKResult:
    """Inverse kinematics of one tcp target (vmap over scenes at the call site).

    ``q_init`` (6,) is the current arm configuration: one seed starts there (continuity along
    a motor program), the other at ``analytic_seed``. Among the seeds that meet the
    tolerances the one nearest ``q_init`` wins, else the one with the smallest error.
    """
    q_init = jnp.clip(jnp.asarray(q_init, jnp.float32), arm.q_lo, arm.q_hi)
    seeds = jnp.stack([analytic_seed(arm, target, q_init[5]), q_init])
    if cfg.ik_solver == "lm":
        qs = jax.vmap(lambda s: descend_lm(arm, cfg, s, target, _residual))(seeds)
    else:
        qs = jax.vmap(lambda s: _descend(arm, cfg, s, target))(seeds)
    pos_err, ang_err = jax.vmap(lambda q: _errors(arm, q, target))(qs)
    ok = (pos_err < cfg.ik_pos_tol) & (ang_err < cfg.ik_ang_tol)
    cost = pos_err + cfg.ik_orient_length * ang_err
    cost = cost + cfg.ik_continuity * jnp.sum((qs - q_init) ** 2, axis=-1) + jnp.where(ok, 0.0, 1e3)
    best = jnp.argmin(cost)
    q = qs[best]
    sigma = task_sigma(arm, cfg, q, target)
    reachable = ok[best] & (sigma > cfg.ik_min_sigma)
    return IKResult(q, pos_err[best], ang_err[best], sigma, reachable)


def solve_ik_path(arm: Arm, cfg: ArmConfig, targets: IKTarget, q_init: jax.Array,
                  n_used: jax.Array | None = None) -> IKResult:
    """IK of a sequence of W targets (leading axis of every ``targets`` field), each warm-started
    from the previous solution so consecutive joint waypoints stay close. Returns ``IKResult``
    with a leading (W,) axis; the program is feasible iff ``reachable.all()``.

    ``n_used`` () int (may be traced, not batched): solve only the first ``n_used`` targets;
    the later rows hold the last solution with zero residuals and ``reachable`` False
    (``lax.cond``: skipped, not computed). A lift uses 3 of the 6 targets, so its plan costs
    about half; the solved rows are bit-identical to those of a full solve
    (``tests/sim/test_arm.py``)."""

    def solve(q_prev, target):
        res = solve_ik(arm, cfg, target, q_prev)
        return res.q, res

    if n_used is None:
        _, res = jax.lax.scan(solve, jnp.asarray(q_init, jnp.float32), targets)
        return res

    def hold(q_prev, _):
        z = jnp.zeros((), jnp.float32)
        return q_prev, IKResult(q_prev, z, z, z, jnp.zeros((), bool))

    def step(carry, target):
        q_prev, k = carry
        q, res = jax.lax.cond(k < n_used, solve, hold, q_prev, target)
        return (q, k + 1), res

    _, res = jax.lax.scan(step, (jnp.asarray(q_init, jnp.float32), jnp.int32(0)), targets)
    return res
