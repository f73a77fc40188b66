"""Outcomes made one target and block of sizes at a time (learn/online.Outcomes): the same
bits as the whole (A, C + 2, S, R, N) array the analysis held before, in the half curves and
the resampled means of the intervals."""
import numpy as np
import pytest

from relaff_jax.learn import layout
from relaff_jax.learn.analysis import half_curves
from relaff_jax.learn.intervals import resampled_means, scene_halves
from relaff_jax.learn.online import FAMILIES, _mix, extend, online_weights


def _whole(correct, loo, lay):
    """The former ``extend``: every outcome mixed and cast at once."""
    w = online_weights(loo, lay)
    on = np.stack([np.nan_to_num(_mix(correct, lay[f], w[f])) for f in FAMILIES], 1)
    return np.concatenate([correct.astype(np.float32), on.astype(np.float32)], 1)


@pytest.fixture
def case():
    rng = np.random.default_rng(3)
    a, s, r, n = 3, 7, 4, 31
    lay = layout(a, 3)
    c = lay["n"]
    correct = rng.random((a, c, s, r, n)) < 0.6
    loo = rng.integers(0, 11, (a, c, r)) / 10.0  # ties are common, as with ten samples
    acc = correct.mean(-1)
    n_test = np.array([31, 30, 1])  # the last: one scene, its other half empty
    return acc, correct, loo, lay, n_test


def test_blocks_are_slices_of_the_whole(case):
    acc, correct, loo, lay, _ = case
    whole = _whole(correct, loo, lay)
    _, out, _ = extend(acc, correct, loo, lay)
    out.budget = 1  # one size per block
    assert out.shape == whole.shape
    assert len(out.size_blocks()) == whole.shape[2]
    for t in range(whole.shape[0]):
        np.testing.assert_array_equal(np.concatenate([out.block(t, sl) for sl in out.size_blocks()], 1), whole[t])


@pytest.mark.parametrize("budget", [1, 4 * 52 * 4 * 31 * 3, 1e12])  # 1 size, 3 sizes, all 7 per block
def test_half_curves_and_resampled_means_same_bits(case, budget):
    acc, correct, loo, lay, n_test = case
    whole = _whole(correct, loo, lay)
    acc_x, out, _ = extend(acc, correct, loo, lay)
    out.budget = budget
    halves = scene_halves(n_test, None, correct.shape[-1])
    np.testing.assert_array_equal(half_curves(acc_x, out, halves), half_curves(acc_x, whole, halves))
    got = resampled_means(acc_x, out, n_test, 50, 7, halves)
    ref = resampled_means(acc_x, whole, n_test, 50, 7, halves)
    np.testing.assert_array_equal(got, ref)
    assert np.isnan(got[:, 1, 2]).all()  # the one-scene test set's empty half
    assert np.isfinite(got[:, 0, 0]).any()


def test_packed_bits_unpack_where_indexed():
    from relaff_jax.learn.results import PackedBits

    rng = np.random.default_rng(5)
    bits = rng.random((2, 3, 4, 5, 21)) < 0.5
    pk = PackedBits(np.packbits(bits, axis=-1), 21)
    assert pk.shape == bits.shape
    np.testing.assert_array_equal(pk[1:2, :, 1:3], bits[1:2, :, 1:3])
    np.testing.assert_array_equal(np.asarray(pk), bits)
    np.testing.assert_array_equal(np.asarray(pk, dtype=np.float32), bits.astype(np.float32))


def test_outcomes_read_packed_bits_alike(case):
    from relaff_jax.learn.results import PackedBits

    acc, correct, loo, lay, n_test = case
    _, plain, _ = extend(acc, correct, loo, lay)
    _, packed, _ = extend(acc, PackedBits(np.packbits(correct, axis=-1), correct.shape[-1]), loo, lay)
    for t in range(correct.shape[0]):
        np.testing.assert_array_equal(packed.block(t), plain.block(t))
