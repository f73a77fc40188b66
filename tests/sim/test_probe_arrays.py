"""``probe_arrays.ArrayProbe`` gives ``physics_probe.Probe``'s readings bit for bit, and the
replay's pad contacts read from the contact arrays (``native._pad_contacts``) equal the ones read
one ``d.contact[i]`` at a time: hand-built MuJoCo C scenes with presses, impacts, a rolling ball,
a weld to the hand, frictionless and elliptic contacts and two models in one probe."""
import mujoco
import numpy as np
import pytest

from relaff_jax.sim.native import reference as native
from relaff_jax.sim.native.probe import Probe
from relaff_jax.sim.native.probe_arrays import ArrayProbe

# A box and a ball; above them a weightless "hand" (the probes' arm_hand) on a slide, pushed down;
# the ball falls onto the box's edge and rolls off; a weld between the hand and the ball that
# the test switches on for a while (the grasp lock's equality).
SCENE = """
<mujoco>
  <option timestep="0.004" cone="{cone}"/>
  <worldbody>
    <geom name="table" type="plane" size="2 2 0.1" condim="{table_condim}"/>
    <body name="toy" pos="0.04 0.03 0.25"><freejoint/>
      <geom name="ball" type="sphere" size="0.03" mass="0.1" condim="{toy_condim}"/></body>
    <body name="obj" pos="0 0 0.048"><freejoint/>
      <geom name="box" type="box" size="0.05 0.05 0.05" mass="0.4" condim="6"/>
      <geom name="lid" type="box" pos="0 0 0.052" size="0.03 0.03 0.004" mass="0.05" condim="3"/></body>
    <body name="arm_hand" pos="0.0 0.0 0.16" gravcomp="1">
      <joint name="slide" type="slide" axis="0 0 1" damping="40"/>
      <geom name="palm" type="box" size="0.03 0.03 0.015" mass="0.5"/>
    </body>
  </worldbody>
  <equality><weld body1="arm_hand" body2="toy" active="false"/></equality>
  <actuator><motor joint="slide" gear="1"/></actuator>
</mujoco>
"""


def _model(cone="pyramidal", table_condim=3, toy_condim=6):
    return mujoco.MjModel.from_xml_string(SCENE.format(cone=cone, table_condim=table_condim, toy_condim=toy_condim))


def _both(models, steps=400):
    """Run one rollout per model with both probes observing every step; their results."""
    toy = mujoco.mj_name2id(models[0], mujoco.mjtObj.mjOBJ_BODY, "toy")
    obj = mujoco.mj_name2id(models[0], mujoco.mjtObj.mjOBJ_BODY, "obj")
    ref = Probe(len(models), toy, obj, models[0].opt.timestep)
    new = ArrayProbe(len(models), toy, obj, models[0].opt.timestep)
    for b, m in enumerate(models):
        d = mujoco.MjData(m)
        for t in range(steps):
            d.ctrl[:] = -30.0 * min(1.0, t / 150)  # the palm comes down onto the lid and presses
            d.eq_active[0] = 200 <= t < 260  # the ball welded to the hand for a while
            mujoco.mj_step(m, d)
            ref(b, t, m, d)
            new(b, t, m, d)
    return ref, new


def _same(ref: Probe, new: ArrayProbe, measure):
    a, b = ref.result(measure), new.result(measure)
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype, k
        assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), (k, a[k], b[k])
    return a


@pytest.mark.parametrize("cone,table_condim,toy_condim", [("pyramidal", 3, 6), ("pyramidal", 1, 1), ("pyramidal", 3, 4),
                                                           ("elliptic", 3, 6)])
def test_array_probe_equals_probe(cone, table_condim, toy_condim):
    m1 = _model(cone, table_condim, toy_condim)
    m2 = _model(cone, table_condim, toy_condim)
    m2.body_mass[2] = 0.8  # another model of the pair: a heavier box
    ref, new = _both([m1, m2])
    for measure in (0, 230, 399, 400, np.array([230, 120])):  # in and out of the weld, past the end
        a = _same(ref, new, measure)
    # the readings exercise every branch: palm presses, impacts, a weld, speeds
    assert a["palm_contact"].all() and (a["peak_force_weights"] > 1).all() and (a["max_penetration_m"] > 0).all()
    assert (a["palm_top_steps"] > 0).all() and (a["palm_top_force_n"] > 0).all()  # the palm down on the lid
    assert a["held_toy"][0] and not a["held_toy"][1]
    assert len({tuple(x) for x in ref.load}) == 2  # the two models press differently


def test_an_unobserved_rollout_reads_as_probe():
    m = _model()
    toy, obj = 1, 2
    ref, new = Probe(2, toy, obj, m.opt.timestep), ArrayProbe(2, toy, obj, m.opt.timestep)
    d = mujoco.MjData(m)
    for t in range(30):
        mujoco.mj_step(m, d)
        ref(1, t, m, d)
        new(1, t, m, d)
    _same(ref, new, 10)


def test_pad_contacts_from_arrays_equal_per_contact_reads():
    m = _model()
    d = mujoco.MjData(m)
    gid = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n)
    cases = [(gid("palm"), {gid("lid")}), (gid("box"), {gid("table"), gid("ball")}), (gid("ball"), {gid("palm")})]
    seen = 0
    for t in range(400):
        d.ctrl[:] = -30.0 * min(1.0, t / 150)
        mujoco.mj_step(m, d)
        for pad, geoms in cases:
            cons = [c for c in d.contact[:d.ncon]
                    if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms)]
            dist, normal = native._pad_contacts(d, pad, geoms)
            assert np.array_equal(dist, np.array([c.dist for c in cons]).reshape(-1))
            assert np.array_equal(normal, np.array([np.asarray(c.frame[:3]) for c in cons]).reshape(-1, 3))
            seen += len(cons)
    assert seen > 100


# The palm from the side and from above: a 1 kg box on the table and a weightless "hand" on a
# slide along `axis`, its palm at the box's side (x) or over its top (z), pushed against it by a
# motor ramped to 4 N, under the box's friction (1 x 9.81 N).
PALM_SIDE = """
<mujoco>
  <option timestep="0.004" cone="pyramidal"/>
  <worldbody>
    <geom name="table" type="plane" size="2 2 0.1"/>
    <body name="toy" pos="0.5 0.5 0.03"><freejoint/>
      <geom type="sphere" size="0.03" mass="0.1"/></body>
    <body name="obj" pos="0 0 0.05"><freejoint/>
      <geom type="box" size="0.05 0.05 0.05" mass="1.0"/></body>
    <body name="arm_hand" pos="{pos}" gravcomp="1">
      <joint name="slide" type="slide" axis="{axis}" damping="50"/>
      <geom name="palm" type="box" size="0.03 0.03 0.015" mass="0.5"/>
    </body>
  </worldbody>
  <actuator><motor joint="slide" gear="1"/></actuator>
</mujoco>
"""


@pytest.mark.parametrize("where", ["side", "top"])
def test_palm_contacts_split_by_their_normal(where):
    """The palm pushing the box's side with 4 N reads only side contacts (the normal horizontal);
    pressing its top with 4 N only top contacts (the normal vertical); both probes the same bits."""
    pos, axis = ("-0.0809 0 0.05", "1 0 0") if where == "side" else ("0 0 0.1149", "0 0 -1")
    m = mujoco.MjModel.from_xml_string(PALM_SIDE.format(pos=pos, axis=axis))
    toy, obj = 1, 2
    ref, new = Probe(1, toy, obj, m.opt.timestep), ArrayProbe(1, toy, obj, m.opt.timestep)
    d = mujoco.MjData(m)
    for t in range(600):
        d.ctrl[:] = 4.0 * min(1.0, t / 300)
        mujoco.mj_step(m, d)
        ref(0, t, m, d)
        new(0, t, m, d)
    r = _same(ref, new, 599)
    hit, miss = ("side", "top") if where == "side" else ("top", "side")
    assert r[f"palm_{hit}_steps"][0] > 400 and r[f"palm_{miss}_steps"][0] == 0 and r[f"palm_{miss}_force_n"][0] == 0.0
    assert r[f"palm_{hit}_steps"][0] == r["palm_steps"][0] and r["palm_contact"][0]
    # the motor's 4 N less the slide's damping: the pushed box creeps on MuJoCo's soft friction
    # (about 2 mm/s), so the palm follows it and its damper takes 50 x that speed
    assert r[f"palm_{hit}_force_n"][0] == pytest.approx(4.0 - 50 * abs(d.qvel[-1]), rel=1e-3)
    assert r[f"palm_{hit}_force_n"][0] == pytest.approx(r["palm_force_n"][0], rel=1e-12)
    assert r["speed_other"][0] < 0.005


def test_from_above_is_the_stated_angle_either_sign():
    from relaff_jax.sim import physics_bounds as bounds
    from relaff_jax.sim.native.probe import from_above

    c = lambda deg: np.cos(np.radians(deg))
    assert bounds.PALM_ABOVE_DEG == 45.0
    got = from_above(np.array([1.0, -1.0, c(44), -c(44), c(46), -c(46), 0.0, bounds.PALM_ABOVE_COS]))
    assert got.tolist() == [True, True, True, True, False, False, False, True]
