"""Scene sampling and MJX settling, at batch 8."""
import json
import subprocess
import sys
import textwrap

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax import cli, config
from relaff_jax.sim.native import reference as native
from relaff_jax.sim import objects as lib
from relaff_jax.sim import scenes as sc

from helpers.scenes import hand_built

B = 8


def test_hand_built_relations(scene_world, settle):
    w = scene_world
    cup_floor = dict(lib.get("cup").parts)["base"].size[2]
    rows = [
        ("block", "cup", (0.8, 0.0, cup_floor + 0.002), (0.8, 0.0, 0.0), 0.0),  # inside
        ("ball", "bowl", (0.6, 0.5, 0.012), (0.6, 0.5, 0.0), 0.5),  # inside
        ("block", "tray", (0.7, -0.3, 0.022), (0.7, -0.3, 0.0), 0.2),  # on top
        ("toy_car", "book", (1.0, 0.2, 0.032), (1.0, 0.2, 0.0), 0.0),  # on top
        ("block", "cup", (1.1, 0.0, 0.0), (0.8, 0.0, 0.0), 0.0),  # 30 cm away: beside
        ("ball", "tray", (0.5, 0.6, 0.0), (0.5, 0.9, 0.0), 0.0),  # beside
        # a ball dropped beyond the plate's edge (centre outside the plate) falls off
        ("ball", "plate", (0.9 + 0.125 + 0.02, -0.6, 0.02), (0.9, -0.6, 0.0), 0.0),
        ("block", "brick", (0.6, 0.0, 0.0), (0.4, 0.0, 0.0), 0.0),  # beside an obstacle
    ]
    pair, qpos0 = hand_built(w, rows)
    out = jax.device_get(settle(pair, qpos0, jnp.zeros(B, jnp.int32)))
    names = [sc.RELATIONS[r] for r in out.relation]
    assert names == ["inside", "inside", "on_top", "on_top", "beside", "beside", "beside", "beside"]
    assert out.at_rest.all()
    # the toy placed in the cup is still in it, at the floor
    toy_z = out.qpos[0, w.toy_qpos + 2]
    assert abs(toy_z - cup_floor) < 0.003


def covering_pairs(w):
    """One pair per non-toy object (toys cycle), so every one of the 29 objects appears."""
    toys = lib.members("toy")
    rows = []
    for i, other in enumerate(o for o in lib.OBJECT_NAMES if lib.get(o).group != "toy" or o == "cup"):
        toy = toys[i % len(toys)]
        toy = "ball" if toy == other else toy
        rows.append(w.pair_id(toy, other))
    return np.array(rows)


def test_every_object_and_pairing_settles(scene_world, settle):
    w = scene_world
    ids = covering_pairs(w)
    assert {n for i in ids for n in w.pairs[i][:2]} == set(lib.OBJECT_NAMES)
    ids = np.concatenate([ids, ids[: (-len(ids)) % B]])
    for c, start in enumerate(range(0, len(ids), B)):
        pair = jnp.asarray(ids[start:start + B], jnp.int32)
        qpos0, intended = sc.place(w, sc.SceneConfig(), jax.random.PRNGKey(c), pair)
        out = jax.device_get(settle(pair, qpos0, intended))
        nq, nv = w.mj_model.nq, w.mj_model.nv
        chex.assert_shape([out.qpos, out.qpos0], (B, nq))
        chex.assert_shape(out.qvel, (B, nv))
        chex.assert_shape([out.relation, out.cog_distance, out.at_rest], (B,))
        chex.assert_tree_all_finite((out.qpos, out.qvel, out.cog_distance))
        assert out.at_rest.all(), [w.pairs[i] for i in np.asarray(pair)[~out.at_rest]]
        # nothing fell through the table or left the workspace
        for q in (w.toy_qpos, w.obj_qpos):
            assert (out.qpos[:, q + 2] > -0.005).all()
            assert (np.linalg.norm(out.qpos[:, q:q + 2], axis=-1) < 2.0).all()
        # rakes stay in the gripper, non-toy+base scenes are never stacked
        pg = np.array([w.pairs[i][2] for i in np.asarray(pair)])
        assert (out.relation[pg != "toy+base"] == sc.BESIDE).all()
        held = pg == "toy+rake"
        np.testing.assert_array_equal(out.qpos[held, w.obj_qpos:w.obj_qpos + 7],
                                      out.qpos0[held, w.obj_qpos:w.obj_qpos + 7])


def test_sampling_distribution_and_determinism(scene_world):
    w = scene_world
    cfg = sc.SceneConfig()
    pair = sc.sample_pairs(jax.random.PRNGKey(0), np.arange(w.n_pairs), w, 3000)
    pg = sc.pair_table(w).pairing[np.asarray(pair)]
    np.testing.assert_allclose(np.bincount(pg) / 3000, [1 / 3] * 3, atol=0.04)
    q1, i1 = jax.device_get(sc.place(w, cfg, jax.random.PRNGKey(1), pair))
    q2, i2 = jax.device_get(sc.place(w, cfg, jax.random.PRNGKey(1), pair))
    np.testing.assert_array_equal(q1, q2)
    q3, _ = jax.device_get(sc.place(w, cfg, jax.random.PRNGKey(2), pair))
    assert not np.array_equal(q1, q3)
    # the other object lies in the half-disc 0.2..1.8 m around the robot
    xy = q1[pg != 2, w.obj_qpos:w.obj_qpos + 2]
    r = np.linalg.norm(xy, axis=-1)
    assert (r >= 0.2).all()
    assert (r <= 1.8).all()
    assert (xy[:, 0] >= 0).all()
    # about half the toy+base scenes are stacked (on top / inside)
    stacked = i1[pg == 0] != sc.BESIDE
    assert 0.4 < stacked.mean() < 0.6
    # obstacles are often between the robot and the toy
    obst = pg == 1
    t = q1[obst, w.toy_qpos:w.toy_qpos + 2]
    o = q1[obst, w.obj_qpos:w.obj_qpos + 2]
    between = (np.linalg.norm(o, axis=-1) < np.linalg.norm(t, axis=-1)) & (
        np.sum(o * t, -1) / np.linalg.norm(o, axis=-1) / np.linalg.norm(t, axis=-1) > 0.9)
    assert between.mean() > 0.4


@pytest.mark.slow  # compiles run_scenes at a second batch size
def test_run_scenes_one_compile_and_bitwise_reproducible(scene_world):
    s1, st1 = sc.run_scenes(12, seed=5, batch=B, world=scene_world, progress=False)
    s2, st2 = sc.run_scenes(12, seed=5, batch=B, world=scene_world, progress=False)
    # one placement program and one settle program per batch shape, whatever the pairs
    assert st1["compilations"] <= 2
    assert st2["compilations"] == 0
    chex.assert_trees_all_equal(s1, s2)
    assert s1.pair.shape == (12,)
    assert len({scene_world.pairs[p][2] for p in s1.pair}) == 3  # a mixed batch
    s3, _ = sc.run_scenes(12, seed=6, batch=B, world=scene_world, progress=False)
    assert not np.array_equal(s1.qpos, s3.qpos)


def test_native_mujoco_cross_check(scene_world, settle):
    """MJX settling against mujoco.mj_step on the same placements (24 mixed scenes here;
    benchmarks/settle.py --crosscheck runs a few hundred)."""
    w = scene_world
    pairs, q0s, outs = [], [], []
    for c in range(3):
        pair = sc.sample_pairs(jax.random.PRNGKey(100 + c), np.arange(w.n_pairs), w, B)
        qpos0, intended = sc.place(w, sc.SceneConfig(), jax.random.PRNGKey(200 + c), pair)
        outs.append(jax.device_get(settle(pair, qpos0, intended)))
        pairs.append(np.asarray(pair))
        q0s.append(np.asarray(qpos0))
    pair, q0 = np.concatenate(pairs), np.concatenate(q0s)
    rel = np.concatenate([o.relation for o in outs])
    qpos = np.concatenate([o.qpos for o in outs])
    q_c, rel_c = native.settle_native(w, pair, q0)
    assert np.mean(rel == rel_c) >= 0.9
    err = np.maximum(np.linalg.norm(qpos[:, w.toy_qpos:w.toy_qpos + 3] - q_c[:, w.toy_qpos:w.toy_qpos + 3], axis=-1),
                     np.linalg.norm(qpos[:, w.obj_qpos:w.obj_qpos + 3] - q_c[:, w.obj_qpos:w.obj_qpos + 3], axis=-1))
    assert np.median(err) < 0.005, err
    assert np.mean(err < 0.02) >= 0.85, err


@pytest.mark.slow  # settles scenes in a CLI run (a third compile)
def test_cli_scenes_json(capsys):
    assert cli.main(["scenes", "8", "--batch", "8", "--seed", "3", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert {"n", "relations", "pairings", "compilations", "seconds"} <= set(s)
    assert s["n"] == 8
    assert sum(s["relations"].values()) == 8
    assert sum(v["n"] for v in s["pairings"].values()) == 8


def test_bad_input():
    with pytest.raises(ValueError, match="n must be >= 1"):
        sc.run_scenes(0)
    with pytest.raises(config.ConfigError, match="unknown config key 'settle_stepz'"):
        config.override(sc.SceneConfig(), {"settle_stepz": 3})
    assert config.override(sc.SceneConfig(), {"settle_steps": 3}).settle_steps == 3
    assert cli.main(["scenes", "0", "--json"]) == 2


HANG_SCRIPT = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    from relaff_jax.sim import scenes, world
    w = world.build_world()
    place, settle, _ = scenes.jitted_scene_fns(w, scenes.SceneConfig(settle_steps=4))
    pair = scenes.sample_pairs(jax.random.PRNGKey(0), np.arange(w.n_pairs), w, 1024)
    out = settle(pair, *place(jax.random.PRNGKey(1), pair))
    out.qpos.block_until_ready()
    assert np.isfinite(np.asarray(out.qpos)).all()
    print("ok", out.qpos.shape)
""")


@pytest.mark.slow  # a batch of 1024 scenes
def test_batch_1024_does_not_deadlock():
    """jax 0.10 deadlocked vmapped mjx.step at batch 1024 on this machine (docs/facts.md, "JAX version").
    A separate process with a hard timeout: a deadlock cannot be interrupted in-process."""
    r = subprocess.run([sys.executable, "-c", HANG_SCRIPT], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "ok (1024, 14)" in r.stdout


def test_the_model_stack_is_built_on_first_use_and_eagerly_inside_a_trace():
    """``World.model`` (the pairs' MJX leaves stacked) is not built with the world (MuJoCo C
    needs only the native models) but when first read, here inside a jitted function being
    traced: the stack is concrete arrays, equal to one built outside any trace."""
    from relaff_jax.sim import world as wd

    w = wd._build_world.__wrapped__(config.PhysicsConfig(), False, lib.active())  # a new world, not the cached one
    assert "_stacked_models" not in w.__dict__
    seen = {}

    @jax.jit
    def f(x):
        seen["leaves"] = jax.tree_util.tree_leaves(w.model)
        return x + 1

    f(0.0)
    assert not any(isinstance(x, jax.core.Tracer) for x in seen["leaves"])
    model, axes, names = wd._stack_models(w.mj_models)
    assert names == w.batched_fields and len(names) > 0
    assert jax.tree_util.tree_structure(axes) == jax.tree_util.tree_structure(w.model_axes)
    assert all(np.array_equal(np.asarray(a), np.asarray(b))
               for a, b in zip(jax.tree_util.tree_leaves(model), seen["leaves"]))


def test_contact_masks_asked_for_inside_a_trace():
    """The MJX settle asks for its contact slots when it is traced (a run settling in MuJoCo C
    never pays for them): computed there, they equal those computed outside any trace."""
    from relaff_jax.sim import world as wd

    w = wd.build_world()
    sc.contact_masks.cache_clear()
    seen = {}

    @jax.jit
    def f(x):
        seen["masks"] = sc.contact_masks(w)
        return x + 1

    f(0.0)
    sc.contact_masks.cache_clear()
    outside = sc.contact_masks(w)
    assert all(isinstance(m, np.ndarray) and m.dtype == bool for m in seen["masks"])
    assert all(np.array_equal(a, b) for a, b in zip(seen["masks"], outside)) and outside[0].any()
