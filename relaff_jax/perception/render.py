"""Stage 1: depth images from the camera's rays, and the object pixels of one scene.

Takes a ``SceneGeoms`` and a ``PerceptionConfig``; gives ``render`` (every pixel: depth
(H, W), points/normals (P, 3), seg/geom (P,)), ``active_tiles`` (which image tiles can show
an object), ``render_objects`` (the same rays, only in those tiles) and ``compact_objects``
(object pixels in a fixed buffer of ``max_object_pixels``).
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from relaff_jax.constants import OBJECT_SEGMENTS, SEG_NONE, SEG_OTHER, SEG_TOY

from .camera import camera_frame, camera_rays, intrinsics, tile_rays
from relaff_jax.config.perception import PerceptionConfig
from .ops import cumsum, scatter_set
from .raycast import cast_rays, surface_normals
from .scene import GEOM_BOX, GEOM_SPHERE, SceneGeoms


def _select_static(index, table, default):
    """table[index] for a small static table, as a chain of selects (XLA CPU gathers are slow)."""
    out = jnp.full(index.shape, default, jnp.int32)
    for i, value in enumerate(table):
        out = jnp.where(index == i, value, out)
    return out


def render(scene: SceneGeoms, cfg: PerceptionConfig) -> dict:
    """Noise-free depth image of one scene.

    Returns (P = H*W pixels, row-major):
      depth:  (H, W) camera z in metres, 0 where invalid
      points: (P, 3) robot-frame hit points (0 where invalid)
      normal: (P, 3) robot-frame surface normals at the hits
      seg:    (P,) int32 segment label of the hit geom, -1 if no hit / outside [near, far]
      geom:   (P,) int32 hit geom index, -1 likewise
    """
    cam = cfg.camera
    origin, dirs = camera_rays(cam)
    t, geom = cast_rays(scene, origin, dirs)
    valid = (geom >= 0) & (t >= cam.near) & (t <= cam.far)
    seg = jnp.where(valid, _select_static(geom, scene.geom_seg, SEG_NONE), SEG_NONE)
    geom = jnp.where(valid, geom, -1)
    t = jnp.where(valid, t, 0.0)
    points = jnp.where(valid[:, None], jnp.asarray(origin, jnp.float32) + t[:, None] * jnp.asarray(dirs, jnp.float32), 0.0)
    normal = surface_normals(scene, points, geom)
    return dict(depth=t.reshape(cam.height, cam.width), points=points, normal=normal, seg=seg, geom=geom)


def _box_bounds(corners_cam, fx, fy, cx, cy):
    """Pixel bounds (u_lo, u_hi, v_lo, v_hi) (K,) and depth range (z_lo, z_hi) of K convex
    geoms given by their corners in camera coordinates (K, 8, 3): a convex body in front of the
    camera projects into the hull of its corners' projections; a corner at or behind the
    camera plane gives infinite bounds (every tile)."""
    X, Y, Z = corners_cam[..., 0], corners_cam[..., 1], corners_cam[..., 2]
    z_lo, z_hi = jnp.min(Z, axis=1), jnp.max(Z, axis=1)
    front = z_lo > 1e-6
    zs = jnp.where(front[:, None], Z, 1.0)
    u, v = X / zs * fx + cx, Y / zs * fy + cy
    inf = lambda x, s: jnp.where(front, x, s * jnp.inf)
    return (inf(jnp.min(u, 1), -1), inf(jnp.max(u, 1), 1), inf(jnp.min(v, 1), -1), inf(jnp.max(v, 1), 1),
            z_lo, z_hi)


def _sphere_bounds(centres, rad, fx, fy, cx, cy):
    """Like ``_box_bounds`` for spheres (K, 3) camera coordinates, (K,) radii: for Z - R > 0
    every point has x / z within the extremes of (X +- R) / (Z +- R) (x / z is monotone in x
    and z), likewise y / z."""
    X, Y, Z = centres[:, 0], centres[:, 1], centres[:, 2]
    z_lo, z_hi = Z - rad, Z + rad
    front = z_lo > 1e-6
    z_lo_s = jnp.where(front, z_lo, 1.0)

    def extent(c, f, cc):
        lo = jnp.minimum((c - rad) / z_lo_s, (c - rad) / z_hi) * f + cc
        hi = jnp.maximum((c + rad) / z_lo_s, (c + rad) / z_hi) * f + cc
        return jnp.where(front, lo, -jnp.inf), jnp.where(front, hi, jnp.inf)

    return (*extent(X, fx, cx), *extent(Y, fy, cy), z_lo, z_hi)


_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float32)  # (8, 3)
_MARGIN_PX = 1.0  # float32 rounding of the projection: the bounds grow by a pixel


def active_tiles(scene: SceneGeoms, cfg: PerceptionConfig):
    """(n_tiles,) bool: tiles that the projected bounds of some object geom, grown by
    ``_MARGIN_PX``, overlap. Boxes and capsules: the hull of the projected corners of the
    geom's box (a capsule's: radius, radius, half-length + radius); spheres: the extremes of
    (X +- R) / (Z +- R). Every object pixel lies in an active tile (its ray hits the geom, whose
    projection lies within the bounds); a geom reaching behind the camera activates every tile.
    """
    cam, tile = cfg.camera, cfg.cull.tile
    fx, fy, cx, cy = intrinsics(cam)
    pos, rot = camera_frame(cam)
    obj = [i for i, s in enumerate(scene.geom_seg) if s in OBJECT_SEGMENTS]
    nty, ntx = cam.height // tile, cam.width // tile
    if not obj:
        return jnp.zeros(nty * ntx, bool)
    pos, rot = jnp.asarray(pos, jnp.float32), jnp.asarray(rot, jnp.float32)
    spheres = [i for i in obj if scene.geom_type[i] == GEOM_SPHERE]
    boxes = [i for i in obj if scene.geom_type[i] != GEOM_SPHERE]  # boxes and capsules
    bounds = []
    if spheres:
        ia = np.asarray(spheres)
        centres = (scene.xpos[ia] - pos) @ rot  # (K, 3)
        bounds.append(_sphere_bounds(centres, scene.size[ia, 0], fx, fy, cx, cy))
    if boxes:
        ib = np.asarray(boxes)
        half = jnp.stack([scene.size[i] if scene.geom_type[i] == GEOM_BOX else
                          jnp.stack([scene.size[i, 0], scene.size[i, 0], scene.size[i, 1] + scene.size[i, 0]])
                          for i in boxes])  # (K, 3)
        local = _CORNERS[None] * half[:, None, :]  # (K, 8, 3)
        world = scene.xpos[ib][:, None, :] + jnp.einsum("kij,kcj->kci", scene.xmat[ib], local)
        bounds.append(_box_bounds((world - pos) @ rot, fx, fy, cx, cy))
    u_lo, u_hi, v_lo, v_hi, z_lo, z_hi = (jnp.concatenate(b) for b in zip(*bounds))
    u_lo, v_lo, u_hi, v_hi = u_lo - _MARGIN_PX, v_lo - _MARGIN_PX, u_hi + _MARGIN_PX, v_hi + _MARGIN_PX
    visible = (z_hi > cam.near) & (z_lo < cam.far)
    tx = np.arange(ntx) * tile
    ty = np.arange(nty) * tile
    ox = (tx[None, :] <= u_hi[:, None]) & ((tx + tile)[None, :] >= u_lo[:, None])  # (K, ntx)
    oy = (ty[None, :] <= v_hi[:, None]) & ((ty + tile)[None, :] >= v_lo[:, None])  # (K, nty)
    act = oy[:, :, None] & ox[:, None, :] & visible[:, None, None]
    return jnp.any(act, axis=0).reshape(-1)


def render_objects(scene: SceneGeoms, cfg: PerceptionConfig) -> dict:
    """Like ``render`` but only for the tiles that can show an object (``active_tiles``).

    Casts max_tiles * tile^2 rays against every rendered geom, so occlusion by anything,
    table included, is the same as in ``render``. Returns (R = max_tiles * tile^2 rays):
      pixel (R,) int32 flat pixel index (-1: unused slot), depth (R,), points (R, 3),
      seg (R,) int32 (-1: no valid hit or unused), geom (R,) int32 (no normals: see
      ``surface_normals``, evaluated after compaction on object pixels only),
      tile_overflow () bool: more active tiles than max_tiles (the rest are not cast).
    """
    cam, cc = cfg.camera, cfg.cull
    dirs_t, pix_t = tile_rays(cam, cc.tile)
    act = active_tiles(scene, cfg)
    n_t = dirs_t.shape[0]
    K = min(cc.max_tiles, n_t)
    dest = jnp.where(act, cumsum(act.astype(jnp.int32)) - 1, K)
    slot_tile = scatter_set(jnp.full((K,), -1, jnp.int32), dest, jnp.arange(n_t, dtype=jnp.int32))
    used = slot_tile >= 0
    ts = jnp.maximum(slot_tile, 0)
    dirs = jnp.asarray(dirs_t, jnp.float32)[ts].reshape(-1, 3)
    pixel = jnp.where(used[:, None], jnp.asarray(pix_t)[ts], -1).reshape(-1)
    origin = np.asarray(cam.position, np.float64)
    t, geom = cast_rays(scene, origin, dirs)
    valid = (pixel >= 0) & (geom >= 0) & (t >= cam.near) & (t <= cam.far)
    seg = jnp.where(valid, _select_static(geom, scene.geom_seg, SEG_NONE), SEG_NONE)
    t = jnp.where(valid, t, 0.0)
    points = jnp.where(valid[:, None], jnp.asarray(origin, jnp.float32) + t[:, None] * dirs, 0.0)
    return dict(pixel=pixel, depth=t, points=points, seg=seg,
                geom=jnp.where(valid, geom, -1), tile_overflow=jnp.sum(act) > K)


# The fields of a ``compact_objects`` result with one entry per buffer slot (M, ...).
BUFFER_FIELDS = ("pixel", "points", "geom", "depth", "seg")


def compact_objects(cloud: dict, cfg: PerceptionConfig) -> dict:
    """Keep only object pixels (segments 1, 2) in a fixed buffer of M = max_object_pixels.

    cloud: a ``render`` or ``render_objects`` result (pixel (R,), depth, points (R, 3),
    geom (R,), seg (R,)); a ``render`` result gets pixel = arange(H*W) if it has none.
    Returns pixel (M,) int32 flat pixel index (-1 empty), points (M, 3), geom (M,) int32 hit
    geom (-1 empty), depth (M,), seg (M,) int32 (0 empty), n_pixels (2,) int32 per object,
    pixel_overflow () bool: more object pixels than M (the excess is dropped and flagged).
    """
    M = cfg.voxel.max_object_pixels
    seg = cloud["seg"]
    R = seg.shape[0]
    pixel = cloud.get("pixel")
    if pixel is None:
        pixel = jnp.arange(R, dtype=jnp.int32)
    is_obj = (seg == SEG_TOY) | (seg == SEG_OTHER)
    dest = jnp.where(is_obj, cumsum(is_obj.astype(jnp.int32)) - 1, M)
    # One scatter of source indices, then gathers (cheaper than scattering every field).
    src = scatter_set(jnp.full((M,), -1, jnp.int32), dest, jnp.arange(R, dtype=jnp.int32))
    ok = src >= 0
    s = jnp.maximum(src, 0)
    depth = cloud["depth"].reshape(-1)
    return dict(
        pixel=jnp.where(ok, pixel[s], -1),
        points=jnp.where(ok[:, None], cloud["points"][s], 0.0),
        geom=jnp.where(ok, cloud["geom"][s], -1),
        depth=jnp.where(ok, depth[s], 0.0),
        seg=jnp.where(ok, seg[s], 0),
        n_pixels=jnp.stack([jnp.sum(seg == k) for k in OBJECT_SEGMENTS]).astype(jnp.int32),
        pixel_overflow=jnp.sum(is_obj) > M,
    )
