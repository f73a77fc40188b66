"""Scenes settled by MuJoCo C on a thread pool (``mujoco.batch``): the settle of the native engine.

Takes the arm-less ``World`` (``World.mj_models``, one model per pair), placements
(``scenes.place``) and a ``SceneConfig``; gives ``settle_batch``, the ``scenes.Scenes`` of
``scenes.make_settle_fn`` (settled state, relation, COG distance, at rest) computed by
``mj_step`` in float64, with a held rake pinned after every step exactly as MJX and
``native.reference.settle_native`` pin it. It equals ``settle_native`` (one ``MjData`` per scene) bit
for bit at any thread count (``tests/sim/test_native_engine.py``); how far it agrees with MJX's
settle is measured in ``docs/scenes.md`` ("Native settle").
"""
from __future__ import annotations

import mujoco
import mujoco.batch
import numpy as np

from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd
from relaff_jax.sim.native.reference import relation_native
from relaff_jax.sim.still import STILL_STEPS, still_numpy

# What a native dataset records as its settle (sidecar ``settle``): bump when it changes.
SETTLE_NAME = "mujoco_c_batch/1"


def _step_held(world: wd.World, batch, pair: np.ndarray, steps: int) -> None:
    """``steps`` mj_step calls of every scene of ``batch``, a held rake pinned after each step
    as MJX's settle pins it (the rake stays in the gripper: no gravity, no drift)."""
    oq, od = world.obj_qpos, world.obj_dof
    qpos, qvel = batch.bind("qpos"), batch.bind("qvel")
    held = np.flatnonzero([world.pairs[int(p)][2] == "toy+rake" for p in pair])
    if len(held):
        obj7 = qpos[held, oq:oq + 7].copy()
        for _ in range(steps):
            batch.step()
            qpos[held, oq:oq + 7] = obj7
            qvel[held, od:od + 6] = 0.0
    else:
        batch.step(nstep=steps)  # the same mj_step calls, one dispatch


def settle_batch(world: wd.World, pair: np.ndarray, qpos0: np.ndarray, intended: np.ndarray,
                 cfg: sc.SceneConfig = sc.SceneConfig(), nthread: int = 1) -> sc.Scenes:
    """Settle B scenes in one ``mujoco.batch`` of ``nthread`` C threads.

    Args:
      pair: (B,) pair indices; qpos0: (B, nq) placements; intended: (B,) sampler's relation.
    Returns ``scenes.Scenes`` of numpy arrays: ``qpos``/``qvel`` float32 (as MJX gives them),
    ``relation`` int32, ``cog_distance`` float32, ``at_rest`` bool; ``pair``/``qpos0``/``intended``
    as given.
    """
    pair = np.asarray(pair)
    q0 = np.asarray(qpos0, np.float64)
    n = len(pair)
    models = [world.mj_models[int(p)] for p in pair]
    batch = mujoco.batch.Batch(models[0], nsim=n, nthread=int(nthread))
    batch.set_models(models)
    qpos, qvel, xipos = batch.bind("qpos"), batch.bind("qvel"), batch.bind("xipos")
    qpos[:] = q0
    qvel[:] = 0.0
    od, td = world.obj_dof, world.toy_dof
    _step_held(world, batch, pair, cfg.settle_steps)
    batch.forward()
    q, v, com = qpos.copy(), qvel.copy(), xipos.copy()
    rel = np.zeros(n, np.int32)
    datas: dict[int, mujoco.MjData] = {}
    for i in range(n):  # contacts are not bound: one forward pass per scene, on its pair's data
        m, p = models[i], int(pair[i])
        if p not in datas:
            datas[p] = mujoco.MjData(m)
        d = datas[p]
        d.qpos[:], d.qvel[:] = q[i], v[i]
        mujoco.mj_forward(m, d)
        rel[i] = relation_native(world, p, m, d, cfg)
    cog = np.linalg.norm(com[:, world.toy_body] - com[:, world.obj_body], axis=-1)
    speed = np.maximum(np.linalg.norm(v[:, td:td + 3], axis=-1), np.linalg.norm(v[:, od:od + 3], axis=-1))
    return sc.Scenes(pair=pair, qpos0=np.asarray(qpos0), qpos=q.astype(np.float32), qvel=v.astype(np.float32),
                     relation=rel, intended=np.asarray(intended), cog_distance=cog.astype(np.float32),
                     at_rest=speed < cfg.rest_speed)


def still_batch(world: wd.World, pair: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
                steps: int = STILL_STEPS, nthread: int = 1) -> np.ndarray:
    """Programs v4's stillness check in MuJoCo C (``sim/still.py``): each settled scene,
    ``qpos`` (B, nq) and ``qvel`` (B, nv) as ``settle_batch`` gives them, simulated ``steps`` more
    steps; (B,) bool, True where both objects stayed within ``STILL_MOVE`` and ``STILL_TURN_DEG``."""
    pair = np.asarray(pair)
    q0 = np.asarray(qpos, np.float64)
    models = [world.mj_models[int(p)] for p in pair]
    batch = mujoco.batch.Batch(models[0], nsim=len(pair), nthread=int(nthread))
    batch.set_models(models)
    batch.bind("qpos")[:] = q0
    batch.bind("qvel")[:] = np.asarray(qvel, np.float64)
    _step_held(world, batch, pair, steps)
    return still_numpy(world, q0, batch.bind("qpos").copy())
