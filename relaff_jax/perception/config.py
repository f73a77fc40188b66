"""Perception settings: frozen dataclasses (static under jit) and their validation.

Takes nothing; gives ``PerceptionConfig`` (camera, noise, normals, voxel, RHF, culling settings),
``validate_config(cfg) -> cfg`` (raises ``UserError`` naming the bad setting) and the feature
names ``PCA_NAMES`` (9 per object) and ``RHF_NAMES`` (6 histograms).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from relaff_jax.errors import UserError

PCA_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "eig_major", "eig_middle", "eig_minor")
RHF_NAMES = ("dx", "dy", "dz", "dist", "angle_na_nb", "angle_na_d")

# Depth noise models ``noise.NOISE_MODELS`` implements (validated here, before any tracing).
NOISE_MODEL_NAMES = ("robwork", "khoshelham", "nguyen", "none")
# Where the RHF normals come from (``NormalsConfig.source``).
NORMAL_SOURCES = ("ray", "cloud")


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """Pinhole depth camera (RobWork's simulated Kinect intrinsics, docs/facts.md, "Sensor").

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
class NormalsConfig:
    """Where the per-pixel normals (averaged per voxel, used by the RHF) come from.

    ``source``: "ray" (default) the exact surface normal of the hit primitive, noise-free;
    "cloud" PCA of the (noisy) object points in a ``window`` x ``window`` pixel neighbourhood
    of the same object within ``radius`` metres, turned towards the camera
    (``normals.window_normals``; the same rule as ``real.config.NormalConfig(method="window")``).
    """

    source: str = "ray"
    window: int = 5
    radius: float = 0.025


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
    normals: NormalsConfig = NormalsConfig()
    voxel: VoxelConfig = VoxelConfig()
    rhf: RHFConfig = RHFConfig()
    cull: CullConfig = CullConfig()
    min_points: int = 10

    def __post_init__(self):  # refused when the config is made: the parts' checks cross (tile vs image)
        validate_config(self)


def validate_config(cfg: PerceptionConfig) -> PerceptionConfig:
    """Raise ``UserError`` (a ValueError) naming the bad setting; return ``cfg`` unchanged otherwise."""
    cam = cfg.camera
    if cam.width <= 0 or cam.height <= 0:
        raise UserError(f"perception.camera size must be positive, got {cam.width}x{cam.height}")
    if not 0.0 < cam.vfov_deg < 180.0:
        raise UserError(f"perception.camera.vfov_deg must be in (0, 180), got {cam.vfov_deg}")
    if not 0.0 <= cam.near < cam.far:
        raise UserError(f"perception: need 0 <= camera.near < camera.far, got {cam.near}, {cam.far}")
    if np.linalg.norm(np.subtract(cam.target, cam.position)) == 0.0:
        raise UserError("perception.camera.target equals camera.position")
    if cfg.noise.model not in NOISE_MODEL_NAMES:
        raise UserError(f"unknown perception.noise.model {cfg.noise.model!r}; valid: {sorted(NOISE_MODEL_NAMES)}")
    nc = cfg.normals
    if nc.source not in NORMAL_SOURCES:
        raise UserError(f"unknown perception.normals.source {nc.source!r}; valid: {list(NORMAL_SOURCES)}")
    if nc.window < 3 or nc.window % 2 == 0:
        raise UserError(f"perception.normals.window must be odd and >= 3, got {nc.window}")
    if nc.radius <= 0:
        raise UserError(f"perception.normals.radius must be positive, got {nc.radius}")
    if cfg.voxel.size <= 0:
        raise UserError(f"perception.voxel.size must be positive, got {cfg.voxel.size}")
    if cfg.voxel.max_object_pixels <= 0 or cfg.voxel.max_voxels <= 0:
        raise UserError("perception.voxel capacities must be positive")
    r = cfg.rhf
    if r.bins <= 0 or r.chunk <= 0:
        raise UserError(f"perception.rhf.bins and rhf.chunk must be positive, got {r.bins}, {r.chunk}")
    if cfg.voxel.max_voxels % r.chunk:
        raise UserError(
            f"perception.voxel.max_voxels ({cfg.voxel.max_voxels}) must be a multiple of rhf.chunk ({r.chunk})"
        )
    if len(r.ranges) != len(RHF_NAMES) or any(hi <= lo for lo, hi in r.ranges):
        raise UserError(f"perception.rhf.ranges needs {len(RHF_NAMES)} (lo, hi) pairs with hi > lo, got {r.ranges}")
    t = cfg.cull.tile
    if t <= 0 or cam.width % t or cam.height % t:
        raise UserError(f"perception.cull.tile ({t}) must divide the image size {cam.width}x{cam.height}")
    if cfg.cull.max_tiles <= 0:
        raise UserError(f"perception.cull.max_tiles must be positive, got {cfg.cull.max_tiles}")
    if cfg.min_points < 3:
        raise UserError(f"perception.min_points must be >= 3 for a PCA frame, got {cfg.min_points}")
    return cfg


def stored_config(cfg: PerceptionConfig) -> dict:
    """``cfg`` as a feature folder records it (and compares it on resume).

    The default normals (exact ray hits) are recorded by the ``normals`` key's absence, as in
    every feature folder written before the option existed, so that those stay valid and
    resumable: a folder whose config has no ``normals`` used ``source="ray"``.
    """
    from relaff_jax.config import to_dict

    d = to_dict(cfg)
    if cfg.normals == NormalsConfig():
        d.pop("normals")
    return d
