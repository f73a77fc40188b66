"""Session fixtures more than one test file uses (loaded by tests/conftest.py as a plugin)."""
import pytest

from relaff_jax import cli
from relaff_jax import data as dataset
from relaff_jax import config as runconfig
from relaff_jax.config import override
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.stages import features as stage_features

from helpers.scenes import scene_rollout_fn

B = 8


@pytest.fixture(scope="session")
def scene_run(tmp_path_factory, scene_world, settle):
    """A run-shaped folder: data/lift and data/take (16 real scenes each, with features) and
    results/ from `relaff experiment --synthetic` (small forests, two sizes)."""
    root = tmp_path_factory.mktemp("scene_run")
    for seed, action in enumerate(("lift", "take")):
        path = root / "data" / action
        dataset.generate_dataset(path, action, scene_rollout_fn(scene_world, settle), seed=seed, progress=False,
                                 dataset_config=DatasetConfig(n_samples=16, rollout_batch=B, borrow_fraction=1.0))
        stage_features.add_features(override(runconfig.RunConfig(), {"dataset.feature_batch": B}), path,
                                    progress=False)
    argv = ["experiment", "--synthetic", "150", "--out", str(root / "results"), "--jobs", "2", "--no-progress",
            "--set", "experiment.sizes=[4,10]", "--set", "experiment.reps_pca=1", "--set", "experiment.reps_rhf=1",
            "--set", "experiment.forest.base_trees=4", "--set", "experiment.forest.max_trees=4"]
    assert cli.main(argv) == 0
    return root
