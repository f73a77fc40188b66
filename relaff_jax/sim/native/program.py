"""What the MuJoCo C executions of planned programs share: inputs, the weld relpose, labels.

Takes an ``ActionConfig``, an action id and a batch of settled scenes with their plans; gives
the pieces that both C executions (``native.reference.replay_native``, one ``MjData`` per scene, and
``native.batch.execute_native``, ``mujoco.batch``) use, so that they differ only in how they
step and read contacts:

- ``program_inputs``: initial state (objects settled, arm at home) and the actuator command of
  every control step (``ProgramInputs``), computed by the same JAX code as MJX
  (``simulate.initial_data``, ``arm.program_ctrl``);
- ``weld_relpose_np``: ``arm.weld_relpose`` in float64 numpy (the grasp lock's relative pose);
- ``pad_hit``: the grasp test of one pad from contact distances and normals (the rule of
  ``arm.finger_contacts``);
- ``native_labels``: unobstruct's reachability after the action and the outcome rules
  (``labels.goals``), on the centres of mass the C run recorded.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.sim import arm as A
from relaff_jax.sim.actions.registry import per_action_list, registry
from relaff_jax.sim.actions.rules import goal_row
from relaff_jax.sim.labels import Outcome
from relaff_jax.sim.planning import setup
from relaff_jax.sim.programs import toy_reachable
from relaff_jax.sim.guard import guard_tables, stopped_way
from relaff_jax.sim.simulate import initial_data
from relaff_jax.sim.straight import corrections, stopped_corrections, straight_rows
from relaff_jax.sim.actions.tables import run_steps, tables
from relaff_jax.sim.templates import ActionConfig
from relaff_jax.sim.traced_cache import stored_jit


class ProgramInputs(NamedTuple):
    """Everything a C execution of a batch of B programs starts from (float64 arrays).

    qpos (B, nq), qvel (B, nv), eq_active (B, neq): the action world's initial state;
    ctrl (B, T, nu): the command of every control step (T = ``N_STEPS``); closing (T,) bool:
    does step t belong to a segment that closes the fingers; grasp: 0 none, 1 the other
    object, 2 the toy (``templates.GRASPS``); measure: the control step of the lift-type goals
    (v2: the first step a goal may be read at); n_run: the control steps to simulate
    (``actions.tables.run_steps``); v2: whether goals are read at rest (``labels.read_at_rest``);
    guard (T,) bool: may a landing pad stop the descent at step t (``guard.guard_tables``),
    guard_rows (W,) bool the waypoints a stop replaces, aid the action id, q_way (B, W, 6) and
    grip_way (B, W) the plan's waypoints (float32; ``stop_descent`` recomputes ``ctrl``); corr
    (B, S, P - 1, 6) float32 the straight segments' joint corrections (``straight.corrections``;
    v1: P - 1 = 0, unused).
    """

    qpos: np.ndarray
    qvel: np.ndarray
    eq_active: np.ndarray
    ctrl: np.ndarray
    closing: np.ndarray
    grasp: int
    measure: int
    n_run: int
    v2: bool
    guard: np.ndarray
    guard_rows: np.ndarray
    aid: int
    q_way: np.ndarray
    grip_way: np.ndarray
    corr: np.ndarray


@per_action_list(maxsize=4)
def _jitted(cfg: ActionConfig):
    """The jitted JAX pieces (compiled once per batch shape): initial data, commands, reach,
    labels, corrections."""
    st = setup(cfg)
    tb = tables(cfg)

    def init(aid, qpos, qvel):
        d = jax.vmap(lambda q, v: initial_data(st, cfg, aid, q, v))(qpos, qvel)
        return d.qpos, d.eq_active

    v2 = cfg.programs != "v1"  # v2-v4 execute alike (v3 and v4 plan differently, their tables dwell)
    srows = jnp.asarray(straight_rows(cfg, tb.target))

    def corr(aid, q_way):  # (B, S, P - 1, 6): as simulate.make_simulate_fn's, from the plan
        return jax.vmap(lambda qw: corrections(st.arm, cfg, qw, srows[aid])[0])(q_way)

    def ctrl(aid, q_way, grip_way, c):
        seg = jnp.asarray(tb.steps)[aid]
        one = lambda qw, gw, cc: jax.vmap(lambda t: A.program_ctrl(st.arm, qw, gw, seg, t, cc if v2 else None))(
            jnp.arange(tb.n_steps))
        return jax.vmap(one)(q_way, grip_way, c)

    reach = jax.vmap(lambda p, q: toy_reachable(st.arm, cfg, st.geo, p, q))
    specs = registry()
    rules = jax.vmap(lambda *o: goal_row(specs, cfg, Outcome(*o)))  # the Outcome's fields as arguments
    # traces kept on disk with the compilation cache (sim/traced_cache.py)
    return (stored_jit(init, "native_init", cfg), stored_jit(ctrl, "native_ctrl", cfg),
            stored_jit(reach, "toy_reach", cfg), stored_jit(rules, "native_rules", cfg),
            stored_jit(corr, "native_corr", cfg))


def _padded(fn, *arrays):
    """``fn(*arrays)`` on the rows padded (with repeats of the last) to a power of two >= 8,
    then cut back: a few compiled shapes serve every batch size. Rows do not interact."""
    n = len(arrays[0])
    size = max(8, 1 << (n - 1).bit_length())
    idx = np.minimum(np.arange(size), n - 1)
    out = jax.device_get(fn(*(jnp.asarray(np.asarray(a)[idx]) for a in arrays)))
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], out)


def program_inputs(cfg: ActionConfig, aid: int, qpos: np.ndarray, qvel: np.ndarray,
                   q_way: np.ndarray, grip_way: np.ndarray) -> ProgramInputs:
    """Initial states and commands of B planned programs.

    Args: qpos (B, 14), qvel (B, 12) settled object states (arm-less layout); q_way (B, W, 6),
    grip_way (B, W) the plan's waypoints. The objects start at ``qpos``/``qvel`` exactly (in
    float64), the arm and the hand welds as ``simulate.initial_data`` sets them.
    """
    init, ctrl, _, _, corr = _jitted(cfg)
    a = jnp.int32(aid)
    qpos = np.asarray(qpos, np.float64)
    qvel = np.asarray(qvel, np.float64)
    q0, eq0 = _padded(lambda q, v: init(a, q, v), qpos.astype(np.float32), qvel.astype(np.float32))
    nqo, nvo = qpos.shape[-1], qvel.shape[-1]
    full_q = np.concatenate([qpos, np.asarray(q0[:, nqo:], np.float64)], axis=1)
    nv = setup(cfg).world.mj_model.nv
    full_v = np.zeros((len(qpos), nv))
    full_v[:, :nvo] = qvel
    c = np.array(_padded(lambda qw: corr(a, qw), q_way), np.float32)  # writable: a stop zeroes rows
    u = np.asarray(_padded(lambda qw, gw, cc: ctrl(a, qw, gw, cc), q_way, grip_way, c), np.float64)
    tb = tables(cfg)
    seg = np.asarray(A.segment_index(tb.steps[aid], jnp.arange(tb.n_steps)))
    g_seg, g_rows = guard_tables(cfg)
    return ProgramInputs(full_q, full_v, np.asarray(eq0, np.float64), u, np.asarray(tb.closed[aid])[seg],
                         int(tb.grasp[aid]), int(tb.measure[aid]), int(run_steps(cfg)[aid]), cfg.programs != "v1",
                         g_seg[aid][seg], g_rows[aid], int(aid), np.array(q_way, np.float32),
                         np.array(grip_way, np.float32), c)


def stop_descent(cfg: ActionConfig, inp: ProgramInputs, b: int, t: int, q_arm: np.ndarray) -> None:
    """A pad of program ``b`` landed at step ``t`` (``guard.pad_landing_np``): its waypoints
    become ``guard.stopped_way`` of the arm's joints ``q_arm`` (6,) (float64, read as float32
    like MJX's) and ``inp.ctrl[b, t:]`` the commands of those waypoints (the same jitted
    ``arm.program_ctrl`` as ``program_inputs``, one row: both C executors get the same bits); the
    straight segments' corrections as ``straight.stopped_corrections`` (as MJX's)."""
    q_way = stopped_way(inp.q_way[b], inp.guard_rows, np.asarray(q_arm, np.float32))
    inp.q_way[b] = q_way
    inp.corr[b] = stopped_corrections(inp.corr[b], inp.guard_rows)
    u = _padded(lambda qw, gw, cc: _jitted(cfg)[1](jnp.int32(inp.aid), qw, gw, cc), q_way[None],
                inp.grip_way[b][None], inp.corr[b][None])
    inp.ctrl[b, t:] = np.asarray(u[0], np.float64)[t:]


class RestReader:
    """The goal's read step at rest in a C execution of B programs (``labels.read_at_rest`` on
    float64 positions): ``add(t, com (B, 2, 3), qpos (B, nq))`` after every control step t;
    ``done`` once every scene's read step is known (v2: a run may stop there); ``result()``
    gives (com_read (B, 2, 3), qpos_read (B, nq), settled (B,)). v1 reads the measuring step
    (``settled``: were the objects at rest there); v2 the first step at rest from it on, within
    ``cfg.rest_hold`` steps. Both C executors use it, so they agree bit for bit.

    It reads ``read_at_rest``'s rule step by step, for all B scenes at once: each new step's
    displacement is computed once, with the same float64 operations ``read_at_rest`` applies
    to that step (so the same bits), and a scene's read step is the first collected step ``j
    >= window`` with no moving step among the ``window`` before it (``tests/sim/
    test_programs_v2.py`` checks it against ``read_at_rest`` scene by scene)."""

    def __init__(self, cfg: ActionConfig, inp: ProgramInputs):
        self.cfg, self.lo = cfg, inp.measure - cfg.rest_window
        self.hold = cfg.rest_hold if inp.v2 else 0
        self.com, self.q, self.done = [], [], False
        self.moving: list[np.ndarray] = []  # (B,) bool per collected step after the first: j-1 -> j moved
        self.first: np.ndarray | None = None  # (B,) index of the first calm step, -1 while none

    def add(self, t: int, com: np.ndarray, qpos: np.ndarray) -> None:
        if t < self.lo or t > self.lo + self.cfg.rest_window + self.hold:
            return
        self.com.append(np.array(com, np.float64))
        self.q.append(np.array(qpos))
        if self.first is None:
            self.first = np.full(len(self.com[0]), -1)
        if len(self.com) > 1:  # labels.read_at_rest's ``step`` and ``moving`` of this one step
            step = np.sqrt(np.sum((self.com[-1] - self.com[-2]) ** 2, axis=-1))  # (B, 2)
            self.moving.append(np.max(step, axis=-1) >= self.cfg.scene.rest_speed * self.cfg.phys.timestep)
        j, w = len(self.com) - 1, self.cfg.rest_window
        if j >= w:
            calm = ~np.any(self.moving[j - w:j], axis=0) if w else np.ones(len(self.first), bool)
            self.first[(self.first < 0) & calm] = j
            self.done = bool(np.all(self.first >= 0)) or len(self.com) == w + 1 + self.hold

    def _read(self) -> tuple[np.ndarray, np.ndarray]:
        """(B,) the index into the collected steps each scene is read at, and (B,) settled."""
        settled = self.first >= 0
        return np.where(settled, self.first, len(self.com) - 1), settled

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i, settled = self._read()
        rows = np.arange(len(i))
        return np.stack(self.com, axis=1)[rows, i], np.stack(self.q, axis=1)[rows, i], settled

    def read_steps(self) -> np.ndarray:
        """(B,) the control step each scene's goal is read at (v1: the measuring step)."""
        return self.lo + self._read()[0]


def weld_relpose_np(xpos1: np.ndarray, xquat1: np.ndarray, xpos2: np.ndarray,
                    xquat2: np.ndarray) -> np.ndarray:
    """(..., 7) pose of body 2 in body 1's frame (pos, quat), float64: ``arm.weld_relpose``.

    Args: xpos1/xpos2 (..., 3) world positions, xquat1/xquat2 (..., 4) world quaternions
    (w, x, y, z) of body 1 (the hand) and body 2 (the grasped body). Written component by
    component (no reductions), so one scene gives the same bits alone or in a batch.
    """
    n1 = np.sqrt(xquat1[..., 0] ** 2 + xquat1[..., 1] ** 2 + xquat1[..., 2] ** 2 + xquat1[..., 3] ** 2)
    w, x, y, z = (xquat1[..., i] / n1 for i in range(4))
    a, b, c, e = w, -x, -y, -z  # the conjugate of q1, times q2
    p, q, r, s = (xquat2[..., i] for i in range(4))
    quat = [a * p - (b * q + c * r + e * s), a * q + p * b + (c * s - e * r),
            a * r + p * c + (e * q - b * s), a * s + p * e + (b * r - c * q)]
    nq = np.sqrt(quat[0] ** 2 + quat[1] ** 2 + quat[2] ** 2 + quat[3] ** 2)
    rot = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
           [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
           [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    dv = [xpos2[..., i] - xpos1[..., i] for i in range(3)]
    pos = [rot[0][i] * dv[0] + rot[1][i] * dv[1] + rot[2][i] * dv[2] for i in range(3)]  # rot1.T @ dv
    return np.stack(pos + [v / nq for v in quat], axis=-1)


def pad_hit(dist: np.ndarray, normal: np.ndarray, axis: np.ndarray, valid: np.ndarray,
            cfg: ActionConfig) -> np.ndarray:
    """Does a pad grip (the rule of ``arm.finger_contacts``)? Any valid contact nearer than
    ``cfg.arm.contact_dist`` whose normal is within ``arccos(contact_face_cos)`` of the pad's
    closing axis.

    Args: dist (..., K) contact distances, normal (..., K, 3), axis (..., 3) the pad's closing
    axis (its local y in the world), valid (..., K) bool. Returns (...) bool. The dot product
    is summed in a fixed order, so one contact gives the same answer in every caller.
    """
    a = axis[..., None, :]
    dot = normal[..., 0] * a[..., 0] + normal[..., 1] * a[..., 1] + normal[..., 2] * a[..., 2]
    return np.any(valid & (dist < cfg.arm.contact_dist) & (np.abs(dot) >= cfg.arm.contact_face_cos), axis=-1)


def reachable(cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray) -> np.ndarray:
    """(B,) bool: is the toy reachable (``programs.toy_reachable``) in scenes ``qpos`` (B, 14)?"""
    return np.asarray(_padded(_jitted(cfg)[2], pair, np.asarray(qpos, np.float32)), bool)


def native_labels(cfg: ActionConfig, aid: int, pair: np.ndarray, com0: np.ndarray, com_m: np.ndarray,
                  com_end: np.ndarray, qpos_final: np.ndarray, direction: np.ndarray,
                  before: np.ndarray, feasible: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Labels of B executed programs and unobstruct's reachability after them.

    Args: pair (B,); com0/com_m/com_end (B, 2, 3) centres of mass of (toy, other) before, at
    the measuring step and at the end; qpos_final (B, 14) float32 final object states;
    direction (B, 3) the plan's; before (B,) reachability before; feasible (B,).
    Returns label (B,) bool (False where infeasible) and reach_after (B,) bool (False unless
    the action is unobstruct).
    """
    rules = _jitted(cfg)[3]
    if tables(cfg).reach[aid]:
        after = reachable(cfg, pair, qpos_final)
    else:
        after = np.zeros(len(pair), bool)
    f32 = lambda x: np.asarray(x, np.float32)
    o = (f32(com0), f32(com_m), f32(com_end), f32(direction), np.asarray(before, bool), after)
    label = _padded(rules, *o)[:, aid] & np.asarray(feasible, bool)
    return label, after
