"""Run independent forest jobs over worker processes, in order, with a progress bar.

Takes ``calls``: ``[(function, args, kwargs)]`` of picklable module-level functions; gives
their results in call order. ``jobs == 1`` runs in this process (what tests monkeypatch);
otherwise joblib's process pool, results collected as they finish. With ``client`` (a
``distributed.Client``) every call is a task on that Dask cluster instead
(``cluster.map_calls``; ``jobs`` is then ignored), with the same results and progress. The
bar counts ``weights`` (forest fits per call) from ``initial`` (fits already on disk) to
``total``.

Workers end with their driver: joblib's (loky) workers outlive a driver killed by SIGKILL
for minutes (their idle timeout), still fitting and writing blocks. Each worker therefore
watches the driver's pid and the folder locks the driver holds (a thread, every
``WATCH_SECONDS``) and exits when either is gone, and fences its writes
(``io.set_write_fence``): an atomic write is discarded before its rename once the driver or
its lock has gone, so no file appears in the run folder after the lock is released (a dying
process releases its locks before its children are handed to init). A worker first executes
the driver's ``--plugins`` files (``plugins.load_files``): a user action's state order and its
id are the registry's, in every process.
"""
from __future__ import annotations

import os
import threading
import time
from typing import Any
from relaff_jax.io import held_locks, lock_is_held
from relaff_jax import io as rio
from relaff_jax.cluster.tasks import map_calls
from relaff_jax.plugins import load_files, loaded_files

WATCH_SECONDS = 0.5
_watching: list[int] = []  # the driver pid this worker process watches (set once)


def run_parallel(calls: list, jobs: int, progress: bool, total: int, desc: str, unit: str, weights=None, initial: int = 0,
                 client: Any = None) -> list:
    """Run joblib ``calls`` over ``jobs`` processes (or ``client``'s cluster), in order, with a progress bar."""
    from tqdm import tqdm

    weights = [1] * len(calls) if weights is None else weights
    bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=not progress, smoothing=0, dynamic_ncols=True)
    results: list = [None] * len(calls)

    def done(i, r):
        results[i] = r
        bar.update(weights[i])

    try:
        if client is not None and calls:
            map_calls(client, calls, done)
        elif jobs == 1:
            for i, c in enumerate(calls):
                fn, args, kwargs = c
                done(i, fn(*args, **kwargs))
        else:
            from joblib import Parallel

            driver = (os.getpid(), held_locks())  # the workers' fence: this pid, and the folder locks it holds
            files = loaded_files()  # the driver's --plugins files: a worker registers the same actions
            indexed = [(_indexed, (i, c, driver, files), {}) for i, c in enumerate(calls)]
            for i, r in Parallel(n_jobs=jobs, return_as="generator_unordered")(indexed):
                done(i, r)
    finally:
        bar.close()
    return results


def driver_alive(driver: int, locks=()) -> bool:
    """Whether process ``driver`` still runs (a worker's parent: its pid is the parent's, until
    the parent dies and the worker is handed to init or a subreaper) and still holds the
    folder ``locks`` it held when it started the worker (they go first when it dies)."""
    if any(lock_is_held(x) is False for x in locks):
        return False
    if os.getppid() == driver:
        return True
    try:
        os.kill(driver, 0)  # not our parent (another process tree): is it alive at all?
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return not _is_zombie(driver)


def _is_zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return False


def _watch(driver: int, locks=()) -> None:
    """In a worker process: end it when the driver is gone; fence its writes meanwhile."""
    if _watching or driver == os.getpid():
        return

    locks = tuple(locks)
    _watching.append(driver)
    rio.set_write_fence(lambda: driver_alive(driver, locks))

    def loop():
        while driver_alive(driver, locks):
            time.sleep(WATCH_SECONDS)
        os._exit(0)  # nobody is left to read this worker's results

    threading.Thread(target=loop, name="relaff-driver-watch", daemon=True).start()


def _indexed(i: int, call, driver: tuple | None = None, files: tuple = ()):
    if driver is not None:
        _watch(*driver)

    load_files(files)  # the driver's plugin files, and only those (a reused worker forgets others)
    fn, args, kwargs = call
    return i, fn(*args, **kwargs)
