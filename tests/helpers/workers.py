"""The suite on several pytest-xdist workers (`python -m pytest -n 2 --dist loadfile`): which
files run on one worker, in what order, and on which cores (a pytest plugin loaded by
tests/conftest.py; without xdist it does nothing).

- One work unit per test file, so a file's module fixtures are built once. Files that share a
  session fixture of ``helpers.fixtures`` that simulates form one unit (``GROUPS``), so it is
  built once too (a session fixture is per worker).
- The units that take longest start first (``FIRST``), so that the run does not end with one
  worker on a long file while the other idles.
- Each worker is pinned to its share of the CPUs (``pin_worker``), so the processes and threads
  a test starts (``--jobs 2``, a LocalCluster, MuJoCo's batch threads, XLA's pool) stay on that
  worker's cores and two workers never run more CPU-bound threads than there are cores.
  ``RELAFF_TEST_PIN=0`` turns it off.
"""
import os

import pytest

# file -> unit name: files that use the same expensive session fixture (helpers/fixtures.py)
GROUPS = {
    "tests/docs/test_notebooks.py": "scene_run",
    "tests/report/test_reproduce_report.py": "scene_run",
}

# units started first, the longest ones (the whole suite's --durations on an idle machine: the
# tiny preset end to end ~360 s, two processes generating ~160 s, the native audit ~90 s, the
# notebooks on the scene_run folder, the screened plan ~65 s); the rest follow in collection order.
# Ordered so that units compiling the same programs do not compile them at once on both workers,
# the later one loading them from the session's compilation cache (conftest.py). xdist hands
# one worker the first unit and, as that unit has a single test, the third; the other worker
# the second, then the rest in order as it runs out. The end to end compiles the batch-8
# planner (its scenes settled in C) while the other worker runs programs_v2 (v1 and v2
# planners: nothing in common); then test_actions.py compiles the batch-8 MJX settle and action
# programs that scene_run (after the end to end) and notebook 01's kernel load, which keeps
# the notebook's cells short (nbclient's timeout), and its rollout test, the generate processes
# and the native audit load the planner.
FIRST = (
    "tests/e2e/test_reproduce_e2e.py",
    "tests/sim/test_programs_v2.py",
    "scene_run",
    "tests/sim/test_actions.py",
    "tests/data/test_generate_processes.py",
    "tests/data/test_audit.py",
    "tests/sim/test_reach_screen.py",
)


def unit_of(nodeid: str) -> str:
    """The work unit of a test id: its file, or the group the file belongs to."""
    path = nodeid.split("::", 1)[0]
    return GROUPS.get(path, path)


def order_units(units: list[str]) -> list[str]:
    """``units`` (collection order, no repeats) with ``FIRST``'s present ones in front, in its order."""
    first = [u for u in FIRST if u in units]
    return first + [u for u in units if u not in first]


def worker_cpus(cpus: list[int], worker: int, count: int) -> list[int] | None:
    """The CPUs worker ``worker`` of ``count`` runs on: every ``count``-th of ``cpus`` from its
    index; None (no pinning) when there are fewer CPUs than workers."""
    if count < 2 or len(cpus) < count or not 0 <= worker < count:
        return None
    return sorted(cpus)[worker::count]


def pin_worker() -> list[int] | None:
    """Pin this process's threads (and so the threads and processes they start) to its worker's
    CPUs, when it is an xdist worker; returns the CPUs, or None. Called when this plugin is
    loaded, before any test runs and before XLA sizes its thread pool (at its first computation)."""
    name, count = os.environ.get("PYTEST_XDIST_WORKER", ""), os.environ.get("PYTEST_XDIST_WORKER_COUNT", "")
    if not name.startswith("gw") or not count.isdigit() or os.environ.get("RELAFF_TEST_PIN") == "0":
        return None
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpus = worker_cpus(list(os.sched_getaffinity(0)), int(name[2:]), int(count))
    if cpus is None:
        return None
    # Linux affinity is per thread: set it on every thread that already exists
    for tid in os.listdir("/proc/self/task") if os.path.isdir("/proc/self/task") else ["0"]:
        try:
            os.sched_setaffinity(int(tid), cpus)
        except OSError:  # a thread that ended meanwhile
            pass
    return cpus


# the CPUs before pinning (a test starting its own two-worker suite gives them back to it)
MACHINE_CPUS = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
PINNED = pin_worker()


def _scheduler_class():
    from xdist.scheduler import LoadScopeScheduling

    class FileGroupScheduling(LoadScopeScheduling):
        """xdist's load-by-scope with a scope per file or group, longest units first."""

        def _split_scope(self, nodeid: str) -> str:
            return unit_of(nodeid)

        def _assign_work_unit(self, node) -> None:
            # the queue is complete before the first unit is handed out: put FIRST's units in front
            if not getattr(self, "_ordered", False):
                units = order_units(list(self.workqueue))
                self.workqueue = type(self.workqueue)((u, self.workqueue[u]) for u in units)
                self._ordered = True
            super()._assign_work_unit(node)

    return FileGroupScheduling


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile``: this suite's units (``GROUPS``) in this suite's order (``FIRST``)."""
    if config.getvalue("dist") != "loadfile":
        return None
    return _scheduler_class()(config, log)
