"""The paper's open choices as readings: each reading changes what it should and
nothing else; the extra statistics on hand-worked cases."""
import numpy as np
import pytest

from relaff_jax import learn as L
from relaff_jax.learn.sweep import run_experiment
from relaff_jax.config.experiment import ForestConfig
from helpers.experiments import synthetic3, tiny_cfg


@pytest.fixture(scope="module")
def data3():
    return synthetic3()


def test_dbn_repeats_changes_dbn_and_nothing_else(data3, tmp_path):
    runs = {}
    for reading in ("same", "once"):
        cfg = tiny_cfg(dbn_repeats=reading)
        runs[reading] = np.load(run_experiment(data3, tmp_path / reading, cfg, ["pca"], seed=2, jobs=1,
                                                 progress=False)["pca"])
    lay = L.layout(3, len(tiny_cfg().thresholds))
    dbn = lay["DBn"]
    same, once = runs["same"], runs["once"]
    others = [c for c in range(lay["n"]) if c != dbn]
    np.testing.assert_array_equal(same["acc"][:, others], once["acc"][:, others])
    np.testing.assert_array_equal(same["correct"][:, others], once["correct"][:, others])
    assert not np.array_equal(same["correct"][:, dbn], once["correct"][:, dbn])  # 12 inputs against 2
    np.testing.assert_array_equal(same["corr"], once["corr"])


def test_dbn_repeats_learner_count(data3):
    cfg = tiny_cfg(dbn_repeats="once")
    # with two actions DBn's one input is DB1's: the same learner only where it is repeated as often
    plan = L.condition_plan(["lift", "pull"], 0, np.eye(2), cfg, "pca")
    from relaff_jax.learn.protocol import condition_repeats

    assert L.block_fits(plan, 1, repeats=condition_repeats(plan, tiny_cfg(), "pca", 2)) < \
        L.block_fits(plan, 1, repeats=condition_repeats(plan, cfg, "pca", 2))


def test_robustness_rows_hand_worked():
    from relaff_jax.report.robustness import robustness_rows, robustness_table

    def f(fid, verdict, est, lo, hi):
        return {"id": fid, "finding": fid.upper(), "verdict": verdict,
                "claims": [{"estimate": est, "interval": [lo, hi]}]}

    readings = {"a": [f("x", "reproduced", 1.0, 0.9, 1.1), f("y", "reproduced", 2.0, 1.5, 2.5)],
                "b": [f("x", "reproduced", 1.2, 1.0, 1.4), f("y", "undecided at this scale", 1.0, 0.5, 1.5)],
                "c": [f("x", "reproduced", 0.8, 0.7, 0.9), f("y", "not reproduced", 0.2, 0.1, 0.3)]}
    rows = {r["id"]: r for r in robustness_rows(readings)}
    assert rows["x"]["survives"] == "yes"
    assert rows["y"]["survives"] == "no: only in a"
    assert rows["y"]["cells"]["c"] == ("not reproduced", "0.20 [0.10, 0.30]")
    header, body = robustness_table(readings)
    assert header == ["finding", "a", "b", "c", "reproduced in every reading"]
    assert body[1][2] == "**undecided at this scale**: 1.00 [0.50, 1.50]"


# ---------------------------------------------------------------- beyond the paper's statistics


def test_window_area_and_samples_saved_hand_made():
    from relaff_jax.learn import gains as G

    sizes = [2, 4, 10, 25, 50]
    gain = np.array([0.5, 0.1, 0.1, 0.1, 0.0])
    assert G.window_area(gain, sizes, 4, 25) == pytest.approx(0.1 * 21)
    nb = np.array([0.5, 0.6, 0.7, 0.8, 0.9])
    # the bootstrapped learner at n = 10 is at 0.75: NB gets there halfway from 10 to 25
    bl = np.array([0.6, 0.7, 0.75, 0.85, 0.9])
    saved, cens = G.samples_saved(bl, nb, sizes, 10)
    assert saved == pytest.approx(17.5 - 10) and not cens
    # at 0.95 NB never gets there: censored at the largest size (a lower bound)
    saved, cens = G.samples_saved(np.array([0.9, 0.9, 0.95, 0.95, 0.95]), nb, sizes, 10)
    assert saved == pytest.approx(40) and cens
    # no better than NB: NB needs at most as many (here exactly ten, none saved)
    assert G.samples_saved(nb, nb, sizes, 10)[0] == pytest.approx(0)
    # below NB's first size: NB's first size
    assert G.samples_needed(nb, sizes, np.array(0.3))[0] == pytest.approx(2)


def test_stratified_poi_has_the_bits_of_one_resample_at_a_time(monkeypatch):
    # the resamples compared many at once (and in steps: POI_CELLS small) against the loop
    # of probability_of_improvement over the same draws; NaN repetitions, ties, a task without values
    from relaff_jax.learn import gains as G

    rng = np.random.default_rng(7)
    x, y = np.round(rng.random((9, 6)), 1), np.round(rng.random((9, 5)), 1)
    x[2, :2], y[4, 1] = np.nan, np.nan
    x[7], y[8, :] = np.nan, np.nan
    for cells in (G.POI_CELLS, 700):
        monkeypatch.setattr(G, "POI_CELLS", cells)
        got = G.stratified_poi(x, y, 50, np.random.default_rng(3))
        g, rows, want = np.random.default_rng(3), np.arange(9)[:, None], []
        for _ in range(50):
            ix, iy = g.integers(0, 6, (9, 6)), g.integers(0, 5, (9, 5))
            want.append(G.probability_of_improvement(x[rows, ix], y[rows, iy]))
        np.testing.assert_array_equal(got, want)
        assert np.isfinite(got).all() and len(set(got.tolist())) > 10
    x[:], y[:] = np.nan, np.nan  # no task with a value: NaN, as probability_of_improvement
    assert np.isnan(G.stratified_poi(x, y, 4, np.random.default_rng(3))).all()


def test_probability_of_improvement_and_holm_hand_worked():
    from relaff_jax.learn import gains as G

    x = np.array([[0.9, 0.8], [0.5, 0.5]])  # task 0: both above NB's; task 1: tied pairs and one lower
    y = np.array([[0.7, 0.6], [0.5, 0.6]])
    # task 0: 4 of 4 pairs x > y -> 1; task 1: (0.5 vs 0.5 tie, 0.5 < 0.6) twice -> (0.5 + 0 + 0.5 + 0) / 4
    assert G.probability_of_improvement(x, y) == pytest.approx((1.0 + 0.25) / 2)
    # rliable's normalised U statistic on one task
    from scipy.stats import mannwhitneyu

    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 5, 7).astype(float), rng.integers(0, 5, 6).astype(float)
    u = mannwhitneyu(a, b, alternative="greater").statistic / (7 * 6)
    assert G.probability_of_improvement(a[None], b[None]) == pytest.approx(u)
    boot = G.stratified_poi(x, y, 200, np.random.default_rng(1))
    assert boot.shape == (200,) and np.all((boot >= 0) & (boot <= 1))
    assert G.bootstrap_p(np.array([0.6, 0.7, 0.8, 0.4]), 0.5) == pytest.approx(0.5)
    # Holm on 0.01, 0.04, 0.03, 0.2 (m = 4): 0.04, 0.09 (0.03 x 3), 0.09 (0.04 x 2, made monotone), 0.2
    adj, rej = G.holm([0.01, 0.04, 0.03, 0.2], 0.05)
    np.testing.assert_allclose(adj, [0.04, 0.09, 0.09, 0.2])
    assert rej.tolist() == [True, False, False, False]
    adj, rej = G.holm([0.01, np.nan, 0.02], 0.05)
    np.testing.assert_allclose(adj, [0.02, np.nan, 0.02])
    assert rej.tolist() == [True, False, True]


def test_category_labels_changes_the_categories_only(data3, tmp_path):
    from relaff_jax.learn.prep import category_labels

    labels = {"a": np.array([1, 0, 1, 0], bool), "b": np.array([1, 1, 0, 0], bool)}
    src = {"a": np.array([0, 1, 2]), "b": np.array([1, 3])}
    other = {"a": {"b": np.array([1.0, 0.0])}, "b": {"a": np.array([0.0, 1.0, 1.0])}}
    # a's scenes: own (1, 0, 1) with b's predicted (0, 1, 1); b's scenes: own (1, 0) with a's (1, 0)
    assert category_labels(("a", "b"), labels, src, other, "union").tolist() == [1, 0, 1, 1, 0]
    assert category_labels(("a", "b"), labels, src, other, "both").tolist() == [0, 0, 1, 1, 0]
    assert category_labels(("a", "b"), labels, src, other, "either").tolist() == [1, 1, 1, 1, 0]
    runs = {}
    for reading in ("union", "both"):
        cfg = tiny_cfg(category_labels=reading)
        runs[reading] = np.load(run_experiment(data3, tmp_path / reading, cfg, ["pca"], seed=2, jobs=1,
                                                 progress=False)["pca"])
    lay = L.layout(3, len(tiny_cfg().thresholds))
    cats = set(lay["CB1"].tolist()) | set(lay["CBn"].tolist())
    keep = [c for c in range(lay["n"]) if c not in cats]
    u, b = runs["union"], runs["both"]
    np.testing.assert_array_equal(u["acc"][:, keep], b["acc"][:, keep])
    np.testing.assert_array_equal(u["corr"], b["corr"])  # the heuristic reads the source predictors only
    assert not np.array_equal(u["correct"][:, lay["CB1"]], b["correct"][:, lay["CB1"]])


@pytest.mark.parametrize("n", [3, 10, 25, 60])
def test_subsample_trees_are_sklearns_on_the_subsample_alone(n):
    """Each tree of the subsample reading is scikit-learn's DecisionTreeClassifier fitted on
    its 2/3 of the rows alone (bootstrap=False on a subsample): the zero weights leave the
    other rows out of the tree entirely."""
    from sklearn.tree import DecisionTreeClassifier

    from relaff_jax.learn.forest.estimator import subsample_size, subsample_weights

    rng = np.random.default_rng(n)
    X = rng.normal(size=(n, 18)).astype(np.float32)
    y = rng.random(n) < 0.5
    y[:2] = [True, False]
    cfg = ForestConfig(per_tree="subsample", engine="sklearn")
    forest = L.fit_forest(X, y, 5, cfg)
    checked = 0
    for est in forest.estimators_:
        w = subsample_weights(np.random.RandomState(), est.random_state, n)
        assert w.sum() == subsample_size(n) == max(1, 2 * n // 3) and set(np.unique(w)) <= {0.0, 1.0}
        sub = np.flatnonzero(w)
        if len(np.unique(y[sub])) < 2:  # one class: a lone tree would know one class only
            continue
        alone = DecisionTreeClassifier(max_features="sqrt", max_depth=200, random_state=est.random_state).fit(X[sub], y[sub])
        for k in ("feature", "threshold", "children_left", "children_right"):
            np.testing.assert_array_equal(getattr(est.tree_, k), getattr(alone.tree_, k))
        np.testing.assert_array_equal(est.predict(X), alone.predict(X))
        checked += 1
    assert checked >= len(forest.estimators_) // 2
