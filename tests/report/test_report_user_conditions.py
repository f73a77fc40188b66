"""A registered condition in the report: a small experiment on synthetic data (no simulation)
with a condition of variants (VOTE) and one of a single learner (ALL) registered in the test;
the report's Table II (table2.csv, table2.md, report.md), its per affordance table, its chosen
sources and summary.json show each beside the paper's rows, marked "not in the paper", with the
values of ``learn.user_rows`` and a gain checked by hand from the stored accuracies."""
import csv
import io
import json

import numpy as np
import pytest

from relaff_jax.config import RunConfig, override
from relaff_jax.config.experiment import experiment_preset
from relaff_jax.learn import conditions as C
from relaff_jax.learn.results import load_results
from relaff_jax.learn.measures import size_mask
from relaff_jax.learn.user_rows import user_rows
from relaff_jax.report.write import write_report

ACTS = ("lift", "pull", "take")


def _vote(k):
    """Share of the other actions' predictors saying yes, and whether any does."""
    s = np.stack(list(k.sources.values()))
    return {"share": s.mean(0)[:, None], "any": s.max(0)[:, None]}


def _all(k):
    return k.repeated(*k.sources.values())


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    from relaff_jax.stages.experiment import experiment_folder

    saved = dict(C._REGISTRY)
    C.register_condition("VOTE", _vote)
    C.register_condition("ALL", _all)
    try:
        exp = override(experiment_preset("quick"), {
            "sizes": (2, 4, 6, 10), "reps_pca": 3, "test_size": 40, "source_size": 40, "corr_scenes": 15,
            "conditions_pca": ("NB", "DB1", "VOTE", "ALL"), "forest.base_trees": 8, "forest.max_trees": 8,
            "ci_resamples": 40})
        tree = override(RunConfig(experiment=exp), {"reproduce.actions": ACTS, "reproduce.spaces": ("pca",)})
        root = tmp_path_factory.mktemp("user_cond")
        experiment_folder(tree, 160, root / "res", seed=2, jobs=1, progress=False)
    finally:
        C._REGISTRY.clear()
        C._REGISTRY.update(saved)
    out = write_report(root / "res", root / "report", examples_per_action=0)
    return root / "res", out


def test_the_tables_show_each_user_condition_beside_the_paper_rows(folders):
    res_dir, out = folders
    res = load_results(res_dir)
    u = user_rows(res["pca"], res.config, seed=2)
    names = ["VOTE average", "VOTE best", "VOTE best after ten", "ALL"]
    assert u["names"] == names
    rows = {r["method"]: r for r in csv.DictReader(io.StringIO((out / "table2.csv").read_text()))}
    assert "NB" in rows and "DB1 best" in rows
    for i, name in enumerate(names):
        r = rows[name]
        assert r["paper_avg"] == "-" and float(r["avg"]) == pytest.approx(u["table2"][i, 0], abs=1e-4)
        assert float(r["gain_avg"]) == pytest.approx(u["gain"][i, 0], abs=1e-4)
        assert float(r["ci_low"]) <= float(r["avg"]) <= float(r["ci_high"])
        assert float(r["gain_ci_low"]) <= float(r["gain_avg"]) <= float(r["gain_ci_high"])
    md, report = (out / "table2.md").read_text(), (out / "report.md").read_text()
    for name in names:
        assert f"| {name} (not in the paper) |" in md and f"| {name} (not in the paper) |" in report
    for text in (md, report):  # the chosen variants
        assert "VOTE best (not in the paper): lift <- (" in text
        assert "VOTE best after ten (not in the paper): lift <- (" in text
    s = json.loads((out / "summary.json").read_text())["pca"]["user_conditions"]
    assert s["note"] == "not in the paper" and sorted(s["rows"]) == sorted(names)
    assert set(s["best"]["VOTE"].values()) <= {"share", "any"} and set(s["best"]["VOTE"]) == set(ACTS)


def test_a_user_row_s_gain_is_its_accuracy_over_nb_by_hand(folders):
    """ALL's gain per target: mean over the window's sizes of (mean accuracy of its learner -
    NB's), read from the stored accuracies; the row's average over the targets."""
    res_dir, out = folders
    res = load_results(res_dir)
    r, cfg = res["pca"], res.config
    c = list(r["conditions"]).index("ALL")
    acc = np.asarray(r["acc"], dtype=float)
    w = size_mask(r["sizes"], *cfg.bf_sizes)
    hand = (acc[:, c].mean(-1) - acc[:, 0].mean(-1))[:, w].mean(-1)  # (A,)
    s = json.loads((out / "summary.json").read_text())["pca"]["user_conditions"]["rows"]["ALL"]
    np.testing.assert_allclose([s["gain_per_affordance"][t] for t in ACTS], hand, rtol=0, atol=1e-12)
    assert s["gain"] == pytest.approx(hand.mean(), abs=1e-12)
    assert s["per_affordance_ci"] is not None and s["ci"] is not None
