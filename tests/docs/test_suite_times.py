"""benchmarks/suite_times.py: the per-test time record as tables (folders, slowest tests, a
second run beside), on a hand-made record whose sums are worked out here."""
import json
import sys

import pytest

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import suite_times  # noqa: E402


def _t(nodeid, wall, cpu, kids=0.0, worker="gw0", outcome="passed", slow=False, start=0.0):
    return {"nodeid": nodeid, "wall_s": wall, "cpu_s": cpu, "children_cpu_s": kids, "worker": worker,
            "outcome": outcome, "slow": slow, "start": start}


TESTS = [_t("tests/sim/test_a.py::test_1", 10.0, 8.0, 1.0, slow=True),
         _t("tests/sim/test_b.py::test_2", 5.0, 4.0, worker="gw1"),
         _t("tests/learn/test_c.py::test_3[x]", 2.0, 1.0, 3.0, worker="gw1", outcome="failed")]
RECORD = {"started": 100.0, "finished": 112.5, "load_start": [1.5, 1, 1], "load_end": [2.25, 1, 1], "workers": 2,
          "cpus": 2, "tests": TESTS}


def test_totals_by_folder_and_file():
    f = suite_times.totals(TESTS, "folder")
    assert f == {"tests/sim": {"n": 2, "wall": 15.0, "cpu": 12.0, "kids": 1.0},
                 "tests/learn": {"n": 1, "wall": 2.0, "cpu": 1.0, "kids": 3.0}}
    assert set(suite_times.totals(TESTS, "file")) == {"tests/sim/test_a.py", "tests/sim/test_b.py", "tests/learn/test_c.py"}


def test_printed_tables(tmp_path, capsys):
    path = tmp_path / "t.json"
    path.write_text(json.dumps(RECORD))
    old = tmp_path / "old.json"
    old.write_text(json.dumps(dict(RECORD, tests=[_t("tests/sim/test_a.py::test_1", 30.0, 26.0)])))
    assert suite_times.main([str(path), "--top", "2", "--against", str(old)]) == 0
    out = capsys.readouterr().out
    assert "tests 3 (1 slow), failed 1, skipped 0" in out
    assert "session wall 12 s, workers 2, cpus 2, load average 1.5 at start, 2.2 at end" in out
    assert "wall 17 s, CPU 13 s in the test processes + 4 s in their children = 17 s" in out
    assert "busy wall per worker: gw0 10 s, gw1 7 s" in out
    # folders by CPU (13 of 17 s in sim), the two slowest by CPU, sim against the old run's 26 s
    assert "| tests/sim | 2 | 15.0 | 12.0 | 1.0 | 76.5 % |" in out
    assert "| tests/learn | 1 | 2.0 | 1.0 | 3.0 | 23.5 % |" in out
    slow = [ln for ln in out.splitlines() if ln.startswith("| tests/") and "::" in ln]
    assert slow == ["| tests/sim/test_a.py::test_1 | gw0 | 10.0 | 8.0 | 1.0 | 0.90 |",
                    "| tests/sim/test_b.py::test_2 | gw1 | 5.0 | 4.0 | 0.0 | 0.80 |"]
    assert "| tests/sim | 26.0 | 13.0 | 0.50 | 30.0 | 15.0 | 0.50 |" in out
    assert "| tests/learn | 0.0 | 4.0 | nan | 0.0 | 2.0 | nan |" in out


def test_a_running_record_is_read_from_its_parts(tmp_path, capsys):
    path = tmp_path / "t.json"
    (tmp_path / "t.json.gw0.jsonl").write_text(json.dumps(TESTS[0]) + "\n" + '{"nodeid": "cut sh')
    (tmp_path / "t.json.gw1.jsonl").write_text(json.dumps(TESTS[1]) + "\n")
    assert suite_times.main([str(path), "--by", "file"]) == 0
    out = capsys.readouterr().out
    assert "tests 2 (1 slow), failed 0, skipped 0; the run is still going" in out
    assert "| tests/sim/test_a.py | 1 | 10.0 | 8.0 | 1.0 | 69.2 % |" in out
    with pytest.raises(SystemExit, match="no record at"):
        suite_times.main([str(tmp_path / "none.json")])


def test_jax_table_sums_the_events_and_names_the_costliest_traces(capsys):
    tests = [dict(TESTS[0], jax_trace_s=20.0, jax_lower_s=2.0, jax_compile_s=5.5, traced={"prepare_fn": 19.0}),
             dict(TESTS[1], jax_trace_s=8.0, jax_lower_s=0.5, jax_compile_s=1.0,
                  traced={"prepare_fn": 6.0, "screen_fn": 1.5})]
    lines = suite_times.table_jax(tests, 5)
    assert lines[0] == "JAX in the test processes: tracing 28 s, lowering 2 s, compile or cache load 6 s (wall)"
    assert lines[4] == "| prepare_fn | 2 | 25.0 | test_1, test_2 |"
    assert lines[5] == "| screen_fn | 1 | 1.5 | test_2 |"
    assert suite_times.table_jax(TESTS, 5) == []  # a record made before these were kept


def test_the_times_plugin_hears_jax_trace_events():
    from helpers import times

    before = dict(times._jax["sums"]), dict(times._jax["traced"])
    try:
        times._on_jax_event("/jax/core/compile/jaxpr_trace_duration", 2.5, fun_name="prepare_fn")
        times._on_jax_event("/jax/core/compile/jaxpr_trace_duration", 0.5, fun_name="small")
        times._on_jax_event("/jax/other", 9.0)
        assert times._jax["sums"]["jax_trace_s"] == pytest.approx(before[0]["jax_trace_s"] + 3.0)
        assert times._jax["traced"]["prepare_fn"] == pytest.approx(before[1].get("prepare_fn", 0.0) + 2.5)
        assert "small" not in times._jax["traced"] or before[1].get("small")
    finally:
        times._jax["sums"], times._jax["traced"] = before
