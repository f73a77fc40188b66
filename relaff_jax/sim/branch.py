"""Programs v3, the held rake: joint waypoints on one IK branch, and the refusal of large base turns.

Takes the ``Arm`` tables, an ``ArmConfig``, a program's tcp targets and the forward IK path
(``kinematics.solve_ik_path``, each target warm-started from the previous solution); gives
``one_branch``, the path whose consecutive waypoints turn the base joint least (the forward
path, or the same targets solved backwards from the last one), and ``base_turn``, the largest
base-joint turn between consecutive waypoints after the transit. One program; the caller vmaps
and jits. Used by ``planning.make_plan_fn`` for the held-tool programs under v3 only.

Why (journal, the 2,000-rollout rake audit): 16 of 30 failing rake rollouts changed IK branch
between waypoints. The grip point of a long rake lies near or behind the base axis for a toy
close to the robot; the forward path reaches ``above`` leaning back over the base (the branch
nearest home), and ``low``, a few centimetres lower, is out of that branch's reach (the shoulder
joint at its -60 degree limit), so the analytic seed's other branch wins: the base turns by
~180 degrees in what is planned as a vertical descent, the wrist the other way, and the tool
swings over the table. Solving the targets backwards from the last one puts ``above`` on the
branch ``low`` needs (the transit from home, a joint-space move, absorbs the turn).

The base joint's range is +-175 degrees, so a base angle has no other equivalent (+-360 degrees)
within the limits: a turn cannot be shortened by wrapping. The "far wrap" turns the audit found
in the pull (+226 to +321 degrees where -134 to -39 would reach the same angle) cross the joint
limit the short way; such a pull is refused by the turn bound below.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from relaff_jax.config.action import ArmConfig

from .arm_model import Arm
from .kinematics import IKResult, IKTarget, solve_ik

# rad: the largest base-joint turn v3 accepts between consecutive waypoints of a held-tool
# program after the transit (the descent, the pull, the raise). A vertical descent turns it by
# nothing, a 30 cm pull along a line 20 cm from the base axis by 74 degrees; the audited
# failures turned it 81-92 (a pull passing the base axis) or 176-321 degrees (branch changes).
BASE_TURN_MAX = float(jnp.deg2rad(90.0))


def backward_path(arm: Arm, cfg: ArmConfig, targets: IKTarget, forward: IKResult, n_used: jax.Array) -> IKResult:
    """The first ``n_used`` targets (of W) solved from the last one back to the first, each
    warm-started from the solution of the target after it (``solve_ik``: the warm seed and the
    analytic seed, the nearest good one wins); the last used target keeps the forward solution.
    Rows from ``n_used`` on are the forward path's. Returns ``IKResult`` with a (W,) axis."""
    w = targets.pos.shape[0]
    last = n_used - 1
    take = lambda tree, k: jax.tree_util.tree_map(lambda x: x[k], tree)

    def step(q_next, k):
        def solve(q):
            return solve_ik(arm, cfg, take(targets, k), q)

        def keep(_):
            return take(forward, k)

        res = jax.lax.cond(k < last, solve, keep, q_next)
        return jnp.where(k <= last, res.q, q_next), res

    q_last = forward.q[last]
    _, res = jax.lax.scan(step, q_last, jnp.arange(w - 1, -1, -1))
    return jax.tree_util.tree_map(lambda x: x[::-1], res)


def base_turn(q: jax.Array, n_used: jax.Array) -> jax.Array:
    """() rad: the largest base-joint turn between consecutive used waypoints ``q`` (W, 6),
    the transit to the first one (from home) not counted."""
    turn = jnp.abs(jnp.diff(q[:, 0]))
    return jnp.max(jnp.where(jnp.arange(1, q.shape[0]) < n_used, turn, 0.0))


def one_branch(arm: Arm, cfg: ArmConfig, targets: IKTarget, forward: IKResult, n_used: jax.Array) -> IKResult:
    """The forward path if its base turns stay within ``BASE_TURN_MAX`` (the v2 plan, unchanged),
    else the backward path (``backward_path``) if it reaches every used target and turns the base
    less, else the forward path (which the turn bound then refuses)."""
    back = backward_path(arm, cfg, targets, forward, n_used)
    used = jnp.arange(targets.pos.shape[0]) < n_used
    back_ok = jnp.all(back.reachable | ~used)
    t_fwd, t_back = base_turn(forward.q, n_used), base_turn(back.q, n_used)
    use_back = (t_fwd > BASE_TURN_MAX) & back_ok & (t_back < t_fwd)
    return jax.tree_util.tree_map(lambda b, f: jnp.where(use_back, b, f), back, forward)
