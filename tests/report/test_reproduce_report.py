"""The reproduction report (report.md / report.html): findings, clusters, rendering, and the
whole report on a results folder of `relaff experiment --synthetic` plus small datasets of
real settled scenes (labels from a test rule, not from the arm's actions)."""
import base64
import json
import os
import shutil
import re
import subprocess
import sys

import jax
import numpy as np
import pytest

from relaff_jax import cli
from relaff_jax.config import override
from relaff_jax import data as dataset
from relaff_jax import learn as E
from relaff_jax.learn.results import load_results
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax import report as R
from relaff_jax.report.write import write_report

# ------------------------------------------------------------------- findings, by hand


def _analysis(nb_pca, nb_rhf, rows, best_curves, counts=(36, 5, 2), spread=0.01):
    """A minimal ``analyse`` output: NB means per size, Table II averages, threshold averages,
    and resamples of each spread evenly by +-``spread`` around its value (paired: the same
    offsets in every quantity, so a difference of two equal values has a zero-width interval)."""
    sizes = [2, 4, 10, 25]
    acts = ["lift", "move", "pull"]
    off = np.linspace(-spread, spread, 201)[:, None]  # (B, 1)

    def space(nb, table):
        mean = np.full((3, 5, 4), np.nan)
        mean[:, 0] = np.asarray(nb)[None]
        t2 = np.ones((len(E.TABLE2_ROWS), 3))
        for name, v in table.items():
            t2[E.TABLE2_ROWS.index(name), 0] = v
        avg = np.array(best_curves, dtype=float)
        th = {"T": [0.0, 0.125, 0.5], "best_curve": np.stack([np.full(4, c) for c in best_curves]),
              "count": list(counts), "overall_curve": np.ones(4), "avg": avg}
        return {"sizes": sizes, "actions": acts, "mean": mean, "table2": t2, "thresholds": th,
                "table2_boot": t2[:, 0][None] + off, "threshold_boot": avg[None] + off,
                "nb_boot": np.asarray(nb, dtype=float)[None] + off}

    return {"pca": space(nb_pca, rows), "rhf": space(nb_rhf, {})}


CFG = ExperimentConfig(sizes=(2, 4, 10, 25))
GOOD = {"DB1 best": 2.0, "CBn": 1.6, "DBn": 1.5, "DB1 best after ten": 1.9, "CB1 best": 2.2, "CB1 best after ten": 2.1}


def verdicts(an):
    return {f["id"]: f["verdict"] for f in R.findings(an, CFG)}


def test_findings_hand_worked():
    an = _analysis([0.6, 0.65, 0.7, 0.8], [0.62, 0.7, 0.71, 0.79], GOOD, [2.0, 1.95, 1.9])
    got = R.findings(an, CFG)
    assert [f["id"] for f in got] == ["rhf_faster", "bootstrapping_helps", "dbn_below_db1", "pruning_cheap", "best_after_ten"]
    assert all(f["verdict"] == "reproduced" for f in got)
    assert all(f["reproduced"] is True for f in got)
    f = {x["id"]: x for x in got}
    # n <= 10: RHF - PCA = +0.02, +0.05, +0.01 -> mean +0.0267; paired resamples: interval of zero width
    assert f["rhf_faster"]["values"]["sizes"] == [2, 4, 10]
    assert f["rhf_faster"]["values"]["difference"] == pytest.approx(0.08 / 3)
    assert f["rhf_faster"]["claims"][0]["interval"] == [pytest.approx(0.08 / 3)] * 2
    assert "+0.027" not in f["rhf_faster"]["numbers"]
    assert "0.027 [0.027, 0.027] (claim > 0)" in f["rhf_faster"]["numbers"]
    assert f["pruning_cheap"]["values"]["avg_bf"] == [pytest.approx(2.0), pytest.approx(1.9)]
    assert f["pruning_cheap"]["values"]["built"] == [36, 2]
    assert "ratio 0.95 [" in f["pruning_cheap"]["numbers"]
    assert f["best_after_ten"]["values"]["DB1"]["ratio"] == pytest.approx(0.95)
    lo, hi = f["bootstrapping_helps"]["claims"][0]["interval"]  # DB1 best 2.0 +- 0.01
    assert 1.98 < lo < 2.0 < hi < 2.02
    assert "bootstrap interval (bias-corrected, or the percentile interval" in f["dbn_below_db1"]["decision"]

    assert verdicts(_analysis([0.6] * 4, [0.59] * 4, GOOD, [2.0, 1.9, 1.9]))["rhf_faster"] == "not reproduced"
    assert verdicts(_analysis([0.6] * 4, [0.7] * 4, dict(GOOD, CBn=1.2), [2.0] * 3))["bootstrapping_helps"] == "not reproduced"
    assert verdicts(_analysis([0.6] * 4, [0.7] * 4, dict(GOOD, DBn=2.1), [2.0] * 3))["dbn_below_db1"] == "not reproduced"
    assert verdicts(_analysis([0.6] * 4, [0.7] * 4, GOOD, [2.0, 2.0, 1.7]))["pruning_cheap"] == "not reproduced"  # 0.85 < 0.9
    assert verdicts(_analysis([0.6] * 4, [0.7] * 4, dict(GOOD, **{"CB1 best after ten": 1.9}), [2.0] * 3))["best_after_ten"] == "not reproduced"
    # undefined numbers (no category kept at T = 0.5; no RHF sweep) are "not measurable"
    v = verdicts(_analysis([0.6] * 4, [0.7] * 4, GOOD, [2.0, 1.9, np.nan]))
    assert v["pruning_cheap"] == "not measurable"
    # CBn with no category kept at its threshold (T = 0.5): not measurable, whatever number the row holds
    f = {x["id"]: x for x in R.findings(_analysis([0.6] * 4, [0.7] * 4, dict(GOOD, CBn=1.0), [2.0] * 3,
                                                 counts=(36, 5, 0)), CFG)}
    assert f["bootstrapping_helps"]["verdict"] == "not measurable"
    assert f["bootstrapping_helps"]["reproduced"] is None
    assert "no category passed T = 0.5: CBn is not measurable" in f["bootstrapping_helps"]["numbers"]
    an = _analysis([0.6] * 4, [0.7] * 4, GOOD, [2.0] * 3)
    del an["rhf"]
    assert verdicts(an)["rhf_faster"] == "not measurable"
    # no resamples (intervals not computed): nothing can be decided
    an = _analysis([0.6] * 4, [0.7] * 4, GOOD, [2.0] * 3)
    for s in an.values():
        del s["table2_boot"], s["threshold_boot"], s["nb_boot"]
    assert set(verdicts(an).values()) == {"not measurable"}


def test_verdicts_whose_interval_crosses_the_bound_are_undecided():
    # DBn 1.95 vs DB1 best 2.0, each resampled +-0.1 independently (not paired): DBn - DB1 in
    # about [-0.15, +0.05], which contains 0 -> undecided, though the point difference is < 0
    an = _analysis([0.6] * 4, [0.61] * 4, dict(GOOD, DBn=1.95), [2.0] * 3, spread=0.1)
    pca = an["pca"]
    rng = np.random.default_rng(0)
    for name in ("DBn",):
        i = E.TABLE2_ROWS.index(name)
        pca["table2_boot"][:, i] = rng.permutation(pca["table2_boot"][:, i])  # break the pairing
    got = {f["id"]: f for f in R.findings(an, CFG)}
    j = got["dbn_below_db1"]["claims"][0]
    assert j["estimate"] == pytest.approx(-0.05)
    assert j["interval"][0] < 0 < j["interval"][1]
    assert got["dbn_below_db1"]["verdict"] == "undecided at this scale"
    assert got["dbn_below_db1"]["reproduced"] is None
    # RHF 0.01 above PCA, each NB resampled +-0.1 independently: the interval holds 0 -> undecided
    an["rhf"]["nb_boot"] = rng.permutation(an["rhf"]["nb_boot"])
    got = {f["id"]: f for f in R.findings(an, CFG)}
    assert got["rhf_faster"]["verdict"] == "undecided at this scale"
    # hand-made: an estimate 1.3 whose interval [1.2, 1.4] holds the bound 1.25
    j = R.judge(1.3, np.linspace(1.2, 1.4, 101), 1.25, True, 0.95)
    assert j["verdict"] == "undecided at this scale"
    assert R.judge(1.3, np.linspace(1.26, 1.34, 101), 1.25, True, 0.95)["verdict"] == "reproduced"
    assert R.judge(1.1, np.linspace(1.0, 1.2, 101), 1.25, True, 0.95)["verdict"] == "not reproduced"
    assert R.judge(np.nan, np.linspace(1.0, 1.2, 101), 1.25, True, 0.95)["verdict"] == "not measurable"


def test_a_claim_whose_bc_end_rests_on_the_extreme_tail_is_decided_by_the_percentile_interval():
    """The paper run's "DBn below DB1 best" in the once reading, in miniature: 1,000 resampled
    differences around -0.68 with two outliers at +1.2 and +1.6, the estimate -0.64 above 73 % of
    them. BC reads its upper end at the 99.93rd percentile, between the outliers: "undecided"
    rests on them. With ``tail`` = 0.005 the percentile interval decides (wholly below 0)."""
    rng = np.random.default_rng(3)
    boot = np.concatenate([rng.normal(-0.68, 0.14, 998), [1.2, 1.6]])
    est = float(np.quantile(boot, 0.731))
    old = R.judge(est, boot, 0.0, False, 0.95)  # tail 0: bias-corrected, as before
    assert old["method"] == "BC" and old["verdict"] == "undecided at this scale" and old["interval"][1] > 1.0
    new = R.judge(est, boot, 0.0, False, 0.95, 0.005)
    assert new["method"] == "percentile" and new["verdict"] == "reproduced"
    np.testing.assert_allclose(new["interval"], np.percentile(boot, [2.5, 97.5]))
    assert new["bc_interval"] == old["interval"] and new["percentile_interval"] == new["interval"]
    from relaff_jax.report.findings import _text
    assert "percentile interval: the bias-corrected one" in _text("DBn - DB1 best", new)
    # an estimate near the resamples' median keeps the bias-corrected interval
    mid = R.judge(float(np.median(boot)), boot, 0.0, False, 0.95, 0.005)
    assert mid["method"] == "BC" and mid["interval"] == mid["bc_interval"]


def test_correlation_clusters_hand_worked():
    acts = ["a", "b", "c", "d", "e", "f"]
    corr = np.eye(6) + 0.1 * (1 - np.eye(6))
    corr[5, :5] = corr[:5, 5] = 0.0
    for i, j, v in ((0, 1, 0.6), (1, 2, 0.7), (3, 4, 0.55), (0, 5, -0.9)):
        corr[i, j] = corr[j, i] = v
    assert R.correlation_clusters(corr, acts, 0.5) == [["a", "b", "c"], ["d", "e"], ["f"]]
    assert R.correlation_clusters(corr, acts, 0.65) == [["b", "c"], ["a"], ["d"], ["e"], ["f"]]
    assert R.correlation_clusters(corr, acts, 0.05) == [acts[:5], ["f"]]


def test_numeric_columns_read_intervals_and_dashes_as_numbers():
    from relaff_jax.report.document import numeric_columns

    rows = [["lift", "0.85 [0.80, 0.90]", "infeasible", "-", "**1.2**"],
            ["move", "\u22120.02", "reach", "n/a", "nan"]]
    assert numeric_columns(list("abcde"), rows) == [False, True, False, True, True]
    assert numeric_columns(["a"], []) == [False]  # an empty column stays left-aligned


def test_render_markdown_and_html(tmp_path):
    png = b"\x89PNG\r\n\x1a\n" + bytes(range(40))
    (tmp_path / "f.png").write_bytes(png)
    blocks = [("h", 1, "Title"), ("p", "a < b & `code` **bold**"), ("ul", ["one", "two"]),
              ("table", ["x", "y"], [[1, "<2>"]]), ("img", "f.png", "a figure")]
    md = R.render_markdown(blocks)
    assert md.splitlines()[:4] == ["# Title", "", "a < b & `code` **bold**", ""]
    # a number column is right-aligned, a text column left-aligned
    assert "| x | y |\n|---:|---|\n| 1 | <2> |" in md
    assert "![a figure](f.png)" in md
    page = R.render_html(blocks, tmp_path, "t")
    assert "<p>a &lt; b &amp; <code>code</code> <b>bold</b></p>" in page
    assert '<td class="num">1</td><td class="txt">&lt;2&gt;</td>' in page
    assert "<li>two</li>" in page
    data = re.search(r'src="data:image/png;base64,([^"]+)"', page).group(1)
    assert base64.b64decode(data) == png
    with pytest.raises(ValueError, match="unknown block"):
        R.render_markdown([("video", "x")])


def test_figures_leave_the_matplotlib_backend_alone(tmp_path):
    """Library code draws on ``matplotlib.figure.Figure``: importing the report and writing a
    figure neither switches the backend (a notebook keeps its own) nor loads pyplot."""
    script = f"""
import sys, matplotlib
matplotlib.use("svg")
from relaff_jax.report.figures import dataset_figure
infos = {{"lift": {{"rollouts_positive_rate_by_relation": {{"beside": 0.1, "on_top": 0.8, "inside": None}}}}}}
p = dataset_figure(infos, __import__("pathlib").Path({str(tmp_path / "f.png")!r}))
assert p.read_bytes()[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert "matplotlib.pyplot" not in sys.modules
"""
    subprocess.run([sys.executable, "-c", script], check=True)


# ---------------------------------------------------------------------- the whole report


def test_full_report(scene_run, tmp_path):
    out = tmp_path / "report"
    data_dirs = {"lift": scene_run / "data" / "lift", "take": scene_run / "data" / "take"}
    info = {"preset": "tiny", "seed": 0, "timings": {"generate": 12.5, "report": None},
            "versions": {"jax": jax.__version__}}
    write_report(scene_run / "results", out, data_dirs, info, examples_per_action=2)
    for f in ("report.md", "report.html", "findings.json", "summary.json", "table2.csv", "fig_datasets.png",
              "fig06_nb_learning.png", "fig11_correlation.png", "fig12_thresholds.png"):
        assert (out / f).stat().st_size > 0, f
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()

    # every image of the markdown exists, and the html embeds exactly those, nothing external
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert all((out / p).is_file() for p in images)
    embedded = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert len(embedded) == len(images)
    assert 'src="http' not in page
    assert "<link" not in page
    assert [base64.b64decode(e) for e in embedded] == [(out / p).read_bytes() for p in images]

    # example scenes: two per action, a positive and a negative, drawn by features.show_scene
    examples = sorted((out / "examples").glob("*.png"))
    assert len(examples) == 4
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in examples)
    for action in data_dirs:
        caps = re.findall(rf"\*({action}: [^*]+)\*", md)
        assert len(caps) == 2
        assert "positive" in caps[0]
        assert "negative" in caps[1]

    # dataset statistics are dataset.info's
    for action, d in data_dirs.items():
        i = dataset.info(d)
        rates = " | ".join(f"{100 * i['rollouts_positive_rate_by_relation'][r]:.0f} %"
                           if i['rollouts_positive_rate_by_relation'][r] is not None else "-" for r in dataset.RELATIONS)
        assert f"| {action} | {i['n']} | {i['rollouts']} | {100 * i['rollouts_positive_rate']:.0f} % | {rates} |" in md

    # Table II, findings and clusters are the experiment's numbers
    res = load_results(scene_run / "results")
    an = {s: E.analyse(res[s], res["config"]) for s in ("pca", "rhf")}
    t2 = an["pca"]["table2"]
    from relaff_jax.report.formatting import row_cells  # a row without a value reads "not measurable: why"
    row = lambda name: f"| {name} | " + " | ".join(row_cells(an["pca"], E.TABLE2_ROWS.index(name)))
    assert row("DB1 best") in md
    assert row("CBn") in md
    assert "| 2.819 | 0.976 | 3.657 |" in md
    assert "nan" not in row("CBn")
    for i, name in enumerate(E.TABLE2_ROWS):  # every row says how many affordances it averages
        assert f"{row(name)} | {an['pca']['n_targets'][i]} of {len(an['pca']['actions'])} |" in md
    assert f"of {len(an['pca']['actions'])} affordances, by row (column n)" in md
    assert "bias-corrected (BC) bootstrap" in md
    assert "## Sizes of the protocol" in md
    assert "| test scenes (per affordance) |" in md
    found = json.loads((out / "findings.json").read_text())["findings"]
    assert [f["id"] for f in found] == [f["id"] for f in R.findings(an, res["config"])]
    by_id = {f["id"]: f for f in found}
    assert by_id["dbn_below_db1"]["values"]["dbn"] == pytest.approx(t2[E.TABLE2_ROWS.index("DBn"), 0])
    # decided from the interval of the paired difference, not from the point values
    i_dbn, i_db1 = E.TABLE2_ROWS.index("DBn"), E.TABLE2_ROWS.index(by_id["dbn_below_db1"]["values"]["db1_row"])
    j = R.judge(t2[i_dbn, 0] - t2[i_db1, 0], an["pca"]["table2_boot"][:, i_dbn] - an["pca"]["table2_boot"][:, i_db1],
                0.0, False, res["config"].ci_level, res["config"].ci_tail)
    assert by_id["dbn_below_db1"]["verdict"] == j["verdict"]
    for f in found:
        assert f"| {f['finding']} |" in md
    clusters = R.correlation_clusters(res["rhf"]["corr"], an["rhf"]["actions"], res["config"].cbn_threshold)
    groups = "; ".join("{" + ", ".join(g) + "}" for g in clusters if len(g) > 1)
    assert f"RHF: affordances linked by correlations above T = 0.5: {groups or 'none'}" in md
    assert "synthetic features" in md  # the results say where they came from
    assert "preset `tiny`, seed 0" in md
    assert "generate: 12 s" in md
    # the report's own time replaces the run log's (None: the stage had not ended), with the machine and load
    assert re.search(r"- report: \d+ s \(this document\)", md)
    assert f"{os.cpu_count()} cores" in md
    assert "load average as the report was written: " in md

    # the reach section names the datasets without a 'feasible' field; compare reads the report back
    assert "Reach or relation" in md
    assert "No anatomy for lift" in md
    reach = json.loads((out / "reach.json").read_text())
    assert reach["subsets"] == ["positives", "feasible negatives", "infeasible negatives"]
    cmp_md = tmp_path / "compare.md"
    assert cli.main(["compare", f"a={out}", f"b={out}", "--size", "10", "--out", str(cmp_md)]) == 2  # one folder twice
    shutil.copytree(out, tmp_path / "report_b")
    assert cli.main(["compare", f"a={out}", f"b={tmp_path / 'report_b'}", "--size", "10", "--out", str(cmp_md)]) == 0
    page = cmp_md.read_text()
    nb = reach["spaces"]["pca"]
    i = nb["sizes"].index(10)
    # positives are the only known subset here (no feasible field): the whole-set cell is theirs
    assert f"| {nb['actions'][0]} | {R.fmt(nb['nb_acc_subset'][0][i][0])} (" in page
    for f in found:
        assert f"| {f['finding']} |" in page
    assert cli.main(["compare", f"a={out}"]) == 2  # one reading is refused


def test_example_scenes_in_a_second_process_and_a_failed_report_stops_it(scene_run, tmp_path, monkeypatch):
    """On two cores the example scenes are drawn in a spawned process (``examples_beside``):
    the same PNG files as drawn here; a report that fails while they are drawn stops that
    process instead of waiting for it."""
    import signal

    from relaff_jax.report import examples as X
    from relaff_jax.report import write as W

    data_dirs = {"lift": scene_run / "data" / "lift", "take": scene_run / "data" / "take"}
    here = X.example_scenes(data_dirs, tmp_path / "here", 1)
    d = X.examples_beside(data_dirs, tmp_path / "there", 1, cores=2)
    assert d.pool is not None and d() == [(a, p.replace("here/", "there/"), c) for a, p, c in here]
    for _, p, _ in here:
        assert (tmp_path / p).read_bytes() == (tmp_path / p.replace("here/", "there/")).read_bytes()

    started = []

    def beside(*a, **k):
        drawing = X.examples_beside(*a, **k, cores=2)
        started.append(list(drawing.pool._processes.values()))  # spawned at submit
        return drawing

    def failing(*a, **k):
        raise RuntimeError("analysis failed")

    monkeypatch.setattr(W, "examples_beside", beside)
    monkeypatch.setattr(W, "analyse", failing)
    with pytest.raises(RuntimeError, match="analysis failed"):
        write_report(scene_run / "results", tmp_path / "failed", data_dirs, examples_per_action=2)
    assert len(started) == 1 and len(started[0]) == 1
    proc = started[0][0]
    proc.join(30)
    assert proc.exitcode == -signal.SIGTERM  # stopped, not left to finish its drawing


def test_a_drawing_process_that_dies_is_replaced_by_drawing_here(capsys):
    """A drawing process killed abruptly (out of memory, a signal) leaves a broken pool: the
    report draws the pictures in its own process instead, and stopping a broken or finished
    drawing does not raise (it once raised AttributeError over the report's own error)."""
    import os
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from relaff_jax.report import examples as X

    pool = ProcessPoolExecutor(1, mp_context=get_context("spawn"))
    job = pool.submit(os._exit, 3)  # the child dies without a result
    here = [("lift", "examples/lift_0.png", "drawn here")]
    d = X.Drawing(lambda: here, pool=pool, job=job)
    assert d() == here
    assert "ended abruptly" in capsys.readouterr().err
    d.cancel()  # the pool is shut down and broken: nothing left to stop
    X.Drawing(lambda: here).cancel()


def test_cli_report_takes_the_datasets(scene_run, tmp_path, capsys):
    """``relaff report RESULTS --data DIR...``: each folder's action read from its sidecar, as
    ``write_report``'s ``data_dirs``, so the datasets' statistics and figures are in the report;
    two folders of one action are refused before anything is written."""
    lift, take = scene_run / "data" / "lift", scene_run / "data" / "take"
    out = tmp_path / "report"
    argv = ["report", str(scene_run / "results"), "--out", str(out), "--set", "reproduce.examples_per_action=0"]
    assert cli.main(argv + ["--data", str(take), str(lift)]) == 0
    assert (out / "fig_datasets.png").stat().st_size > 0
    md = (out / "report.md").read_text()
    rows = [re.search(rf"^\| {action} \| \d+ \| \d+ \|", md, re.M) for action in ("lift", "take")]
    assert all(rows)  # the Datasets table: samples, rollouts
    assert rows[0].start() < rows[1].start()  # in the canonical order, whatever the order given
    without = tmp_path / "bare"
    assert cli.main(argv[:3] + [str(without)]) == 0
    assert not (without / "fig_datasets.png").exists()
    capsys.readouterr()
    assert cli.main(argv + ["--data", str(lift), str(lift)]) == 2
    assert "are both lift datasets" in capsys.readouterr().err


def test_after_ten_reading_changes_the_after_ten_finding_only():
    rows = dict(GOOD, **{"DB1 best after ten (causal)": 1.2, "CB1 best after ten (causal)": 1.3})
    an = _analysis([0.6] * 4, [0.7] * 4, rows, [2.0] * 3)
    whole = {f["id"]: f for f in R.findings(an, CFG)}
    causal = {f["id"]: f for f in R.findings(an, override(CFG, {"after_ten": "causal"}))}
    assert whole["best_after_ten"]["verdict"] == "reproduced"
    assert causal["best_after_ten"]["verdict"] == "not reproduced"
    assert causal["best_after_ten"]["values"]["DB1"]["rows"][0] == "DB1 best after ten (causal)"
    for fid in whole:
        if fid != "best_after_ten":
            assert whole[fid] == causal[fid]
