"""Native MuJoCo C references for cross-checking the MJX stages.

Takes the same per-pair models (``World.mj_models``) and placements as the JAX code; gives
settled states and relation labels computed by ``mujoco.mj_step`` and C contacts, with no
JAX involved, so tests and benchmarks can compare the two implementations.
"""
from __future__ import annotations

import mujoco
import numpy as np

from . import objects as lib
from . import scenes as sc
from . import world as wd


def relation_native(world: wd.World, pair: int, m: mujoco.MjModel, d: mujoco.MjData,
                    cfg: sc.SceneConfig) -> int:
    """Relation of a settled native scene from C contacts (same rule as ``scenes.relation_of``)."""
    toy, obj = world.toy_body, world.obj_body
    on_obj = on_table = False
    for c in d.contact[: d.ncon]:
        if c.dist >= cfg.contact_dist:
            continue
        bodies = {int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])}
        on_obj |= bodies == {toy, obj}
        on_table |= bodies == {toy, 0}
    if not on_obj or on_table:
        return sc.BESIDE
    spec = lib.get(world.pairs[pair][1])
    local = d.xmat[obj].reshape(3, 3).T @ (d.xipos[toy] - d.xpos[obj])
    if spec.inner is not None:
        ix, iy, rim = spec.inner
        if abs(local[0]) < ix and abs(local[1]) < iy and local[2] < rim:
            return sc.INSIDE
    return sc.ON_TOP


def settle_native(world: wd.World, pair: np.ndarray, qpos0: np.ndarray,
                  cfg: sc.SceneConfig = sc.SceneConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Settle scenes one by one with ``mujoco.mj_step`` (float64), holding rakes as MJX does.

    Args:
      pair: (B,) pair indices; qpos0: (B, nq) placements.
    Returns:
      qpos: (B, nq) settled states; relation: (B,) int labels.
    """
    out_q = np.zeros_like(qpos0, dtype=np.float64)
    out_r = np.zeros(len(pair), np.int32)
    oq, od = world.obj_qpos, world.obj_dof
    for i, (p, q0) in enumerate(zip(np.asarray(pair), np.asarray(qpos0, np.float64))):
        m = world.mj_models[int(p)]
        d = mujoco.MjData(m)
        d.qpos[:] = q0
        held = world.pairs[int(p)][2] == "toy+rake"
        for _ in range(cfg.settle_steps):
            mujoco.mj_step(m, d)
            if held:
                d.qpos[oq:oq + 7] = q0[oq:oq + 7]
                d.qvel[od:od + 6] = 0.0
        mujoco.mj_forward(m, d)
        out_q[i] = d.qpos
        out_r[i] = relation_native(world, int(p), m, d, cfg)
    return out_q, out_r
