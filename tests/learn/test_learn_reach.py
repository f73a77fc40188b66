"""What a learner relies on: derived and partial states, forest.max_features as a
number, accuracies by test subset, predictor correlations with reach and relation. Each is
checked against a hand-worked case or numpy."""
from __future__ import annotations

import numpy as np
import pytest

from relaff_jax.config.experiment import ExperimentConfig, ForestConfig
from relaff_jax.learn.checks import check_config
from relaff_jax.config import override
from relaff_jax.errors import UserError
from relaff_jax.learn import blocks
from relaff_jax.learn.correlation import correlation_with
from relaff_jax.config.experiment import max_features_value
from relaff_jax.config.experiment import RHF_PARTS, StateConfig
from relaff_jax.learn.states import state_features, state_width
from relaff_jax.learn.sweep import subset_codes as subsets_of
from relaff_jax.config.perception import RHF_NAMES


def _pca():
    pca = np.zeros((2, 18), np.float32)
    pca[0, :3] = [0.3, 0.4, 0.10]  # toy
    pca[0, 9:12] = [0.6, 0.0, 0.05]  # other
    pca[1, :3] = [1.0, 0.0, 0.0]
    pca[1, 9:12] = [1.0, 0.0, 0.0]
    pca[:, 3:9] = 7.0  # not a centroid: must not enter the derived columns
    return pca


def test_derived_columns_hand_worked():
    pca = _pca()
    x = state_features(pca, None, "lift", "pca", StateConfig(extra=("relative", "reach")))
    assert x.shape == (2, 24) == (2, state_width("pca", StateConfig(extra=("relative", "reach"))))
    np.testing.assert_array_equal(x[:, :18], state_features(pca, None, "lift", "pca"))  # the paper's state first
    # toy - other = (-0.3, 0.4, 0.05), planar 0.5; toy 0.5 from the robot, other 0.6
    np.testing.assert_allclose(x[0, 18:], [-0.3, 0.4, 0.05, 0.5, 0.5, 0.6], rtol=1e-6)
    np.testing.assert_allclose(x[1, 18:], [0, 0, 0, 0, 1, 1], atol=1e-7)
    # the extra columns do not depend on the action's order (toy minus other always)
    np.testing.assert_array_equal(state_features(pca, None, "take", "pca", StateConfig(extra=("relative",)))[:, 18:],
                                  x[:, 18:22])


def test_rhf_parts_and_bins_only():
    assert RHF_PARTS == RHF_NAMES  # the order the perception stage writes its histograms in
    pca = _pca()
    rhf = np.arange(600, dtype=np.float32).reshape(2, 300)
    full = state_features(pca, rhf, "lift", "rhf")
    assert full.shape == (2, 318)
    only = state_features(pca, rhf, "lift", "rhf", StateConfig(rhf_pca=False))
    np.testing.assert_array_equal(only, rhf)
    part = state_features(pca, rhf, "lift", "rhf", StateConfig(rhf_pca=False, rhf_parts=("dist", "dx")))
    np.testing.assert_array_equal(part, np.concatenate([rhf[:, 150:200], rhf[:, 0:50]], axis=1))
    assert state_width("rhf", StateConfig(rhf_pca=False, rhf_parts=("dist", "dx"))) == 100
    with pytest.raises(UserError, match="rhf_parts' must be a list of at least 1 values, distinct"):
        StateConfig(rhf_parts=("dist", "height"))
    with pytest.raises(UserError, match="extra' must be a list of values, distinct"):
        StateConfig(extra=("relative", "relative"))
    with pytest.raises(UserError, match="'experiment.state.extra' must be a list of values, distinct"):
        check_config(override(ExperimentConfig(), {"state.extra": ("reach", "colour")}))


def test_max_features_strings():
    assert [max_features_value(v) for v in ("sqrt", "log2", None, "6", "0.5")] == ["sqrt", "log2", None, 6, 0.5]
    with pytest.raises(UserError, match="'experiment.forest.max_features' must be one of sqrt, log2"):
        override(ExperimentConfig(), {"forest.max_features": "most"})  # refused when the node is made


def test_correlation_with_matches_numpy():
    rng = np.random.default_rng(0)
    out = (rng.random((4, 200)) < 0.4).astype(float)
    x = (rng.random(200) < 0.5) | (out[0] > 0)
    got = correlation_with(out, x)
    want = [np.corrcoef(o, x)[0, 1] for o in out]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    out[2] = 1.0  # a constant predictor has no correlation
    assert np.isnan(correlation_with(out, x)[2])
    assert np.isnan(correlation_with(out, np.full(200, np.nan))).all()


def test_subset_accuracy_hand_worked():
    # 6 test scenes: 2 positives, 3 feasible negatives, 1 infeasible negative
    subset = np.array([0, 0, 1, 1, 1, 2])
    correct = np.array([[[1, 0, 1, 1, 0, 1]], [[0, 0, 0, 0, 0, 0]]], bool)  # (C=2, S=1, T=6)
    got = blocks.subset_accuracy(correct, subset)
    np.testing.assert_allclose(got[0, 0], [0.5, 2 / 3, 1.0])
    np.testing.assert_allclose(got[1, 0], [0.0, 0.0, 0.0])
    assert np.isnan(blocks.subset_accuracy(correct, np.array([0, 0, -1, -1, -1, -1]))[0, 0, 1:]).all()
    ds = {"label": np.array([1, 0, 0, 1, 0], bool), "feasible": np.array([1, 1, 0, 1, 0], bool)}
    np.testing.assert_array_equal(subsets_of(ds, np.array([4, 0, 1, 2])), [2, 0, 1, 2])
    np.testing.assert_array_equal(subsets_of({"label": ds["label"]}, np.array([0, 1])), [0, -1])


def test_block_file_holds_subset_accuracies(tmp_path):
    rng = np.random.default_rng(1)
    X = rng.normal(size=(60, 5)).astype(np.float32)
    y = X[:, 0] > 0
    boot = np.zeros((1, 60), np.float32)
    test_idx, order = np.arange(40, 60), np.arange(40)
    subset = np.where(y[test_idx], 0, np.where(np.arange(20) % 2, 1, 2))
    cfg = override(ForestConfig(), {"base_trees": 5, "max_trees": 5})
    out = blocks.run_block_to_file(str(tmp_path / "b.npz"), X, y, boot, [(0, ())], order, test_idx, [10, 20], 1, 2,
                                   cfg, (0, 1), keep_outcomes=False, subset=subset)
    back = blocks.read_block(tmp_path / "b.npz", 2, [10, 20])
    np.testing.assert_array_equal(back["acc_subset"], out["acc_subset"])
    assert back["correct"].shape[-1] == 0  # outcomes not kept, the breakdown is
    # each subset's accuracy weighted by its size is the accuracy
    counts = np.bincount(subset, minlength=3)
    np.testing.assert_allclose((out["acc_subset"][0] * counts).sum(-1) / 20, out["acc"][0])
    assert np.isnan(out["acc_subset"][1]).all()  # condition 1 did not run
