"""Arm kinematics and IK, checked against MuJoCo C (mj_kinematics) on the arm's own model."""

# MJX/XLA:CPU is ~100x slower on deep kinematic chains with the fusion emitters (docs/arm.md);
# must be set before JAX creates its CPU client.

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from relaff_jax.sim import arm as A
from relaff_jax.config.action import ArmConfig


@pytest.fixture(scope="module")
def ik(arm):
    cfg = ArmConfig()
    return jax.jit(jax.vmap(lambda t, q: A.solve_ik(arm, cfg, t, q)))


def c_tcp(model, arm, q):
    """tcp pose by MuJoCo C for arm joints q (6,)."""
    d = mujoco.MjData(model)
    d.qpos[arm.qpos_arm] = q
    mujoco.mj_kinematics(model, d)
    return d.site_xpos[arm.tcp_site].copy(), d.site_xmat[arm.tcp_site].reshape(3, 3).copy()


def test_fk_matches_mujoco_c(model, arm):
    rng = np.random.default_rng(0)
    qs = rng.uniform(arm.q_lo, arm.q_hi, (8, 6))
    pos, mat = jax.jit(jax.vmap(lambda q: A.fk_tcp(arm, q)))(jnp.asarray(qs))
    for q, p, r in zip(qs, np.asarray(pos), np.asarray(mat)):
        pc, rc = c_tcp(model, arm, q)
        np.testing.assert_allclose(p, pc, atol=2e-6)
        np.testing.assert_allclose(r, rc, atol=2e-6)


def test_reach_and_geometry(model, arm):
    # Zero pose by hand: shoulder 0.40 m up, upper arm 0.62 m vertical, forearm 0.60 m along
    # +x, tcp 0.19 m below the wrist centre and pointing down.
    p, r = c_tcp(model, arm, np.zeros(6))
    np.testing.assert_allclose(p, [0.60, 0.0, 0.40 + 0.62 - 0.19], atol=1e-9)
    np.testing.assert_allclose(r[:, 2], [0, 0, -1], atol=1e-9)
    # Joint limits and actuator ranges agree (inheritrange).
    np.testing.assert_allclose(model.actuator_ctrlrange[arm.act_arm], np.stack([arm.q_lo, arm.q_hi], 1), atol=1e-6)
    assert np.all(arm.q_lo >= model.jnt_range[:6, 0])
    assert np.all(arm.q_hi <= model.jnt_range[:6, 1])


def random_workspace_targets(rng, n):
    """Top-down grasps (random yaw) over the reachable part of the table half-disc."""
    r = rng.uniform(0.25, 1.15, n)
    th = rng.uniform(-np.pi / 2, np.pi / 2, n)
    z = rng.uniform(0.03, 0.5, n)
    pos = np.stack([r * np.cos(th), r * np.sin(th), z], 1)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return jax.vmap(A.top_down_target)(jnp.asarray(pos), jnp.asarray(yaw))


def check_against_c(model, arm, res, targets, tol_pos=0.005, tol_ang=0.05):
    q = np.asarray(res.q)
    assert np.all(q >= arm.q_lo - 1e-6)
    assert np.all(q <= arm.q_hi + 1e-6)
    errs = []
    for i in range(q.shape[0]):
        pc, rc = c_tcp(model, arm, q[i])
        pe = np.linalg.norm(pc - np.asarray(targets.pos[i]))
        ae = np.arccos(np.clip(rc[:, 2] @ np.asarray(targets.approach[i]), -1, 1))
        ce = np.arccos(np.clip(abs(rc[:, 1] @ np.asarray(targets.closing[i])), 0, 1))
        ce = ce if float(targets.closing_weight[i]) > 0 else 0.0
        errs.append((pe, max(ae, ce)))
        assert pe < tol_pos, (i, pe)
        assert max(ae, ce) < tol_ang, (i, ae, ce)
        # the reported residual is the one MuJoCo C sees
        assert abs(pe - float(res.pos_err[i])) < 1e-4
    return np.asarray(errs)


def test_ik_reaches_random_top_down_targets(model, arm, ik):
    targets = random_workspace_targets(np.random.default_rng(1), 8)
    res = ik(targets, jnp.zeros((8, 6)))
    assert np.asarray(res.reachable).all()
    check_against_c(model, arm, res, targets)


@pytest.mark.slow  # a second IK compile; the fast tier keeps the top-down IK test
def test_ik_reaches_tilted_targets_from_fk(model, arm, ik):
    # Targets made by FK of random configurations with the tcp within 60 deg of straight down
    # are reachable by construction; the solver must find a pose (maybe another branch).
    rng = np.random.default_rng(2)
    qs = []
    while len(qs) < 8:
        q = rng.uniform(arm.q_lo, arm.q_hi)
        q[1:4] = rng.uniform([0.2, -1.2, -2.5], [1.6, 1.8, 0.5])
        q[4] = rng.uniform(-0.8, 0.8)
        p, r = c_tcp(model, arm, q)
        if p[0] > 0.25 and 0.05 < p[2] < 0.8 and r[2, 2] < -0.5:
            qs.append(q)
    pos, mat = zip(*[c_tcp(model, arm, q) for q in qs])
    mat = np.stack(mat)
    targets = A.IKTarget(jnp.asarray(np.stack(pos)), jnp.asarray(mat[:, :, 2]),
                         jnp.asarray(mat[:, :, 1]), jnp.ones(8), jnp.zeros(8))
    res = ik(targets, jnp.zeros((8, 6)))
    assert np.asarray(res.reachable).all(), res
    check_against_c(model, arm, res, targets)


@pytest.mark.slow  # a second IK compile; the fast tier keeps the top-down IK test
def test_far_target_is_unreachable_and_limits_hold(arm, ik):
    pos = jnp.array([[1.6, 0.0, 0.05], [0.0, 1.6, 0.2], [1.25, 0.0, 0.05], [0.8, 0.0, 0.05]])
    targets = jax.vmap(A.top_down_target)(pos, jnp.zeros(4))
    res = ik(targets, jnp.zeros((4, 6)))
    assert list(np.asarray(res.reachable)) == [False, False, False, True]
    assert float(res.pos_err[0]) > 0.2  # ~0.4 m beyond the reach
    q = np.asarray(res.q)
    assert np.all(q >= arm.q_lo)
    assert np.all(q <= arm.q_hi)  # float32 limits lie inside the model's


@pytest.mark.slow  # another IK path compile
def test_ik_path_is_continuous(arm):
    cfg = ArmConfig()
    pts = jnp.array([[0.7, 0.2, 0.3], [0.7, 0.2, 0.05], [0.7, 0.2, 0.4], [0.5, -0.2, 0.4]])
    targets = jax.vmap(A.top_down_target)(pts, jnp.full(4, 0.3))
    res = jax.jit(lambda t: A.solve_ik_path(arm, cfg, t, jnp.zeros(6)))(targets)
    assert np.asarray(res.reachable).all()
    # consecutive waypoints: no joint flips (a yaw flip by pi would show as a ~3 rad jump)
    assert np.abs(np.diff(np.asarray(res.q), axis=0)).max() < 1.5


def test_program_ctrl_interpolates(arm):
    q_way = jnp.stack([jnp.zeros(6), jnp.ones(6), jnp.full(6, 3.0)])
    grip = jnp.array([0.12, 0.0, 0.0])
    f = jax.jit(lambda t: A.program_ctrl(arm, q_way, grip, (10, 20), t))
    c = np.stack([np.asarray(f(t)) for t in (0, 5, 10, 20, 30, 40)])
    qa, qf = c[:, arm.act_arm], c[:, arm.act_fingers]
    np.testing.assert_allclose(qa[:, 0], [0.0, 0.5, 1.0, 2.0, 3.0, 3.0], atol=1e-6)  # smoothstep(1/2) = 1/2
    np.testing.assert_allclose(qf[:, 0], [0.12, 0.06, 0.0, 0.0, 0.0, 0.0], atol=1e-6)
    assert np.all(qf[:, 0] == qf[:, 1])
    with pytest.raises(ValueError, match="segment lengths"):
        A.program_ctrl(arm, q_way, grip, (10,), 0)


def test_model_without_arm_is_a_clear_error():
    m = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom type='plane' size='1 1 1'/></worldbody></mujoco>")
    with pytest.raises(ValueError, match="no joint named 'j1'.*arm.xml"):
        A.arm_from_model(m)


def test_collision_pairs_are_few(model):
    # Only pedestal, palm and pads collide; the arm links never test against anything.
    from mujoco.mjx._src import collision_driver

    names = {tuple(sorted((model.geom(a).name, model.geom(b).name)))
             for a, b, _ in collision_driver.geom_pairs(model)}
    assert names == {
        ("arm_palm", "table"), ("arm_pad_l", "table"), ("arm_pad_r", "table"), ("obj_geom", "table"),
        ("arm_pedestal", "obj_geom"), ("arm_palm", "obj_geom"), ("arm_pad_l", "obj_geom"),
        ("arm_pad_r", "obj_geom"),
    }
    types = {int(model.geom_type[g]) for g in range(model.ngeom) if model.geom_contype[g]}
    assert types <= {int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_BOX),
                     int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE)}


def test_ik_path_solves_only_the_used_targets(arm):
    """``solve_ik_path(..., n_used)`` (the plan solves only the targets its template uses):
    the solved rows equal a full solve bit for bit, the skipped ones hold the last solution
    and are never reachable. n_used is a traced argument, one value for the batch (vmap)."""
    cfg = ArmConfig()
    rng = np.random.default_rng(0)
    pos = np.stack([rng.uniform([0.35, -0.3, 0.05], [0.6, 0.3, 0.3], (6, 3)) for _ in range(3)]).astype(np.float32)
    targets = jax.vmap(jax.vmap(A.top_down_target))(jnp.asarray(pos))  # (3 scenes, 6 targets)
    q0 = jnp.zeros(6)
    full = jax.jit(jax.vmap(lambda t: A.solve_ik_path(arm, cfg, t, q0)))(targets)
    part = jax.jit(jax.vmap(lambda t, n: A.solve_ik_path(arm, cfg, t, q0, n), in_axes=(0, None)))(targets, 4)
    assert bool(np.all(np.asarray(full.reachable)[:, :4])), "the test's targets should be reachable"
    for f, p in zip(full, part):
        np.testing.assert_array_equal(np.asarray(p)[:, :4], np.asarray(f)[:, :4])
    q = np.asarray(part.q)
    np.testing.assert_array_equal(q[:, 4:], np.repeat(q[:, 3:4], 2, axis=1))
    assert not np.asarray(part.reachable)[:, 4:].any()
    assert not np.asarray(part.pos_err)[:, 4:].any()
    assert not np.array_equal(q[:, 4:], np.asarray(full.q)[:, 4:])  # the skipped rows were not solved


def test_lm_solver_reaches_the_same_targets(model, arm):
    """``ik_solver="lm"`` (Levenberg-Marquardt, ``ik_lm.py``): the random top-down targets and
    the far ones give L-BFGS's reachability, the joints within limits, C's tcp on the targets;
    the default config records no solver (``templates.stored_config``), "lm" does."""
    import dataclasses

    from relaff_jax.sim import templates

    cfg = dataclasses.replace(ArmConfig(), ik_solver="lm")
    ik_lm = jax.jit(jax.vmap(lambda t, q: A.solve_ik(arm, cfg, t, q)))
    targets = random_workspace_targets(np.random.default_rng(1), 8)
    res = ik_lm(targets, jnp.zeros((8, 6)))
    assert np.asarray(res.reachable).all()
    check_against_c(model, arm, res, targets)
    far = jax.vmap(A.top_down_target)(jnp.array([[1.6, 0.0, 0.05], [0.0, 1.6, 0.2], [1.25, 0.0, 0.05], [0.8, 0.0, 0.05]]),
                                      jnp.zeros(4))
    res = ik_lm(jax.tree_util.tree_map(lambda x: jnp.concatenate([x, x]), far), jnp.zeros((8, 6)))
    assert list(np.asarray(res.reachable)) == [False, False, False, True] * 2
    q = np.asarray(res.q)
    assert np.all(q >= arm.q_lo)
    assert np.all(q <= arm.q_hi)
    with pytest.raises(ValueError, match="ik_solver"):
        A.solve_ik(arm, dataclasses.replace(cfg, ik_solver="newton"), jax.tree_util.tree_map(lambda x: x[0], far),
                   jnp.zeros(6))
    action = templates.ActionConfig()
    assert "ik_solver" not in templates.stored_config(action)["arm"]
    lm = dataclasses.replace(action, arm=cfg)
    assert templates.stored_config(lm)["arm"]["ik_solver"] == "lm"
