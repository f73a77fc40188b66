"""What a run log records of the machine (relaff_jax/provenance.py): the CPU model and its
vector extensions, and the BLAS kernels scipy chose."""
import os
import subprocess
import sys

import numpy as np
import pytest


def test_cpuinfo_model_and_vector_extensions_by_hand():
    """Run logs record the CPU model and its vector extensions (XLA's code depends on them):
    the first processor's fields, only the listed extensions, in the listed order."""
    from relaff_jax.provenance import parse_cpuinfo

    text = ("processor\t: 0\ncpu family\t: 26\nmodel\t\t: 2\nmodel name\t: AMD EPYC 9R14\n"
            "flags\t\t: fpu sse4_2 avx512bw avx avx2 fma avx512f\n\n"
            "processor\t: 1\ncpu family\t: 25\nmodel\t\t: 17\nmodel name\t: other\nflags\t\t: fpu\n")
    assert parse_cpuinfo(text) == {"cpu_model": "AMD EPYC 9R14", "cpu_family": 26, "cpu_model_number": 2,
                                   "isa": ["sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw"]}
    assert parse_cpuinfo("") == {"cpu_model": None, "cpu_family": None, "cpu_model_number": None, "isa": []}


def test_machine_records_the_blas_kernels_scipy_chose():
    """The PCA features' eigen-solver runs in scipy's OpenBLAS, whose kernels depend on the CPU
    it finds: a run log names them. Forced by ``OPENBLAS_CORETYPE`` in a fresh process, the
    record follows (so it reads the library's choice, not a constant)."""
    from relaff_jax.provenance import machine

    blas = machine()["blas"]
    assert blas and all(b["internal_api"] and b["filepath"] for b in blas)
    if not any(b["internal_api"] == "openblas" for b in blas):
        pytest.skip("no OpenBLAS loaded: another BLAS names no kernel")
    code = "from relaff_jax.provenance import blas_kernels; print(sorted({b.get('architecture') for b in blas_kernels()}))"
    for core in ("Sandybridge", "Haswell"):
        env = dict(os.environ, OPENBLAS_CORETYPE=core)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
        assert core in out, (core, out)


def test_derive_seeds_is_derive_seed_row_by_row():
    """The vectorised seeds equal SeedSequence's, for tuples shorter and longer than its
    pool of four words, small and full 32-bit keys."""
    from relaff_jax.provenance import derive_seed, derive_seeds

    rng = np.random.default_rng(1)
    for k in (1, 3, 4, 5, 7, 8, 9):
        keys = rng.integers(0, 2**32, size=(60, k))
        keys[:30] = rng.integers(0, 6, size=(30, k))
        np.testing.assert_array_equal(derive_seeds(keys), [derive_seed(*row) for row in keys])
    assert derive_seeds(np.zeros((0, 7), np.int64)).shape == derive_seeds([]).shape == (0,)
    with pytest.raises(ValueError):
        derive_seeds([[2**32]])
