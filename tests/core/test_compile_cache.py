"""JAX's persistent compilation cache of the ``relaff`` command (relaff_jax/compile_cache.py)."""
import os
import subprocess
import sys

from relaff_jax import compile_cache as cc
from relaff_jax.cli import build_parser


def test_cache_folder_from_the_environment(tmp_path):
    home = {"HOME": str(tmp_path)}
    assert cc.cache_dir({"XDG_CACHE_HOME": "/x/cache"}) == cc.Path("/x/cache/relaff_jax/jax")
    assert cc.cache_dir({}) == cc.Path(os.path.expanduser("~")) / ".cache" / "relaff_jax" / "jax"
    assert cc.cache_dir({"JAX_COMPILATION_CACHE_DIR": "/j", **home}) == cc.Path("/j")  # JAX's own setting
    assert cc.cache_dir({"RELAFF_COMPILE_CACHE": "/r", "JAX_COMPILATION_CACHE_DIR": "/j"}) == cc.Path("/r")
    assert cc.cache_dir({"RELAFF_COMPILE_CACHE": "1", "XDG_CACHE_HOME": "/x"}) == cc.Path("/x/relaff_jax/jax")
    for off in ("0", "off", "False", "no"):
        assert cc.cache_dir({"RELAFF_COMPILE_CACHE": off, "JAX_COMPILATION_CACHE_DIR": "/j"}) is None


def test_no_compile_cache_flag_parses_before_and_after_the_command():
    p = build_parser()
    assert p.parse_args(["reproduce", "--out", "x"]).no_compile_cache is False
    assert p.parse_args(["--no-compile-cache", "reproduce", "--out", "x"]).no_compile_cache is True
    assert p.parse_args(["reproduce", "--out", "x", "--no-compile-cache"]).no_compile_cache is True


def test_configure_turns_jax_cache_on_and_off_in_a_fresh_process(tmp_path):
    """In a child process (JAX's config is process-wide): the cache folder gets a compiled
    program when on, even one that compiles in milliseconds, and JAX is told the cache is off
    when off."""
    code = ("import sys, os; from relaff_jax import compile_cache as cc; d = cc.configure(disable=sys.argv[1] == 'off');"
            "import jax, jax.numpy as jnp;"
            "jax.jit(lambda x: jnp.sin(x) * 3)(jnp.arange(5.0)).block_until_ready();"
            "print(d, jax.config.jax_enable_compilation_cache, jax.config.jax_compilation_cache_dir)")
    env = dict(os.environ, RELAFF_COMPILE_CACHE=str(tmp_path / "c"))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env.pop(cc.MIN_SECONDS_ENV, None)
    on = subprocess.run([sys.executable, "-c", code, "on"], env=env, capture_output=True, text=True, check=True)
    assert on.stdout.split() == [str(tmp_path / "c"), "True", str(tmp_path / "c")]
    assert any((tmp_path / "c").iterdir())
    off = subprocess.run([sys.executable, "-c", code, "off"], env=env, capture_output=True, text=True, check=True)
    assert off.stdout.split()[:2] == ["None", "False"]


def test_programs_loaded_from_the_cache_print_nothing(tmp_path):
    """XLA logs an E-level ``cpu_aot_loader`` false alarm for each program it loads from the
    cache on these CPUs. configure() silences it also in a process that imported JAX first and
    inherited JAX's ``TF_CPP_MIN_LOG_LEVEL=1`` (a test's or a script's command); a user's other
    value is kept."""
    code = ("import sys, os, jax, jax.numpy as jnp; from relaff_jax import compile_cache as cc; cc.configure();"
            "jax.jit(lambda x: jnp.cos(x) * 5 + 1)(jnp.arange(7.0)).block_until_ready();"
            "print(os.environ['TF_CPP_MIN_LOG_LEVEL'])")
    env = dict(os.environ, RELAFF_COMPILE_CACHE=str(tmp_path / "c"), TF_CPP_MIN_LOG_LEVEL="1")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    for _ in range(2):  # the second run loads the program the first one stored
        run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        assert (run.stdout.strip(), run.stderr) == ("3", "")
    assert any((tmp_path / "c").iterdir())
    run = subprocess.run([sys.executable, "-c", code], env=dict(env, TF_CPP_MIN_LOG_LEVEL="0"), capture_output=True,
                         text=True, check=True)
    assert run.stdout.strip() == "0" and "pjrt_executable" in run.stderr  # the user asked to see XLA's log
