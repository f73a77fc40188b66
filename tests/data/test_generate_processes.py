"""`relaff generate` gives the same dataset bits in two processes (same seed)."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


@pytest.mark.slow
def test_two_processes_generate_bit_identical_datasets(tmp_path):
    """`relaff generate` twice, in two processes, same seed: every stored array identical.

    The second process loads the first one's compiled programs from the session's JAX cache
    (conftest.py), so the cost is one compile of the take program (about a minute on two idle
    cores, several on loaded ones) and two short simulations."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    cmd = [sys.executable, "-m", "relaff_jax.cli", "generate", "take", "--samples", "2", "--batch", "8",
           "--max-rollouts", "32", "--seed", "3", "--engine", "native", "--set", "dataset.borrow_fraction=1.0", "--set", "dataset.distance_bins=2"]
    for name in ("a", "b"):
        r = subprocess.run(cmd + ["--out", str(tmp_path / name)], capture_output=True, text=True, env=env, timeout=1800)
        assert r.returncode == 0, r.stderr[-2000:]
    from relaff_jax.data.store import chunk_indices, chunk_path, read_chunk

    ca, cb = tmp_path / "a" / "chunks", tmp_path / "b" / "chunks"
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
    assert Path(tmp_path / "a" / "selection.json").read_text() == Path(tmp_path / "b" / "selection.json").read_text()
