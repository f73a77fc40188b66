"""The outcome rules of Table I: was an action's goal reached?

Takes an ``ActionConfig`` (thresholds) and an ``Outcome`` of one scene (centres of mass of the
toy and the other object before, at the measuring step and at the end; the action's
direction; unobstruct's reachability before/after); gives (9,) bool, one goal per action in
``ACTIONS`` order. Pure JAX; the caller vmaps.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .templates import ActionConfig

from relaff_jax.constants import ACTIONS


class Outcome(NamedTuple):
    """Inputs of the outcome rules, per scene: centres of mass (2, 3) of (toy, other) before
    the action, at the measuring step and at the end; the action direction (3,); the
    unobstruct reachability before/after."""

    com0: jax.Array
    com_m: jax.Array
    com_end: jax.Array
    direction: jax.Array
    reach_before: jax.Array
    reach_after: jax.Array


def goals(cfg: ActionConfig, o: Outcome) -> jax.Array:
    """(9,) bool: the goal of every action of Table I (in ``ACTIONS`` order) on one scene."""
    rise = o.com_m[:, 2] - o.com0[:, 2]  # (2,) toy, other
    lifted = rise >= cfg.lifted
    r0 = jnp.linalg.norm(o.com0[:, :2], axis=-1)
    r1 = jnp.linalg.norm(o.com_end[:, :2], axis=-1)
    along = (o.com_end - o.com0) @ o.direction
    toy_moved = jnp.linalg.norm(o.com_m[0] - o.com0[0]) >= cfg.moved
    if cfg.move_rule == "apart":  # the toy moved aside from the base (the base left behind)
        move = along[0] - along[1] >= cfg.aside
    else:  # "both" (config.action declares the two): Table I read literally, both moved aside
        move = jnp.all(along >= cfg.aside)
    rules = {
        "lift": lifted[0] & lifted[1],  # base and toy lifted
        "move": move,  # toy and base moved aside (from each other, by default)
        "pull": jnp.all(r1 - r0 <= -cfg.closer),  # both pulled closer
        "push": jnp.all(r1 - r0 >= cfg.farther),  # both pushed further away
        "rake": r1[0] - r0[0] <= -cfg.closer,  # toy brought closer
        "take": lifted[0] & ~lifted[1],  # toy lifted (taken: its base, if any, left behind)
        "pour": lifted[0] & lifted[1],  # base and toy lifted (after the tilt)
        "slide": lifted[1] & toy_moved & ~lifted[0],  # base lifted, toy moved, not lifted
        "unobstruct": ~o.reach_before & o.reach_after,  # toy reachable now, not before
    }
    return jnp.stack([rules[a] for a in ACTIONS])


def read_at_rest(com, window: int, speed: float, dt: float, xp=jnp):
    """Where a goal is read at rest (v2) and whether the objects had come to rest (one scene).

    ``com`` (T, 2, 3): the centres of mass of (toy, other) at control steps ``measure -
    window`` .. ``measure + hold`` (T = window + 1 + hold). The objects are at rest at step j
    when both moved slower than ``speed`` (m/s; the per-step displacement over ``dt``) over
    each of the ``window`` steps up to j. Returns (i, settled): the index into ``com`` of the
    first step from ``measure`` on (i >= window) at rest, or of the last step (``settled``
    False) if none is. With hold 0 this is the fixed step ``measure`` and whether it was at
    rest. ``xp``: ``jax.numpy`` (MJX, float32) or ``numpy`` (the C engines, float64).
    """
    step = xp.sqrt(xp.sum((com[1:] - com[:-1]) ** 2, axis=-1))  # (T-1, 2) displacement per step
    moving = xp.max(step, axis=-1) >= speed * dt  # (T-1,) step j-1 -> j
    count = xp.concatenate([xp.zeros(1, xp.int32), xp.cumsum(moving.astype(xp.int32))])  # (T,)
    j = xp.arange(window, com.shape[0])
    calm = (count[j] - count[j - window]) == 0  # (hold + 1,)
    settled = xp.any(calm)
    return window + xp.where(settled, xp.argmax(calm), calm.shape[0] - 1), settled

