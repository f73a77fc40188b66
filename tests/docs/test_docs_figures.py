"""Every measured headline figure is kept once, in docs/figures.json.

The README and the reference pages in docs/ quote a figure behind a marker,
``<!-- fig:ID -->`` followed by its text (``benchmarks/figures.py``: ``display``); the journal
(docs/journal/) keeps dated history and is not checked.
"""
from __future__ import annotations

import re
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import figures  # noqa: E402


def pages() -> list[Path]:
    """README and every reference page (docs/*.md, not the journal)."""
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def test_figures_file_is_well_formed():
    recs = figures.load()
    assert {"quick_native_s", "paper_native_s"} <= recs.keys()
    for rid, rec in recs.items():
        assert isinstance(rec["value"], (int, float)), rid
        assert rec["rests_on"].get("date"), f"{rid}: no date"
        assert rec["rests_on"].get("machine"), f"{rid}: no machine"
        assert rec["source"].strip(), f"{rid}: no source"


def test_display_by_hand():
    rec = {"id": "x", "unit": "s", "value": 5515}
    assert figures.display(dict(rec, shown="h min")) == "1 h 32 min"
    assert figures.display(dict(rec, shown="min")) == "91.9 minutes"
    assert figures.display(dict(rec, value=1733, shown="min s")) == "28 min 53 s"
    assert figures.display(dict(rec, shown="s")) == "5,515 s"
    assert figures.display({"id": "y", "unit": "GB", "value": 7.0, "digits": 1, "shown": "plain"}) == "7.0 GB"
    with pytest.raises(ValueError):
        figures.display(dict(rec, unit="GB", shown="min"))


def test_every_marked_figure_equals_the_file():
    recs = figures.load()
    seen, wrong = 0, []
    for page in pages():
        text = page.read_text()
        for m in figures.MARK.finditer(text):
            rid = m.group(1)
            seen += 1
            if rid not in recs:
                wrong.append(f"{page.name}: unknown figure {rid}")
                continue
            want = figures.display(recs[rid])
            got = text[m.end():m.end() + len(want)]
            if got != want:
                wrong.append(f"{page.name}: fig:{rid} reads {got!r}, the file says {want!r}")
    assert not wrong, "\n".join(wrong)
    assert seen >= 3  # the README's headline figures at least


def test_readme_headline_figures_are_marked():
    text = (ROOT / "README.md").read_text()
    ids = set(figures.MARK.findall(text))
    assert {"quick_native_s", "paper_native_s"} <= ids


def unmarked(text: str, phrase: str) -> int:
    """Occurrences of ``phrase`` in ``text`` not directly behind a figure marker."""
    n = 0
    for m in re.finditer(re.escape(phrase), text):
        if not re.search(r"<!-- fig:[a-z0-9_]+ -->$", text[:m.start()]):
            n += 1
    return n


def test_no_figure_quoted_unmarked():
    """A figure's text (e.g. "1 h 32 min") appears in the reference pages only behind its marker."""
    recs = figures.load()
    loose = []
    for page in pages():
        text = page.read_text()
        for rid, rec in recs.items():
            phrase = figures.display(rec)
            if len(phrase) >= 6 and unmarked(text, phrase):
                loose.append(f"{page.name}: {phrase!r} (figure {rid}) without its marker")
    assert not loose, "\n".join(loose)


TIMING = re.compile(r"(\d[\d.,]*\s?(?:h \d+ min|min \d+ s|minutes|min|hours|h|s))\s+on (?:two|2)\b")


def test_no_headline_timing_copied_unmarked():
    """A timing phrase like "4.4 minutes on two idle cores" appears unmarked in one place at most."""
    where = defaultdict(list)
    for page in pages():
        text = page.read_text()
        for m in TIMING.finditer(text):
            if re.search(r"<!-- fig:[a-z0-9_]+ -->$", text[:m.start()]):
                continue
            where[m.group(1)].append(page.name)
    copies = {k: v for k, v in where.items() if len(v) > 1}
    assert not copies, copies


def test_write_records_is_atomic_and_keeps_the_rest(tmp_path):
    path = tmp_path / "figures.json"
    path.write_text((ROOT / "docs" / "figures.json").read_text())
    before = figures.load(path)
    rec = dict(before["quick_native_s"], value=300)
    figures.write_records([rec], path)
    after = figures.load(path)
    assert figures.display(after["quick_native_s"]) == "5.0 minutes"
    assert list(after) == list(before)
    assert {k: v for k, v in after.items() if k != "quick_native_s"} == \
        {k: v for k, v in before.items() if k != "quick_native_s"}
    assert not [p for p in tmp_path.iterdir() if p.name != "figures.json"]  # no temp file left


def test_run_times_writes_a_run_logs_figure(tmp_path):
    import json

    import run_times

    run = tmp_path / "run"
    run.mkdir()
    log = {"preset": "quick", "machine": {"machine": "x86_64", "cpu_model": "CPU", "cpus": 2}, "runs": [
        {"started": "2026-12-01T10:00:00Z", "seconds": 50.0,
         "stages": {"generate": {"status": "killed", "seconds": 50.0}}},
        {"started": "2026-12-02T11:00:00Z", "seconds": 262.4,
         "stages": {"generate": {"status": "ran", "seconds": 157.2, "actions": {
                        "lift": {"status": "ran", "seconds": 100.0, "rollouts": 320},
                        "move": {"status": "ran", "seconds": 57.2, "rollouts": 192}}},
                    "features": {"status": "ran", "seconds": 26.0},
                    "experiment": {"status": "ran", "seconds": 59.0}, "report": {"status": "ran", "seconds": 19.0}}}]}
    (run / "run.json").write_text(json.dumps(log))
    figs = tmp_path / "figures.json"
    figs.write_text((ROOT / "docs" / "figures.json").read_text())
    old = figures.FIGURES
    figures.FIGURES = figs
    try:
        assert run_times.main([str(run), "--write-figures", "quick_native_s"]) == 0
        assert run_times.main([str(run), "--write-figures", "paper_native_rollouts_per_s"]) == 0
        assert run_times.main([str(run), "--write-figures", "no_such_figure"]) == 2
    finally:
        figures.FIGURES = old
    rec = figures.load(figs)["quick_native_s"]
    assert rec["value"] == 262 and rec["stages_s"]["generate"] == 157
    assert rec["rests_on"]["date"] == "2026-12-02"
    assert rec["rests_on"]["machine"] == "x86_64, CPU, 2 cores"
    assert figures.load(figs)["paper_native_rollouts_per_s"]["value"] == round(512 / 157.2)


def test_paper_stages_writes_the_quick_figure(tmp_path):
    """``benchmarks/paper_stages.py --write-figures``: the quick run's wall and stage seconds
    go to ``quick_native_s`` without a compilation cache, to ``quick_native_warm_s`` with one."""
    import paper_stages

    figs = tmp_path / "figures.json"
    figs.write_text((ROOT / "docs" / "figures.json").read_text())
    old = figures.FIGURES
    figures.FIGURES = figs
    try:
        quick = {"seconds": 250.4, "stages": {"generate": 150.2, "report": 20.0}, "programs": "v2"}
        paper_stages.write_quick_figure(quick, "")
        paper_stages.write_quick_figure(dict(quick, seconds=199.6), "/tmp/some_cache")
    finally:
        figures.FIGURES = old
    recs = figures.load(figs)
    assert recs["quick_native_s"]["value"] == 250
    assert recs["quick_native_s"]["stages_s"] == {"generate": 150, "report": 20}
    assert recs["quick_native_s"]["rests_on"]["programs"] == "v2"
    assert recs["quick_native_warm_s"]["value"] == 200
    assert figures.display(recs["quick_native_s"]) == "4.2 minutes"


def test_code_points_to_the_figures_file():
    """CLI help and docstrings name a figure by its id in docs/figures.json, never copy its value."""
    recs = figures.load()
    copies = []
    for path in sorted((ROOT / "relaff_jax").rglob("*.py")):
        text = path.read_text()
        for rid, rec in recs.items():
            phrase = figures.display(rec)
            if len(phrase) >= 6 and phrase in text:
                copies.append(f"{path.relative_to(ROOT)}: {phrase!r} (figure {rid})")
    assert not copies, "\n".join(copies)
