"""Perception (paper section IV-B): simulated Kinect -> segmented clouds -> PCA and RHF features.

Takes one settled scene described by its geoms (``SceneGeoms``: static MuJoCo geom types and
segment labels, per-scene sizes, positions and rotation matrices in the robot frame) and a
PRNG key; returns the paper's two state spaces for that scene:

* ``pca``  (18,)  toy's 9 values then the other object's 9 (centroid xyz, roll/pitch/yaw of
  the eigenvector frame, three eigenvalues), canonical order, the learning stage reorders;
* ``rhf``  (300,) six 50-bin relational histograms over all (toy point, other point) pairs;
* ``unseen`` (2,) flags, ``n_points`` (2,) voxel counts and overflow flags.

Stages, each a pure single-scene function (vmap at the caller, the caller owns jit):

1. ``render``      : pinhole depth camera, one ray per pixel cast against the geoms with our
                     own ray-primitive intersection (plane, sphere, capsule, box); the hit
                     geom's segment label stands in for colour segmentation. The feature path
                     uses ``render_objects`` (the same rays, only in image tiles that can show
                     an object) and ``compact_objects`` (object pixels into a fixed buffer).
2. ``add_depth_noise``: z noise in the camera frame (RobWork model, or Khoshelham-Elberink,
                     Nguyen), keyed.
3. ``voxel_downsample``: per object, one point per occupied 0.0125 m voxel at the centroid of
                     its points (Open3D ``voxel_down_sample`` semantics), fixed capacity, overflow
                     flagged.
4. ``pca_object``  : centroid, roll/pitch/yaw, eigenvalues; ``unseen`` below ``min_points``.
5. ``rhf_histograms``: normals from the ray-hit geometry averaged per voxel; six histograms,
                     computed tile by tile so memory does not grow with the point count.

``features`` chains them for one scene; ``make_batched_features`` builds the jitted batch
version once; ``render_scene_png`` draws what the robot saw. Exact definitions (camera pose,
noise formulas, voxel grid origin, angle convention, sign rule, RHF bins) are in
docs/perception.md.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

# MuJoCo mjtGeom values we can render.
GEOM_PLANE, GEOM_SPHERE, GEOM_CAPSULE, GEOM_BOX = 0, 2, 3, 6
SUPPORTED_GEOMS = {GEOM_PLANE: "plane", GEOM_SPHERE: "sphere", GEOM_CAPSULE: "capsule", GEOM_BOX: "box"}

from relaff_jax.constants import OBJECT_SEGMENTS, SEG_BACKGROUND, SEG_NONE, SEG_OTHER, SEG_TOY  # noqa: F401

PCA_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "eig_major", "eig_middle", "eig_minor")
RHF_NAMES = ("dx", "dy", "dz", "dist", "angle_na_nb", "angle_na_d")

_BITS = 9  # voxel index bits per axis in the sort key: 512 voxels = 6.4 m per object
_KEY_EMPTY = 1 << 30


def _make_scatter(op: str):
    """``target.at[idx].<op>(upd, mode="drop")`` along axis 0, with a vmap rule that folds the
    batch into a 1-D index. XLA CPU lowers a vmapped scatter to (batch, index) pairs built in
    an unvectorised fusion together with everything that computes the index (measured 5-20x
    slower than this flat form)."""

    @jax.custom_batching.custom_vmap
    def scatter(target, idx, upd):
        return getattr(target.at[idx], op)(upd, mode="drop")

    @scatter.def_vmap
    def _rule(axis_size, in_batched, target, idx, upd):
        bc = lambda x, b: x if b else jnp.broadcast_to(x, (axis_size,) + x.shape)
        target, idx, upd = (bc(x, b) for x, b in zip((target, idx, upd), in_batched))
        k = target.shape[1]
        offs = (jnp.arange(axis_size, dtype=idx.dtype) * k).reshape((-1,) + (1,) * (idx.ndim - 1))
        flat = jnp.where((idx >= 0) & (idx < k), idx + offs, axis_size * k)  # out of range stays dropped
        out = scatter(target.reshape((-1,) + target.shape[2:]), flat.reshape(-1),
                      upd.reshape((-1,) + upd.shape[idx.ndim:]))
        return out.reshape(target.shape), True

    return scatter


_scatter_add = _make_scatter("add")
_scatter_set = _make_scatter("set")


def _cumsum(x):
    """Inclusive prefix sum; XLA CPU's reduce-window cumsum is ~2x slower than this scan."""
    return jax.lax.associative_scan(jnp.add, x)


# ----------------------------------------------------------------------------- configs


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """Pinhole depth camera (RobWork's simulated Kinect intrinsics, REFERENCE section 3).

    fy = fx = (height / 2) / tan(vfov / 2), cx = width / 2, cy = height / 2; the pose looks from
    ``position`` at ``target`` with the image's "up" towards world +z.
    """

    width: int = 640
    height: int = 480
    vfov_deg: float = 43.0
    position: tuple[float, float, float] = (2.9, 0.0, 2.3)
    target: tuple[float, float, float] = (0.7, 0.0, 0.0)
    near: float = 0.01
    far: float = 6.0


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """Depth noise: ``model`` in {"robwork", "khoshelham", "nguyen", "none"}."""

    model: str = "robwork"


@dataclasses.dataclass(frozen=True)
class VoxelConfig:
    """Voxel grid subsampling (paper: 0.0125 m) with fixed capacities.

    ``max_object_pixels``: object pixels (both objects) kept per scene before voxelisation;
    ``max_voxels``: voxels per object. Exceeding either sets an overflow flag.
    """

    size: float = 0.0125
    max_object_pixels: int = 32768
    max_voxels: int = 4096


@dataclasses.dataclass(frozen=True)
class RHFConfig:
    """Relational histogram features: one (lo, hi) range per feature, ``bins`` bins each.

    Features in order: dx, dy, dz (of b - a, metres, robot frame), |b - a| (m),
    angle(n_a, n_b), angle(n_a, b - a) (radians). Values outside a range go to its end bin.
    Ranges are shifted off round numbers so that frequent exact values never sit on a bin
    edge, where float rounding would pick the bin: the signed ranges by 1/3 bin (object
    sizes are whole millimetres, so noise-free top faces give dz in whole mm, >= 1/3 mm from
    an edge), the angle ranges by 1/6 bin (normals are exact: 0, 90 and, at voxels on box
    edges, 45 deg are frequent; 0, 30, 45, 60, 90 deg are all >= 1/6 bin from an edge; on
    [0, pi] 90 deg would be an edge). 180 deg clips into the last bin.
    ``chunk``: tile edge of the pairwise work (``chunk`` x ``chunk`` pairs at a time).
    """

    bins: int = 50
    ranges: tuple[tuple[float, float], ...] = (
        (-0.5 - 0.02 / 3, 0.5 - 0.02 / 3),
        (-0.5 - 0.02 / 3, 0.5 - 0.02 / 3),
        (-0.25 - 0.01 / 3, 0.25 - 0.01 / 3),
        (0.0, 0.75),
        (-float(np.pi) / 300, float(np.pi) * 299 / 300),
        (-float(np.pi) / 300, float(np.pi) * 299 / 300),
    )
    chunk: int = 256


@dataclasses.dataclass(frozen=True)
class CullConfig:
    """Which pixels the feature path ray-casts: image tiles of ``tile`` x ``tile`` pixels that a
    conservative projection of an object geom's bounding sphere touches, at most ``max_tiles``
    (more sets ``tile_overflow``). Pixels outside these tiles cannot show an object. The
    largest library object at the workspace point nearest the camera needs ~120 tiles."""

    tile: int = 16
    max_tiles: int = 256


@dataclasses.dataclass(frozen=True)
class PerceptionConfig:
    """All perception settings; ``min_points``: voxels below which an object is ``unseen``."""

    camera: CameraConfig = CameraConfig()
    noise: NoiseConfig = NoiseConfig()
    voxel: VoxelConfig = VoxelConfig()
    rhf: RHFConfig = RHFConfig()
    cull: CullConfig = CullConfig()
    min_points: int = 10


def validate_config(cfg: PerceptionConfig) -> PerceptionConfig:
    """Raise ValueError naming the bad setting; return ``cfg`` unchanged otherwise."""
    cam = cfg.camera
    if cam.width <= 0 or cam.height <= 0:
        raise ValueError(f"camera size must be positive, got {cam.width}x{cam.height}")
    if not 0.0 < cam.vfov_deg < 180.0:
        raise ValueError(f"camera.vfov_deg must be in (0, 180), got {cam.vfov_deg}")
    if not 0.0 <= cam.near < cam.far:
        raise ValueError(f"need 0 <= camera.near < camera.far, got {cam.near}, {cam.far}")
    if np.linalg.norm(np.subtract(cam.target, cam.position)) == 0.0:
        raise ValueError("camera.target equals camera.position")
    if cfg.noise.model not in NOISE_MODELS:
        raise ValueError(f"unknown noise.model {cfg.noise.model!r}; valid: {sorted(NOISE_MODELS)}")
    if cfg.voxel.size <= 0:
        raise ValueError(f"voxel.size must be positive, got {cfg.voxel.size}")
    if cfg.voxel.max_object_pixels <= 0 or cfg.voxel.max_voxels <= 0:
        raise ValueError("voxel capacities must be positive")
    r = cfg.rhf
    if r.bins <= 0 or r.chunk <= 0:
        raise ValueError(f"rhf.bins and rhf.chunk must be positive, got {r.bins}, {r.chunk}")
    if cfg.voxel.max_voxels % r.chunk:
        raise ValueError(
            f"voxel.max_voxels ({cfg.voxel.max_voxels}) must be a multiple of rhf.chunk ({r.chunk})"
        )
    if len(r.ranges) != len(RHF_NAMES) or any(hi <= lo for lo, hi in r.ranges):
        raise ValueError(f"rhf.ranges needs {len(RHF_NAMES)} (lo, hi) pairs with hi > lo, got {r.ranges}")
    t = cfg.cull.tile
    if t <= 0 or cam.width % t or cam.height % t:
        raise ValueError(f"cull.tile ({t}) must divide the image size {cam.width}x{cam.height}")
    if cfg.cull.max_tiles <= 0:
        raise ValueError(f"cull.max_tiles must be positive, got {cfg.cull.max_tiles}")
    if cfg.min_points < 3:
        raise ValueError(f"min_points must be >= 3 for a PCA frame, got {cfg.min_points}")
    return cfg


# ----------------------------------------------------------------------------- scene


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["size", "xpos", "xmat"],
    meta_fields=["geom_type", "geom_seg"],
)
@dataclasses.dataclass(frozen=True)
class SceneGeoms:
    """Geoms of one settled scene (a pytree; the two tuples are static).

    geom_type: (G,) MuJoCo mjtGeom ints (plane 0, sphere 2, capsule 3, box 6)
    geom_seg:  (G,) segment label: 0 table/background, 1 toy, 2 other object, -1 never rendered
    size:      (G, 3) MuJoCo geom_size
    xpos:      (G, 3) geom centres, robot frame
    xmat:      (G, 3, 3) rotations, columns = geom axes in the robot frame
    """

    geom_type: tuple[int, ...]
    geom_seg: tuple[int, ...]
    size: Any
    xpos: Any
    xmat: Any


def make_scene(geom_type, geom_seg, size, xpos, xmat) -> SceneGeoms:
    """Build a ``SceneGeoms`` with checked static info; ``xmat`` may be (..., G, 9)."""
    gt = tuple(int(t) for t in np.asarray(geom_type).ravel())
    gs = tuple(int(s) for s in np.asarray(geom_seg).ravel())
    if len(gt) != len(gs):
        raise ValueError(f"geom_type has {len(gt)} entries but geom_seg has {len(gs)}")
    for i, (t, s) in enumerate(zip(gt, gs)):
        if s not in (SEG_NONE, SEG_BACKGROUND, SEG_TOY, SEG_OTHER):
            raise ValueError(f"geom {i}: segment label {s} not in (-1, 0, 1, 2)")
        if s != SEG_NONE and t not in SUPPORTED_GEOMS:
            raise ValueError(
                f"geom {i}: mjtGeom {t} cannot be rendered (supported: {SUPPORTED_GEOMS}); "
                "give it segment -1 or use a supported primitive"
            )
        if s in OBJECT_SEGMENTS and t == GEOM_PLANE:
            raise ValueError(f"geom {i}: a plane cannot be part of object segment {s}")
    xmat = jnp.asarray(xmat, jnp.float32)
    xmat = xmat.reshape(xmat.shape[:-1] + (3, 3)) if xmat.shape[-1] == 9 else xmat
    size = jnp.asarray(size, jnp.float32)
    xpos = jnp.asarray(xpos, jnp.float32)
    g = len(gt)
    if size.shape[-2:] != (g, 3) or xpos.shape[-2:] != (g, 3) or xmat.shape[-3:] != (g, 3, 3):
        raise ValueError(
            f"expected size/xpos (..., {g}, 3) and xmat (..., {g}, 3, 3), got "
            f"{size.shape}, {xpos.shape}, {xmat.shape}"
        )
    return SceneGeoms(gt, gs, size, xpos, xmat)


def scene_from_mujoco(model, data, geom_seg) -> SceneGeoms:
    """``SceneGeoms`` of a native MuJoCo (MjModel, MjData) after ``mj_forward``."""
    return make_scene(model.geom_type, geom_seg, model.geom_size, data.geom_xpos, data.geom_xmat)


# ----------------------------------------------------------------------------- 1. camera


def camera_frame(cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Camera origin (3,) and rotation (3, 3) whose columns are the camera x (image right),
    y (image down) and z (optical axis) axes in the robot frame (OpenCV convention)."""
    pos = np.asarray(cam.position, np.float64)
    fwd = np.asarray(cam.target, np.float64) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("camera looks straight up or down; cannot orient the image with world +z up")
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return pos, np.stack([right, down, fwd], axis=1)


def intrinsics(cam: CameraConfig) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels; 640x480 at 43 deg gives fx = fy ~ 609.3, (320, 240)."""
    fy = (cam.height / 2.0) / np.tan(np.deg2rad(cam.vfov_deg) / 2.0)
    return fy, fy, cam.width / 2.0, cam.height / 2.0


def camera_rays(cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Static rays: origin (3,) and directions (H*W, 3) in the robot frame, row-major pixels.

    Pixel (v, u) looks through ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1) in the camera frame;
    directions are *not* normalised, their camera-z component is 1, so the ray parameter of a
    hit is the depth z.
    """
    fx, fy, cx, cy = intrinsics(cam)
    pos, rot = camera_frame(cam)
    u = (np.arange(cam.width) + 0.5 - cx) / fx
    v = (np.arange(cam.height) + 0.5 - cy) / fy
    uu, vv = np.meshgrid(u, v)
    d_cam = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    return pos, d_cam @ rot.T


# Ray-primitive tests work on structure-of-arrays: lo (3,) local origin, ld (3, N) local
# directions, so every operation is a plain (N,) vector op (XLA CPU vectorises these; reductions
# over a trailing axis of length 3 it does not).


def _ray_plane(lo, ld, size):
    """Front-face hit of the local z=0 plane, finite if size[0], size[1] > 0 (as mj_ray)."""
    lz = ld[2]
    t = -lo[2] / jnp.where(lz < 0, lz, -1.0)
    px, py = lo[0] + t * ld[0], lo[1] + t * ld[1]
    inside = ((size[0] <= 0) | (jnp.abs(px) <= size[0])) & ((size[1] <= 0) | (jnp.abs(py) <= size[1]))
    return jnp.where((lz < 0) & (t >= 0) & inside, t, jnp.inf)


def _sphere_hits(lo, ld, centre, radius):
    """Both ray parameters (near, far) of a sphere, stable form (closest approach), inf if missed.

    Solving the quadratic directly loses ~1e-5 m at 3 m in float32; projecting first does not.
    """
    dd = ld[0] * ld[0] + ld[1] * ld[1] + ld[2] * ld[2]
    oc = [lo[i] - centre[i] for i in range(3)]
    tc = -(oc[0] * ld[0] + oc[1] * ld[1] + oc[2] * ld[2]) / dd  # closest approach, in ray units
    q = [oc[i] + tc * ld[i] for i in range(3)]
    h2 = (radius * radius - (q[0] * q[0] + q[1] * q[1] + q[2] * q[2])) / dd
    h = jnp.sqrt(jnp.maximum(h2, 0.0))
    ok = h2 >= 0
    return jnp.where(ok, tc - h, jnp.inf), jnp.where(ok, tc + h, jnp.inf)


def _first_nonneg(t_near, t_far):
    t = jnp.where(t_near >= 0, t_near, t_far)
    return jnp.where(t >= 0, t, jnp.inf)


def _ray_sphere(lo, ld, size):
    return _first_nonneg(*_sphere_hits(lo, ld, (0.0, 0.0, 0.0), size[0]))


def _ray_capsule(lo, ld, size):
    """Capsule along local z: radius size[0], half-length size[1]; cylinder + two caps."""
    r, hl = size[0], size[1]
    # Infinite cylinder, 2-D closest-approach form.
    dd = ld[0] * ld[0] + ld[1] * ld[1]
    dd_safe = jnp.where(dd > 0, dd, 1.0)
    tc = -(lo[0] * ld[0] + lo[1] * ld[1]) / dd_safe
    qx, qy = lo[0] + tc * ld[0], lo[1] + tc * ld[1]
    h2 = (r * r - (qx * qx + qy * qy)) / dd_safe
    h = jnp.sqrt(jnp.maximum(h2, 0.0))
    ok = (h2 >= 0) & (dd > 0)
    best = jnp.full_like(tc, jnp.inf)
    for c in (tc - h, tc + h):
        on_segment = jnp.abs(lo[2] + c * ld[2]) <= hl  # keep roots on the cylinder part
        best = jnp.minimum(best, jnp.where(ok & on_segment & (c >= 0), c, jnp.inf))
    for sgn in (1.0, -1.0):
        for c in _sphere_hits(lo, ld, (0.0, 0.0, sgn * hl), r):
            best = jnp.minimum(best, jnp.where(c >= 0, c, jnp.inf))
    return best


def _ray_box(lo, ld, size):
    """Slab method: entry parameter (exit if the origin is inside)."""
    t_in = jnp.full(ld.shape[1:], -jnp.inf)
    t_out = jnp.full(ld.shape[1:], jnp.inf)
    for i in range(3):
        d = ld[i]
        d = jnp.where(jnp.abs(d) < 1e-30, jnp.where(d < 0, -1e-30, 1e-30), d)
        inv = 1.0 / d
        t1 = (-size[i] - lo[i]) * inv
        t2 = (size[i] - lo[i]) * inv
        t_in = jnp.maximum(t_in, jnp.minimum(t1, t2))
        t_out = jnp.minimum(t_out, jnp.maximum(t1, t2))
    hit = (t_out >= t_in) & (t_out >= 0)
    return jnp.where(hit, jnp.where(t_in < 0, t_out, t_in), jnp.inf)


def _normal_plane(pl, size):
    return [jnp.zeros_like(pl[0]), jnp.zeros_like(pl[0]), jnp.ones_like(pl[0])]


def _unit(v):
    n = jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    n = jnp.maximum(n, 1e-12)
    return [v[0] / n, v[1] / n, v[2] / n]


def _normal_sphere(pl, size):
    return _unit(pl)


def _normal_capsule(pl, size):
    z = pl[2] - jnp.clip(pl[2], -size[1], size[1])
    return _unit([pl[0], pl[1], z])


def _normal_box(pl, size):
    # The face the hit lies on is the axis where |p| / half-size is largest.
    r = [jnp.abs(pl[i]) / jnp.maximum(size[i], 1e-12) for i in range(3)]
    x_wins = (r[0] >= r[1]) & (r[0] >= r[2])
    y_wins = ~x_wins & (r[1] >= r[2])
    z_wins = ~x_wins & ~y_wins
    return [jnp.where(w, jnp.sign(pl[i]), 0.0) for i, w in enumerate((x_wins, y_wins, z_wins))]


_RAY_FNS = {GEOM_PLANE: _ray_plane, GEOM_SPHERE: _ray_sphere, GEOM_CAPSULE: _ray_capsule, GEOM_BOX: _ray_box}
_NORMAL_FNS = {GEOM_PLANE: _normal_plane, GEOM_SPHERE: _normal_sphere, GEOM_CAPSULE: _normal_capsule,
               GEOM_BOX: _normal_box}


def _rotate_t(rot, v):
    """rot.T @ v for v (3, N) written out: XLA CPU runs tiny-matrix dots ~10x slower than
    the equivalent elementwise arithmetic, batched or not."""
    return jnp.stack([rot[0, j] * v[0] + rot[1, j] * v[1] + rot[2, j] * v[2] for j in range(3)])


def _select_static(index, table, default):
    """table[index] for a small static table, as a chain of selects (XLA CPU gathers are slow)."""
    out = jnp.full(index.shape, default, jnp.int32)
    for i, value in enumerate(table):
        out = jnp.where(index == i, value, out)
    return out


def _geom_table(scene: SceneGeoms):
    """Rendered geoms as scan inputs: (branch (K,), rot (K, 3, 3), pos (K, 3), size (K, 3),
    geom id (K,)) and the geom types of the branches."""
    rendered = [i for i, s in enumerate(scene.geom_seg) if s != SEG_NONE]
    if not rendered:
        raise ValueError("scene has no rendered geoms")
    types = sorted({scene.geom_type[i] for i in rendered})
    ia = np.asarray(rendered)
    branch = np.asarray([types.index(scene.geom_type[i]) for i in rendered], np.int32)
    return (branch, scene.xmat[ia], scene.xpos[ia], scene.size[ia], ia.astype(np.int32)), types


def cast_rays(scene: SceneGeoms, origin, dirs):
    """Nearest hit of each ray over the rendered geoms (segment != -1).

    origin: (3,) robot frame; dirs: (N, 3) robot frame (any length).
    Returns t (N,) ray parameter (inf: no hit) and geom (N,) int32 geom index (-1: no hit).

    A ``lax.scan`` over the geoms with a ``lax.switch`` on the (static, unbatched) type keeps
    a running minimum. The loop matters on the CPU: XLA drops optimization barriers and, when
    the cast is written as straight-line code, fuses all of it into every consumer and
    recomputes it there unvectorised (measured 20-70x slower); a loop boundary it cannot fuse.
    """
    origin = jnp.asarray(origin, jnp.float32)
    dirs_t = jnp.asarray(dirs, jnp.float32).T  # (3, N)
    xs, types = _geom_table(scene)
    branches = [_RAY_FNS[ty] for ty in types]

    def step(carry, x):
        t, k = carry
        b, rot, pos, size, gid = x
        lo, ld = rot.T @ (origin - pos), _rotate_t(rot, dirs_t)
        ti = jax.lax.switch(b, branches, lo, ld, size) if len(branches) > 1 else branches[0](lo, ld, size)
        closer = ti < t
        return (jnp.where(closer, ti, t), jnp.where(closer, gid, k)), None

    init = (jnp.full(dirs_t.shape[1:], jnp.inf), jnp.full(dirs_t.shape[1:], -1, jnp.int32))
    (t, k), _ = jax.lax.scan(step, init, xs)
    return t, k


def surface_normals(scene: SceneGeoms, points, geom):
    """Unit outward normals (N, 3) of geom ``geom`` (N,) at surface points ``points`` (N, 3),
    robot frame; (0, 0, 1) where geom < 0. A scan over geoms, like ``cast_rays``."""
    p = jnp.asarray(points, jnp.float32).T
    xs, types = _geom_table(scene)
    branches = [_NORMAL_FNS[ty] for ty in types]

    def step(normal, x):
        b, rot, pos, size, gid = x
        pl = _rotate_t(rot, p - pos[:, None])
        nl = jax.lax.switch(b, branches, pl, size) if len(branches) > 1 else branches[0](pl, size)
        nl = jnp.stack(nl)
        nw = jnp.stack([rot[j, 0] * nl[0] + rot[j, 1] * nl[1] + rot[j, 2] * nl[2] for j in range(3)])
        return jnp.where(geom == gid, nw, normal), None

    init = jnp.zeros_like(p).at[2].set(1.0)
    normal, _ = jax.lax.scan(step, init, xs)
    return normal.T


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


def bounding_radius(geom_type: int, size):
    """Radius of a sphere about the geom centre enclosing the geom. size: (..., 3)."""
    if geom_type == GEOM_SPHERE:
        return size[..., 0]
    if geom_type == GEOM_CAPSULE:
        return size[..., 0] + size[..., 1]
    if geom_type == GEOM_BOX:
        return jnp.linalg.norm(size, axis=-1)
    raise ValueError(f"no bounding sphere for mjtGeom {geom_type} ({SUPPORTED_GEOMS.get(geom_type)})")


def tile_rays(cam: CameraConfig, tile: int) -> tuple[np.ndarray, np.ndarray]:
    """Static per-tile rays: dirs (n_tiles, tile*tile, 3) and flat pixel index (n_tiles, tile*tile).

    Tiles are numbered row-major over the (H / tile, W / tile) grid."""
    _, dirs = camera_rays(cam)
    H, W = cam.height, cam.width
    pix = np.arange(H * W, dtype=np.int32).reshape(H // tile, tile, W // tile, tile)
    pix = pix.transpose(0, 2, 1, 3).reshape(-1, tile * tile)
    return dirs[pix], pix


def active_tiles(scene: SceneGeoms, cfg: PerceptionConfig):
    """(n_tiles,) bool: tiles that a conservative projection of any object geom's bounding
    sphere overlaps. For a sphere (X, Y, Z, R) in camera coordinates with Z - R > 0 every
    point has x / z within the extremes of (X +- R) / (Z +- R) (x / z is monotone in x and
    z), likewise y / z; a sphere reaching behind the camera activates every tile."""
    cam, tile = cfg.camera, cfg.cull.tile
    fx, fy, cx, cy = intrinsics(cam)
    pos, rot = camera_frame(cam)
    obj = [i for i, s in enumerate(scene.geom_seg) if s in OBJECT_SEGMENTS]
    nty, ntx = cam.height // tile, cam.width // tile
    if not obj:
        return jnp.zeros(nty * ntx, bool)
    ia = np.asarray(obj)
    centres = (scene.xpos[ia] - jnp.asarray(pos, jnp.float32)) @ jnp.asarray(rot, jnp.float32)  # (K, 3)
    rad = jnp.stack([bounding_radius(scene.geom_type[i], scene.size[i]) for i in obj])
    X, Y, Z = centres[:, 0], centres[:, 1], centres[:, 2]
    z_lo, z_hi = Z - rad, Z + rad
    front = z_lo > 1e-6
    z_lo_s = jnp.where(front, z_lo, 1.0)

    def extent(c, f, cc):
        lo = jnp.minimum((c - rad) / z_lo_s, (c - rad) / z_hi) * f + cc
        hi = jnp.maximum((c + rad) / z_lo_s, (c + rad) / z_hi) * f + cc
        return jnp.where(front, lo, -jnp.inf), jnp.where(front, hi, jnp.inf)

    u_lo, u_hi = extent(X, fx, cx)
    v_lo, v_hi = extent(Y, fy, cy)
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
    dest = jnp.where(act, _cumsum(act.astype(jnp.int32)) - 1, K)
    slot_tile = _scatter_set(jnp.full((K,), -1, jnp.int32), dest, jnp.arange(n_t, dtype=jnp.int32))
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
    dest = jnp.where(is_obj, _cumsum(is_obj.astype(jnp.int32)) - 1, M)
    # One scatter of source indices, then gathers (cheaper than scattering every field).
    src = _scatter_set(jnp.full((M,), -1, jnp.int32), dest, jnp.arange(R, dtype=jnp.int32))
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


# ----------------------------------------------------------------------------- 2. noise


def _sigma_robwork(depth, r):
    d = depth * 1000.0  # mm
    s = 2.344 - 1.202e-2 * r - 1.734e-3 * d + 1.818e-5 * r * r + 6.516e-6 * r * d + 1.233e-6 * d * d
    return jnp.maximum(s, 0.0) / 1000.0


NOISE_MODELS: dict[str, Callable] = {
    "robwork": _sigma_robwork,
    "khoshelham": lambda z, r: 1.425e-3 * z * z,
    "nguyen": lambda z, r: 0.0012 + 0.0019 * (z - 0.4) ** 2,
    "none": lambda z, r: jnp.zeros_like(z),
}


def pixel_radius(pixel, cam: CameraConfig):
    """Distance (px) of flat pixel indices from the image centre, rescaled to a 640-wide image
    so the RobWork polynomial (fitted at 640x480) means the same at any resolution."""
    _, _, cx, cy = intrinsics(cam)
    u = (pixel % cam.width).astype(jnp.float32) + 0.5 - cx
    v = (pixel // cam.width).astype(jnp.float32) + 0.5 - cy
    return jnp.hypot(u, v) * (640.0 / cam.width)


def depth_noise_sigma(depth, pixel, cam: CameraConfig, model: str):
    """Noise std (m) for ``depth`` (...,) metres at flat pixel indices ``pixel`` (...,)."""
    if model not in NOISE_MODELS:
        raise ValueError(f"unknown noise model {model!r}; valid: {sorted(NOISE_MODELS)}")
    return NOISE_MODELS[model](depth, pixel_radius(pixel, cam))


def add_depth_noise(cloud: dict, key, cfg: PerceptionConfig) -> dict:
    """Add z ~ N(0, sigma(depth, r)) along the optical axis to every valid pixel of ``cloud``.

    ``cloud`` is a ``render`` result (every pixel) or a ``compact_objects`` result (object pixels
    only: the table is dropped anyway, so this draws 32k instead of 307k normals). Valid entries
    have pixel >= 0 and seg >= 0. Only the camera-frame z of a point changes (its camera x, y
    stay): the paper's "noise on the z-coordinate". Returns a copy with new depth and points.
    """
    cam = cfg.camera
    depth = cloud["depth"].reshape(-1)
    pixel = cloud.get("pixel")
    if pixel is None:
        pixel = jnp.arange(depth.shape[0], dtype=jnp.int32)
    valid = (pixel >= 0) & (cloud["seg"] >= 0)
    sigma = depth_noise_sigma(depth, pixel, cam, cfg.noise.model)
    eps = jnp.where(valid, sigma * jax.random.normal(key, sigma.shape), 0.0)
    fwd = jnp.asarray(camera_frame(cam)[1][:, 2], jnp.float32)
    out = dict(cloud)
    out["depth"] = (depth + eps).reshape(cloud["depth"].shape)
    out["points"] = cloud["points"] + eps[:, None] * fwd
    return out


# ----------------------------------------------------------------------------- 3. voxels


def voxel_downsample(points, normals, seg, cfg: PerceptionConfig) -> dict:
    """Open3D-style voxel grid per object segment, static shapes.

    points: (P, 3), normals: (P, 3), seg: (P,) int32 labels (only 1 and 2 are used).
    Per object the grid origin is (min bound of that object's points) - size / 2, and a point
    goes to voxel floor((p - origin) / size), exactly as ``open3d voxel_down_sample``.
    Returns (O = 2 objects in order toy, other; V = max_voxels):
      points (O, V, 3) voxel centroids, normals (O, V, 3) unit mean hit normals
      ((0, 0, 1) if the mean is ~0), mask (O, V) bool (valid voxels first, sorted by
      (iz, iy, ix)), count (O,) int32 occupied voxels (may exceed V), voxel_overflow (O,),
      range_overflow () (an object wider than 512 voxels = 6.4 m) bools.
    """
    vc = cfg.voxel
    V, size = vc.max_voxels, vc.size
    occ = (seg == SEG_TOY) | (seg == SEG_OTHER)
    obj = jnp.where(occ, seg - 1, 0)
    mins = jnp.stack(
        [jnp.min(jnp.where((seg == s)[:, None], points, jnp.inf), axis=0) for s in OBJECT_SEGMENTS]
    )
    origin = jnp.where(jnp.isfinite(mins), mins - size / 2.0, 0.0)  # (O, 3)
    rel = points - origin[obj]
    ijk = jnp.floor(rel / size).astype(jnp.int32)
    lim = (1 << _BITS) - 1
    range_overflow = jnp.any(occ[:, None] & (ijk > lim))
    ijk = jnp.clip(ijk, 0, lim)
    key = (obj << (3 * _BITS)) | (ijk[:, 2] << (2 * _BITS)) | (ijk[:, 1] << _BITS) | ijk[:, 0]
    key = jnp.where(occ, key, _KEY_EMPTY)
    # A single-operand sort is ~6x faster than sorting (key, index) pairs on the CPU; each
    # point then finds its voxel's rank by binary search in the sorted keys.
    key_s = jnp.sort(key)
    valid_s = key_s < _KEY_EMPTY
    prev = jnp.concatenate([jnp.full((1,), -1, key_s.dtype), key_s[:-1]])
    new = valid_s & (key_s != prev)
    uid_s = _cumsum(new.astype(jnp.int32)) - 1
    obj_s = key_s >> (3 * _BITS)
    count = jnp.stack([jnp.sum(new & (obj_s == o)) for o in range(2)]).astype(jnp.int32)
    uid = uid_s[jnp.searchsorted(key_s, key, method="scan")]
    slot = uid - jnp.where(obj == 1, count[0], 0)
    seg_id = jnp.where(occ & (slot < V), obj * V + slot, 2 * V)  # 2V: dropped
    # Sum offsets from the per-object origin (not absolute coordinates): better float32 means.
    stacked = jnp.concatenate([rel, normals, occ[:, None].astype(rel.dtype)], axis=1)
    sums = _scatter_add(jnp.zeros((2 * V, 7), rel.dtype), seg_id, stacked).reshape(2, V, 7)
    s_p, s_n, cnt = sums[..., :3], sums[..., 3:6], sums[..., 6]
    mask = cnt > 0
    cent = jnp.where(mask[..., None], s_p / jnp.maximum(cnt, 1.0)[..., None] + origin[:, None, :], 0.0)
    nlen = jnp.linalg.norm(s_n, axis=-1, keepdims=True)
    up = jnp.array([0.0, 0.0, 1.0], s_n.dtype)
    nrm = jnp.where(nlen > 1e-6, s_n / jnp.maximum(nlen, 1e-6), up)
    nrm = jnp.where(mask[..., None], nrm, 0.0)
    return dict(
        points=cent,
        normals=nrm,
        mask=mask,
        count=count,
        voxel_overflow=count > V,
        range_overflow=range_overflow,
    )


# ----------------------------------------------------------------------------- 4. PCA


def _sign_fix(v, order):
    """Flip ``v`` so its first component (in ``order``) with |c| > 1e-6 is positive."""
    comps = v[jnp.asarray(order)]
    big = jnp.abs(comps) > 1e-6
    first = jnp.argmax(big)
    s = jnp.where(jnp.any(big), jnp.sign(comps[first]), 1.0)
    return v * jnp.where(s == 0, 1.0, s)


def rotation_to_rpy(rot):
    """(roll, pitch, yaw) with rot = Rz(yaw) @ Ry(pitch) @ Rx(roll); pitch in [-pi/2, pi/2]."""
    yaw = jnp.arctan2(rot[1, 0], rot[0, 0])
    pitch = jnp.arctan2(-rot[2, 0], jnp.hypot(rot[0, 0], rot[1, 0]))
    roll = jnp.arctan2(rot[2, 1], rot[2, 2])
    return jnp.stack([roll, pitch, yaw])


def pca_frame(points, mask):
    """Centroid (3,), right-handed eigenvector frame (3, 3) and eigenvalues (3,) descending.

    points: (V, 3), mask: (V,). Covariance is the population one (divide by n). Frame columns:
    x = major axis with its first non-zero component among (x, y, z) positive, z = minor axis
    with its first non-zero component among (z, x, y) positive, y = z cross x.
    """
    w = mask.astype(points.dtype)
    n = jnp.maximum(jnp.sum(w), 1.0)
    mu = jnp.sum(points * w[:, None], axis=0) / n
    d = (points - mu) * w[:, None]
    cov = d.T @ d / n
    evals, evecs = jnp.linalg.eigh(cov)  # ascending
    x = _sign_fix(evecs[:, 2], (0, 1, 2))
    z = _sign_fix(evecs[:, 0], (2, 0, 1))
    y = jnp.cross(z, x)
    return mu, jnp.stack([x, y, z], axis=1), evals[::-1]


def pca_object(points, mask, min_points: int):
    """Nine PCA values of one object and its ``unseen`` flag.

    Returns (9,) [x, y, z, roll, pitch, yaw, eig_major, eig_middle, eig_minor] and a bool that
    is True when fewer than ``min_points`` voxels were seen; then all nine values are 0.
    """
    n = jnp.sum(mask)
    unseen = n < min_points
    # A well-posed dummy cloud for the unseen branch keeps eigh free of NaN.
    mu, frame, evals = pca_frame(points, mask)
    feats = jnp.concatenate([mu, rotation_to_rpy(frame), evals])
    feats = jnp.where(unseen | ~jnp.all(jnp.isfinite(feats)), 0.0, feats)
    return feats, unseen


# ----------------------------------------------------------------------------- 5. RHF

# Abramowitz & Stegun 4.4.46: acos(x) = sqrt(1 - x) * poly(x) on [0, 1], |error| <= 2e-8.
# XLA's CPU acos/atan2 cost ~25-55 ns per value; this costs ~1 ns.
_ACOS_COEF = (1.5707963050, -0.2145988016, 0.0889789874, -0.0501743046,
              0.0308918810, -0.0170881256, 0.0066700901, -0.0012624911)


def fast_arccos(x):
    """arccos of x clipped to [-1, 1], accurate to ~4e-7 rad in float32."""
    x = jnp.clip(x, -1.0, 1.0)
    ax = jnp.abs(x)
    p = jnp.full_like(ax, _ACOS_COEF[-1])
    for c in _ACOS_COEF[-2::-1]:
        p = p * ax + c
    r = jnp.sqrt(jnp.maximum(1.0 - ax, 0.0)) * p
    return jnp.where(x < 0, jnp.float32(np.pi) - r, r)


def rhf_pair_values(a, na, b, nb):
    """The six RHF values of pairs, as a list of six arrays. a, na, b, nb: lists of the three
    coordinate arrays (any broadcastable shapes) of A's point and unit normal, B's point and
    unit normal.

    dx, dy, dz of d = b - a; |d|; angle(n_a, n_b) = acos(n_a . n_b);
    angle(n_a, d) = acos(n_a . d / |d|), defined as 0 when d = 0.
    """
    d = [b[i] - a[i] for i in range(3)]
    dist = jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    cos_nn = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]
    dot_nd = na[0] * d[0] + na[1] * d[1] + na[2] * d[2]
    cos_nd = jnp.where(dist > 0, dot_nd / jnp.where(dist > 0, dist, 1.0), 1.0)
    return [d[0], d[1], d[2], dist, fast_arccos(cos_nn), fast_arccos(cos_nd)]


def rhf_bin(value, feature: int, rcfg: RHFConfig):
    """Bin of values of feature ``feature``: floor((v - lo) / (hi - lo) * bins) clipped to
    [0, bins - 1] (out-of-range values go to the end bins)."""
    lo, hi = rcfg.ranges[feature]
    b = jnp.floor((value - np.float32(lo)) * np.float32(rcfg.bins / (hi - lo)))
    return jnp.clip(b, 0, rcfg.bins - 1).astype(jnp.int32)


def rhf_histograms(pa, na, ca, pb, nb, cb, rcfg: RHFConfig):
    """Six histograms over all pairs (a in object A, b in object B), tile by tile.

    pa, na: (V, 3) points and unit normals of A with the first ``ca`` valid; likewise pb, nb, cb.
    Values per pair: ``rhf_pair_values``; bins: ``rhf_bin``. Work is done on
    ``chunk`` x ``chunk`` tiles in a while loop over only the tiles that hold valid pairs, so
    memory is bounded and time follows ca * cb, not V * V. Counts are accumulated in three joint
    bins x bins histograms (dx,dy), (dz,|d|), (the two angles) -- one scatter per two
    features -- and marginalised at the end (exact: the same counts).
    Returns (6 * bins,): counts divided by ca * cb (each histogram sums to 1), or all zeros if
    ca * cb == 0.
    """
    C, nbin = rcfg.chunk, rcfg.bins
    V = pa.shape[0]
    if V % C:
        raise ValueError(f"point capacity {V} is not a multiple of rhf.chunk {C}")
    ca = jnp.minimum(ca, V).astype(jnp.int32)
    cb = jnp.minimum(cb, V).astype(jnp.int32)
    ta = (ca + C - 1) // C
    tb = jnp.maximum((cb + C - 1) // C, 1)
    ar = jnp.arange(C)
    joint = nbin * nbin
    dump = 3 * joint  # invalid pairs land here and are discarded
    pa_t, na_t, pb_t, nb_t = pa.T, na.T, pb.T, nb.T  # (3, V) structure of arrays

    def load(t):
        i, j = t // tb, t % tb
        wa = (i * C + ar) < ca
        wb = (j * C + ar) < cb
        sl = lambda x, k: jax.lax.dynamic_slice(x, (0, k * C), (3, C))
        return sl(pa_t, i), sl(na_t, i), wa, sl(pb_t, j), sl(nb_t, j), wb

    def body(state):
        # The current tiles travel in the loop state: read as loop parameters, the pair
        # arithmetic vectorises; with the dynamic slices fused into it, it ran ~10x slower.
        t, hist, (a, an, wa, b, bn, wb) = state
        w = wa[:, None] & wb[None, :]
        vals = rhf_pair_values(a[:, :, None], an[:, :, None], b[:, None, :], bn[:, None, :])
        bins = [rhf_bin(v, f, rcfg) for f, v in enumerate(vals)]
        for q in range(3):  # joint (feature 2q, feature 2q+1) histogram q
            idx = jnp.where(w, q * joint + bins[2 * q] * nbin + bins[2 * q + 1], dump).reshape(-1)
            hist = _scatter_add(hist, idx, jnp.ones_like(idx))
        return t + 1, hist, load(t + 1)

    init = (jnp.int32(0), jnp.zeros(dump + 1, jnp.int32), load(jnp.int32(0)))
    _, hist, _ = jax.lax.while_loop(lambda s: s[0] < ta * tb, body, init)
    j3 = hist[:dump].reshape(3, nbin, nbin)
    marg = jnp.stack([j3.sum(2), j3.sum(1)], axis=1).reshape(len(RHF_NAMES), nbin)  # dx,dy,dz,d,...
    pairs = ca.astype(jnp.float32) * cb.astype(jnp.float32)
    out = marg.astype(jnp.float32) / jnp.maximum(pairs, 1.0)
    return jnp.where(pairs > 0, out, 0.0).reshape(-1)


# ----------------------------------------------------------------------------- top level


def point_cloud(scene: SceneGeoms, key, cfg: PerceptionConfig) -> dict:
    """Stages 1-3 for one scene: object pixels (noisy) and per-object voxel clouds.

    Returns dict(pixels=``compact_objects`` result after noise, voxels=``voxel_downsample``
    result plus n_pixels, pixel_overflow and tile_overflow).
    """
    ro = render_objects(scene, cfg)
    pix = compact_objects(ro, cfg)
    # Normals come from the exact (noise-free) hit geometry, see docs/perception.md.
    pix["normal"] = surface_normals(scene, pix["points"], pix["geom"])
    if cfg.noise.model != "none":
        pix = add_depth_noise(pix, key, cfg)
    vox = voxel_downsample(pix["points"], pix["normal"], pix["seg"], cfg)
    vox["n_pixels"] = pix["n_pixels"]
    vox["pixel_overflow"] = pix["pixel_overflow"]
    vox["tile_overflow"] = ro["tile_overflow"]
    return dict(pixels=pix, voxels=vox)


def features_from_voxels(vox: dict, cfg: PerceptionConfig) -> dict:
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
    return dict(
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


def features(scene: SceneGeoms, key, cfg: PerceptionConfig = PerceptionConfig()) -> dict:
    """Whole chain for one scene (pure; vmap over scenes and jit at the caller).

    Returns
      pca (18,) float32: toy [x y z roll pitch yaw eig1 eig2 eig3] then other object, robot
          frame, metres / radians / m^2; an unseen object's nine values are 0.
      rhf (300,) float32: six 50-bin histograms (RHF_NAMES order), each sums to 1, or all 0
          if either object is unseen.
      unseen (2,) bool, n_points (2,) int32 occupied voxels, n_pixels (2,) int32,
      overflow () bool = tile_overflow | pixel_overflow | any(voxel_overflow) | range_overflow
          (each also returned); features of an overflowing scene are computed from the data that
          fit and must not be used silently.
    """
    validate_config(cfg)  # static: runs once per trace
    return features_from_voxels(point_cloud(scene, key, cfg)["voxels"], cfg)


def make_batched_features(geom_type, geom_seg, cfg: PerceptionConfig = PerceptionConfig(), wrap=None):
    """Jitted batched ``features`` for one geom layout, built once.

    Returns f(size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3) or (B, G, 9), keys (B,) keys)
    -> dict of (B, ...) arrays (see ``features``). Same shapes never retrace; ``f.jitted`` is
    the underlying jitted function. ``wrap`` (optional) decorates the single-scene function
    before vmap, e.g. ``chex.assert_max_traces(n=1)`` in tests.
    """
    validate_config(cfg)
    g = len(np.asarray(geom_type).ravel())
    static = make_scene(geom_type, geom_seg, np.zeros((g, 3)), np.zeros((g, 3)), np.tile(np.eye(3), (g, 1, 1)))

    def one(size, xpos, xmat, key):
        return features(SceneGeoms(static.geom_type, static.geom_seg, size, xpos, xmat), key, cfg)

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


# ----------------------------------------------------------------------------- picture


@functools.lru_cache(maxsize=8)
def _scene_view_fn(geom_type: tuple, geom_seg: tuple, cfg: PerceptionConfig):
    """Jitted (cached per layout and config) view of one scene for ``scene_view``."""

    def view(size, xpos, xmat, key):
        scene = SceneGeoms(geom_type, geom_seg, size, xpos, xmat)
        k_img, k_feat = jax.random.split(key)
        full = render(scene, cfg)
        if cfg.noise.model != "none":
            full = add_depth_noise(full, k_img, cfg)
        pc = point_cloud(scene, k_feat, cfg)
        frames = [pca_frame(pc["voxels"]["points"][o], pc["voxels"]["mask"][o]) for o in range(2)]
        return dict(depth=full["depth"], seg=full["seg"].reshape(full["depth"].shape),
                    pixels=pc["pixels"], voxels=pc["voxels"], frames=frames,
                    feats=features_from_voxels(pc["voxels"], cfg))

    return jax.jit(view)


def scene_view(scene: SceneGeoms, key, cfg: PerceptionConfig = PerceptionConfig()) -> dict:
    """Everything a picture of one (unbatched) scene needs, as numpy: depth (H, W) (noisy,
    0 = no return), seg (H, W), pixels (noisy ``compact_objects`` result), voxels
    (``voxel_downsample`` result), frames (per object: centroid, frame, eigenvalues) and
    feats (the ``features`` outputs). ``key`` is split: image noise, feature noise."""
    validate_config(cfg)
    fn = _scene_view_fn(scene.geom_type, scene.geom_seg, cfg)
    return jax.tree.map(np.asarray, fn(scene.size, scene.xpos, scene.xmat, key))


def render_scene_png(scene: SceneGeoms, key, out_path, cfg: PerceptionConfig = PerceptionConfig(),
                     title: str | None = None) -> dict:
    """Draw what the robot saw: the depth image, the segmentation and the two objects' voxel
    clouds with their PCA frames (axes 2 sqrt(eigenvalue) long, at least 4 cm); writes a PNG
    atomically. Jits one view function per (layout, config), cached.

    scene: one unbatched ``SceneGeoms``. Returns the ``scene_view`` dict."""
    import io as _io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    from relaff_jax.io import atomic_write_bytes

    v = scene_view(scene, key, cfg)
    fig = plt.figure(figsize=(15, 4.8))
    ax0 = fig.add_subplot(1, 3, 1)
    depth = np.ma.masked_where(v["depth"] <= 0, v["depth"])
    im = ax0.imshow(depth, cmap="viridis")
    fig.colorbar(im, ax=ax0, fraction=0.035, label="depth z (m)")
    ax0.set_title("depth image (noisy)")
    ax1 = fig.add_subplot(1, 3, 2)
    cmap = ListedColormap(["black", "0.75", "tab:orange", "tab:purple"])
    ax1.imshow(v["seg"] + 1, cmap=cmap, vmin=0, vmax=3, interpolation="nearest")
    ax1.set_title("segments: table grey, toy orange, other purple")
    for a in (ax0, ax1):
        a.set_xticks([])
        a.set_yticks([])
    ax2 = fig.add_subplot(1, 3, 3, projection="3d")
    feats = v["feats"]
    for o, (name, colour) in enumerate((("toy", "tab:orange"), ("other", "tab:purple"))):
        n = int(min(v["voxels"]["count"][o], cfg.voxel.max_voxels))
        p = v["voxels"]["points"][o][:n]
        ax2.scatter(p[:, 0], p[:, 1], p[:, 2], s=2, c=colour, label=f"{name}: {n} voxels")
        if feats["unseen"][o]:
            continue
        mu, frame, ev = v["frames"][o]
        for k, c in enumerate(("r", "g", "b")):
            vec = frame[:, k] * max(2 * np.sqrt(max(ev[k], 0.0)), 0.04)
            ax2.quiver(*mu, *vec, color=c, linewidth=2)
    ax2.scatter([0], [0], [0], marker="^", c="k", s=40, label="robot base")
    ax2.set_xlabel("x (m)")
    ax2.set_ylabel("y (m)")
    ax2.set_zlabel("z (m)")
    ax2.legend(loc="upper left", fontsize=8)
    pca = feats["pca"]
    ax2.set_title("voxel clouds, PCA frames (x red, y green, z blue)\n"
                  f"toy yaw {np.rad2deg(pca[5]):.0f} deg, other yaw {np.rad2deg(pca[14]):.0f} deg"
                  + ("  [UNSEEN: " + ", ".join(n for n, u in zip(("toy", "other"), feats["unseen"]) if u) + "]"
                     if feats["unseen"].any() else ""), fontsize=9)
    # equal aspect around the objects
    pts = np.concatenate([v["voxels"]["points"][o][: int(min(v["voxels"]["count"][o], cfg.voxel.max_voxels))]
                          for o in range(2)] + [np.zeros((1, 3))])
    centre, half = pts[1:].mean(0) if len(pts) > 1 else np.zeros(3), 0.3
    ax2.set_xlim(centre[0] - half, centre[0] + half)
    ax2.set_ylim(centre[1] - half, centre[1] + half)
    ax2.set_zlim(0, 2 * half)
    ax2.set_box_aspect((1, 1, 1))
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    atomic_write_bytes(out_path, buf.getvalue())
    return v
