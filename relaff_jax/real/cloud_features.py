"""Features of a real object pair: normals from the cloud, voxel grid, PCA state and RHF.

Takes object points in the table frame (metres) and a ``RealConfig``; gives the simulation's
two state spaces through the simulation's own code (``perception.voxels.voxel_downsample``,
then ``perception.pipeline.features_from_voxels``: ``pca_object`` and ``rhf_histograms``):

* ``cloud_normals(points (N, 3), knn, viewpoint (3,)) -> (N, 3)``: unit normals by PCA of each
  point's ``knn`` nearest neighbours (itself included), turned towards ``viewpoint``;
* ``pair_features(points_a (Na, 3), normals_a (Na, 3), points_b, normals_b, cfg)`` -> dict(pca
  (18,) a's 9 values then b's, rhf (300,), unseen (2,), n_points (2,) voxels, overflow (),
  voxels (the ``voxel_downsample`` result: centroids (2, V, 3), mean normals, mask, count));
* ``window_cloud_normals(xyz (H, W, 3), select (H, W) bool, window, radius) -> (N, 3)``: the
  simulation's image-window rule (``perception.normals.window_normals``) on an organized cloud,
  for the N selected pixels (row-major), neighbours among the selected pixels, camera at 0;
* ``object_points(cloud, seg, obj_id, frame, cfg)`` -> (points (N, 3), normals (N, 3)) in the
  table frame, normals (``cfg.normals.method``: "knn" or "window") from the camera-frame cloud
  oriented towards the camera;
* ``object_pair_features(cloud, seg, id_a, id_b, frame, cfg)``: the two above chained.
Point buffers are padded to a power of two (>= 4096) so few shapes are ever compiled.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from relaff_jax.constants import SEG_OTHER, SEG_TOY
from relaff_jax.errors import UserError
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.perception.normals import window_normals
from relaff_jax.perception.pipeline import features_from_voxels
from relaff_jax.perception.voxels import voxel_downsample

from relaff_jax.config.real import RealConfig
from .frame import to_table, vectors_to_table


def cloud_normals(points, knn: int = 20, viewpoint=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Unit normals (N, 3) of points (N, 3): eigenvector of the smallest eigenvalue of the
    covariance of the ``knn`` nearest points (fewer if N < knn), with n . (viewpoint - p) >= 0."""
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise UserError(f"cloud_normals needs finite (N, 3) points, got shape {p.shape}")
    if len(p) < 3:
        raise UserError(f"cloud_normals needs >= 3 points, got {len(p)}")
    k = min(int(knn), len(p))
    _, nb = cKDTree(p).query(p, k=k)
    q = p[nb.reshape(len(p), k)]
    d = q - q.mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", d, d) / k)
    n = vecs[:, :, 0]
    flip = np.einsum("ni,ni->n", n, np.asarray(viewpoint, np.float64) - p) < 0
    return np.where(flip[:, None], -n, n)


def _bucket(n: int) -> int:
    return max(4096, 1 << int(np.ceil(np.log2(max(n, 1)))))


@functools.lru_cache(maxsize=4)
def _window_fn(width: int, height: int, window: int, radius: float):
    return jax.jit(lambda pts, lab, pix: window_normals(pts, lab, pix, width, height, window, radius,
                                                         jnp.zeros(3, jnp.float32)))


def window_cloud_normals(xyz, select, window: int = 5, radius: float = 0.025) -> np.ndarray:
    """Unit normals (N, 3) float64 of the N pixels where ``select`` (H, W) is true (row-major
    order, as ``xyz[select]``), by PCA over the selected pixels of their ``window`` x ``window``
    neighbourhood within ``radius`` m of them, turned towards the camera (the origin).
    xyz: (H, W, 3) organized camera-frame cloud (NaN where invalid; select must avoid those)."""
    xyz, select = np.asarray(xyz), np.asarray(select, bool)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or select.shape != xyz.shape[:2]:
        raise UserError(f"window normals need an organized (H, W, 3) cloud and an (H, W) selection, "
                        f"got {xyz.shape} and {select.shape}")
    if not np.all(np.isfinite(xyz[select])):
        raise UserError("window normals: the selection holds invalid (non-finite) points")
    H, W = select.shape
    pix = np.flatnonzero(select).astype(np.int32)
    buf = np.full(_bucket(len(pix)), -1, np.int32)
    buf[:len(pix)] = pix
    pts = np.where(select[..., None], xyz, 0.0).reshape(-1, 3).astype(np.float32)
    n = _window_fn(W, H, int(window), float(radius))(pts, select.reshape(-1).astype(np.int32), buf)
    return np.asarray(n, np.float64)[:len(pix)]


@functools.lru_cache(maxsize=4)
def _pair_fn(pcfg: PerceptionConfig):
    def fn(points, normals, seg):
        vox = voxel_downsample(points, normals, seg, pcfg)
        vox.update(n_pixels=jnp.stack([jnp.sum(seg == SEG_TOY), jnp.sum(seg == SEG_OTHER)]),
                   pixel_overflow=jnp.bool_(False), tile_overflow=jnp.bool_(False))
        return vox, features_from_voxels(vox, pcfg)

    return jax.jit(fn)


def pair_features(points_a, normals_a, points_b, normals_b, cfg: RealConfig = RealConfig()) -> dict:
    """PCA (18,) and RHF (300,) of an object pair, object a first (see the module docstring).
    Points in the table frame (metres), normals unit length; both objects need >= 1 point."""
    arrs = [np.asarray(a, np.float32) for a in (points_a, normals_a, points_b, normals_b)]
    for name, a in zip(("points_a", "normals_a", "points_b", "normals_b"), arrs):
        if a.ndim != 2 or a.shape[1] != 3 or not np.all(np.isfinite(a)):
            raise UserError(f"{name} must be finite (N, 3), got shape {a.shape}")
    pa, na, pb, nb = arrs
    if len(pa) != len(na) or len(pb) != len(nb):
        raise UserError("each object needs one normal per point")
    if len(pa) == 0 or len(pb) == 0:
        raise UserError(f"both objects need points, got {len(pa)} and {len(pb)}")
    n = len(pa) + len(pb)
    size = _bucket(n)
    pts = np.zeros((size, 3), np.float32)
    nrm = np.zeros((size, 3), np.float32)
    seg = np.zeros(size, np.int32)
    pts[:n] = np.concatenate([pa, pb])
    nrm[:n] = np.concatenate([na, nb])
    seg[: len(pa)], seg[len(pa):n] = SEG_TOY, SEG_OTHER
    vox, f = jax.tree.map(np.asarray, _pair_fn(cfg.perception)(pts, nrm, seg))
    return dict(pca=f.pca, rhf=f.rhf, unseen=f.unseen, n_points=f.n_points, overflow=f.overflow, voxels=vox)


def object_points(cloud, seg, obj_id: int, frame: dict, cfg: RealConfig = RealConfig()):
    """Points and cloud normals of object ``obj_id`` of segment map ``seg`` (same leading shape
    as ``cloud.xyz``), in the table frame ``frame``: ((N, 3), (N, 3)) float64."""
    seg = np.asarray(seg)
    if seg.shape != cloud.xyz.shape[:-1]:
        raise UserError(f"segment map shape {seg.shape} does not match the cloud {cloud.xyz.shape[:-1]}")
    sel = (seg == obj_id) & cloud.valid
    if np.count_nonzero(sel) < 3:
        present = sorted(int(v) for v in np.unique(seg) if v >= 2)
        raise UserError(f"object {obj_id} has {np.count_nonzero(sel)} points (< 3) in "
                        f"{cloud.path or 'the cloud'}; objects present: {present}")
    p = cloud.xyz[sel].astype(np.float64)
    nc = cfg.normals
    if nc.method == "window":
        if cloud.xyz.ndim != 3:
            raise UserError(f"normals.method 'window' needs an organized cloud; {cloud.path or 'the cloud'} "
                            "is unorganized (use 'knn')")
        n = window_cloud_normals(cloud.xyz, sel, nc.window, nc.radius)
    else:
        n = cloud_normals(p, nc.knn, viewpoint=(0.0, 0.0, 0.0))
    return to_table(p, frame), vectors_to_table(n, frame)


def object_pair_features(cloud, seg, id_a: int, id_b: int, frame: dict, cfg: RealConfig = RealConfig()) -> dict:
    """``pair_features`` of objects ``id_a`` (first) and ``id_b`` of a segmented real cloud."""
    if id_a == id_b:
        raise UserError(f"an object pair needs two different objects, got {id_a} twice")
    pa, na = object_points(cloud, seg, id_a, frame, cfg)
    pb, nb = object_points(cloud, seg, id_b, frame, cfg)
    return pair_features(pa, na, pb, nb, cfg)
