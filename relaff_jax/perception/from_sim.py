"""From stored scenes to the paper's state spaces: the glue between datasets and perception.

Takes a dataset's per-sample ``pair`` (int) and ``qpos_settled`` ((nq,) settled object state
in the arm-less world layout) and gives ``pca`` (18,), ``rhf`` (300,), ``unseen`` (2,) and the
overflow flag per sample: the scene's geoms are placed by ``mjx.kinematics`` on the pair's
model (batched model fields, as in ``world.py``), then ``perception.features`` sees them.
The depth-noise key of a sample depends only on the seed and its ``rollout_id``
(``rollout_keys``), so features do not depend on the batch size or on resuming.

``make_feature_fn`` is the compute function the features stage
(``stages.features.add_features``, ``relaff features``) hands to ``data.add_features``;
``show_scene`` draws what the robot saw (``relaff show``). Nothing here imports ``data``.
"""
from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from relaff_jax.perception.culled import make_culled_features
from relaff_jax.perception.pipeline import make_batched_features
from relaff_jax.perception.plots import render_scene_png
from relaff_jax.perception.scene import make_scene
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.errors import UserError
from relaff_jax.sim import world as wd


def scene_geoms(world: wd.World, pair: jax.Array, qpos: jax.Array):
    """Geom sizes and poses of a batch of settled scenes.

    Args:
      pair: (B,) pair indices; qpos: (B, nq) settled states (arm-less layout).
    Returns:
      size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3), robot frame.
    """
    models = wd.scene_models(world, pair)
    d0 = mjx.make_data(world.mj_model)

    def one(m, q):
        d = mjx.kinematics(m, d0.replace(qpos=q))
        return m.geom_size, d.geom_xpos, d.geom_xmat

    return jax.vmap(one, in_axes=(world.model_axes, 0))(models, qpos)


def split_ids(rollout_ids) -> tuple[np.ndarray, np.ndarray]:
    """Low and high 32 bits (uint32 each, shape of ``rollout_ids``) of non-negative int64 ids."""
    ids = np.asarray(rollout_ids).astype(np.int64)
    return (ids & 0xFFFFFFFF).astype(np.uint32), (ids >> 32).astype(np.uint32)


def rollout_keys(root, rollout_ids):
    """Depth-noise keys (B, 2) of samples: ``fold_in(root, low 32 bits of the id)``, and for
    ids >= 2^32 that key folded with the high 32 bits too.

    Ids below 2^32 keep the key of earlier versions (which used the low 32 bits only); ids that
    differ by a multiple of 2^32 used to share a noise stream and no longer do.
    """
    lo, hi = split_ids(rollout_ids)
    return _keys_of(root, jnp.asarray(lo), jnp.asarray(hi))


@jax.jit
def _keys_of(root, lo, hi):
    """(B, 2) keys of ``rollout_keys`` from the ids' 32-bit halves (B,): one compiled dispatch
    (integer ops, the same bits as eager)."""

    def one(lo, hi):
        k = jax.random.fold_in(root, lo)
        return jnp.where(hi == 0, k, jax.random.fold_in(k, hi))

    return jax.vmap(one)(lo, hi)


def show_key(rollout_id: int):
    """Image and feature noise key of ``show_scene`` for one sample: ``PRNGKey(id)`` for
    ids < 2^32 (as before), ``fold_in(PRNGKey(low 32 bits), high 32 bits)`` above (before,
    the high bits were dropped)."""
    lo, hi = (int(x) for x in split_ids(rollout_id))
    key = jax.random.PRNGKey(lo)
    return key if hi == 0 else jax.random.fold_in(key, hi)


@functools.lru_cache(maxsize=4)
def jitted_geoms(world: wd.World):
    """``scene_geoms`` of ``world`` jitted once per world (cached): ``(pair, qpos) -> (size, xpos, xmat)``."""
    return jax.jit(lambda pair, qpos: scene_geoms(world, pair, qpos))


# Scenes per perception call inside a feature chunk. The chain's per-scene cost grows with the
# batch (640 x 480 rays per scene: a call of 32 scenes streams ~8x the working set of 4 through
# the caches); features do not depend on it, bit for bit (tests/perception/test_features.py), so a chunk
# of ``feature_batch`` samples is perceived in calls of this many (docs/perception.md,
# "Performance notes").
SUB_BATCH = 4


def make_feature_fn(world: wd.World, cfg: PerceptionConfig = PerceptionConfig(), seed: int = 0,
                    sub_batch: int = SUB_BATCH, culled: bool = True, compiler_options=None):
    """``compute(samples) -> dict of numpy arrays`` for ``relaff_jax.data.add_features``.

    ``samples`` needs ``pair`` (B,), ``qpos_settled`` (B, nq) and ``rollout_id`` (B,) int64;
    a sample's noise key is ``rollout_keys(PRNGKey(seed), rollout_id)``. The B scenes are
    perceived in calls of ``sub_batch`` (the last one padded by repeating its last scene; the
    features are the same at any ``sub_batch``). ``culled`` (default): capacities sized per call
    (``perception.culled``, the same bits); False: every call at the config's capacities (the
    reference, ``benchmarks/perception_culled.py``). ``compiler_options``: the culled chain's XLA
    options (``culled.make_culled_features``; None: its default). Raises ``UserError`` if fields are missing or
    a scene exceeds a perception capacity.
    """
    if int(sub_batch) < 1:
        raise UserError(f"sub_batch must be >= 1, got {sub_batch}")
    feats = make_batched_features(world.mj_model.geom_type, world.geom_seg, cfg)
    sized = make_culled_features(world.mj_model.geom_type, world.geom_seg, cfg, sub_batch=sub_batch,
                                 compiler_options=compiler_options)
    geoms = jitted_geoms(world)
    root = jax.random.PRNGKey(seed)

    def perceive(size, xpos, xmat, keys) -> dict:
        """The chain on (B, ...) inputs in calls of ``sub_batch`` scenes, dispatched back to back."""
        b = size.shape[0]
        sb = min(int(sub_batch), b)
        idx = np.minimum(np.arange(-(-b // sb) * sb), b - 1)  # pad by repeating the last scene
        parts = [feats(size[i], xpos[i], xmat[i], keys[i]) for i in np.split(idx, len(idx) // sb)]
        parts = jax.device_get(parts)
        return {k: np.concatenate([p[k] for p in parts])[:b] for k in parts[0]}

    def compute(samples: dict) -> dict:
        missing = {"pair", "qpos_settled", "rollout_id"} - set(samples)
        if missing:
            raise UserError(f"samples lack {sorted(missing)}: not a scene dataset of this version")
        size, xpos, xmat = geoms(jnp.asarray(samples["pair"], jnp.int32),
                                 jnp.asarray(samples["qpos_settled"], jnp.float32))
        ids = np.asarray(samples["rollout_id"])
        keys = rollout_keys(root, ids)
        out = (sized if culled else perceive)(size, xpos, xmat, keys)
        if out["overflow"].any():
            bad = np.flatnonzero(out["overflow"])
            flags = {k: np.asarray(out[k])[bad].tolist() for k in
                     ("tile_overflow", "pixel_overflow", "voxel_overflow", "range_overflow")}
            raise UserError(
                f"perception capacity exceeded for rollout_id {ids[bad].tolist()} ({flags}); "
                "raise the matching capacity in PerceptionConfig (docs/perception.md) rather than "
                "truncate the point clouds")
        return {"pca": out["pca"], "rhf": out["rhf"], "unseen": out["unseen"],
                "n_points": out["n_points"], "overflow": out["overflow"]}

    return compute


def show_scene(world: wd.World, pair: int, qpos: np.ndarray, out: str | Path, key=None,
               cfg: PerceptionConfig = PerceptionConfig(), title: str = "") -> Path:
    """Draw what the robot saw in one settled scene (``perception.render_scene_png``: noisy
    depth image, the objects' depth and segments, voxel clouds with PCA frames); writes
    ``out`` atomically.
    ``key`` defaults to ``PRNGKey(0)``; ``show_key(rollout_id)`` is the key ``relaff show`` uses."""
    key = jax.random.PRNGKey(0) if key is None else key
    size, xpos, xmat = jax.device_get(jitted_geoms(world)(
        jnp.asarray([pair], jnp.int32), jnp.asarray(qpos, jnp.float32)[None]))
    scene = make_scene(world.mj_model.geom_type, world.geom_seg, size[0], xpos[0], xmat[0])
    toy, other = world.pairs[pair][:2]
    render_scene_png(scene, key, out, cfg, title=title or f"{toy} + {other}")
    return Path(out)
