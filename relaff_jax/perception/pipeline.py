"""The whole perception chain for one scene, and its jitted batched form.

Takes a ``SceneGeoms`` (or a geom layout plus batched sizes/poses), PRNG key(s) and a
``PerceptionConfig``; gives ``point_cloud`` (stages 1-3), ``features_from_voxels``
(stages 4-5) and ``features`` (pca (18,), rhf (300,), unseen (2,), counts, overflow flags);
``make_batched_features`` builds the jitted vmapped version once per layout.
"""
from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.perception import PerceptionConfig
from .descriptors import pca_object, rhf_histograms
from .noise import add_depth_noise
from .normals import pixel_normals
from .raycast import surface_normals
from .render import compact_objects, render_objects
from .scene import SceneGeoms, scene_layout
from .voxels import voxel_downsample


def object_pixels(scene: SceneGeoms, cfg: PerceptionConfig) -> dict:
    """Stage 1 for one scene: the ``compact_objects`` result of ``render_objects`` (noise-free
    object pixels in a buffer of ``voxel.max_object_pixels``) plus its ``tile_overflow``."""
    ro = render_objects(scene, cfg)
    return dict(compact_objects(ro, cfg), tile_overflow=ro["tile_overflow"])


def cloud_from_pixels(scene: SceneGeoms, pix: dict, key, cfg: PerceptionConfig) -> dict:
    """Stages 2-3 on an ``object_pixels`` result: normals, depth noise, voxel grid (returns
    what ``point_cloud`` does). Any buffer length that holds the scene's object pixels gives the same
    bits (slot i's noise is draw i; the voxel sort sees the same valid keys in the same order)."""
    pix = dict(pix)
    tile_overflow = pix.pop("tile_overflow")
    if cfg.normals.source == "ray":  # the exact (noise-free) hit geometry, see docs/perception.md
        pix["normal"] = surface_normals(scene, pix["points"], pix["geom"])
    if cfg.noise.model != "none":
        pix = add_depth_noise(pix, key, cfg)
    if cfg.normals.source == "cloud":  # from the noisy points, as on real data
        pix["normal"] = pixel_normals(pix, cfg)
    vox = voxel_downsample(pix["points"], pix["normal"], pix["seg"], cfg)
    vox["n_pixels"] = pix["n_pixels"]
    vox["pixel_overflow"] = pix["pixel_overflow"]
    vox["tile_overflow"] = tile_overflow
    return dict(pixels=pix, voxels=vox)


def point_cloud(scene: SceneGeoms, key, cfg: PerceptionConfig) -> dict:
    """Stages 1-3 for one scene: object pixels (noisy) and per-object voxel clouds.

    Returns dict(pixels=``compact_objects`` result after noise with normal (M, 3) from
    ``cfg.normals.source``, voxels=``voxel_downsample`` result plus n_pixels, pixel_overflow
    and tile_overflow).
    """
    return cloud_from_pixels(scene, object_pixels(scene, cfg), key, cfg)


@chex.dataclass(frozen=True)
class SceneFeatures:
    """What perception gives for one scene (a pytree; batched, every field gains a leading
    (B,) axis). Also a read-only mapping: ``f["pca"]`` is ``f.pca``.

    pca (18,) float32, rhf (300,) float32, unseen (2,) bool, n_points (2,) int32 occupied
    voxels, n_pixels (2,) int32, overflow () bool and its four causes (see ``features``).
    """

    pca: jax.Array
    rhf: jax.Array
    unseen: jax.Array
    n_points: jax.Array
    n_pixels: jax.Array
    overflow: jax.Array
    tile_overflow: jax.Array
    pixel_overflow: jax.Array
    voxel_overflow: jax.Array
    range_overflow: jax.Array


def features_from_voxels(vox: dict, cfg: PerceptionConfig) -> SceneFeatures:
    """Stages 4-5 on a ``point_cloud(...)["voxels"]`` result; see ``features`` for the outputs."""
    pca_t, un_t = pca_object(vox["points"][0], vox["mask"][0], cfg.min_points)
    pca_o, un_o = pca_object(vox["points"][1], vox["mask"][1], cfg.min_points)
    unseen = jnp.stack([un_t, un_o])
    cnt = jnp.where(jnp.any(unseen), 0, jnp.minimum(vox["count"], cfg.voxel.max_voxels))
    rhf = rhf_histograms(
        vox["points"][0], vox["normals"][0], cnt[0], vox["points"][1], vox["normals"][1], cnt[1], cfg.rhf
    )
    overflow = (vox["tile_overflow"] | vox["pixel_overflow"] | jnp.any(vox["voxel_overflow"])
                | vox["range_overflow"])
    return SceneFeatures(
        pca=jnp.concatenate([pca_t, pca_o]),
        rhf=rhf,
        unseen=unseen,
        n_points=vox["count"],
        n_pixels=vox["n_pixels"],
        overflow=overflow,
        tile_overflow=vox["tile_overflow"],
        pixel_overflow=vox["pixel_overflow"],
        voxel_overflow=vox["voxel_overflow"],
        range_overflow=vox["range_overflow"],
    )


def features(scene: SceneGeoms, key, cfg: PerceptionConfig = PerceptionConfig()) -> SceneFeatures:
    """Whole chain for one scene (pure; vmap over scenes and jit at the caller).

    Returns a ``SceneFeatures``:
      pca (18,) float32: toy [x y z roll pitch yaw eig1 eig2 eig3] then other object, robot
          frame, metres / radians / m^2; an unseen object's nine values are 0.
      rhf (300,) float32: six 50-bin histograms (RHF_NAMES order), each sums to 1, or all 0
          if either object is unseen.
      unseen (2,) bool, n_points (2,) int32 occupied voxels, n_pixels (2,) int32,
      overflow () bool = tile_overflow | pixel_overflow | any(voxel_overflow) | range_overflow
          (each also returned); features of an overflowing scene are computed from the data that
          fit and must not be used silently.
    """
    return features_from_voxels(point_cloud(scene, key, cfg)["voxels"], cfg)


def make_batched_features(geom_type, geom_seg, cfg: PerceptionConfig = PerceptionConfig(), wrap=None):
    """Jitted batched ``features`` for one geom layout, built once.

    Returns f(size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3) or (B, G, 9), keys (B,) keys)
    -> ``SceneFeatures`` of (B, ...) arrays (see ``features``). Same shapes never retrace; ``f.jitted`` is
    the underlying jitted function. ``wrap`` (optional) decorates the single-scene function
    before vmap, e.g. ``chex.assert_max_traces(n=1)`` in tests.
    """
    g = len(np.asarray(geom_type).ravel())
    scene = scene_layout(geom_type, geom_seg)

    def one(size, xpos, xmat, key):
        return features(scene(size, xpos, xmat), key, cfg)

    batched = jax.jit(jax.vmap(wrap(one) if wrap is not None else one))

    def f(size, xpos, xmat, keys):
        xmat = jnp.asarray(xmat, jnp.float32)
        if xmat.shape[-1] == 9:
            xmat = xmat.reshape(xmat.shape[:-1] + (3, 3))
        size = jnp.asarray(size, jnp.float32)
        xpos = jnp.asarray(xpos, jnp.float32)
        b = size.shape[0] if size.ndim == 3 else None
        if size.shape != (b, g, 3) or xpos.shape != (b, g, 3) or xmat.shape != (b, g, 3, 3):
            raise ValueError(f"expected size and xpos (B, {g}, 3), xmat (B, {g}, 3, 3) or (B, {g}, 9); "
                             f"got {size.shape}, {xpos.shape}, {xmat.shape}")
        if len(keys) != b:
            raise ValueError(f"need one PRNG key per scene: {b} scenes, {len(keys)} keys")
        return batched(size, xpos, xmat, keys)

    f.jitted = batched
    return f
