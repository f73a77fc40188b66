"""`relaff experiment --data` on real dataset folders (dataset stage storage, synthetic rollouts).

The rollouts and features are numpy draws (tests/helpers/standins.py), not physics: this checks the hand-over from
``relaff_jax.data.load_dataset`` to the learning stage, not any result.
"""
import argparse

import numpy as np
import pytest

from relaff_jax import data as ds
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax import learn as E
from relaff_jax.learn.results import load_results
from relaff_jax.cli import learn as cli_learn

from helpers import standins


def test_experiment_reads_dataset_folders(tmp_path):
    dirs = []
    for i, action in enumerate(("lift", "take", "pour")):
        p = tmp_path / action
        ds.generate_dataset(p, action, standins.rollout_factory(action, 64)[0], seed=i, progress=False,
                            dataset_config=DatasetConfig(max_rollouts=4000, distance_bins=4, borrow_fraction=0.5,
                                                         n_samples=120, rollout_batch=64))
        ds.add_features(p, standins.feature_factory(i)[0], batch=64, progress=False)
        dirs.append(str(p))
    loaded = E.load_datasets(dirs)
    assert sorted(loaded) == ["lift", "pour", "take"]
    assert loaded["lift"]["pca"].shape == (120, 18)

    parser = argparse.ArgumentParser()
    cli_learn.register(parser.add_subparsers(dest="command"))
    sets = ["--set", "experiment.sizes=[2,10]", "--set", "experiment.reps_pca=1", "--set", "experiment.reps_rhf=1",
            "--set", "experiment.forest.base_trees=5", "--set", "experiment.forest.max_trees=5",
            "--set", "experiment.online_select=false"]
    args = parser.parse_args(["experiment", "--data", *dirs, "--out", str(tmp_path / "res"), "--jobs", "1",
                              "--no-progress"] + sets)
    assert args.func(args) == 0
    res = load_results(tmp_path / "res")
    assert res["meta"]["actions"] == ["lift", "take", "pour"]
    acc = res["pca"]["acc"]
    assert acc.shape == (3, E.layout(3, 3)["n"], 2, 1)
    assert np.all(np.isfinite(acc[:, 0]))
    # shrink_to_data (quick preset): 120 samples -> 48 source, 12 correlation scenes, 50 test
    # scenes asked for, balanced by class (fewer, and even, if the pool lacks one class)
    n, pos = res["pca"]["test_size"], res["pca"]["test_positive"]
    assert np.all(n <= 50)
    assert np.all(n % 2 == 0)
    assert np.all(n >= 40)
    assert list(pos) == list(n // 2)
    with pytest.raises(ValueError, match="two datasets for action 'lift'"):
        E.load_datasets([dirs[0], dirs[0]])
