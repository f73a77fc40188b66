"""Settings of the real-scene pipeline: frozen dataclasses and their validation.

Takes nothing; gives ``RealRunConfig``, the node ``RunConfig.real`` of the one config tree
(``relaff_jax.runconfig``): the real-only settings (plane RANSAC, crop, k-means, cloud normals,
the proposal rule, the simulated relation data, the experiments, the sensor tolerance). The voxel
grid and the RHF are not here: they are the tree's ``perception.voxel`` and ``perception.rhf``,
shared with simulation, so ``--set perception.voxel.size=...`` reaches both. ``pipeline_config(tree)``
gives the ``RealConfig`` the stages run with (the real-only settings plus the tree's perception);
``validate_real_config(cfg) -> cfg`` (UserError naming the bad setting).
"""
from __future__ import annotations

import dataclasses

from relaff_jax.errors import UserError
from relaff_jax.perception.config import PerceptionConfig

from .propose import RuleConfig


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


# Object pixels (both objects) kept per real pair before voxelisation: a capacity, not a
# setting of the features (points beyond it set the overflow flag, they are never dropped
# silently). Real objects are seen at 0.6-0.8 m, nearer than the simulated ones, and a real pair
# fills more than ``perception.voxel.max_object_pixels`` (32768) of the 640 x 480 image, so the
# real stages keep their own, larger capacity (the value they have always used).
REAL_MAX_OBJECT_PIXELS = 65536


@dataclasses.dataclass(frozen=True)
class PipelineConfig:
    """The real-only settings of segmentation and features (``RunConfig.real.pipeline``); the
    voxel grid and RHF are the tree's ``perception`` node (``pipeline_config``)."""

    plane: PlaneConfig = PlaneConfig()
    crop: CropConfig = CropConfig()
    kmeans: KMeansConfig = KMeansConfig()
    normals: NormalConfig = NormalConfig()
    max_object_pixels: int = REAL_MAX_OBJECT_PIXELS


def real_perception(perception: PerceptionConfig, max_object_pixels: int = REAL_MAX_OBJECT_PIXELS) -> PerceptionConfig:
    """The tree's perception settings (voxel size and capacity per object, RHF, ``min_points``)
    with the real pairs' object pixel capacity."""
    return dataclasses.replace(perception, voxel=dataclasses.replace(perception.voxel,
                                                                     max_object_pixels=max_object_pixels))


@dataclasses.dataclass(frozen=True)
class RealConfig:
    """What the real stages run with: ``PipelineConfig``'s settings and ``perception``, the
    tree's perception node with the real capacity (``pipeline_config(tree)``; the default is
    the default tree's)."""

    plane: PlaneConfig = PlaneConfig()
    crop: CropConfig = CropConfig()
    kmeans: KMeansConfig = KMeansConfig()
    normals: NormalConfig = NormalConfig()
    perception: PerceptionConfig = real_perception(PerceptionConfig())


def validate_real_config(cfg: RealConfig) -> RealConfig:
    """Raise ``UserError`` naming the bad setting; return ``cfg`` unchanged otherwise."""
    from relaff_jax.perception.config import validate_config

    check_pipeline_parts(cfg)
    validate_config(cfg.perception)
    return cfg


def check_pipeline_parts(cfg) -> None:
    """The plane, crop, k-means and normal settings of a ``RealConfig`` or ``PipelineConfig``."""
    p = cfg.plane
    if p.threshold <= 0 or p.iterations <= 0 or p.batch <= 0:
        raise UserError(f"real.pipeline.plane.threshold, .iterations and .batch must be positive, got {p}")
    c = cfg.crop
    if not 0 <= c.min_height < c.max_height or c.radius_scale <= 0:
        raise UserError(f"need 0 <= real.pipeline.crop.min_height < crop.max_height and crop.radius_scale > 0, got {c}")
    k = cfg.kmeans
    if k.k < 1 + int(k.background) or k.iterations <= 0 or k.n_init <= 0:
        raise UserError(f"real.pipeline.kmeans.k must leave an object cluster and kmeans.iterations, .n_init "
                        f"positive, got {k}")
    nc = cfg.normals
    if nc.knn < 3:
        raise UserError(f"real.pipeline.normals.knn must be >= 3 for a plane fit, got {nc.knn}")
    if nc.method not in ("knn", "window"):
        raise UserError(f"unknown real.pipeline.normals.method {nc.method!r}; valid: ['knn', 'window']")
    if nc.window < 3 or nc.window % 2 == 0 or nc.radius <= 0:
        raise UserError(f"real.pipeline.normals.window must be odd and >= 3 and normals.radius positive, got {nc}")


def pipeline_config(tree) -> RealConfig:
    """The ``RealConfig`` of a ``RunConfig`` tree: ``tree.real.pipeline`` with ``tree.perception``
    (voxel grid, RHF) and the real object pixel capacity; validated."""
    p = tree.real.pipeline
    return validate_real_config(RealConfig(plane=p.plane, crop=p.crop, kmeans=p.kmeans, normals=p.normals,
                                           perception=real_perception(tree.perception, p.max_object_pixels)))


# ---- the sim-to-real study's settings (JAX-free, so that ``--set`` mistakes are reported at once) ----

@dataclasses.dataclass(frozen=True)
class SimSensor:
    """The simulated camera's pose over the table and its vertical field of view (degrees)."""

    height: float
    tilt_deg: float
    vfov_deg: float = 43.0


@dataclasses.dataclass(frozen=True)
class SimRelationConfig:
    """Simulated relation data: scenes per chunk, workspace radius (m, around the robot),
    the least scenes of each relation in ``need`` to stop at, a cap on chunks, the seed;
    ``normals``: the RHF normals, "ray" (exact ray-hit geometry) or "cloud" (window PCA of the
    noisy points, ``perception.NormalsConfig``)."""

    per_relation: int = 1000
    need: tuple[str, ...] = ("beside", "on_top")
    chunk: int = 256
    workspace_radius: float = 1.1
    max_chunks: int = 200
    noise: str = "robwork"
    feature_batch: int = 32  # scenes per perception call (memory: ~1 GB at these capacities)
    max_tiles: int = 600  # of 1200 16 x 16 tiles: objects 0.6 m from the camera are large
    max_object_pixels: int = 65536  # of both objects: the real sensor's objects are near, as for the real pairs
    seed: int = 0
    # ``noise`` and ``normals`` are the simulated relation data's own (``perception.noise.model``
    # and ``perception.normals.source`` of the tree are not read here): they are in the guard
    # of every simulated folder built so far (``sim_relations.GUARD_KEYS``), and the study's
    # ``--sim-normals`` flag sets them apart from the simulated datasets' choice
    normals: str = "ray"


@dataclasses.dataclass(frozen=True)
class SensorTolerance:
    """How far a simulated folder's sensor may be from the one a study asks for and still be
    reused (its data are then used as they are, and the study says so). The defaults lie
    below the spread of the real scenes' own poses about their mean (45 learn scenes: height
    std 0.006 m, tilt std 3.4 deg, 46.7-55.9 deg), so a reused simulation is no further from
    any real scene than the mean sensor already is; 0 everywhere asks for the exact sensor."""

    height: float = 0.01  # m
    tilt_deg: float = 2.5
    vfov_deg: float = 0.5


SPLITS = ("scene", "pair")


@dataclasses.dataclass(frozen=True)
class RealExperimentConfig:
    """Section VI settings: 50 repetitions, forests of 100 trees, balanced sets. ``split``:
    how one folder's pairs are cut into train and test per repetition, "scene" (every pair of
    a scene on one side: pairs of a scene share objects, pose and lighting) or "pair" (pairs
    drawn one by one, the protocol before issue 28)."""

    reps: int = 50
    trees: int = 100
    train_fraction: float = 0.625  # the paper's 100 of 160
    n_full: int = 1000  # SIM_full training samples (paper: 6500), as many to test
    repeats_pca: int = 6
    repeats_rhf: int = 30
    n_boot: int = 2000  # resamples of the bootstrap interval
    seed: int = 0
    engine: str = "fast"
    split: str = "scene"
    # the bootstrap factor's window in real training sizes: the paper's early range (V-C: "roughly
    # from samples 4 to 25"; VI gives none of its own); only the summary reads it
    bf_sizes: tuple[int, int] = (4, 25)

    def forest(self):
        from relaff_jax.learn.forests import ForestConfig

        return ForestConfig(base_trees=self.trees, max_trees=self.trees, engine=self.engine)

    def repeats(self, space: str) -> int:
        return self.repeats_pca if space == "pca" else self.repeats_rhf


@dataclasses.dataclass(frozen=True)
class RealRunConfig:
    """Every real-only setting, the node ``RunConfig.real`` (``--set real.dotted.key=value``):
    ``pipeline`` the real scenes' segmentation and features, ``rule`` the relation proposal
    rule (``real propose``), ``sim`` the simulated relation data, ``experiment`` the four
    experiments, ``tolerance`` the reuse of simulated data."""

    pipeline: PipelineConfig = PipelineConfig()
    rule: RuleConfig = RuleConfig()
    sim: SimRelationConfig = SimRelationConfig()
    experiment: RealExperimentConfig = RealExperimentConfig()
    tolerance: SensorTolerance = SensorTolerance()

    def __post_init__(self):  # refused when the config is made (the perception it shares: check_tree)
        check_real_node(self)


def validate_run_config(tree):
    """Raise ``UserError`` naming the bad real setting of a ``RunConfig`` tree: its ``real`` node
    checked itself when it was made (``check_real_node``); this checks the pipeline with the
    perception it shares. Return ``tree`` unchanged otherwise."""
    pipeline_config(tree)
    return tree


def check_real_node(cfg: RealRunConfig) -> None:
    """The real node's own settings (run when a ``RealRunConfig`` is made)."""
    check_pipeline_parts(cfg.pipeline)
    if cfg.pipeline.max_object_pixels < 1:
        raise UserError(f"real.pipeline.max_object_pixels must be >= 1, got {cfg.pipeline.max_object_pixels}")
    e, s, t = cfg.experiment, cfg.sim, cfg.tolerance
    if e.split not in SPLITS:
        raise UserError(f"unknown real.experiment.split {e.split!r}; valid: {list(SPLITS)}")
    if not 0 < e.train_fraction < 1:
        raise UserError(f"real.experiment.train_fraction must lie in (0, 1), got {e.train_fraction}")
    if len(e.bf_sizes) != 2 or not 2 <= e.bf_sizes[0] <= e.bf_sizes[1]:
        raise UserError(f"real.experiment.bf_sizes must be [lo, hi] training sizes with 2 <= lo <= hi, got {list(e.bf_sizes)}")
    for name, v, lo in (("real.experiment.reps", e.reps, 1), ("real.experiment.trees", e.trees, 1),
                        ("real.experiment.n_full", e.n_full, 2), ("real.sim.per_relation", s.per_relation, 1),
                        ("real.sim.chunk", s.chunk, 1), ("real.sim.feature_batch", s.feature_batch, 1)):
        if v < lo:
            raise UserError(f"{name} must be >= {lo}, got {v}")
    if s.normals not in ("ray", "cloud"):
        raise UserError(f"unknown real.sim.normals {s.normals!r}; valid: ['ray', 'cloud']")
    if s.chunk % s.feature_batch:
        raise UserError(f"real.sim.chunk ({s.chunk}) must be a multiple of real.sim.feature_batch ({s.feature_batch})")
    if min(t.height, t.tilt_deg, t.vfov_deg) < 0:
        raise UserError(f"real.tolerance values must be >= 0, got {t}")


def sensor_difference(a: SimSensor, b: SimSensor) -> dict:
    """|a - b| per field: height (m), tilt_deg, vfov_deg."""
    return {k: abs(float(getattr(a, k)) - float(getattr(b, k))) for k in ("height", "tilt_deg", "vfov_deg")}


def sensor_mismatch(stored: SimSensor, wanted: SimSensor, tol: SensorTolerance) -> str | None:
    """None when ``wanted`` lies within ``tol`` of ``stored``, else the reason (what differs, by how much)."""
    d = sensor_difference(stored, wanted)
    bad = [f"{k} {getattr(stored, k)} vs {getattr(wanted, k)} (|diff| {d[k]:.4g} > tolerance {getattr(tol, k)})"
           for k in d if d[k] > getattr(tol, k) + 1e-12]
    return "; ".join(bad) or None
