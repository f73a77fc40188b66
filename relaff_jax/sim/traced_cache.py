"""Traced programs kept on disk beside JAX's compilation cache, so a later run skips the trace.

Takes a pure function of arrays, a name and a key (what else shapes its trace, e.g. the
config); gives ``stored_jit(fn, name, key)``, a jitted stand-in for ``fn``. JAX's persistent
cache (``relaff_jax/compile_cache.py``) keeps what XLA compiled, keyed by the lowered program, so every
run still traces the Python function and lowers it before it can ask the cache; for the motor
programs' planner (nine actions' programs and their IK in one ``lax.switch``) that trace is
~15 CPU s, most of a warm quick run's generate stage. With the compilation cache on,
``stored_jit`` keeps ``fn``'s traced and lowered program per argument shape, serialized by
``jax.export``, in ``<compile cache>/traced/``; a later process reads it instead of tracing.
Every call runs that exported program (``Exported.call``, jitted, whose compile JAX's cache
keeps as usual), whether it was traced now or read from disk, so a fresh and a warm run run
the same program; ``tests/sim/test_traced_cache.py`` (an IK program) and
``benchmarks/planner_trace.py`` (the planner) check its outputs against ``jax.jit(fn)``'s, bit
for bit.

The store is read and written only where nothing but the package's own code can have shaped a
trace: when the ``relaff`` command turned it on (``compile_cache.enable_traces``: the
compilation cache on and ``RELAFF_TRACE_STORE`` not off), and only while no plugin file has been
executed in the process and no user action is registered (a plugin is arbitrary code: it may
change a module the planner reads without changing anything in the file name below). Otherwise
``stored_jit(fn, ...)`` is ``jax.jit(fn)``: ``relaff_jax`` used as a library (whose caller may
monkeypatch a module), ``--no-compile-cache``, a plugin. The test session sets ``RELAFF_TRACE_STORE=0`` for itself and
the commands it starts, so no test reads a trace another test stored (its processes share one
compilation cache); the store's own tests use a private folder.

A stored program's file name is a sha256 of everything its trace reads: the name, the key's
``repr``, the arguments' shapes and dtypes, the JAX and jaxlib versions, the JAX settings
that change a trace, every file of the package and of its MJCF scenes (``sources_digest``),
and the active object set. Anything else ``fn`` reads must be in ``key``. A file that cannot be
read is traced and written again.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import threading
from pathlib import Path
from typing import Any, Callable

import jax
import jaxlib
import numpy as np

from .arm_model import scenes_dir

# JAX settings that change what a function traces to (the others change only its compile,
# which JAX's own cache key covers)
TRACE_SETTINGS = ("jax_enable_x64", "jax_threefry_partitionable", "jax_default_matmul_precision",
                  "jax_numpy_rank_promotion", "jax_numpy_dtype_promotion", "jax_default_prng_impl")


def folder() -> Path | None:
    """The store's folder (``<compilation cache>/traced``), or None when the store is off: not
    turned on by the command, or a plugin file executed, or a user action registered."""
    from relaff_jax import compile_cache, plugins
    from .actions.registry import user_names

    where = compile_cache.traces_dir()
    if where is None or plugins.any_executed() or user_names():
        return None
    return where


@functools.lru_cache(maxsize=1)
def sources_digest() -> str:
    """sha256 of every file of the package and of its scenes folder (paths and bytes): a
    stored program is only read by the code that traced it."""
    h = hashlib.sha256()
    for root in (Path(__file__).resolve().parents[1], scenes_dir()):
        for p in sorted(root.rglob("*")):
            if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"):
                h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def _context() -> list:
    """What a trace reads besides its function's code and key: versions, settings, objects (user
    actions turn the store off, ``folder``)."""
    from . import object_library, objects  # here: object_library imports the config tree, which imports sim

    return [jax.__version__, jaxlib.__version__, [str(getattr(jax.config, s, None)) for s in TRACE_SETTINGS],
            sources_digest(), object_library.digest(objects.active().specs)]


def _spec(a: Any) -> jax.ShapeDtypeStruct:
    if isinstance(a, (jax.Array, np.ndarray, np.generic)):
        return jax.ShapeDtypeStruct(np.shape(a), a.dtype)
    if isinstance(a, (bool, int, float)):  # a Python scalar: the dtype jit gives it
        return jax.ShapeDtypeStruct((), jax.dtypes.canonicalize_dtype(np.asarray(a).dtype))
    raise TypeError(f"stored_jit: arguments must be arrays or scalars, got {type(a).__name__}")


def file_name(name: str, key: Any, specs: tuple) -> str:
    """The stored program's file name for ``name``, ``key`` and the argument ``specs``."""
    text = json.dumps([name, repr(key), [(list(s.shape), str(s.dtype)) for s in specs], _context()])
    return f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.jaxexport"


def _write(path: Path, blob: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(blob)
    os.replace(tmp, path)  # atomic: a concurrent reader sees the whole file or none


def load_or_export(fn: Callable, name: str, key: Any, specs: tuple, where: Path) -> jax.export.Exported:
    """``fn`` at ``specs`` as an ``Exported``: read from ``where`` if stored, else traced and stored."""
    from jax import export

    path = where / file_name(name, key, specs)
    try:
        exp = export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # missing, damaged or written by another serialization: trace it again
        pass
    else:
        _lapack_ready()
        return exp
    exp = export.export(jax.jit(fn))(*specs)
    try:
        _write(path, bytes(exp.serialize()))
    except (OSError, ImportError):  # a full or read-only cache (or no flatbuffers) only costs time
        pass
    return exp


def _lapack_ready() -> None:
    """Load jaxlib's LAPACK kernels before a program read from disk runs. JAX loads them when it
    lowers a linear-algebra call; a program read from disk (the IK's SVD and LU solves) is not
    lowered in this process, and run first its LAPACK call crashes the process (segmentation
    fault, jaxlib 0.9.2)."""
    from jaxlib import lapack

    lapack.prepare_lapack_call("gesdd_ffi", np.dtype(np.float32))


class _Stored:
    def __init__(self, fn: Callable, name: str, key: Any):
        self.fn, self.name, self.key = fn, name, key
        self.jitted = jax.jit(fn)
        self.calls: dict = {}
        # one trace and one compile per argument shape, whichever thread calls first (a
        # warm-up on the generate stage's background thread, sim/warm.py): a second caller
        # waits for the first's program instead of tracing and compiling it again
        self.lock = threading.Lock()

    def __call__(self, *args):
        where = folder()
        try:
            specs = tuple(_spec(a) for a in args)
        except TypeError:
            if where is not None:
                raise
            return self.jitted(*args)  # jax.jit's own rules, as without the store
        sig = (where, tuple((s.shape, str(s.dtype)) for s in specs))
        call = self.calls.get(sig)
        if call is not None:
            return call(*self._args(args, specs, where))
        with self.lock:
            call = self.calls.get(sig)
            if call is None:  # the first call of this shape: traced (or read) and compiled here
                call = self.jitted if where is None else jax.jit(
                    load_or_export(self.fn, self.name, self.key, specs, where).call)
                out = call(*self._args(args, specs, where))
                self.calls[sig] = call
                return out
        return call(*self._args(args, specs, where))

    @staticmethod
    def _args(args: tuple, specs: tuple, where: Path | None) -> list:
        if where is None:
            return list(args)
        return [np.asarray(a, s.dtype) if not isinstance(a, jax.Array) else a for a, s in zip(args, specs)]


def stored_jit(fn: Callable, name: str, key: Any = ()) -> Callable:
    """``jax.jit(fn)`` whose traced program is kept on disk (module doc). ``fn`` takes arrays
    or scalars (no keyword arguments) and returns arrays in tuples, dicts or namedtuples
    registered with ``jax.export.register_namedtuple_serialization``; ``name`` names its files
    and ``key`` (its ``repr``) holds what else shapes the trace."""
    return _Stored(fn, name, key)
