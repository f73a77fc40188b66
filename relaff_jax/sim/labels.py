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
from relaff_jax.errors import UserError


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
    elif cfg.move_rule == "both":  # Table I read literally: both moved aside
        move = jnp.all(along >= cfg.aside)
    else:
        raise UserError(f"unknown move_rule {cfg.move_rule!r}; valid: 'apart', 'both'")
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
