"""The native engine (``sim/native/batch.py``): planned programs executed by ``mujoco.batch``
equal the scene-by-scene MuJoCo C replay (``native.reference.replay_native``) bit for bit, for every
action, at any thread count and chunk size; its pieces checked by hand; the rollout sampler's
``engine`` argument."""
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest


from relaff_jax.constants import ACTIONS, action_id
from relaff_jax.errors import UserError
from relaff_jax.sim import arm as A
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim.native import batch as native_batch, program as native_program, reference as native
from relaff_jax.sim.native import settle as native_settle
from relaff_jax.sim import objects as lib
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd

from helpers.scenes import BASE_ROWS, OBST_ROWS, RAKE_ROWS, hand_built

CFG = templates.ActionConfig()
FIELDS = ("label", "com0", "com_m", "com_end", "qpos_final", "reach_after", "settled")


def test_weld_relpose_np_hand_worked():
    """Body 2 in body 1's frame: hand-worked poses, float32 JAX within 1e-6, rows of a batch
    bit-identical to single calls."""
    f = native_program.weld_relpose_np
    eye = np.array([1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(f(np.zeros(3), eye, np.array([1.0, 2.0, 3.0]), eye), [1, 2, 3, 1, 0, 0, 0])
    # hand turned 90 deg about z: world +x is the hand's -y; the body's yaw 90 deg is its identity
    qz = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(f(np.array([1.0, 0, 0]), qz, np.array([2.0, 0, 0]), qz), [0, -1, 0, 1, 0, 0, 0],
                               atol=1e-15)
    np.testing.assert_allclose(f(np.zeros(3), 2 * eye, np.zeros(3), qz)[3:], qz, atol=1e-15)  # q1 normalised
    rng = np.random.default_rng(0)
    p1, p2 = rng.normal(size=(2, 6, 3))
    q1, q2 = rng.normal(size=(2, 6, 4))
    q2 /= np.linalg.norm(q2, axis=1, keepdims=True)
    got = f(p1, q1, p2, q2)
    want = jax.vmap(A.weld_relpose)(*(jnp.asarray(x, jnp.float32) for x in (p1, q1, p2, q2)))
    np.testing.assert_allclose(got, np.asarray(want), atol=2e-6)
    for i in range(6):
        np.testing.assert_array_equal(f(p1[i], q1[i], p2[i], q2[i]), got[i])


def test_sensor_models_same_physics():
    """The engine's models are the world's plus four pad contact sensors: the same steps, bit
    for bit."""
    p = [(t, o) for t, o, _ in lib.pairs()].index(("block", "cup"))
    m0 = mujoco.MjModel.from_xml_string(wd.pair_xml("block", "cup", CFG.phys, arm=True))  # World.mj_models[p]
    m1 = native_batch.sensor_models(CFG.phys, [p])[0]
    assert m1.nsensor == 4
    assert m0.nsensor == 0
    assert m1.nq == m0.nq
    assert m1.neq == m0.neq
    d0, d1 = mujoco.MjData(m0), mujoco.MjData(m1)
    j = m0.joint("obj_free")
    for d in (d0, d1):  # the cup dropped from 5 cm, spinning
        d.qpos[j.qposadr[0]:j.qposadr[0] + 3] = [0.8, 0.0, 0.05]
        d.qvel[j.dofadr[0] + 5] = 3.0
    for _ in range(50):
        mujoco.mj_step(m0, d0)
        mujoco.mj_step(m1, d1)
    np.testing.assert_array_equal(d0.qpos, d1.qpos)
    np.testing.assert_array_equal(d0.qvel, d1.qvel)


@pytest.fixture(scope="module")
def planned():
    """Hand-built scenes (helpers/scenes.py) settled in C, and the JAX plan of every action."""
    w = wd.build_world(CFG.phys)
    prepare_fn, _ = rollouts.jitted_stage_fns(CFG)
    out = {}
    for action in ACTIONS:
        rows = {"unobstruct": OBST_ROWS, "rake": RAKE_ROWS}.get(action, BASE_ROWS)
        pair, q0 = hand_built(w, rows)
        q, _ = native.settle_native(w, np.asarray(pair), np.asarray(q0))
        q = np.asarray(q, np.float32)
        plan, before = jax.device_get(prepare_fn(action_id(action), jnp.asarray(pair), jnp.asarray(q)))
        qvel = np.random.default_rng(action_id(action)).normal(0, 1e-3, (len(q), 12)).astype(np.float32)
        out[action] = (np.asarray(pair), q, qvel, plan, before)
    return out


@pytest.mark.slow  # shares the plan compile of the replay test
def test_sensors_read_the_pad_contacts(planned):
    """The grasp test on the contact sensors (``native.batch._touching``) equals the one on C
    contacts (``native.both_pads``) at every step of a lift that squeezes the base and of a
    take that grips the toy (without the lock, so the pads keep pressing)."""
    world = wd.build_world(CFG.phys, arm=True)
    wl = native.welds(world)
    arm = A.arm_from_model(world.mj_model)
    # lift: the block in the cup (the cup gripped); take: the block on the tray (the block)
    for action, i, body, geoms in (("lift", 0, "obj", wl.obj_geoms), ("take", 1, "toy", wl.toy_geoms)):
        pair, q, qvel, plan, _ = planned[action]
        s = slice(i, i + 1)
        inp = native_program.program_inputs(CFG, action_id(action), q[s], qvel[s], plan.q_way[s], plan.grip_way[s])
        m = native_batch.sensor_models(CFG.phys, pair[s])[0]
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.eq_active[:] = inp.qpos[0], inp.qvel[0], inp.eq_active[0]
        mujoco.mj_forward(m, d)
        seen = 0
        for t in range(templates.N_STEPS):
            c = native.both_pads(d, arm, CFG, set(geoms.tolist()))
            got = native_batch._touching(d.sensordata[None], d.geom_xmat[None], m, body, CFG)[0]
            assert c == got, (action, t)
            seen += c
            d.ctrl[:] = inp.ctrl[0, t]
            mujoco.mj_step(m, d)
        assert seen > 50, (action, seen)


@pytest.mark.slow  # plan compile (~30 s) and nine C replays
@pytest.mark.parametrize("action", ACTIONS)
def test_engine_equals_replay(planned, action):
    pair, q, qvel, plan, before = planned[action]
    idx = np.arange(4) if action != "unobstruct" else np.array([0, 1, 3, 4])
    sub = plan._replace(**{f: getattr(plan, f)[idx] for f in ("q_way", "grip_way", "feasible", "direction",
                                                               "ik_error")})
    ref = native.replay_native(action, CFG, pair[idx], q[idx], qvel[idx],
                               dict(q_way=sub.q_way, grip_way=sub.grip_way, feasible=sub.feasible,
                                    direction=sub.direction))
    got = native_batch.execute_native(action, CFG, pair[idx], q[idx], qvel[idx], sub, before[idx])
    for f in FIELDS:
        np.testing.assert_array_equal(got[f], ref[f], err_msg=f"{action} {f}")
    assert got["label"].dtype == bool
    assert got["qpos_final"].dtype == np.float32
    # the objects moved: the equality is not that of programs that did nothing
    moved = np.linalg.norm(got["com_end"] - got["com0"], axis=-1).max()
    assert moved > 0.02, (action, moved)


@pytest.mark.slow  # shares the plan compile of the replay test
def test_engine_independent_of_threads_and_chunks(planned):
    for action in ("take", "pour", "rake"):  # toy lock, base lock, held tool
        pair, q, qvel, plan, before = planned[action]
        runs = [native_batch.execute_native(action, CFG, pair, q, qvel, plan, before, nthread=t, chunk=c)
                for t, c in ((1, None), (2, 3), (2, 1))]
        for r in runs[1:]:
            for f in FIELDS:
                np.testing.assert_array_equal(r[f], runs[0][f], err_msg=f"{action} {f}")
    with pytest.raises(UserError, match="nthread and chunk must be >= 1"):
        native_batch.execute_native("lift", CFG, pair, q, qvel, plan, before, chunk=0)


def test_rollout_engine_argument():
    with pytest.raises(UserError, match="unknown engine 'gpu'; valid: mjx, native"):
        rollouts.make_rollout_fn("lift", 4, engine="gpu")
    with pytest.raises(UserError, match="nthread must be >= 1, got 0"):
        rollouts.make_rollout_fn("lift", 4, engine="native", nthread=0)


@pytest.mark.slow  # compiles placement, settling and planning (MJX) at batch 8, as test_actions does
def test_tiny_native_dataset_through_the_cli(tmp_path):
    """`relaff generate --engine native`: a balanced tiny dataset that records its engine."""
    from relaff_jax import data as ds
    from relaff_jax.cli import main
    from relaff_jax.io import read_json

    out = tmp_path / "lift"
    assert main(["generate", "lift", "--samples", "2", "--batch", "8", "--max-rollouts", "64", "--engine", "native",
                 "--out", str(out), "--set", "dataset.borrow_fraction=1.0", "--set", "dataset.distance_bins=2",
                 "--json"]) == 0
    assert read_json(out / ds.SIDECAR)["engine"] == "native"
    d = ds.load_dataset(out)
    assert len(d["label"]) == 2
    assert d["label"].sum() == 1
    assert d["simulated"][d["label"]].all()


@pytest.mark.slow  # compiles placement and settling (MJX)
def test_native_rollout_fn_equals_replay(scene_world):
    """``make_rollout_fn(engine="native")``: the dataset fields, scenes settled in C equal to
    ``settle_native``, and labels and final states equal to the C replay of the same sampled,
    settled and planned scenes."""
    B = 8
    key = jax.random.PRNGKey(5)
    out = rollouts.make_rollout_fn("pull", B, engine="native")(key, B)
    kp, ks, _ = jax.random.split(key, 3)
    place, settle, _ = sc.jitted_scene_fns(scene_world)
    pair = sc.sample_pairs(kp, rollouts.allowed_pairs(scene_world, "pull"), scene_world, B)
    q0, intended = jax.device_get(place(ks, pair))
    s = native_settle.settle_batch(scene_world, np.asarray(pair), q0, intended)  # the engine settles in C
    q_ref, rel_ref = native.settle_native(scene_world, np.asarray(pair), q0)
    np.testing.assert_array_equal(out["pair"], np.asarray(pair))
    np.testing.assert_array_equal(out["qpos_settled"], q_ref.astype(np.float32))
    np.testing.assert_array_equal(out["relation"], rel_ref)
    run = np.flatnonzero(out["feasible"])
    assert 0 < len(run) < B, out["feasible"]
    assert np.array_equal(out["simulated"], out["feasible"]), out["feasible"]
    prepare_fn, _ = rollouts.jitted_stage_fns(CFG)
    plan, _ = jax.device_get(prepare_fn(action_id("pull"), pair, s.qpos))
    ref = native.replay_native("pull", CFG, np.asarray(pair)[run], np.asarray(s.qpos)[run], np.asarray(s.qvel)[run],
                               dict(q_way=plan.q_way[run], grip_way=plan.grip_way[run], feasible=plan.feasible[run],
                                    direction=plan.direction[run]))
    np.testing.assert_array_equal(out["label"][run], ref["label"])
    np.testing.assert_array_equal(out["qpos_final"][run], ref["qpos_final"])
    assert not out["label"][~out["feasible"]].any()
    np.testing.assert_array_equal(out["qpos_final"][~out["feasible"]], out["qpos_settled"][~out["feasible"]])
    assert out["label"].dtype == bool
    assert out["rollout_id"].dtype == np.int64


@pytest.mark.parametrize("nthread", [1, 2])
def test_settle_batch_equals_settle_native(scene_world, nthread):
    """The C settle on a thread pool equals ``settle_native`` (one MjData per scene, rake
    pinned) bit for bit, with held rakes and without, at any thread count."""
    for seed, allowed in ((0, np.arange(scene_world.n_pairs)), (1, rollouts.allowed_pairs(scene_world, "lift"))):
        pair = np.asarray(sc.sample_pairs(jax.random.PRNGKey(seed), allowed, scene_world, 12))
        q0, intended = jax.device_get(sc.jitted_scene_fns(scene_world)[0](jax.random.PRNGKey(seed + 7), pair))
        got = native_settle.settle_batch(scene_world, pair, q0, intended, nthread=nthread)
        q, rel = native.settle_native(scene_world, pair, q0)
        np.testing.assert_array_equal(got.qpos, q.astype(np.float32))
        np.testing.assert_array_equal(got.relation, rel)
        assert got.qvel.dtype == np.float32
        assert got.at_rest.dtype == bool
        assert got.cog_distance.shape == (12,)
    assert seed == 1
    assert not any(scene_world.pairs[p][2] == "toy+rake" for p in pair)  # the nstep branch ran


@pytest.mark.slow  # C executions of two actions, full and stopped
@pytest.mark.parametrize("action", ["lift", "push"])
def test_early_stop_in_c(planned, action):
    """Same world, with and without the early stop, in C: lift's outcome is read at the
    measuring step, so the centres of mass there and the labels are bit-identical (only the
    final state moves on); push reads the end, which is the program's end when stopped."""
    pair, q, qvel, plan, before = planned[action]
    # v1's fixed reads (v2 reads at rest, where the stop changes nothing: checked below)
    v1 = templates.ActionConfig(programs="v1")
    full = templates.ActionConfig(programs="v1", stop_at_program_end=False)
    a = native_batch.execute_native(action, v1, pair, q, qvel, plan, before)
    b = native_batch.execute_native(action, full, pair, q, qvel, plan, before)
    a2 = native_batch.execute_native(action, CFG, pair, q, qvel, plan, before)
    b2 = native_batch.execute_native(action, templates.ActionConfig(stop_at_program_end=False), pair, q, qvel,
                                     plan, before)
    for f in FIELDS:
        np.testing.assert_array_equal(a2[f], b2[f], err_msg=f)
    np.testing.assert_array_equal(a["com_m"], b["com_m"])
    if action == "lift":
        np.testing.assert_array_equal(a["label"], b["label"])
        assert a["label"].any()  # a lift that worked, not programs that did nothing
    else:
        np.testing.assert_array_equal(a["com_end"], a["com_m"])  # stopped at the measuring step
        assert not np.array_equal(a["qpos_final"], b["qpos_final"])


def test_stretch_ends_hand_worked():
    """``_stretch_end`` stops a stretch at the next step needing a decision, where the closing
    flag flips (with a grasp), at the rest window's ends, and after ``STRETCH_AFTER_MEASURE``
    steps once the run may stop; ``_checks`` names the steps needing one."""
    from types import SimpleNamespace as NS
    T = 100
    guard, closing = np.zeros(T, bool), np.zeros(T, bool)
    guard[10:14] = True
    closing[20:30] = True
    inp = NS(guard=guard, closing=closing, n_run=T, measure=40)
    stopped, eq = np.zeros(3, bool), np.zeros((3, 2))
    grasp = (1, None, "toy")
    lo, hi = 35, 80
    end = lambda t, g=grasp: native_batch._stretch_end(inp, t, g, stopped, eq, lo, hi)
    assert native_batch._checks(inp, 10, grasp, stopped, eq)  # a descent still going
    assert end(0) == 10
    assert not native_batch._checks(inp, 10, grasp, np.ones(3, bool), eq)  # every descent stopped
    assert native_batch._checks(inp, 20, grasp, stopped, eq)  # a grasp not locked
    assert native_batch._checks(inp, 20, None, stopped, eq) is False  # no grasp: nothing to lock
    assert end(14) == 20
    assert end(14, None) == 35  # no grasp: the closing flag does not cut; the window's start does
    locked = eq.copy()
    locked[:, 1] = 1.0
    assert native_batch._stretch_end(inp, 20, grasp, stopped, locked, lo, hi) == 30  # locked: to the flip
    assert end(30) == 35
    cap = native_batch.STRETCH_AFTER_MEASURE
    assert end(35) == 40 + cap  # in the window: at most the cap past the measuring step
    assert end(40) == 40 + cap
    assert end(70) == 80 + 1  # hi is the window's last step
    assert end(81) == T


@pytest.mark.slow  # shares the plan compile of the replay test
def test_stretches_equal_one_step_at_a_time(planned, monkeypatch):
    """The stretches stepped in one ``Batch.rollout`` call give the bits of stepping every
    control step alone (every step made a decision step), for a toy lock with a guarded
    descent, a base lock and a plain push; and they do replace most single steps."""
    import mujoco.batch
    calls = {"step": 0, "rollout": 0}
    step, rollout = mujoco.batch.Batch.step, mujoco.batch.Batch.rollout

    def counted(name, fn):
        def call(self, *a, **k):
            calls[name] += 1
            return fn(self, *a, **k)
        return call
    monkeypatch.setattr(mujoco.batch.Batch, "step", counted("step", step))
    monkeypatch.setattr(mujoco.batch.Batch, "rollout", counted("rollout", rollout))
    for action in ("take", "pour", "push"):
        pair, q, qvel, plan, before = planned[action]
        calls.update(step=0, rollout=0)
        fast = native_batch.execute_native(action, CFG, pair, q, qvel, plan, before)
        n_single, n_rollout = calls["step"], calls["rollout"]
        with monkeypatch.context() as m:
            m.setattr(native_batch, "_checks", lambda *a: True)
            slow = native_batch.execute_native(action, CFG, pair, q, qvel, plan, before)
        assert calls["rollout"] == n_rollout, action  # the one-step run made no rollout
        for f in FIELDS:
            np.testing.assert_array_equal(fast[f], slow[f], err_msg=f"{action} {f}")
        assert n_rollout > 0 and n_single < calls["step"] - n_single, (action, n_single, calls["step"])


@pytest.mark.slow  # shares the plan compile of the replay test
def test_benchmark_former_chunk_equals_the_engine(planned, monkeypatch):
    """``benchmarks/native_stretches.py`` times the engine against the chunk function it replaced,
    kept verbatim there: that copy still runs and gives the engine's bits (else the benchmark's
    ratio would compare other work)."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "native_stretches.py"
    spec = importlib.util.spec_from_file_location("native_stretches", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    for action in ("lift", "unobstruct"):  # a guarded base grasp; the toy reached before and after
        pair, q, qvel, plan, before = planned[action]
        new = native_batch.execute_native(action, CFG, pair, q, qvel, plan, before)
        with monkeypatch.context() as m:
            m.setattr(native_batch, "_run_chunk", bench.former_run_chunk)
            old = native_batch.execute_native(action, CFG, pair, q, qvel, plan, before)
        for f in FIELDS:
            np.testing.assert_array_equal(new[f], old[f], err_msg=f"{action} {f}")
