"""Forests, state spaces, bootstrap inputs and the correlation heuristic (relaff_jax.learn)."""
import math

import numpy as np
import pytest
from sklearn.ensemble import RandomForestClassifier

from relaff_jax import learn as L
from relaff_jax.config.experiment import ForestConfig
from relaff_jax.config import override


@pytest.mark.parametrize("n, trees", [(2, 95), (19, 95), (20, 96), (25, 96), (100, 100), (399, 114), (400, 115), (2000, 115)])
def test_tree_count_follows_paper(n, trees):
    assert L.n_trees(n) == trees
    assert L.make_forest(n, seed=0).n_estimators == trees


def test_forest_parameters_are_the_papers():
    f = L.make_forest(50, seed=3)
    p = f.get_params()
    assert p["criterion"] == "gini"
    assert p["max_depth"] == 200
    assert p["min_samples_leaf"] == 1
    assert p["max_features"] == "sqrt"
    assert p["bootstrap"] is True
    assert p["max_samples"] is None  # N draws with replacement (~63 % distinct)
    assert p["n_jobs"] == 1
    assert p["random_state"] == 3


def test_fitted_forest_matches_plain_sklearn_and_tries_sqrt_m_features():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 24)).astype(np.float32)
    y = X[:, 0] + 0.3 * rng.normal(size=40) > 0
    f = L.fit_forest(X, y, seed=11)
    assert len(f.estimators_) == 97  # 95 + 40 // 20
    assert all(t.max_features_ == math.isqrt(24) for t in f.estimators_)  # m = floor(sqrt(M)) = 4
    assert all(t.get_depth() <= 200 for t in f.estimators_)
    ref = RandomForestClassifier(n_estimators=97, criterion="gini", max_depth=200, min_samples_leaf=1,
                                 max_features="sqrt", bootstrap=True, random_state=11).fit(X, y)
    Xt = rng.normal(size=(200, 24)).astype(np.float32)
    np.testing.assert_array_equal(L.predict_class(f, Xt), ref.predict(Xt).astype(np.float32))


def test_max_samples_reading_is_a_parameter():
    cfg = override(ForestConfig(), {"max_samples": 2 / 3})
    assert L.make_forest(30, 0, cfg).max_samples == pytest.approx(2 / 3)


def test_single_class_training_predicts_that_class():
    f = L.fit_forest(np.zeros((2, 18)), np.array([True, True]), seed=0)
    np.testing.assert_array_equal(L.predict_class(f, np.ones((3, 18))), [1, 1, 1])


@pytest.mark.parametrize("action", L.ACTIONS)
def test_state_puts_manipulated_object_first(action):
    rng = np.random.default_rng(1)
    pca = rng.normal(size=(4, 18)).astype(np.float32)
    rhf = rng.random(size=(4, 300)).astype(np.float32)
    s = L.state_features(pca, rhf, action, "pca")
    toy, other = pca[:, :9], pca[:, 9:]
    first, second = (toy, other) if action in ("move", "take") else (other, toy)
    np.testing.assert_array_equal(s[:, :9], first)
    np.testing.assert_array_equal(s[:, 9:], second)
    r = L.state_features(pca, rhf, action, "rhf")
    assert r.shape == (4, 318)
    assert r.dtype == np.float32
    np.testing.assert_array_equal(r[:, :18], s)
    np.testing.assert_array_equal(r[:, 18:], rhf)
    np.testing.assert_array_equal(L.state_features(pca, None, None, "pca"), pca)  # canonical (categories)


def test_state_features_errors_name_the_problem():
    pca = np.zeros((3, 18))
    with pytest.raises(ValueError, match="unknown action 'throw'"):
        L.state_features(pca, None, "throw", "pca")
    with pytest.raises(ValueError, match="unknown state space"):
        L.state_features(pca, None, "lift", "depth")
    with pytest.raises(ValueError, match=r"pca features must be \(N, 18\)"):
        L.state_features(np.zeros((3, 17)), None, "lift", "pca")
    with pytest.raises(ValueError, match="rhf features must be"):
        L.state_features(pca, np.zeros((2, 300)), "lift", "rhf")
    with pytest.raises(ValueError, match="needs the rhf"):
        L.state_features(pca, None, "lift", "rhf")


def test_augment_repeats_each_input():
    X = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    out = np.array([[1, 0, 1], [0, 0, 1]])
    a = L.augment(X, out, 3)
    expect = np.array([[1, 2, 1, 1, 1, 0, 0, 0], [3, 4, 0, 0, 0, 0, 0, 0], [5, 6, 1, 1, 1, 1, 1, 1]], dtype=np.float32)
    np.testing.assert_array_equal(a, expect)
    assert L.augment(np.zeros((5, 18)), np.zeros((1, 5)), 6).shape == (5, 24)  # paper: 24 PCA dims
    assert L.augment(np.zeros((5, 318)), np.zeros((1, 5)), 30).shape == (5, 348)  # 348 RHF dims
    np.testing.assert_array_equal(L.augment(X, np.zeros((0, 3)), 6), X)


def test_category_pairs():
    pairs = L.category_pairs()
    assert len(pairs) == 36
    assert pairs[0] == (0, 1)
    assert pairs[-1] == (7, 8)
    assert len(set(pairs)) == 36
    assert all(i < j for i, j in pairs)


def test_correlation_matrix_matches_numpy_and_handles_constant_outputs():
    rng = np.random.default_rng(2)
    o = (rng.random((4, 500)) < 0.5).astype(np.float32)
    o[1] = np.where(rng.random(500) < 0.8, o[0], 1 - o[0])
    np.testing.assert_allclose(L.correlation_matrix(o), np.corrcoef(o), atol=1e-12)
    o[3] = 1.0
    c = L.correlation_matrix(o)
    assert c[3, 3] == 1.0
    assert np.all(c[3, :3] == 0)
    assert np.all(c[:3, 3] == 0)


def test_categories_above_threshold():
    corr = np.array([[1, 0.6, -0.3], [0.6, 1, 0.1], [-0.3, 0.1, 1]])
    pairs = L.category_pairs(range(3))  # (0,1) (0,2) (1,2)
    np.testing.assert_array_equal(L.categories_above(corr, pairs, 0.0), [True, True, True])  # no heuristic
    np.testing.assert_array_equal(L.categories_above(corr, pairs, 0.05), [True, False, True])
    np.testing.assert_array_equal(L.categories_above(corr, pairs, 0.125), [True, False, False])
    np.testing.assert_array_equal(L.categories_above(corr, pairs, 0.6), [False, False, False])  # strictly above


def test_synthetic_datasets_have_the_dataset_layout_and_are_reproducible():
    d = L.synthetic_datasets(200, seed=4, actions=("lift", "take"))
    for a in ("lift", "take"):
        x = d[a]
        assert x["action"] == a
        assert x["pca"].shape == (200, 18)
        assert x["pca"].dtype == np.float32
        assert x["rhf"].shape == (200, 300)
        assert x["label"].dtype == bool
        assert x["label"].mean() == 0.5
        for k in ("relation", "cog_distance", "toy", "other", "unseen"):
            assert len(x[k]) == 200
    e = L.synthetic_datasets(200, seed=4, actions=("lift", "take"))
    np.testing.assert_array_equal(d["take"]["pca"], e["take"]["pca"])
    assert not np.array_equal(d["lift"]["pca"], d["take"]["pca"])  # each action has its own scenes
