"""The reach screen (sim/reach_screen.py): its bound against the arm's own kinematics (MuJoCo C)
and the screened plan against the unscreened one, field by field."""
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.sim import arm as A
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim.native import settle as native_settle
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd
from relaff_jax.sim.planning import Plan, setup
from relaff_jax.sim.reach_screen import beyond_reach, jitted_screen_fn, prepare_screened, reach_bound
from relaff_jax.sim.simulate import make_prepare_fn

CFG = templates.ActionConfig()
B = 8  # scenes per batch: the tiny preset's, whose compiled programs the session shares


@pytest.fixture(scope="module")
def arm():
    return setup(CFG).arm


def test_bound_by_hand(arm):
    # the arm of docs/arm.md: shoulder 0.40 m up, upper arm 0.62 m, forearm 0.60 m, tcp 0.19 m
    # from the wrist centre along the approach; tolerances 5 mm and 0.05 rad, margins 2 mm, 2 mrad
    b = reach_bound(arm, CFG.arm)
    np.testing.assert_allclose(b.shoulder, [0.0, 0.0, 0.40], atol=1e-12)
    assert b.lever == pytest.approx(0.19, abs=1e-12)
    turn = 2 * np.sin((0.05 + 2e-3) / 2)
    assert b.base == pytest.approx(0.62 + 0.60 + 0.19 * turn + 0.005 + 0.002, abs=1e-12)


def _targets(pos, approach):
    n = len(pos)
    return A.IKTarget(jnp.asarray(pos, jnp.float32), jnp.asarray(approach, jnp.float32),
                      jnp.tile(jnp.array([0.0, 1.0, 0.0]), (n, 1)), jnp.zeros(n), jnp.zeros(n))


def test_no_reachable_pose_is_screened(arm):
    """Poses the arm reaches (MuJoCo C's forward kinematics at random q), moved by up to the
    tolerances in position and approach, are never screened; the bound is tight: poses at full
    stretch come within 3 cm of it, and the same poses pushed 5 cm beyond it are screened."""
    m = setup(CFG).world.mj_model  # the action world the plans use
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    qs = rng.uniform(arm.q_lo, arm.q_hi, (3000, 6))
    qs[:1000, 2] = rng.uniform(-0.05, 0.05, 1000)  # elbow straight: the edge of the workspace
    pos, app = [], []
    for q in qs:
        d.qpos[arm.qpos_arm] = q
        mujoco.mj_kinematics(m, d)
        pos.append(d.site_xpos[arm.tcp_site].copy())
        app.append(d.site_xmat[arm.tcp_site].reshape(3, 3)[:, 2].copy())
    pos, app = np.asarray(pos), np.asarray(app)
    # within tolerance: 4.9 mm away, the approach tilted by 0.049 rad about a random axis
    step = rng.normal(size=pos.shape)
    pos_t = pos + 0.0049 * step / np.linalg.norm(step, axis=1, keepdims=True)
    side = np.cross(app, rng.normal(size=app.shape))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    app_t = np.cos(0.049) * app + np.sin(0.049) * side
    b = reach_bound(arm, CFG.arm)
    far = jax.jit(jax.vmap(lambda t: beyond_reach(b, t)))
    assert not np.asarray(far(_targets(pos_t, app_t))).any()
    c = np.linalg.norm(pos - b.lever * app - b.shoulder, axis=1)
    assert c.max() > b.base - 0.03  # tight, not vacuous
    out = b.shoulder + (pos - b.lever * app - b.shoulder) * ((b.base + 0.05) / c)[:, None] + b.lever * app
    assert np.asarray(far(_targets(out, app))).all()


@pytest.mark.slow  # plans 9 x 64 scenes (the programs at batch 8 are the session's: generate's)
def test_screened_plan_equals_plan():
    """Every action, 64 scenes in 8 batches of 8: the screened plan equals the unscreened plan
    of ``make_prepare_fn`` compiled as one program in every field but ``ik_error`` (NaN where
    screened); the screened scenes are infeasible in the full plan. Unobstruct's scenes include
    all three kinds: program and toy, program only (toy beyond reach), toy only (program beyond
    reach). The generation's unscreened prepare (``jitted_stage_fns``: the screen's programs,
    their plan and the toy's reach, each a program of its own) equals the one program in every
    field. Batches of 8 (the tiny
    preset's, tests/sim/test_actions.py's) reuse the session's compiled place, plan and screen
    programs instead of compiling them for 64 scenes."""
    sw = wd.build_world(CFG.phys)
    place_fn, _, _ = sc.jitted_scene_fns(sw, CFG.scene)
    prep = jax.jit(make_prepare_fn(CFG))  # the reference: plan and toy reach in one program
    parts = rollouts.jitted_stage_fns(CFG)[0]
    screened = 0
    for action in ACTIONS:
        aid = action_id(action)
        kinds = []
        for c in range(8):
            kp, ks = jax.random.split(rollouts.bench_batch_key(0, B, c))[:2]
            pair = sc.sample_pairs(kp, rollouts.allowed_pairs(sw, action), sw, B)
            qpos0, intended = jax.device_get(place_fn(ks, pair))
            pair = np.asarray(pair)
            q = np.asarray(native_settle.settle_batch(sw, pair, qpos0, intended, CFG.scene, 2).qpos, np.float32)
            ref, ref_before = jax.device_get(prep(aid, jnp.asarray(pair), jnp.asarray(q)))
            got, before = prepare_screened(CFG, aid, pair, q)
            whole, whole_before = jax.device_get(parts(aid, jnp.asarray(pair), jnp.asarray(q)))
            for f in Plan._fields:
                np.testing.assert_array_equal(np.asarray(getattr(whole, f)), np.asarray(getattr(ref, f)),
                                              err_msg=f"{action} {f}, unscreened")
            np.testing.assert_array_equal(whole_before, ref_before)
            skip = np.isnan(got.ik_error)
            for f in ("q_way", "grip_way", "seg_steps", "feasible", "direction"):
                a, g = np.asarray(getattr(ref, f)), np.asarray(getattr(got, f))
                assert a.dtype == g.dtype and a.shape == g.shape, (action, f)
                np.testing.assert_array_equal(g, a, err_msg=f"{action} {f}")
            np.testing.assert_array_equal(got.ik_error[~skip], np.asarray(ref.ik_error)[~skip])
            np.testing.assert_array_equal(before, ref_before)
            assert not np.asarray(ref.feasible)[skip].any()
            kinds.append(skip)
            if action == "unobstruct":
                far, toy_far = jax.device_get(jitted_screen_fn(CFG)(aid, jnp.asarray(pair), jnp.asarray(q)))[:2]
                kinds[-1] = np.stack([far, toy_far])
                np.testing.assert_array_equal(skip, far)
        if action == "unobstruct":
            far, toy_far = np.concatenate(kinds, axis=1)
            assert (~far & ~toy_far).any() and (~far & toy_far).any() and (far & ~toy_far).any()
            skip = far
        else:
            skip = np.concatenate(kinds)
        assert (~skip).any(), action
        screened += skip.sum()
    assert screened > 0.25 * 64 * len(ACTIONS)  # about half the scenes are beyond reach


def test_stored_config_records_the_screen_only_when_off():
    """Datasets written before the screen stay resumable: the default is recorded by absence."""
    import dataclasses

    from relaff_jax.errors import UserError

    assert "reach_screen" not in templates.stored_config(CFG)["arm"]
    off = dataclasses.replace(CFG, arm=dataclasses.replace(CFG.arm, reach_screen=False))
    assert templates.stored_config(off)["arm"]["reach_screen"] is False
    with pytest.raises(UserError, match="action.arm.reach_screen"):
        dataclasses.replace(CFG.arm, reach_screen="yes")
