"""The methods against NB that choose a source ("best", "best after ten") rest on Table II's
held-out choice: hand-made outcomes whose in-sample and held-out choices differ, with the area,
the samples saved and P(improvement) worked out by hand for both; the per repetition half
curves against the whole outcome array, on both paths of the analysis."""
import numpy as np
import pytest

from relaff_jax import learn as E
from relaff_jax.config import override
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn import gains as G
from relaff_jax.learn import heldout as H
from relaff_jax.learn.intervals import resampled_means, scene_halves
from relaff_jax.learn.online import extend

ACTS = ["lift", "pull", "take"]
LAY = E.layout(3, 3)
SIZES = [2, 4, 10, 25]
N = 16  # balanced test scenes: halves of 8, every accuracy a multiple of 1/8
NB = np.array([0.5, 0.5, 0.625, 0.75])
CURVES = {  # (half 0, half 1) accuracy per size of NB and of the two DB1 sources of every target
    "NB": (NB, NB),
    "A": (NB + 0.25, NB - 0.125),  # whole NB + 0.0625: the in-sample choice
    "B": (NB - 0.125, NB + 0.125),  # whole NB
}
CHOSEN = ("DB1 best", "DB1 best after ten")


def _cfg(**kw):
    return override(ExperimentConfig(), dict({"sizes": tuple(SIZES), "ci_resamples": 40}, **kw))


def _results(reps=2):
    """Per target: source A chosen on half 0 (NB + 0.25 there) scores NB - 0.125 on half 1;
    source B chosen on half 1 (NB + 0.125) scores NB - 0.125 on half 0. Held out: NB - 0.125 at
    every size; in sample: A, NB + 0.0625. Every repetition the same."""
    halves = scene_halves(np.array([N]), np.array([N // 2]), N)[0]
    correct = np.zeros((3, LAY["n"], len(SIZES), reps, N), bool)
    for t in range(3):
        a, b = [s for s in range(3) if s != t]
        for name, c in (("NB", LAY["NB"]), ("A", LAY["DB1"][a]), ("B", LAY["DB1"][b])):
            for h, acc in enumerate(CURVES[name]):
                idx = np.flatnonzero(halves == h)
                for j, p in enumerate(acc):
                    correct[t, c, j, :, idx[: int(round(p * len(idx)))]] = True
    cfg = _cfg()
    ran = correct.any(axis=(2, 3, 4), keepdims=True)[..., 0]
    return {"acc": np.where(ran, correct.mean(-1), np.nan), "correct": correct, "n_test": np.full(3, N),
            "test_positive": np.full(3, N // 2), "sizes": np.array(SIZES), "actions": np.array(ACTS),
            "conditions": np.array(E.condition_names(ACTS, cfg.thresholds)),
            "category_masks": E.category_masks(np.eye(3), ACTS, cfg)}


@pytest.mark.parametrize("intervals", [False, True])  # the half curves alone, or fused with the resampling
def test_best_rows_area_saved_and_improvement_use_the_held_out_choice(intervals):
    an = E.analyse(_results(), _cfg(), seed=3, intervals=intervals)
    m = an["methods"]
    gain = an["gain_per_target"][E.TABLE2_ROWS.index("DB1 best")]
    np.testing.assert_allclose(gain, -0.125)  # Table II's held-out gain
    np.testing.assert_allclose(an["gain_per_target"][E.TABLE2_ROWS.index("DB1 best (in-sample oracle)")], 0.0625)
    for name in CHOSEN:
        k = G.METHODS.index(name)
        assert m["names"][k] == name  # held out: Table II's row name, no oracle suffix
        # the gain curve is the held-out gain at every size: area = gain x (25 - 4)
        np.testing.assert_allclose(m["area_per_target"][k], -0.125 * 21)
        # at n = 10 the held-out learner scores 0.5; NB is at 0.5 from its first size: 2 - 10
        np.testing.assert_allclose(m["saved_per_target"][k], 2 - 10)
        assert not m["censored_per_target"][k].any()
        assert m["poi"][k] == 0.0  # every repetition below NB's on the same halves
    # a method without a choice is unchanged: DB1 average = NB + (0.0625 + 0) / 2
    k = G.METHODS.index("DB1 average")
    np.testing.assert_allclose(m["area_per_target"][k], 0.03125 * 21)
    f = an["affordances"]
    assert f["saved_method"] == "DB1 best" == f["best_row"]
    np.testing.assert_allclose(f["saved"], -8.0)
    np.testing.assert_allclose(f["gain"], gain)
    if intervals:  # the resamples choose on their own halves, as Table II's do
        lo, hi = np.moveaxis(m["saved_per_target_ci"][G.METHODS.index("DB1 best")], -1, 0)
        assert (lo <= -8).all() and (hi >= -8).all()


def test_without_outcomes_the_best_rows_are_the_in_sample_oracle():
    res = _results()
    res = {k: v for k, v in res.items() if k not in ("correct", "n_test", "test_positive")}
    an = E.analyse(res, _cfg(), seed=3, intervals=False)
    m = an["methods"]
    for name in CHOSEN:
        k = G.METHODS.index(name)
        assert m["names"][k] == name + " (in-sample oracle)"
        np.testing.assert_allclose(m["area_per_target"][k], 0.0625 * 21)
        # in sample A at n = 10 is 0.6875: NB gets there halfway from n = 10 (0.625) to 25 (0.75)
        np.testing.assert_allclose(m["saved_per_target"][k], 17.5 - 10)
        assert m["poi"][k] == 1.0
    assert an["affordances"]["saved_method"] == "DB1 best (in-sample oracle)" == an["affordances"]["best_row"]


def test_held_out_curves_by_hand_with_a_source_missing():
    """``heldout_curves`` on hand-made half curves of one target: the mean over the two halves
    of the choice scored on the other, NB's over the same halves; NaN with nothing to score."""
    cfg = _cfg()
    c = LAY["n"] + 2
    halves = np.full((2, 3, c, len(SIZES)), np.nan)
    halves[:, 0, LAY["NB"]] = [NB, NB + 0.1]
    halves[:, 0, LAY["DB1"][1]] = [NB + 0.2, NB + 0.05]
    halves[:, 0, LAY["DB1"][2]] = [NB + 0.1, NB + 0.3]
    cur, nb = H.heldout_curves(halves, G.METHODS, LAY, SIZES, cfg)
    j = H.choosing(G.METHODS).index(G.METHODS.index("DB1 best"))
    # half 0 picks source 1, scored on half 1: NB + 0.05; half 1 picks source 2, on half 0: NB + 0.1
    np.testing.assert_allclose(cur[j, 0], NB + 0.075)
    np.testing.assert_allclose(nb[j, 0], NB + 0.05)
    assert np.isnan(cur[j, 1:]).all() and np.isnan(nb[j, 1:]).all()  # nothing ran for the others
    halves[1, 0, LAY["DB1"][2]] = np.nan  # source 2 not on half 1: half 1 picks source 1, scored on half 0
    cur, nb = H.heldout_curves(halves, G.METHODS, LAY, SIZES, cfg)
    np.testing.assert_allclose(cur[j, 0], NB + (0.05 + 0.2) / 2)
    halves[1, 0, LAY["DB1"]] = np.nan  # no source on half 1: nothing to score half 0's choice on
    cur, nb = H.heldout_curves(halves, G.METHODS, LAY, SIZES, cfg)
    assert np.isnan(cur[j, 0]).all() and np.isnan(nb[j, 0]).all()


def test_half_rep_curves_same_bits_on_every_path():
    rng = np.random.default_rng(8)
    a, s, r, n = 3, 5, 4, 23
    lay = E.layout(a, 3)
    correct = rng.random((a, lay["n"], s, r, n)) < 0.6
    loo = rng.integers(0, 11, (a, lay["n"], r)) / 10.0
    acc = correct.mean(-1)
    acc_x, out, _ = extend(acc, correct, loo, lay)
    n_test = np.array([23, 22, 1])
    halves = scene_halves(n_test, None, n)
    fast = H.half_rep_curves(acc_x, out, halves)
    ref = H.half_rep_curves(acc_x, out, halves, reference=True)
    np.testing.assert_array_equal(fast, ref)
    # numpy by hand: target 0, condition 0, half 1
    want = correct[0, 0][..., halves[0] == 1].mean(-1)  # (S, R)
    np.testing.assert_allclose(fast[1, 0, 0], want, rtol=0, atol=1e-15)
    # the fused pass of the intervals fills the same values
    reps = np.full(fast.shape, np.nan)
    means = np.full(fast.shape[:-1], np.nan)
    resampled_means(acc_x, out, n_test, 20, 5, halves, means=means, rep_means=reps)
    ran = np.isfinite(acc_x).any(-1)[None, ..., None]
    np.testing.assert_array_equal(np.where(ran, reps, np.nan), fast)
    np.testing.assert_array_equal(np.where(ran[..., 0], means, np.nan), fast.mean(-1))
