"""Protocol, bootstrap factors, Table II, resumable sweeps and the CLI (relaff_jax.learn, relaff_jax.cli.learn)."""
import argparse
import csv

import numpy as np
import pytest

from relaff_jax import learn as E
from relaff_jax.learn.blocks import read_block, run_block
from relaff_jax.learn.results import is_complete, load_results
from relaff_jax.learn.sweep import run_experiment
from relaff_jax.config.experiment import ExperimentConfig, experiment_preset
from relaff_jax.learn.checks import check_config
from relaff_jax import learn as L
from relaff_jax.cli import learn as cli_learn
from relaff_jax.config import override
from helpers.experiments import ACTS3, TINY, synthetic3, tiny_cfg
from relaff_jax.learn import folder, sweep
from relaff_jax.provenance import derive_seed


@pytest.fixture(scope="module")
def data3():
    return synthetic3()


# --------------------------------------------------------------------- bootstrap factor


def test_bootstrap_factor_hand_worked():
    # paper III-D: a jump from 76.7 % to 90 % is a bootstrap factor of 1.5
    assert E.bootstrap_factor(0.9, 0.5 + 0.4 / 1.5) == pytest.approx(1.5)
    assert E.bootstrap_factor(0.75, 0.75) == pytest.approx(1.0)
    assert E.bootstrap_factor(0.55, 0.6) == pytest.approx(0.5)
    assert E.bootstrap_factor(0.7, 0.6, chance=0.4) == pytest.approx(1.5)
    bf = E.bootstrap_factor(np.array([0.8, 0.8, 0.8]), np.array([0.5, 0.45, 0.65]))
    assert np.isnan(bf[0])
    assert np.isnan(bf[1])
    assert bf[2] == pytest.approx(2.0)  # undefined at/below chance


def test_average_bf_over_4_to_25_hand_worked():
    sizes = [2, 3, 4, 10, 25, 26, 100]
    bf = np.array([[9.0, 9.0, 2.0, 3.0, 4.0, 50.0, 100.0], [0, 0, 1.0, np.nan, 2.0, 0, 0]])
    np.testing.assert_allclose(E.average_bf(bf, sizes, 4, 25), [3.0, 1.5])


def test_selection_hand_worked():
    sizes = [2, 10, 50, 100]
    p = np.array([[0.6, 0.70, 0.80, 0.90],   # best at 10 (0.70 > 0.69)
                  [0.6, 0.69, 0.90, 0.95],   # best mean over 2..100
                  [np.nan] * 4])            # not run: never chosen
    assert E.select_best(p, sizes, 2, 100) == 1
    assert E.select_at(p, sizes, 10) == 0
    assert E.select_best(p, sizes, 2, 10) == 0  # over 2..10 only


def test_table2_from_hand_built_accuracies():
    # three targets, conditions of a 3-action layout; constant-in-rep accuracies
    acts = list(ACTS3)
    cfg = override(ExperimentConfig(), {"sizes": (2, 4, 10, 25)})
    lay = E.layout(3, 3)
    acc = np.full((3, lay["n"], 4, 2), np.nan)
    nb = np.array([0.55, 0.6, 0.7, 0.8])
    acc[:, 0] = nb[:, None]
    # target 0: DB1 from 1 is good (bf 2 at n=4,10,25 -> P = 0.5 + 2*(P_sl-0.5)), from 2 is neutral
    acc[0, lay["DB1"][1]] = (0.5 + 2 * (nb - 0.5))[:, None]
    acc[0, lay["DB1"][2]] = nb[:, None]
    for t in (1, 2):  # targets 1, 2: every DB1 source gives bf 1.5
        for s in range(3):
            if s != t:
                acc[t, lay["DB1"][s]] = (0.5 + 1.5 * (nb - 0.5))[:, None]
    acc[:, lay["DBn"]] = nb[:, None]
    k_allowed = E.category_allowed(acts, cfg)  # categories not built from the target
    for t in range(3):
        for k in np.flatnonzero(k_allowed[t]):
            acc[t, lay["CB1"][k]] = (0.5 + 3.0 * (nb - 0.5))[:, None]
        acc[t, lay["CBn"]] = nb[:, None]
    res = {"acc": acc, "sizes": np.array(cfg.sizes), "actions": np.array(acts),
           "conditions": np.array(E.condition_names(acts, cfg.thresholds)),
           "category_masks": E.category_masks(np.eye(3), acts, cfg)}
    an = E.analyse(res, cfg, intervals=False)
    t2 = dict(zip(an["table2_rows"], an["table2"]))
    per = dict(zip(an["table2_rows"], an["table2_per_target"]))
    np.testing.assert_allclose(t2["NB"], [1, 1, 1])
    np.testing.assert_allclose(per["DB1 average"], [1.5, 1.5, 1.5])  # target 0: (2 + 1) / 2
    np.testing.assert_allclose(per["DB1 best (in-sample oracle)"], [2.0, 1.5, 1.5])
    np.testing.assert_allclose(t2["DB1 best (in-sample oracle)"], [5 / 3, 1.5, 2.0])
    np.testing.assert_allclose(t2["CB1 best (in-sample oracle)"], [3, 3, 3])
    # no category passed T = 0.5 (identity corr): CBn would be NB relabelled, so it has no value
    assert np.all(np.isnan(t2["CBn"]))
    assert "no category passed T = 0.5" in an["unmeasurable"]["CBn"]
    assert "no test outcomes" in an["unmeasurable"]["DB1 best"]  # no halves to choose on
    assert an["best_db1"][0] == lay["DB1"][1]
    assert an["ten_db1"][0] == lay["DB1"][1]
    # with no category above 0.5 (identity corr), Fig. 12's T=0.5 curve is empty, T=0 uses all
    th = an["thresholds"]
    assert th["count"] == [3, 0, 0]
    assert np.allclose(th["best_curve"][0][1:], 3.0)
    assert np.all(np.isnan(th["best_curve"][2]))


def test_informative_source_bootstraps_and_noise_does_not():
    """One bootstrap input is the label itself, another pure noise (paper-sized 6x repetition)."""
    rng = np.random.default_rng(0)
    m, test = 1600, 1500
    X = rng.normal(size=(m, 18)).astype(np.float32)
    y = X[:, 0] + X[:, 1] > 0
    boot = np.stack([y.astype(np.float32), (rng.random(m) < 0.5).astype(np.float32)])
    acts = list(ACTS3)  # target lift (0); sources pull (1) = label, take (2) = noise
    cfg = override(ExperimentConfig(), {"sizes": (2, 4, 6, 10, 16, 25), "forest.base_trees": 25, "forest.max_trees": 25})
    lay = E.layout(3, 3)
    plan = [(0, ()), (int(lay["DB1"][1]), (0,)), (int(lay["DB1"][2]), (1,))]
    reps = 12
    acc = np.full((3, lay["n"], len(cfg.sizes), reps), np.nan)
    for r in range(reps):
        test_idx, order = E.draw_rep(y, test, max(cfg.sizes), 0, 0, r)
        acc[0, :, :, r] = run_block(X, y, boot, plan, order, test_idx, cfg.sizes, 6, lay["n"], cfg.forest, (0, r))
    res = {"acc": acc, "sizes": np.array(cfg.sizes), "actions": np.array(acts),
           "conditions": np.array(E.condition_names(acts, cfg.thresholds)),
           "category_masks": E.category_masks(np.eye(3), acts, cfg)}
    an = E.analyse(res, cfg, intervals=False)
    bf_label, bf_noise = an["avg_bf"][0, lay["DB1"][1]], an["avg_bf"][0, lay["DB1"][2]]
    assert bf_label > 2.0, bf_label
    assert 0.6 < bf_noise < 1.3, bf_noise
    assert an["best_db1"][0] == lay["DB1"][1]
    assert an["ten_db1"][0] == lay["DB1"][1]
    assert an["mean"][0, lay["DB1"][1], -1] > 0.97  # the label input is learnt almost perfectly


# -------------------------------------------------------------------------- protocol


def test_condition_plan_counts_for_nine_actions():
    cfg = ExperimentConfig()
    corr = np.full((9, 9), 0.3)
    plan = E.condition_plan(L.ACTIONS, 0, corr, cfg, "pca")
    fams = [E.condition_names(L.ACTIONS, cfg.thresholds)[c].split(":")[0] for c, _ in plan]
    assert fams.count("NB") == 1
    assert fams.count("DB1") == 8
    assert fams.count("DBn") == 1
    assert fams.count("CB1") == 28
    assert fams.count("CBn") == 3  # C(8, 2): categories without the target
    dbn = dict(plan)[int(E.layout(9, 3)["DBn"])]
    assert dbn == tuple(range(1, 9))
    cbn = {c: rows for c, rows in plan if c in E.layout(9, 3)["CBn"]}
    assert [len(v) for v in cbn.values()] == [28, 28, 0]  # corr 0.3: all at T=0, 0.125; none at 0.5
    with_t = override(cfg, {"categories_with_target": True})
    assert sum(c in E.layout(9, 3)["CB1"] for c, _ in E.condition_plan(L.ACTIONS, 0, corr, with_t, "pca")) == 36
    rhf = E.condition_plan(L.ACTIONS, 0, corr, cfg, "rhf")
    assert len(rhf) == 9  # NB + 8 DB1 (the paper shows only those in RHF)


def test_pools_are_disjoint_and_too_small_data_is_an_error():
    cfg = ExperimentConfig()
    p = E.split_pools(10000, 2, cfg, seed=5)
    assert len(p["source"]) == 2000
    assert len(p["corr"]) == 500
    assert len(p["target"]) == 7500
    allidx = np.concatenate([p["source"], p["corr"], p["target"]])
    assert len(np.unique(allidx)) == 10000
    with pytest.raises(ValueError, match="pull: 5000 samples, but the protocol needs 6600"):
        E.split_pools(5000, 2, cfg, seed=5)
    q = E.split_pools(1000, 2, override(cfg, {"shrink_to_data": True}), seed=5)
    assert len(q["source"]) == 400
    assert len(q["corr"]) == 100
    assert int(q["test_size"]) == 400
    labels = np.random.default_rng(0).random(len(q["target"])) < 0.5
    test, order = E.draw_rep(labels, int(q["test_size"]), 100, 0, 2, 1)
    assert len(np.intersect1d(test, order)) == 0
    assert len(order) == 100
    assert labels[test].sum() == len(test) // 2
    assert len(test) >= int(q["test_size"]) - 1


def test_source_outputs_are_the_source_predictor_on_target_scenes_in_its_order(data3):
    cfg = tiny_cfg()
    prep = E.prepare(data3, "pca", cfg, seed=9)
    # reference: source 'take' (toy first) applied to 'lift' target scenes (base first in lift's state)
    pools = {a: E.split_pools(200, L.ACTIONS.index(a), cfg, 9) for a in ACTS3}
    src = pools["take"]["source"]
    d = data3["take"]
    f = L.fit_forest(L.state_features(d["pca"][src], None, "take", "pca"), d["label"][src],
                     derive_seed(9, 2, 0, L.ACTIONS.index("take")), cfg.forest)
    tgt = pools["lift"]["target"]
    np.testing.assert_array_equal(prep["target:lift"], tgt)
    expect = L.predict_class(f, L.state_features(data3["lift"]["pca"][tgt], None, "take", "pca"))
    np.testing.assert_array_equal(prep["boot:lift"][2], expect)
    assert prep["boot:lift"].shape == (3 + 3, len(tgt))
    assert prep["corr"].shape == (3, 3)
    assert int(prep["corr_n"]) == 3 * 20
    for a in ACTS3:  # source/corr pools never overlap the target pool
        assert not np.intersect1d(pools[a]["target"], np.concatenate([pools[a]["source"], pools[a]["corr"]])).size


def test_forests_per_space_hand_worked():
    paper = experiment_preset("paper")  # 9 actions, 99 sizes, 50 PCA / 25 RHF repetitions
    # PCA: 9 sources + 36 categories, then per target NB + 8 DB1 + DBn + 28 CB1 + 3 CBn = 41 forests
    # per size, and per repetition 10 leave-one-out forests for each of the 8 + 28 candidates
    assert E.forests_per_space(paper, 9, "pca") == 9 + 36 + 9 * (41 * 99 + 36 * 10) * 50 == 1_988_595
    # RHF runs NB and DB1 only: no categories
    assert E.forests_per_space(paper, 9, "rhf") == 9 + 9 * (9 * 99 + 8 * 10) * 25 == 218_484
    with_t = override(paper, {"categories_with_target": True})
    assert E.forests_per_space(with_t, 9, "pca") == 9 + 36 + 9 * ((1 + 8 + 1 + 36 + 3) * 99 + 44 * 10) * 50
    # with the correlations, CBn sets that repeat another condition's share its forest:
    # corr 0.3 keeps all 28 categories at T = 0 and 0.125 (one set) and none at 0.5 (NB's)
    corr = np.full((9, 9), 0.3)
    assert E.forests_per_space(paper, 9, "pca", corr) == 9 + 36 + 9 * (39 * 99 + 36 * 10) * 50


def _count_fits(monkeypatch):
    from relaff_jax.learn import blocks, prep
    from relaff_jax.learn.forest import engine

    n = {"fits": 0}
    real, real_many = engine.fit, engine.fit_many  # what prep and the sweep fit with (any engine)

    def counting(*args, **kwargs):
        n["fits"] += 1
        return real(*args, **kwargs)

    def counting_many(Xs, *args, **kwargs):
        n["fits"] += len(Xs)
        return real_many(Xs, *args, **kwargs)

    monkeypatch.setattr(prep, "fit", counting)
    monkeypatch.setattr(blocks, "fit_many", counting_many)
    return n


def test_forests_per_space_is_the_number_of_fits_a_run_makes(data3, tmp_path, monkeypatch):
    n = _count_fits(monkeypatch)
    for space, online in (("pca", True), ("rhf", False)):  # with and without the leave-one-out forests
        cfg = tiny_cfg(sizes=(2, 4, 10), conditions_rhf=("NB", "DB1", "CBn"), online_select=online, reps_pca=1)
        n["fits"] = 0
        path = run_experiment(data3, tmp_path / space, cfg, [space], seed=1, jobs=1, progress=False)[space]
        res = np.load(path)
        exact = E.forests_per_space(cfg, 3, space, res["corr"])
        assert n["fits"] == exact == int(res["new_fits"]) + 3 + 3  # sweep + 3 sources + 3 categories
        # before the run (no correlations) every condition counts as its own forest: an upper bound
        assert E.forests_per_space(cfg, 3, space) >= exact


# ----------------------------------------------------------------- sweeps and resuming


def test_sweep_reproducible_and_resumes_after_interruption(data3, tmp_path, monkeypatch):
    cfg = tiny_cfg()
    full = run_experiment(data3, tmp_path / "a", cfg, ["pca"], seed=2, jobs=1, progress=False)["pca"]
    a = np.load(full)
    acc = a["acc"]
    assert acc.shape == (3, E.layout(3, 3)["n"], 4, 2)
    assert np.all(np.isfinite(acc[:, 0]))
    assert np.all((acc >= 0) | np.isnan(acc))
    assert np.nanmax(acc) <= 1
    lay = E.layout(3, 3)
    for t in range(3):
        assert np.all(np.isnan(acc[t, lay["DB1"][t]]))  # no self-bootstrapping

    # interrupted run: the third block raises (like a kill), then a rerun finishes the rest
    calls = {"n": 0}
    real = sweep.run_block_job

    def flaky(*args):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(sweep, "run_block_job", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(data3, tmp_path / "b", cfg, ["pca"], seed=2, jobs=1, progress=False)
    blocks = sorted((tmp_path / "b" / "pca" / "blocks").glob("*.npz"))
    assert len(blocks) == 2
    assert not (tmp_path / "b" / "pca" / "results.npz").exists()
    monkeypatch.setattr(sweep, "run_block_job", real)
    done = {p.name: p.stat().st_mtime_ns for p in blocks}
    b = np.load(run_experiment(data3, tmp_path / "b", cfg, ["pca"], seed=2, jobs=1, progress=False)["pca"])
    np.testing.assert_array_equal(b["acc"], acc)
    assert {p.name: p.stat().st_mtime_ns for p in blocks} == done  # finished blocks were not redone
    assert int(b["new_fits"]) < int(a["new_fits"])

    # a corrupt block and a deleted block are recomputed; result identical
    bdir = tmp_path / "b" / "pca" / "blocks"
    sorted(bdir.glob("*.npz"))[0].write_bytes(b"garbage")
    sorted(bdir.glob("*.npz"))[-1].unlink()
    (tmp_path / "b" / "pca" / "results.npz").unlink()
    c = np.load(run_experiment(data3, tmp_path / "b", cfg, ["pca"], seed=2, jobs=1, progress=False)["pca"])
    np.testing.assert_array_equal(c["acc"], acc)

    # another seed gives other draws; another config in the same folder is refused
    other = np.load(run_experiment(data3, tmp_path / "c", cfg, ["pca"], seed=3, jobs=1, progress=False)["pca"])
    assert not np.array_equal(other["acc"], acc, equal_nan=True)
    with pytest.raises(ValueError, match=r"different \['config.reps_pca'\]"):
        run_experiment(data3, tmp_path / "b", override(cfg, {"reps_pca": 3}), ["pca"], seed=2, jobs=1, progress=False)
    # the forest engine changes no result: the finished folder is the same experiment
    d = np.load(run_experiment(data3, tmp_path / "b", override(cfg, {"forest.engine": "sklearn"}), ["pca"], seed=2,
                                 jobs=1, progress=False)["pca"])
    np.testing.assert_array_equal(d["acc"], acc)
    changed = {a: dict(data3[a]) for a in ACTS3}
    changed["take"]["label"] = ~changed["take"]["label"]
    with pytest.raises(ValueError, match=r"different \['pca data'\]"):
        run_experiment(changed, tmp_path / "b", cfg, ["pca"], seed=2, jobs=1, progress=False)
    # a finished PCA experiment can be extended by the RHF space
    assert is_complete(tmp_path / "b", ["pca"])
    assert not is_complete(tmp_path / "b", ["pca", "rhf"])
    run_experiment(data3, tmp_path / "b", cfg, ["rhf"], seed=2, jobs=1, progress=False)
    assert is_complete(tmp_path / "b")
    assert load_results(tmp_path / "b")["meta"]["spaces"] == ["pca", "rhf"]


def test_results_outcomes_are_the_blocks_bits(data3, tmp_path):
    """The sweep holds the blocks' outcomes bit-packed: results.npz's ``correct``
    is what packing the whole bool array once gave (every block unpacked, zero-padded to
    the most test scenes), from fresh blocks and from blocks read back on a resume."""
    cfg = tiny_cfg(test_size=21, keep_outcomes=True)  # 20 scenes: a partial last byte
    path = run_experiment(data3, tmp_path / "a", cfg, ["pca"], seed=5, jobs=1, progress=False)["pca"]
    res = dict(np.load(path))
    n_cond, sizes, chunk = E.layout(3, 3)["n"], list(cfg.sizes), cfg.sizes_per_block
    n_test = res["n_test"]
    whole = np.zeros(res["acc"].shape + (int(n_test.max()),), bool)
    for ti, t in enumerate(ACTS3):
        for r in range(cfg.reps_pca):
            for ci in range(0, len(sizes), chunk):
                got = read_block(folder.block(tmp_path / "a" / "pca", t, r, ci // chunk), n_cond, sizes[ci : ci + chunk])
                whole[ti, :, ci : ci + chunk, r, : n_test[ti]] = got["correct"]
    np.testing.assert_array_equal(res["correct"], np.packbits(whole, axis=-1))
    assert res["correct"].shape[-1] == 3 and list(n_test) == [20, 20, 20]
    ran = np.isfinite(res["acc"])
    np.testing.assert_array_equal(whole.mean(-1)[ran], res["acc"][ran])
    (tmp_path / "a" / "pca" / "results.npz").unlink()  # resumed from the block files alone
    again = np.load(run_experiment(data3, tmp_path / "a", cfg, ["pca"], seed=5, jobs=1, progress=False)["pca"])
    for k in res:
        if k not in ("seconds", "seconds_prep", "new_fits"):
            np.testing.assert_array_equal(again[k], res[k])


def test_two_processes_give_the_same_bits_as_one(data3, tmp_path):
    cfg = tiny_cfg(sizes=(2, 10), reps_pca=1, reps_rhf=1)
    one = run_experiment(data3, tmp_path / "one", cfg, ["pca", "rhf"], seed=4, jobs=1, progress=False)
    two = run_experiment(data3, tmp_path / "two", cfg, ["pca", "rhf"], seed=4, jobs=2, progress=False)
    for s in ("pca", "rhf"):
        x, y = np.load(one[s]), np.load(two[s])
        for k in ("acc", "corr", "correct", "n_test", "acc_subset", "loo"):  # the outcomes come back packed
            np.testing.assert_array_equal(x[k], y[k])
        assert x["correct"].any()
    rhf = np.load(one["rhf"])["acc"]
    assert np.all(np.isnan(rhf[:, E.layout(3, 3)["DBn"]]))  # RHF runs NB and DB1 only


def test_bad_inputs_are_clear_errors(data3, tmp_path):
    with pytest.raises(ValueError, match="at least two actions"):
        run_experiment({"lift": data3["lift"]}, tmp_path / "x", tiny_cfg(), ["pca"])
    bad = {a: dict(data3[a]) for a in ACTS3}
    bad["pull"]["pca"] = bad["pull"]["pca"][:, :17]
    with pytest.raises(ValueError, match=r"pull: pca must be \(N, 18\)"):
        run_experiment(bad, tmp_path / "x", tiny_cfg(), ["pca"])
    nofeat = {a: {k: v for k, v in data3[a].items() if k != "rhf"} for a in ACTS3}
    with pytest.raises(ValueError, match="no 'rhf' array"):
        run_experiment(nofeat, tmp_path / "x", tiny_cfg(), ["rhf"])
    with pytest.raises(ValueError, match=r"'experiment.select_size' \(with 'experiment.sizes'\) \(10, 'best after ten'\) must be one of sizes"):
        check_config(tiny_cfg(sizes=(2, 4, 25)))
    with pytest.raises(ValueError, match="unknown preset"):
        experiment_preset("huge")


# ------------------------------------------------------------------------------- CLI


@pytest.mark.slow  # a whole synthetic sweep and report through the CLI
def test_cli_experiment_and_report(tmp_path):
    parser = argparse.ArgumentParser()
    cli_learn.register(parser.add_subparsers(dest="command"))
    sets = []
    for k, v in dict(TINY, reps_pca=1, sizes=[2, 10]).items():
        v = list(v) if isinstance(v, tuple) else str(v).lower() if isinstance(v, bool) else v
        sets += ["--set", f"experiment.{k}={v}".replace(" ", "")]
    args = parser.parse_args(["experiment", "--synthetic", "150", "--out", str(tmp_path / "res"), "--space", "both",
                              "--jobs", "1", "--seed", "1", "--no-progress"] + sets)
    assert args.func(args) == 0
    res = load_results(tmp_path / "res")
    assert res["config"].sizes == (2, 10)
    assert res["pca"]["acc"].shape == (9, 50, 2, 1)
    args = parser.parse_args(["report", str(tmp_path / "res"), "--out", str(tmp_path / "rep")])
    assert args.func(args) == 0
    with open(tmp_path / "rep" / "table2.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["method", "avg", "min", "max", "paper_avg", "paper_min", "paper_max", "n_targets", "ci_low",
                       "ci_high", "gain_avg", "gain_ci_low", "gain_ci_high", "not_measurable"]
    assert [r[0] for r in rows[1:]] == list(E.TABLE2_ROWS)
    assert rows[1][1:7] == ["1.0000"] * 6  # NB is 1 by definition, in the paper too
    by = {r[0]: r for r in rows[1:]}
    assert by["DB1 best (in-sample oracle)"][4:7] == ["2.8190", "0.9760", "3.6570"]  # paper's DB1 best: chosen in sample
    assert by["DB1 best"][4:7] == ["-"] * 3  # the held-out row is not in the paper ("-": no value)
    assert by["DB1 best after ten (online)"][4:7] == ["-"] * 3  # nor the online row
    assert (tmp_path / "rep" / "table2_rhf.csv").exists()
    md = (tmp_path / "rep" / "table2.md").read_text()
    assert "| DB1 best after ten |" in md
    assert "Categories built per threshold" in md
    for fig in ("fig06_nb_learning", "fig07_nb_spaces", "fig08_db1_best", "fig09_db1_best_bf",
                "fig10_average_bf", "fig11_correlation", "fig12_thresholds"):
        assert (tmp_path / "rep" / f"{fig}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(FileNotFoundError, match="not an experiment folder"):
        load_results(tmp_path / "rep")


def test_cli_out_paths_are_checked_before_any_work(tmp_path):
    from relaff_jax.errors import UserError

    parser = argparse.ArgumentParser()
    cli_learn.register(parser.add_subparsers(dest="command"))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    results = tmp_path.parent / f"{tmp_path.name}_results"  # looks like an experiment folder (checked first)
    results.mkdir()
    (results / "experiment.json").write_text("{}")
    for argv in (["experiment", "--synthetic", "150", "--out", str(blocker / "res")],
                 ["experiment", "--synthetic", "150", "--out", str(blocker)],
                 ["report", str(results), "--out", str(blocker / "rep")]):
        args = parser.parse_args(argv)
        with pytest.raises(UserError, match="file"):
            args.func(args)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing was made
    args = parser.parse_args(["experiment", "--out", str(tmp_path / "res")])
    with pytest.raises(UserError, match="give --data"):
        args.func(args)
    args = parser.parse_args(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "rep")])
    with pytest.raises(UserError, match="not an experiment folder"):
        args.func(args)


def test_cli_space_is_the_tree_key_it_aliases(tmp_path):
    """``--space`` is ``reproduce.spaces`` (what ``stages.experiment.experiment_folder`` sweeps
    and records): a ``--set`` of the key that disagrees is refused before any work."""
    from relaff_jax.errors import UserError

    parser = argparse.ArgumentParser()
    cli_learn.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["experiment", "--synthetic", "150", "--out", str(tmp_path / "res"), "--space", "pca",
                              "--set", 'reproduce.spaces=["rhf"]'])
    with pytest.raises(UserError, match="--space .* and --set reproduce.spaces=.* disagree"):
        args.func(args)
    assert not (tmp_path / "res").exists()


def test_experiment_stage_checks_its_inputs_before_any_work(tmp_path):
    import re

    from relaff_jax.errors import UserError
    from relaff_jax.config import RunConfig
    from relaff_jax.stages.experiment import experiment_folder

    tree = RunConfig(experiment=tiny_cfg())
    missing = tmp_path / "none"
    for data in ([missing], str(missing)):  # a folder given alone is one folder, not its name's characters
        with pytest.raises(UserError, match=f"^{re.escape(str(missing))}: no such dataset directory"):
            experiment_folder(tree, data, tmp_path / "res")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(UserError, match="is a file"):
        experiment_folder(tree, 150, blocker)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
