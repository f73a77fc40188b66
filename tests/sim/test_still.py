"""Programs v4's stillness check (relaff_jax/sim/still.py): a settled scene is simulated
``STILL_STEPS`` more steps and its program refused where an object moves or turns beyond the
bounds. Hand-worked bounds, MuJoCo C on hand-built scenes (fast), MJX against C (slow), and the
refusal in the v4 prepare."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.sim import rollouts
from relaff_jax.sim import still as S
from relaff_jax.sim.native import settle as native_settle

from helpers.scenes import hand_built

ROWS = [
    ("ball", "cup", (0.7, 0.3, 0.0), (0.7, 0.0, 0.0), 0.0),  # 0 a ball set rolling at 0.2 m/s
    ("block", "cup", (0.8, 0.45, 0.0), (0.8, 0.0, 0.0), 0.0),  # 1 left as settled: still
    ("toy_car", "tray", (0.7, -0.3, 0.0), (0.7, 0.3, 0.0), 0.0),  # 2 the car raised 3 cm: it falls
    ("block", "book", (0.6, 0.2, 0.0), (0.9, 0.2, 0.0), 0.0),  # 3 the book raised 3 cm: it falls
]


def _turned(deg):
    h = np.deg2rad(deg) / 2
    return [np.cos(h), 0.0, 0.0, np.sin(h)]


def test_bounds_hand_worked(scene_world):
    w = scene_world
    q0 = np.tile(np.asarray(w.mj_model.qpos0, np.float64)[:14], (6, 1))
    q0[:, 3:7] = q0[:, 10:14] = [1.0, 0.0, 0.0, 0.0]
    q1 = q0.copy()
    q1[1, w.toy_qpos] += 0.009  # 9 mm: within STILL_MOVE (1 cm)
    q1[2, w.obj_qpos + 1] += 0.011  # 11 mm: beyond
    q1[3, w.toy_qpos + 3:w.toy_qpos + 7] = _turned(9.0)  # within STILL_TURN_DEG (10)
    q1[4, w.obj_qpos + 3:w.obj_qpos + 7] = _turned(11.0)  # beyond
    q1[5, w.toy_qpos + 3:w.toy_qpos + 7] = -np.asarray(_turned(3.0))  # -q is the same turn
    want = [True, True, False, True, False, True]
    assert S.still_numpy(w, q0, q1).tolist() == want
    assert np.asarray(S.stayed_still(w, jnp.asarray(q0, jnp.float32), jnp.asarray(q1, jnp.float32))).tolist() == want


def _disturbed(w):
    """The ROWS settled in C, then disturbed as each row says: (pair, qpos, qvel)."""
    pair, q0 = hand_built(w, ROWS)
    pair, q0 = np.asarray(pair), np.asarray(q0)
    s = native_settle.settle_batch(w, pair, q0, np.zeros(len(pair), np.int32))
    q, v = np.array(s.qpos), np.array(s.qvel)
    v[0, w.toy_dof] = 0.2
    q[2, w.toy_qpos + 2] += 0.03
    q[3, w.obj_qpos + 2] += 0.03
    return pair, q, v


def test_c_check_refuses_what_moves_and_keeps_what_stays(scene_world):
    pair, q, v = _disturbed(scene_world)
    got = native_settle.still_batch(scene_world, pair, q, v, nthread=2)
    assert got.tolist() == [False, True, False, False]
    # the same scenes left as settled all stay still
    s = native_settle.settle_batch(scene_world, pair, np.asarray(hand_built(scene_world, ROWS)[1]),
                                   np.zeros(len(pair), np.int32))
    assert native_settle.still_batch(scene_world, pair, s.qpos, s.qvel).all()


@pytest.mark.slow  # compiles MJX's 125-step check
def test_mjx_check_equals_c(scene_world):
    pair, q, v = _disturbed(scene_world)
    fn = rollouts.jitted_still_fn(scene_world)
    got = np.asarray(jax.device_get(fn(jnp.asarray(pair), jnp.asarray(q), jnp.asarray(v))))
    assert got.tolist() == native_settle.still_batch(scene_world, pair, q, v).tolist() == [False, True, False, False]


def test_v4_prepare_refuses_the_programs_of_scenes_that_move(monkeypatch):
    """The native prepare of v4 runs the check after planning, on the scenes whose program is
    feasible, and refuses those it rejects; the scenes stay as settled; v3 never runs it. The
    planner is replaced by one that plans every other scene (compiling the real one costs two
    minutes of CPU; the refusal is what is tested here)."""
    from relaff_jax.sim.planning import Plan

    def every_other(cfg, aid, pair, qpos):
        n = len(pair)
        z = np.zeros
        return Plan(z((n, 3, 6), np.float32), z((n, 3), np.float32), z(2, np.int32), np.arange(n) % 2 == 0,
                    z((n, 3), np.float32), z(n, np.float32)), z(n, bool)

    seen = []

    def reject_first(world, pair, qpos, qvel, nthread=1):
        seen.append(np.asarray(qpos))
        return np.arange(len(pair)) > 0

    monkeypatch.setattr(rollouts, "prepare_screened", every_other)
    monkeypatch.setattr(rollouts, "still_batch", reject_first)
    v4 = dataclasses.replace(ActionConfig(), programs="v4")
    got = rollouts.make_batch_prepare_fn("pull", v4, settle="native")(jax.random.PRNGKey(3), 8)
    (qpos,) = seen
    np.testing.assert_array_equal(qpos, got.scenes.qpos[[0, 2, 4, 6]])  # the planned scenes, as settled
    assert np.flatnonzero(got.plan.feasible).tolist() == [2, 4, 6]  # the first of them refused
    v3 = rollouts.make_batch_prepare_fn("pull", dataclasses.replace(v4, programs="v3"), settle="native")
    assert np.flatnonzero(v3(jax.random.PRNGKey(3), 8).plan.feasible).tolist() == [0, 2, 4, 6]
    assert len(seen) == 1
