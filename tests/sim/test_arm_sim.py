"""The arm in MJX: a waypoint program (reach, grasp, lift, tilt) on a free 1 kg box, checked by
physics and replayed in native MuJoCo C (mj_step) with the same actuator commands."""
import functools

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from relaff_jax.sim import arm as A
from relaff_jax.config.action import ArmConfig

# home->above, dwell, ->down, close, ->lift, ->tilt, dwell (control steps of 4 ms)
SEG = (200, 50, 150, 75, 200, 200, 50)
WAY = (0, 0, 1, 2, 3, 4, 4)  # IK target of each waypoint after the home pose
TILT = np.radians(70)
# scenes: box x, y; gripper offset in y (0.2 = closes 20 cm beside the box: a miss)
XS = np.array([0.7, 0.5, 1.0, 0.7])
YS = np.array([0.0, 0.3, -0.3, 0.0])
MISS = np.array([0.0, 0.0, 0.0, 0.2])


def waypoint_targets(x, y, off):
    gy = y + off
    pos = jnp.stack([jnp.array([x, gy, 0.25]), jnp.array([x, gy, 0.045]), jnp.array([x, gy, 0.045]),
                     jnp.array([x, gy, 0.35]), jnp.array([x, gy, 0.35])])
    down, across = jnp.array([0.0, 0.0, -1.0]), jnp.array([1.0, 0.0, 0.0])
    # the last waypoint tilts the tool 70 deg about world y (perpendicular to the closing axis)
    tilt_a = jnp.array([-np.sin(TILT), 0.0, -np.cos(TILT)])
    tilt_c = jnp.array([np.cos(TILT), 0.0, -np.sin(TILT)])
    return A.IKTarget(pos, jnp.stack([down] * 4 + [tilt_a]), jnp.stack([across] * 4 + [tilt_c]),
                      jnp.ones(5), jnp.zeros(5))


@pytest.fixture(scope="module")
def sim():
    m = mujoco.MjModel.from_xml_path(str(A.arm_test_xml_path()))
    arm, cfg = A.arm_from_model(m), ArmConfig()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    oq = m.jnt_qposadr[m.joint("obj_free").id]
    obj, obj_geom = m.body("obj").id, m.geom("obj_geom").id
    q0 = jnp.asarray(d.qpos[arm.qpos_arm], jnp.float32)
    targets = jax.vmap(waypoint_targets)(jnp.asarray(XS), jnp.asarray(YS), jnp.asarray(MISS))
    ik = jax.jit(jax.vmap(lambda t: A.solve_ik_path(arm, cfg, t, q0)))(targets)
    b = len(XS)
    q_way = jnp.concatenate([jnp.broadcast_to(q0, (b, 1, 6)), ik.q[:, list(WAY)]], axis=1)
    o, c = cfg.grip_open, cfg.grip_closed
    grip_way = jnp.broadcast_to(jnp.array([0.06, o, o, o, c, c, c, c]), (b, len(SEG) + 1))

    mx, dx0 = mjx.put_model(m), mjx.put_data(m, d)
    data = jax.vmap(lambda x, y: dx0.replace(qpos=dx0.qpos.at[oq:oq + 3].set(jnp.stack([x, y, 0.04]))))(
        jnp.asarray(XS, jnp.float32), jnp.asarray(YS, jnp.float32))
    observe = lambda dd: (dd.xpos[obj], dd.site_xpos[arm.tcp_site],
                          A.finger_contacts(arm, cfg, dd, [obj_geom]))
    traced = chex.assert_max_traces(n=1)(
        lambda dd, qw, gw: jax.vmap(functools.partial(A.run_program, arm, mx, seg_steps=SEG,
                                                      observe=observe))(dd, qw, gw))
    run = jax.jit(traced)
    out, trace = run(data, q_way, grip_way)
    out2, _ = run(data, q_way + 0.0, grip_way)  # same shapes: no second trace
    return dict(m=m, arm=arm, cfg=cfg, ik=ik, targets=targets, q_way=q_way, grip_way=grip_way,
                out=out, out2=out2, trace=jax.device_get(trace), obj=obj, oq=oq)


@pytest.mark.slow  # compiles the arm's MJX world
def test_ik_waypoints_reachable(sim):
    assert np.asarray(sim["ik"].reachable).all()


@pytest.mark.slow  # compiles the arm's MJX world
def test_grasp_lifts_box_and_miss_holds_nothing(sim):
    obj_pos, _, touch = sim["trace"]
    ends = np.cumsum(SEG) - 1
    z = obj_pos[:, :, 2]
    grasp = MISS == 0
    assert np.all(z[:, ends[3]] < 0.045)  # still on the table after closing
    assert np.all(z[grasp, -1] - 0.04 > 0.10), z[:, -1]  # lifted (and still held after the tilt)
    assert np.all(touch[grasp, ends[3]])
    assert np.all(touch[grasp, -1])  # both pads on the box
    # the closed gripper beside the box: no contact, box never moved
    assert not touch[~grasp].any()
    np.testing.assert_allclose(obj_pos[~grasp, -1], np.c_[XS, YS, np.full(4, 0.04)][~grasp], atol=2e-3)


@pytest.mark.slow  # compiles the arm's MJX world
def test_arm_tracks_waypoints(sim):
    _, tcp, _ = sim["trace"]
    ends = np.cumsum(SEG) - 1
    targets = np.asarray(sim["targets"].pos)
    # unloaded, after a 0.2 s dwell: within 1 mm of the waypoint (at the end of the move
    # itself the servo lags by up to ~7 mm: programs dwell where precision matters)
    err_above = np.linalg.norm(tcp[:, ends[1]] - targets[:, 0], axis=-1)
    assert err_above.max() < 0.001, err_above
    miss = MISS > 0
    err_final = np.linalg.norm(tcp[:, -1] - targets[:, -1], axis=-1)
    assert err_final[miss].max() < 0.001, err_final
    # holding the 1 kg box tilted: gravity compensation covers the arm, not the payload
    assert err_final[~miss].max() < 0.015, err_final


@pytest.mark.slow  # compiles the arm's MJX world
def test_no_retrace_and_deterministic(sim):
    np.testing.assert_array_equal(np.asarray(sim["out"].qpos), np.asarray(sim["out2"].qpos))


@pytest.mark.slow  # compiles the arm's MJX world
def test_native_c_replay_agrees(sim):
    m, arm = sim["m"], sim["arm"]
    total = int(sum(SEG))
    ctrl_fn = jax.jit(jax.vmap(lambda qw, gw, t: A.program_ctrl(arm, qw, gw, SEG, t), in_axes=(None, None, 0)))
    out = sim["out"]
    for b in range(len(XS)):
        ctrl = np.asarray(ctrl_fn(sim["q_way"][b], sim["grip_way"][b], jnp.arange(total)))
        d = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d, 0)
        d.qpos[sim["oq"]:sim["oq"] + 3] = [XS[b], YS[b], 0.04]
        for t in range(total):
            d.ctrl[:] = ctrl[t]
            mujoco.mj_step(m, d)
        # MJX (float32) and C (float64) agree to a few mm after 825 steps with a grasp
        np.testing.assert_allclose(d.xpos[sim["obj"]], np.asarray(out.xpos[b, sim["obj"]]), atol=0.005)
        np.testing.assert_allclose(d.site_xpos[arm.tcp_site], np.asarray(out.site_xpos[b, arm.tcp_site]),
                                   atol=0.002)
        np.testing.assert_allclose(d.qpos[arm.qpos_arm], np.asarray(out.qpos[b, arm.qpos_arm]), atol=0.01)
