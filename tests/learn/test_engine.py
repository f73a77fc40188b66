"""The fast and compiled forest engines against RandomForestClassifier: the same trees,
bit-identical predict_proba and classes (relaff_jax.learn.forest: engine, fit, evaluate,
relaff_jax.learn.forest.compiled)."""
import contextlib
import inspect

import numpy as np
import pytest
import sklearn
from sklearn.ensemble import RandomForestClassifier

from relaff_jax import learn as L
from relaff_jax.config.experiment import ForestConfig
from relaff_jax.config import override
from relaff_jax.errors import UserError
from relaff_jax.learn import blocks
from relaff_jax.learn.forest import compiled, engine
from relaff_jax.learn.forest.evaluate import pack_forest, predict_block, predict_labels, predict_proba, round_down_f32
from relaff_jax.learn.forest.fit import fit_trees

SKLEARN_PIN = "1.9.1"


def test_scikit_learn_is_the_pinned_version_and_its_private_api_unchanged():
    """The engine calls scikit-learn's private tree API; an upgrade must fail here first."""
    assert sklearn.__version__ == SKLEARN_PIN, (
        f"scikit-learn {sklearn.__version__} is installed, the engine was checked against {SKLEARN_PIN}: "
        "re-read sklearn/ensemble/_forest.py and sklearn/tree/_classes.py, update learn/forest/fit.py and the pin")
    from sklearn.ensemble import _base, _bootstrap, _forest
    from sklearn.tree import _classes
    from sklearn.tree._criterion import Gini
    from sklearn.tree._splitter import BestSplitter
    from sklearn.tree._tree import DepthFirstTreeBuilder, Tree

    sig = lambda f: list(inspect.signature(f).parameters)  # noqa: E731
    assert sig(_forest._generate_sample_indices) == ["random_state", "n_samples", "n_samples_bootstrap", "sample_weight"]
    assert sig(_forest._parallel_build_trees)[:5] == ["tree", "bootstrap", "X", "y", "sample_weight"]
    assert sig(_bootstrap._get_n_samples_bootstrap) == ["n_samples", "max_samples", "sample_weight"]
    assert _forest.MAX_INT == np.iinfo(np.int32).max
    assert "random_state.randint(np.iinfo(np.int32).max)" in inspect.getsource(_base._set_random_states)
    assert "random_instance.randint(0, n_samples, n_samples_bootstrap)" in inspect.getsource(_forest._generate_sample_indices)
    src = inspect.getsource(_classes.BaseDecisionTree._fit)
    assert "DepthFirstTreeBuilder(" in src
    assert "min_samples_split = max(min_samples_split, 2 * min_samples_leaf)" in src
    # the Cython constructors take what forest.fit passes
    crit = Gini(1, np.array([2], dtype=np.intp))
    split = BestSplitter(crit, 1, 1, 0.0, np.random.RandomState(0), None)
    DepthFirstTreeBuilder(split, 2, 1, 0.0, 200, 0.0).build(
        Tree(2, np.array([2], dtype=np.intp), 1), np.asfortranarray(np.eye(2, dtype=np.float32)),
        np.array([[0.0], [1.0]]), np.ones(2))


def test_tree_seeds_are_the_forests():
    X = np.random.default_rng(0).normal(size=(30, 18)).astype(np.float32)
    y = X[:, 0] > 0
    for seed in (0, 5, 2**31 - 2):
        ref = L.fit_forest(X, y, seed)
        rs = np.random.RandomState(seed)
        assert [e.random_state for e in ref.estimators_] == [rs.randint(np.iinfo(np.int32).max) for _ in ref.estimators_]


def test_round_down_f32_is_the_largest_float32_not_above():
    t = np.array([0.1, -0.1, 1.0, 0.5 * (np.float32(0.1) + np.nextafter(np.float32(0.1), np.float32(1))), 3.4e38, -3.4e38, 1e-45])
    r = round_down_f32(t)
    assert r.dtype == np.float32
    assert np.all(r.astype(np.float64) <= t)
    assert np.all(np.nextafter(r, np.float32(np.inf)).astype(np.float64) > t)
    assert r[2] == 1.0


def _data(n, d, seed, kind="plain"):
    rng = np.random.default_rng(1000 * n + d + seed)
    X = rng.normal(size=(n, d)).astype(np.float32)
    y = X[:, 0] + 0.5 * X[:, 1] + 0.3 * rng.normal(size=n) > 0
    if kind == "one_class":
        y = np.ones(n, bool)
    elif kind == "duplicates":  # repeated rows, some with the other label: impure leaves
        k = max(1, n // 3)
        X[-k:] = X[:k]
        y[-k:] = ~y[:k]
    elif kind == "constant":
        X[:, ::2] = 1.5
    elif kind == "ties":  # equal values, and values apart by less than FEATURE_THRESHOLD (1e-7)
        X = np.round(X, 1)
        X[:, 1] = np.float32(0.01) + rng.integers(0, 3, n).astype(np.float32) * np.float32(5e-8)
        X[:, 2] = np.float32(0.01) + rng.integers(0, 2, n).astype(np.float32) * np.float32(2e-7)
    elif kind == "binary":  # two-valued columns (bootstrap inputs), the compiled engine's own path
        b = (X[:, 0] + rng.normal(size=n) > 0).astype(np.float32)
        X[:, 4:10] = b[:, None]  # one 0/1 input repeated, as states.augment does
        X[:, 10] = np.where(b > 0, np.float32(-0.0), np.float32(0.0))  # two bit patterns, one value: constant
        X[:, 11] = np.where(rng.random(n) < 0.3, np.float32(-2.5), np.float32(-7.0))  # lower value second
        X[:, 12] = np.float32(3.0) + b * np.float32(5e-8)  # apart by less than FEATURE_THRESHOLD: constant
        X[:, 13] = np.where(rng.random(n) < 0.5, np.float32(0.0), np.float32(-0.0)) - b  # -1, -0 and 0: two values
    return X, y


def _test_rows(X, forest_trees, m, seed):
    """Random rows, the training rows, and rows sitting on the trees' thresholds (rounded
    to float32 and one float32 step either side): where float32/float64 matter."""
    rng = np.random.default_rng(seed)
    d = X.shape[1]
    rows = [rng.normal(size=(m, d)).astype(np.float32), X]
    for tree in forest_trees[:5]:
        inner = np.flatnonzero(tree.children_left != -1)[:8]
        for i in inner:
            t32 = np.float32(tree.threshold[i])
            for v in (t32, np.nextafter(t32, np.float32(-np.inf)), np.nextafter(t32, np.float32(np.inf))):
                r = X[rng.integers(len(X))].copy()
                r[tree.feature[i]] = v
                rows.append(r[None])
    return np.concatenate(rows).astype(np.float32)


def _same_trees(forest, estimators):
    """A compiled ``Forest``'s trees equal the estimators' ``tree_`` arrays (compared for
    the whole forest at once; tree by tree when they differ, to name the first)."""
    trees = [e.tree_ for e in estimators]
    assert forest.n_trees == len(trees)
    np.testing.assert_array_equal(np.diff(forest.tree_start), [t.node_count for t in trees])
    cat = {k: np.concatenate([getattr(t, k) for t in trees]) for k in ("feature", "threshold", "children_left",
                                                                       "children_right", "value")}
    got = {"feature": forest.feature, "threshold": forest.threshold, "children_left": forest.left,
           "children_right": forest.right, "value": forest.value[:, None, :]}
    if all(np.array_equal(got[k], cat[k]) for k in cat):
        return
    for t, tree in enumerate(trees):
        mine = forest.tree(t)
        for k in cat:
            np.testing.assert_array_equal(mine[k], getattr(tree, k), err_msg=f"tree {t}: {k}")


def _check(X, y, seed, cfg=ForestConfig(), m=300):
    ref = L.fit_forest(X, y, seed, cfg)
    fast = fit_trees(X, y, seed, cfg)
    comp = compiled.fit(X, y, seed, cfg)
    assert len(fast.trees) == len(ref.estimators_) == L.n_trees(len(y), cfg)
    np.testing.assert_array_equal(fast.classes, ref.classes_)
    np.testing.assert_array_equal(comp.classes, ref.classes_)
    for a, b in zip(ref.estimators_, fast.trees):
        assert a.tree_.node_count == b.node_count
        np.testing.assert_array_equal(a.tree_.feature, b.feature)
        np.testing.assert_array_equal(a.tree_.threshold, b.threshold)
        np.testing.assert_array_equal(a.tree_.value, b.value)
    _same_trees(comp, ref.estimators_)
    Xt = _test_rows(X, fast.trees, m, seed)
    p_ref = ref.predict_proba(Xt)
    assert np.array_equal(predict_proba(fast, Xt), p_ref)  # bit for bit, not approx
    assert np.array_equal(compiled.predict_proba(comp, Xt), p_ref)
    labels = ref.predict(Xt)
    np.testing.assert_array_equal(predict_labels(fast, Xt), labels)
    np.testing.assert_array_equal(predict_block([fast], Xt.T, [np.arange(X.shape[1])])[0], labels)
    np.testing.assert_array_equal(engine.predict(fast, Xt), labels.astype(np.float32))
    np.testing.assert_array_equal(engine.predict(comp, Xt), labels.astype(np.float32))  # compiled.predict_block
    return fast


# fast tier: every n and every feature count at least once (the slow test runs the whole grid)
FAST_GRID = [(2, 18), (3, 318), (10, 24), (25, 18), (25, 348), (100, 318), (100, 18), (400, 24)]


@pytest.mark.parametrize("n, d", FAST_GRID)
def test_same_forest_and_predictions_as_sklearn(n, d):
    _check(*_data(n, d, 0), seed=n + d)


@pytest.mark.parametrize("kind, n", [("one_class", 2), ("one_class", 25), ("duplicates", 25), ("duplicates", 100),
                                     ("constant", 3), ("constant", 25), ("ties", 25), ("ties", 100),
                                     ("binary", 2), ("binary", 25), ("binary", 100), ("binary", 400)])
def test_edge_cases_match_sklearn(kind, n):
    fast = _check(*_data(n, 24, 1, kind), seed=7)
    if kind == "one_class":
        assert len(fast.classes) == 1
        assert pack_forest(fast) is None
    if kind == "duplicates" and n >= 25:
        assert pack_forest(fast) is None  # impure leaves: the exact float64 path


def test_large_n_nodes_between_the_sort_paths():
    """N = 1000 (16 bitmap words, kept in memory): nodes of m <= 12 samples (insertion sort),
    12 < m < 16 (insertion sort: the bitmap would be longer than the node) and m >= 16
    (bitmap) in the same trees, with ties."""
    _check(*_data(1000, 3, 0, "ties"), seed=5, cfg=override(ForestConfig(), {"base_trees": 4, "max_trees": 4}), m=100)


@pytest.mark.parametrize("cfg", [
    {"max_samples": 2 / 3}, {"max_samples": 0.05}, {"bootstrap": False},
    {"base_trees": 3, "max_trees": 7, "samples_per_extra_tree": 5}, {"min_samples_leaf": 3},
    {"max_depth": 2}, {"max_features": "log2"}, {"max_features": "0.5"}, {"max_features": "6"},
    {"max_features": None}, {"per_tree": "subsample"}, {"per_tree": "subsample", "min_samples_leaf": 3},
])
def test_parameters_match_sklearn(cfg):
    # 0.05 x 40 = 2 draws per tree: scikit-learn warns, and so does the engine
    with pytest.warns(UserWarning) if cfg.get("max_samples") == 0.05 else contextlib.nullcontext():
        _check(*_data(40, 24, 2), seed=3, cfg=override(ForestConfig(), cfg))


@pytest.mark.parametrize("kind, n", [("plain", 2), ("plain", 3), ("ties", 25), ("plain", 100), ("one_class", 10)])
def test_subsample_reading_matches_sklearn(kind, n):
    """The 2/3 subsample without replacement: the same trees in every engine."""
    _check(*_data(n, 24, 4, kind), seed=11, cfg=override(ForestConfig(), {"per_tree": "subsample"}))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["plain", "one_class", "duplicates", "constant", "binary"])
@pytest.mark.parametrize("d", [18, 24, 318, 348])
@pytest.mark.parametrize("n", [2, 3, 10, 25, 100, 400])
def test_full_grid_several_seeds(n, d, kind):
    for seed in (0, 1, 12345):
        _check(*_data(n, d, seed, kind), seed=seed * 7 + n, m=1000)


def test_block_of_many_forests_with_shared_columns():
    """predict_block over forests of different sizes and feature maps = each forest alone."""
    rng = np.random.default_rng(3)
    Z = rng.normal(size=(400, 30)).astype(np.float32)
    forests, maps, refs = [], [], []
    for i, n in enumerate([2, 5, 25, 60, 100, 25, 3, 40, 80, 10]):
        cols = rng.choice(30, size=12, replace=False)
        X = rng.normal(size=(n, 12)).astype(np.float32)
        y = X[:, 0] > 0 if i != 6 else np.zeros(n, bool)
        forests.append(fit_trees(X, y, i))
        maps.append(cols)
        refs.append(L.fit_forest(X, y, i).predict(Z[:, cols]))
    got = predict_block(forests, Z.T, maps, chunk=4)
    for g, r in zip(got, refs):
        np.testing.assert_array_equal(g, r)


def test_run_block_same_accuracies_with_both_engines(monkeypatch):
    rng = np.random.default_rng(0)
    m = 500
    X = rng.normal(size=(m, 18)).astype(np.float32)
    y = X[:, 0] + X[:, 1] > 0
    boot = (rng.random((4, m)) < 0.5).astype(np.float32)
    boot[3] = np.nan  # a row this space did not compute: unused, so harmless
    plan = [(0, ()), (1, (0,)), (2, (1,)), (3, (0, 1, 2)), (4, (0,))]
    args = (X, y, boot, plan, np.arange(400, 430), np.arange(400), [2, 4, 25], 6, 6)
    ref = blocks.run_block(*args, ForestConfig(engine="sklearn"), (1, 2))
    got = blocks.run_block(*args, ForestConfig(engine="fast"), (1, 2))
    assert np.array_equal(ref, got, equal_nan=True)
    assert np.isnan(got[5]).all()
    assert np.array_equal(got[4], got[1])
    kw = dict(loo_size=25, loo_conditions=(1, 2, 3))  # the leave-one-out forests too
    fast = blocks.block_outcomes(*args, ForestConfig(engine="fast"), (1, 2), **kw)
    comp = blocks.block_outcomes(*args, ForestConfig(engine="compiled"), (1, 2), **kw)
    assert np.array_equal(comp["acc"], ref, equal_nan=True)
    for k in fast:
        assert np.array_equal(fast[k], comp[k], equal_nan=True), k


def test_engine_setting():
    from relaff_jax import config as runconfig

    assert ForestConfig().engine == "fast"
    cfg = runconfig.resolve(None, {"experiment.forest.engine": "sklearn"}).experiment.forest
    assert isinstance(engine.fit(np.eye(3, dtype=np.float32), np.array([0, 1, 1]), 0, cfg), RandomForestClassifier)
    cfg = runconfig.resolve(None, {"experiment.forest.engine": "compiled"}).experiment.forest
    L.check_forest_config(cfg)
    assert isinstance(engine.fit(np.eye(3, dtype=np.float32), np.array([0, 1, 1]), 0, cfg), compiled.Forest)
    with pytest.raises(UserError, match="config key 'experiment.forest.engine' must be one of fast, sklearn, compiled, got 'turbo'"):  # refused when the node is made
        ForestConfig(engine="turbo")
    turbo = ForestConfig()
    object.__setattr__(turbo, "engine", "turbo")  # past the node's check: the engine refuses it too
    with pytest.raises(UserError, match="forest engine 'turbo'"):
        engine.fit(np.eye(3, dtype=np.float32), np.array([0, 1, 1]), 0, turbo)
    for eng in ("fast", "compiled"):
        with pytest.raises(ValueError, match="NaN"):
            engine.fit(np.full((3, 2), np.nan, np.float32), np.array([0, 1, 1]), 0, engine=eng)
    X = np.eye(3, dtype=np.float32)
    with pytest.raises(ValueError, match="2\\*\\*32"):
        compiled.fit(X, np.array([0, 1, 1]), 2**32)
    with pytest.raises(ValueError, match="3 classes"):
        compiled.fit(X, np.array([0, 1, 2]), 0)
    with pytest.raises(ValueError, match="max_features"):
        compiled.fit(X, np.array([0, 1, 1]), 0, ForestConfig(max_features="5"))
    with pytest.raises(ValueError, match="gini"):
        compiled.fit(X, np.array([0, 1, 1]), 0, ForestConfig(criterion="entropy"))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        compiled.predict_proba(compiled.fit(X, np.array([0, 1, 1]), 0), np.eye(2, dtype=np.float32))


@pytest.mark.parametrize("eng", ["fast", "compiled", "sklearn"])
def test_an_input_error_names_the_function_called(eng):
    """One input check (forests.checked_inputs / checked_states) for every engine, its message
    naming the function the caller called, not another one."""
    X, y = np.eye(3, dtype=np.float32), np.array([0, 1, 1])
    bad = np.full((3, 2), np.nan, np.float32)
    with pytest.raises(ValueError, match=r"^engine\.fit: X contains NaN"):
        engine.fit(bad, y, 0, engine=eng)
    with pytest.raises(ValueError, match=r"^engine\.fit_many: forest 1: X must be \(N, D\) and y \(N,\)"):
        engine.fit_many([X, X], [y, y[:2]], [0, 1], engine=eng)
    forest = engine.fit(X, y, 0, engine=eng)
    with pytest.raises(ValueError, match=r"^engine\.predict: X contains NaN"):
        engine.predict(forest, np.full((2, 3), np.inf, np.float32))
    with pytest.raises(ValueError, match=r"^engine\.predict_many: ZT contains NaN"):
        engine.predict_many([forest], np.full((3, 2), np.nan, np.float32), [np.arange(3)])
    with pytest.raises(ValueError, match=r"^fit_forest: X contains NaN"):  # the estimator's own entry
        L.fit_forest(bad, y, 0)
    with pytest.raises(ValueError, match=r"^predict_class: X contains NaN"):
        L.predict_class(L.fit_forest(X, y, 0), np.full((2, 3), np.nan, np.float32))


def test_compiled_random_streams_are_numpys_and_sklearns():
    """rng.py: legacy MT19937 seeding and masked randint as numpy's RandomState, rand_r as
    scikit-learn's our_rand_r, the splitter seed peeked without a second seeding."""
    from sklearn.utils._random import _our_rand_r_py

    from relaff_jax.learn.forest.compiled import rng

    mt = np.zeros(625, np.int64)
    for seed in (0, 1, 12345, 2**31 - 2, 2**32 - 1):
        rng.mt_seed(mt, seed)
        assert [rng.randint(mt, 0, rng.MAX_INT) for _ in range(700)] == list(
            np.random.RandomState(seed).randint(rng.MAX_INT, size=700))  # crosses a 624-word block
        for high in (1, 2, 3, 25, 100, 4000):
            rng.mt_seed(mt, seed)
            assert [rng.randint(mt, 0, high) for _ in range(50)] == list(np.random.RandomState(seed).randint(0, high, 50))
        rng.mt_seed(mt, seed)
        assert rng.first_randint(mt, 0, rng.RAND_R_MAX) == np.random.RandomState(seed).randint(0, rng.RAND_R_MAX)
        assert rng.randint(mt, 0, 7) == np.random.RandomState(seed).randint(0, 7)  # the peek consumed nothing
    mts, one = np.zeros((4, 625), np.int64), np.zeros(625, np.int64)
    seeds = (0, 12345, 2**31 - 2, 2**32 - 1)
    rng.mt_seed4(mts, *seeds)  # four streams seeded together = each seeded alone
    for g, seed in enumerate(seeds):
        rng.mt_seed(one, seed)
        np.testing.assert_array_equal(mts[g], one)
        for n, draws in ((1, 5), (2, 30), (25, 25), (100, 700)):  # 700 draws cross a 624-word block
            rng.mt_seed(one, seed)
            rng.first_randint(one, 0, rng.RAND_R_MAX)  # as build_forests: the peek, then the bootstrap
            wt = np.zeros(n)
            rng.draw_bootstrap(one, wt, n, draws)
            np.testing.assert_array_equal(wt, np.bincount(np.random.RandomState(seed).randint(0, n, draws), minlength=n))
            if n > 1:  # the stream's position is left where randint's would be
                assert rng.randint(one, 0, n) == np.random.RandomState(seed).randint(0, n, draws + 1)[-1]
    for s in (0, 1, 12345, 2**31 - 1, 2**32 - 1):
        state = np.array([s], np.int64)
        assert rng.rand_r(state) == _our_rand_r_py(s)
    assert rng.rand_r(np.array([0], np.int64)) == rng.rand_r(np.array([1], np.int64))  # a zero state is 1


def test_compiled_gini_filter_passes_every_candidate_that_wins():
    """split.may_win (a candidate's Gini divisions are skipped when it cannot beat the best)
    never skips a candidate whose computed proxy is above the best one, checked against the
    closest such best: one float64 step below the candidate's own proxy."""
    from relaff_jax.learn.forest.compiled import split

    rng = np.random.default_rng(0)
    counts = np.concatenate([rng.integers(0, 120, (3000, 4)), rng.integers(0, 20000, (3000, 4))]).astype(float)
    for l0, l1, r0, r1 in counts:
        wl, wr = l0 + l1, r0 + r1
        if wl == 0 or wr == 0:
            continue
        gl, gr = split.gini_pair(l0, l1, l0 + r0, l1 + r1, wl, wr)
        proxy = -wr * gr - wl * gl  # as best_split computes it
        best = np.nextafter(proxy, -np.inf)
        assert split.may_win(l0, l1, r0, r1, wl, wr, split.cut_of(best, wl + wr)), (l0, l1, r0, r1)


def test_compiled_many_forests_per_call_and_large_trees():
    """fit_many over forests of different sizes and widths = each forest alone; trees with
    more than 64 leaves (the node walk of evaluate.py) predict as scikit-learn's."""
    rng = np.random.default_rng(5)
    sets = [(rng.normal(size=(n, d)).astype(np.float32), s) for s, (n, d) in enumerate([(25, 24), (25, 348), (3, 5), (25, 7)])]
    data = [(X, X[:, 0] + 0.5 * rng.normal(size=len(X)) > 0, s) for X, s in sets]
    many = compiled.fit_many([d[0] for d in data], [d[1] for d in data], [d[2] for d in data])
    for f, (X, y, s) in zip(many, data):
        one = compiled.fit(X, y, s)
        for k in ("feature", "threshold", "left", "right", "value", "tree_start"):
            np.testing.assert_array_equal(getattr(f, k), getattr(one, k))
    X = rng.normal(size=(400, 6)).astype(np.float32)
    y = rng.random(400) < 0.5  # noise: deep trees
    comp, ref = compiled.fit(X, y, 3), L.fit_forest(X, y, 3)
    leaves = np.diff(comp.tree_start) - np.add.reduceat(comp.left != -1, comp.tree_start[:-1])
    assert leaves.max() > 64
    Xt = rng.normal(size=(500, 6)).astype(np.float32)
    assert np.array_equal(compiled.predict_proba(comp, Xt), ref.predict_proba(Xt))
    np.testing.assert_array_equal(compiled.predict_labels(comp, Xt), ref.predict(Xt))
    got = engine.predict_many([comp, compiled.fit(X[:30], y[:30], 4)], Xt.T, [np.arange(6)] * 2)
    np.testing.assert_array_equal(got[0], ref.predict(Xt).astype(np.float32))
