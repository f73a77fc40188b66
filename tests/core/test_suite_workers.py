"""The suite's own plugins (tests/helpers/workers.py, helpers/times.py): units of work on two
xdist workers, the workers' cores, the per-test CPU and wall record."""
import ast
import functools
import json
import os
import subprocess
import sys
import textwrap

import pytest

from helpers import ROOT, TESTS
from helpers import workers as W

pytest.importorskip("xdist")


def _session_fixtures() -> set[str]:
    """Names of the session fixtures helpers/fixtures.py defines (built once per worker)."""
    tree = ast.parse((TESTS / "helpers" / "fixtures.py").read_text())
    names = set()
    for fn in (n for n in tree.body if isinstance(n, ast.FunctionDef)):
        for dec in fn.decorator_list:
            if isinstance(dec, ast.Call) and any(k.arg == "scope" and getattr(k.value, "value", None) == "session"
                                                 for k in dec.keywords):
                names.add(fn.name)
    return names


@functools.cache
def _arguments() -> dict[str, set[str]]:
    """Test file (rootdir-relative) -> the argument names of its functions (tests and fixtures)."""
    out = {}
    for path in sorted(TESTS.rglob("test_*.py")):
        tree = ast.parse(path.read_text())
        out[path.relative_to(ROOT).as_posix()] = {a.arg for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
                                                  for a in n.args.args}
    return out


def _users(name: str) -> list[str]:
    """Test files with a test or fixture taking ``name`` as an argument."""
    return [f for f, args in _arguments().items() if name in args]


def test_files_sharing_a_session_fixture_form_one_unit():
    fixtures = _session_fixtures()
    assert "scene_run" in fixtures
    for name in fixtures:
        users = _users(name)
        units = {W.unit_of(f"{f}::test_x") for f in users}
        assert len(units) <= 1, f"{name} is used by {users}: one entry of helpers.workers.GROUPS each"
    assert _users("scene_run") and set(_users("scene_run")) == {f for f, g in W.GROUPS.items() if g == "scene_run"}


def test_lanes_exist_and_each_worker_runs_its_own_first():
    laned = [u for lane in W.LANES for u in lane]
    assert len(laned) == len(set(laned))  # a unit in one lane only
    for unit in laned:
        assert unit in W.GROUPS.values() or (ROOT / unit).is_file(), unit
    a, b = W.LANES
    queued = ["tests/x/test_x.py", b[1], a[2], "tests/y/test_y.py", b[0]]
    assert W.next_unit(queued, a) == a[2]  # its lane's first still queued
    assert W.next_unit(queued, b) == b[0]
    assert W.next_unit(queued, ()) == "tests/x/test_x.py"  # a third worker: the first in no lane
    assert W.next_unit([b[1], "tests/y/test_y.py"], a) == "tests/y/test_y.py"  # lane done: no lane's first
    assert W.next_unit([b[1]], a) == b[1]  # then the other lane's
    assert W.unit_of("tests/docs/test_notebooks.py::test_x[1]") == "scene_run"
    assert W.unit_of("tests/sim/test_arm.py::TestA::test_b") == "tests/sim/test_arm.py"


def test_worker_cpus_split_the_cores():
    assert W.worker_cpus([0, 1], 0, 2) == [0] and W.worker_cpus([1, 0], 1, 2) == [1]
    assert W.worker_cpus([0, 1, 2, 3, 4], 1, 2) == [1, 3]
    assert W.worker_cpus([0], 0, 2) is None  # fewer cores than workers: not pinned
    assert W.worker_cpus([0, 1], 0, 1) is None and W.worker_cpus([0, 1], 2, 2) is None


_CONFTEST = """
pytest_plugins = ["helpers.workers", "helpers.times"]
"""
_PROBE = """
import json, os, subprocess, sys, time
def test_{name}(tmp_path_factory):
    child = subprocess.run([sys.executable, "-c", "import os; print(sorted(os.sched_getaffinity(0)))"],
                           capture_output=True, text=True).stdout.strip()
    t = time.process_time()
    while time.process_time() - t < 0.3:  # CPU the record must see
        pass
    rec = dict(file="{name}", worker=os.environ.get("PYTEST_XDIST_WORKER"), pid=os.getpid(),
               cpus=sorted(os.sched_getaffinity(0)), child=child,
               cache=os.environ.get("JAX_COMPILATION_CACHE_DIR"), tmp=str(tmp_path_factory.getbasetemp()))
    with open(os.environ["PROBE_OUT"], "a") as f:
        f.write(json.dumps(rec) + "\\n")
"""


def _fake_suite(root, names):
    """A suite laid out like tests/ whose files each record where they ran."""
    (root / "tests").mkdir()
    (root / "tests" / "conftest.py").write_text(_CONFTEST)
    for rel in names:
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(_PROBE.format(name=p.stem))


@pytest.mark.skipif(len(W.MACHINE_CPUS) < 2, reason="pinning needs two cores")
def test_two_workers_groups_pins_and_times(tmp_path):
    """pytest -n 2 --dist loadfile on a stand-in suite: the two scene_run files run on one worker,
    each worker on its own core (its child processes too), one shared JAX cache folder and a
    separate tmp folder per worker, and RELAFF_TEST_TIMES holds every test with its CPU seconds."""
    files = ["tests/docs/test_notebooks.py", "tests/report/test_reproduce_report.py", "tests/e2e/test_reproduce_e2e.py",
             "tests/a/test_a1.py", "tests/a/test_a2.py", "tests/b/test_b1.py"]
    _fake_suite(tmp_path, files)
    probe, times = tmp_path / "probe.jsonl", tmp_path / "times.json"
    env = dict(os.environ, PROBE_OUT=str(probe), RELAFF_TEST_TIMES=str(times), JAX_COMPILATION_CACHE_DIR="/x/cache",
               PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    env.pop("PYTEST_XDIST_WORKER", None), env.pop("PYTEST_XDIST_WORKER_COUNT", None)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile", "-p", "no:cacheprovider",
                        "--rootdir", str(tmp_path), "tests"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=600, preexec_fn=lambda: os.sched_setaffinity(0, W.MACHINE_CPUS))  # this worker's pinning undone
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    recs = {d["file"]: d for d in map(json.loads, probe.read_text().splitlines())}
    assert set(recs) == {f.rsplit("/", 1)[1][:-3] for f in files}
    assert recs["test_notebooks"]["worker"] == recs["test_reproduce_report"]["worker"]
    assert {d["worker"] for d in recs.values()} == {"gw0", "gw1"}
    cores = {d["worker"]: d["cpus"] for d in recs.values()}
    assert sorted(cores.values()) == [[c] for c in W.worker_cpus(W.MACHINE_CPUS, 0, 2) + W.worker_cpus(W.MACHINE_CPUS, 1, 2)]
    assert all(d["child"] == str(d["cpus"]) for d in recs.values())  # children inherit the pinning
    assert {d["cache"] for d in recs.values()} == {"/x/cache"}
    assert len({d["tmp"] for d in recs.values()}) == 2
    out = json.loads(times.read_text())
    assert out["workers"] == 2 and out["exitstatus"] == 0
    assert sorted(t["nodeid"].split("::")[0] for t in out["tests"]) == sorted(files)
    assert all(t["cpu_s"] >= 0.25 and t["wall_s"] >= t["cpu_s"] * 0.5 and t["outcome"] == "passed" for t in out["tests"])
    assert all(t["children_cpu_s"] > 0 for t in out["tests"])  # the child's interpreter start-up
    assert not list(tmp_path.glob("times.json.*.jsonl"))  # parts merged and removed
    # the e2e unit is handed out first: its worker starts it before any other test of its own
    e2e = next(t for t in out["tests"] if "e2e" in t["nodeid"])
    assert e2e["start"] == min(t["start"] for t in out["tests"] if t["worker"] == e2e["worker"])


def test_times_recorded_in_one_process(tmp_path):
    """Without xdist: the main process writes the file; a failing test is recorded as failed."""
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "conftest.py").write_text(_CONFTEST)
    (tmp_path / "tests" / "test_one.py").write_text(textwrap.dedent("""
        import pytest
        def test_ok():
            sum(range(10**6))
        def test_bad():
            assert 1 == 2
        @pytest.mark.skip(reason="x")
        def test_skip():
            pass
    """))
    times = tmp_path / "t.json"
    env = dict(os.environ, RELAFF_TEST_TIMES=str(times), PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    env.pop("PYTEST_XDIST_WORKER", None), env.pop("PYTEST_XDIST_WORKER_COUNT", None)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path), "tests"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stdout[-2000:]
    out = json.loads(times.read_text())
    got = {t["nodeid"].split("::")[1]: (t["outcome"], t["worker"]) for t in out["tests"]}
    assert got == {"test_ok": ("passed", "main"), "test_bad": ("failed", "main"), "test_skip": ("skipped", "main")}
    assert out["workers"] == 0 and out["exitstatus"] == 1
