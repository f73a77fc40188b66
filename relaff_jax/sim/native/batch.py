"""The native engine: planned motor programs executed by ``mujoco.batch`` on a C thread pool.

Takes an ``ActionConfig``, an action name, settled scenes (the arm-less layout of
``scenes.Scenes``) and their JAX plans (``planning.Plan``) with unobstruct's reachability
before the action; gives ``execute_native``, the same per-scene fields as MJX's
``simulate.make_simulate_fn`` (labels, centres of mass, final states), computed by MuJoCo C
(``mj_step``, float64) with the same grasp-lock rule, weld relpose, measuring step and outcome
rules. It equals ``native.reference.replay_native`` (one ``MjData`` per scene) bit for bit, at any
thread count and chunk size (``tests/sim/test_native_engine.py``).

How the grasp lock is read: ``mujoco.batch`` cannot bind contacts, so every scene's model
carries four contact sensors (``sensor_models``: each finger pad against the toy body and
against the other body, every matching contact's distance and normal, ``reduce="none"``) and
the lock test (``native.program.pad_hit``) reads ``sensordata``. The weld's relative pose is
written into the scene's own copy of its pair's model (``set_models`` forbids ``expand``), at
the step the lock engages.
"""
from __future__ import annotations

import copy
import functools
import os
import sys

import mujoco
import mujoco.batch
import numpy as np

from relaff_jax.sim.actions.registry import action_id  # the run's list: the nine, then a user's
from relaff_jax.sim import objects as lib
from relaff_jax.sim import world as wd
from relaff_jax.sim.guard import hold_joints, pad_landing_np
from relaff_jax.sim.native.program import (RestReader, native_labels, pad_hit, program_inputs, stop_descent,
                                           weld_relpose_np)
from relaff_jax.sim.planning import Plan, setup
from relaff_jax.sim.simulate import welds
from relaff_jax.sim.templates import ActionConfig

from relaff_jax.errors import UserError

# Contact slots per sensor: a box pad against the toy (a box and a sphere) or the other object
# (five boxes). MuJoCo's box-box test gives at most 8 contacts, so these never overflow; an
# overflow would still raise (``_touching``) rather than drop a contact silently.
SLOTS = {"toy": 16, "obj": 48}
PAD_SENSORS = tuple((pad, body) for body in ("toy", "obj") for pad in ("arm_pad_l", "arm_pad_r"))


def sensor_xml() -> str:
    """The ``<sensor>`` section of the engine's models: pad-vs-body contact sensors."""
    rows = [f'<contact name="{pad}_{body}" geom1="{pad}" body2="{body}" num="{SLOTS[body]}" '
            'data="found dist normal" reduce="none"/>' for pad, body in PAD_SENSORS]
    return "<sensor>\n    " + "\n    ".join(rows) + "\n  </sensor>\n"


def sensor_model(toy: str, other: str, phys: wd.PhysicsConfig = wd.PhysicsConfig()) -> mujoco.MjModel:
    """The action-world model of one pair (``world.pair_xml(..., arm=True)``, the physics of
    ``World.mj_models``) plus the contact sensors of ``sensor_xml``; compiled once per pair of
    specs (a library object of the same name but other sizes is another model)."""
    return _sensor_model(toy, other, phys, lib.get(toy), lib.get(other))


@functools.lru_cache(maxsize=None)
def _sensor_model(toy: str, other: str, phys: wd.PhysicsConfig, _toy_spec, _other_spec) -> mujoco.MjModel:
    head, tag, tail = wd.pair_xml(toy, other, phys, arm=True).rpartition("</mujoco>")
    return mujoco.MjModel.from_xml_string(head + sensor_xml() + tag + tail)


def sensor_models(phys: wd.PhysicsConfig, pair: np.ndarray) -> list[mujoco.MjModel]:
    """The ``sensor_model`` of each pair index in ``pair`` (B,) (``World.pairs`` order)."""
    names = lib.pairs()
    return [sensor_model(names[int(p)][0], names[int(p)][1], phys) for p in pair]


def default_threads() -> int:
    """Threads of the batch: the CPUs this process may run on, or, in a Dask worker
    (``--cluster``), the worker's task threads, so that workers do not oversubscribe the cores."""
    if "distributed" in sys.modules:  # only a cluster run has imported it
        try:
            return int(sys.modules["distributed"].get_worker().state.nthreads)
        except (ValueError, AttributeError):  # not in a worker
            pass
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class _Pads:
    """The four pad contact sensors' places in ``sensordata`` and the pads' geom ids, looked up
    once per chunk (every model of a batch has the same sensors at the same addresses)."""

    def __init__(self, m: mujoco.MjModel):
        self.adr = {(pad, body): int(m.sensor(f"{pad}_{body}").adr[0]) for pad, body in PAD_SENSORS}
        self.geom = {pad: int(m.geom(pad).id) for pad, _ in PAD_SENSORS}

    def any_contact(self, sd: np.ndarray, rows: np.ndarray, pads: tuple[str, ...], body: str) -> bool:
        """Does any of ``rows`` (n,) bool have a contact of every pad in ``pads`` with ``body``?
        Without one neither test can hold (``pad_hit`` and ``pad_landing_np`` read valid
        contacts only), so a step without one needs no test. Raises as ``contacts`` when a
        sensor found more contacts than its slots."""
        for pad in pads:
            found = sd[:, self.adr[pad, body]]
            if np.any(found > SLOTS[body]):
                raise RuntimeError(f"contact sensor {pad}_{body}: {int(found.max())} contacts > {SLOTS[body]} slots")
            rows = rows & (found > 0)
        return bool(rows.any())

    def contacts(self, sd: np.ndarray, gxmat: np.ndarray, pad: str, body: str):
        """One pad's contacts with ``body`` ("toy" / "obj") from ``sensordata`` (n, S) and
        ``geom_xmat`` (n, G, 9) of the same forward pass: dist (n, K), normal (n, K, 3), the
        pad's closing axis (n, 3), valid (n, K)."""
        n, k, a = sd.shape[0], SLOTS[body], self.adr[pad, body]
        block = sd[:, a:a + 5 * k].reshape(n, k, 5)  # found, dist, normal (3)
        found = block[:, 0, 0]
        if np.any(found > k):
            raise RuntimeError(f"contact sensor {pad}_{body}: {int(found.max())} contacts > {k} slots")
        valid = np.arange(k)[None, :] < found[:, None]
        axis = gxmat[:, self.geom[pad]].reshape(n, 3, 3)[:, :, 1]
        return block[:, :, 1], block[:, :, 2:5], axis, valid


def _touching(sd: np.ndarray, gxmat: np.ndarray, m: mujoco.MjModel | _Pads, body: str,
              cfg: ActionConfig) -> np.ndarray:
    """(n,) bool: do both pads grip ``body`` ("toy" / "obj")?"""
    pads = m if isinstance(m, _Pads) else _Pads(m)
    hits = [pad_hit(*pads.contacts(sd, gxmat, pad, body), cfg) for pad in ("arm_pad_l", "arm_pad_r")]
    return hits[0] & hits[1]


def _landing(sd: np.ndarray, gxmat: np.ndarray, m: mujoco.MjModel | _Pads, cfg: ActionConfig) -> np.ndarray:
    """(n,) bool: does a pad land on either object (``guard.pad_landing_np``)?"""
    pads = m if isinstance(m, _Pads) else _Pads(m)
    return np.any([pad_landing_np(*pads.contacts(sd, gxmat, pad, body), cfg)
                   for pad in ("arm_pad_l", "arm_pad_r") for body in ("toy", "obj")], axis=0)


# the longest stretch stepped in one call once a run may stop (v2's read step found): a bound
# on the steps simulated past it, which change no result
STRETCH_AFTER_MEASURE = 16


def _checks(inp, t: int, grasp, stopped: np.ndarray, eq: np.ndarray) -> bool:
    """Does control step t need a decision before it: a guarded step with a descent still
    going, or a closing step with a scene not yet locked (``_run_chunk``'s two tests)?"""
    if inp.guard[t] and not stopped.all():
        return True
    return grasp is not None and bool(inp.closing[t]) and not bool(np.all(eq[:, grasp[0]] != 0))


def _stretch_end(inp, t: int, grasp, stopped: np.ndarray, eq: np.ndarray, lo: int, hi: int) -> int:
    """The end (exclusive) of the stretch of steps from t that need no decision: it stops at
    the next step that needs one, where the closing flag changes (with a grasp), where the
    recorded rest window [lo, hi] begins or ends, and in the window at most
    ``STRETCH_AFTER_MEASURE`` steps past the measuring step or the stretch's start, whichever
    is later (from there the run may stop)."""
    end = t + 1
    cap = inp.n_run if not lo <= t <= hi else min(inp.n_run, max(t, inp.measure) + STRETCH_AFTER_MEASURE)
    while end < cap and not _checks(inp, end, grasp, stopped, eq) and (t < lo) == (end < lo) \
            and (t <= hi) == (end <= hi) and (grasp is None or inp.closing[end] == inp.closing[t]):
        end += 1
    return end


def _run_chunk(cfg: ActionConfig, models: list, inp, rows: np.ndarray, nthread: int, nqo: int) -> dict:
    """Execute programs ``rows`` of ``inp`` (``native.program.ProgramInputs``) in one batch.

    Steps that need a decision (a guarded descent still going, a grasp not yet locked on every
    scene) are stepped one at a time, as ``reference.replay_native``; the stretches between
    them are stepped in one ``Batch.rollout`` call each, with the same commands (set before
    every ``mj_step``, as one step at a time), recording the centres of mass and ``qpos``
    where the rest reader needs them. The batch keeps every simulation's state (``qacc``'s
    warm start included) between calls, so the stretches give the steps' bits."""
    world = setup(cfg).world
    wl = welds(world)
    bodies = [world.toy_body, world.obj_body]
    own = [copy.copy(models[r]) for r in rows]  # each simulation owns its model: the lock's eq_data
    batch = mujoco.batch.Batch(own[0], nsim=len(rows), nthread=nthread)
    batch.set_models(own)
    pads = _Pads(own[0])
    qpos, qvel, ctrl, eq = (batch.bind(f) for f in ("qpos", "qvel", "ctrl", "eq_active"))
    xipos, xpos, xquat, gxmat, sd = (batch.bind(f) for f in ("xipos", "xpos", "xquat", "geom_xmat", "sensordata"))
    qpos[:], qvel[:], eq[:] = inp.qpos[rows], inp.qvel[rows], inp.eq_active[rows]
    batch.forward()
    com0 = xipos[:, bodies].copy()
    com_m = None
    rest = RestReader(cfg, inp)
    lo, hi = rest.lo, rest.lo + cfg.rest_window + rest.hold  # the steps the rest reader reads
    grasp = {1: (wl.obj, world.obj_body, "obj"), 2: (wl.toy, world.toy_body, "toy")}.get(inp.grasp)
    stopped = np.zeros(len(rows), bool)
    q_arm, v_arm = setup(cfg).arm.qpos_arm, setup(cfg).arm.qvel_arm
    t = 0
    while t < inp.n_run:
        if not _checks(inp, t, grasp, stopped, eq):
            end = _stretch_end(inp, t, grasp, stopped, eq, lo, hi)
            if grasp is not None and not inp.closing[t]:
                eq[:, grasp[0]] = 0.0
            read = lo <= t <= hi  # the whole stretch is in the window or out of it; measure is in it
            rec = batch.rollout(end - t, control=inp.ctrl[rows, t:end], record=("xipos", "qpos") if read else ())
            for k in range(end - t):
                if t + k == inp.measure:
                    com_m = rec["xipos"][:, k, bodies].copy()
                if read:
                    rest.add(t + k, rec["xipos"][:, k, bodies], rec["qpos"][:, k, :nqo])
                if inp.v2 and rest.done:
                    break
            t = end
            if inp.v2 and rest.done:
                break
            continue
        going = ~stopped
        if inp.guard[t] and any(pads.any_contact(sd, going, (pad,), body) for pad, body in PAD_SENSORS):
            # the descent stops where a pad lands (guard.py)
            for i in np.flatnonzero(going & _landing(sd, gxmat, pads, cfg)):
                stopped[i] = True
                stop_descent(cfg, inp, int(rows[i]), t, hold_joints(qpos[i, q_arm], qvel[i, v_arm]))
        # the grasp lock of simulate.run_program_locked, on the pads' contact sensors (the
        # other hand weld stays off: initial_data leaves it off and only the grasp row moves)
        if grasp is not None:
            row, body, name = grasp
            if inp.closing[t]:
                active = eq[:, row] != 0
                grips = pads.any_contact(sd, ~active, ("arm_pad_l", "arm_pad_r"), name)
                lock = active | _touching(sd, gxmat, pads, name, cfg) if grips else active
                new = np.flatnonzero(lock & ~active)
                if len(new):
                    rel = weld_relpose_np(xpos[new, wl.hand_body], xquat[new, wl.hand_body], xpos[new, body],
                                          xquat[new, body])
                    for i, r in zip(new, rel):
                        own[i].eq_data[row, 3:10] = r
                    batch.set_models(own)
                eq[:, row] = lock
            else:
                eq[:, row] = 0.0
        ctrl[:] = inp.ctrl[rows, t]
        batch.step()
        if t == inp.measure:  # like MJX: the positions of the step's forward pass
            com_m = xipos[:, bodies].copy()
        rest.add(t, xipos[:, bodies], qpos[:, :nqo])
        if inp.v2 and rest.done:  # every scene's read step is known: the rest changes nothing
            break
        t += 1
    com_r, q_r, settled = rest.result()
    if inp.v2:  # every goal and the final state at the read step
        return dict(com0=com0, com_m=com_r, com_end=com_r, qpos_final=q_r.astype(np.float32), settled=settled)
    return dict(com0=com0, com_m=com_m, com_end=xipos[:, bodies].copy(),
                qpos_final=qpos[:, :nqo].astype(np.float32), settled=settled)


def execute_native(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
                   plan: Plan, before: np.ndarray, nthread: int | None = None,
                   chunk: int | None = None) -> dict[str, np.ndarray]:
    """Execute B planned programs in MuJoCo C on a thread pool and label them.

    Args:
      pair: (B,) pair indices; qpos (B, 14), qvel (B, 12): settled object states.
      plan: the scenes' ``Plan`` (``q_way`` (B, W, 6), ``grip_way`` (B, W), ``feasible``,
        ``direction`` (B, 3), ``ik_error``); before: (B,) unobstruct's reachability before.
      nthread: C threads (default: every CPU of the process); chunk: simulations per batch
        (default all B). Neither changes a bit of the results.
    Returns the fields of ``make_simulate_fn`` as numpy arrays: ``label``, ``feasible``,
    ``ik_error``, ``com0``/``com_m``/``com_end`` (B, 2, 3) float64, ``reach_before``,
    ``reach_after``, ``qpos_final`` (B, 14) float32, ``q_way``, ``grip_way``, ``seg_steps``.
    """
    aid = action_id(action)
    nthread = default_threads() if nthread is None else int(nthread)
    pair = np.asarray(pair)
    n = len(pair)
    chunk = max(n, 1) if chunk is None else int(chunk)
    if nthread < 1 or chunk < 1:
        raise UserError(f"nthread and chunk must be >= 1, got {nthread} and {chunk}")
    qpos, qvel = np.asarray(qpos), np.asarray(qvel)
    models = sensor_models(cfg.phys, pair)
    outs = []
    if n:
        inp = program_inputs(cfg, aid, qpos, qvel, np.asarray(plan.q_way), np.asarray(plan.grip_way))
        outs = [_run_chunk(cfg, models, inp, np.arange(lo, min(lo + chunk, n)), nthread, qpos.shape[-1])
                for lo in range(0, n, chunk)]
    cat = lambda k, shape, dt: np.concatenate([o[k] for o in outs]) if outs else np.zeros(shape, dt)
    com0, com_m, com_end = (cat(k, (0, 2, 3), np.float64) for k in ("com0", "com_m", "com_end"))
    qf = cat("qpos_final", (0, qpos.shape[-1]), np.float32)
    settled = cat("settled", (0,), bool)
    feasible = np.asarray(plan.feasible, bool)
    label, after = native_labels(cfg, aid, pair, com0, com_m, com_end, qf, np.asarray(plan.direction),
                                 np.asarray(before, bool), feasible) if n else (np.zeros(0, bool),) * 2
    return dict(label=label, feasible=feasible, ik_error=np.asarray(plan.ik_error), com0=com0, com_m=com_m,
                com_end=com_end, reach_before=np.asarray(before, bool), reach_after=after, qpos_final=qf, settled=settled,
                q_way=np.asarray(plan.q_way), grip_way=np.asarray(plan.grip_way),
                seg_steps=np.asarray(plan.seg_steps))
