"""Programs v3, the held rake: waypoints on one IK branch, the refusals of a large base turn, of a
pull line passing the base axis and of a grip point behind the base, and the dwell before the descent; v2's rake unchanged. Hand-built
scenes (``programs.program``, the IK path of ``planning.make_plan_fn``; no simulation)."""
import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.constants import action_id
from relaff_jax.sim import arm as A
from relaff_jax.sim import branch, planning, programs
from relaff_jax.sim.actions.registry import registry
from relaff_jax.sim.actions.tables import RAKE_DWELL, spec_tables, tables

V3 = ActionConfig(programs="v3")
V2 = dataclasses.replace(V3, programs="v2")
RAKE = action_id("rake")
GRIP = float(A.TOOL_GRIP_POS[0])  # the tcp 4 cm along the handle from its near end


def scene(toy, tool, x, y, yaw=0.0):
    w = planning.setup(V3).world
    q = np.array(w.mj_model.qpos0, np.float32)[:14]
    q[0:7] = [x, y, 0.001, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    q[7:14] = [*V3.phys.held_rake_pos, 1.0, 0.0, 0.0, 0.0]
    return jnp.int32(w.pair_id(toy, tool)), jnp.asarray(q)


@functools.partial(jax.jit, static_argnums=0)
def _path(cfg, pair, qpos):
    """The rake program's four targets solved as ``planning.make_plan_fn`` solves them: forward
    from home (v2's plan), and put on one branch (v3's)."""
    st = planning.setup(cfg)
    pr = programs.program("rake", st.arm, cfg, st.geo, pair, qpos)
    fwd = A.solve_ik_path(st.arm, cfg.arm, pr.targets, jnp.asarray(st.q_home), jnp.int32(4))
    return pr.ok, fwd, branch.one_branch(st.arm, cfg.arm, pr.targets, fwd, jnp.int32(4))


def turns_deg(q):
    return np.abs(np.diff(np.degrees(np.asarray(q)[:4, 0])))


@pytest.mark.slow
def test_descent_that_flips_the_base_in_v2_stays_on_one_branch_in_v3():
    # a toy car 26 cm in front of the robot, the hoe (head 47 cm out): the grip point lies behind
    # the base axis. The forward path reaches `above` leaning back over the base; `low`, 5 cm
    # lower, is beyond that branch (the shoulder at its limit), so v2's `low` turns the base 180
    # degrees in the vertical descent. v3 solves the targets backwards: `above` on `low`'s branch.
    ok, fwd, one = _path(V3, *scene("toy_car", "hoe", 0.26, 0.0))
    assert bool(jnp.all(fwd.reachable[:4])) and bool(jnp.all(one.reachable[:4]))
    assert not bool(ok)  # v3 refuses the program all the same: the grip point is behind the base
    assert turns_deg(fwd.q)[0] == pytest.approx(180.0, abs=5.0)  # above -> low
    assert turns_deg(one.q).max() < 45.0
    assert np.abs(np.degrees(np.asarray(one.q[1:4] - fwd.q[1:4]))).max() < 5.0  # from `low` on: as before
    # the forward path is v2's plan: v2's program has the same targets (the pull line clears the axis)
    st = planning.setup(V2)
    pair, q = scene("toy_car", "hoe", 0.26, 0.0)
    v2 = programs.program("rake", st.arm, V2, st.geo, pair, q)
    v3 = programs.program("rake", st.arm, V3, st.geo, pair, q)
    np.testing.assert_array_equal(np.asarray(v2.targets.pos), np.asarray(v3.targets.pos))
    # 10 cm to the right the pull must cross the base joint's +-175 degree limit the short way:
    # both paths turn the base by more than 300 degrees, and the turn bound refuses the program
    _, fwd, one = _path(V3, *scene("toy_car", "hoe", 0.26, -0.1))
    assert turns_deg(one.q).max() > 300.0 and branch.base_turn(one.q, 4) > branch.BASE_TURN_MAX


def test_base_turn_and_the_choice_of_path_hand_worked():
    deg = np.deg2rad
    q = np.zeros((6, 6), np.float32)
    q[:, 0] = deg([-150.0, 30.0, 60.0, 0.0, 170.0, 170.0])  # rows 4-5: unused (n_used 4)
    # the turns after the first target: 180, 30, 60 (the transit from home is not in q)
    assert float(branch.base_turn(jnp.asarray(q), 4)) == pytest.approx(deg(180.0), abs=1e-5)
    assert float(branch.base_turn(jnp.asarray(q[1:]), 3)) == pytest.approx(deg(60.0), abs=1e-5)
    assert float(branch.base_turn(jnp.asarray(q), 1)) == 0.0
    assert branch.BASE_TURN_MAX == pytest.approx(deg(90.0))


def test_axis_distance_hand_worked():
    arm = planning.setup(V3).arm
    d = lambda a, b: float(programs.axis_distance(arm, jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)))
    assert d([0.3, 0.05, 0.2], [-0.1, 0.05, 0.2]) == pytest.approx(0.05, abs=1e-6)  # passes beside the axis
    assert d([0.4, 0.0, 0.1], [0.2, 0.0, 0.1]) == pytest.approx(0.2, abs=1e-6)  # ends 20 cm short of it
    assert d([0.3, 0.2, 0.0], [0.1, 0.2, 0.0]) == pytest.approx(np.hypot(0.1, 0.2), abs=1e-6)
    assert d([0.1, 0.0, 0.0], [-0.1, 0.0, 0.0]) == 0.0  # through it


@pytest.mark.parametrize("x, refused", [(0.5, True), (0.9, False)])
def test_pull_line_refusal_hand_worked(x, refused):
    # a 5 cm block on the x axis, the long rake (head's near face 57 cm along the handle): the
    # hand's line runs 2 + 1.25 + 2.5 = 5.75 cm beside the x axis, from x - (57 - 2.5 - 2 - 4) cm
    # back by the 30 cm pull: for the block at 50 cm from +1.5 to -28.5 cm, past the axis at
    # 5.75 cm (refused, < 10 cm); at 90 cm from 41.5 to 11.5 cm, 12.9 cm away at its end (pulled)
    st = planning.setup(V3)
    pair, q = scene("block", "rake_long", x, 0.0)
    pr = programs.program("rake", st.arm, V3, st.geo, pair, q)
    pr2 = programs.program("rake", st.arm, V2, st.geo, pair, q)
    side = 0.0125 + V3.rake_gap + 0.025
    start = x - (float(st.geo.head_x0[int(pair)]) - 0.025 - V3.rake_gap - GRIP)
    end = start - V3.rake_pull
    want = side if end < 0.0 < start else np.hypot(min(abs(start), abs(end)), side)
    got = float(programs.axis_distance(st.arm, pr.targets.pos[1], pr.targets.pos[2]))
    assert got == pytest.approx(want, abs=1e-4)
    assert (got < programs.RAKE_AXIS_CLEARANCE) == refused
    assert bool(pr.ok) == (not refused) and bool(pr2.ok)  # v2 pulls both
    np.testing.assert_array_equal(np.asarray(pr.targets.pos), np.asarray(pr2.targets.pos))  # same targets


def test_hand_behind_the_base_refused_hand_worked():
    # the long rake's grip point 12 cm behind the base axis (the toy 36.5 cm out on the x axis):
    # the pull line, 5.75 cm beside the axis and from -12 cm back to -42 cm, stays
    # hypot(12, 5.75) = 13.3 cm from it, so only the hand-ahead rule refuses it
    st = planning.setup(V3)
    pair, _ = scene("block", "rake_long", 0.5, 0.0)
    x = -0.12 + (float(st.geo.head_x0[int(pair)]) - 0.025 - V3.rake_gap - GRIP)
    pair, q = scene("block", "rake_long", x, 0.0)
    pr = programs.program("rake", st.arm, V3, st.geo, pair, q)
    low = pr.targets.pos[1]
    assert float(programs.axis_distance(st.arm, low, pr.targets.pos[2])) == pytest.approx(np.hypot(0.12, 0.0575), abs=1e-4)
    assert float(programs.ahead_of_base(st.arm, low, jnp.array([1.0, 0.0, 0.0]))) == pytest.approx(-0.12, abs=1e-4)
    assert not bool(pr.ok) and bool(programs.program("rake", st.arm, V2, st.geo, pair, q).ok)


def test_v3_rake_dwells_at_above_after_the_transit():
    t2, t3 = tables(V2), tables(V3)
    base = spec_tables(registry())
    # v2: the declared templates, the final rest rest_hold longer (as before v3)
    np.testing.assert_array_equal(t2.target, base.target)
    np.testing.assert_array_equal(t2.measure, base.measure)
    # v3: every action but rake as v2; rake holds `above` (target 0) RAKE_DWELL steps more
    other = np.arange(len(t2.measure)) != RAKE
    for k in ("steps", "target", "closed", "measure"):
        np.testing.assert_array_equal(getattr(t3, k)[other], getattr(t2, k)[other])
    assert list(t3.steps[RAKE][:3]) == [t2.steps[RAKE][0], RAKE_DWELL, t2.steps[RAKE][1]]
    assert list(t3.target[RAKE][:3]) == [0, 0, 1]
    assert t3.measure[RAKE] == t2.measure[RAKE] + RAKE_DWELL
    assert t3.n_steps == t2.n_steps and t3.steps[RAKE].sum() == t2.steps[RAKE].sum()  # within the padding
