"""Motor programs v4: the arm at rest above the objects before every descent (the tables), the
pads' footprint grown by ``bodies.PAD_MARGIN``, the palm clear of the tipping reach of a toy
a base grasp pushes across, and move's fingertips over a low base the sweep crosses. Fast tests
on the tables and on hand-built scenes (``programs.program``, no simulation); v3's plans are
pinned in ``test_programs_v3.py``."""
import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.sim import bodies, guard, pad_sweep, planning, programs, sweep
from relaff_jax.sim import objects as lib
from relaff_jax.sim.actions.tables import DESCENT_DWELL, RAKE_DWELL, TOOL_TRANSIT, run_steps, tables

from helpers.scenes import posed as scene, posed_program as prog

V3 = ActionConfig(programs="v3")
V4 = dataclasses.replace(V3, programs="v4")


def test_v4_holds_the_first_waypoint_before_every_descent():
    t3, t4 = tables(V3), tables(V4)
    assert t4.steps.shape[1] == t3.steps.shape[1] + 1  # one segment more: the dwell
    assert (t4.steps.sum(axis=1) == t4.n_steps).all() and t4.hold == t3.hold
    for a, name in enumerate(ACTIONS):
        n = int(np.count_nonzero(t3.steps[a] > 1))  # the declared segments (the padding is 1-step dwells)
        if name == "rake":  # v3's dwell already; the held tool's transit TOOL_TRANSIT long, then v3's segments
            assert t3.steps[a][0] == 150 and t4.steps[a][0] == TOOL_TRANSIT
            np.testing.assert_array_equal(t4.steps[a][1:n - 1], t3.steps[a][1:n - 1])
            np.testing.assert_array_equal(t4.target[a][:n], t3.target[a][:n])
            assert t4.measure[a] == t3.measure[a] + TOOL_TRANSIT - 150
            continue
        # the transit as in v3, then DESCENT_DWELL steps at waypoint 0 with the same fingers
        assert t4.steps[a][0] == t3.steps[a][0] and t4.steps[a][1] == DESCENT_DWELL, name
        assert t4.target[a][:2].tolist() == [0, 0] and t4.closed[a][1] == t4.closed[a][0], name
        # then v3's segments, each as long, the measuring step DESCENT_DWELL later
        np.testing.assert_array_equal(t4.steps[a][2:n], t3.steps[a][1:n - 1])
        np.testing.assert_array_equal(t4.target[a][2:n + 1], t3.target[a][1:n])
        np.testing.assert_array_equal(t4.closed[a][2:n + 1], t3.closed[a][1:n])
        assert t4.measure[a] == t3.measure[a] + DESCENT_DWELL, name
    assert RAKE_DWELL == DESCENT_DWELL  # one dwell for every program
    np.testing.assert_array_equal(run_steps(V4) - run_steps(V3),
                                  np.where(np.asarray(ACTIONS) == "rake", TOOL_TRANSIT - 150, DESCENT_DWELL))


def test_v4_guard_starts_at_the_descent_after_the_dwell():
    seg, rows = guard.guard_tables(V4)
    for a in ("lift", "take", "pour", "slide", "pull", "push", "unobstruct"):
        i = action_id(a)
        assert np.flatnonzero(seg[i]).tolist() == [2, 3], a  # the descent and the dwell at the grasp
        assert np.flatnonzero(rows[i]).tolist() == [2, 3, 4, 5, 6], a
    for a in ("move", "rake"):
        assert not seg[action_id(a)].any() and not rows[action_id(a)].any()


def test_pads_footprint_margin_hand_worked():
    # unobstruct's grasp of a brick, a block on the table beside it along the closing axis, its
    # near face GAP beyond the outer face of a pad's footprint (the pad's pre-grasp place): v3
    # tests the exact footprint and grasps; v4 grows it by PAD_MARGIN and refuses a gap inside it
    _, arm, (toy, obst) = prog("unobstruct", V3, "block", "brick", (0.7, 0.0, 0.0), (0.7, 0.0, 0.0))
    g = bodies.top_down_grasp(arm, V3, obst)
    u = np.asarray(g.closing)

    def ok(cfg, gap):
        off = float(g.opening) + arm.pad_thickness + gap + float(toy.half_width(g.closing))
        return bool(prog("unobstruct", cfg, "block", "brick", tuple(np.array([0.7, 0.0, 0.0]) + off * u),
                         (0.7, 0.0, 0.0))[0].ok)

    m = bodies.PAD_MARGIN
    assert ok(V3, 0.5 * m) and not ok(V4, 0.5 * m)
    assert ok(V3, 1.5 * m) and ok(V4, 1.5 * m)


def test_palm_clears_a_toy_pushed_across_hand_worked():
    # a toy car turned a quarter on a cup (5 cm along the closing axis, the cup 9 cm): centred, the
    # pads close on the cup's walls and never meet it; 9 mm over the cup's side, the pad on that
    # side pushes it across the open top (pull 10054 of the paper v3 dataset)
    cup = lib.get("cup").height
    st = planning.setup(V4)

    def plan(cfg, shift):
        t = (0.7 + shift, 0.0, cup)  # the closing axis is world x here
        pr, arm, (car, cup_b) = prog("pull", cfg, "toy_car", "cup", t, (0.7, 0.0, 0.0), tyaw=np.pi / 2)
        p, q = scene(st.world, "toy_car", "cup", t, (0.7, 0.0, 0.0), np.pi / 2)
        sc = programs._scene(st.geo, jnp.int32(p), jnp.asarray(q))
        g = bodies.clear_grasp(arm, cfg, bodies.top_down_grasp(arm, cfg, cup_b), cup_b, car, jnp.zeros(3))
        assert np.allclose(np.abs(np.asarray(g.closing)), [1.0, 0.0, 0.0])
        half, cup_half = float(car.half_width(g.closing)), float(cup_b.half_width(g.closing))
        return pr, bool(programs.pushed_across(arm, g, sc)), half, cup_half

    centred3, pushed, half, cup_half = plan(V3, 0.0)
    centred4, _, _, _ = plan(V4, 0.0)
    assert not pushed and bool(centred4.ok)
    np.testing.assert_array_equal(np.asarray(centred4.targets.pos), np.asarray(centred3.targets.pos))
    shift = cup_half + 0.009 - half  # 9 mm past the cup's side
    over3, pushed, _, _ = plan(V3, shift)
    over4, _, _, _ = plan(V4, shift)
    assert pushed
    assert bool(over3.ok) and float(over3.targets.pos[1, 2]) == pytest.approx(0.07, abs=1e-4)  # fingertips at 5 cm
    # v4: the palm 2 cm above the car's diagonal (from the cup's rim) leaves the pads less than
    # min_grip of the cup: refused
    assert not bool(over4.ok)


def _posed_scene(cfg, toy, other, txyz, oxyz):
    st = planning.setup(cfg)
    p, q = scene(st.world, toy, other, txyz, oxyz)
    return st.arm, programs._scene(st.geo, jnp.int32(p), jnp.asarray(q))


def test_take_refuses_a_wall_between_the_pads_hand_worked():
    # a block in a baking pan (30 x 22 cm, 8 mm walls), take's closing axis along world y here;
    # 7 cm off the pan's centre along it the + pad (inner face 5 cm from the block's centre)
    # comes down 1 cm outside the pan's wall, the - pad inside: the pads would end on the block
    # and the wall together (take 13155 and 30927 of the paper v3 dataset). Centred, both pads
    # come down inside the opening and v4 plans as v3.
    floor = dict(lib.get("baking_pan").parts)["base"].size[2]

    def plan(cfg, dy):
        t, o = (0.7, 0.0, floor), (0.7, -dy, 0.0)  # the block on the x axis: closing along y
        arm, sc = _posed_scene(cfg, "block", "baking_pan", t, o)
        g = programs._toy_grasp(arm, cfg, sc)[0]
        assert np.allclose(np.abs(np.asarray(g.closing)), [0.0, 1.0, 0.0])
        return prog("take", cfg, "block", "baking_pan", t, o)[0], bool(pad_sweep.wall_between_pads(arm, g, sc.oth, sc.inner))

    centred3, _ = plan(V3, 0.0)
    centred4, wall = plan(V4, 0.0)
    assert not wall and bool(centred3.ok) and bool(centred4.ok)
    np.testing.assert_array_equal(np.asarray(centred4.targets.pos), np.asarray(centred3.targets.pos))
    near3, _ = plan(V3, 0.07)
    near4, wall = plan(V4, 0.07)
    assert wall and bool(near3.ok) and not bool(near4.ok)


def test_drag_refuses_a_carry_over_a_standing_toy_hand_worked():
    # push a bucket (23 cm square, 20 cm tall) along world x, its closing axis: the far pad goes
    # 25 cm ahead with its fingertips at 11 cm (2 cm higher during the carry). A 12 cm can on the
    # table 5 cm ahead of that pad's footprint stands in its way (push 25333 of the paper v3
    # dataset: the pad came down on such a can at 76 N); a 5 cm block there is passed over;
    # the can 15 cm to the side of the pads' lane is never met.
    arm, sc = _posed_scene(V4, "toy_can", "bucket", (0.0, 0.7, 0.0), (0.7, 0.0, 0.0))
    g = programs._base_grasp(arm, V4, sc)[0]
    assert np.allclose(np.abs(np.asarray(g.closing)), [1.0, 0.0, 0.0])
    far = 0.7 + float(g.opening) + arm.pad_thickness + 0.05  # 5 cm beyond the far pad's outer face
    push = lambda cfg, toy, half, y: prog("push", cfg, toy, "bucket", (far + half, y, 0.0), (0.7, 0.0, 0.0))[0]
    can, block = 0.0325, 0.025
    assert bool(push(V3, "toy_can", can, 0.0).ok) and not bool(push(V4, "toy_can", can, 0.0).ok)
    assert bool(push(V4, "block", block, 0.0).ok)
    aside3, aside4 = push(V3, "toy_can", can, 0.15 + can), push(V4, "toy_can", can, 0.15 + can)
    assert bool(aside3.ok) and bool(aside4.ok)
    np.testing.assert_array_equal(np.asarray(aside4.targets.pos), np.asarray(aside3.targets.pos))


def test_move_sweeps_over_a_low_base_it_crosses_hand_worked():
    # a block on a 1.5 cm lid: v3 sweeps with the fingertips 1 cm above the table, into the lid's
    # side, which they ride up onto (move 4143: 33 N on the lid for 1 s); v4 raises them to 1 cm
    # above the lid's top and sweeps the block off it. The same block beside the lid (the sweep
    # never crosses it), on a placemat below the fingertips and on a pallet board well above them
    # (pushed along): v4 plans as v3.
    tip = lambda pr, arm: float(pr.targets.pos[1, 2]) - arm.tip_below_tcp
    lid = lib.get("lid").height
    on3, arm, (_, lid_b) = prog("move", V3, "block", "lid", (0.7, 0.0, lid), (0.7, 0.0, 0.0))
    on4, _, _ = prog("move", V4, "block", "lid", (0.7, 0.0, lid), (0.7, 0.0, 0.0))
    top = float(lid_b.z_range()[1])
    assert tip(on3, arm) == pytest.approx(0.01, abs=1e-6) and top - 0.01 <= sweep.STEP_ABOVE
    assert tip(on4, arm) == pytest.approx(top + V4.tip_clearance + 0.005, abs=1e-6) and bool(on4.ok)
    # a car (4 cm) on the lid: raised the same and swept, not refused as a toy fallen near the
    # fingertips (v3's refusal is for a raise that clears the palm)
    car, _, _ = prog("move", V4, "toy_car", "lid", (0.7, 0.0, lid), (0.7, 0.0, 0.0))
    assert tip(car, arm) == pytest.approx(top + V4.tip_clearance + 0.005, abs=1e-6) and bool(car.ok)
    # the whole sweep at that height, from free table beside the lid across it
    np.testing.assert_allclose(np.asarray(on4.targets.pos[1:3, 2]), float(on4.targets.pos[1, 2]))
    assert bool(sweep.sweep_crosses(arm, on4.targets.pos[1], on4.targets.pos[2], on4.direction, lid_b))
    for other, t, o in (("lid", (0.7, 0.3, 0.0), (0.7, 0.0, 0.0)),
                        ("placemat", (0.7, 0.0, lib.get("placemat").height), (0.7, 0.0, 0.0)),
                        ("pallet_board", (0.7, 0.0, lib.get("pallet_board").height), (0.7, 0.0, 0.0))):
        p3, _, (_, ob) = prog("move", V3, "block", other, t, o)
        p4, _, _ = prog("move", V4, "block", other, t, o)
        np.testing.assert_array_equal(np.asarray(p4.targets.pos), np.asarray(p3.targets.pos))
        assert bool(p4.ok) == bool(p3.ok), other
