"""The audit's fast replay (``probe_arrays.ArrayProbe``, the replay's pad contacts from arrays) and
its worker processes (``data/audit_replay.py``) give the audit of the former path, field for field,
on a generated native dataset."""
import subprocess
import sys

import numpy as np
import pytest

from relaff_jax.data import audit as A
from relaff_jax.data import audit_replay as AR
from relaff_jax.sim.native import reference as native
from relaff_jax.sim.native import probe_arrays
from relaff_jax.sim.native.probe import Probe


def _former_pad_contacts(d, pad, geoms):
    cons = [c for c in d.contact[:d.ncon]
            if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms)]
    return np.array([c.dist for c in cons]), np.array([np.asarray(c.frame[:3], np.float64) for c in cons]).reshape(-1, 3)


def test_workers_for_few_scenes_is_one():
    assert AR.n_workers(AR.MIN_PER_JOB - 1, 2) == 1 and AR.n_workers(2 * AR.MIN_PER_JOB, 2) == 2
    assert AR.n_workers(10 * AR.MIN_PER_JOB, 1) == 1 and AR.default_jobs() >= 1


@pytest.mark.slow  # generates a small native dataset (plan compile), audits it three times, starts 2 workers
def test_fast_audit_and_its_workers_equal_the_former_audit(tmp_path, monkeypatch):
    d = tmp_path / "take"
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "generate", "take", "--samples", "8", "--out", str(d),
                        "--engine", "native", "--batch", "8", "--seed", "5"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    with monkeypatch.context() as mp:  # the former path: Probe, contacts read one at a time
        mp.setattr(probe_arrays, "ArrayProbe", Probe)
        mp.setattr(native, "_pad_contacts", _former_pad_contacts)
        ref = A.audit_dataset(d, 6, 0, jobs=1)
    one = A.audit_dataset(d, 6, 0, jobs=1)
    monkeypatch.setattr(AR, "MIN_PER_JOB", 1)
    two = A.audit_dataset(d, 6, 0, jobs=2)  # 2 spawned workers, 3 scenes each
    assert ref["n_audited"] >= 4 and ref["replay"]["label_agreement"] == 1.0
    for a in (one, two):
        assert a["rollouts"] == ref["rollouts"]
        assert {k: v for k, v in a.items() if k != "seconds"} == {k: v for k, v in ref.items() if k != "seconds"}


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
