"""The paper's real segmentation, and the hand segmentation of a labelled scene.

Takes a ``RealCloud``, a PRNG key and a ``RealConfig``; ``segment_scene`` gives the segment map
(``cloud.SEG_*`` convention: 0 none/background, 1 table, objects 2, 3, ... largest first),
the table plane and what was cropped. Steps: (1) RANSAC (``ransac.ransac_plane``) on all valid
points: the largest plane is the table; its normal is turned towards the camera (up);
(2) crop: points between ``crop.min_height`` and ``crop.max_height`` above the plane whose
projection on the plane lies within ``crop.radius_scale`` x the table's extent (the largest
distance of a projected table inlier from the inliers' centroid); (3) k-means
(``ransac.kmeans``) of the cropped points into k = ``kmeans.k`` clusters (``n_objects + 1``
when the object count is given): the k - 1 largest are the objects, the smallest the
background (with ``kmeans.background=False``: k = n_objects clusters, all objects).
``hand_segmentation(label)`` maps the database's labels to the same convention (1-9 -> table,
label >= 20 -> label // 10). Arrays are padded to fixed sizes so that one compile serves every
scene of a sensor; the jitted stages are built once here (this module is their caller).
"""
from __future__ import annotations

import functools

import jax
import numpy as np

from relaff_jax.errors import UserError

from .cloud import FIRST_OBJECT, SEG_NONE, SEG_TABLE, RealCloud
from relaff_jax.config.real import RealConfig
from .ransac import kmeans, ransac_plane

MIN_TABLE_POINTS = 500  # fewer plane inliers than this: "no table"


def _bucket(n: int, step: int = 16384) -> int:
    """Padded size for ``n`` points: a multiple of ``step`` (limits recompiles)."""
    return max(step, -(-n // step) * step)


def _pad(points: np.ndarray, size: int):
    out = np.zeros((size, 3), np.float32)
    out[: len(points)] = points
    mask = np.zeros(size, bool)
    mask[: len(points)] = True
    return out, mask


@functools.lru_cache(maxsize=4)
def _ransac_fn(threshold: float, iterations: int, batch: int):
    return jax.jit(functools.partial(ransac_plane, threshold=threshold, iterations=iterations, batch=batch))


@functools.lru_cache(maxsize=4)
def _kmeans_fn(k: int, iterations: int, n_init: int):
    return jax.jit(functools.partial(kmeans, k=k, iterations=iterations, n_init=n_init))


def fit_table_plane(points: np.ndarray, key, cfg: RealConfig = RealConfig()) -> dict:
    """RANSAC table plane of valid points (N, 3) (camera frame, no NaN): dict(plane (4,) float64
    with the unit normal pointing towards the camera (plane . (0, 0, 0, 1) = d > 0),
    inliers (N,) bool). UserError with fewer than ``MIN_TABLE_POINTS`` inliers."""
    if len(points) < MIN_TABLE_POINTS:
        raise UserError(f"the cloud has {len(points)} valid points; a table plane needs >= {MIN_TABLE_POINTS}")
    pc = cfg.plane
    pts, mask = _pad(np.asarray(points, np.float32), _bucket(len(points)))
    plane, inl, n_in = _ransac_fn(pc.threshold, pc.iterations, pc.batch)(pts, mask, key)
    plane = np.asarray(plane, np.float64)
    if int(n_in) < MIN_TABLE_POINTS or not np.any(plane[:3]):
        raise UserError(f"no table plane found: the largest plane has {int(n_in)} inliers "
                        f"(< {MIN_TABLE_POINTS}) within {pc.threshold} m")
    if plane[3] < 0:
        plane = -plane
    return dict(plane=plane, inliers=np.asarray(inl)[: len(points)])


def crop_above_table(points: np.ndarray, plane: np.ndarray, inliers: np.ndarray, cfg: RealConfig) -> dict:
    """Which points (N, 3) k-means sees (see the module docstring): dict(keep (N,) bool,
    height (N,) metres above the plane, centre (3,) table inliers' centroid on the plane,
    radius () metres)."""
    n, d = plane[:3], plane[3]
    height = points @ n + d
    proj = points - height[:, None] * n
    centre = proj[inliers].mean(axis=0)
    radius = float(np.max(np.linalg.norm(proj[inliers] - centre, axis=1))) * cfg.crop.radius_scale
    keep = ((height >= cfg.crop.min_height) & (height <= cfg.crop.max_height)
            & (np.linalg.norm(proj - centre, axis=1) <= radius) & ~inliers)
    return dict(keep=keep, height=height, centre=centre, radius=radius)


def cluster_objects(points: np.ndarray, key, k: int, cfg: RealConfig = RealConfig(),
                    background: bool = True) -> np.ndarray:
    """k-means of points (M, 3) into ``k`` clusters; returns (M,) int32 segment ids: the k - 1
    largest clusters as objects 2, 3, ... (largest first), the smallest as SEG_NONE (with
    ``background=False`` all k clusters are objects)."""
    if len(points) < k:
        raise UserError(f"only {len(points)} points above the table; k-means needs >= {k}")
    km = cfg.kmeans
    pts, mask = _pad(np.asarray(points, np.float32), _bucket(len(points), 4096))
    res = _kmeans_fn(k, km.iterations, km.n_init)(pts, mask, key)
    lab = np.asarray(res["labels"])[: len(points)]
    order = np.argsort(-np.bincount(lab, minlength=k), kind="stable")
    ids = np.full(k, SEG_NONE, np.int32)
    n_obj = k - int(background)
    ids[order[:n_obj]] = FIRST_OBJECT + np.arange(n_obj)
    return ids[lab]


def segment_scene(cloud: RealCloud, key, cfg: RealConfig = RealConfig(), n_objects: int | None = None) -> dict:
    """The paper's segmentation of one scene (see the module docstring).

    Returns dict(seg (H, W) / (N,) int32 segment map, plane (4,) camera-frame table plane with
    its normal towards the camera, n_objects (int), k (clusters), crop (``crop_above_table`` result over the
    valid points), valid (H, W) / (N,) bool). ``key`` is split for RANSAC and k-means."""
    bg = int(cfg.kmeans.background)
    if n_objects is not None and int(n_objects) < 1:
        raise UserError(f"n_objects must be >= 1, got {n_objects}")
    k = cfg.kmeans.k if n_objects is None else int(n_objects) + bg
    if k < 1 + bg:
        raise UserError(f"kmeans.k = {k} leaves no object cluster")
    valid = cloud.valid
    pts = cloud.xyz[valid].astype(np.float64)
    if len(pts) == 0:
        raise UserError(f"{cloud.path or 'the cloud'} has no valid points")
    k_plane, k_means = jax.random.split(key)
    table = fit_table_plane(pts, k_plane, cfg)
    crop = crop_above_table(pts, table["plane"], table["inliers"], cfg)
    seg_v = np.where(table["inliers"], SEG_TABLE, SEG_NONE).astype(np.int32)
    seg_v[crop["keep"]] = cluster_objects(pts[crop["keep"]], k_means, k, cfg, background=bool(bg))
    seg = np.zeros(valid.shape, np.int32)
    seg[valid] = seg_v
    return dict(seg=seg, plane=table["plane"], n_objects=k - bg, k=k, crop=crop, valid=valid)


def hand_segmentation(label) -> np.ndarray:
    """Database labels (H, W) / (N,) -> segment map: 1-9 -> SEG_TABLE, >= 20 -> label // 10,
    everything else (0 invalid, 10-19 unused) -> SEG_NONE."""
    lab = np.asarray(label).astype(np.int64)
    out = np.where((lab >= 1) & (lab <= 9), SEG_TABLE, SEG_NONE)
    return np.where(lab >= 20, lab // 10, out).astype(np.int32)


def object_ids(seg) -> list[int]:
    """Object ids (>= 2) present in a segment map, ascending."""
    u = np.unique(np.asarray(seg))
    return [int(v) for v in u if v >= FIRST_OBJECT]
