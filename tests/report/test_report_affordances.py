"""The report's per-affordance answer on a synthetic experiment with a tenth (user) action (no
simulation, no fits): report.md / report.html's table, affordances.csv and summary.json's
``affordances`` hold one row per space and affordance with the analysis' values, the tenth
marked "not in the paper"; Table II's, the methods block's and the findings' means rest on the
paper's nine, and the text says so."""
import csv
import io
import json

import numpy as np
import pytest

from relaff_jax import learn as E
from relaff_jax.config import override
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.constants import ACTIONS
from relaff_jax.learn.results import load_results
from relaff_jax.learn.synthetic_results import write_synthetic_results
from relaff_jax.report.affordances import CSV_COLUMNS
from relaff_jax.report.write import write_report

ROW_KEYS = {"in_paper", "note", "bf_average", "bf_average_ci", "bf_best", "bf_best_ci", "best_source",
            "best_source_share", "gain", "gain_ci", "samples_saved", "samples_saved_ci", "samples_saved_censored",
            "verdict"}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    cfg = override(ExperimentConfig(), {"sizes": (2, 4, 6, 10, 25), "test_size": 40, "reps_pca": 3, "reps_rhf": 3,
                                        "ci_resamples": 50})
    root = tmp_path_factory.mktemp("aff")
    write_synthetic_results(root / "res", cfg, tuple(ACTIONS) + ("drag",), spaces=("pca", "rhf"), seed=2)
    out = write_report(root / "res", root / "rep", examples_per_action=0)
    res = load_results(root / "res")
    an = {s: E.analyse(res[s], res.config, seed=int(res["meta"]["seed"])) for s in ("pca", "rhf")}
    return out, an


def test_summary_and_csv_hold_every_affordance_with_its_interval_and_verdict(report):
    out, an = report
    s = json.loads((out / "summary.json").read_text())
    rows = list(csv.DictReader(io.StringIO((out / "affordances.csv").read_text())))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == 20
    for space in ("pca", "rhf"):
        f, j = an[space]["affordances"], s[space]["affordances"]
        assert j["best_row"] == "DB1 best" and j["samples_saved_method"] == "DB1 best" and j["ci_level"] == 0.95
        assert sorted(j["rows"]) == sorted(list(ACTIONS) + ["drag"])  # JSON keys are written sorted
        by = {r["affordance"]: r for r in rows if r["space"] == space}
        for i, t in enumerate(f["actions"]):
            r, c = j["rows"][t], by[t]
            assert set(r) == ROW_KEYS
            assert r["in_paper"] == (t != "drag") and c["in_paper"] == ("yes" if t != "drag" else "no")
            assert r["note"] == (None if t != "drag" else "not in the paper")
            assert r["gain"] == pytest.approx(f["gain"][i]) and float(c["gain"]) == pytest.approx(f["gain"][i], abs=1e-4)
            lo, hi = r["gain_ci"]
            assert lo <= r["gain"] <= hi  # a BC interval of a statistic linear in the accuracies holds its estimate
            assert float(c["gain_ci_low"]) == pytest.approx(lo, abs=1e-4)
            assert r["verdict"] == c["verdict"] == ("helps" if lo > 0 else "hurts" if hi < 0 else "no evidence")
            assert r["bf_best_ci"] == pytest.approx(list(an[space]["per_target_ci"][E.TABLE2_ROWS.index("DB1 best"), i]),
                                                    nan_ok=True)
            assert c["best_source"] == r["best_source"] == an[space]["conditions"][an[space]["best_db1"][i]][4:]


def test_the_report_shows_the_tenth_apart_and_says_what_each_mean_rests_on(report):
    out, an = report
    md, html = (out / "report.md").read_text(), (out / "report.html").read_text()
    assert "## Per affordance: does what the robot knows help it?" in md and "does what the robot knows help it?" in html
    sec = md[md.index("## Per affordance"):]
    assert sec.count("| drag (not in the paper) |") == 2  # one row per space
    for t in ACTIONS:
        assert f"| {t} |" in sec
    assert "Every column rests on the paper's affordances only (9 of 10;" in md  # the methods block
    assert "Every mean behind a verdict is over the paper's affordances only" in md  # the findings
    t2md = (out / "table2.md").read_text()
    assert t2md.count("| drag (not in the paper) |") >= 2 and "### Per affordance: does what the robot knows help it? (RHF)" in t2md
    assert md.count("of 9 affordances (the paper's; drag: not in the paper, left out), by row") == 2  # Table II, per space
    # Table II's avg and the findings' DB1 best are the nine's means
    s = json.loads((out / "summary.json").read_text())["pca"]
    per = s["table2_per_affordance"]["DB1 best"]
    nine = [per[t] for t in ACTIONS if per[t] is not None]
    assert s["table2"]["DB1 best"]["avg"] == pytest.approx(np.mean(nine), rel=1e-12)
    found = {f["id"]: f for f in json.loads((out / "findings.json").read_text())["findings"]}
    assert found["bootstrapping_helps"]["values"]["db1_best"] == pytest.approx(np.mean(nine), rel=1e-12)
    nb = [np.nanmean(an["pca"]["mean"][:9, 0, an["pca"]["sizes"].index(n)]) for n in (2, 4, 6, 10)]
    assert found["rhf_faster"]["values"]["pca"] == pytest.approx(nb, rel=1e-12)
