"""The batched feature chain at the cost of what it reads: capacities sized per call.

Takes a geom layout, a ``PerceptionConfig`` and batched scenes (size, xpos, xmat, keys as
``make_batched_features``); gives the same features as ``make_batched_features`` bit for bit
(numpy, one row per scene, input order). ``make_batched_features`` casts ``cull.max_tiles``
tiles (65,536 rays at the default) and compacts into ``voxel.max_object_pixels`` (32,768)
slots per scene whatever the scene shows; here a cheap first pass counts each scene's active
tiles (``render.active_tiles``), scenes are grouped by that count, and each group is cast
(``object_pixels``) by the program compiled for the smallest capacity of ``TILE_BUCKETS``
that holds it: max_tiles = K, max_object_pixels = min(M, K * tile^2). The stages after the
cast (``cloud_from_pixels``, ``features_from_voxels``) then run in a second program on the
buffer cut to the smallest of ``PIXEL_BUCKETS`` that holds the group's object pixels (read
back from the cast), with RHF pair tiles of ``RHF_CHUNK`` columns.

Why the bits stay: every object pixel lies in an active tile and the active tiles keep their
order, so the compacted buffer holds the same pixels in the same slots; slot i's noise is
draw i of ``normal(key, (M',))``, which with JAX's partitionable threefry (the default) is
draw i of ``normal(key, (M,))`` (without it the pixel buffer stays at M; cutting it to the
object pixels only drops empty slots, the same argument); the voxel sort,
scatter and RHF counts see the same valid entries in the same order (the RHF counts are
integers, so their tiling does not matter). Overflow flags are
those of the full capacities: a group with more than the largest bucket's tiles runs at the
config's capacities, where the chain sets ``tile_overflow`` itself; a smaller buffer can
never overflow (object pixels <= K * tile^2). Tested: ``tests/perception/test_features.py``.
"""
from __future__ import annotations

import dataclasses
import functools
import threading
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.perception import PerceptionConfig
from .pipeline import cloud_from_pixels, features_from_voxels, object_pixels
from .render import BUFFER_FIELDS, active_tiles
from .scene import scene_layout

# Tile capacities a group can run at (each one compiled when first used), then the config's.
TILE_BUCKETS = (32, 64, 128)
# Object pixel buffer lengths the stages after the cast can run at (each compiled when first
# used), below the cast's own buffer. Settled scenes show a median of ~2,500 object pixels.
PIXEL_BUCKETS = (2048, 3072, 4096, 6144, 8192)
# XLA options of the chain's programs. The package turns XLA:CPU's fusion emitters off for the
# whole process (relaff_jax/__init__.py: MJX's kinematics need them off); the chain has no MJX,
# and with them its scatters are emitted as loops instead of one-element updates: the RHF took
# 0.57x the CPU time, the whole chain ~0.8x, the same bits (benchmarks/features_emitters.py,
# tests/perception/test_perception.py compares with make_batched_features, compiled without).
CHAIN_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": True}
# RHF pair tile columns (``rhf.chunk``; tiles of ``descriptors.RHF_ROWS`` x this): the
# histograms are integer counts, so any tiling gives the same bits.
RHF_CHUNK = 256


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


def pixel_capacity(count: int, cast_pixels: int, buckets=PIXEL_BUCKETS) -> int:
    """Smallest bucket below the cast's buffer ``cast_pixels`` holding ``count`` object pixels,
    else ``cast_pixels`` (always so if threefry is not partitionable: see ``capacity_config``)."""
    if not jax.config.jax_threefry_partitionable:
        return cast_pixels
    return next((b for b in sorted(buckets) if count <= b < cast_pixels), cast_pixels)


@functools.partial(jax.jit, static_argnums=1)
def cut(pix: dict, m: int) -> dict:
    """A batch of ``object_pixels`` results with the buffer fields cut to their first m slots
    (one dispatch for all of them)."""
    return {name: v[:, :m] if name in BUFFER_FIELDS else v for name, v in pix.items()}


def _layout(geom_type, geom_seg) -> tuple:
    return tuple(int(v) for v in np.asarray(geom_type).ravel()), tuple(int(v) for v in np.asarray(geom_seg).ravel())


def _options(compiler_options) -> tuple:
    """``compiler_options`` as a hashable key (None: ``CHAIN_COMPILER_OPTIONS`` on a CPU backend)."""
    if compiler_options is None:
        compiler_options = CHAIN_COMPILER_OPTIONS if jax.default_backend() == "cpu" else {}
    return tuple(sorted(dict(compiler_options).items()))


class _Programs:
    """The chain's jitted programs of one geom layout, config and XLA options, by capacity:
    ``cast(k)`` (``object_pixels`` at k tiles) and ``rest(m)`` (the stages after the cast on a
    buffer of m slots). One per key (``_programs``), so every ``make_culled_features`` of it
    and ``warmups`` share the programs JAX traced and compiled."""

    def __init__(self, layout: tuple, cfg: PerceptionConfig, options: tuple):
        self.scene, self.cfg, self.options = scene_layout(*layout), cfg, dict(options) or None
        self.casts: dict[int, object] = {}
        self.rests: dict[int, object] = {}
        self.lock = threading.Lock()  # two threads asking for a capacity get one program

    def cast(self, k: int):
        with self.lock:
            if k not in self.casts:
                ck, scene = capacity_config(self.cfg, k), self.scene
                self.casts[k] = jax.jit(jax.vmap(lambda s, x, m: object_pixels(scene(s, x, m), ck)),
                                        compiler_options=self.options)
            return self.casts[k]

    def rest(self, m: int):
        with self.lock:
            if m not in self.rests:
                base = capacity_config(self.cfg, self.cfg.cull.max_tiles)
                cm = dataclasses.replace(base, voxel=dataclasses.replace(base.voxel, max_object_pixels=m))
                scene = self.scene

                def one(s, x, mat, key, pix):
                    return features_from_voxels(cloud_from_pixels(scene(s, x, mat), pix, key, cm)["voxels"], cm)

                self.rests[m] = jax.jit(jax.vmap(one), compiler_options=self.options)
            return self.rests[m]


@functools.lru_cache(maxsize=None)
def _programs(layout: tuple, cfg: PerceptionConfig, options: tuple) -> _Programs:
    return _Programs(layout, cfg, options)


def warmups(geom_type, geom_seg, cfg: PerceptionConfig = PerceptionConfig(), sub_batch: int = 4,
            buckets=TILE_BUCKETS, pixel_buckets=PIXEL_BUCKETS, compiler_options=None) -> list[Callable[[], None]]:
    """Functions of no argument, each tracing and compiling (or loading from the compilation
    cache) one program of ``make_culled_features`` with these arguments at the shapes its calls
    of ``sub_batch`` scenes have: the cast at every tile capacity of ``buckets``, then the
    stages after it at every buffer length of ``pixel_buckets``, on placeholder scenes (zeros).
    A compiled program depends on its arguments' shapes and dtypes, not their values, so a
    later ``make_culled_features`` runs the programs it would have compiled itself: the same
    bits. The generate stage runs them on its background thread while the physics runs
    (``stages/generate.py``), so that the features stage finds them ready."""
    programs = _programs(_layout(geom_type, geom_seg), cfg, _options(compiler_options))
    g, sb = len(_layout(geom_type, geom_seg)[0]), int(sub_batch)
    size, xpos, xmat = (jnp.zeros((sb, g) + s, jnp.float32) for s in ((3,), (3,), (3, 3)))
    tiles = sorted(b for b in buckets if b < cfg.cull.max_tiles)
    keys = jnp.zeros((sb, 2), jnp.uint32)  # raw keys, as from_sim.rollout_keys gives the features stage

    def cast(k):
        jax.block_until_ready(programs.cast(k)(size, xpos, xmat))

    @functools.cache
    def widest():  # the largest cast's output, made once: its buffer holds every bucket below it
        return programs.cast(tiles[-1] if tiles else cfg.cull.max_tiles)(size, xpos, xmat)

    def rest(m):
        pix = widest()
        full = pix["seg"].shape[1]
        jax.block_until_ready(programs.rest(min(m, full))(size, xpos, xmat, keys, cut(pix, m) if m < full else pix))

    return [functools.partial(cast, k) for k in tiles] + [functools.partial(rest, m) for m in sorted(pixel_buckets)]


def make_tile_counter(geom_type, geom_seg, cfg: PerceptionConfig):
    """Jitted ``(size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3)) -> (B,) int32`` active tiles per scene."""
    scene = scene_layout(geom_type, geom_seg)
    return jax.jit(jax.vmap(lambda size, xpos, xmat: jnp.sum(active_tiles(scene(size, xpos, xmat), cfg))))


def make_culled_features(geom_type, geom_seg, cfg: PerceptionConfig = PerceptionConfig(), sub_batch: int = 4,
                         buckets=TILE_BUCKETS, pixel_buckets=PIXEL_BUCKETS, compiler_options=None):
    """``f(size, xpos, xmat, keys) -> dict`` of numpy arrays (B, ...), the fields of
    ``SceneFeatures``, equal to ``make_batched_features(...)(...)`` bit for bit.

    Inputs as ``make_batched_features`` (xmat (B, G, 3, 3)). Scenes are sorted by active tiles
    and perceived in calls of ``sub_batch`` (the last padded by repeating its last scene): the
    cast (``object_pixels``) at ``tile_capacity`` of the call's largest count, then the stages
    after it (``cloud_from_pixels``, ``features_from_voxels``) on the buffer cut to
    ``pixel_capacity`` of its largest object pixel count. ``f.capacities`` lists the tile
    capacities used so far, ``f.pixel_capacities`` the buffer lengths. ``compiler_options``: XLA
    options of the cast and the stages after it (None: ``CHAIN_COMPILER_OPTIONS`` on a CPU
    backend, none elsewhere; ``{}``: the process's own settings).
    """
    programs = _programs(_layout(geom_type, geom_seg), cfg, _options(compiler_options))
    count = make_tile_counter(geom_type, geom_seg, cfg)
    casts: dict[int, object] = {}  # the capacities this function used (the programs are shared)
    rests: dict[int, object] = {}

    def cast(k):
        if k not in casts:
            casts[k] = programs.cast(k)
        return casts[k]

    def rest(m):
        if m not in rests:
            rests[m] = programs.rest(m)
        return rests[m]

    def f(size, xpos, xmat, keys) -> dict:
        xmat = jnp.asarray(xmat, jnp.float32)
        xmat = xmat.reshape(xmat.shape[:-1] + (3, 3)) if xmat.shape[-1] == 9 else xmat
        size, xpos = jnp.asarray(size, jnp.float32), jnp.asarray(xpos, jnp.float32)
        b = size.shape[0]
        n = np.asarray(count(size, xpos, xmat))
        order = np.argsort(n, kind="stable")
        sb = max(1, min(int(sub_batch), b))
        order = np.concatenate([order, np.full(-len(order) % sb, order[-1])])  # pad: repeat the last
        groups = np.split(order, len(order) // sb)
        # Every cast is dispatched before the first pixel count is read back.
        pixels = [cast(tile_capacity(int(n[grp].max()), cfg, buckets))(size[grp], xpos[grp], xmat[grp])
                  for grp in groups]
        parts = []
        for grp, pix in zip(groups, pixels):
            full = pix["seg"].shape[1]
            m = pixel_capacity(int(np.asarray(pix["n_pixels"]).sum(1).max()), full, pixel_buckets)
            if m < full:
                pix = cut(pix, m)
            parts.append(rest(m)(size[grp], xpos[grp], xmat[grp], keys[grp], pix))
        parts = jax.device_get(parts)
        out = {}
        for name in parts[0]:
            cat = np.concatenate([p[name] for p in parts])[:b]
            out[name] = np.empty_like(cat)
            out[name][order[:b]] = cat
        return out

    f.capacities = casts
    f.pixel_capacities = rests
    return f
