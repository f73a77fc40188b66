"""JAX's persistent compilation cache for the ``relaff`` command: on by default, per user.

Takes the environment (and the command's ``--no-compile-cache``); gives ``cache_dir()`` (where
compiled programs go, or None) and ``configure()`` (turns the cache on or off for this process
and the worker processes it starts). The folder: ``$RELAFF_COMPILE_CACHE`` if it names one;
else ``$JAX_COMPILATION_CACHE_DIR`` (JAX's own setting) if set; else
``$XDG_CACHE_HOME/relaff_jax/jax`` (``~/.cache/relaff_jax/jax``). ``RELAFF_COMPILE_CACHE=0``
(or off / false / no) or ``--no-compile-cache`` turns it off. A cached program is the
program XLA compiled, so results do not depend on the cache (docs/reproduce.md, "Compilation
cache"). ``enable_traces`` keeps traced programs beside it (``sim/traced_cache.py``). Library
users keep JAX's own default (off) and no traced programs; only the command line calls these.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

ENV = "RELAFF_COMPILE_CACHE"
TRACES_ENV = "RELAFF_TRACE_STORE"  # off: no traced programs kept (sim/traced_cache.py; the test session's)
MIN_SECONDS_ENV = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"  # JAX's: cache programs that compiled in this long
_OFF = ("0", "off", "false", "no")
_ON = ("1", "on", "true", "yes")
_traces: Path | None = None  # the traced programs' folder, once the command turned the store on


def cache_dir(environ=None) -> Path | None:
    """The cache folder the environment asks for (see the module doc), or None when it is off."""
    env = os.environ if environ is None else environ
    value = env.get(ENV, "").strip()
    if value.lower() in _OFF:
        return None
    if value and value.lower() not in _ON:
        return Path(value).expanduser()
    if env.get("JAX_COMPILATION_CACHE_DIR"):
        return Path(env["JAX_COMPILATION_CACHE_DIR"]).expanduser()
    base = env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "relaff_jax" / "jax"


def configure(disable: bool = False) -> Path | None:
    """Turn the cache on (``cache_dir()``) or off for this process and its children; returns
    the folder in use. Environment variables carry the setting, so it holds for processes
    started later (the experiment's workers) and for JAX imported after this call; if JAX is
    already imported its config is updated too. A folder that cannot be made leaves the cache
    off with one line on stderr: the cache only saves time."""
    d = None if disable else cache_dir()
    if d is not None:
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            print(f"relaff: note: compilation cache off, cannot use {d}: {e.strerror}", file=sys.stderr)
            d = None
    if d is None:
        os.environ["JAX_ENABLE_COMPILATION_CACHE"] = "false"
        os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    else:
        os.environ["JAX_ENABLE_COMPILATION_CACHE"] = "true"
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(d)
        # every program, not only those whose compile took over JAX's default 1 s (the small
        # glue programs between batches, dozens of shapes)
        os.environ.setdefault(MIN_SECONDS_ENV, "0")
        # Each program loaded from the cache makes XLA print an E-level "cpu_aot_loader" line
        # about +prefer-no-gather/scatter, tuning hints it mistakes for CPU features (noise:
        # docs/journal/2026-12-05.md, "--smoke on the idle machine"). jaxlib reads the variable
        # when it loads; a process that imported JAX first (a plugin file, a script calling
        # cli.main) gets the same level set at run time below. "1" is JAX's own default, which
        # importing JAX writes to the environment that child processes (a test's command) inherit,
        # so only another value counts as the user's and wins (0 shows the lines).
        if os.environ.get("TF_CPP_MIN_LOG_LEVEL", "1") == "1":
            os.environ["TF_CPP_MIN_LOG_LEVEL"] = "3"
    if "jax" in sys.modules:
        import jax

        if d is not None and os.environ["TF_CPP_MIN_LOG_LEVEL"] == "3":
            from jaxlib import utils as _xla_utils  # jax.config's "jax_logging_level" would also reset Python's loggers

            _xla_utils.absl_set_min_log_level(3)
        jax.config.update("jax_enable_compilation_cache", d is not None)
        if d is not None:
            jax.config.update("jax_compilation_cache_dir", str(d))
            jax.config.update("jax_persistent_cache_min_compile_time_secs", float(os.environ[MIN_SECONDS_ENV]))
    return d


def enable_traces(d: Path | None) -> Path | None:
    """The ``relaff`` command's: keep traced programs in ``d/traced`` (``sim/traced_cache.py``)
    for this process, ``d`` being the compilation cache ``configure`` returned; off when ``d``
    is None or ``$RELAFF_TRACE_STORE`` is off (``0``/off/false/no: the test session sets it, so
    no test reads another's trace). Returns the folder, or None."""
    global _traces
    off = os.environ.get(TRACES_ENV, "").strip().lower() in _OFF
    _traces = None if d is None or off else Path(d) / "traced"
    return _traces


def traces_dir() -> Path | None:
    """The folder ``enable_traces`` turned on in this process, or None (a library's default)."""
    return _traces
