"""The audit's worker processes (``data/audit_replay.py``): how many, and which plugin files they
load. The fast replay and its workers against the former audit, on a generated native dataset:
tests/data/test_generate_processes.py (it shares that test's dataset)."""
import numpy as np

from relaff_jax.data import audit_replay as AR


def test_workers_for_few_scenes_is_one():
    assert AR.n_workers(AR.MIN_PER_JOB - 1, 2) == 1 and AR.n_workers(2 * AR.MIN_PER_JOB, 2) == 2
    assert AR.n_workers(10 * AR.MIN_PER_JOB, 1) == 1 and AR.default_jobs() >= 1


def test_workers_get_only_the_plugin_files_whose_registrations_stand(tmp_path, monkeypatch):
    """A plugin file whose registrations were undone (as a test's registry fixture does) is not
    handed to the audit's workers: they would register its names again, clashing with a later
    file of the same names (what two workers of the test suite met)."""
    from pathlib import Path

    from relaff_jax import plugins as P
    from relaff_jax.learn import conditions as C

    monkeypatch.setattr(C, "_REGISTRY", dict(C._REGISTRY))
    monkeypatch.setattr(P, "_LOADED", dict(P._LOADED))
    src = ("from relaff_jax.learn import register_condition\n\n\n@register_condition('AUDITVOTE')\n"
           "def vote(k):\n    return k.state\n")
    first, second = tmp_path / "first.py", tmp_path / "second.py"
    first.write_text(src)
    second.write_text(src)
    P.load_file(first)
    C._REGISTRY.pop("AUDITVOTE")  # undone: the name is free again
    P.load_file(second)
    seen = []

    class Pool:  # stands in for the spawned workers: records what each would load
        def __init__(self, *a, **k):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def map(self, fn, jobs):
            seen.extend(j[1] for j in jobs)
            return [({"x": np.zeros(1)}, {"y": np.zeros(1)}) for _ in jobs]

    monkeypatch.setattr(AR, "ProcessPoolExecutor", Pool)
    monkeypatch.setattr(AR, "MIN_PER_JOB", 1)
    AR.replay_probed({}, None, "take", np.zeros(2, int), np.zeros((2, 14)), np.zeros((2, 12)),
                     {"feasible": np.ones(2, bool)}, 0, jobs=2)
    assert len(seen) == 2
    for files in seen:
        assert [Path(p).name for p, _ in files if Path(p).parent == tmp_path] == ["second.py"]
