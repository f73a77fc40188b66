"""The whole config tree, every node declared and checked in one place.

- ``constraints``: the declarative vocabulary (``Interval``, ``Options``, ``Seq``, ...) and the
  one checker ``check_node`` every node runs when it is built; ``ConfigError``.
- ``override``: ``parse_set`` (the CLI's ``--set``), ``override``, ``from_dict``, ``to_dict``,
  ``differences``.
- one module per node: ``action`` (physics, scene, arm), ``perception``, ``dataset``,
  ``experiment`` (forest, state), ``reproduce``, ``real`` (pipeline, proposal rule, simulated
  relations, experiments).
- ``tree``: ``RunConfig``, ``preset``, ``precheck``, ``resolve``, ``check_tree``, ``keys``,
  ``from_json``.
- ``streams``: the named random-stream ids.

No JAX, MuJoCo, numpy-heavy stage code or scikit-learn is imported here.
"""
from relaff_jax.config.constraints import ConfigError
from relaff_jax.config.override import differences, from_dict, override, override_under, parse_set, to_dict
from relaff_jax.config.tree import PRESETS, RunConfig, check_tree, from_json, keys, precheck, preset, resolve
from relaff_jax.config.action import ActionConfig, ArmConfig, PhysicsConfig, SceneConfig
from relaff_jax.config.perception import (CameraConfig, CullConfig, NoiseConfig, NormalsConfig, PerceptionConfig,
                                          RHFConfig, VoxelConfig)
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.config.experiment import ExperimentConfig, ForestConfig, StateConfig
from relaff_jax.config.reproduce import ReproduceConfig
from relaff_jax.config.real import (CropConfig, KMeansConfig, NormalConfig, PipelineConfig, PlaneConfig, RealConfig,
                                    RealExperimentConfig, RealRunConfig, RuleConfig, SensorTolerance,
                                    SimRelationConfig)

__all__ = ["ConfigError", "differences", "from_dict", "override", "override_under", "parse_set", "to_dict",
           "PRESETS", "RunConfig", "check_tree", "from_json", "keys", "precheck", "preset", "resolve",
           "ActionConfig", "ArmConfig", "PhysicsConfig", "SceneConfig", "CameraConfig", "CullConfig", "NoiseConfig",
           "NormalsConfig", "PerceptionConfig", "RHFConfig", "VoxelConfig", "DatasetConfig", "ExperimentConfig",
           "ForestConfig", "StateConfig", "ReproduceConfig", "CropConfig", "KMeansConfig", "NormalConfig",
           "PipelineConfig", "PlaneConfig", "RealConfig", "RealExperimentConfig", "RealRunConfig", "RuleConfig",
           "SensorTolerance", "SimRelationConfig"]
