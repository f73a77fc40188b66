"""`relaff generate` gives the same dataset bits in two processes (same seed), and the audit's
fast replay of that dataset equals the former replay (tests/data/test_audit_jobs.py): one small
native take dataset made twice serves both (each `relaff generate` process traces the planner)."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from relaff_jax.data import audit as A
from relaff_jax.data import audit_replay as AR
from relaff_jax.sim.native import probe_arrays
from relaff_jax.sim.native import reference as native
from relaff_jax.sim.native.probe import Probe

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def two_datasets(tmp_path_factory):
    """``relaff generate take`` (native engine, 8 samples, seed 5) in two processes: two folders.

    The second process loads the first one's compiled programs from the session's JAX cache
    (conftest.py), so the cost is at most one compile of the take planner and two short
    simulations (none in the whole suite, where the end-to-end test compiled it before:
    helpers/workers.py)."""
    root = tmp_path_factory.mktemp("take")
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    cmd = [sys.executable, "-m", "relaff_jax.cli", "generate", "take", "--samples", "8", "--batch", "8",
           "--seed", "5", "--engine", "native"]
    for name in ("a", "b"):
        r = subprocess.run(cmd + ["--out", str(root / name)], capture_output=True, text=True, env=env, timeout=1800)
        assert r.returncode == 0, r.stderr[-2000:]
    return root / "a", root / "b"


def test_two_processes_generate_bit_identical_datasets(two_datasets):
    """`relaff generate` twice, in two processes, same seed: every stored array identical."""
    from relaff_jax.data.store import chunk_indices, chunk_path, read_chunk

    a_dir, b_dir = two_datasets
    ca, cb = a_dir / "chunks", b_dir / "chunks"
    ks = chunk_indices(ca)
    assert ks
    assert ks == chunk_indices(cb)
    n = 0
    for k in ks:
        a, _ = read_chunk(chunk_path(ca, k))
        b, _ = read_chunk(chunk_path(cb, k))
        assert sorted(a) == sorted(b)
        for key in a:
            np.testing.assert_array_equal(np.asarray(a[key]), np.asarray(b[key]), err_msg=f"chunk {k} {key}")
            n += 1
    assert n > 10
    assert Path(a_dir / "selection.json").read_text() == Path(b_dir / "selection.json").read_text()


def _former_pad_contacts(d, pad, geoms):
    cons = [c for c in d.contact[:d.ncon]
            if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms)]
    return np.array([c.dist for c in cons]), np.array([np.asarray(c.frame[:3], np.float64) for c in cons]).reshape(-1, 3)


def test_fast_audit_and_its_workers_equal_the_former_audit(two_datasets, monkeypatch):
    """The audit of the former path (``Probe``, contacts read one at a time), the fast path in
    this process and the fast path in 2 spawned workers (3 scenes each): equal, field for field."""
    d = two_datasets[0]
    with monkeypatch.context() as mp:
        mp.setattr(probe_arrays, "ArrayProbe", Probe)
        mp.setattr(native, "_pad_contacts", _former_pad_contacts)
        ref = A.audit_dataset(d, 6, 0, jobs=1)
    one = A.audit_dataset(d, 6, 0, jobs=1)
    monkeypatch.setattr(AR, "MIN_PER_JOB", 1)
    two = A.audit_dataset(d, 6, 0, jobs=2)
    assert ref["n_audited"] >= 4 and ref["replay"]["label_agreement"] == 1.0
    for a in (one, two):
        assert a["rollouts"] == ref["rollouts"]
        assert {k: v for k, v in a.items() if k != "seconds"} == {k: v for k, v in ref.items() if k != "seconds"}
