"""The config tree and its one override path (hand-worked cases)."""
import dataclasses

import pytest

from relaff_jax import runconfig
from relaff_jax.config import ConfigError, override, parse_set, to_dict
from relaff_jax.errors import UserError


def test_parse_set_reads_json_values_and_keeps_strings():
    got = parse_set(["a.b=1", "c=[1, 2]", "d=robwork", "e=true", "f=0.5", "g=null", "h=[[0, 1], [2, 3]]"])
    assert got == {"a.b": 1, "c": (1, 2), "d": "robwork", "e": True, "f": 0.5, "g": None, "h": ((0, 1), (2, 3))}
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        parse_set(["novalue"])
    assert issubclass(ConfigError, UserError)


def test_tree_has_every_stage_and_sets_nested_keys():
    cfg = runconfig.RunConfig()
    assert [f.name for f in dataclasses.fields(cfg)] == ["action", "perception", "dataset", "experiment", "reproduce",
                                                       "real"]
    new = runconfig.resolve(cfg, {"perception.voxel.size": 0.02, "action.scene.settle_steps": 300,
                                  "dataset.n_samples": 50, "experiment.forest.max_trees": 7})
    assert new.perception.voxel.size == 0.02
    assert new.action.scene.settle_steps == 300
    assert new.dataset.n_samples == 50
    assert new.experiment.forest.max_trees == 7
    assert cfg.perception.voxel.size == 0.0125  # the original is untouched (frozen)
    assert runconfig.from_json(to_dict(new)) == new
    assert "perception.voxel.size" in runconfig.keys()
    assert "real.pipeline.kmeans.k" in runconfig.keys()
    assert "experiment.forest.max_trees" in runconfig.keys()


def test_unknown_or_ill_typed_keys_are_clear_errors():
    cfg = runconfig.RunConfig()
    with pytest.raises(ConfigError, match=r"unknown config key 'voxel_size'.*valid keys: \['camera', 'cull'"):
        override(cfg.perception, {"voxel_size": 1})
    with pytest.raises(ConfigError, match="unknown config key 'perceptoin.voxel.size'"):
        runconfig.resolve(cfg, {"perceptoin.voxel.size": 0.02})
    with pytest.raises(ConfigError, match="expects a number"):
        runconfig.resolve(cfg, {"perception.voxel.size": "small"})
    with pytest.raises(ConfigError, match="expects an integer"):
        runconfig.resolve(cfg, {"dataset.n_samples": 10.5})
    with pytest.raises(ConfigError, match="expects true or false"):
        runconfig.resolve(cfg, {"experiment.shrink_to_data": 1})
    with pytest.raises(ConfigError, match="group of settings"):
        runconfig.resolve(cfg, {"perception.voxel": 3})
    with pytest.raises(ConfigError, match="has no sub-keys"):
        runconfig.resolve(cfg, {"dataset.n_samples.x": 3})
    # an int given for a float is stored as a float: one spelling per value
    assert runconfig.resolve(cfg, {"perception.voxel.size": 1}).perception.voxel.size == 1.0
    assert isinstance(runconfig.resolve(cfg, {"perception.voxel.size": 1}).perception.voxel.size, float)


def test_presets():
    tiny, quick, study, paper = (runconfig.preset(p) for p in runconfig.PRESETS)
    assert study.dataset.n_samples == 1000
    assert study.experiment.sizes == tuple(range(2, 51))
    assert (tiny.dataset.n_samples, tiny.dataset.rollout_batch, tiny.dataset.feature_batch) == (24, 8, 8)
    assert (quick.dataset.n_samples, quick.dataset.rollout_batch, quick.dataset.feature_batch) == (100, 64, 16)
    assert paper.dataset.n_samples == 10_000
    assert paper.dataset.rollout_batch == 1024
    # the paper preset reads the feasible population (issue 24), the others today's reading
    assert (paper.dataset.population, paper.dataset.match_patience, paper.dataset.max_rollouts) == ("feasible", 1.0, 300_000)
    assert {p.dataset.population for p in (tiny, quick, study)} == {"all"}
    assert tiny.experiment.forest.max_trees == 8
    assert quick.experiment.sizes == (2,) + tuple(range(4, 26))
    with pytest.raises(UserError, match="unknown preset"):
        runconfig.preset("fast")


def test_a_criterion_the_engine_cannot_build_is_refused_by_the_config_check(capsys, tmp_path):
    """entropy used to pass the check and fail inside a sweep worker; now the check refuses it
    before any work, naming the engine, and the sklearn engine accepts it."""
    from relaff_jax import cli
    from relaff_jax.errors import UserError
    from relaff_jax.learn import ExperimentConfig, check_config

    bad = override(ExperimentConfig(), {"forest.criterion": "entropy"})
    with pytest.raises(UserError, match="fast engine builds gini trees only"):
        check_config(bad)
    check_config(override(bad, {"forest.engine": "sklearn"}))
    out = tmp_path / "e"
    assert cli.main(["experiment", "--synthetic", "40", "--out", str(out), "--set",
                     "experiment.forest.criterion=entropy"]) == 2
    assert "gini trees only" in capsys.readouterr().err
    assert not out.exists()
