"""`--cluster`: the stages as Dask tasks give the bits of the run without a cluster.

The simulation and the perception are numpy stand-ins (tests/helpers/standins.py, as in the reproduce tests; the
real ones would cost minutes of compiling per worker), so these tests check the task
plumbing: ordering, the stopping point, resume, faults and the checks made before any work.
The forests, the sweep blocks and the report are the real ones. Every cluster test shares
one `LocalCluster` of two spawned worker processes (starting one costs ~10 s here).
"""
import functools
import importlib.util
import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from relaff_jax import cluster as C
from relaff_jax import data as D
from relaff_jax.cli import main
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.errors import UserError
from relaff_jax.learn.parallel import run_parallel

from helpers import ROOT, TESTS, standins
from helpers.standins import builds, rollout_factory

ACTS = ("lift", "take")


def run(out, client=None, rollouts=rollout_factory):
    return standins.run(out, ACTS, rollout_factory=rollouts, client=client)


def fingerprint(folder):
    spec = importlib.util.spec_from_file_location("fingerprint", ROOT / "benchmarks" / "fingerprint.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.fingerprint(Path(folder))


def check_nothing_extra(folder):
    """Every dataset's chunks are a contiguous prefix with unique rollout ids, nothing pending."""
    for a in ACTS:
        d = Path(folder) / "data" / a
        meta = json.loads((d / D.SIDECAR).read_text())
        names = sorted(p.name for p in (d / D.CHUNKS).iterdir())
        assert names == [f"chunk_{k:06d}" for k in range(meta["counts"]["chunks"])]
        assert not (d / D.FEATURES / ".pending").exists()
        ids = D.load_rollouts(d)["rollout"]
        assert len(np.unique(ids)) == len(ids) == meta["counts"]["rollouts"]


# ---- no cluster needed -------------------------------------------------------------------

def test_parse_address():
    assert C.parse_address("local:2") == C.Address("local", workers=2)
    assert str(C.parse_address(" tcp://10.0.0.5:8786 ")) == "tcp://10.0.0.5:8786"
    assert C.parse_address("tls://[::1]:8786").url == "tls://[::1]:8786"
    for bad, why in [("local:0", "1 <= N"), ("local:x", "expected local:N"), ("tcp://host", "expected"),
                     ("http://h:1", "expected"), ("tcp://h:70000", "outside 1-65535"), ("", "expected")]:
        with pytest.raises(UserError, match=why):
            C.parse_address(bad)


def test_bad_address_fails_before_any_work(tmp_path, capsys):
    out = tmp_path / "d"
    assert main(["generate", "lift", "--samples", "4", "--out", str(out), "--cluster", "local"]) == 2
    assert "expected local:N" in capsys.readouterr().err
    assert not out.exists()
    # how fast it is refused is a benchmark figure (benchmarks/cluster.py, "unreachable scheduler")
    with pytest.raises(UserError, match="cannot reach a Dask scheduler"):
        with C.connect("tcp://127.0.0.1:9", folder=tmp_path, timeout=1):
            pass


def test_remote_is_built_once_per_process():
    before = builds()
    f = C.Remote(rollout_factory, "lift", 4, pick=0)
    g = C.Remote(rollout_factory, "lift", 4, pick=0)
    key = np.asarray([0, 7], np.uint32)
    assert f.key == g.key
    assert np.array_equal(f(key, 4)["label"], g(key, 4)["label"])
    assert builds() == before + 1
    with pytest.raises(UserError, match="not picklable"):
        C.Remote(rollout_factory, threading.Lock())


# ---- on a LocalCluster of two worker processes ----------------------------------------------

@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with C.connect("local:2", folder=tmp_path_factory.mktemp("probe")) as c:
        yield c


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "run"
    run(out)
    return out, fingerprint(out)


@pytest.mark.slow
def test_local2_is_bit_identical(client, baseline, tmp_path):
    out, want = baseline
    before = client.run(builds)
    log = run(tmp_path / "run", client)
    assert log["runs"][-1]["cluster"]["threads"] == 2
    got = fingerprint(tmp_path / "run")
    assert any(k.startswith("results/rhf/acc") for k in want)
    assert "report/findings.json" in want
    assert got == want  # datasets, features, accuracy arrays, findings
    check_nothing_extra(tmp_path / "run")
    # each worker built each recipe (2 rollout functions, 1 feature function) at most once
    assert all(client.run(builds)[w] - before[w] <= 3 for w in before)


@pytest.mark.slow
def test_generation_overshoot_is_discarded_and_said(client, tmp_path):
    fn = C.Remote(rollout_factory, "lift", 4, pick=0)
    sizes = DatasetConfig(n_samples=8, rollout_batch=4)
    serial = D.generate_dataset(tmp_path / "a", "lift", rollout_factory("lift", 4)[0], 5, progress=False,
                                dataset_config=sizes)
    par = D.generate_dataset(tmp_path / "b", "lift", fn, 5, progress=False, client=client, dataset_config=sizes)
    assert par["chunks"] == serial["chunks"]
    assert par["discarded_chunks"] >= 1
    assert serial["discarded_chunks"] == 0
    a, b = D.load_dataset(tmp_path / "a"), D.load_dataset(tmp_path / "b")
    assert all(np.array_equal(a[k], b[k]) for k in a if isinstance(a[k], np.ndarray))
    assert not (tmp_path / "b" / "chunks" / ".pending").exists()


@pytest.mark.slow
def test_unwritable_folder_fails_before_any_work(client, tmp_path):
    with pytest.raises(UserError, match=r"2 of 2 cluster workers cannot write in /proc"):
        C.check_workers(client, "/proc/relaff/out")


@pytest.mark.slow
def test_run_parallel_on_the_given_cluster(client):
    calls = [(np.multiply, (np.arange(5), i), {}) for i in range(6)]
    got = run_parallel(calls, 1, False, total=6, desc="t", unit="call", client=client)
    assert all(np.array_equal(g, np.arange(5) * i) for i, g in enumerate(got))


@pytest.mark.slow
def test_worker_killed_mid_run(client, baseline, tmp_path):
    out = tmp_path / "run"
    slow = functools.partial(rollout_factory, delay=0.15)
    box = {}
    th = threading.Thread(target=lambda: box.setdefault("log", run(out, client, rollouts=slow)))
    th.start()
    chunks = out / "data" / "lift" / "chunks"
    deadline = time.time() + 60
    while time.time() < deadline and len(list(chunks.glob("chunk_*"))) < 2:
        time.sleep(0.05)
    pids = client.run(os.getpid)
    victim = sorted(pids)[0]
    os.kill(pids[victim], signal.SIGKILL)
    th.join(120)
    assert "log" in box
    assert box["log"]["runs"][-1]["status"] == "complete"
    assert pids[victim] not in client.run(os.getpid).values()  # the kill did happen, during the run
    assert fingerprint(out) == baseline[1]
    check_nothing_extra(out)
    client.wait_for_workers(2, timeout=60)  # the nanny restarts the killed worker


DRIVER = textwrap.dedent("""
    import functools, sys
    sys.path.insert(0, {tests!r})
    from helpers import standins
    from relaff_jax import cluster as C
    with C.connect({address!r}, folder={out!r}) as client:
        standins.run({out!r}, {acts!r}, rollout_factory=functools.partial(standins.rollout_factory, delay=0.15),
                     client=client)
""")


@pytest.mark.slow
def test_driver_killed_and_restarted(client, baseline, tmp_path):
    out = tmp_path / "run"
    script = DRIVER.format(tests=str(TESTS), acts=ACTS, address=client.scheduler.address, out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    chunks = out / "data" / "lift" / "chunks"
    deadline = time.time() + 90
    while time.time() < deadline and len(list(chunks.glob("chunk_*"))) < 3 and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert D.dataset_status(out / "data" / "lift")[0] == "partial"  # killed mid-generation
    # the killed driver's tasks may still finish into .pending: the rerun takes them as they are
    log = run(out, client)
    assert log["runs"][0]["status"].startswith("killed")  # the rerun marks the dead run (it never recorded its end)
    assert log["runs"][-1]["status"] == "complete"
    assert fingerprint(out) == baseline[1]
    check_nothing_extra(out)


@pytest.mark.slow
def test_cli_experiment_joins_a_running_scheduler(client, tmp_path, capsys):
    sets = ["--set", "experiment.sizes=[4,10]", "--set", "experiment.reps_pca=1", "--set", 'experiment.conditions_pca=["NB","DB1"]',
            "--set", "experiment.forest.base_trees=4", "--set", "experiment.forest.max_trees=4"]
    argv = ["experiment", "--synthetic", "40", "--space", "pca", "--no-progress"] + sets
    assert main(argv + ["--out", str(tmp_path / "a"), "--cluster", client.scheduler.address]) == 0
    assert "2 workers, 2 threads" in capsys.readouterr().err
    assert main(argv + ["--out", str(tmp_path / "b"), "--jobs", "1"]) == 0
    with np.load(tmp_path / "a" / "pca" / "results.npz") as a, np.load(tmp_path / "b" / "pca" / "results.npz") as b:
        assert np.array_equal(a["acc"], b["acc"], equal_nan=True)


def test_benchmark_projection_by_hand():
    """benchmarks/cluster.py's paper-preset projection against a hand-worked row: 48 s of CPU
    for 6 chunks of 64 rollouts = 0.125 s per rollout, 1 s of overhead per task, so a chunk of
    1024 takes 129 s; 9 x ceil(10,000 x 3.70 / 1024) = 333 chunks plus 9 x (ceil(32 / 9) - 1)
    = 27 past the stopping points on 32 workers: ceil(360 / 32) = 12 rounds, + 60 s compile."""
    spec = importlib.util.spec_from_file_location("cluster_bench", ROOT / "benchmarks" / "cluster.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    row = {"engine": "native", "generate": [60.0, 54.0, 6, 48.0], "features": [12.0, 12.0, 12, 12.0],
           "sweep": [10.0, 10.0, 27, 10.0], "fits": 2520, "batch": 64, "feature_batch": 32,
           "compile_generate_s": 60.0, "compile_features_s": 10.0}
    lines = bench.project(row).splitlines()
    w32 = next(line for line in lines if line.startswith("| 32 |"))
    assert w32.split(" | ")[1] == f"{(60 + 12 * 129) / 60:.1f} min"  # 26.8 min
    assert w32.endswith("generate: 12 rounds of 129 s |")
    assert "native engine" in lines[1]
    assert "125 ms per rollout" in lines[1]
    # the nine actions' (CPU, wall) per rollout replace the one action's: 1024 x 0.25 + 1 = 257 s a chunk
    w8 = next(line for line in bench.project(row, (0.25, 0.3)).splitlines() if line.startswith("| 8 |"))
    assert w8.split(" | ")[1] == f"{(60 + 42 * 257) / 60:.1f} min"  # ceil(333 / 8) = 42 rounds
