"""Traced programs stored on disk (sim/traced_cache.py): stored, read back without tracing,
keyed by what shapes them, redone when damaged, and running the same bits as ``jax.jit``; off
unless the ``relaff`` command turned it on, off in this test session and wherever a plugin or
user action runs, so a monkeypatched module cannot read another test's trace."""
import importlib
import os
import subprocess
import sys
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from relaff_jax import compile_cache, plugins
from relaff_jax.sim import rollouts, templates  # noqa: F401 (imports the config tree before traced_cache)
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import traced_cache as tc
from relaff_jax.sim import world as wd
from relaff_jax.sim.native.settle import settle_batch
from relaff_jax.sim.planning import setup
from relaff_jax.sim.programs import toy_reachable


class Pair(NamedTuple):
    total: jax.Array
    scaled: jax.Array


jax.export.register_namedtuple_serialization(Pair, serialized_name="tests.sim.test_traced_cache.Pair")


def toy(k, x):
    k = jnp.asarray(k, jnp.int32)
    y = jax.lax.switch(k, [jnp.sin, jnp.cos, jnp.tanh], x) * (1.0 + 1e-3 * x)
    return Pair(jnp.sum(y, axis=-1), y / (1.0 + jnp.abs(y)))


X = np.linspace(-2.0, 2.0, 24, dtype=np.float32).reshape(4, 6)


registry = importlib.import_module("relaff_jax.sim.actions.registry")  # (the package's attribute is a function)
GAIN = 2.0  # a module setting a traced function reads (a test below monkeypatches it)


def gained():
    """``x * GAIN``, a new function each call, as in a new process (JAX keeps a trace per
    function object within one)."""
    return lambda x: x * GAIN


@pytest.fixture
def stored(tmp_path, monkeypatch):
    """The store on in the private folder ``tmp_path``, as the command turns it on (no plugin
    file executed, no user action in this process: another test's are set aside)."""
    monkeypatch.setattr(compile_cache, "_traces", tmp_path)
    monkeypatch.setattr(plugins, "_LOADED", {})
    monkeypatch.setattr(registry, "_USER", {})
    return tmp_path


def _equal(a, b):
    return all(np.array_equal(np.asarray(u), np.asarray(v)) for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_off_is_jit(monkeypatch, tmp_path):
    """Off (a library's default, and this session's): ``jax.jit``, nothing written in JAX's
    compilation cache folder, which this session's processes share."""
    assert compile_cache.traces_dir() is None and tc.folder() is None
    before = sorted(os.listdir(jax.config.jax_compilation_cache_dir))
    out = tc.stored_jit(toy, "toy")(1, X)
    assert _equal(out, jax.jit(toy)(1, X)) and isinstance(out, Pair)
    assert "traced" not in os.listdir(jax.config.jax_compilation_cache_dir) and "traced" not in before


def test_enable_traces_only_where_the_environment_allows(monkeypatch, tmp_path):
    monkeypatch.setattr(compile_cache, "_traces", None)
    assert os.environ[compile_cache.TRACES_ENV] == "0"  # tests/conftest.py: the whole session
    assert compile_cache.enable_traces(tmp_path) is None and compile_cache.traces_dir() is None
    monkeypatch.delenv(compile_cache.TRACES_ENV)
    assert compile_cache.enable_traces(None) is None  # the compilation cache off
    assert compile_cache.enable_traces(tmp_path) == tmp_path / "traced" == compile_cache.traces_dir()


@pytest.mark.slow  # two new processes (~10 s idle)
def test_the_command_keeps_traces_only_outside_the_test_session(tmp_path):
    """``relaff`` in a new process: the store on in its compilation cache, and off when started
    from this session (its environment)."""
    code = ("import sys; from relaff_jax.cli import main; main(sys.argv[1:]);"
            "from relaff_jax import compile_cache; print('traces', compile_cache.traces_dir())")
    env = dict(os.environ, RELAFF_COMPILE_CACHE=str(tmp_path / "c"))
    run = lambda env, *flags: subprocess.run([sys.executable, "-c", code, *flags, "objects"], env=env,
                                             capture_output=True, text=True, check=True).stdout.splitlines()[-1]
    assert run(env) == "traces None"
    env.pop(compile_cache.TRACES_ENV)
    assert run(env) == f"traces {tmp_path / 'c' / 'traced'}"


def test_plugins_and_user_actions_turn_the_store_off(stored, monkeypatch):
    assert tc.folder() == stored
    monkeypatch.setattr(plugins, "_LOADED", {"file /x/p.py": ("0" * 64, [])})  # even one since undone
    assert plugins.any_executed() and tc.folder() is None
    monkeypatch.setattr(plugins, "_LOADED", {})
    monkeypatch.setattr(registry, "_USER", {"drag": None})
    assert tc.folder() is None
    monkeypatch.setattr(registry, "_USER", {})
    assert tc.folder() == stored


def test_a_monkeypatched_module_cannot_read_a_stored_trace(stored, monkeypatch):
    """What the store would risk, and what keeps it out of this session: a trace stored with the
    module as it was is read back after a test changed the module (the file name cannot see
    the change); with the store as this session has it (off), the change is traced."""
    x = np.arange(4, dtype=np.float32)
    assert np.array_equal(tc.stored_jit(gained(), "gained")(x), 2 * x)  # stored
    monkeypatch.setattr(sys.modules[__name__], "GAIN", 3.0)
    assert np.array_equal(tc.stored_jit(gained(), "gained")(x), 2 * x)  # the store on: the stale trace
    monkeypatch.setattr(compile_cache, "_traces", compile_cache.enable_traces(stored))  # as the session does
    assert compile_cache.traces_dir() is None
    assert np.array_equal(tc.stored_jit(gained(), "gained")(x), 3 * x)


def test_stored_then_read_without_tracing(stored, monkeypatch):
    ref = [jax.jit(toy)(k, X) for k in range(3)]
    first = tc.stored_jit(toy, "toy", ("cfg", 1))
    assert all(_equal(first(k, X), r) for k, r in enumerate(ref))
    files = sorted(p.name for p in stored.iterdir())
    assert len(files) == 1 and files[0].startswith("toy-") and files[0].endswith(".jaxexport")

    def no_trace(*a, **k):
        raise AssertionError("traced again")

    monkeypatch.setattr(jax.export, "export", no_trace)
    again = tc.stored_jit(toy, "toy", ("cfg", 1))  # a new process's first call
    out = again(2, X)
    assert isinstance(out, Pair) and _equal(out, ref[2])
    with pytest.raises(AssertionError, match="traced again"):  # another key is another trace
        tc.stored_jit(toy, "toy", ("cfg", 2))(0, X)
    with pytest.raises(AssertionError, match="traced again"):  # and so is another shape
        tc.stored_jit(toy, "toy", ("cfg", 1))(0, X[:2])


@pytest.mark.parametrize("store", [True, False])
def test_threads_calling_first_at_once_trace_once(store, tmp_path, monkeypatch, request):
    """Two threads making the first call of one shape at once (the generate stage's warm-up
    beside the generation, sim/warm.py): one traces and compiles, the other waits for its
    program; both get jax.jit's bits. With the store on and off."""
    import threading

    if store:
        request.getfixturevalue("stored")
    traced, gate = [], threading.Barrier(2)

    def slow_toy(k, x):
        traced.append(1)  # runs at trace time only
        return toy(k, x)

    fn = tc.stored_jit(slow_toy, "slow_toy", ("cfg", 3))
    outs = [None, None]

    def call(i):
        gate.wait()
        outs[i] = fn(1, X)

    threads = [threading.Thread(target=call, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    ref = jax.jit(toy)(1, X)
    assert len(traced) == 1 and len(fn.calls) == 1
    assert all(_equal(o, ref) for o in outs)


def test_key_holds_what_shapes_the_trace(monkeypatch):
    spec = (jax.ShapeDtypeStruct((), jnp.int32), jax.ShapeDtypeStruct((4, 6), jnp.float32))
    name = tc.file_name("toy", "k", spec)
    assert name == tc.file_name("toy", "k", spec)
    assert name != tc.file_name("toy", "k2", spec)
    assert name != tc.file_name("toy", "k", (spec[0], jax.ShapeDtypeStruct((4, 6), jnp.int32)))
    monkeypatch.setattr(tc, "sources_digest", lambda: "another package")
    assert name != tc.file_name("toy", "k", spec)


def test_damaged_file_is_traced_again(stored):
    tc.stored_jit(toy, "toy")(0, X)
    (path,) = stored.iterdir()
    path.write_bytes(b"not a program")
    assert _equal(tc.stored_jit(toy, "toy")(0, X), jax.jit(toy)(0, X))
    assert path.read_bytes() != b"not a program"


@pytest.mark.slow  # two traces and compiles of an IK program (~20 s idle)
def test_ik_program_same_bits_stored(stored):
    """unobstruct's toy reach (an L-BFGS IK per scene, ``reach_screen.jitted_parts``): the stored
    program gives jax.jit's bits (the planner itself: benchmarks/planner_trace.py)."""
    cfg = templates.ActionConfig()
    world = wd.build_world(cfg.phys)
    place_fn, _, _ = sc.jitted_scene_fns(world, cfg.scene)
    kp, ks = jax.random.split(jax.random.PRNGKey(1))
    pair = sc.sample_pairs(kp, rollouts.allowed_pairs(world, "unobstruct"), world, 16)
    scenes = settle_batch(world, *jax.device_get((pair, *place_fn(ks, pair))), cfg.scene, 1)
    pair, qpos = np.asarray(pair, np.int32), np.asarray(scenes.qpos, np.float32)

    st = setup(cfg)
    reach = jax.vmap(lambda a, q: toy_reachable(st.arm, cfg, st.geo, a, q))
    ref = jax.jit(reach)(pair, qpos)
    assert _equal(tc.stored_jit(reach, "toy_reach-test", cfg)(pair, qpos), ref)
    assert _equal(tc.stored_jit(reach, "toy_reach-test", cfg)(pair, qpos), ref)  # read back from the file


SVD_FIRST = """
import sys
from pathlib import Path
import numpy as np
import jax.numpy as jnp
from relaff_jax import compile_cache
from relaff_jax.sim import rollouts  # noqa: F401 (the config tree before traced_cache)
from relaff_jax.sim import traced_cache as tc
compile_cache._traces = Path(sys.argv[1])
svd = tc.stored_jit(lambda x: jnp.linalg.svd(x, compute_uv=False), "svd_first")
print(np.asarray(svd(np.diag(np.float32([3, 2, 1])))).tolist())
"""


def test_a_stored_linear_algebra_program_runs_first_in_a_new_process(tmp_path):
    """A program read from disk is not lowered in the process that runs it, so nothing there has
    loaded jaxlib's LAPACK kernels: run first, its SVD crashed the process (the planner's home
    pose, read from disk before any other IK). The second process reads the first's trace."""
    run = lambda: subprocess.run([sys.executable, "-c", SVD_FIRST, str(tmp_path)], capture_output=True, text=True)
    first = run()
    assert first.returncode == 0, first.stderr[-2000:]
    assert [p.name.split("-")[0] for p in tmp_path.iterdir()] == ["svd_first"]  # stored by the first
    second = run()
    assert second.returncode == 0, f"exit {second.returncode}: {second.stderr[-2000:]}"
    assert first.stdout.splitlines()[-1] == second.stdout.splitlines()[-1] == "[3.0, 2.0, 1.0]"
