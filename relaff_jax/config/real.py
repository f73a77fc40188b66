"""The real scenes' settings (the tree's ``real`` node, ``RealRunConfig``): plane RANSAC, crop,
k-means, cloud normals, the proposal rule, the simulated relation data, the experiments, the
sensor tolerance. The voxel grid and the RHF are not here: they are the tree's
``perception.voxel`` and ``perception.rhf``, shared with simulation, so ``--set
perception.voxel.size=...`` reaches both. ``pipeline_config(tree)`` gives the ``RealConfig`` the
stages run with (the real-only settings plus the tree's perception)."""
from __future__ import annotations

import dataclasses

from relaff_jax.config.constraints import (FRACTION, Boolean, Interval, Options, Rule, Seq, count, length)
from relaff_jax.config.experiment import ENGINES, ForestConfig
from relaff_jax.config.node import Node
from relaff_jax.config.perception import (MAX_IMAGE, NOISE_MODEL_NAMES, NORMAL_SOURCES, ODD_WINDOW,
                                          PerceptionConfig, odd)
from relaff_jax.constants import RELATIONS

SEED = count(0, 2**32 - 1)  # numpy's seeds
PIXELS = count(1, MAX_IMAGE * MAX_IMAGE)


@dataclasses.dataclass(frozen=True)
class PlaneConfig(Node):
    """RANSAC plane fit (Open3D ``segment_plane`` semantics): a point is an inlier when its
    distance to the plane is below ``threshold`` (m); ``iterations`` hypotheses of 3 points,
    evaluated ``batch`` at a time; the best plane is refitted by least squares to its inliers."""

    threshold: float = 0.01
    iterations: int = 1000
    batch: int = 50

    _path = "real.pipeline.plane"
    _constraints = {"threshold": Interval(float, 0.0, 1.0, closed="right"), "iterations": count(1, 10_000_000),
                    "batch": count(1, 1_000_000)}


@dataclasses.dataclass(frozen=True)
class CropConfig(Node):
    """Which non-table points k-means sees: at least ``min_height`` and at most ``max_height``
    (m) above the table plane, and (projected on the plane) at most ``radius_scale`` x the
    largest distance of a table inlier from the inliers' centroid (the table's extent)."""

    min_height: float = 0.01
    max_height: float = 0.5
    radius_scale: float = 1.0

    _path = "real.pipeline.crop"
    _constraints = {"min_height": length(), "max_height": length(), "radius_scale": Interval(float, 0.0, 100.0, closed="right"),
                    ("min_height", "max_height"): Rule(lambda c: c.min_height < c.max_height,
                                                       lambda c: f"must be below crop.max_height, got {c.min_height}, {c.max_height}")}


@dataclasses.dataclass(frozen=True)
class KMeansConfig(Node):
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

    _path = "real.pipeline.kmeans"
    _constraints = {"k": count(1, 1000), "background": Boolean(), "iterations": count(1, 1_000_000),
                    "n_init": count(1, 10_000),
                    ("k", "background"): Rule(lambda c: c.k >= 1 + int(c.background),
                                              lambda c: f"must leave an object cluster (>= 2 with the background), got {c.k}")}


@dataclasses.dataclass(frozen=True)
class NormalConfig(Node):
    """Normals from the cloud, oriented towards the camera. ``method`` "knn" (default): PCA of
    each point's ``knn`` nearest neighbours among the object's points (smallest-eigenvalue
    eigenvector); "window" (organized clouds only): PCA of the object's points in a ``window`` x
    ``window`` pixel neighbourhood within ``radius`` m, the simulation's
    ``PerceptionConfig.normals.source = "cloud"`` rule (``perception.normals.window_normals``)."""

    knn: int = 20
    method: str = "knn"
    window: int = 5
    radius: float = 0.025

    _path = "real.pipeline.normals"
    _constraints = {"knn": count(3, 10_000), "method": Options(("knn", "window")), "window": ODD_WINDOW,
                    "radius": Interval(float, 0.0, 1.0, closed="right"), ("window",): odd("window")}


# Object pixels (both objects) kept per real pair before voxelisation: a capacity, not a
# setting of the features (points beyond it set the overflow flag, they are never dropped
# silently). Real objects are seen at 0.6-0.8 m, nearer than the simulated ones, and a real pair
# fills more than ``perception.voxel.max_object_pixels`` (32768) of the 640 x 480 image, so the
# real stages keep their own, larger capacity (the value they have always used).
REAL_MAX_OBJECT_PIXELS = 65536


@dataclasses.dataclass(frozen=True)
class PipelineConfig(Node):
    """The real-only settings of segmentation and features (``RunConfig.real.pipeline``); the
    voxel grid and RHF are the tree's ``perception`` node (``pipeline_config``)."""

    plane: PlaneConfig = PlaneConfig()
    crop: CropConfig = CropConfig()
    kmeans: KMeansConfig = KMeansConfig()
    normals: NormalConfig = NormalConfig()
    max_object_pixels: int = REAL_MAX_OBJECT_PIXELS

    _path = "real.pipeline"
    _constraints = {"max_object_pixels": PIXELS}


def real_perception(perception: PerceptionConfig, max_object_pixels: int = REAL_MAX_OBJECT_PIXELS) -> PerceptionConfig:
    """The tree's perception settings (voxel size and capacity per object, RHF, ``min_points``)
    with the real pairs' object pixel capacity."""
    return dataclasses.replace(perception, voxel=dataclasses.replace(perception.voxel,
                                                                     max_object_pixels=max_object_pixels))


@dataclasses.dataclass(frozen=True)
class RealConfig(Node):
    """What the real stages run with: ``PipelineConfig``'s settings and ``perception``, the
    tree's perception node with the real capacity (``pipeline_config(tree)``; the default is
    the default tree's). Every part checked itself when it was built."""

    plane: PlaneConfig = PlaneConfig()
    crop: CropConfig = CropConfig()
    kmeans: KMeansConfig = KMeansConfig()
    normals: NormalConfig = NormalConfig()
    perception: PerceptionConfig = real_perception(PerceptionConfig())

    _path = "real.pipeline"


def pipeline_config(tree) -> RealConfig:
    """The ``RealConfig`` of a ``RunConfig`` tree: ``tree.real.pipeline`` with ``tree.perception``
    (voxel grid, RHF) and the real object pixel capacity."""
    p = tree.real.pipeline
    return RealConfig(plane=p.plane, crop=p.crop, kmeans=p.kmeans, normals=p.normals,
                      perception=real_perception(tree.perception, p.max_object_pixels))


@dataclasses.dataclass(frozen=True)
class RuleConfig(Node):
    """Tolerances of the relation proposal rule (``real.propose``), metres and fractions."""

    lo_q: float = 0.02
    hi_q: float = 0.98
    table_tol: float = 0.02
    contact_tol: float = 0.03
    min_overlap: float = 0.25
    grow: float = 0.01

    _path = "real.rule"
    _constraints = {"lo_q": FRACTION, "hi_q": FRACTION, "table_tol": length(1.0), "contact_tol": length(1.0),
                    "min_overlap": FRACTION, "grow": length(1.0),
                    ("lo_q", "hi_q"): Rule(lambda c: c.lo_q < c.hi_q, lambda c: f"must be below rule.hi_q, got {c.lo_q}, {c.hi_q}")}


@dataclasses.dataclass(frozen=True)
class SimSensor:
    """The simulated camera's pose over the table and its vertical field of view (degrees)."""

    height: float
    tilt_deg: float
    vfov_deg: float = 43.0


@dataclasses.dataclass(frozen=True)
class SimRelationConfig(Node):
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

    _path = "real.sim"
    _constraints = {
        "per_relation": count(1, 10_000_000), "need": Seq(Options(RELATIONS), distinct=True),
        "chunk": count(1, 1 << 16), "workspace_radius": Interval(float, 0.0, 10.0, closed="right"),
        "max_chunks": count(1, 1_000_000), "noise": Options(NOISE_MODEL_NAMES), "feature_batch": count(1, 1 << 16),
        "max_tiles": PIXELS, "max_object_pixels": PIXELS, "seed": SEED, "normals": Options(NORMAL_SOURCES),
        ("chunk", "feature_batch"): Rule(lambda c: c.chunk % c.feature_batch == 0,
                                         lambda c: f"({c.chunk}) must be a multiple of real.sim.feature_batch ({c.feature_batch})"),
    }


@dataclasses.dataclass(frozen=True)
class SensorTolerance(Node):
    """How far a simulated folder's sensor may be from the one a study asks for and still be
    reused (its data are then used as they are, and the study says so). The defaults lie
    below the spread of the real scenes' own poses about their mean (45 learn scenes: height
    std 0.006 m, tilt std 3.4 deg, 46.7-55.9 deg), so a reused simulation is no further from
    any real scene than the mean sensor already is; 0 everywhere asks for the exact sensor."""

    height: float = 0.01  # m
    tilt_deg: float = 2.5
    vfov_deg: float = 0.5

    _path = "real.tolerance"
    _constraints = {"height": length(), "tilt_deg": Interval(float, 0.0, 180.0), "vfov_deg": Interval(float, 0.0, 180.0)}


SPLITS = ("scene", "pair")


@dataclasses.dataclass(frozen=True)
class RealExperimentConfig(Node):
    """Section VI settings, what the real experiments run with (``real_experiment(tree)``): 50
    repetitions, forests of 100 trees, balanced sets. ``split``:
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

    _path = "real.experiment"
    _constraints = {
        "reps": count(1, 100_000), "trees": count(1, 100_000), "train_fraction": Interval(float, 0.0, 1.0, closed="neither"),
        "n_full": count(2, 100_000_000), "repeats_pca": count(1, 10_000), "repeats_rhf": count(1, 10_000),
        "n_boot": count(10, 10_000_000), "seed": SEED, "engine": Options(ENGINES), "split": Options(SPLITS),
        "bf_sizes": Seq(count(2, 1_000_000), length=2),
        ("bf_sizes",): Rule(lambda c: c.bf_sizes[0] <= c.bf_sizes[1],
                            lambda c: f"must be [lo, hi] training sizes with lo <= hi, got {list(c.bf_sizes)}"),
    }

    def forest(self):
        return ForestConfig(base_trees=self.trees, max_trees=self.trees, engine=self.engine)

    def repeats(self, space: str) -> int:
        return self.repeats_pca if space == "pca" else self.repeats_rhf


@dataclasses.dataclass(frozen=True)
class RealExperimentSettings(Node):
    """The real experiments' own settings, the tree's ``real.experiment`` node: what
    ``RealExperimentConfig`` holds beyond the keys it takes from the tree's ``experiment`` node
    (``SHADOWED``: the forest engine, the bootstrap input repetitions, the bf window);
    ``real_experiment(tree)`` gives the whole."""

    reps: int = 50
    trees: int = 100
    train_fraction: float = 0.625  # the paper's 100 of 160
    n_full: int = 1000  # SIM_full training samples (paper: 6500), as many to test
    n_boot: int = 2000  # resamples of the bootstrap interval
    seed: int = 0
    split: str = "scene"

    _path = "real.experiment"
    _constraints = {k: c for k, c in RealExperimentConfig._constraints.items()
                    if k in ("reps", "trees", "train_fraction", "n_full", "n_boot", "seed", "split")}


# keys of ``RealExperimentConfig`` taken from the tree's ``experiment`` node (a stored tree made
# when ``real.experiment`` still had them: ``tree.from_json`` maps or refuses them)
SHADOWED = {"engine": "experiment.forest.engine", "repeats_pca": "experiment.repeats_pca",
            "repeats_rhf": "experiment.repeats_rhf", "bf_sizes": "experiment.bf_sizes"}


def real_experiment(tree) -> RealExperimentConfig:
    """What the real experiments run with: ``tree.real.experiment`` with the forest engine, the
    bootstrap input repetitions and the bf window of ``tree.experiment``."""
    e, x = tree.real.experiment, tree.experiment
    return RealExperimentConfig(**dataclasses.asdict(e), engine=x.forest.engine, repeats_pca=x.repeats_pca,
                                repeats_rhf=x.repeats_rhf, bf_sizes=tuple(x.bf_sizes))


@dataclasses.dataclass(frozen=True)
class RealRunConfig(Node):
    """Every real-only setting, the node ``RunConfig.real`` (``--set real.dotted.key=value``):
    ``pipeline`` the real scenes' segmentation and features, ``rule`` the relation proposal
    rule (``real propose``), ``sim`` the simulated relation data, ``experiment`` the four
    experiments (their forest engine, input repetitions and bf window are the tree's
    ``experiment``'s: ``real_experiment``), ``tolerance`` the reuse of simulated data."""

    pipeline: PipelineConfig = PipelineConfig()
    rule: RuleConfig = RuleConfig()
    sim: SimRelationConfig = SimRelationConfig()
    experiment: RealExperimentSettings = RealExperimentSettings()
    tolerance: SensorTolerance = SensorTolerance()

    _path = "real"


def sensor_difference(a: SimSensor, b: SimSensor) -> dict:
    """|a - b| per field: height (m), tilt_deg, vfov_deg."""
    return {k: abs(float(getattr(a, k)) - float(getattr(b, k))) for k in ("height", "tilt_deg", "vfov_deg")}


def sensor_mismatch(stored: SimSensor, wanted: SimSensor, tol: SensorTolerance) -> str | None:
    """None when ``wanted`` lies within ``tol`` of ``stored``, else the reason (what differs, by how much)."""
    d = sensor_difference(stored, wanted)
    bad = [f"{k} {getattr(stored, k)} vs {getattr(wanted, k)} (|diff| {d[k]:.4g} > tolerance {getattr(tol, k)})"
           for k in d if d[k] > getattr(tol, k) + 1e-12]
    return "; ".join(bad) or None
