"""Straight tcp segments (programs v2): the joint-space correction that keeps the tcp on the line.

Takes the ``Arm`` tables, an ``ActionConfig`` and a program's joint waypoints; gives
``straight_rows(cfg)`` (which segments of each action may be straight), ``corrections`` (per
segment the joint offsets at ``cfg.straight_pieces - 1`` points along it) and ``ctrl_q`` (the
arm's joint command at a segment fraction, with the correction). One program; the caller vmaps
and jits.

Why: a segment interpolates its two joint waypoints linearly, so a tcp move that is level at
both ends sags in between (the arm's joints do not move the tcp on a line): measured on the
study's programs up to 19 mm for rake's pull and 26 mm for pull's carry, which pressed the held
rake into the table at 300-430 N in every rake rollout. A robot's controller moves the tool
on a line (a Cartesian "move linear"). Here each segment between two waypoints whose tcp
orientations agree is cut into ``straight_pieces`` equal parts; at each cut the joints that put
the tcp on the line are solved (Levenberg-Marquardt from the linear joints, ``ik_lm``) and the
difference to the linear joints is the correction there. The command adds the correction,
interpolated linearly between the cuts (zero at both ends), to the linear joints, at the same
smoothstep fraction as before: between cuts the tcp is off the line by about the sag divided
by the pieces squared (0.4 mm at 8 pieces for 26 mm). Segments from the home pose (a joint-space
transit) and segments that turn the tool (pour's tilt) stay linear in the joints.
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.action import ActionConfig

from .arm_model import Arm
from .ik_lm import descend_lm
from .kinematics import IKTarget, _residual, fk_tcp

LM_STEPS = 6  # Levenberg-Marquardt steps per cut, from the linear joints (a few mm off the line)
SAME_ORIENTATION = 1e-3  # largest difference of the tcp axes (unit vectors) of a straight segment's ends


def straight_rows(cfg: ActionConfig, target: np.ndarray) -> np.ndarray:
    """(A, S) bool from the templates' targets (A, S): segment k may be straight when it moves to
    another target than segment k - 1 (not the first segment, a transit from home). All False
    for v1 and for ``straight_pieces`` 1."""
    rows = np.zeros(target.shape, bool)
    if cfg.programs == "v1" or cfg.straight_pieces <= 1:
        return rows
    rows[:, 1:] = target[:, 1:] != target[:, :-1]
    return rows


def _segment(arm: Arm, cfg: ActionConfig, q0: jax.Array, q1: jax.Array, straight: jax.Array):
    """Corrections (P - 1, 6) and the largest tcp residual () at the cuts of one segment."""
    p0, r0 = fk_tcp(arm, q0)
    p1, r1 = fk_tcp(arm, q1)
    same = straight & (jnp.max(jnp.abs(r0 - r1)) < SAME_ORIENTATION)
    n = int(cfg.straight_pieces)
    lm = dataclasses.replace(cfg.arm, ik_lm_steps=LM_STEPS)

    def cut(s):
        q_lin = q0 + s * (q1 - q0)
        target = IKTarget(p0 + s * (p1 - p0), r1[:, 2], r1[:, 1], jnp.asarray(1.0), jnp.asarray(1.0))
        q = descend_lm(arm, lm, q_lin, target, _residual)
        return q - q_lin, jnp.linalg.norm(fk_tcp(arm, q)[0] - target.pos)

    delta, err = jax.vmap(cut)(jnp.arange(1, n, dtype=jnp.float32) / n)
    return jnp.where(same, delta, 0.0), jnp.where(same, jnp.max(err), 0.0)


def corrections(arm: Arm, cfg: ActionConfig, q_way: jax.Array, straight: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The joint corrections of one program: ``q_way`` (S + 1, 6) waypoints, ``straight`` (S,)
    bool (a row of ``straight_rows``); returns (S, P - 1, 6) float32 (zero on segments that are
    not straight, P = ``cfg.straight_pieces``) and () the largest tcp residual at a cut (m)."""
    q_way = jnp.asarray(q_way, jnp.float32)
    if cfg.programs == "v1" or cfg.straight_pieces <= 1:  # no cuts: linear in the joints
        return jnp.zeros((q_way.shape[0] - 1, 0, 6), jnp.float32), jnp.zeros((), jnp.float32)
    corr, err = jax.vmap(lambda a, b, s: _segment(arm, cfg, a, b, s))(q_way[:-1], q_way[1:], jnp.asarray(straight))
    return corr, jnp.max(err)


def ctrl_q(q0: jax.Array, q1: jax.Array, corr: jax.Array, s: jax.Array) -> jax.Array:
    """The joints (6,) at smoothstep fraction ``s`` () of a segment from ``q0`` to ``q1`` (6,):
    the linear joints plus ``corr`` (P - 1, 6) interpolated over the P pieces (0 at the ends)."""
    n = corr.shape[0] + 1
    nodes = jnp.concatenate([jnp.zeros((1, 6), corr.dtype), corr, jnp.zeros((1, 6), corr.dtype)])
    u = s * n
    j = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, n - 1)
    w = u - j
    return q0 + s * (q1 - q0) + nodes[j] + w * (nodes[j + 1] - nodes[j])


def stopped_corrections(corr: jax.Array, rows) -> jax.Array:
    """The corrections (S, P - 1, 6) after a guarded descent stopped (``guard.stopped_way``):
    zero on the segments whose both waypoints the stop replaced (the arm holds still there).
    ``rows`` (S + 1,) bool; works on numpy and JAX arrays."""
    xp = jnp if isinstance(corr, jax.Array) else np
    held = xp.asarray(rows[:-1]) & xp.asarray(rows[1:])
    return xp.where(held[:, None, None], xp.zeros((), corr.dtype), corr)
