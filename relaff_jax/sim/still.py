"""Programs v4: a settled scene must stay still before a program runs on it.

Settling stops after ``SceneConfig.settle_steps`` and calls a scene at rest when both objects'
origins are slower than ``rest_speed``. A can leaning on a plate's rim passes that test (its
origin, at its bottom, moves 6 mm/s while it turns) and then falls flat in the next 0.4 s, with
no arm near it: its program was planned for a leaning can and its pads landed on the lying one
(move 8873 of the v4 audit, docs/actions.md "Programs v4"). So v4 simulates each settled scene
whose program is feasible (MJX: every scene of the batch, one compiled shape) ``STILL_STEPS``
more steps, from its settled positions and velocities, and refuses the program
of a scene in which either object's origin moves more than ``STILL_MOVE`` or it turns more than
``STILL_TURN_DEG`` (``rollouts.make_batch_prepare_fn``). The scene itself stays as settled.

``make_still_fn`` is the MJX check (pure; the caller jits it); ``native.settle.still_batch`` is
MuJoCo C's, for the native engine. ``stayed_still`` compares two object states (numpy or JAX).
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from . import world as wd
from .scenes import pair_table, step_held

# Measured on the 9,216 settled scenes of the v4 move audit (journal 2026-12-07, "Programs v4: a
# settled scene must stay still"): over 0.5 s after settling, 4 scenes moved 21-58 mm and turned
# 38-119 degrees (a can falling off a rim, a ball rolling off a lid, a car tipping off a board);
# every other one moved at most 3.0 mm and turned at most 4.3 degrees. The bounds sit in that gap.
STILL_STEPS = 125  # control steps: 0.5 s at the default 4 ms step
STILL_MOVE = 0.01  # m an object's origin may move over STILL_STEPS
STILL_TURN_DEG = 10.0  # degrees an object may turn over STILL_STEPS
_COS_HALF_TURN = math.cos(math.radians(STILL_TURN_DEG) / 2)  # a unit quaternion turned by t has |<q0, q1>| = cos(t/2)


def stayed_still(world: wd.World, q0, q1, xp=jnp):
    """(B,) bool: did both objects stay within ``STILL_MOVE`` and ``STILL_TURN_DEG`` from the
    states ``q0`` to ``q1`` (B, nq)? ``xp``: ``jnp`` or ``numpy``."""
    ok = True
    for a in (world.toy_qpos, world.obj_qpos):
        moved = xp.linalg.norm(q1[:, a:a + 3] - q0[:, a:a + 3], axis=-1)
        turn = xp.abs(xp.sum(q1[:, a + 3:a + 7] * q0[:, a + 3:a + 7], axis=-1))
        ok = ok & (moved <= STILL_MOVE) & (turn >= _COS_HALF_TURN)
    return ok


def make_still_fn(world: wd.World, steps: int = STILL_STEPS):
    """Build ``still_fn(pair, qpos, qvel) -> (B,) bool`` (pure; the caller jits it): each settled
    scene (``Scenes.qpos``/``qvel``, (B, nq)/(B, nv)) simulated ``steps`` more MJX steps on the
    arm-less world, a held rake pinned as ``scenes.make_settle_fn`` pins it; True where both
    objects stayed still (``stayed_still``)."""
    table = pair_table(world)
    d0 = mjx.make_data(world.mj_model)

    def still_fn(pair: jax.Array, qpos: jax.Array, qvel: jax.Array) -> jax.Array:
        step = wd.batched_step(world)
        models = wd.scene_models(world, pair)
        data = jax.vmap(lambda q, v: d0.replace(qpos=q, qvel=v))(qpos, qvel)
        data = step_held(world, table, step, models, pair, data, steps)
        return stayed_still(world, qpos, data.qpos)

    return still_fn


def still_numpy(world: wd.World, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``stayed_still`` on numpy arrays."""
    return np.asarray(stayed_still(world, np.asarray(q0, np.float64), np.asarray(q1, np.float64), xp=np), bool)
