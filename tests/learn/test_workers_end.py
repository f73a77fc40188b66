"""Workers end with their driver: a joblib worker watches its driver's pid and
exits when it is gone, and its atomic writes are fenced, so that no file appears in a run
folder after the driver (and with it the folder's lock) has gone.

On some machines a killed driver's loky workers are reaped at once by a subreaper (as on
the machine these tests were written on); elsewhere they ran on for minutes. The tests
therefore make the "driver" a separate process the worker is told to watch, and kill that."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest
import time

WORKER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from relaff_jax import io as rio
    from relaff_jax.learn import parallel
    driver, out, seconds = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
    parallel._watch(driver)
    print("watching", flush=True)
    end = time.time() + seconds
    while time.time() < end:  # busy in numpy, as a forest fit is
        np.linalg.svd(np.random.default_rng(0).random((120, 120)))
    rio.atomic_write_text(out, "late")
""")


def _worker(driver_pid, out, seconds):
    p = subprocess.Popen([sys.executable, "-c", WORKER, str(driver_pid), str(out), str(seconds)],
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "watching"
    return p


@pytest.mark.slow
def test_a_worker_ends_within_seconds_of_its_driver_and_writes_nothing(tmp_path):
    driver = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    worker = _worker(driver.pid, tmp_path / "block.npz", 8.0)
    try:
        time.sleep(0.5)
        assert worker.poll() is None  # alive while its driver is
        os.kill(driver.pid, signal.SIGKILL)  # a zombie until reaped: counted as gone
        t0 = time.monotonic()
        worker.wait(timeout=5)
        assert time.monotonic() - t0 < 3.0
        time.sleep(8.5 - (time.monotonic() - t0))  # past the moment it would have written
        assert list(tmp_path.iterdir()) == []
    finally:
        for p in (driver, worker):
            p.kill()
            p.wait()


def test_a_write_after_the_driver_is_gone_is_discarded(tmp_path):
    """The fence alone (the watcher's poll not yet run): the rename is never made."""
    code = textwrap.dedent(f"""
        from relaff_jax import io as rio
        rio.atomic_write_text({str(tmp_path / 'kept.txt')!r}, "early")
        rio.set_write_fence(lambda: False)
        rio.atomic_write_text({str(tmp_path / 'late.txt')!r}, "late")
        raise SystemExit(3)  # not reached: a fenced write ends the process
    """)
    r = subprocess.run([sys.executable, "-c", code])
    assert r.returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.txt"]


def test_the_driver_itself_is_never_fenced():
    from relaff_jax.learn import parallel

    assert parallel.driver_alive(os.getpid()) and parallel.driver_alive(os.getppid())
    parallel._watch(os.getpid())  # the in-process path (jobs == 1): no watcher, no fence
    from relaff_jax import io as rio

    assert rio._FENCE == [] and parallel._watching == []


def test_the_fence_follows_the_folder_lock(tmp_path):
    """A lock held by another process reads as held, and as gone once that process ends; a
    worker's fence on it then refuses (the lock goes before the pid changes hands)."""
    from relaff_jax.io import lock_is_held
    from relaff_jax.learn import parallel

    code = textwrap.dedent(f"""
        import sys, time
        from relaff_jax import io as rio
        with rio.folder_lock({str(tmp_path)!r}, "busy"):
            print("locked", flush=True)
            time.sleep(60)
    """)
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        lock = tmp_path / ".relaff.lock"
        assert lock_is_held(lock) is True
        assert parallel.driver_alive(os.getppid(), [str(lock)])
        holder.kill()
        holder.wait()
        assert lock_is_held(lock) is False
        assert not parallel.driver_alive(os.getppid(), [str(lock)])  # our own parent lives; the lock is gone
    finally:
        holder.kill()
        holder.wait()


JOB = textwrap.dedent("""
    import time
    import numpy as np
    from relaff_jax import io as rio

    def job(path, seconds):
        end = time.time() + seconds
        while time.time() < end:
            np.linalg.svd(np.random.default_rng(0).random((120, 120)))
        rio.atomic_write_text(path, "block")
        return 1
""")

DRIVER = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    from relaff_jax import io as rio
    from relaff_jax.learn.parallel import run_parallel
    from relaff_job import job
    out = sys.argv[2]
    with rio.folder_lock(out, "busy"):
        calls = [(job, (f"{out}/b{i}.txt", 0.2 if i < 2 else 6.0), {}) for i in range(6)]
        run_parallel(calls, 2, False, 6, "x", "x")
""")


@pytest.mark.slow  # starts a driver with two joblib workers and kills it
def test_kill_9_of_a_driver_leaves_no_worker_and_no_late_file(tmp_path):
    (tmp_path / "relaff_job.py").write_text(JOB)
    out = tmp_path / "run"
    out.mkdir()
    driver = subprocess.Popen([sys.executable, "-c", DRIVER, str(tmp_path), str(out)])
    try:
        t0 = time.time()
        while time.time() - t0 < 120 and len(list(out.glob("b*.txt"))) < 2:  # the workers run the long jobs now
            time.sleep(0.05)
        assert len(list(out.glob("b*.txt"))) >= 2, "the workers never started"
        kids = [int(p) for p in open(f"/proc/{driver.pid}/task/{driver.pid}/children").read().split()]
        before = {p.name for p in out.iterdir()}
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
        t_kill = time.monotonic()
        while time.monotonic() - t_kill < 5 and any(os.path.exists(f"/proc/{k}") and not _zombie(k) for k in kids):
            time.sleep(0.1)
        assert not any(os.path.exists(f"/proc/{k}") and not _zombie(k) for k in kids), "a worker outlived its driver"
        time.sleep(7)  # past the moment the long jobs would have written
        assert {p.name for p in out.iterdir()} == before
    finally:
        driver.kill()
        driver.wait()


def _zombie(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True
