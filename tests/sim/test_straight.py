"""Straight tcp segments (programs v2, ``sim/straight.py``): the corrected joint path keeps the tcp
on the line, measured by MuJoCo C's kinematics; the interpolation and the stop by hand."""
import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from relaff_jax.config.action import ActionConfig, ArmConfig
from relaff_jax.constants import ACTIONS
from relaff_jax.sim import arm as A
from relaff_jax.sim import straight as S
from relaff_jax.sim.templates import TPL_TARGET


def c_tcp_pos(model, arm, q):
    d = mujoco.MjData(model)
    d.qpos[arm.qpos_arm] = q
    mujoco.mj_kinematics(model, d)
    return d.site_xpos[arm.tcp_site].copy()


def off_line(model, arm, qs, a, b):
    """Largest distance (m) of the C tcp at joints ``qs`` (N, 6) from the line a-b."""
    u = (b - a) / np.linalg.norm(b - a)
    p = np.stack([c_tcp_pos(model, arm, q) for q in qs]) - a
    return np.linalg.norm(p - np.outer(p @ u, u), axis=1).max()


def level_segment(arm):
    """Joint waypoints of a 30 cm level pull towards the robot, tool pointing down (pull's carry)."""
    ik = jax.jit(lambda t, q: A.solve_ik(arm, ArmConfig(), t, q))
    yaw = jnp.asarray(0.3)
    r0 = ik(A.top_down_target(jnp.array([0.85, 0.2, 0.06]), yaw), jnp.zeros(6))
    r1 = ik(A.top_down_target(jnp.array([0.55, 0.13, 0.06]), yaw), r0.q)
    assert bool(r0.reachable) and bool(r1.reachable)
    return np.asarray(r0.q), np.asarray(r1.q)


def test_corrected_segment_stays_on_the_line_in_c(model, arm):
    q0, q1 = level_segment(arm)
    a, b = c_tcp_pos(model, arm, q0), c_tcp_pos(model, arm, q1)
    cfg = ActionConfig()
    corr, err = jax.jit(lambda qw: S.corrections(arm, cfg, qw, jnp.array([True])))(jnp.stack([q0, q1]))
    assert corr.shape == (1, cfg.straight_pieces - 1, 6) and float(err) < 1e-5
    s = np.linspace(0.0, 1.0, 41)
    linear = q0 + s[:, None] * (q1 - q0)
    straight = np.stack([np.asarray(S.ctrl_q(jnp.asarray(q0), jnp.asarray(q1), corr[0], x)) for x in s])
    sag, kept = off_line(model, arm, linear, a, b), off_line(model, arm, straight, a, b)
    assert sag > 0.005  # the joint-linear path leaves the line by millimetres ...
    assert kept < 0.001 and kept < sag / 10  # ... the corrected one stays within a millimetre


def test_ctrl_q_by_hand():
    q0, q1 = jnp.zeros(6), jnp.ones(6)
    corr = jnp.arange(3 * 6, dtype=jnp.float32).reshape(3, 6)  # 4 pieces: cuts at 1/4, 1/2, 3/4
    np.testing.assert_allclose(S.ctrl_q(q0, q1, corr, 0.0), np.zeros(6))
    np.testing.assert_allclose(S.ctrl_q(q0, q1, corr, 1.0), np.ones(6))
    np.testing.assert_allclose(S.ctrl_q(q0, q1, corr, 0.5), 0.5 + np.arange(6, 12), rtol=1e-6)
    # halfway between the cuts at 1/4 (corr[0]) and 1/2 (corr[1])
    np.testing.assert_allclose(S.ctrl_q(q0, q1, corr, 0.375), 0.375 + np.arange(6) + 3.0, rtol=1e-6)
    # with zero corrections, the joint-linear interpolation
    np.testing.assert_allclose(S.ctrl_q(q0, q1, jnp.zeros((3, 6)), 0.3), np.full(6, 0.3), rtol=1e-6)


def test_rows_turns_and_stops(arm):
    v2, v1 = ActionConfig(), dataclasses.replace(ActionConfig(), programs="v1")
    rows = S.straight_rows(v2, TPL_TARGET)
    assert not S.straight_rows(v1, TPL_TARGET).any()
    assert not S.straight_rows(dataclasses.replace(v2, straight_pieces=1), TPL_TARGET).any()
    # rake: down (1), pull (3), raise (5); never the transit from home (0) or a dwell
    assert np.flatnonzero(rows[ACTIONS.index("rake")]).tolist() == [1, 3, 5]
    assert not rows[:, 0].any()
    # a segment that turns the tool (pour's tilt) keeps its joint-linear path
    q0 = np.zeros(6, np.float32)
    q1 = q0.copy()
    q1[5] = 0.5  # the wrist turns: the tcp's axes differ
    corr, _ = S.corrections(arm, v2, jnp.stack([q0, q1]), jnp.array([True]))
    assert float(jnp.abs(corr).max()) == 0.0
    # a stop that holds segments 1-2 (waypoints 1-3 replaced) zeroes their corrections only
    c = np.ones((4, 7, 6), np.float32)
    held = np.array([False, True, True, True, False])
    out = S.stopped_corrections(c, held)
    assert out[1:3].max() == 0.0 and out[0].min() == 1.0 and out[3].min() == 1.0
    np.testing.assert_array_equal(np.asarray(S.stopped_corrections(jnp.asarray(c), held)), out)
