"""The arm world's tuning (``PhysicsConfig.arm_*``, ``ActionConfig.stop_at_program_end``):
the geom pairs and contact slots MJX compiles, the steps each action runs and ``templates.untuned``
(today's world, kept for the benchmark). The early stop's effect on outcomes is checked in C
(deterministic stepping) in ``sim/test_native_engine.py``; the tuned MJX's labels by the hand-built
scenes of ``sim/test_actions.py``."""
import dataclasses

import mujoco
import pytest
from mujoco.mjx._src import collision_driver as cd

from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim import world as wd

CFG = templates.ActionConfig()


def _pairs(phys):
    m = mujoco.MjModel.from_xml_string(wd.pair_xml("block", "cup", phys, arm=True))  # every pair: same geoms
    name = lambda g: m.geom(int(g)).name  # noqa: E731
    return m, [(name(a), name(b)) for a, b, _ in cd.geom_pairs(m)]


def _groups(m):
    """{((geom type, geom type), condim): pairs} of MJX's collision functions in model ``m``."""
    return {(tuple(int(t) for t in k.types), int(k.condim)): len(v) for k, v in cd._geom_groups(m).items()}


# contacts one pair gives in each of MJX's collision functions (geom types: 0 plane, 2 sphere,
# 3 capsule, 6 box; mujoco/mjx/_src/collision_driver.py, _COLLISION_FUNC)
NCON = {(0, 2): 1, (0, 6): 4, (2, 3): 1, (2, 6): 1, (3, 6): 2, (6, 6): 4}


def _slots(groups, cap):
    """Contact slots of ``_groups``' pairs: each function's pairs (at most ``cap`` of them
    unless a plane is involved) times the contacts one pair gives."""
    return sum((n if cap is None or 0 in types else min(n, cap)) * NCON[types] for (types, _), n in groups.items())


def test_run_steps_by_hand():
    """Each action runs to its measuring step + 1 (template sums, docs/actions.md); untuned: 815."""
    v1 = dataclasses.replace(CFG, programs="v1")
    steps = dict(zip(ACTIONS, templates.run_steps(v1)))
    assert steps == {"lift": 560, "move": 800, "pull": 755, "push": 755, "rake": 650, "take": 560,
                     "pour": 810, "slide": 810, "unobstruct": 755}
    assert set(templates.run_steps(templates.untuned(v1))) == {templates.N_STEPS}
    # v2: up to rest_hold (200) more steps to read the goals at rest
    assert dict(zip(ACTIONS, templates.run_steps(CFG))) == {a: n + CFG.rest_hold for a, n in steps.items()}
    assert set(templates.run_steps(templates.untuned(CFG))) == {templates.N_STEPS + CFG.rest_hold}


def test_tuned_world_pairs_and_slots():
    """The tuned world drops the pedestal's 7 pairs and caps MJX's broad phase per collision
    function at 6 pairs; ``untuned`` restores both."""
    m, pairs = _pairs(CFG.phys)
    mu, pairs_u = _pairs(templates.untuned(CFG).phys)
    ped = [p for p in pairs_u if "arm_pedestal" in p]
    assert len(ped) == 7
    assert not [p for p in pairs if "arm_pedestal" in p]
    assert set(pairs) == set(pairs_u) - set(ped)
    assert cd._numeric(m, "max_geom_pairs") == 6
    assert cd._numeric(mu, "max_geom_pairs") == -1
    # the pads keep condim 4: at 3 they would join the objects' box-box function and share
    # its 4 pairs (docs/actions.md, "Tuning": lift agreement 97.4 %, rake 91.0 %)
    pad = m.geom("arm_pad_l").id
    assert m.geom_condim[pad] == 4 == mu.geom_condim[pad]
    groups = _groups(m)
    # pads apart from the toy/base pairs; the toy's box against the other's 5 boxes and the
    # palm's against all 6 boxes share one function of 11 pairs, which the cap cuts to 6
    assert groups[((6, 6), 4)] == 12
    assert groups[((6, 6), 3)] == 11
    # contact slots MJX allocates: every pair's contacts untuned, 6 pairs per function tuned
    # (planes take no broad phase, so no cap), by hand from the pairs per function above
    assert len(cd.make_condim(mu)) == _slots(_groups(mu), None) == 1 + 4 * 4 + 2 * 4 + 8 + 11 * 4 + 1 + 6 * 2 + 12 * 4
    assert len(cd.make_condim(m)) == _slots(_groups(m), 6) == 1 + 4 * 4 + 2 * 4 + 6 + 6 * 4 + 6 * 4


def test_palm_modes_pairs():
    """``arm_palm_objects``: which palm pairs exist and in which collision function."""
    palm = lambda pairs: sorted(p for p in pairs if "arm_palm" in p)  # noqa: E731
    modes = {mode: _pairs(dataclasses.replace(CFG.phys, arm_palm_objects=mode))
             for mode in ("contact", "exclude_other", "frictionless")}
    with_obj = [p for p in palm(modes["contact"][1]) if any(g.startswith("obj_") for g in p)]
    assert len(with_obj) == 5  # the other's 5 boxes
    assert palm(modes["exclude_other"][1]) == sorted(set(palm(modes["contact"][1])) - set(with_obj))
    m, _ = modes["exclude_other"]
    groups = _groups(m)
    assert groups[((6, 6), 3)] == 6  # the cap keeps every pair
    m, pairs = modes["frictionless"]
    assert palm(pairs) == palm(modes["contact"][1])  # the same pairs, with the palm's condim 1
    pg = m.geom("arm_palm").id
    assert m.geom_condim[pg] == 1
    assert m.geom_priority[pg] == 1
    groups = _groups(m)
    assert groups[((6, 6), 1)] == 6
    assert groups[((6, 6), 3)] == 5
    with pytest.raises(UserError, match="'action.phys.arm_palm_objects' must be one of contact, frictionless, exclude_other, got 'off'"):
        dataclasses.replace(CFG.phys, arm_palm_objects="off")


def test_untuned_settle_world_unchanged():
    """The arm_* settings touch the action world only: the settle world's XML is the same."""
    other = dataclasses.replace(CFG.phys, arm_max_geom_pairs=-1, arm_pedestal_contacts=True)
    assert wd.pair_xml("block", "cup", CFG.phys) == wd.pair_xml("block", "cup", other)


def test_execute_batch_refuses_unknown_engine():
    with pytest.raises(UserError, match="unknown engine"):
        rollouts.execute_batch(None, CFG, engine="bullet")


def test_disagreement_classes_by_hand():
    """``benchmarks/disagreements.py``'s first-guess classes on hand-made rule quantities (cm)."""
    import numpy as np

    dis = _bench("disagreements")
    z = np.zeros(2)
    q = lambda **kw: {k: np.asarray(kw.get(k, z), float) for k in ("rise", "along", "dr", "drop", "moved", "apart")}  # noqa: E731
    # lift: one lifts both bodies 24 cm, the other nothing: a grasp, although the drops differ
    assert dis.classify("lift", CFG, q(rise=[24, 24], drop=[-24, -24]), q()) == "grasp"
    # push: both near the 10 cm threshold (9.0 and 11.5 cm)
    assert dis.classify("push", CFG, q(dr=[9.0, 12.0]), q(dr=[11.5, 12.0])) == "threshold"
    # rake: the toy tips in one (its centre 2.8 cm lower), pulled 11 cm against 1 cm
    assert dis.classify("rake", CFG, q(dr=[-11, 0], drop=[2.8, 0]), q(dr=[-1, 0])) == "tips"
    # move reads toy minus base along the sweep against 8 cm: 6.6 against 8.9 is a threshold,
    # although each body moved 25-34 cm; 20 against 2 cm is not
    near = dict(along=[31.3, 24.7], apart=[6.6, 6.6]), dict(along=[33.7, 24.8], apart=[8.9, 8.9])
    assert dis.classify("move", CFG, q(**near[0]), q(**near[1])) == "threshold"
    assert dis.classify("move", CFG, q(apart=[20, 20]), q(apart=[2, 2])) == "other"
    # the per-action quantities of a hand-made outcome (toy rises 6 cm, base 1 cm; along +x)
    o = {"com0": np.zeros((1, 2, 3)), "com_m": np.array([[[0.0, 0, 0.06], [0, 0, 0.01]]]),
         "com_end": np.array([[[0.5, 0, 0.0], [0.6, 0, 0.0]]])}
    qq = dis.quantities(o, 0, np.array([1.0, 0, 0]))
    np.testing.assert_allclose(qq["rise"], [6, 1]); np.testing.assert_allclose(qq["along"], [50, 60])
    np.testing.assert_allclose(qq["dr"], [50, 60]); np.testing.assert_allclose(qq["apart"], [-10, -10])
    np.testing.assert_allclose(qq["moved"], [np.hypot(0, 6)] * 2)


def _bench(name):
    import importlib.util
    from helpers import ROOT

    path = ROOT / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_chaos_shift_and_interval_by_hand():
    """``benchmarks/chaos.py``: the shift moves the toy's x only, and the Wilson interval of
    5 of 10 is the textbook 0.2366-0.7634."""
    import numpy as np

    from relaff_jax.sim.scenes import Scenes

    chaos = _bench("chaos")
    lo, hi = chaos.wilson(5, 10)
    assert abs(lo - 0.2366) < 1e-4
    assert abs(hi - 0.7634) < 1e-4
    assert chaos.wilson(10, 10)[1] == pytest.approx(1.0)
    q = np.arange(2 * 14, dtype=np.float32).reshape(2, 14)
    z = np.zeros(2)
    s = Scenes(pair=z, qpos0=q, qpos=q, qvel=q, relation=z, intended=z, cog_distance=z, at_rest=z)
    prep = rollouts.Prepared("lift", z, s, None, z, z, z)
    moved = chaos.shifted(prep, 7, 1e-6).scenes.qpos
    diff = moved - q
    assert np.all(diff[:, 7] > 0)
    assert np.count_nonzero(diff) == 2  # both rows, toy x only
    assert np.array_equal(prep.scenes.qpos, np.arange(28, dtype=np.float32).reshape(2, 14))  # not in place
