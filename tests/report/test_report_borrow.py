"""The per-affordance 'what one source can lend' table (report/borrow.py): the rank
correlation against scipy, and the table's columns on a hand-made analysis."""
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from relaff_jax.learn import TABLE2_ROWS, layout
from relaff_jax.report.borrow import borrow_blocks, borrow_rows, ranks, spearman


def test_ranks_average_ties():
    np.testing.assert_array_equal(ranks(np.array([3.0, 1.0, 3.0, 2.0])), [3.5, 1.0, 3.5, 2.0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_spearman_matches_scipy(seed):
    rng = np.random.default_rng(seed)
    x = np.round(rng.normal(size=12), 1)  # rounded: ties happen
    y = x + rng.normal(size=12)
    assert spearman(x, y) == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)


def test_spearman_skips_nan_and_needs_three_pairs():
    assert spearman([1.0, 2.0, np.nan, 4.0], [1.0, 3.0, 0.0, 2.0]) == pytest.approx(0.5)
    assert np.isnan(spearman([1.0, 2.0], [2.0, 1.0]))


def test_borrow_rows_hand_worked():
    acts = ["a", "b", "c"]
    cfg = SimpleNamespace(bf_sizes=(4, 25), thresholds=(0.0, 0.125, 0.5))
    sizes = np.array([2, 4, 10, 25, 50])
    n_cond = layout(3, 3)["n"]
    mean = np.full((3, n_cond, len(sizes)), 0.7)
    mean[:, 0] = [[0.5, 0.55, 0.6, 0.65, 0.7], [0.5, 0.6, 0.7, 0.8, 0.9], [0.5, 0.52, 0.54, 0.56, 0.58]]  # NB
    per_target = np.full((len(TABLE2_ROWS), 3), np.nan)
    per_target[TABLE2_ROWS.index("DB1 average")] = [3.0, 1.0, 2.0]
    corr = np.array([[1.0, -0.9, 0.2], [-0.9, 1.0, 0.1], [0.2, 0.1, 1.0]])
    a = {"actions": acts, "sizes": sizes, "mean": mean, "table2_per_target": per_target}
    r = borrow_rows({"corr": corr, "corr_stacked": np.array([0.8, -0.7, 0.0])}, a, cfg)
    np.testing.assert_array_equal(r["best_corr"], [-0.9, -0.9, 0.2])
    assert r["best_with"] == ["b", "a", "a"]
    assert r["nb_sizes"] == [4, 25]  # the window's first and last size that ran
    np.testing.assert_allclose(r["nb_lo"], [0.55, 0.6, 0.52])
    np.testing.assert_allclose(r["nb_hi"], [0.65, 0.8, 0.56])
    # |best corr| 0.9, 0.9, 0.2 against 3, 1, 2: ranks (2.5, 2.5, 1) and (3, 1, 2)
    assert r["spearman"] == pytest.approx(stats.spearmanr([0.9, 0.9, 0.2], [3, 1, 2]).statistic)
    assert np.isnan(r["db1_ci"]).all()  # no intervals in this analysis: shown as absent, not invented
    (_, text), (_, header, table) = borrow_blocks(r, "pca")
    assert "over the 3 affordances" in text
    assert table[0][:4] == ["a", "3.00", "-", "-0.90 (b)"]
    assert len(header) == len(table[0])
