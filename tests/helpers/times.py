"""Where the suite's time goes, on a loaded machine too: with ``RELAFF_TEST_TIMES=FILE.json``
each test's wall seconds are recorded next to the CPU seconds its process used (every thread of
the pytest process or xdist worker, ``time.process_time``) and those of the child processes it
waited for (``RUSAGE_CHILDREN``), setup and teardown included (a module fixture's cost lands on
the test that first needs it). A pytest plugin loaded by tests/conftest.py; without the variable
it does nothing. ``benchmarks/suite_times.py FILE.json`` prints the tables.

Each row also holds what JAX spent in the test's process (``jax.monitoring``'s duration events,
wall seconds): tracing (``jax_trace_s``), lowering to MLIR (``jax_lower_s``) and the backend's
compile or its load from the compilation cache (``jax_compile_s``), and the functions traced for
more than a second (``traced``: name -> seconds). Child processes' JAX time is not seen.

Each process appends one JSON line per test to ``FILE.json.<worker>.jsonl`` as the test ends
(readable while the run goes on, kept if a worker dies); at the end of the session the main
process merges them into ``FILE.json`` (written atomically) and removes the parts.
"""
import json
import os
import resource
import socket
import time
from pathlib import Path

import pytest

ENV = "RELAFF_TEST_TIMES"

# jax.monitoring's duration events -> the row's field; summed per process while a test runs
JAX_EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "jax_trace_s",
              "/jax/core/compile/jaxpr_to_mlir_module_duration": "jax_lower_s",
              "/jax/core/compile/backend_compile_duration": "jax_compile_s"}
TRACED_MIN_S = 1.0  # a traced function is named in the row from this many seconds
_jax: dict = {"sums": dict.fromkeys(JAX_EVENTS.values(), 0.0), "traced": {}}


def _on_jax_event(event: str, duration: float, **kwargs) -> None:
    field = JAX_EVENTS.get(event)
    if field is None:
        return
    _jax["sums"][field] += duration
    if field == "jax_trace_s" and duration >= TRACED_MIN_S:
        name = str(kwargs.get("fun_name", "?"))
        _jax["traced"][name] = _jax["traced"].get(name, 0.0) + duration


def pytest_configure(config):
    if os.environ.get(ENV):
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_on_jax_event)


def _worker() -> str:
    return os.environ.get("PYTEST_XDIST_WORKER", "main")


def part_path(out: Path, worker: str) -> Path:
    return out.with_name(f"{out.name}.{worker}.jsonl")


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def read_parts(out: Path) -> list[dict]:
    """Every test record in the part files of ``out`` (a line cut short by a dying worker is skipped)."""
    rows = []
    for part in sorted(out.parent.glob(f"{out.name}.*.jsonl")):
        for line in part.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                pass
    return rows


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    out = os.environ.get(ENV)
    if not out:
        yield
        return
    start, wall0, cpu0, kids0 = time.time(), time.perf_counter(), time.process_time(), _children_cpu()
    jax0 = dict(_jax["sums"])
    _jax["traced"] = {}
    yield
    jax_row = {k: round(v - jax0[k], 3) for k, v in _jax["sums"].items()}
    jax_row["traced"] = {k: round(v, 2) for k, v in _jax["traced"].items()}
    row = {**jax_row, "nodeid": item.nodeid, "worker": _worker(), "start": start,
           "wall_s": time.perf_counter() - wall0, "cpu_s": time.process_time() - cpu0,
           "children_cpu_s": _children_cpu() - kids0, "slow": item.get_closest_marker("slow") is not None,
           "outcome": getattr(item, "_relaff_outcome", "passed")}
    with open(part_path(Path(out), _worker()), "a") as f:  # one short line per append
        f.write(json.dumps(row) + "\n")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    if rep.failed or (rep.skipped and call.when == "setup"):
        item._relaff_outcome = rep.outcome  # the first failure or a skip wins
    elif not hasattr(item, "_relaff_outcome") and rep.skipped:
        item._relaff_outcome = "skipped"


def pytest_sessionstart(session):
    out = os.environ.get(ENV)
    if out and _worker() == "main":
        session.config._relaff_times = {"started": time.time(), "load_start": os.getloadavg()}
        for part in Path(out).parent.glob(f"{Path(out).name}.*.jsonl"):  # an earlier run's leftovers
            part.unlink()


def pytest_sessionfinish(session, exitstatus):
    out = os.environ.get(ENV)
    head = getattr(session.config, "_relaff_times", None)
    if not out or head is None:  # workers leave the merge to the main process
        return
    from relaff_jax.io import atomic_write_json

    out = Path(out)
    rows = sorted(read_parts(out), key=lambda r: r["start"])
    numprocesses = getattr(session.config.option, "numprocesses", None)
    atomic_write_json(out, dict(head, finished=time.time(), load_end=os.getloadavg(), host=socket.gethostname(),
                                cpus=os.cpu_count(), workers=numprocesses or 0, exitstatus=int(exitstatus),
                                tests=rows))
    for part in out.parent.glob(f"{out.name}.*.jsonl"):
        part.unlink()
