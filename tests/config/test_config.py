"""The config tree and its one override path (hand-worked cases)."""
import copy
import dataclasses
import json

import pytest

from relaff_jax import config as runconfig
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
    assert [f.name for f in dataclasses.fields(cfg)] == ["seed", "action", "perception", "dataset", "experiment",
                                                       "reproduce", "real"]
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
    # the paper preset reads the feasible population, the others today's reading
    assert (paper.dataset.population, paper.dataset.match_patience, paper.dataset.max_rollouts) == ("feasible", 1.0, 300_000)
    assert {p.dataset.population for p in (tiny, quick, study)} == {"all"}
    assert tiny.experiment.forest.max_trees == 8
    assert quick.experiment.sizes == (2,) + tuple(range(4, 26))
    # the same forests with either engine: the compiled one where a run fits thousands of forests
    # (its numba compile is cached on disk), the fast one for the tests' tiny runs
    assert [p.experiment.forest.engine for p in (tiny, quick, study, paper)] == ["fast", "compiled", "compiled", "compiled"]
    with pytest.raises(UserError, match="unknown preset"):
        runconfig.preset("fast")


def test_the_quick_preset_differs_from_its_experiment_preset_by_speed_only():
    """``relaff reproduce --preset quick`` runs ``experiment_preset("quick")``'s protocol with
    the compiled engine: a results folder of either is the other's (no result-changing key
    differs), and the tests' tiny preset keeps the fast engine."""
    from relaff_jax.config.experiment import experiment_preset, result_differences

    quick, exp = runconfig.preset("quick").experiment, experiment_preset("quick")
    assert (quick.forest.engine, exp.forest.engine, runconfig.preset("tiny").experiment.forest.engine) == \
        ("compiled", "fast", "fast")
    stored = json.loads(json.dumps(to_dict(exp)))  # as a results folder's experiment.json holds it
    assert result_differences(stored, quick) == []
    assert to_dict(quick) != to_dict(exp)  # the engine is compared: not the same tree


def test_result_differences_ignore_the_forest_engine_and_analysis_keys_a_folder_lacks():
    """The rule the experiment's status and its resume check share, by hand: the engine is
    never a difference; an analysis-only key is one only when the stored config has it; any
    other key, nested or not, is."""
    from relaff_jax.io import jsonable
    from relaff_jax.config.experiment import ExperimentConfig
    from relaff_jax.config.experiment import result_differences

    cfg = ExperimentConfig()
    stored = jsonable(to_dict(cfg))
    assert result_differences(stored, cfg) == []
    engine = copy.deepcopy(stored)
    engine["forest"]["engine"] = "compiled"
    assert result_differences(engine, cfg) == []
    older = {k: v for k, v in stored.items() if k not in ("chance_tol_scenes", "min_defined_share")}
    assert result_differences(older, cfg) == []
    changed = dict(stored, chance_tol_scenes=stored["chance_tol_scenes"] + 1, reps_pca=7)
    changed["forest"] = dict(stored["forest"], max_depth=3, engine="sklearn")
    assert result_differences(changed, cfg) == ["chance_tol_scenes", "forest.max_depth", "reps_pca"]
    assert result_differences(None, cfg)  # no stored config: everything differs


def test_a_criterion_the_engine_cannot_build_is_refused_when_the_config_is_built(capsys, tmp_path):
    """entropy used to pass the check and fail inside a sweep worker; now the config node
    refuses it when it is made, naming the engine, and the sklearn engine accepts it (with
    scikit-learn's own validation in the whole tree's check)."""
    from relaff_jax import cli
    from relaff_jax.errors import UserError
    from relaff_jax.config.experiment import ExperimentConfig, ForestConfig
    from relaff_jax.learn.checks import check_config

    with pytest.raises(UserError, match="fast engine builds gini trees only"):
        override(ExperimentConfig(), {"forest.criterion": "entropy"})
    with pytest.raises(UserError, match="compiled engine builds gini trees only"):
        ForestConfig(criterion="entropy", engine="compiled")
    check_config(override(ExperimentConfig(), {"forest.criterion": "entropy", "forest.engine": "sklearn"}))
    out = tmp_path / "e"
    assert cli.main(["experiment", "--synthetic", "40", "--out", str(out), "--set",
                     "experiment.forest.criterion=entropy"]) == 2
    assert "gini trees only" in capsys.readouterr().err
    assert not out.exists()


FOREST_GRID = {"max_depth": [None, 0, 1, 5, -1], "min_samples_leaf": [0, 1, 3, 0.0, 0.5, 1.0, 2.0],
               "max_features": ["sqrt", "log2", "0", "1", "3", "0.5", "1.0", "1.5", "abc", None],
               "max_samples": [None, 0, 1, 10, 0.0, 0.5, 1.0, 1.5], "criterion": ["gini", "entropy", "log_loss", "x"],
               "base_trees": [0, 1, 95], "max_trees": [1, 95, 200]}


@pytest.mark.parametrize("key", sorted(FOREST_GRID))
def test_the_forest_node_refuses_what_scikit_learn_refuses(key):
    """ForestConfig checks itself when it is made, without importing scikit-learn; on this grid
    it accepts exactly the values RandomForestClassifier's own parameter validation accepts
    (the tree counts reach scikit-learn as n_estimators = min(max_trees, base_trees + ...))."""
    from relaff_jax.config.experiment import ForestConfig
    from relaff_jax.learn.forest.estimator import make_forest

    for value in FOREST_GRID[key]:
        base = ForestConfig(engine="sklearn")  # the only engine that builds every criterion
        try:
            dataclasses.replace(base, **{key: value})
            node = True
        except UserError:
            node = False
        forced = copy.copy(base)
        object.__setattr__(forced, key, value)  # past the node's check, to ask scikit-learn
        try:
            make_forest(2, 0, forced)._validate_params()
            reference = True
        except (ValueError, TypeError):
            reference = False
        assert node == reference, f"{key}={value!r}: node accepts {node}, scikit-learn {reference}"


BAD_VALUES = {"dataset.n_samples": 1, "dataset.population": "some", "perception.voxel.size": -1.0,
              "perception.cull.tile": 7, "experiment.select_size": 1000, "experiment.forest.criterion": "entropy",
              "experiment.state.extra": ("x",), "reproduce.actions": ("lift",), "real.experiment.split": "x",
              "real.pipeline.normals.method": "y", "action.scene.settle_steps": 0, "action.arm.ik_steps": 0,
              "action.phys.solver": "PGS", "action.move_rule": "x"}


@pytest.mark.parametrize("key", sorted(BAD_VALUES))
def test_each_node_refuses_a_bad_value_when_the_tree_is_built(key):
    """Every node of the tree checks its own values when it is made (``__post_init__``), so a
    bad ``--set`` fails while the tree is built, before any stage; the message names the key
    as it is spelled from the root. The good default beside it is accepted."""
    import re

    with pytest.raises(UserError, match=re.escape(key)):
        runconfig.resolve(runconfig.preset("tiny"), {key: BAD_VALUES[key]})
    runconfig.check_tree(runconfig.resolve(runconfig.preset("tiny"), {}))
