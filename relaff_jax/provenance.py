"""What a run folder records about how it was made: package versions, the machine, seeds, and
the config record every stage writes into its output folder (``record_config``)."""
from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path
from typing import Any

import numpy as np
from relaff_jax import io as rio
from relaff_jax.config import to_dict

PACKAGES = ("relaff_jax", "jax", "jaxlib", "mujoco", "mujoco-mjx", "numpy", "scikit-learn",
            "orbax-checkpoint", "matplotlib")


def versions() -> dict[str, str | None]:
    """Python and the versions of the packages that can change results (None: not installed)."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


# The vector extensions that decide which code XLA:CPU emits (docs/reproduce.md: the same code
# and seed on AVX-512 and AVX2 gives other contact outcomes).
ISA_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512vl", "avx512_bf16", "amx_tile")


def parse_cpuinfo(text: str) -> dict[str, Any]:
    """The first processor's ``model name``, ``cpu family`` and ``model`` numbers and which of
    ``ISA_FLAGS`` its ``flags`` hold, from the text of Linux's ``/proc/cpuinfo``. The numbers
    say more than a virtual machine's generic name ("AMD EPYC"), and OpenBLAS picks its kernels
    from them (``blas_kernels``)."""
    fields: dict[str, str] = {}
    for line in text.splitlines():
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    number = lambda k: int(fields[k]) if fields.get(k, "").isdigit() else None
    flags = set(fields.get("flags", "").split())
    return {"cpu_model": fields.get("model name"), "cpu_family": number("cpu family"), "cpu_model_number": number("model"),
            "isa": [f for f in ISA_FLAGS if f in flags]}


def blas_kernels() -> list[dict[str, Any]]:
    """The BLAS libraries loaded for numpy and scipy and the kernels each chose at run time
    (``threadpoolctl``; OpenBLAS's ``architecture``: Haswell, SkylakeX, ...). JAX's CPU linear
    algebra (``jnp.linalg.eigh``, so the PCA features) calls scipy's LAPACK, whose OpenBLAS picks
    its kernels from the CPU it finds: on this machine forcing SkylakeX kernels instead of Haswell
    moves PCA features by up to 1.4e-6 and leaves RHF's bits alone (docs/reproduce.md). Empty
    when threadpoolctl (scikit-learn's dependency) or scipy is missing."""
    try:
        import scipy.linalg  # noqa: F401  loads scipy's OpenBLAS, which jax's LAPACK calls go to
        from threadpoolctl import threadpool_info
    except ImportError:
        return []
    keep = ("internal_api", "version", "architecture", "filepath")
    out = [{k: Path(d[k]).name if k == "filepath" else d.get(k) for k in keep if k in d}
           for d in threadpool_info() if d.get("user_api") == "blas"]
    return sorted(out, key=lambda b: (str(b.get("internal_api")), str(b.get("filepath"))))  # in load order otherwise


def machine() -> dict[str, Any]:
    """Platform, CPU architecture, model, vector extensions, core count and BLAS kernels (XLA's
    code, and so float rounding and contact outcomes, depend on the CPU's features; the PCA
    features' eigen-solver on the BLAS kernels)."""
    out = {"platform": platform.platform(), "machine": platform.machine(), "cpus": os.cpu_count()}
    text = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            text = f.read()
        out.update(parse_cpuinfo(text))
    except OSError:  # not Linux: the processor string is all there is
        out.update(cpu_model=platform.processor() or None, isa=None)
    out["blas"] = blas_kernels()
    out["xla_target"] = xla_target(text)
    return out


def xla_target(cpuinfo: str) -> dict[str, Any]:
    """What decides the code XLA:CPU compiles (the MJX engine, the ray caster) on this machine:
    it targets the host CPU as LLVM sees it, every feature flag the (virtual) CPU exposes, unless
    ``XLA_FLAGS`` caps it (``--xla_cpu_max_isa``). Two VM builds of one machine kind that expose
    different flags get different instructions, so other float rounding and, through chaotic
    contacts, other MJX rollouts (docs/reproduce.md, "Which arrays depend on the machine").
    Gives the ``XLA_FLAGS`` in force, the stepping and microcode (not in ``parse_cpuinfo``),
    and the number and sha256 prefix of the whole CPU flag list: equal prefixes, same flags."""
    import hashlib

    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    flags = sorted(set(fields.get("flags", "").split()))
    return {"xla_flags": os.environ.get("XLA_FLAGS", ""), "stepping": fields.get("stepping"),
            "microcode": fields.get("microcode"), "cpu_flags": len(flags),
            "cpu_flags_sha256": hashlib.sha256(" ".join(flags).encode()).hexdigest()[:16] if flags else None}


def derive_seed(*keys: int) -> int:
    """A 32-bit seed from integer keys: an independent stream per tuple of keys.

    ``derive_seed(run_seed, stage, index)`` never collides with another tuple's stream
    (``numpy.random.SeedSequence`` hashes the whole tuple).
    """
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])


# numpy's SeedSequence constants (numpy/random/bit_generator.pyx)
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R, _POOL = 0xCA01F9DD, 0x4973F715, 4


def derive_seeds(keys: np.ndarray) -> np.ndarray:
    """``derive_seed(*row)`` of every row of ``keys: (F, K)`` integers in [0, 2**32), as
    ``(F,)`` int64, in one vectorised pass (a SeedSequence object per seed costs ~20 us, the
    sweep derives one per forest). SeedSequence's own mixing, step by step: each key is one
    32-bit word of entropy, the pool of 4 words is mixed with ``hashmix`` / ``mix`` and the
    first word of ``generate_state`` is hashed out; tests check it against SeedSequence."""
    if len(keys) == 0:
        return np.zeros(0, np.int64)
    keys = np.asarray(keys, dtype=np.int64)
    if keys.ndim != 2 or keys.size and (keys.min() < 0 or keys.max() >= 2**32):
        raise ValueError(f"derive_seeds: keys must be (F, K) integers in [0, 2**32), got shape {keys.shape}")
    m32 = np.uint64(0xFFFFFFFF)
    sh = np.uint64(16)
    ent = keys.astype(np.uint64)
    h = _INIT_A

    def hashmix(v):
        nonlocal h
        v = (v ^ np.uint64(h)) & m32
        h = (h * _MULT_A) & 0xFFFFFFFF
        v = (v * np.uint64(h)) & m32  # both < 2**32: the product fits in uint64
        return v ^ (v >> sh)

    def mix(x, y):
        r = (np.uint64(_MIX_L) * x - np.uint64(_MIX_R) * y) & m32  # uint64 wraps: mod 2**32 after the mask
        return r ^ (r >> sh)

    zero = np.zeros(len(keys), np.uint64)
    pool = [hashmix(ent[:, i] if i < ent.shape[1] else zero) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for src in range(_POOL, ent.shape[1]):
        for dst in range(_POOL):
            pool[dst] = mix(pool[dst], hashmix(ent[:, src]))
    v = (pool[0] ^ np.uint64(_INIT_B)) & m32
    v = (v * np.uint64((_INIT_B * _MULT_B) & 0xFFFFFFFF)) & m32
    return (v ^ (v >> sh)).astype(np.int64)


CONFIG_RECORD = "relaff_config.json"


def record_config(folder: str | os.PathLike, cfg: Any, command: str, argv: list[str] | None = None) -> Path:
    """Write the whole resolved config tree that made ``folder`` into ``folder/relaff_config.json``
    (atomically, after the stage finished): ``{"command", "argv", "config", "versions"}``, one
    shape for every stage and route. The stage's own sidecars record the settings that decide
    its output and its resume checks; this file says how the folder was made in full."""
    path = Path(folder) / CONFIG_RECORD
    rio.atomic_write_json(path, {"command": command, "argv": argv, "config": to_dict(cfg), "versions": versions()})
    return path
