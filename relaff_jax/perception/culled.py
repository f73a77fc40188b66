"""The batched feature chain at the cost of what it reads: capacities sized per call.

Takes a geom layout, a ``PerceptionConfig`` and batched scenes (size, xpos, xmat, keys as
``make_batched_features``); gives the same features as ``make_batched_features`` bit for bit
(numpy, one row per scene, input order). ``make_batched_features`` casts ``cull.max_tiles``
tiles (65,536 rays at the default) and compacts into ``voxel.max_object_pixels`` (32,768)
slots per scene whatever the scene shows; here a cheap first pass counts each scene's active
tiles (``render.active_tiles``), scenes are grouped by that count, and each group runs the
chain compiled for the smallest capacity of ``TILE_BUCKETS`` that holds it: max_tiles = K,
max_object_pixels = min(M, K * tile^2), and RHF pair tiles of ``RHF_CHUNK``.

Why the bits stay: every object pixel lies in an active tile and the active tiles keep their
order, so the compacted buffer holds the same pixels in the same slots; slot i's noise is
draw i of ``normal(key, (M',))``, which with JAX's partitionable threefry (the default) is
draw i of ``normal(key, (M,))`` (without it the pixel buffer stays at M); the voxel sort,
scatter and RHF counts see the same valid entries in the same order (the RHF counts are
integers, so their tiling does not matter). Overflow flags are
those of the full capacities: a group with more than the largest bucket's tiles runs at the
config's capacities, where the chain sets ``tile_overflow`` itself; a smaller buffer can
never overflow (object pixels <= K * tile^2). Tested: ``tests/perception/test_features.py``.
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.perception import PerceptionConfig
from .pipeline import make_batched_features
from .render import active_tiles
from .scene import SceneGeoms, make_scene

# Tile capacities a group can run at (each one compiled when first used), then the config's.
TILE_BUCKETS = (32, 64, 128)
# RHF pair tile edge: the histograms are integer counts, so any tiling gives the same bits;
# 128 x 128 pairs run faster than the config's 256 x 256 on XLA CPU (the tile's pair
# arrays fit the caches; benchmarks/perception_culled.py).
RHF_CHUNK = 128


def capacity_config(cfg: PerceptionConfig, tiles: int) -> PerceptionConfig:
    """``cfg`` with ``cull.max_tiles`` = tiles, the pixel buffer cut to what that many tiles
    can hold (kept at ``voxel.max_object_pixels`` if threefry is not partitionable: the noise
    draws of a shorter buffer would differ) and RHF tiles of ``RHF_CHUNK`` where that divides
    the voxel capacity. Internal to a call: a feature folder records ``cfg`` itself."""
    pixels = cfg.voxel.max_object_pixels
    if jax.config.jax_threefry_partitionable:
        pixels = min(pixels, tiles * cfg.cull.tile ** 2)
    chunk = cfg.rhf.chunk
    if chunk > RHF_CHUNK and cfg.voxel.max_voxels % RHF_CHUNK == 0:
        chunk = RHF_CHUNK
    return dataclasses.replace(cfg, cull=dataclasses.replace(cfg.cull, max_tiles=tiles),
                               voxel=dataclasses.replace(cfg.voxel, max_object_pixels=pixels),
                               rhf=dataclasses.replace(cfg.rhf, chunk=chunk))


def tile_capacity(count: int, cfg: PerceptionConfig, buckets=TILE_BUCKETS) -> int:
    """Smallest bucket below ``cull.max_tiles`` holding ``count`` active tiles, else ``cull.max_tiles``."""
    return next((b for b in sorted(buckets) if count <= b < cfg.cull.max_tiles), cfg.cull.max_tiles)


def make_tile_counter(geom_type, geom_seg, cfg: PerceptionConfig):
    """Jitted ``(size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3)) -> (B,) int32`` active tiles per scene."""
    g = len(np.asarray(geom_type).ravel())
    static = make_scene(geom_type, geom_seg, np.zeros((g, 3)), np.zeros((g, 3)), np.tile(np.eye(3), (g, 1, 1)))

    def one(size, xpos, xmat):
        return jnp.sum(active_tiles(SceneGeoms(static.geom_type, static.geom_seg, size, xpos, xmat), cfg))

    return jax.jit(jax.vmap(one))


def make_culled_features(geom_type, geom_seg, cfg: PerceptionConfig = PerceptionConfig(), sub_batch: int = 4,
                         buckets=TILE_BUCKETS):
    """``f(size, xpos, xmat, keys) -> dict`` of numpy arrays (B, ...), the fields of
    ``SceneFeatures``, equal to ``make_batched_features(...)(...)`` bit for bit.

    Inputs as ``make_batched_features`` (xmat (B, G, 3, 3)). Scenes are sorted by active tiles
    and perceived in calls of ``sub_batch`` (the last padded by repeating its last scene), each
    at ``tile_capacity`` of its largest count. ``f.capacities`` lists the capacities used so far.
    """
    count = make_tile_counter(geom_type, geom_seg, cfg)
    fns: dict[int, object] = {}

    def f(size, xpos, xmat, keys) -> dict:
        xmat = jnp.asarray(xmat, jnp.float32)
        xmat = xmat.reshape(xmat.shape[:-1] + (3, 3)) if xmat.shape[-1] == 9 else xmat
        size, xpos = jnp.asarray(size, jnp.float32), jnp.asarray(xpos, jnp.float32)
        b = size.shape[0]
        n = np.asarray(count(size, xpos, xmat))
        order = np.argsort(n, kind="stable")
        sb = max(1, min(int(sub_batch), b))
        order = np.concatenate([order, np.full(-len(order) % sb, order[-1])])  # pad: repeat the last
        parts = []
        for grp in np.split(order, len(order) // sb):
            k = tile_capacity(int(n[grp].max()), cfg, buckets)  # the config's own: overflow as there
            if k not in fns:
                fns[k] = make_batched_features(geom_type, geom_seg, capacity_config(cfg, k))
            parts.append(fns[k](size[grp], xpos[grp], xmat[grp], keys[grp]))
        parts = jax.device_get(parts)
        out = {}
        for name in parts[0]:
            cat = np.concatenate([p[name] for p in parts])[:b]
            out[name] = np.empty_like(cat)
            out[name][order[:b]] = cat
        return out

    f.capacities = fns
    return f
