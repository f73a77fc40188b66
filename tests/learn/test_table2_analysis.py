"""Table II that says what it rests on (undefined cells, n_targets, ties, the online "best
after ten", the accuracy gain, intervals), and balanced and independent draws of the
learning protocol, on hand-worked cases and against scikit-learn and numpy."""
import csv
import io

import numpy as np
import pytest

from relaff_jax import learn as E
from relaff_jax.learn.blocks import block_outcomes
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.config import override
from relaff_jax.report import table2_csv

ACTS = ["lift", "pull", "take"]
LAY = E.layout(3, 3)
SIZES = [2, 4, 10, 25]


def _cfg(**kw):
    return override(ExperimentConfig(), dict({"sizes": tuple(SIZES)}, **kw))


def _res(acc, loo=None):
    cfg = _cfg()
    out = {"acc": acc, "sizes": np.array(SIZES), "actions": np.array(ACTS),
           "conditions": np.array(E.condition_names(ACTS, cfg.thresholds)),
           "category_masks": E.category_masks(np.eye(3), ACTS, cfg)}
    if loo is not None:
        out["loo"] = loo
    return out


def _acc(nb, db1, reps=1):
    """acc (3, C, 4, reps): NB curves ``nb (3, 4)``, DB1 curves ``db1 {(target, source): (4,)}``."""
    acc = np.full((3, LAY["n"], len(SIZES), reps), np.nan)
    acc[:, LAY["NB"]] = np.asarray(nb, dtype=float)[..., None]
    for (t, s), curve in db1.items():
        acc[t, LAY["DB1"][s]] = np.asarray(curve, dtype=float)[..., None]
    return acc


# ------------------------------------------------------------------ undefined cells, n_targets


def test_undefined_cells_are_counted_and_a_target_without_any_is_left_out_and_said():
    # lift: NB above chance at n = 4 and 25 only (10 is at chance: undefined); pull: NB never above chance
    nb = [[0.5, 0.6, 0.5, 0.9], [0.5, 0.5, 0.45, 0.5], [0.5, 0.7, 0.8, 0.9]]
    db1 = {(0, 1): [0.5, 0.7, 0.6, 0.95], (1, 0): [0.5, 0.6, 0.6, 0.6], (2, 0): [0.5, 0.8, 0.8, 0.9]}
    an = E.analyse(_res(_acc(nb, db1)), _cfg(), intervals=False)
    assert list(an["defined"]) == [2, 0, 3]  # window 4..25 holds 3 of the sizes run
    assert an["window_sizes"] == 3
    db1_avg = an["table2_per_target"][E.TABLE2_ROWS.index("DB1 average")]
    # lift: bf(4) = 0.2/0.1 = 2, bf(25) = 0.45/0.4 = 1.125 -> 1.5625; pull: none; take: (1.5 + 1 + 1) / 3
    np.testing.assert_allclose(db1_avg, [1.5625, np.nan, (1.5 + 1 + 1) / 3])
    i = E.TABLE2_ROWS.index("DB1 average")
    assert an["n_targets"][i] == 2
    np.testing.assert_allclose(an["table2"][i], [(1.5625 + 7 / 6) / 2, 7 / 6, 1.5625])
    # the gain is defined for pull too: mean over n = 4, 10, 25 of P_bl - P_sl
    np.testing.assert_allclose(an["gain_per_target"][i], [(0.1 + 0.1 + 0.05) / 3, (0.1 + 0.15 + 0.1) / 3, (0.1 + 0 + 0) / 3])
    assert an["gain_n_targets"][i] == 3


def test_every_row_averages_exactly_the_targets_it_says(tmp_path):
    rng = np.random.default_rng(1)
    acc = np.clip(0.45 + 0.4 * rng.random((3, LAY["n"], len(SIZES), 3)), 0, 1)
    acc[1, LAY["NB"]] = 0.5  # one target never above chance
    an = E.analyse(_res(acc), _cfg(), intervals=False)
    rows = list(csv.DictReader(io.StringIO(table2_csv(an, paper=True))))
    assert [r["method"] for r in rows] == list(E.TABLE2_ROWS)
    for i, r in enumerate(rows):
        vals = an["table2_per_target"][i]
        ok = np.isfinite(vals)
        assert int(r["n_targets"]) == ok.sum() == an["n_targets"][i]
        if ok.any():
            assert float(r["avg"]) == pytest.approx(vals[ok].mean(), abs=1e-4)
            assert float(r["min"]) == pytest.approx(vals[ok].min(), abs=1e-4)
        assert not ok[1]  # the target at chance is in no row


# ------------------------------------------------------------------------------- ties


def test_tie_weights_hand_worked():
    np.testing.assert_allclose(E.tie_weights(np.array([0.6, 0.8, 0.8, np.nan])), [0, 0.5, 0.5, 0])
    np.testing.assert_allclose(E.tie_weights(np.array([np.nan, np.nan])), [0, 0])
    np.testing.assert_allclose(E.tie_weights(np.array([[1.0, 0.0], [0.3, 0.3]])), [[1, 0], [0.5, 0.5]])


def test_tied_candidates_share_best_and_best_after_ten():
    nb = [[0.5, 0.6, 0.7, 0.8]] * 3
    # target lift: sources pull and take tie at n = 10 and over 2..100, with different bf
    db1 = {(0, 1): [0.5, 0.8, 0.8, 0.8], (0, 2): [0.5, 0.6, 0.8, 1.0]}
    an = E.analyse(_res(_acc(nb, db1)), _cfg(), intervals=False)
    bf_pull = (0.3 / 0.1 + 0.3 / 0.2 + 0.3 / 0.3) / 3
    bf_take = (1 + 0.3 / 0.2 + 0.5 / 0.3) / 3
    # the in-sample rows (no outcomes kept: the held-out ones are NaN); before n = 10 the after-ten
    # learner is an equal share of pull and take, which is what the tie gives here too
    for row in ("DB1 best (in-sample oracle)", "DB1 best after ten (in-sample oracle)",
                "DB1 best after ten (causal) (in-sample oracle)"):
        assert an["table2_per_target"][E.TABLE2_ROWS.index(row), 0] == pytest.approx((bf_pull + bf_take) / 2)
    assert np.isnan(an["table2_per_target"][E.TABLE2_ROWS.index("DB1 best"), 0])
    assert an["ties_db1"][0] == 2


# ----------------------------------------------------------------- online vs offline choice


def test_online_choice_differs_from_the_offline_one_in_the_known_way():
    """Offline (test accuracy at n = 10 over both repetitions) picks pull; the learner's
    leave-one-out accuracy picks take in repetition 0 and ties pull and take in repetition 1."""
    nb = np.array([[0.5, 0.6, 0.6, 0.6]] * 3)
    acc = _acc(nb, {}, reps=2)
    acc[0, LAY["DB1"][1]] = np.array([[0.5, 0.5], [0.9, 0.7], [0.9, 0.9], [0.9, 0.9]])  # pull (S, R)
    acc[0, LAY["DB1"][2]] = np.array([[0.5, 0.5], [0.7, 0.7], [0.7, 0.8], [0.7, 0.7]])  # take
    loo = np.full((3, LAY["n"], 2), np.nan)
    loo[0, LAY["DB1"][1]] = [0.5, 0.8]
    loo[0, LAY["DB1"][2]] = [0.7, 0.8]
    an = E.analyse(_res(acc, loo), _cfg(), intervals=False)
    assert an["ten_db1"][0] == LAY["DB1"][1]
    np.testing.assert_allclose(an["online_db1"][0, :, 0], [0, 0, 1])
    np.testing.assert_allclose(an["online_db1"][0, :, 1], [0, 0.5, 0.5])
    # the online learner per repetition from n = 10 on: rep 0 = take, rep 1 = (pull + take) / 2;
    # before n = 10 (here n = 4) nothing is chosen yet: an equal share of pull and take
    online = np.stack([acc[0, LAY["DB1"][2], :, 0], (acc[0, LAY["DB1"][1], :, 1] + acc[0, LAY["DB1"][2], :, 1]) / 2], -1)
    p = online.mean(-1)
    at4 = (acc[0, LAY["DB1"][1], 1].mean() + acc[0, LAY["DB1"][2], 1].mean()) / 2  # 0.75
    want = np.mean([(at4 - 0.5) / 0.1] + list((p[2:] - 0.5) / 0.1))
    row = lambda name: an["table2_per_target"][E.TABLE2_ROWS.index(name), 0]  # noqa: E731
    assert row("DB1 best after ten (causal) (online)") == pytest.approx(want)
    off = np.mean([(at4 - 0.5) / 0.1] + list((acc[0, LAY["DB1"][1], 2:].mean(-1) - 0.5) / 0.1))
    assert row("DB1 best after ten (causal) (in-sample oracle)") == pytest.approx(off)
    assert want < off
    # the whole-curve reading: the kept learners' own curves at every size of the window
    assert row("DB1 best after ten (online)") == pytest.approx(np.mean((p[1:] - 0.5) / 0.1))
    assert row("DB1 best after ten (in-sample oracle)") == pytest.approx(
        np.mean((acc[0, LAY["DB1"][1], 1:].mean(-1) - 0.5) / 0.1))


def test_leave_one_out_accuracy_matches_sklearn_forests_on_nine_samples():
    from relaff_jax.config.experiment import ForestConfig
    from relaff_jax.learn.forest.estimator import fit_forest, predict_class
    from relaff_jax.provenance import derive_seed

    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 18)).astype(np.float32)
    y = X[:, 0] > 0
    boot = np.stack([(X[:, 1] > 0).astype(np.float32)])
    fc = ForestConfig(base_trees=5, max_trees=5)
    plan = [(0, ()), (1, (0,))]
    order, test = np.arange(10), np.arange(10, 40)
    got = block_outcomes(X, y, boot, plan, order, test, [4, 10], 6, 2, fc, (3,), loo_size=10, loo_conditions=(1,))
    hits = []
    for i in range(10):
        keep = np.delete(order, i)
        f = fit_forest(E.augment(X[keep], boot[:, keep], 6), y[keep], derive_seed(3, 10, 1, i + 1), fc)
        hits.append(predict_class(f, E.augment(X[[i]], boot[:, [i]], 6))[0] == y[i])
    assert got["loo"][1] == pytest.approx(np.mean(hits))
    assert np.isnan(got["loo"][0])  # NB is no candidate
    np.testing.assert_allclose(got["acc"], got["correct"].mean(-1))


@pytest.mark.parametrize("sizes,select", [((2, 3, 4, 6, 10, 14, 25, 30), 10), ((2, 4, 30), 30), (tuple(range(4, 26)), 10)])
def test_table2_rows_from_the_window_only_has_the_bits_of_every_size(sizes, select):
    # the default makes bf and gain cells for the window's sizes only (with a window of one
    # size, for all: numpy would sum a single column's candidates pairwise, which the causal
    # rows' equal shares of eight sources before select_size show); the reference for every
    # size: every output the same bits, with resamples in front, ties (accuracies in 1/31), a
    # source that did not run, NB at chance
    from relaff_jax.constants import ACTIONS
    from relaff_jax.learn.measures import chance_tolerance, table2_rows

    cfg = override(_cfg(), {"sizes": sizes, "select_size": select})
    lay = E.layout(9, len(cfg.thresholds))
    rng = np.random.default_rng(len(sizes))
    halves = np.round(rng.uniform(0.45, 1.0, (4, 2, 9, lay["n"] + 2, len(sizes))) * 31) / 31
    halves[..., lay["DB1"][2], :] = np.nan  # a source that did not run
    halves[:, :, 1, 0, 1:] = 0.5  # NB of one target at chance beyond the first size
    mean = halves.mean(1)
    corr = np.eye(9) + rng.uniform(0, 0.9, (9, 9))
    masks = E.category_masks((corr + corr.T) / 2, list(ACTIONS), cfg)
    tol = chance_tolerance(cfg, np.full(9, 62), 9)
    for m, h in ((mean[0], halves[0]), (mean, halves), (mean, None)):
        args = (m, list(sizes), cfg, lay, tol, h, np.arange(9) % 3 > 0, masks)
        new, ref = table2_rows(*args, min_cells=1), table2_rows(*args, min_cells=1, reference=True)
        assert new.keys() == ref.keys()
        for k in new:
            np.testing.assert_array_equal(new[k], ref[k], err_msg=k)
        assert np.isfinite(new["bf"]).any() and np.isnan(new["bf"]).any()


# ------------------------------------------------------------------------- intervals


def test_resampled_means_match_a_plain_numpy_loop():
    rng = np.random.default_rng(2)
    correct = rng.random((2, 3, 2, 4, 6)) < 0.7  # (A, C, S, R, N)
    correct[1, ..., 5] = False  # target 1 has 5 test scenes (one padding)
    n_test = np.array([6, 5])
    acc = np.stack([correct[0].mean(-1), correct[1, ..., :5].mean(-1)])
    halves = E.scene_halves(n_test, None, 6)  # alternate scenes; padding -1
    np.testing.assert_array_equal(halves, [[0, 1, 0, 1, 0, 1], [0, 1, 0, 1, 0, -1]])
    got = E.resampled_means(acc, correct, n_test, 7, seed=11, halves=halves)
    assert got.dtype == np.float64
    assert got.shape == (7, 2, 2, 3, 2)
    g = np.random.default_rng(11)
    v = g.multinomial(4, np.full(4, 0.25), size=7)
    for t in range(2):
        for h in range(2):
            idx = np.flatnonzero(halves[t] == h)
            w = g.multinomial(len(idx), np.full(len(idx), 1 / len(idx)), size=7)  # within the half
            for b in range(7):
                per_rep = (correct[t][..., idx] * w[b]).sum(-1) / len(idx)  # (C, S, R)
                np.testing.assert_allclose(got[b, h, t], (per_rep * v[b]).sum(-1) / 4, rtol=1e-12)
    # the halves average back to the whole test set: with no resampling, the plain accuracy
    sizes = E.half_sizes(n_test, halves)
    np.testing.assert_array_equal(sizes, [[3, 3], [3, 2]])
    per_half = np.stack([np.stack([correct[t][..., halves[t] == h].mean(-1) for t in range(2)]) for h in range(2)])
    plain = E.whole(np.moveaxis(per_half, -1, 0), sizes)  # repetitions in front: (R, A, C, S)
    np.testing.assert_allclose(plain, np.moveaxis(acc, -1, 0), rtol=1e-12)


def test_balanced_test_sets_split_into_balanced_halves():
    # draws.draw_test puts the k positives first: scenes 0..3 positive, 4..7 negative
    h = E.scene_halves(np.array([8]), np.array([4]), 8)[0]
    assert list(h) == [0, 1, 0, 1, 0, 1, 0, 1]
    h = E.scene_halves(np.array([6]), np.array([3]), 6)[0]  # k = 3: halves of 3 (2 + 1 and 1 + 2)
    assert list(h) == [0, 1, 0, 1, 0, 1]
    h = E.scene_halves(np.array([2]), np.array([1]), 2)[0]  # one scene per class: one in each half
    assert list(h) == [0, 1]


def test_no_bootstrap_factor_exceeds_the_bound_of_the_test_set_size():
    """bf is undefined where NB is at most half a test scene above chance, so with T test scenes
    no cell (and no interval end) can exceed T in size, in the estimate or in any resample;
    float32 put NB means of exactly 0.5 at 0.5 + 6e-8 (a bf of ~1e6)."""
    t_scenes = 24
    assert np.isnan(E.bootstrap_factor(0.9, 0.5 + 0.5 / t_scenes, 0.5, 0.5 / t_scenes))  # at the tolerance
    assert E.bootstrap_factor(0.0, 0.5 + 1 / t_scenes, 0.5, 0.5 / t_scenes) == pytest.approx(-12.0)
    rng = np.random.default_rng(0)
    reps = 2
    correct = np.zeros((3, LAY["n"], len(SIZES), reps, t_scenes), bool)
    # NB: every repetition 13 or 14 of 24 right (1-2 scenes above chance); sources random
    for t in range(3):
        for s in range(len(SIZES)):
            for r in range(reps):
                correct[t, 0, s, r, rng.permutation(t_scenes)[: 13 + (r + s + t) % 2]] = True
    correct[:, 1:] = rng.random(correct[:, 1:].shape) < 0.5
    acc = correct.mean(-1)
    res = dict(_res(acc), correct=correct, n_test=np.full(3, t_scenes), test_positive=np.full(3, t_scenes // 2))
    an = E.analyse(res, _cfg(ci_resamples=300, min_defined_share=0.0), seed=1)
    np.testing.assert_allclose(an["tol"], 0.5 / t_scenes)
    for key in ("table2_ci", "per_target_ci", "table2_boot"):
        v = np.asarray(an[key])
        assert np.all(np.abs(v[np.isfinite(v)]) <= t_scenes + 1e-9), key
    assert np.isfinite(an["table2_boot"]).any()  # the bound was tested on real values
    bf = an["bf"]
    assert np.all(np.abs(bf[np.isfinite(bf)]) <= t_scenes)


def test_intervals_are_seeded_and_contain_the_estimate_for_a_linear_measure():
    rng = np.random.default_rng(3)
    acc = np.clip(0.6 + 0.3 * rng.random((3, LAY["n"], len(SIZES), 4)), 0, 1)
    cfg = _cfg(ci_resamples=200)
    a1, a2 = E.analyse(_res(acc), cfg, seed=5), E.analyse(_res(acc), cfg, seed=5)
    np.testing.assert_array_equal(a1["gain_ci"], a2["gain_ci"])
    i = E.TABLE2_ROWS.index("DB1 average")
    lo, hi = a1["gain_ci"][i]
    assert lo < a1["gain"][i, 0] < hi
    assert a1["mean_ci"].shape == a1["mean"].shape + (2,)
    assert not np.array_equal(E.analyse(_res(acc), cfg, seed=6)["gain_ci"], a1["gain_ci"])


# -------------------------------------------------------------------------------- draws


def test_test_set_is_balanced_shared_by_repetitions_and_never_trained_on():
    rng = np.random.default_rng(4)
    labels = rng.random(60) < 0.3  # an unbalanced pool
    tests, trains = [], []
    for r in range(4):
        test, order = E.draw_rep(labels, 20, 25, 0, 2, r)
        tests.append(test), trains.append(order)
        assert labels[test].sum() == len(test) // 2
        assert len(test) == 20
    assert all(np.array_equal(t, tests[0]) for t in tests)
    assert len(np.intersect1d(np.concatenate(trains), tests[0])) == 0
    assert not np.array_equal(trains[0], trains[1])
    few = E.draw_test(np.array([True] * 3 + [False] * 30), 20, 0, 0)
    assert len(few) == 6
    assert few.dtype.kind == "i"  # only 3 positives: 3 + 3


def test_balanced_training_prefixes_hold_both_classes():
    labels = np.array([True] * 10 + [False] * 40)
    order = E.draw_train(labels, np.array([], int), 30, 0, 0, 1, balanced=True)
    for n in range(2, 21, 2):
        assert labels[order[:n]].sum() == n // 2
    assert labels[order[20:]].sum() == 0  # positives used up: the rest follow
    plain = E.draw_train(labels, np.arange(40, 50), 30, 0, 0, 1)  # the last 10 scenes are a test set
    assert len(set(plain)) == 30
    assert max(plain) < 40
