"""``relaff compare``'s per-affordance table on synthetic report folders (no simulation, no
fits): each affordance a row, each run's verdict, gain, bf and samples saved with their
intervals as its summary.json says, whether the verdict is the same in every run, in the page
and in the terminal; one clear error for a report without the per-affordance answers."""
import json
import shutil

import pytest

from relaff_jax import cli
from relaff_jax.config import override
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.synthetic_results import write_synthetic_results
from relaff_jax.report import compare_affordances as CA
from relaff_jax.report.write import write_report

ROW = {"in_paper": True, "verdict": "helps", "gain": 0.0512, "gain_ci": [0.0101, 0.0923], "bf_best": 1.234,
       "bf_best_ci": [1.01, 1.5], "samples_saved": 7.25, "samples_saved_ci": [2.0, 12.5], "samples_saved_censored": False}


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """Report ``a`` of a synthetic run; ``b`` its copy with lift's answer replaced by ``ROW``."""
    root = tmp_path_factory.mktemp("cmp")
    cfg = override(ExperimentConfig(), {"sizes": (2, 4, 10, 25), "test_size": 24, "reps_pca": 2, "ci_resamples": 20,
                                        "keep_outcomes": True})
    write_synthetic_results(root / "res", cfg, ("lift", "pull", "take"), spaces=("pca",), seed=2)
    a = write_report(root / "res", root / "a", examples_per_action=0)
    b = root / "b"
    shutil.copytree(a, b)
    s = json.loads((b / "summary.json").read_text())
    s["pca"]["affordances"]["rows"]["lift"] = dict(s["pca"]["affordances"]["rows"]["lift"], **ROW)
    (b / "summary.json").write_text(json.dumps(s))
    return root, a, b


def _rows(path):
    return json.loads((path / "summary.json").read_text())["pca"]["affordances"]["rows"]


def test_page_and_terminal_show_every_run_side_by_side(reports, capsys):
    root, a, b = reports
    ra = _rows(a)
    out = root / "c.md"
    assert cli.main(["compare", f"a={a}", f"b={b}", "--out", str(out)]) == 0
    page = out.read_text()
    sec = page[page.index("## Per affordance"):page.index("## Robustness")]
    lines = {ln.split(" | ")[0][2:]: ln for ln in sec.splitlines() if ln.startswith("| ") and " | " in ln}
    assert list(lines)[1:] == ["lift", "pull", "take"]  # header first, then the paper's order
    # b's lift: the numbers of its summary.json, with their intervals
    assert ("**helps**: gain +0.051 [+0.010, +0.092]; bf 1.23 [1.01, 1.50]; saved 7.2 [2.0, 12.5]"
            in lines["lift"].split(" | ")[2])
    for t in ("pull", "take"):  # the same answer in both runs: a's numbers twice, "yes"
        cells = lines[t].rstrip(" |").split(" | ")
        assert cells[1] == cells[2] == CA.cell(ra[t])
        assert cells[3] == f"yes: {ra[t]['verdict']}"
        assert f"gain {ra[t]['gain']:+.3f}" in cells[1]
    want = "yes: helps" if ra["lift"]["verdict"] == "helps" else f"no: {ra['lift']['verdict']} in a; helps in b"
    assert lines["lift"].rstrip(" |").split(" | ")[3] == want
    assert "`a`: bf and gain of 'DB1 best', samples saved of 'DB1 best', 95 % intervals" in sec
    term = capsys.readouterr().out
    assert f"  lift: {ra['lift']['verdict']} | helps | {want}" in term
    # printed without --out: the same section in the terminal
    assert cli.main(["compare", f"a={a}", f"b={b}"]) == 0
    assert sec in capsys.readouterr().out


def test_a_report_without_the_answers_is_refused_before_any_page(reports, capsys):
    root, a, b = reports
    old = root / "old"
    shutil.copytree(a, old)
    (old / "affordances.csv").unlink()
    out = root / "refused.md"
    assert cli.main(["compare", f"a={a}", f"old={old}", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{old} has no per-affordance answers (affordances.csv is missing" in err and not out.exists()
    assert len(err.strip().splitlines()) == 1
    bare = root / "bare"
    shutil.copytree(a, bare)
    s = json.loads((bare / "summary.json").read_text())
    del s["pca"]["affordances"]
    (bare / "summary.json").write_text(json.dumps(s))
    assert cli.main(["compare", f"bare={bare}", f"a={a}"]) == 2
    assert "summary.json's affordances is missing" in capsys.readouterr().err


def test_same_verdict_and_a_missing_or_user_affordance_by_hand():
    assert CA.same_verdict({"x": "helps", "y": "helps"}) == "yes: helps"
    assert CA.same_verdict({"x": "helps", "y": "no evidence", "z": "helps"}) == "no: helps in x, z; no evidence in y"
    assert CA.same_verdict({"x": "helps", "y": None}) == "no: helps in x; not in y"
    s = {"x": {"pca": {"affordances": {"rows": {"drag": dict(ROW, in_paper=False), "lift": ROW}}}},
         "y": {"pca": {"affordances": {"rows": {"lift": dict(ROW, verdict="no evidence", gain_ci=[-0.01, 0.1],
                                                               samples_saved_censored=True)}}}}}
    header, rows = CA.table(s, "pca")
    assert header == ["affordance", "x", "y", "same verdict in every run"]
    assert [r[0] for r in rows] == ["lift", "drag (not in the paper)"]
    assert rows[0][2].startswith("**no evidence**: gain +0.051 [-0.010, +0.100]") and rows[0][2].endswith("(censored)")
    assert rows[1][2] == "-" and rows[1][3] == "no: helps in x; not in y"
