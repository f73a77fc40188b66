"""Programs v2's guarded descent (sim/guard.py): the arm stops going down to a grasp where a
pad lands on an object. Fast tests check the tables and the landing rule by hand; the slow
one replays a take whose pads come down on a cup in MuJoCo C, with and without the guard."""
import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.sim import arm as A
from relaff_jax.sim import guard, planning, templates
from relaff_jax.sim.native import reference as native
from relaff_jax.sim.native.probe import Probe
from relaff_jax.sim import world as wd
from relaff_jax.config.action import ActionConfig
from relaff_jax.sim.actions.tables import tables

V2 = ActionConfig(programs="v3")  # the guard as v2 and v3 lay it out (v4, one dwell later: test_programs_v4.py)
V1 = dataclasses.replace(V2, programs="v1")
# the slow replay runs the default programs (v4: the guard one dwell later), as the tool does
DEFAULT = ActionConfig()
OFF = dataclasses.replace(DEFAULT, guard_depth=1.0)  # no contact is a metre deep: the guard never stops


def test_guard_tables_by_hand():
    seg, rows = guard.guard_tables(V2)
    for a in ("lift", "take", "pour", "slide", "pull", "push", "unobstruct"):
        i = action_id(a)
        # the descent to the grasp (segment 1) and the dwell before closing (segment 2)
        assert np.flatnonzero(seg[i]).tolist() == [1, 2], a
        # waypoint 1 (the descent's start) through waypoint 5 (the end of the grasp's last segment)
        assert np.flatnonzero(rows[i]).tolist() == [1, 2, 3, 4, 5], a
    for a in ("move", "rake"):  # no grasp: nothing guarded
        assert not seg[action_id(a)].any() and not rows[action_id(a)].any()
    s1, r1 = guard.guard_tables(V1)
    assert not s1.any() and not r1.any()  # v1 is never guarded
    assert seg.shape == (len(ACTIONS), templates.N_SEGMENTS) and rows.shape[1] == templates.N_SEGMENTS + 1


def test_guard_tables_cover_a_user_action():
    """The tables are the run's (the nine, then a user's), as the compiled programs index them:
    a registered user action that grasps its base gets a row, guarded like lift's."""
    import runpy

    from helpers import ROOT
    from relaff_jax.sim.actions.registry import names, unregister

    nine = guard.guard_tables(V2)
    runpy.run_path(str(ROOT / "examples" / "tenth_action.py"))  # registers "drag" (no plugin-file record left)
    try:
        seg, rows = guard.guard_tables(V2)
        i = names().index("drag")
        assert seg.shape[0] == rows.shape[0] == len(names()) == len(ACTIONS) + 1
        np.testing.assert_array_equal(seg[:len(ACTIONS)], nine[0])
        np.testing.assert_array_equal(rows[:len(ACTIONS)], nine[1])
        assert np.flatnonzero(seg[i]).tolist() == [1, 2]  # the descent to the base's grasp and the dwell
    finally:
        unregister("drag")


def test_landing_rule_by_hand():
    axis = np.array([0.0, 1.0, 0.0])  # the pad's closing axis
    up, face = np.array([0.0, 0.0, 1.0]), np.array([0.0, -1.0, 0.0])
    edge = np.array([0.0, -np.sin(np.pi / 3), np.cos(np.pi / 3)])  # 60 deg off vertical: a face contact (cos 0.87)
    land = lambda d, n, cfg=V2, ok=True: bool(guard.pad_landing_np(np.array([d]), np.array([n]), axis,
                                                                    np.array([ok]), cfg))
    assert land(-1e-4, up)  # the pad's bottom on a top, penetrating
    assert not land(1e-4, up)  # not yet touching
    assert not land(-1e-3, face) and not land(-1e-3, edge)  # a gripping-face contact never stops it
    assert not land(-1e-3, up, ok=False)  # an empty sensor slot
    deeper = dataclasses.replace(V2, guard_depth=0.002)
    assert not land(-1e-3, up, deeper) and land(-3e-3, up, deeper)
    q = np.arange(7 * 6, dtype=np.float32).reshape(7, 6)
    rows = np.array([0, 1, 1, 0, 0, 0, 0], bool)
    out = guard.stopped_way(q, rows, np.full(6, -1.0))
    np.testing.assert_array_equal(out[[1, 2]], -1.0)
    np.testing.assert_array_equal(out[[0, 3, 4, 5, 6]], q[[0, 3, 4, 5, 6]])
    np.testing.assert_array_equal(np.asarray(guard.stopped_way(jnp.asarray(q), jnp.asarray(rows), jnp.full(6, -1.0))), out)


def _cup_scene():
    """A 9 cm cup turned 45 degrees on a book, taken: its diagonal (12.7 cm) is wider than
    take's fixed 10 cm opening, so the pads come down on its walls. Settled in C and planned
    by JAX (``plan_rows``: the session's batch-8 planner; the guard does not change a plan,
    only its execution). Returns pair (1,), qpos (1, 14) and the plan."""
    from helpers.scenes import plan_rows

    w = planning.setup(DEFAULT).world
    q = np.array(w.mj_model.qpos0, np.float64)[:14]
    yaw = np.pi / 4
    q[0:7] = [0.7, 0.0, 0.03, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    q[7:14] = [0.7, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    pair = np.array([w.pair_id("cup", "book")])
    qs, _ = native.settle_native(wd.build_world(DEFAULT.phys), pair, q[None])
    qpos = qs[:, :14]
    res = plan_rows("take", DEFAULT, pair, qpos)
    assert res["feasible"].all()
    return pair, qpos, res


def _take_steps(cfg):
    """Take's grasp waypoint (the row of ``q_way`` the descent ends at) and the last step
    before the fingers close (the end of the dwell at the grasp), from ``cfg``'s tables."""
    aid = action_id("take")
    seg = np.flatnonzero(guard.guard_tables(cfg)[0][aid])  # the descent, then the dwell at the grasp
    return int(seg[0]) + 1, int(tables(cfg).steps[aid][:seg[-1] + 1].sum()) - 1


def _cup_take(cfg, pair, qpos, res):
    """The cup scene's take replayed in C under ``cfg``; returns the plan's tcp height at the
    grasp, the tcp height per step and the physics readings (``native.forces``)."""
    st = planning.setup(cfg)
    w = st.world
    tcp = []
    site = st.arm.tcp_site
    probe_z = lambda b, t, m, d: tcp.append(float(d.site_xpos[site][2]))
    probe = Probe(1, w.toy_body, w.obj_body, cfg.phys.timestep)
    both = lambda b, t, m, d: (probe(b, t, m, d), probe_z(b, t, m, d))
    out = native.replay_native("take", cfg, pair, qpos, np.zeros((1, 12)), res, observe=both)
    grasp_z = float(A.fk_tcp(st.arm, jnp.asarray(res["q_way"][0, _take_steps(cfg)[0]]))[0][2])
    return grasp_z, np.array(tcp), probe.result(out["read_step"]), out


@pytest.mark.slow  # settles and plans one take, replays it twice in C
def test_take_descent_stops_where_the_pads_land_and_the_press_stays_bounded():
    from relaff_jax.sim.physics_bounds import PALM_CONTACT_STEPS, press_ok

    scene_plan = _cup_scene()  # one plan: the guard changes only the execution
    z_on, tcp_on, r_on, _ = _cup_take(DEFAULT, *scene_plan)
    z_off, tcp_off, r_off, _ = _cup_take(OFF, *scene_plan)
    dwell_end = _take_steps(DEFAULT)[1]  # the last step before closing
    # without the guard the servos drive the pads down the cup to within 1 cm of the planned
    # grasp; with it the tcp stays where the pads met the cup's walls, centimetres above
    assert tcp_off[dwell_end] < z_off + 0.01
    assert tcp_on[dwell_end] > z_on + 0.03
    assert r_off["press_weights"][0] > r_on["press_weights"][0]
    assert press_ok(r_on["press_n"][0], r_on["weight_n"][0]) and r_on["palm_steps"][0] <= PALM_CONTACT_STEPS
