"""The suite on several pytest-xdist workers (`python -m pytest -n 2 --dist loadfile`): which
files run on one worker, in what order, and on which cores (a pytest plugin loaded by
tests/conftest.py; without xdist it does nothing).

- One work unit per test file, so a file's module fixtures are built once. Files that share a
  session fixture of ``helpers.fixtures`` that simulates form one unit (``GROUPS``), so it is
  built once too (a session fixture is per worker).
- Each worker runs its lane first (``LANES``): one lane holds the units that run the default
  motor programs in the worker's process, after the end to end traced them there; the other
  starts with long units that simulate no arm. Then both take the rest as they run out.
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

# Two lanes, one per worker (the first worker to ask takes lane A, the second lane B; a third
# takes no lane). Each runs its own units first, in order, then both take the rest in collection
# order as they run out. Lane A holds the units that run the default programs at batch 8 in the
# worker's own process (or there and in child processes: the generate processes' audit), after
# the tiny end to end (run in process) has traced and compiled them: the later units reuse that
# process's traced programs (a planner's trace is 20-30 s, the compile 50 s) and nothing is
# traced or compiled on both workers at once. Lane B starts with
# long units that simulate no arm, then the units whose child processes plan with the default
# programs (they load them from the session's compilation cache, written by then: the end to
# end's generate stage is its first ~300 s), then scene_run, whose notebook kernels load the
# MJX programs tests/sim/test_actions.py compiles on lane A.
LANE_A = (
    "tests/e2e/test_reproduce_e2e.py",
    "tests/sim/test_actions.py",
    "tests/data/test_generate_processes.py",
    "tests/sim/test_programs_v2.py",
    "tests/sim/test_guarded_descent.py",
    "tests/sim/test_programs_v3.py",
    "tests/sim/test_animate.py",
    "tests/sim/test_native_engine.py",
    "tests/sim/test_reach_screen.py",
    "tests/sim/test_warm.py",
    "tests/sim/test_still.py",
)
LANE_B = (
    "tests/learn/test_engine.py",
    "tests/perception/test_perception.py",
    "tests/sim/test_arm.py",
    "tests/learn/test_intervals.py",
    "tests/sim/test_arm_sim.py",
    "tests/perception/test_features.py",
    "tests/sim/test_scenes.py",
    "tests/data/test_audit.py",
    "tests/sim/test_action_plugins.py",
    "scene_run",
)
LANES = (LANE_A, LANE_B)


def unit_of(nodeid: str) -> str:
    """The work unit of a test id: its file, or the group the file belongs to."""
    path = nodeid.split("::", 1)[0]
    return GROUPS.get(path, path)


def next_unit(queued: list[str], lane: tuple[str, ...]) -> str:
    """The unit a worker of ``lane`` runs next, of the ``queued`` ones (collection order): its
    lane's first still queued, else the first queued in no lane, else the first queued."""
    for unit in lane:
        if unit in queued:
            return unit
    laned = {u for ln in LANES for u in ln}
    return next((u for u in queued if u not in laned), queued[0])


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
        """xdist's load-by-scope with a scope per file or group, each worker its lane first."""

        def _split_scope(self, nodeid: str) -> str:
            return unit_of(nodeid)

        def _assign_work_unit(self, node) -> None:
            lanes = self.__dict__.setdefault("_lanes", {})
            if node not in lanes:  # the first worker to ask takes lane A, the second lane B
                lanes[node] = LANES[len(lanes)] if len(lanes) < len(LANES) else ()
            unit = next_unit(list(self.workqueue), lanes[node])
            self.workqueue.move_to_end(unit, last=False)  # xdist hands out the queue's first unit
            super()._assign_work_unit(node)

    return FileGroupScheduling


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile``: this suite's units (``GROUPS``), each worker its lane first (``LANES``)."""
    if config.getvalue("dist") != "loadfile":
        return None
    return _scheduler_class()(config, log)
