"""Per affordance answers (``learn.per_target``): a hand-worked case whose per target gain, its
bias-corrected interval, the best source and the samples saved are recomputed in numpy on the
same resample draws; and a run with a tenth (user) action whose means beside the paper's numbers
are the means over the nine, bit for bit, while its own values stay in its own row."""
from statistics import NormalDist

import numpy as np
import pytest

from relaff_jax import learn as E
from relaff_jax.config import override, streams
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.constants import ACTIONS
from relaff_jax.learn import gains as G
from relaff_jax.learn.analysis import _outcomes
from relaff_jax.learn.heldout import half_rep_curves
from relaff_jax.learn.intervals import scene_halves
from relaff_jax.learn.measures import _quiet
from relaff_jax.learn.online import extend
from relaff_jax.learn.results import load_results
from relaff_jax.learn.synthetic_results import write_synthetic_results
from relaff_jax.provenance import derive_seed

ACTS = ["lift", "pull", "take"]
SIZES = [2, 4, 10, 25]
LAY = E.layout(3, 3)
NB = np.array([0.6, 0.7, 0.8, 0.9])
E_REP = np.array([0.02, -0.02, 0.01, -0.01])  # per repetition, common to NB and DB1 (mean 0)
F_REP = np.array([0.01, -0.01, 0.0, 0.0])  # per repetition, DB1 only (mean 0)
G_REP = np.array([0.04, -0.04, 0.03, -0.03])


def _hand_case():
    """lift: DB1 take = NB + 0.05 (+ F), pull = NB + 0.02 (helps, take always best);
    pull: DB1 lift = NB - 0.05 + F, take = NB - 0.049 - F (hurts; take best on average, not in
    every resample); take: DB1 lift = NB + G, pull = NB + G - 0.01 (a gain of 0: no evidence)."""
    acc = np.full((3, LAY["n"], len(SIZES), 4), np.nan)
    base = NB[:, None] + E_REP[None, :]  # (S, R)
    acc[:, LAY["NB"]] = base
    db1 = {(0, 2): base + 0.05 + F_REP, (0, 1): base + 0.02, (1, 0): base - 0.05 + F_REP, (1, 2): base - 0.049 - F_REP,
           (2, 0): base + G_REP, (2, 1): base + G_REP - 0.01}
    for (t, s), v in db1.items():
        acc[t, LAY["DB1"][s]] = v
    cfg = override(ExperimentConfig(), {"sizes": tuple(SIZES), "ci_resamples": 300})
    res = {"acc": acc, "sizes": np.array(SIZES), "actions": np.array(ACTS),
           "conditions": np.array(E.condition_names(ACTS, cfg.thresholds)),
           "category_masks": E.category_masks(np.eye(3), ACTS, cfg)}
    return res, cfg


def _bc(boot, est, level, tail=0.0):
    """Efron's BC interval, written apart from ``intervals.checked_interval``: the percentile
    interval instead where an end leaves less than ``tail`` of the resamples beyond it."""
    nd = NormalDist()
    below = np.mean(boot < est) + 0.5 * np.mean(boot == est)
    z0, za = nd.inv_cdf(below), nd.inv_cdf(0.5 + level / 2)
    q = np.array([nd.cdf(2 * z0 - za), nd.cdf(2 * z0 + za)])
    if q[0] < tail or 1 - q[1] < tail:
        q = np.array([(1 - level) / 2, (1 + level) / 2])
    return np.percentile(boot, 100 * q)


def test_per_target_gain_interval_source_and_saved_against_numpy_on_the_same_draws():
    res, cfg = _hand_case()
    seed = 11
    a = E.analyse(res, cfg, seed=seed)
    f = a["affordances"]
    assert f["best_row"] == "DB1 best (in-sample oracle)"  # no outcomes kept: no halves to choose on
    # the same draws as intervals.resampled_means: without outcomes only the repetitions are drawn
    rng = np.random.default_rng(derive_seed(seed, streams.INTERVALS))
    v = rng.multinomial(4, np.full(4, 0.25), size=cfg.ci_resamples) / 4  # (B, R)
    acc = res["acc"]
    window = np.isin(SIZES, [4, 10, 25])
    for t, (want_src, want_gain, want_verdict) in enumerate([("take", 0.05, "helps"), ("take", -0.049, "hurts"),
                                                              ("lift", 0.0, "no evidence")]):
        src = [s for s in range(3) if s != t]
        nb_b = v @ acc[t, LAY["NB"]].T  # (B, S)
        db_b = np.stack([v @ acc[t, LAY["DB1"][s]].T for s in src], 1)  # (B, K, S)
        pick = np.argmax(db_b.mean(-1), 1)  # best over n = 2..25: every size run
        gain_b = (db_b[np.arange(len(v)), pick] - nb_b)[:, window].mean(-1)
        mean = acc[t].mean(-1)
        best = src[int(np.argmax(mean[LAY["DB1"][src]].mean(-1)))]
        est = (mean[LAY["DB1"][best]] - mean[LAY["NB"]])[window].mean()
        assert f["source"][t] == f"DB1:{want_src}" == f"DB1:{ACTS[best]}"
        assert f["gain"][t] == pytest.approx(want_gain, abs=1e-12) and f["gain"][t] == pytest.approx(est, abs=1e-15)
        np.testing.assert_allclose(f["gain_ci"][t], _bc(gain_b, est, cfg.ci_level, cfg.ci_tail), rtol=0, atol=1e-12)
        assert f["source_share"][t] == pytest.approx(np.mean(np.asarray(src)[pick] == best))
        assert f["verdict"][t] == want_verdict
    assert f["source_share"][0] == 1.0 and 0 < f["source_share"][1] < 1  # take always wins for lift, not for pull
    # the values and intervals are Table II's per target ones (one resampling scheme)
    i_best, i_avg = E.TABLE2_ROWS.index(f["best_row"]), E.TABLE2_ROWS.index("DB1 average")
    np.testing.assert_array_equal(f["bf_best_ci"], a["per_target_ci"][i_best])
    np.testing.assert_array_equal(f["bf_average_ci"], a["per_target_ci"][i_avg])
    np.testing.assert_array_equal(f["gain_ci"], a["gain_per_target_ci"][i_best])
    # lift's samples saved: take at n = 10 is 0.85; NB reaches it halfway from n = 10 (0.80) to 25 (0.90)
    assert f["saved"][0] == pytest.approx(17.5 - 10) and not f["saved_censored"][0]
    lo, hi = f["saved_ci"][0]
    assert lo <= f["saved"][0] <= hi and hi - lo > 0


def test_without_intervals_every_verdict_is_not_measurable():
    res, cfg = _hand_case()
    f = E.analyse(res, cfg, intervals=False)["affordances"]
    assert f["verdict"] == ["not measurable"] * 3 and np.isnan(f["gain_ci"]).all()
    assert f["gain"][0] == pytest.approx(0.05)


@pytest.fixture(scope="module")
def tenth(tmp_path_factory):
    cfg = override(ExperimentConfig(), {"sizes": (2, 4, 6, 10, 25), "test_size": 40, "reps_pca": 3, "ci_resamples": 60})
    d = write_synthetic_results(tmp_path_factory.mktemp("tenth") / "res", cfg, tuple(ACTIONS) + ("drag",),
                                spaces=("pca",), seed=1)
    res = load_results(d)["pca"]
    return res, cfg, E.analyse(res, cfg, seed=4)


def _nine(x):
    """The nine-only mean over the last axis (the tenth action is last)."""
    with _quiet():
        return np.nanmean(np.asarray(x)[..., :9], -1)


def test_a_tenth_action_is_in_no_mean_beside_the_paper_and_has_its_own_row(tenth):
    res, cfg, a = tenth
    assert a["actions"][-1] == "drag" and list(a["paper"]) == [True] * 9 + [False]
    same = lambda x, y: np.testing.assert_array_equal(np.asarray(x), np.asarray(y))  # noqa: E731 (NaN == NaN)
    same(a["table2"][:, 0], _nine(a["table2_per_target"]))
    same(a["gain"][:, 0], _nine(a["gain_per_target"]))
    same(a["n_targets"], np.isfinite(a["table2_per_target"][:, :9]).sum(-1))
    m = a["methods"]
    same(m["area"], _nine(m["area_per_target"]))
    same(m["saved"], _nine(m["saved_per_target"]))
    same(m["censored"], m["censored_per_target"][:, :9].sum(-1))
    th = a["thresholds"]
    same(th["avg"], _nine(th["per_target"]))
    same(th["n_targets"], np.isfinite(th["per_target"][:, :9]).sum(-1))
    # P(improvement): its tasks are the nine
    lay = E.layout(10, len(cfg.thresholds))
    acc = np.asarray(res["acc"], float)
    loo, correct, n_test = _outcomes(res, acc)
    acc_x, corr_x, _ = extend(acc, correct, loo, lay)
    reps = half_rep_curves(acc_x, corr_x, scene_halves(n_test, res["test_positive"], corr_x.shape[-1]))
    assert reps is not None  # outcomes kept: the choosing methods' scores are held out
    x, y = G.rep_scores(acc_x, m["weights"], lay, a["sizes"], cfg, (reps, reps.mean(-1)))
    for k in range(len(G.METHODS)):
        keep = np.isfinite(x[k]).any(-1) & np.isfinite(y[k]).any(-1)
        assert keep[9]  # the tenth ran, and is left out
        assert m["poi"][k] == G.probability_of_improvement(x[k][:9][keep[:9]], y[k][:9][keep[:9]])
    # the tenth's own row: its per target values, marked as not in the paper
    f = a["affordances"]
    assert f["actions"][-1] == "drag" and f["in_paper"] == [True] * 9 + [False]
    i_best = E.TABLE2_ROWS.index(f["best_row"])
    assert f["gain"][-1] == a["gain_per_target"][i_best, -1]
    assert f["bf_average"][-1] == a["table2_per_target"][E.TABLE2_ROWS.index("DB1 average"), -1]
    assert f["saved"][-1] == m["saved_per_target"][G.METHODS.index("DB1 best"), -1]
    assert np.isfinite(f["gain_ci"][-1]).all() and f["verdict"][-1] in ("helps", "no evidence", "hurts")
    # the guard can fail: over all ten the means differ
    assert not np.array_equal(a["gain"][:, 0], np.nanmean(a["gain_per_target"], -1), equal_nan=True)
