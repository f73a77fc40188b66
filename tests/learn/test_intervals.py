"""Intervals that mean what they say. A choice made on one half of the test scenes and
scored on the other is not optimistic where the in-sample choice is; the bias-corrected
bootstrap of Table II covers a known truth at its nominal level; the BC interval by hand."""
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from relaff_jax import learn as E
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.config import override

ACTS = ["lift", "pull", "take"]
LAY = E.layout(3, 3)
SIZES = [2, 4, 10, 25]


def _cfg(**kw):
    return override(ExperimentConfig(), dict({"sizes": tuple(SIZES)}, **kw))


def _res(correct, n_test, n_pos):
    """Results of hand-made outcomes ``correct (3, C, S, R, N)``; conditions with no True
    outcome anywhere did not run (NaN accuracy)."""
    cfg = _cfg()
    ran = correct.any(axis=(2, 3, 4), keepdims=True)[..., 0]  # (3, C, 1, 1)
    acc = np.where(ran, correct.mean(-1), np.nan)
    return {"acc": acc, "correct": correct, "n_test": np.full(3, n_test), "test_positive": np.full(3, n_pos),
            "sizes": np.array(SIZES), "actions": np.array(ACTS),
            "conditions": np.array(E.condition_names(ACTS, cfg.thresholds)),
            "category_masks": E.category_masks(np.eye(3), ACTS, cfg)}


def _set(correct, t, c, half_acc, halves):
    """Outcomes of condition c of target t: accuracy ``half_acc[h]`` on half h at every size/rep."""
    for h, p in enumerate(half_acc):
        idx = np.flatnonzero(halves == h)
        correct[t, c, ..., idx[: int(round(p * len(idx)))]] = True


def test_held_out_choice_is_not_optimistic_where_the_in_sample_one_is():
    """16 balanced test scenes, halves of 8. Per target, source A scores 1.0 on half 0 and 0.5 on
    half 1 (whole 0.75); source B 0.625 and 0.75 (whole 0.6875); NB 0.625 on both. In sample
    A wins and reports its own 0.75 (bf 2). Held out: half 0 picks A, which scores 0.5 on half 1
    (bf 0); half 1 picks B, which scores 0.625 on half 0 (bf 1): 0.5, not 2."""
    n = 16
    halves = E.scene_halves(np.array([n]), np.array([8]), n)[0]
    assert list(halves[:8]) == [0, 1] * 4  # balanced: alternate within each class
    correct = np.zeros((3, LAY["n"], len(SIZES), 1, n), bool)
    for t in range(3):
        _set(correct, t, LAY["NB"], (0.625, 0.625), halves)
        a, b = [s for s in range(3) if s != t]
        _set(correct, t, LAY["DB1"][a], (1.0, 0.5), halves)
        _set(correct, t, LAY["DB1"][b], (0.625, 0.75), halves)
    an = E.analyse(_res(correct, n, 8), _cfg(), intervals=False)
    row = lambda name: an["table2_per_target"][E.TABLE2_ROWS.index(name)]  # noqa: E731
    np.testing.assert_allclose(row("DB1 best (in-sample oracle)"), 2.0)
    np.testing.assert_allclose(row("DB1 best"), 0.5)
    # after ten, causal: before n = 10 (the window's n = 4) an equal share of A and B, whole or
    # half: bf 1.75; from n = 10 on the choice at n = 10 (the same as 'best' here)
    np.testing.assert_allclose(row("DB1 best after ten (causal) (in-sample oracle)"), (1.75 + 2 + 2) / 3)
    np.testing.assert_allclose(row("DB1 best after ten (causal)"), (1.75 + 0.5 + 0.5) / 3)
    # whole curve of the learner kept at n = 10: the choice is 'best''s here, so are the rows
    np.testing.assert_allclose(row("DB1 best after ten (in-sample oracle)"), row("DB1 best (in-sample oracle)"))
    np.testing.assert_allclose(row("DB1 best after ten"), row("DB1 best"))
    # the gain says the same: in sample 0.125, held out (0.5 - 0.625 + 0.625 - 0.625) / 2
    gain = an["gain_per_target"][E.TABLE2_ROWS.index("DB1 best")]
    np.testing.assert_allclose(gain, -0.0625)
    np.testing.assert_allclose(an["gain_per_target"][E.TABLE2_ROWS.index("DB1 best (in-sample oracle)")], 0.125)
    np.testing.assert_allclose(row("DB1 average"), ((0.75 + 0.6875) / 2 - 0.5) / 0.125)  # no choice: unchanged


def test_bc_interval_by_hand():
    vals = np.arange(1.0, 101.0)  # 1..100
    # the estimate at the median: z0 = 0, the plain 2.5 / 97.5 % percentiles
    lo, hi = E.bc_interval(vals[:, None], np.array([50.5]), 0.95)
    np.testing.assert_allclose([lo[0], hi[0]], np.percentile(vals, [2.5, 97.5]))
    # the estimate at the 84.13th percentile (z0 = 1): percentiles Phi(2 -+ 1.96) = 51.6 %, 99.997 %
    est = np.percentile(vals, 100 * 0.841345)
    below = (vals < est).mean()
    from statistics import NormalDist
    z0 = NormalDist().inv_cdf(below)
    q = [100 * NormalDist().cdf(2 * z0 + z) for z in (-1.959964, 1.959964)]
    lo, hi = E.bc_interval(vals[:, None], np.array([est]), 0.95)
    np.testing.assert_allclose([lo[0], hi[0]], np.percentile(vals, q), rtol=1e-6)
    assert lo[0] > np.percentile(vals, 2.5)  # moved up, toward where the estimate sits
    # NaN resamples are left out; no finite resample or a NaN estimate: NaN
    lo, hi = E.bc_interval(np.array([[np.nan, 1.0], [np.nan, 2.0], [np.nan, 3.0]]), np.array([1.0, np.nan]), 0.9)
    assert np.isnan(lo).all()
    assert np.isnan(hi).all()


def _simulate(rng, p_nb, p_db, p_dbn, reps, n, shared=0.5, rep_sd=0.02):
    """Outcomes ``(3, C, S, R, n)`` drawn from known accuracy curves ``p (S,)``: every
    repetition shifts its curve by N(0, rep_sd) (a training draw), each test scene is right
    with that probability; with probability ``shared`` a scene's uniform is the same for
    every condition, size and repetition (the comparison is paired, as in the sweep)."""
    c, s = LAY["n"], len(SIZES)
    p = np.full((3, c, s), np.nan)
    p[:, LAY["NB"]] = p_nb
    for t in range(3):
        p[t, LAY["DB1"][[k for k in range(3) if k != t]]] = p_db
    p[:, LAY["DBn"]] = p_dbn
    ran = np.isfinite(p)
    p = np.nan_to_num(p)[..., None] + rep_sd * rng.normal(size=(3, c, s, reps))  # (3, C, S, R)
    u_scene = rng.random((3, 1, 1, 1, n))
    u = np.where(rng.random((3, c, s, reps, n)) < shared, u_scene, rng.random((3, c, s, reps, n)))
    return (u < p[..., None]) & ran[..., None, None]


@pytest.mark.slow
def test_table2_intervals_cover_a_known_truth_at_the_nominal_level():
    """Coverage of the 95 % intervals of three Table II rows over 200 simulated runs (3
    affordances, 4 repetitions, 60 balanced test scenes, 300 resamples): DB1 average's bf
    (truth 1.5 exactly), DBn's bf (a ratio of known curves) and DB1 average's gain. The
    observed coverage must be within 3 Monte Carlo standard errors (about 0.046) of 0.95."""
    rng = np.random.default_rng(25)
    p_nb = np.array([0.62, 0.66, 0.72, 0.8])
    p_db = 0.5 + 1.5 * (p_nb - 0.5)
    p_dbn = p_nb + 0.04
    window = np.isin(SIZES, [4, 10, 25])
    truth = {"DB1 average": 1.5, "DBn": float(np.mean(((p_dbn - 0.5) / (p_nb - 0.5))[window]))}
    truth_gain = float(np.mean((p_db - p_nb)[window]))
    cfg = _cfg(ci_resamples=300)
    m, hits = 200, {"DB1 average": 0, "DBn": 0, "gain": 0}
    # one BLAS thread: the resamples' small products spent more CPU waking a second thread than
    # computing (about half of each analysis beside another worker); the intervals keep their bits
    with threadpool_limits(1, user_api="blas"):
        for i in range(m):
            correct = _simulate(rng, p_nb, p_db, p_dbn, reps=4, n=60)
            an = E.analyse(_res(correct, 60, 30), cfg, seed=i)
            for name, want in truth.items():
                lo, hi = an["table2_ci"][E.TABLE2_ROWS.index(name)]
                hits[name] += lo <= want <= hi
            lo, hi = an["gain_ci"][E.TABLE2_ROWS.index("DB1 average")]
            hits["gain"] += lo <= truth_gain <= hi
    se = np.sqrt(0.95 * 0.05 / m)
    for k, h in hits.items():
        assert abs(h / m - 0.95) <= 3 * se, (k, h / m)


def test_bc_tally_from_chunked_counts_is_interval_pairs_tally():
    # estimates inside, at the edge of and outside the resamples (bias-corrected and percentile
    # intervals both), ties with the estimate, NaN resamples, a column without any, NaN estimates
    from relaff_jax.learn import intervals as I

    rng = np.random.default_rng(5)
    vals = np.round(rng.normal(size=(300, 40)), 1)
    vals[rng.random(vals.shape) < 0.1] = np.nan
    vals[:, 3] = np.nan
    est = np.concatenate([np.zeros(10), np.full(10, 1.9), np.full(10, -2.4), np.full(10, np.nan)])
    est[3] = 0.0
    for tail in (0.005, 0.0, 0.02):
        want: list = []
        I.interval_pairs(vals, est, 0.95, tail, want)
        counts = [0, 0, 0]
        for b in range(0, 300, 70):
            counts = [c + k for c, k in zip(counts, I.bc_counts(vals[b : b + 70], est))]
        got = I.bc_tally(counts, est, 0.95, tail)
        assert got == want[0]
        assert 0 < got[0] < got[1] < 40 or tail == 0.0


def test_checked_interval_keeps_bc_unless_an_end_rests_on_the_extreme_tail():
    from statistics import NormalDist
    nd = NormalDist()
    vals = np.arange(1.0, 1001.0)  # 1..1000
    # three estimates: at the median (z0 = 0), at the 57.3rd percentile (z0 = 0.18: upper end at
    # Phi(2.33) = 99.0 %, 1 % beyond it) and at the 73.1st (z0 = 0.62: 99.93 %, 0.07 % beyond)
    est = np.array([500.5, 573.5, 731.5])
    q_hi = [nd.cdf(2 * nd.inv_cdf((vals < e).mean()) + 1.959964) for e in est]
    assert 1 - q_hi[1] > 0.005 > 1 - q_hi[2]
    lo, hi, bc = E.checked_interval(np.repeat(vals[:, None], 3, 1), est, 0.95, 0.005)
    blo, bhi = E.bc_interval(np.repeat(vals[:, None], 3, 1), est, 0.95)
    assert bc.tolist() == [True, True, False]
    np.testing.assert_array_equal([lo[:2], hi[:2]], [blo[:2], bhi[:2]])
    np.testing.assert_allclose([lo[2], hi[2]], np.percentile(vals, [2.5, 97.5]))  # the percentile interval
    assert bhi[2] > 999 and hi[2] < 976  # BC's end sat on the last resamples
    # tail 0: bias-corrected everywhere, bit for bit
    lo0, hi0, bc0 = E.checked_interval(np.repeat(vals[:, None], 3, 1), est, 0.95, 0.0)
    assert bc0.all()
    np.testing.assert_array_equal([lo0, hi0], [blo, bhi])
    # a lower end in the tail (estimate at the 26.9th percentile) falls back as well; NaN estimate stays NaN
    lo, hi, bc = E.checked_interval(np.stack([vals, vals], 1), np.array([269.5, np.nan]), 0.95, 0.005)
    assert not bc[0] and np.isnan([lo[1], hi[1]]).all()
