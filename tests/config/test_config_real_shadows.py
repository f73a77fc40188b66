"""``real.experiment`` takes its forest engine, input repetitions and bf window from the tree's
``experiment`` node; trees and run logs stored before (with those keys) still read."""
from __future__ import annotations

import json

import pytest

import relaff_jax.config as C
from relaff_jax.config.real import SHADOWED, real_experiment
from relaff_jax.errors import UserError


def _old_tree(name="tiny", **shadow):
    d = json.loads(json.dumps(C.to_dict(C.preset(name)), default=list))
    d["real"]["experiment"].update({"engine": "fast", "repeats_pca": 6, "repeats_rhf": 30, "bf_sizes": [4, 25]}, **shadow)
    return d


def test_real_experiment_derives_the_shadowed_keys():
    tree = C.resolve(None, {"experiment.repeats_pca": 4, "experiment.bf_sizes": [3, 12], "real.experiment.reps": 7})
    e = real_experiment(tree)
    assert (e.repeats_pca, e.bf_sizes, e.reps, e.engine) == (4, (3, 12), 7, "fast")
    assert real_experiment(C.RunConfig()) == C.RealExperimentConfig()  # the defaults: as before
    for key in SHADOWED:
        assert f"real.experiment.{key}" not in C.keys()
        with pytest.raises(C.ConfigError, match=f"unknown config key 'real.experiment.{key}'"):
            C.precheck({f"real.experiment.{key}": "foo"})  # e.g. real.experiment.engine=foo


@pytest.mark.parametrize("name", C.PRESETS)
def test_old_trees_read_back(name):
    assert C.from_json(_old_tree(name)) == C.preset(name)
    # the paper preset's experiment uses the compiled engine: a stored real 'fast' is the same forests
    assert C.from_json(_old_tree(name, engine="sklearn")) == C.preset(name)


def test_old_tree_with_another_value_is_one_line():
    with pytest.raises(C.ConfigError, match=r"'real.experiment.repeats_pca' of this stored tree \(7\) differs from "
                                            r"'experiment.repeats_pca'") as e:
        C.from_json(_old_tree(repeats_pca=7))
    assert "\n" not in str(e.value)


def test_old_run_log_resumes(tmp_path):
    from relaff_jax.reproduce.folder import Paths, open_log

    paths = Paths(tmp_path / "run")
    log = open_log(paths, "tiny", C.preset("tiny"), 0)
    log["config"] = _old_tree()
    paths.log.write_text(json.dumps(log))
    again = open_log(paths, "tiny", C.preset("tiny"), 0)
    assert sorted(again["removed_settings"]) == sorted(f"real.experiment.{k}" for k in SHADOWED)
    log["config"] = _old_tree(bf_sizes=[2, 9])
    paths.log.write_text(json.dumps(log))
    with pytest.raises(UserError, match="real.experiment.bf_sizes"):
        open_log(paths, "tiny", C.preset("tiny"), 0)
