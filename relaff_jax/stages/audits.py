"""The generate stage's physics audits, each beside the next action's generation.

Takes the stage's ``Run``; gives ``Beside``: ``warm(fns)`` first compiles the planner's programs
ahead of the generation that calls them (``sim/warm.py``) and ``submit(action)`` audits a finished
dataset (``data.audit.ensure_audit``, written atomically to its ``audit.json``), both on one
background thread; ``warm_elsewhere`` runs work that holds the GIL (numba's compile of the
forest kernels) in a spawned process; ``finish()`` waits for them all and returns the audits'
run-log records. An audit is one
core's work (a scene-by-scene MuJoCo C replay with a Python probe), and the generation of the
next action leaves a core idle between its C batches and planner calls, so on two cores the
audits cost little wall time (``docs/reproduce.md``, "The quick preset's defaults"). The
results are the same bits either way: the replay works on its own copies of the models
(``sim.native.reference.replay_native``) and the planner's calls do not share state.

An audit runs here, at once, when this process has one core (``MIN_CORES``), or when the
dataset records another object set than the active one: the set is process-wide
(``sim.objects.activate``), and the audit activates the dataset's.
"""
from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Callable

from relaff_jax.data import DatasetError
from relaff_jax.data import audit as A
from relaff_jax.data.audit_replay import default_jobs
from relaff_jax.data.store import read_sidecar
from relaff_jax.stages.protocol import Run

MIN_CORES = 2  # below this an audit beside the generation would only take the generation's core


def audit(path: Path) -> tuple[dict | None, str | None, float]:
    """``(audit, None, seconds)`` of the dataset ``path`` (stored or made now), or
    ``(None, why, seconds)`` when it cannot be replayed (e.g. a stand-in simulation's rollouts)."""
    t0 = time.perf_counter()
    try:
        a = A.ensure_audit(path, A.DEFAULT_SAMPLE, 0)
    except DatasetError as e:
        return None, str(e), time.perf_counter() - t0
    return a, None, time.perf_counter() - t0


def record(run: Run, action: str, a: dict | None, why: str | None, seconds: float) -> dict:
    """Say one audit's outcome on the progress line; what the run log records of it."""
    if a is None:
        run.progress.message(f"audit {action}: not audited ({why})")
        return {"status": "not audited", "why": why}
    c = a["checks"]
    run.progress.message(f"audit {action}: {a['n_audited']} rollouts replayed in MuJoCo C, palm from above "
                         f"{c['palm_contact']['count']} (side {c['palm_contact']['side_count']}), peak force "
                         f"{c['force']['weights']['max'] or 0:.0f} weights, moving at measuring {c['moving']['count']}, "
                         f"label agreement {a['replay']['agree']}/{a['replay']['n']} in {seconds:.0f} s")
    return {"n": a["n_audited"], "seconds": round(seconds, 2),
            "failing": {k: v["count"] for k, v in c.items()}, "label_agreement": a["replay"]["label_agreement"]}


def _same_objects(path: Path) -> bool:
    """Does the dataset record the active object set (so its audit activates an equal one)?"""
    from relaff_jax.sim import object_library as ol
    from relaff_jax.sim import objects as lib

    try:
        meta = read_sidecar(path)
        return ol.from_record((meta.get("config") or {}).get("objects")) == lib.active()
    except Exception:  # unreadable: audited here, where its error is reported as usual
        return False


class Beside:
    """Audits of finished datasets on one background thread (a context manager: leaving it
    early cancels the audits not started; a started one finishes and writes its file)."""

    def __init__(self, run: Run, cores: int | None = None):
        self.run = run
        cores = default_jobs() if cores is None else cores
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="audit") if cores >= MIN_CORES else None
        self.pending: dict[str, Future] = {}
        self.warming: list[Future] = []
        self.process = None
        self.done: dict[str, dict] = {}

    def warm(self, fns: list[Callable[[], None]]) -> None:
        """Run ``fns`` (``sim.warm.planner_warmups``) on the background thread, before the
        audits; nothing runs without the thread (one core: the generation compiles them itself)."""
        if self.pool is not None:
            self.warming += [self.pool.submit(f) for f in fns]

    def warm_elsewhere(self, fn: Callable, *args) -> None:
        """Run ``fn(*args)`` in a spawned process of its own (work that holds the GIL, such as
        numba's compile of the forest kernels, ``learn.forest.compiled.warm``); nothing runs
        without the background thread's second core."""
        if self.pool is None:
            return
        if self.process is None:  # one process for every such warm-up, run one after another
            from concurrent.futures import ProcessPoolExecutor
            from multiprocessing import get_context

            self.process = ProcessPoolExecutor(1, mp_context=get_context("spawn"))
        self.warming.append(self.process.submit(fn, *args))

    def submit(self, action: str) -> None:
        path = self.run.paths.dataset(action)
        if self.pool is None or not _same_objects(path):
            self.done[action] = record(self.run, action, *audit(path))
        else:
            self.pending[action] = self.pool.submit(audit, path)
        self._collect(wait=False)

    def _collect(self, wait: bool) -> None:
        for action in list(self.pending):
            if wait or self.pending[action].done():
                self.done[action] = record(self.run, action, *self.pending.pop(action).result())

    def finish(self) -> dict[str, dict]:
        """Wait for every audit and warm-up; ``{action: run-log record}`` (an audit's error is
        raised here, a warm-up's said in one line)."""
        for f in self.warming:  # a warm-up only saves time: the stage that needs its program compiles it
            e = f.exception()
            if e is not None:
                self.run.progress.message(f"note: a compile ahead of time failed ({type(e).__name__}: {e}); "
                                          "the stage that needs it compiles it")
        self._collect(wait=True)
        return dict(self.done)

    def __enter__(self) -> "Beside":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is not None and self.process is not None:
            # a stage that failed or was stopped does not wait for a compile it no longer needs
            # (numba writes each cache file whole)
            for proc in list((getattr(self.process, "_processes", None) or {}).values()):  # None once shut down
                proc.terminate()
        for pool in (self.pool, self.process):
            if pool is not None:
                pool.shutdown(wait=exc[0] is None, cancel_futures=True)
