"""Motor programs v3: move's sweep raised to a fixed point over every top near the palm, and a
base or obstacle grasp refused when the toy stands between the pads; v2's plans unchanged, bit
for bit. Fast tests on hand-built scenes (``programs.program``, no simulation)."""
import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.sim import bodies, planning, programs, sweep
from relaff_jax.sim.geometry import quat_to_mat
from relaff_jax.sim import objects as lib

from helpers.scenes import posed as scene, posed_program as prog

V3 = ActionConfig(programs="v3")
V2 = dataclasses.replace(V3, programs="v2")
FLOOR = dict(lib.get("basket").parts)["base"].size[2]  # the basket's floor, 1 cm
# v2's programs of SCENES, made by ``pinned_programs()`` with the code before v3 existed (main at
# a00fc45, run with PYTHONPATH pointing at it): v2 must plan them bit for bit as then
REFERENCE = Path(__file__).with_name("programs_v2_reference.json")
# v3's, made the same way with the code before v4 existed (main at 1d674f7)
REFERENCE_V3 = Path(__file__).with_name("programs_v3_reference.json")


def sweep_palm(arm, pr):
    """The palm's underside during move's sweep (targets 1-2)."""
    return float(pr.targets.pos[2, 2]) - arm.tip_below_tcp + arm.palm_above_tip


# (toy, other, toy position, other position, toy yaw): the toy centred in or on the other
MOVE_SCENES = {
    "can in basket": ("toy_can", "basket", (0.7, 0.0, FLOOR), (0.7, 0.0, 0.0)),
    "car on cup": ("toy_car", "cup", (0.7, 0.0, lib.get("cup").height), (0.7, 0.0, 0.0)),
    "can on cutting board": ("toy_can", "cutting_board", (0.7, 0.0, 0.02), (0.7, 0.0, 0.0)),
    "can on cutting board +0.1 mm": ("toy_can", "cutting_board", (0.7, 0.0, 0.0201), (0.7, 0.0, 0.0)),
    "can on cutting board -0.3 mm": ("toy_can", "cutting_board", (0.7, 0.0, 0.0197), (0.7, 0.0, 0.0)),
}


@pytest.mark.parametrize("name", sorted(MOVE_SCENES))
def test_move_palm_clears_every_top_it_sweeps_over(name):
    toy, other, t, o = MOVE_SCENES[name]
    pr, arm, (tb, ob) = prog("move", V3, toy, other, t, o)
    palm = sweep_palm(arm, pr)
    zmin, zmax = (float(z) for z in tb.z_range())
    # the toy's top, its top once swept onto the table, the other's top (the sweep starts over it)
    tops = [zmax, zmax - zmin, float(ob.z_range()[1])]
    for top in tops:  # each top is palm_margin below the palm's underside or beyond the band above
        assert top <= palm - V3.palm_margin + 1e-6 or top > palm + V3.palm_margin + sweep.TOP_TOL, (name, top, palm)


def test_move_v3_heights_hand_worked():
    # unraised sweep: fingertips 1 cm up, the palm's underside 12 cm up (palm_above_tip 11 cm)
    pr, arm, (tb, ob) = prog("move", V3, *MOVE_SCENES["can in basket"])
    assert arm.palm_above_tip == pytest.approx(0.11, abs=1e-6)
    # the can (12 cm on the 1 cm floor: top 13 cm) -> 15 cm; the basket's rim (15 cm) -> 17 cm
    assert float(ob.z_range()[1]) == pytest.approx(0.15, abs=1e-6)
    assert sweep_palm(arm, pr) == pytest.approx(0.17, abs=1e-5) and bool(pr.ok)  # falls inside
    pr2, _, _ = prog("move", V2, *MOVE_SCENES["can in basket"])
    assert sweep_palm(arm, pr2) == pytest.approx(0.15, abs=1e-5)  # v2: on the rim
    # the car's top 2 cm above the palm (the band's edge) -> 16 cm; v2 left it at 12 cm; the
    # car pushed off the cup lies 4 cm high, 1 cm under the fingertips (5 cm): refused
    pr, _, (tb, _) = prog("move", V3, *MOVE_SCENES["car on cup"])
    assert float(tb.z_range()[1]) == pytest.approx(0.14, abs=1e-6)
    assert sweep_palm(arm, pr) == pytest.approx(0.16, abs=1e-5) and not bool(pr.ok)
    v2 = prog("move", V2, *MOVE_SCENES["car on cup"])[0]
    assert sweep_palm(arm, v2) == pytest.approx(0.12, abs=1e-5) and bool(v2.ok)
    # a can on a 2 cm board: the palm at 16 cm, the fingertips 5 cm, 1.5 cm under the side of the
    # can fallen off the board (6.5 cm): refused (v2 swept at 12 or 16 cm, by 0.1 mm of its height)
    for name in ("can on cutting board", "can on cutting board +0.1 mm", "can on cutting board -0.3 mm"):
        pr, _, _ = prog("move", V3, *MOVE_SCENES[name])
        assert sweep_palm(arm, pr) == pytest.approx(0.16, abs=5e-4) and not bool(pr.ok), name
    # a can on a 1.4 cm lid: palm 15.4 cm, fingertips 4.4 cm, 2.1 cm under the fallen can: swept
    lid, _, _ = prog("move", V3, "toy_can", "lid", (0.7, 0.0, 0.014), (0.7, 0.0, 0.0))
    assert sweep_palm(arm, lid) == pytest.approx(0.154, abs=1e-5) and bool(lid.ok)
    # a can on the table: 14 cm as in v2 (its top 12 cm); it stands on nothing, no fall
    on_table = ("toy_can", "book", (0.7, 0.3, 0.0), (0.7, 0.0, 0.0))
    for cfg in (V3, V2):
        pr = prog("move", cfg, *on_table)[0]
        assert sweep_palm(arm, pr) == pytest.approx(0.14, abs=1e-5) and bool(pr.ok)
    # a car leaning on a cup's rim (tilted 30 degrees): its slope meets the palm at 12 cm, so it
    # rises over the car's top
    lean, _, (tb, _) = prog("move", V3, "toy_car", "cup", (0.7, 0.0, 0.09), (0.7, 0.0, 0.0), tilt=np.pi / 6)
    zmin, zmax = (float(z) for z in tb.z_range())
    assert zmin < 0.12 < zmax - V3.palm_margin
    assert sweep_palm(arm, lean) >= zmax + V3.palm_margin - 1e-5


def test_sweep_raise_fixed_point_hand_worked():
    m, tol = V3.palm_margin, sweep.TOP_TOL
    band = m + tol
    r = lambda palm, tops, depth=None: float(sweep.sweep_raise(
        V3, jnp.float32(palm), jnp.asarray(tops, jnp.float32),
        jnp.full(len(tops), band, jnp.float32) if depth is None else jnp.asarray(depth, jnp.float32)))
    assert r(0.12, [0.13, 0.12, 0.15]) == pytest.approx(0.05, abs=1e-6)  # 0.13 -> 0.15 -> rim 0.15 -> 0.17
    assert r(0.12, [0.15, 0.13, -1.0]) == pytest.approx(0.05, abs=1e-6)  # the order does not matter
    assert r(0.12, [0.14, 0.04, -1.0]) == pytest.approx(0.04, abs=1e-6)  # the band's edge is inside
    assert r(0.12, [0.14 + tol * 0.9, -1.0, -1.0]) == pytest.approx(0.04 + tol * 0.9, abs=1e-6)
    assert r(0.12, [0.14 + tol * 1.5, -1.0, -1.0]) == 0.0  # beyond: the hand meets its side
    assert r(0.12, [0.05, 0.099, -1.0]) == 0.0  # far below
    # a chain of three, each inside the band only once the palm has risen for the one before
    assert r(0.12, [0.173, 0.133, 0.153]) == pytest.approx(0.193 - 0.12, abs=1e-6)
    # a tilted toy from 7 to 15 cm: the palm at 12 cm meets its slope, so it rises over its top
    assert r(0.12, [0.15, -1.0], [0.08 + band, band]) == pytest.approx(0.05, abs=1e-6)
    assert r(0.12, [0.15, -1.0]) == 0.0  # upright, its top 3 cm above the palm: met from the side


def test_pull_refuses_a_grasp_whose_pads_meet_the_toy_first():
    cup = lib.get("cup").height
    # a 10 cm toy car lying across a 9 cm cup along the closing axis: the pads would squeeze the car
    across, arm, (car, cup_b) = prog("pull", V3, "toy_car", "cup", (0.7, 0.0, cup), (0.7, 0.0, 0.0))
    g = bodies.top_down_grasp(arm, V3, cup_b)
    assert float(car.half_width(g.closing)) > float(cup_b.half_width(g.closing))  # the geometry
    assert not bool(across.ok)
    assert bool(prog("pull", V2, "toy_car", "cup", (0.7, 0.0, cup), (0.7, 0.0, 0.0))[0].ok)  # v2 grasped it
    # turned a quarter: 5 cm along the closing axis, inside the cup's width: grasped, as in v2
    along, _, _ = prog("pull", V3, "toy_car", "cup", (0.7, 0.0, cup), (0.7, 0.0, 0.0), tyaw=np.pi / 2)
    along2, _, _ = prog("pull", V2, "toy_car", "cup", (0.7, 0.0, cup), (0.7, 0.0, 0.0), tyaw=np.pi / 2)
    assert bool(along.ok)
    np.testing.assert_array_equal(np.asarray(along.targets.pos), np.asarray(along2.targets.pos))


@pytest.mark.parametrize("action", ["lift", "pour", "slide", "push", "pull"])
def test_every_base_grasp_refuses_the_car_across_the_cup(action):
    cup = lib.get("cup").height
    assert not bool(prog(action, V3, "toy_car", "cup", (0.7, 0.0, cup), (0.7, 0.0, 0.0))[0].ok)
    # a toy inside a container never blocks the pads
    assert bool(prog(action, V3, "toy_car", "basket", (0.7, 0.0, FLOOR), (0.7, 0.0, 0.0))[0].ok)


def test_unobstruct_refuses_a_toy_in_the_pads_lane():
    # the toy 1 cm beside a brick along the grasp's closing axis, inside the pads' reach: refused
    _, arm, (toy, obst) = prog("unobstruct", V3, "block", "brick", (0.7, 0.0, 0.0), (0.7, 0.0, 0.0))
    g = bodies.top_down_grasp(arm, V3, obst)
    off = float(obst.half_width(g.closing)) + 0.01 + float(toy.half_width(g.closing))
    assert off - float(toy.half_width(g.closing)) < float(g.opening)  # inside the pad's start
    near = np.array([0.7, 0.0, 0.0]) + off * np.asarray(g.closing)
    assert not bool(prog("unobstruct", V3, "block", "brick", tuple(near), (0.7, 0.0, 0.0))[0].ok)
    # (v2 refuses it too: its pad would come down on the block, clear_grasp's test)
    assert not bool(prog("unobstruct", V2, "block", "brick", tuple(near), (0.7, 0.0, 0.0))[0].ok)
    far = np.array([0.7, 0.0, 0.0]) + 0.3 * np.asarray(g.closing)
    assert bool(prog("unobstruct", V3, "block", "brick", tuple(far), (0.7, 0.0, 0.0))[0].ok)
    # beside a bottle the grasp is high (the palm 2 cm above its top): the block is below the
    # fingertips, out of the pads' way
    _, _, (toy, obst) = prog("unobstruct", V3, "block", "bottle", (0.7, 0.0, 0.0), (0.7, 0.0, 0.0))
    g = bodies.top_down_grasp(arm, V3, obst)
    off = float(obst.half_width(g.closing)) + 0.01 + float(toy.half_width(g.closing))
    near = np.array([0.7, 0.0, 0.0]) + off * np.asarray(g.closing)
    assert bool(prog("unobstruct", V3, "block", "bottle", tuple(near), (0.7, 0.0, 0.0))[0].ok)


CUP_FLOOR = dict(lib.get("cup").parts)["base"].size[2]
# take: a block and a ball in a cup (the fixed 10 cm opening puts the pads outside its 9 cm);
# lift: a toy car on a book (24 x 17 cm, grasped across its 17 cm), its 5 cm side along the
# closing axis, 1.5 cm past the book's edge on one pad's side
SQUEEZE_SCENES = {
    "take block in cup": ("take", "block", "cup", (0.7, 0.0, CUP_FLOOR), (0.7, 0.0, 0.0), 0.0),
    "take ball in cup": ("take", "ball", "cup", (0.7, 0.0, CUP_FLOOR), (0.7, 0.0, 0.0), 0.0),
    "lift car past a book's edge": ("lift", "toy_car", "book", (0.7, 0.075, lib.get("book").height), (0.7, 0.0, 0.0),
                                    0.0),
}


def test_squeeze_from_the_body_the_pads_end_on_hand_worked():
    def command(name, cfg):
        action, *rest = SQUEEZE_SCENES[name]
        pr, arm, (tb, ob) = prog(action, cfg, *rest)
        return pr, arm, tb, ob

    for name in ("take block in cup", "take ball in cup"):
        pr3, arm, tb, ob = command(name, V3)
        pr2 = command(name, V2)[0]
        f = float(bodies.squeeze_force(V3, arm, jnp.float32(lib.get(SQUEEZE_SCENES[name][1]).mass)))
        assert f == pytest.approx(V3.squeeze_min)  # a toy's squeeze: 5 N
        g = np.asarray(pr3.targets.closing[1])
        cup_half = float(ob.half_width(jnp.asarray(g)))
        assert cup_half == pytest.approx(0.045, abs=1e-6) and cup_half < V3.take_opening  # the pads start outside it
        toy_half = 0.035 if "ball" in name else 0.025
        # v2 commands from the toy: the pads stop on the cup's walls, 1-2 cm further out, and press them
        assert float(pr2.grip_closed) == pytest.approx(toy_half - f / arm.finger_kp, abs=1e-6)
        assert float(pr3.grip_closed) == pytest.approx(cup_half - f / arm.finger_kp, abs=1e-6)
        assert bool(pr3.ok) and bool(pr2.ok)
        np.testing.assert_array_equal(np.asarray(pr3.targets.pos), np.asarray(pr2.targets.pos))
    # a block in a bowl: the pads come down inside the bowl, the block alone between them: as v2
    bowl = dict(lib.get("bowl").parts)["base"].size[2]
    in_bowl = ("block", "bowl", (0.7, 0.0, bowl), (0.7, 0.0, 0.0))
    assert float(prog("take", V3, *in_bowl)[0].grip_closed) == float(prog("take", V2, *in_bowl)[0].grip_closed)
    # the car 1.5 cm past the book's edge: the pad pushes it across and both rest on the book:
    # grasped, with v2's command from the book (the overhang estimate refused it: 2 x (6.4 N +
    # finger_kp x 1.5 cm) against the bound's 49 N)
    pr3, arm, car, book = command("lift car past a book's edge", V3)
    pr2 = command("lift car past a book's edge", V2)[0]
    u = jnp.asarray(np.asarray(pr3.targets.closing[1]))
    past = float(jnp.abs((car.centre - book.centre) @ u) + car.half_width(u) - book.half_width(u))
    assert past == pytest.approx(0.015, abs=1e-5) and float(car.half_width(u)) < float(book.half_width(u))
    assert bool(pr3.ok) and float(pr3.grip_closed) == float(pr2.grip_closed)
    # the same car turned across a 9 cm cup (10 cm along the closing axis): refused, it ends between the pads
    assert not bool(prog("lift", V3, "toy_car", "cup", (0.7, 0.0, lib.get("cup").height), (0.7, 0.0, 0.0))[0].ok)
    # a ball in a cup (its box turned by rolling reaches past the cup, the ball does not): grasped
    turned = ("ball", "cup", (0.7, 0.0, CUP_FLOOR), (0.7, 0.0, 0.0))
    st = planning.setup(V3)
    p, q = scene(st.world, *turned)
    q[3:7] = [np.cos(0.4), np.sin(0.4) * 0.6, np.sin(0.4) * 0.8, 0.0]  # rolled; its centre stays put
    q[0:3] = np.array(turned[2]) + 0.035 * (np.array([0.0, 0.0, 1.0]) - np.asarray(quat_to_mat(jnp.asarray(q[3:7])))[:, 2])
    tb = bodies.bodies(st.geo, jnp.int32(p), jnp.asarray(q))[0]
    np.testing.assert_allclose(np.asarray(tb.centre), [0.7, 0.0, CUP_FLOOR + 0.035], atol=1e-6)
    assert float(tb.half_width(jnp.array([1.0, 0.0, 0.0]))) > 0.045  # the box would be wider than the cup
    assert bool(programs.program("lift", st.arm, V3, st.geo, jnp.int32(p), jnp.asarray(q)).ok)


@pytest.mark.slow  # settles, plans and replays 3 scenes in C
def test_squeeze_stays_within_the_bound_in_c():
    """The squeeze from the body the pads end on (v3, kept by the default v4) stays within the
    press bound on the scenes where v2's squeeze pressed a cup's walls at a kN/m servo 1-2 cm
    short of its command (docs/arm.md; the hand-worked squeeze: above). The session's
    batch-8 planner of the default programs, not one compiled for v2 and v3."""
    from relaff_jax.sim.physics_bounds import press_ok
    from helpers.scenes import replay_built

    default = ActionConfig()

    def run(action):
        w = planning.setup(default).world
        rows = [v[1:] for v in SQUEEZE_SCENES.values() if v[0] == action]
        return replay_built(action, default, [scene(w, *r) for r in rows])

    plan, take = run("take")
    assert plan["feasible"].all()
    assert press_ok(take["press"], take["weight"]).all(), take["press"]
    assert not take["label"].any()  # the cup comes along: not taken
    # the lift of the car past the book's edge (v3: pushed back onto the book within the bound)
    # is refused by v4 at plan time, the car in the palm's tipping reach (test_programs_v4.py);
    # the default's lift squeezes are checked on sampled scenes (test_programs_v2.py, bounds)
    plan, _ = run("lift")
    assert not plan["feasible"].any()


# scenes whose v2 programs are pinned: (action, toy, other, toy position, other position, toy yaw)
SCENES = [(a, *s) for a in ("lift", "pull", "push", "pour", "slide", "take", "unobstruct", "move")
          for s in (("toy_car", "cup", (0.7, 0.0, 0.1), (0.7, 0.0, 0.0), 0.0),
                    ("toy_can", "basket", (0.7, 0.0, 0.01), (0.7, 0.0, 0.0), 0.0),
                    ("toy_can", "cutting_board", (0.6, 0.2, 0.02), (0.6, 0.2, 0.0), 0.3),
                    ("block", "bottle", (0.8, 0.1, 0.0), (0.7, 0.0, 0.0), 0.0),
                    ("ball", "tray", (0.5, -0.3, 0.02), (0.5, -0.3, 0.0), 0.0))]


def pinned_programs(cfg: ActionConfig = V2) -> dict:
    """``cfg``'s program of every scene of SCENES that the world has, as lists of float32 values."""
    st = planning.setup(cfg)
    out = {}
    for action, toy, other, t, o, yaw in SCENES:
        try:
            p, q = scene(st.world, toy, other, t, o, yaw)
        except (KeyError, ValueError):  # the pair is not in the world
            continue
        pr = programs.program(action, st.arm, cfg, st.geo, jnp.int32(p), jnp.asarray(q))
        leaves = [np.asarray(x, np.float32).ravel().tolist() for x in jax.tree_util.tree_leaves(pr)]
        out[f"{action} {toy} {other}"] = leaves
    return out


@pytest.mark.parametrize("cfg, reference", [(V2, REFERENCE), (V3, REFERENCE_V3)], ids=["v2", "v3"])
def test_pinned_programs_unchanged(cfg, reference):
    want = json.loads(reference.read_text())
    got = pinned_programs(cfg)
    assert sorted(got) == sorted(want) and len(got) >= 20
    for k in want:
        assert got[k] == want[k], k


if __name__ == "__main__":  # write v3's reference (run with the code v3 must equal)
    REFERENCE_V3.write_text(json.dumps(pinned_programs(V3), sort_keys=True) + "\n")
