"""The nine actions on hand-built scenes whose outcome is obvious, at batch 8 (one compile
serves every action), and a MuJoCo C replay of some of them."""
import jax
import mujoco
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.cli import sim as cli_sim
from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.errors import UserError
from relaff_jax.sim import bodies, geometry, labels, planning, programs, rollouts, templates
from relaff_jax.sim.native import reference as native
from relaff_jax.sim import scenes as sc

from helpers.scenes import BASE_ROWS, OBST_ROWS, RAKE_ROWS, hand_built, quat

B = 8


# Obvious outcomes: True / False per scene, None where physics may go either way.
T, F, _ = True, False, None
EXPECT = {
    "lift": [T, T, F, T, F, T, F, F],
    # take row 0: the pads (10 cm apart) come down outside the 9 cm cup and lift it, block
    # and all: the pair is lifted, the toy is not taken
    "take": [F, T, T, _, F, T, T, _],
    "pour": [T, F, F, T, F, _, F, F],
    "slide": [F, T, F, F, F, _, F, F],
    "pull": [T, T, F, T, F, T, F, F],
    "push": [T, T, F, T, F, _, F, F],
    "move": [F, F, T, F, F, F, T, T],
    "unobstruct": [T, F, F, F] * 2,
    # rake row 3: the block 0.3 m out; v3 refuses it at plan time (the hand's pull line passes
    # 6.4 cm from the base axis; v2 pulled it 10 cm closer, v1's fingertips jammed the pull)
    "rake": [T, _, F, F] * 2,
}


@pytest.fixture(scope="module")
def scenes(scene_world, settle):
    out = {}
    for name, rows in (("base", BASE_ROWS), ("obst", OBST_ROWS), ("rake", RAKE_ROWS)):
        pair, qpos0 = hand_built(scene_world, rows)
        s = jax.device_get(settle(pair, qpos0, jnp.zeros(B, jnp.int32)))
        out[name] = (np.asarray(pair), s)
    rel = [sc.RELATIONS[r] for r in out["base"][1].relation]
    assert rel == ["inside", "on_top", "beside", "inside", "beside", "on_top", "beside", "beside"]
    return out


@pytest.fixture(scope="module")
def results(scenes):
    act = rollouts.jitted_action_fn()
    res = {}
    for action in ACTIONS:
        kind = {"unobstruct": "obst", "rake": "rake"}.get(action, "base")
        pair, s = scenes[kind]
        res[action] = jax.device_get(act(action_id(action), jnp.asarray(pair), jnp.asarray(s.qpos),
                                         jnp.asarray(s.qvel)))
    return res


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
@pytest.mark.parametrize("action", ACTIONS)
def test_obvious_outcomes(results, action):
    got = results[action]["label"]
    for i, want in enumerate(EXPECT[action]):
        if want is not None:
            assert got[i] == want, (action, i, got, results[action]["feasible"])
    assert got.dtype == bool
    assert got.shape == (B,)


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_mjx_stops_at_the_program_end(results):
    """The tuned default stops each program at its measuring step: the scan's later steps hold
    the state, so the end equals the measuring step bit for bit in every action (it would not
    if the held steps were simulated: the drags release and retreat after it, and lift's
    objects still settle in the grip)."""
    assert templates.ActionConfig().stop_at_program_end
    for action in ACTIONS:
        np.testing.assert_array_equal(results[action]["com_end"], results[action]["com_m"], err_msg=action)


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_infeasible_programs_do_not_move_the_arm(results):
    # base row 4: the toy 1.55 m away cannot be grasped; the arm stays home, nothing moves
    r = results["take"]
    assert not r["feasible"][4]
    assert r["feasible"][[0, 1, 2, 3, 5, 6, 7]].all()
    np.testing.assert_allclose(r["com_end"][4], r["com0"][4], atol=2e-3)
    assert not results["rake"]["feasible"][2] and not results["rake"]["feasible"][3]  # far; the axis rule


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_lift_raises_both_and_release_after_drag(results):
    lift = results["lift"]
    assert np.all(lift["com_m"][[0, 3], :, 2] - lift["com0"][[0, 3], :, 2] > 0.15)  # cup/bowl and toy
    pull = results["pull"]
    # pull ends with the gripper open: the base is back on the table, closer to the robot
    r0 = np.linalg.norm(pull["com0"][0, 1, :2])
    r1 = np.linalg.norm(pull["com_end"][0, 1, :2])
    assert r0 - r1 > 0.15
    assert abs(pull["com_end"][0, 1, 2] - pull["com0"][0, 1, 2]) < 0.01


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_unobstruct_reachability(results):
    r = results["unobstruct"]
    assert not r["reach_before"][0]
    assert r["reach_after"][0]  # the brick blocked the way, then not
    assert r["reach_before"][1]
    assert r["reach_before"][3]  # nothing in the way: no affordance
    assert not r["reach_before"][2]
    assert not r["reach_after"][2]  # out of the arm's reach


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_toy_is_only_moved_by_contacts(results):
    # the actions that never touch the toy directly leave a toy beside the base where it was
    for action in ("lift", "pull", "push", "pour", "slide"):
        r = results[action]
        np.testing.assert_allclose(r["com_end"][7, 0], r["com0"][7, 0], atol=2e-3)


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
@pytest.mark.parametrize("action", ["lift", "slide", "pull", "take"])
def test_native_replay_agrees(scenes, results, action):
    pair, s = scenes["base"]
    idx = [0, 1, 2]
    nat = native.replay_native(action, templates.ActionConfig(), pair[idx], np.asarray(s.qpos)[idx],
                           np.asarray(s.qvel)[idx], {k: v[idx] for k, v in results[action].items()})
    np.testing.assert_array_equal(nat["label"], results[action]["label"][idx])
    # the grasped object follows the same path; a toy that slides off and falls may land
    # elsewhere (chaotic), so only the labels are compared for it
    np.testing.assert_allclose(nat["com_m"][:, 1], results[action]["com_m"][idx, 1], atol=0.01)


@pytest.mark.slow  # compiles and runs the nine programs in MJX (~2 min)
def test_rollout_fn_simulates_only_feasible_programs(scene_world):
    """The dataset path skips infeasible programs; its labels equal running every scene."""
    key = jax.random.PRNGKey(11)
    out = rollouts.make_rollout_fn("lift", B, sim_batch=B)(key, B)  # programs shared with `results`
    # the same scenes, rebuilt with the public scene functions, every program executed
    kp, ks, _ = jax.random.split(key, 3)
    place, settle, _ = sc.jitted_scene_fns(scene_world)
    pair = sc.sample_pairs(kp, rollouts.allowed_pairs(scene_world, "lift"), scene_world, B)
    s = settle(pair, *place(ks, pair))
    full = jax.device_get(rollouts.jitted_action_fn()(action_id("lift"), pair, s.qpos, s.qvel))
    np.testing.assert_array_equal(out["pair"], np.asarray(pair))
    np.testing.assert_array_equal(out["feasible"], full["feasible"])
    sim, skip = out["simulated"], ~out["simulated"]
    assert sim.any(), out["feasible"]
    assert skip.any(), out["feasible"]  # both kinds in this batch
    np.testing.assert_array_equal(sim, out["feasible"])
    np.testing.assert_array_equal(out["label"], full["label"])
    np.testing.assert_allclose(out["qpos_final"][sim], full["qpos_final"][sim], atol=1e-4)
    # a skipped program would have left the objects where they settled
    assert not out["label"][skip].any()
    np.testing.assert_allclose(full["com_end"][skip], full["com0"][skip], atol=2e-3)
    np.testing.assert_allclose(out["qpos_final"][skip], out["qpos_settled"][skip])
    with pytest.raises(ValueError, match="sim_batch must be >= 1"):
        rollouts.make_rollout_fn("lift", 4, sim_batch=0)


def test_rollout_fn_fields_and_errors():
    with pytest.raises(ValueError, match="unknown action 'fly'"):
        rollouts.make_rollout_fn("fly", 4)
    with pytest.raises(ValueError, match="batch must be >= 1"):
        rollouts.make_rollout_fn("lift", 0)
    assert set(ACTIONS) == set(templates.TEMPLATES)
    assert len(ACTIONS) == 9
    for a, tpl in templates.TEMPLATES.items():
        assert sum(tpl.seg_steps) == templates.N_STEPS, a
        assert len(tpl.seg_steps) == templates.N_SEGMENTS, a


def test_cli_generate_bad_input(tmp_path):
    import argparse

    import re

    parser = argparse.ArgumentParser()
    cli_sim.register(parser.add_subparsers())
    (tmp_path / "file").write_text("x")
    for argv, msg in ((["generate", "fly", "--samples", "10", "--out", str(tmp_path / "a")], "unknown action 'fly'"),
                      (["generate", "lift", "--samples", "1", "--out", str(tmp_path / "b")], "config key '--samples (dataset.n_samples)' must be an integer in [2, "),
                      (["generate", "lift", "--samples", "8", "--batch", "0", "--out", str(tmp_path / "c")],
                       "config key '--batch (dataset.rollout_batch)' must be an integer in [1, "),
                      # checked before any simulation: a file, or a folder below a file
                      (["generate", "take", "--samples", "8", "--out", str(tmp_path / "file")], "is a file, not a folder"),
                      (["generate", "take", "--samples", "8", "--out", str(tmp_path / "file" / "d")],
                       "is a file, so no folder can be made under it")):
        args = parser.parse_args(argv)
        with pytest.raises(UserError, match=re.escape(msg)):
            args.func(args)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing half-written


def test_exit_distance_hand_worked():
    # a 40 x 20 cm box at the origin; walking from p along -d until outside the box grown by m
    box = lambda yaw: bodies.Body(jnp.zeros(3), geometry.quat_to_mat(jnp.asarray(quat(yaw), jnp.float32)),
                              jnp.array([-0.2, -0.1, 0.0]), jnp.array([0.2, 0.1, 0.02]))
    ex = lambda p, d, b, m: float(programs.exit_distance(jnp.asarray(p), jnp.asarray(d), b, m))
    np.testing.assert_allclose(ex([0.1, 0.0, 0.0], [1.0, 0.0, 0.0], box(0.0), 0.03), 0.33, atol=1e-6)
    np.testing.assert_allclose(ex([0.1, 0.0, 0.0], [0.0, -1.0, 0.0], box(0.0), 0.0), 0.1, atol=1e-6)
    np.testing.assert_allclose(ex([0.0, 0.1, 0.0], [0.0, -1.0, 0.0], box(np.pi / 2), 0.0), 0.1, atol=1e-5)
    assert ex([0.5, 0.0, 0.0], [1.0, 0.0, 0.0], box(0.0), 0.03) == 0.0  # already on free table
    # diagonal walk from the centre: leaves through the nearer face (y = 0.1 at s = 0.1 * sqrt 2)
    d = np.array([-1.0, -1.0, 0.0]) / np.sqrt(2)
    np.testing.assert_allclose(ex([0.0, 0.0, 0.0], d, box(0.0), 0.0), 0.1 * np.sqrt(2), atol=1e-6)


def test_move_and_take_rules_hand_worked():
    d = jnp.array([1.0, 0.0, 0.0])
    com0 = jnp.array([[0.8, 0.0, 0.03], [0.8, 0.3, 0.01]])

    def label(action, shift_toy, shift_oth, **kw):
        end = com0 + jnp.stack([jnp.asarray(shift_toy), jnp.asarray(shift_oth)])
        o = labels.Outcome(com0, end, end, d, jnp.asarray(False), jnp.asarray(False))
        return bool(labels.goals(templates.ActionConfig(**kw), o)[action_id(action)])

    assert label("move", [0.2, 0, 0], [0, 0, 0])  # swept away from the base
    assert not label("move", [0.2, 0, 0], [0.2, 0, 0])  # pushed along with its container
    assert label("move", [0.2, 0, 0], [0.2, 0, 0], move_rule="both")  # the literal rule
    assert not label("move", [0.05, 0, 0], [0, 0, 0])  # below the 8 cm threshold
    assert label("take", [0, 0, 0.2], [0, 0, 0])
    assert not label("take", [0, 0, 0.2], [0, 0, 0.2])  # lifted with its container: not taken
    with pytest.raises(ValueError, match="config key 'action.move_rule' must be one of apart, both, got 'sideways'"):  # the node refuses it
        label("move", [0.2, 0, 0], [0, 0, 0], move_rule="sideways")


def test_grasp_needs_the_pads_faces_mjx_and_c():
    """Hand-worked contacts: a pad counts only with a normal near its closing axis (its local
    y), in the MJX rule (arm.finger_contacts) and the C replay's rule (_both_pads) alike."""
    from types import SimpleNamespace as NS
    from relaff_jax.sim import arm as A

    m = mujoco.MjModel.from_xml_path(str(A.arm_test_xml_path()))
    arm, cfg = A.arm_from_model(m), templates.ActionConfig()
    pl, pr = (int(g) for g in arm.pad_geoms)
    obj = m.geom("obj_geom").id
    xmat = np.tile(np.eye(3), (m.ngeom, 1, 1))  # every geom axis-aligned: closing axis = world y
    side, top = np.eye(3)[[1, 0, 2]], np.eye(3)[[2, 0, 1]]  # contact frames, normal first row
    tilted = np.array([[0.0, 0.6, 0.8], [1, 0, 0], [0, 0.8, -0.6]])  # |n.y| = 0.6 < 0.7
    cases = [  # (frames of the contacts pad_l-obj, pad_r-obj), both pads held?
        ((side, side), True), ((side, top), False), ((top, top), False), ((side, tilted), False),
    ]
    for (fl, fr), want in cases:
        frames = np.stack([fl, fr])
        dx = NS(_impl=NS(contact=NS(geom=jnp.array([[pl, obj], [obj, pr]]), dist=jnp.array([0.0, -0.001]),
                                    frame=jnp.asarray(frames))), geom_xmat=jnp.asarray(xmat))
        assert bool(jnp.all(A.finger_contacts(arm, cfg.arm, dx, [obj]))) == want
        cons = NS(geom=np.array([[pl, obj], [obj, pr]]), dist=np.array([0.0, -0.001]),  # MjData's contact arrays
                  frame=np.stack([fl.reshape(-1), fr.reshape(-1)]))
        d = NS(contact=cons, ncon=2, geom_xmat=xmat.reshape(m.ngeom, 9))
        assert native.both_pads(d, arm, cfg, {obj}) == want
    # far contacts do not count, whatever their normal
    dx = NS(_impl=NS(contact=NS(geom=jnp.array([[pl, obj], [pr, obj]]), dist=jnp.array([0.0, 0.01]),
                                frame=jnp.asarray(np.stack([side, side])))), geom_xmat=jnp.asarray(xmat))
    assert A.finger_contacts(arm, cfg.arm, dx, [obj]).tolist() == [True, False]


def test_programs_on_hand_built_scenes():
    """The motor programs' tcp targets, one scene at a time, without simulating: lift grasps
    the base (the pair is lifted), take the toy; pull drags towards the robot, push away;
    every target finite, padded to N_TARGETS (fast tier: no MJX step is compiled)."""
    cfg = templates.ActionConfig()
    st = planning.setup(cfg)
    pair, qpos = hand_built(st.world, BASE_ROWS[1:2])  # block on a tray at (0.7, -0.3), yaw 0.2
    p, q = pair[0], qpos[0][:14]
    progs = {a: programs.program(a, st.arm, cfg, st.geo, p, q) for a in
             ("lift", "take", "pull", "push", "pour", "slide", "move")}
    for a, prog in progs.items():
        assert prog.targets.pos.shape == (templates.N_TARGETS, 3), a
        assert bool(jnp.isfinite(prog.targets.pos).all()), a
    toy, oth = bodies.bodies(st.geo, p, q)

    def passes_over(prog, xy):
        return float(jnp.min(jnp.linalg.norm(prog.targets.pos[:, :2] - xy, axis=1))) < 0.01

    assert passes_over(progs["lift"], oth.centre[:2])
    assert passes_over(progs["take"], toy.centre[:2])
    radial = np.asarray(oth.centre[:2]) / np.linalg.norm(np.asarray(oth.centre[:2]))
    np.testing.assert_allclose(np.asarray(progs["pull"].direction[:2]), -radial, atol=1e-6)
    np.testing.assert_allclose(np.asarray(progs["push"].direction[:2]), radial, atol=1e-6)
    with pytest.raises(ValueError, match="unknown action"):
        programs.program("fly", st.arm, cfg, st.geo, p, q)
