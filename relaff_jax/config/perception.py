"""Perception settings (the tree's ``perception`` node): camera, noise, normals, voxel grid,
RHF and culling, frozen (static under jit), and the feature names ``PCA_NAMES`` (9 per object)
and ``RHF_NAMES`` (6 histograms)."""
from __future__ import annotations

import dataclasses
import math

from relaff_jax.config.constraints import Interval, Options, Rule, Seq, count
from relaff_jax.config.node import Node
from relaff_jax.config.override import to_dict

PCA_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "eig_major", "eig_middle", "eig_minor")
RHF_NAMES = ("dx", "dy", "dz", "dist", "angle_na_nb", "angle_na_d")

# Depth noise models ``noise.NOISE_MODELS`` implements (checked here, before any tracing).
NOISE_MODEL_NAMES = ("robwork", "khoshelham", "nguyen", "none")
# Where the RHF normals come from (``NormalsConfig.source``).
NORMAL_SOURCES = ("ray", "cloud")
MAX_IMAGE = 8192  # pixels per image side: the feature path holds whole images in memory
COORD = Interval(float, -100.0, 100.0)  # a point of the scene, metres
ODD_WINDOW = count(3, 101)


def odd(key: str) -> Rule:
    return Rule(lambda c: getattr(c, key) % 2 == 1, lambda c: f"must be odd, got {getattr(c, key)}")


@dataclasses.dataclass(frozen=True)
class CameraConfig(Node):
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

    _path = "perception.camera"
    _constraints = {
        "width": count(1, MAX_IMAGE), "height": count(1, MAX_IMAGE),
        "vfov_deg": Interval(float, 0.0, 180.0, closed="neither"),
        "position": Seq(COORD, length=3), "target": Seq(COORD, length=3),
        "near": Interval(float, 0.0, 1000.0), "far": Interval(float, 0.0, 1000.0, closed="right"),
        ("near", "far"): Rule(lambda c: c.near < c.far, lambda c: f"must be below camera.far, got {c.near}, {c.far}"),
        ("target", "position"): Rule(lambda c: tuple(c.target) != tuple(c.position),
                                     lambda c: "must differ from camera.position"),
    }


@dataclasses.dataclass(frozen=True)
class NoiseConfig(Node):
    """Depth noise: ``model`` in {"robwork", "khoshelham", "nguyen", "none"}."""

    model: str = "robwork"

    _path = "perception.noise"
    _constraints = {"model": Options(NOISE_MODEL_NAMES)}


@dataclasses.dataclass(frozen=True)
class NormalsConfig(Node):
    """Where the per-pixel normals (averaged per voxel, used by the RHF) come from.

    ``source``: "ray" (default) the exact surface normal of the hit primitive, noise-free;
    "cloud" PCA of the (noisy) object points in a ``window`` x ``window`` pixel neighbourhood
    of the same object within ``radius`` metres, turned towards the camera
    (``normals.window_normals``; the same rule as ``config.real.NormalConfig(method="window")``).
    """

    source: str = "ray"
    window: int = 5
    radius: float = 0.025

    _path = "perception.normals"
    _constraints = {"source": Options(NORMAL_SOURCES), "window": ODD_WINDOW,
                    "radius": Interval(float, 0.0, 1.0, closed="right"), ("window",): odd("window")}


@dataclasses.dataclass(frozen=True)
class VoxelConfig(Node):
    """Voxel grid subsampling (paper: 0.0125 m) with fixed capacities.

    ``max_object_pixels``: object pixels (both objects) kept per scene before voxelisation;
    ``max_voxels``: voxels per object. Exceeding either sets an overflow flag.
    """

    size: float = 0.0125
    max_object_pixels: int = 32768
    max_voxels: int = 4096

    _path = "perception.voxel"
    _constraints = {"size": Interval(float, 0.0, 1.0, closed="right"),
                    "max_object_pixels": count(1, MAX_IMAGE * MAX_IMAGE), "max_voxels": count(1, 1 << 20)}


@dataclasses.dataclass(frozen=True)
class RHFConfig(Node):
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
        (-math.pi / 300, math.pi * 299 / 300),
        (-math.pi / 300, math.pi * 299 / 300),
    )
    chunk: int = 256

    _path = "perception.rhf"
    _constraints = {"bins": count(1, 10_000), "chunk": count(1, 1 << 16),
                    "ranges": Seq(Seq(COORD, length=2, increasing=True), length=len(RHF_NAMES))}


@dataclasses.dataclass(frozen=True)
class CullConfig(Node):
    """Which pixels the feature path ray-casts: image tiles of ``tile`` x ``tile`` pixels that a
    conservative projection of an object geom's bounding sphere touches, at most ``max_tiles``
    (more sets ``tile_overflow``). Pixels outside these tiles cannot show an object. The
    largest library object at the workspace point nearest the camera needs ~120 tiles."""

    tile: int = 16
    max_tiles: int = 256

    _path = "perception.cull"
    _constraints = {"tile": count(1, MAX_IMAGE), "max_tiles": count(1, MAX_IMAGE * MAX_IMAGE)}


@dataclasses.dataclass(frozen=True)
class PerceptionConfig(Node):
    """All perception settings; ``min_points``: voxels below which an object is ``unseen``."""

    camera: CameraConfig = CameraConfig()
    noise: NoiseConfig = NoiseConfig()
    normals: NormalsConfig = NormalsConfig()
    voxel: VoxelConfig = VoxelConfig()
    rhf: RHFConfig = RHFConfig()
    cull: CullConfig = CullConfig()
    min_points: int = 10

    _path = "perception"
    _constraints = {
        "min_points": count(3, 1 << 20),  # >= 3 for a PCA frame
        ("voxel.max_voxels",): Rule(lambda c: c.voxel.max_voxels % c.rhf.chunk == 0,
                                    lambda c: f"({c.voxel.max_voxels}) must be a multiple of rhf.chunk ({c.rhf.chunk})"),
        ("cull.tile",): Rule(lambda c: c.camera.width % c.cull.tile == 0 and c.camera.height % c.cull.tile == 0,
                             lambda c: f"({c.cull.tile}) must divide the image size {c.camera.width}x{c.camera.height}"),
    }


def stored_config(cfg: PerceptionConfig) -> dict:
    """``cfg`` as a feature folder records it (and compares it on resume).

    The default normals (exact ray hits) are recorded by the ``normals`` key's absence, as in
    every feature folder written before the option existed, so that those stay valid and
    resumable: a folder whose config has no ``normals`` used ``source="ray"``.
    """
    d = to_dict(cfg)
    if cfg.normals == NormalsConfig():
        d.pop("normals")
    return d
