"""The guarded descent of programs v2: the arm stops going down to a grasp where a pad lands.

Takes an ``ActionConfig`` and, per control step, a scene's contacts and arm joints; gives
where a program is guarded (``guard_tables``), the landing test (``pad_landing`` on MJX
contacts, ``pad_landing_np`` on C contact distances and normals, the same rule) and the
waypoints after a stop (``stopped_way``). Used by the three executors (MJX
``simulate.run_program_locked``, C ``native.reference.replay_native`` and ``native.batch``).

Why: the fingers and the palm go down by position servo (about 4 kN/m at the tcp). A pad that
comes down on an object the plan's boxes did not exclude (take's fixed 10 cm opening over a
toy that is wider along the closing axis, by design: docs/actions.md) was driven on towards
the planned height and pressed the toy into its base with 50+ N, 12 mm deep. With the guard,
the first step at which a pad touches an object off its gripping face (the contact normal
more than ``arccos(arm.contact_face_cos)`` from the closing axis: the pad's bottom or edge on a
top) deeper than ``cfg.guard_depth``, during a segment that opens the fingers and goes to the
grasp (segments 1-2 of every grasp template), the grasp waypoint becomes the arm's joints at
that step, backed off along its motion by ``BACKOFF_S``: the servos hold the arm there instead of pushing, the fingers then close there,
and the program goes on from there (the lift starts from the stop). A pad that only slides
along a toy's side (turning it into the gap) is a face contact and does not stop the descent.
"""
from __future__ import annotations

import numpy as np
import jax
import jax.numpy as jnp

from . import arm as A
from .contacts import contacts
from .actions.tables import tables
from .templates import ActionConfig

GRASP_TARGET = 1  # the grasp's index among a grasp program's IK targets (templates: _LIFT, _DRAG)
# The hold is the joints BACKOFF_S before the landing step along the arm's motion (q - qdot x
# BACKOFF_S): a stop exactly at the landing step holds the pad the last step's travel (up to
# 2 mm) deep, and the position servos then press it there (36 N on a 0.25 kg cup).
BACKOFF_S = 0.02


def guard_tables(cfg: ActionConfig) -> tuple[np.ndarray, np.ndarray]:
    """(A, S) bool (the run's actions, ``actions.tables``): the segments at whose steps a landing
    stops the descent, and (A, S + 1)
    bool: the waypoints a stop replaces (segment k runs from waypoint k to k + 1: the waypoint
    where the descent starts (1; v4 2, after the dwell) through the last one that is the grasp). All False for v1 and
    for the programs without a grasp (move, rake)."""
    tb = tables(cfg)
    grasp = (tb.target == GRASP_TARGET) & (tb.grasp[:, None] != 0)
    seg = grasp & ~tb.closed
    seg[:, 0] = False
    rows = np.zeros((tb.target.shape[0], tb.target.shape[1] + 1), bool)
    if cfg.programs == "v1":
        return np.zeros_like(seg), rows
    for a in range(len(rows)):
        if seg[a].any():
            rows[a, np.flatnonzero(seg[a]).min():np.flatnonzero(grasp[a]).max() + 2] = True
    return seg, rows


def pad_landing(arm: A.Arm, cfg: ActionConfig, dx, geoms: jax.Array) -> jax.Array:
    """() bool: does a pad touch one of ``geoms`` (ids) off its gripping face deeper than
    ``cfg.guard_depth`` in the MJX data ``dx`` (one scene)?"""
    con = contacts(dx)
    g1, g2 = con.geom[:, 0], con.geom[:, 1]
    geoms = jnp.asarray(geoms).reshape(-1)
    is1 = jnp.any(g1[:, None] == geoms[None, :], axis=1)
    is2 = jnp.any(g2[:, None] == geoms[None, :], axis=1)
    normal = con.frame[:, 0, :]
    deep = con.dist < -cfg.guard_depth

    def lands(pad):
        axis = dx.geom_xmat[pad][:, 1]
        side = jnp.abs(normal @ axis) < cfg.arm.contact_face_cos
        return jnp.any((((g1 == pad) & is2) | ((g2 == pad) & is1)) & deep & side)

    return lands(int(arm.pad_geoms[0])) | lands(int(arm.pad_geoms[1]))


def pad_landing_np(dist: np.ndarray, normal: np.ndarray, axis: np.ndarray, valid: np.ndarray,
                   cfg: ActionConfig) -> np.ndarray:
    """``pad_landing``'s rule on C contacts of one pad: dist (..., K), normal (..., K, 3), axis
    (..., 3) the pad's closing axis, valid (..., K) bool; returns (...) bool. The dot product
    is summed in ``native.program.pad_hit``'s order."""
    a = axis[..., None, :]
    dot = normal[..., 0] * a[..., 0] + normal[..., 1] * a[..., 1] + normal[..., 2] * a[..., 2]
    return np.any(valid & (dist < -cfg.guard_depth) & (np.abs(dot) < cfg.arm.contact_face_cos), axis=-1)


def hold_joints(q, qdot):
    """The joints (6,) the stopped descent holds: ``q - qdot x BACKOFF_S`` from the arm's joint
    positions and velocities (6,) at the landing step (numpy float64 in C, float32 in MJX)."""
    return q - qdot * BACKOFF_S


def stopped_way(q_way, rows, q_stop):
    """The waypoints (W, 6) after a stop at the joints ``q_stop`` (6,): ``rows`` (W,) bool
    replaced (``guard_tables``). Works on numpy and JAX arrays alike (float32)."""
    xp = jnp if isinstance(q_way, jax.Array) else np
    return xp.where(rows[:, None], xp.asarray(q_stop, xp.float32)[None, :], q_way)
