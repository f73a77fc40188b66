"""Scenes several test files share: hand-built rows ``(toy, other, toy xyz, other xyz, other
yaw)`` and the nine actions' obvious cases among them (settled in MJX by sim/test_actions.py,
in C by sim/test_native_engine.py), a library pair posed by hand in MuJoCo C (perception), and
rollouts of real settled scenes labelled by their relation (perception, report, notebooks)."""
import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from relaff_jax.sim import objects as lib
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd

CUP_FLOOR = dict(lib.get("cup").parts)["base"].size[2]
HELD = wd.PhysicsConfig().held_rake_pos


def quat(yaw):
    return [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]


# (toy, other, toy xyz, other xyz, other yaw); toy+base scenes shared by seven actions
BASE_ROWS = [
    ("block", "cup", (0.8, 0.0, CUP_FLOOR + 0.002), (0.8, 0.0, 0.0), 0.0),  # 0 inside
    ("block", "tray", (0.7, -0.3, 0.022), (0.7, -0.3, 0.0), 0.2),  # 1 on top of a flat base
    ("block", "cup", (0.8, 0.45, 0.0), (0.8, 0.0, 0.0), 0.0),  # 2 beside, 45 cm apart
    ("ball", "bowl", (0.6, 0.5, 0.012), (0.6, 0.5, 0.0), 0.5),  # 3 inside
    ("block", "plate", (1.55, -0.3, 0.0), (0.9, -0.6, 0.0), 0.0),  # 4 beside, toy out of reach
    ("toy_car", "book", (0.9, 0.2, 0.032), (0.9, 0.2, 0.0), 0.0),  # 5 on top
    ("block", "open_box", (0.75, -0.15, 0.0), (0.75, 0.05, 0.0), 0.0),  # 6 beside, 7.5 cm gap
    # 7 beside, far; the car's long side 25 deg off take's closing axis (11 cm across the
    # 10 cm opening: the pads land on its corners and may turn it into the gap)
    ("toy_car", "tray", (0.604, -0.667, 0.0), (0.5, 0.95, 0.0), 0.0),
]
OBST_ROWS = [
    ("block", "brick", (0.8, 0.0, 0.0), (0.6, 0.0, 0.0), 0.0),  # 0 brick in the way
    ("block", "brick", (0.8, 0.0, 0.0), (0.6, 0.5, 0.0), 0.0),  # 1 brick far off the line
    ("block", "bottle", (1.5, 0.0, 0.0), (1.3, 0.0, 0.0), 0.0),  # 2 toy out of reach
    ("ball", "vase", (0.7, -0.4, 0.0), (0.4, 0.3, 0.0), 0.0),  # 3 vase far off the line
] * 2
RAKE_ROWS = [
    ("ball", "rake_short", (0.9, 0.3, 0.0), HELD, 0.0),  # 0 within reach of the rake
    ("block", "rake_long", (1.45, -0.2, 0.0), HELD, 0.0),  # 1 beyond the arm, within the rake's
    ("ball", "rake_long", (1.75, 0.0, 0.0), HELD, 0.0),  # 2 beyond arm + rake: infeasible
    ("block", "rake_short", (0.3, 0.1, 0.0), HELD, 0.0),  # 3 close to the robot: v3 refuses it (axis)
] * 2

def posed(w, toy, other, txyz, oxyz, tyaw=0.0, tilt=0.0):
    """(pair id, object qpos (14,) float32) of a hand-posed scene: the toy at ``txyz`` turned
    ``tyaw`` about z (or tilted ``tilt`` about its y axis: a car's long side goes up), the other
    object at ``oxyz``, unturned."""
    q = np.array(w.mj_model.qpos0, np.float32)[:14]
    q[0:7] = [*txyz, *quat(tyaw)]
    if tilt:
        q[3:7] = [np.cos(tilt / 2), 0.0, np.sin(tilt / 2), 0.0]
    q[7:14] = [*oxyz, *quat(0.0)]
    return w.pair_id(toy, other), q


def posed_program(action, cfg, toy, other, txyz, oxyz, tyaw=0.0, tilt=0.0):
    """The motor program of ``action`` (``programs.program``, one scene, no simulation) in the
    scene ``posed`` makes, the arm tables and the (toy, other) ``bodies.Body`` views."""
    from relaff_jax.sim import bodies, planning, programs

    st = planning.setup(cfg)
    p, q = posed(st.world, toy, other, txyz, oxyz, tyaw, tilt)
    body = bodies.bodies(st.geo, jnp.int32(p), jnp.asarray(q))
    return programs.program(action, st.arm, cfg, st.geo, jnp.int32(p), jnp.asarray(q)), st.arm, body


def hand_built(w, rows):
    """rows: (toy, other, toy_xyz, obj_xyz, obj_yaw) -> (pair, qpos0) at batch len(rows)."""
    pair, qpos = [], []
    for toy, other, txyz, oxyz, oyaw in rows:
        q = np.array(w.mj_model.qpos0, np.float32)
        q[w.toy_qpos:w.toy_qpos + 7] = [*txyz, *quat(0.3)]
        q[w.obj_qpos:w.obj_qpos + 7] = [*oxyz, *quat(oyaw)]
        pair.append(w.pair_id(toy, other))
        qpos.append(q)
    return jnp.asarray(pair, jnp.int32), jnp.asarray(np.stack(qpos))


def library_scene(toy, other, toy_pose, other_pose):
    """``(model, data, seg)`` of ``world.pair_xml(toy, other)`` with both free joints posed
    (xyz + quaternion) and forwarded; ``seg (ngeom,)``: 1 toy, 2 other, 0 the rest."""
    m = mujoco.MjModel.from_xml_string(wd.pair_xml(toy, other))
    d = mujoco.MjData(m)
    d.qpos[m.jnt_qposadr[0]:m.jnt_qposadr[0] + 7] = toy_pose
    d.qpos[m.jnt_qposadr[1]:m.jnt_qposadr[1] + 7] = other_pose
    mujoco.mj_forward(m, d)
    seg = np.zeros(m.ngeom, np.int32)
    seg[m.geom_bodyid == 1] = 1
    seg[m.geom_bodyid == 2] = 2
    return m, d, seg


def scene_rollout_fn(w, settle):
    """Rollouts of real settled toy+base scenes; label: the toy ended on top of / inside the base."""
    allowed = np.array([i for i, p in enumerate(w.pairs) if p[2] == "toy+base"])

    def rollout(key, batch):
        kp, ks = jax.random.split(key)
        pair = sc.sample_pairs(kp, allowed, w, batch)
        out = jax.device_get(settle(pair, *sc.place(w, sc.SceneConfig(), ks, pair)))
        bits = np.asarray(jax.random.randint(ks, (batch,), 0, 2**31 - 1))
        return {"label": out.relation != sc.BESIDE, "relation": out.relation, "cog_distance": out.cog_distance,
                "pair": out.pair, "toy": np.array([w.pairs[p][0] for p in out.pair]),
                "other": np.array([w.pairs[p][1] for p in out.pair]), "qpos_settled": out.qpos,
                "rollout_id": bits.astype(np.int64)}

    return rollout


def plan_rows(action, cfg, pair, qpos, batch=8):
    """The motor programs of a few hand-built scenes, as a dataset's rollouts get them: the
    session's jitted ``prepare_fn`` (``rollouts.jitted_stage_fns``) at ``batch`` (8, the tiny
    preset's), the rows padded with repeats, so that no test compiles the planner for its own
    row count. Host arrays: pair (n,) with n <= batch, qpos (n, 14). Returns the plan's fields
    the C replay reads (``q_way``, ``grip_way``, ``feasible``, ``direction``), n rows each."""
    from relaff_jax.constants import action_id
    from relaff_jax.sim import rollouts

    n = len(pair)
    idx = np.resize(np.arange(n), batch)
    plan, _ = rollouts.jitted_stage_fns(cfg)[0](action_id(action), jnp.asarray(np.asarray(pair)[idx], jnp.int32),
                                                jnp.asarray(np.asarray(qpos)[idx], jnp.float32))
    plan = jax.device_get(plan)
    return {k: np.asarray(getattr(plan, k))[:n] for k in ("q_way", "grip_way", "feasible", "direction")}


def replay_built(action, cfg, built):
    """Settle hand-built scenes (``built``: (pair, qpos (14,)) per row) in C, plan them (JAX,
    ``plan_rows``) and measure their replay in C (``native.forces.physics``). Returns the plan
    and the measured arrays."""
    from relaff_jax.sim.native import forces as native_forces
    from relaff_jax.sim.native import reference as native

    pair = np.array([p for p, _ in built])
    q0 = np.array([q for _, q in built], np.float64)
    qs, _ = native.settle_native(wd.build_world(cfg.phys), pair, q0)
    qpos = qs[:, :14]
    res = plan_rows(action, cfg, pair, qpos)
    return res, native_forces.physics(action, cfg, pair, qpos, np.zeros((len(built), 12)), res)
