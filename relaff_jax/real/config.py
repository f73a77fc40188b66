"""Settings of the real-scene pipeline: frozen dataclasses and their validation.

Takes nothing; gives ``RealConfig`` (plane RANSAC, crop, k-means, normals, voxel grid and the
feature settings shared with simulation) and ``validate_real_config(cfg) -> cfg`` (UserError
naming the bad setting).
"""
from __future__ import annotations

import dataclasses

from relaff_jax.errors import UserError
from relaff_jax.perception.config import PerceptionConfig, VoxelConfig


@dataclasses.dataclass(frozen=True)
class PlaneConfig:
    """RANSAC plane fit (Open3D ``segment_plane`` semantics): a point is an inlier when its
    distance to the plane is below ``threshold`` (m); ``iterations`` hypotheses of 3 points,
    evaluated ``batch`` at a time; the best plane is refitted by least squares to its inliers."""

    threshold: float = 0.01
    iterations: int = 1000
    batch: int = 50


@dataclasses.dataclass(frozen=True)
class CropConfig:
    """Which non-table points k-means sees: at least ``min_height`` and at most ``max_height``
    (m) above the table plane, and (projected on the plane) at most ``radius_scale`` x the
    largest distance of a table inlier from the inliers' centroid (the table's extent)."""

    min_height: float = 0.01
    max_height: float = 0.5
    radius_scale: float = 1.0


@dataclasses.dataclass(frozen=True)
class KMeansConfig:
    """k-means on the cropped points (camera-frame xyz, metres): ``k`` clusters, the k - 1
    largest being the objects and the smallest the background (the paper's rule); when the
    object count n is given, k = n + 1. ``background=False`` drops the background cluster
    (k clusters = k objects; k = n when n is given), for scenes already cropped to the table.
    k-means++ seeding, at most ``iterations`` Lloyd steps (stops when no point moves),
    ``n_init`` seedings (the lowest inertia wins)."""

    k: int = 3
    background: bool = True
    iterations: int = 100
    n_init: int = 4


@dataclasses.dataclass(frozen=True)
class NormalConfig:
    """Normals from the cloud, oriented towards the camera. ``method`` "knn" (default): PCA of
    each point's ``knn`` nearest neighbours among the object's points (smallest-eigenvalue
    eigenvector); "window" (organized clouds only): PCA of the object's points in a ``window`` x
    ``window`` pixel neighbourhood within ``radius`` m, the simulation's
    ``PerceptionConfig.normals.source = "cloud"`` rule (``perception.normals.window_normals``)."""

    knn: int = 20
    method: str = "knn"
    window: int = 5
    radius: float = 0.025


@dataclasses.dataclass(frozen=True)
class RealConfig:
    """Every real-pipeline setting; ``perception`` carries the voxel grid (0.0125 m, capacities),
    RHF bins/ranges and ``min_points`` shared with simulation, so both give the same features."""

    plane: PlaneConfig = PlaneConfig()
    crop: CropConfig = CropConfig()
    kmeans: KMeansConfig = KMeansConfig()
    normals: NormalConfig = NormalConfig()
    perception: PerceptionConfig = PerceptionConfig(voxel=VoxelConfig(max_object_pixels=65536))


def validate_real_config(cfg: RealConfig) -> RealConfig:
    """Raise ``UserError`` naming the bad setting; return ``cfg`` unchanged otherwise."""
    from relaff_jax.perception.config import validate_config

    p = cfg.plane
    if p.threshold <= 0 or p.iterations <= 0 or p.batch <= 0:
        raise UserError(f"plane.threshold, .iterations and .batch must be positive, got {p}")
    c = cfg.crop
    if not 0 <= c.min_height < c.max_height or c.radius_scale <= 0:
        raise UserError(f"need 0 <= crop.min_height < crop.max_height and crop.radius_scale > 0, got {c}")
    k = cfg.kmeans
    if k.k < 1 + int(k.background) or k.iterations <= 0 or k.n_init <= 0:
        raise UserError(f"kmeans.k must leave an object cluster and kmeans.iterations, .n_init positive, got {k}")
    nc = cfg.normals
    if nc.knn < 3:
        raise UserError(f"normals.knn must be >= 3 for a plane fit, got {nc.knn}")
    if nc.method not in ("knn", "window"):
        raise UserError(f"unknown normals.method {nc.method!r}; valid: ['knn', 'window']")
    if nc.window < 3 or nc.window % 2 == 0 or nc.radius <= 0:
        raise UserError(f"normals.window must be odd and >= 3 and normals.radius positive, got {nc}")
    validate_config(cfg.perception)
    return cfg
