"""Motor programs v2: grasps that keep the palm off the objects, a squeeze from the
held weight, goals read at rest; v1 one ``--set`` away. Fast tests build v2's (and v1's)
programs without simulating; the slow ones replay the default programs (v4, which keeps
what v2 brought) in MuJoCo C and read the contacts (``native.forces``): they check what the
tool runs, with the session's batch-8 planner rather than one compiled per version."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.errors import UserError
from relaff_jax.sim import bodies, labels, planning, programs, templates
from relaff_jax.sim import objects as lib
from relaff_jax.sim import world as wd
from relaff_jax.config.action import ActionConfig

from helpers.scenes import replay_built

V2 = ActionConfig(programs="v2")  # pinned (v3, the default, is tested in test_programs_v3.py)
V1 = dataclasses.replace(V2, programs="v1")
DEFAULT = ActionConfig()  # the slow tests' programs (v4)


def quat(yaw):
    return [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]


def scene(w, toy, other, txyz, oxyz, oyaw=0.0):
    q = np.array(w.mj_model.qpos0, np.float32)[:14]
    q[0:7] = [*txyz, *quat(0.0)]
    q[7:14] = [*oxyz, *quat(oyaw)]
    return w.pair_id(toy, other), q


def prog(action, cfg, toy, other, txyz, oxyz):
    st = planning.setup(cfg)
    p, q = scene(st.world, toy, other, txyz, oxyz)
    return programs.program(action, st.arm, cfg, st.geo, jnp.int32(p), jnp.asarray(q)), st.arm


def palm_z(arm, pr, k=1):
    """Height of the palm's underside at target k (the grasp) of a top-down program."""
    return float(pr.targets.pos[k, 2]) - arm.tip_below_tcp + arm.palm_above_tip


def test_tall_obstacle_is_grasped_below_its_top_by_at_most_the_pads():
    for name in ("bottle", "cereal_box", "vase", "wall_panel"):
        top = lib.get(name).height
        p2, arm = prog("unobstruct", V2, "block", name, (0.9, 0.0, 0.0), (0.7, 0.0, 0.0))
        p1, _ = prog("unobstruct", V1, "block", name, (0.9, 0.0, 0.0), (0.7, 0.0, 0.0))
        assert abs(palm_z(arm, p2) - (top + V2.palm_margin)) < 1e-5, name  # palm 2 cm above its top
        assert palm_z(arm, p1) < top - 0.1, name  # v1: the palm lands 10+ cm below the top
        assert bool(p2.ok) and bool(p1.ok), name
    # a short obstacle keeps v1's grasp (fingertips 5 mm above its bottom)
    p2, _ = prog("unobstruct", V2, "block", "brick", (0.9, 0.3, 0.0), (0.7, 0.0, 0.0))
    p1, _ = prog("unobstruct", V1, "block", "brick", (0.9, 0.3, 0.0), (0.7, 0.0, 0.0))
    np.testing.assert_array_equal(np.asarray(p2.targets.pos), np.asarray(p1.targets.pos))


def test_toy_under_the_palm_refuses_or_raises_the_base_grasp():
    cup_h = lib.get("cup").height  # as a toy: a 10 cm block
    # cup in the middle of a tray: the palm would pin it -> refused in v2 (v1 plans it)
    p2, arm = prog("pour", V2, "cup", "tray", (0.7, 0.0, 0.02), (0.7, 0.0, 0.0))
    p1, _ = prog("pour", V1, "cup", "tray", (0.7, 0.0, 0.02), (0.7, 0.0, 0.0))
    assert not bool(p2.ok) and bool(p1.ok)
    assert palm_z(arm, p1) < 0.02 + cup_h  # the clamp of v1
    # the same cup 13 cm off the palm's footprint (along the tray's long side, away from the
    # pads): planned, with v1's grasp
    p2, _ = prog("pour", V2, "cup", "tray", (0.83, 0.0, 0.02), (0.7, 0.0, 0.0))
    p1, _ = prog("pour", V1, "cup", "tray", (0.83, 0.0, 0.02), (0.7, 0.0, 0.0))
    assert bool(p2.ok)
    np.testing.assert_array_equal(np.asarray(p2.targets.pos), np.asarray(p1.targets.pos))
    # 13 cm towards a pad instead: the pad would come down on the cup
    p2, _ = prog("pour", V2, "cup", "tray", (0.7, 0.13, 0.02), (0.7, 0.0, 0.0))
    assert not bool(p2.ok)
    # a 12 cm can in a 7 cm bowl: the grasp rises until the palm clears the can, the pads
    # still hold 2+ cm of the bowl
    floor = dict(lib.get("bowl").parts)["base"].size[2]
    p2, arm = prog("lift", V2, "toy_can", "bowl", (0.7, 0.0, floor), (0.7, 0.0, 0.0))
    assert bool(p2.ok)
    assert abs(palm_z(arm, p2) - (floor + 0.12 + V2.palm_margin)) < 1e-5
    tip = float(p2.targets.pos[1, 2]) - arm.tip_below_tcp
    assert lib.get("bowl").height - tip >= V2.min_grip - 1e-6


def test_take_pads_on_a_container_rim_are_refused():
    # a block against the bucket's wall: a pad would come down on the rim
    inner = lib.get("bucket").inner
    p2, _ = prog("take", V2, "block", "bucket", (0.7, inner[1] - 0.03, 0.01), (0.7, 0.0, 0.0))
    assert not bool(p2.ok)
    p2, _ = prog("take", V2, "block", "bucket", (0.7, 0.0, 0.01), (0.7, 0.0, 0.0))  # centred: fine
    assert bool(p2.ok)


def test_squeeze_command_hand_worked():
    arm = planning.setup(V2).arm
    # 60 g ball: 3 x 0.589 N / (2 x 1.5) = 0.59 N < 5 N minimum: command r - 5 / 1500
    np.testing.assert_allclose(float(bodies.squeeze_command(arm, V2, jnp.float32(0.035), jnp.float32(0.06))),
                               0.035 - 5.0 / 1500.0, rtol=1e-6)
    # 1.5 kg held: 3 x 14.7 / 3 = 14.7 N
    np.testing.assert_allclose(float(bodies.squeeze_command(arm, V2, jnp.float32(0.05), jnp.float32(1.5))),
                               0.05 - 1.5 * 9.81 / 1500.0, rtol=1e-5)
    p2, _ = prog("take", V2, "ball", "tray", (0.7, 0.1, 0.02), (0.7, 0.0, 0.0))
    p1, _ = prog("take", V1, "ball", "tray", (0.7, 0.1, 0.02), (0.7, 0.0, 0.0))
    assert float(p1.grip_closed) == 0.0 and abs(float(p2.grip_closed) - (0.035 - 5.0 / 1500.0)) < 1e-6


def test_read_at_rest_hand_worked():
    dt, speed, window = 0.004, 0.02, 3
    com = np.zeros((3 + 1 + 6, 2, 3))
    com[:, 0, 2] = [0.5, 0.4, 0.3, 0.2, 0.1, 0.05, 0.05, 0.05, 0.05, 0.05]  # falls, lands at index 5
    for xp in (np, jnp):
        i, ok = labels.read_at_rest(xp.asarray(com), window, speed, dt, xp)
        assert int(i) == 8 and bool(ok)  # 3 calm steps after the landing: 5->6, 6->7, 7->8
    i, ok = labels.read_at_rest(com[:4], window, speed, dt, np)  # hold 0: the measuring step
    assert int(i) == 3 and not bool(ok)
    still = np.zeros((10, 2, 3))
    i, ok = labels.read_at_rest(still, window, speed, dt, np)
    assert int(i) == 3 and bool(ok)
    moving = np.cumsum(np.full((10, 2, 3), 0.001), axis=0)  # 0.43 m/s throughout
    i, ok = labels.read_at_rest(moving, window, speed, dt, np)
    assert int(i) == 9 and not bool(ok)  # never at rest: the hold's last step, unsettled


@pytest.mark.parametrize("programs,window,hold", [("v1", 10, 0), ("v2", 10, 200), ("v2", 3, 12), ("v2", 1, 5)])
def test_rest_reader_equals_read_at_rest_per_scene(programs, window, hold):
    """The C executors' step-by-step reader (all scenes at once) gives every scene the read
    step, state and ``settled`` of ``labels.read_at_rest`` on its own collected steps, bit for
    bit, also where a run stops early (v2: once every scene is read)."""
    from types import SimpleNamespace
    from relaff_jax.sim.native.program import RestReader

    cfg = dataclasses.replace(V2, programs=programs, rest_window=window, rest_hold=hold)
    v2, measure, b = programs != "v1", 30, 40
    rng = np.random.default_rng(window + hold)
    speed = cfg.scene.rest_speed * cfg.phys.timestep
    # per scene: moves (steps around the threshold, ties included) until a random step, then still
    stop = rng.integers(measure - window - 2, measure + hold + 3, b)
    steps = rng.choice([0.0, 0.5, 1.0, 2.0], size=(b, 260, 2, 3)) * speed / np.sqrt(3)
    steps[np.arange(260)[None, :] >= stop[:, None]] = 0.0
    steps[::7, :, 1] = 0.0  # some scenes' other object never moves
    com = 0.3 + np.cumsum(steps, axis=1)
    qpos = rng.normal(size=(b, 260, 14)).astype(np.float32)
    reader = RestReader(cfg, SimpleNamespace(measure=measure, v2=v2))
    t_end = 259
    for t in range(260):
        reader.add(t, com[:, t], qpos[:, t])
        if v2 and reader.done:
            t_end = t
            break
    got_com, got_q, got_settled = reader.result()
    lo = measure - window
    for i in range(b):
        c = com[i, lo:min(t_end, lo + window + hold) + 1]
        j, ok = labels.read_at_rest(c, window, cfg.scene.rest_speed, cfg.phys.timestep, np)
        assert bool(got_settled[i]) == bool(ok) and reader.read_steps()[i] == lo + int(j)
        np.testing.assert_array_equal(got_com[i], c[int(j)])
        np.testing.assert_array_equal(got_q[i], qpos[i, lo + int(j)])
    assert got_settled.any() and (v2 or not got_settled.all() or hold == 0)


def test_versions_config_and_sidecar():
    assert "programs" not in templates.stored_config(V1)
    assert not set(templates.stored_config(V1)) & {"rest_hold", "palm_margin", "squeeze_min"}
    d = templates.stored_config(V2)
    assert d["programs"] == "v2" and d["rest_hold"] == V2.rest_hold
    with pytest.raises(UserError, match="action.programs"):
        ActionConfig(programs="v5")
    with pytest.raises(UserError, match="action.squeeze_max"):
        ActionConfig(squeeze_max=80.0)
    t1, t2 = templates.tables(V1), templates.tables(V2)
    assert t1.n_steps == templates.N_STEPS and t2.n_steps == templates.N_STEPS + V2.rest_hold
    np.testing.assert_array_equal(t2.steps.sum(axis=1), t2.n_steps)
    np.testing.assert_array_equal(templates.run_steps(V2), templates.run_steps(V1) + V2.rest_hold)


def _replay(action, cfg, rows):
    """Settle hand-built scenes in C, plan them (JAX) and measure their replay in C."""
    w = planning.setup(cfg).world
    return replay_built(action, cfg, [scene(w, *r) for r in rows])


@pytest.mark.slow  # plans 4 unobstructs and replays them in C
def test_tall_obstacles_without_a_palm_contact():
    from relaff_jax.sim.physics_bounds import press_ok

    # v1 put the palm 10+ cm below each top (test_tall_obstacle_is_grasped_below_its_top_by_at_most_the_pads)
    # and the palm pressed the bottle at 480-870 N (docs/arm.md); the default never touches them
    rows = [("block", name, (0.95, 0.0, 0.0), (0.75, 0.0, 0.0)) for name in ("bottle", "cereal_box", "vase", "wall_panel")]
    plan, r = _replay("unobstruct", DEFAULT, rows)
    assert plan["feasible"].all()
    assert np.all(r["palm"] == 0.0), r["palm"]  # the palm never touches an object
    assert np.all(press_ok(r["press"], r["weight"])), (r["press"], r["weight"])


@pytest.mark.slow  # plans and replays a pour in C
def test_toy_sliding_off_a_tilted_placemat_is_labelled_where_it_rests():
    # a cup beside the palm's footprint on a placemat: the tilt (60 deg) slides it off; since
    # v2 the program waits until it lies still on the table and reads pour there (not "retained")
    rows = [("cup", "placemat", (0.85, 0.0, 0.006), (0.7, 0.0, 0.0))]
    plan, r = _replay("pour", DEFAULT, rows)
    assert plan["feasible"].all()
    assert r["settled"].all()
    assert r["com_read"][0, 0, 2] < 0.06  # the cup (a 10 cm block) rests on the table
    assert r["com_read"][0, 1, 2] > 0.15  # the placemat is still held up
    assert not r["label"][0]


# The bounds v2 brought and the default keeps (sim/physics_bounds.py, the audit's; docs/arm.md,
# "Bounded forces"), checked on sampled scenes in C
@pytest.mark.slow  # settles, plans and replays 16 scenes per action in C
@pytest.mark.parametrize("action", ["lift", "unobstruct"])
def test_forces_and_penetration_within_bounds(action):
    from relaff_jax.sim import rollouts
    from relaff_jax.sim.native import forces as native_forces
    from relaff_jax.sim.physics_bounds import PALM_CONTACT_STEPS, PENETRATION_M, press_ok

    # 16 scenes in two batches of 8: the place, screen and plan programs of batch 8 are the
    # session's (the tiny preset's batch), not compiled again for 16
    prepare = rollouts.make_batch_prepare_fn(action, DEFAULT, settle="native")
    preps = [prepare(jax.random.fold_in(jax.random.PRNGKey(3), i), 8) for i in range(2)]
    feasible = np.concatenate([p.plan.feasible for p in preps])
    run = np.flatnonzero(feasible)
    assert len(run) >= 4
    plan = {k: np.concatenate([np.asarray(getattr(p.plan, k)) for p in preps])[run]
            for k in ("q_way", "grip_way", "feasible", "direction")}
    pair = np.concatenate([p.pair for p in preps])[run]
    qpos = np.concatenate([np.asarray(p.scenes.qpos) for p in preps])[run]
    qvel = np.concatenate([np.asarray(p.scenes.qvel) for p in preps])[run]
    r = native_forces.physics(action, DEFAULT, pair, qpos, qvel, plan)
    assert np.all(r["palm_steps"] <= PALM_CONTACT_STEPS) and np.all(r["palm"] == 0.0), r["palm"]
    assert np.all(press_ok(r["press"], r["weight"])), (r["press"], r["weight"])
    assert np.all(r["depth"] <= PENETRATION_M), r["depth"]


def _surface_falls_towards(pr, d):
    """Does the grasped base's surface, held at the tilt target (the last), fall towards the
    horizontal direction d? Its normal is minus the tool's z (the tcp's approach axis)."""
    normal = -np.asarray(pr.targets.approach[-1])
    return float(np.dot(normal[:2], np.asarray(d)[:2])) > 0


@pytest.mark.parametrize("action", ["pour", "slide"])
def test_tilt_lowers_the_side_the_toy_stands_on(action):
    # a cup 13 cm along a tray's long side from the grasp, on the robot's side and on the
    # far side: v2 (tilt_lean="toy") lowers the cup's side in both, so a sliding cup leaves
    # the hand; "robot" (v1's lean) lowers the far side whatever the cup, so the near cup
    # slides back under the palm
    robot = dataclasses.replace(V2, tilt_lean="robot")
    for x, towards in ((0.57, -1.0), (0.83, 1.0)):
        rows = ("cup", "tray", (x, 0.0, 0.02), (0.7, 0.0, 0.0))
        p_toy, _ = prog(action, V2, *rows)
        p_rob, _ = prog(action, robot, *rows)
        p_v1, _ = prog(action, V1, *rows)
        assert bool(p_toy.ok)
        assert _surface_falls_towards(p_toy, (towards, 0.0))
        assert _surface_falls_towards(p_rob, (1.0, 0.0))  # away from the robot at the origin
        np.testing.assert_array_equal(np.asarray(p_rob.targets.pos), np.asarray(p_v1.targets.pos))
        np.testing.assert_array_equal(np.asarray(p_rob.targets.approach), np.asarray(p_v1.targets.approach))


def test_tilted_base_grasp_clears_a_tipping_toy():
    # a 12 cm can (6.5 cm square) in a bowl: lift's palm clears its top by palm_margin; pour's
    # (tilt_sweep) clears its diagonal, the height it reaches tipping over about a bottom
    # edge, sqrt(0.12^2 + 0.065^2) = 0.1365 m, or the grasp is refused
    floor = dict(lib.get("bowl").parts)["base"].size[2]
    rows = ("toy_can", "bowl", (0.7, 0.0, floor), (0.7, 0.0, 0.0))
    lift, arm = prog("lift", V2, *rows)
    pour, _ = prog("pour", V2, *rows)
    flat, _ = prog("pour", dataclasses.replace(V2, tilt_sweep=False), *rows)
    diag = float(np.hypot(0.12, 0.065))
    assert bool(lift.ok) and bool(flat.ok)
    np.testing.assert_allclose(palm_z(arm, flat), palm_z(arm, lift), atol=1e-6)
    if bool(pour.ok):
        np.testing.assert_allclose(palm_z(arm, pour) - palm_z(arm, lift), diag - 0.12, atol=1e-5)
    else:  # the pads would hold less than min_grip of the bowl
        assert lib.get("bowl").height - (palm_z(arm, lift) + diag - 0.12 - arm.palm_above_tip) < V2.min_grip
    # a ball rolls: its height is all the palm clears
    ball, _ = prog("pour", V2, "ball", "bowl", (0.7, 0.0, floor), (0.7, 0.0, 0.0))
    ball_lift, _ = prog("lift", V2, "ball", "bowl", (0.7, 0.0, floor), (0.7, 0.0, 0.0))
    np.testing.assert_allclose(palm_z(arm, ball), palm_z(arm, ball_lift), atol=1e-6)


def test_press_floor_covers_the_least_squeeze():
    from relaff_jax.sim.physics_bounds import PRESS_FLOOR_N, PRESS_WEIGHTS, press_ok

    # two pads at the least squeeze on a 100 g pair: 10 N is 10.2 weights, within the floor
    assert PRESS_FLOOR_N >= 2 * V2.squeeze_min
    w = 0.1 * 9.81
    assert 2 * V2.squeeze_min > PRESS_WEIGHTS * w and press_ok(2 * V2.squeeze_min + w, w)
    # above both: refused; a heavy pair's 10 weights: within
    assert not press_ok(PRESS_FLOOR_N + 0.1, w)
    np.testing.assert_array_equal(press_ok(np.array([30.0, 30.0]), np.array([2.9, 3.1])), [False, True])


def test_rake_keeps_the_fingertips_above_the_table_and_squeezes_the_handle_lightly():
    # the tcp holds the handle's centre line, 1.25 cm above its underside; the pads reach 2 cm
    # below the tcp: at v1's low point (head 3 mm up) the fingertips are 4.5 mm in the table
    held = tuple(float(v) for v in wd.PhysicsConfig().held_rake_pos)
    low = {}
    for name, cfg in (("v1", V1), ("v2", V2)):
        pr, arm = prog("rake", cfg, "block", "rake_short", (0.9, 0.3, 0.03), held)
        low[name] = float(pr.targets.pos[1, 2]) - arm.tip_below_tcp  # fingertips at the low point
        if name == "v2":
            assert float(pr.grip_closed) == pytest.approx(bodies.tool_squeeze(arm, cfg))
    assert low["v1"] == pytest.approx(-0.0045, abs=1e-4)
    assert low["v2"] == pytest.approx(V2.tip_clearance, abs=1e-4)
    st = planning.setup(V2)
    # the held tool's pads push at most squeeze_min (kp x (half - command)); v1 the actuator's command
    assert st.arm.finger_kp * (bodies.HANDLE_HALF - bodies.tool_squeeze(st.arm, V2)) == pytest.approx(V2.squeeze_min)
    assert bodies.tool_squeeze(st.arm, V1) == V1.arm.grip_closed
    assert planning.home_grip(V2)[list(templates.ACTIONS).index("rake")] == np.float32(bodies.tool_squeeze(st.arm, V2))


def test_move_sweeps_over_a_top_at_the_palm_height():
    # fingertips 1 cm above the table put the palm's underside 12 cm up: a 12 cm can's top is
    # there, so the hand rises until the palm is palm_margin above it; a ball's is far below
    base = V2.tip_clearance + 0.005 + planning.setup(V2).arm.tip_below_tcp
    can, arm = prog("move", V2, "toy_can", "placemat", (0.7, 0.1, 0.0), (0.7, -0.25, 0.0))
    ball, _ = prog("move", V2, "ball", "placemat", (0.7, 0.1, 0.0), (0.7, -0.25, 0.0))
    assert float(ball.targets.pos[2, 2]) == pytest.approx(base, abs=1e-6)
    palm = float(can.targets.pos[2, 2]) - arm.tip_below_tcp + arm.palm_above_tip
    st = planning.setup(V2)
    p, q = scene(st.world, "toy_can", "placemat", (0.7, 0.1, 0.0), (0.7, -0.25, 0.0))
    top = float(bodies.bodies(st.geo, jnp.int32(p), jnp.asarray(q))[0].z_range()[1])
    assert abs(top - (base - arm.tip_below_tcp + arm.palm_above_tip)) < V2.palm_margin  # the case the rule is for
    assert palm == pytest.approx(top + V2.palm_margin, abs=1e-5)
