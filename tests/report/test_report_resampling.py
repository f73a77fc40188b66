"""The report's fast resampling paths (learn/halfrows: the outcomes read half by half from
their bits, the online learners mixed over their chosen candidates only) give the bits of the
reference paths (``reference=True``: the float copy of every block) on paper-shaped outcomes:
ties in the online weights, conditions that did not run, a family that did not run for a
target, a target without outcomes, a test set of one scene, several block budgets."""
import numpy as np
import pytest

from relaff_jax.learn.analysis import half_curves
from relaff_jax.learn.intervals import resampled_means, scene_halves
from relaff_jax.learn.online import FAMILIES, _mix, _mix_sparse, extend, online_weights
from relaff_jax.learn.results import PackedBits
from relaff_jax.learn.synthetic import synthetic_outcomes


def _case(a, sizes, reps, n_test, seed, packed, not_run=()):
    d = synthetic_outcomes(a, sizes, reps, n_test, seed=seed, not_run=not_run)
    if a > 2:  # a family that did not run for one target: its online learner is NaN there
        d["loo"][1, d["lay"]["CB1"]] = np.nan
        d["acc"][1, d["lay"]["CB1"]] = np.nan
        d["correct"][1, d["lay"]["CB1"]] = False
    corr = d["correct"]
    if packed:
        corr = PackedBits(np.packbits(corr, axis=-1), corr.shape[-1])
    acc_x, out, w = extend(d["acc"], corr, d["loo"], d["lay"])
    return d, acc_x, out, w


def _check(acc_x, out, n_test, budgets, resamples=40, seed=5):
    halves = scene_halves(n_test, n_test // 2, out.shape[-1])
    for budget in budgets:
        out.budget = budget
        hc = half_curves(acc_x, out, halves)
        np.testing.assert_array_equal(hc, half_curves(acc_x, out, halves, reference=True))
        got = resampled_means(acc_x, out, n_test, resamples, seed, halves)
        ref = resampled_means(acc_x, out, n_test, resamples, seed, halves, reference=True)
        np.testing.assert_array_equal(got, ref)
    return hc, got


@pytest.mark.parametrize("packed", [False, True])
def test_small_targets_same_bits(packed):
    # a 31-scene and a 30-scene test set, one of one scene (its other half empty), one without outcomes
    n_test = np.array([31, 30, 1, 0])
    d, acc_x, out, w = _case(4, 7, 5, n_test, 3, packed)
    assert any((w[f] > 0).sum(1).max() > 1 for f in FAMILIES)  # tied online choices
    c1 = 4 * 52 * 5 * 31  # bytes of one size of one target's float32 block
    hc, got = _check(acc_x, out, n_test, [1, 3 * c1, 1e12])
    assert np.isnan(got[:, 1, 2]).all() and np.isnan(hc[1, 2]).all()  # the one-scene test set's empty half
    assert np.isnan(hc[:, 3]).all()  # the target without outcomes has no half curves ...
    assert np.isfinite(got[:, :, 3, 0]).all()  # ... its resampled means resample the repetitions only
    assert np.isnan(got[:, :, 1, -1]).all()  # CB1 online did not run for target 1
    assert np.isnan(got[:, :, 0, d["lay"]["DB1"][0]]).all()  # a target's own DB1 never runs


@pytest.mark.parametrize("reps,not_run", [(50, ()), (25, ("DBn", "CB1", "CBn")), (7, ())])
def test_paper_shaped_target_same_bits(reps, not_run):
    # nine actions (52 conditions with the online learners), a 4000-scene test set; the
    # reference's one matmul per block and half has (C + 2) s R rows: 2600 s, 1300 s (whose
    # BLAS row partition puts rows in OpenBLAS's one-row edge kernel) and 364 s
    n_test = np.array([4000])
    d = synthetic_outcomes(9, 3, reps, np.full(9, 4000), seed=reps, not_run=not_run, targets=[0])
    corr = PackedBits(np.packbits(d["correct"], axis=-1), 4000)
    acc_x, out, w = extend(d["acc"], corr, d["loo"], d["lay"])
    block = 4 * 52 * reps * 4000  # bytes of one size
    _check(acc_x, out, n_test, [block, 2 * block, 1e12], resamples=200)


def test_sparse_mix_same_bits_as_mix():
    rng = np.random.default_rng(0)
    x = rng.random((1, 9, 4, 30, 57)) < 0.5
    loo = rng.integers(0, 4, (1, 9, 30)) / 10.0  # many ties, up to all nine
    loo[0, :, 3] = np.nan  # no candidate: 0 after nan_to_num
    lay = {"DB1": np.arange(1, 10), "CB1": np.arange(1, 10)}
    w = online_weights(np.concatenate([np.full((1, 1, 30), np.nan), loo], 1), lay)
    ref = np.nan_to_num(_mix(x, np.arange(9), w["DB1"]))[0]
    np.testing.assert_array_equal(_mix_sparse(x[0], w["DB1"][0]), ref)
    assert (w["DB1"][0] > 0).sum(0).max() >= 3


def _exact(x, counts):
    """``x @ counts.T`` in integers: x's values times 2**30 are integers (0/1 rows and float32
    mixes of up to 128 tied candidates), so int64 arithmetic gives the sums with no rounding."""
    xi = x * 2.0**30
    assert (xi == np.round(xi)).all()
    return (xi.astype(np.int64) @ counts.T.astype(np.int64)).astype(np.float64) / 2.0**30


@pytest.mark.parametrize("m", [2000, 57])
def test_sums_are_the_exact_integer_products(m):
    # the row counts that OpenBLAS splits with a one-row edge kernel (1300, 3900, 1301, 7) and
    # ones it does not: the sums are exact whatever the split, so equal to integer arithmetic
    from relaff_jax.learn.halfrows import SceneCounts, sums

    rng = np.random.default_rng(m)
    counts = SceneCounts(rng.multinomial(m, np.full(m, 1 / m), size=1000))
    assert (counts.f64.sum(1) == m).all()
    for rows in (1300, 3900, 1301, 7, 7800):
        bits = rng.random((rows, 1, 1, m)) < 0.6
        bits[rng.random(rows) < 0.25] = False  # conditions that did not run
        on = (rng.integers(0, 4, (2, 1, rows // 7 + 1, m)) / 3).astype(np.float32).astype(np.float64)  # tied mixes
        on[0, 0, ::3] = 0.0  # an online learner whose family did not run
        x = np.concatenate([bits.reshape(-1, m), on.reshape(-1, m)]).astype(np.float64)
        exact = _exact(x, counts.f64)
        np.testing.assert_array_equal(sums(bits, on, counts), exact)
        np.testing.assert_array_equal(x @ counts.f64.T, exact)  # the reference's one call: exact too


def test_sums_reuse_their_buffers_with_the_same_bits():
    # halfrows.sums with ``work`` (buffers kept across blocks, as intervals.resampled_means
    # passes them) on blocks of several shapes gives the exact sums of each
    from relaff_jax.learn.halfrows import SceneCounts, sums

    rng = np.random.default_rng(1)
    m = 2000
    counts = SceneCounts(rng.multinomial(m, np.full(m, 1 / m), size=1000))
    work: dict = {}
    for c, s, r in ((50, 1, 26), (20, 3, 7), (50, 1, 26)):
        bits = rng.random((c, s, r, m)) < 0.6
        bits[rng.random(c) < 0.2] = False  # conditions that did not run
        on = np.zeros((2, s, r, m))
        on[0] = (rng.integers(0, 10, (s, r, m)) / 9).astype(np.float32)
        x = np.concatenate([bits, on]).reshape(-1, m).astype(np.float64)
        np.testing.assert_array_equal(sums(bits, on, counts, work), _exact(x, counts.f64))


def test_counts_beyond_exactness_are_refused():
    from relaff_jax.learn.halfrows import M_EXACT, SceneCounts

    with pytest.raises(ValueError, match="exact up to"):
        SceneCounts(np.zeros((2, M_EXACT + 1), np.int64))
