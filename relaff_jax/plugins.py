"""A user's plugin files: Python files that register conditions (``learn/conditions.py``) and/or
actions (``sim/actions/registry.py``), given with ``--plugins FILE.py``.

One loader for both kinds: ``load_file`` executes the file once (by its path and the sha256 of
its bytes), with ``LOADING`` telling the registries where what they register comes from, so
each record names the file and its hash; ``loaded_files`` / ``load_files`` give a worker process
the driver's files. No JAX at import.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Callable

from relaff_jax.errors import UserError

LOADING: list[tuple[str, str]] = []  # (origin, sha256) of the plugin file being executed
_LOADED: dict[str, tuple[str, list[str]]] = {}  # origin -> (sha256, names it registered)


def source_hash(f: Callable) -> str:
    """sha256 of the source of the module defining ``f`` (of ``f`` itself if that is not found)."""
    mod = sys.modules.get(getattr(f, "__module__", ""), None)
    try:
        src = inspect.getsource(mod) if mod is not None else inspect.getsource(f)
    except (OSError, TypeError):
        src = getattr(f, "__qualname__", repr(f))
    return hashlib.sha256(src.encode()).hexdigest()


def _registered() -> set[str]:
    import importlib

    conditions = importlib.import_module("relaff_jax.learn.conditions")
    registry = importlib.import_module("relaff_jax.sim.actions.registry")  # the module (the package's
    # attribute of that name is its registry() function)
    return {f"condition {n}" for n in conditions._REGISTRY} | {f"action {n}" for n in registry.user_names()}


def load_file(path: str | Path) -> list[str]:
    """Execute a Python file that registers conditions or actions; returns what it registered
    (``"condition NAME"``, ``"action NAME"``). A missing file, an error while executing it or a
    file that registers nothing is a ``UserError``; a file already loaded with the same bytes
    is not executed again."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"--plugins {path}: no such file")
    data = p.read_bytes()
    sha = hashlib.sha256(data).hexdigest()
    origin = f"file {p.resolve()}"
    if origin in _LOADED and _LOADED[origin][0] == sha:
        return list(_LOADED[origin][1])
    before = _registered()
    spec = importlib.util.spec_from_file_location(f"relaff_plugin_{p.stem}_{sha[:8]}", p)
    module = importlib.util.module_from_spec(spec)
    LOADING.append((origin, sha))
    try:
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    except UserError:
        raise
    except Exception as e:
        raise UserError(f"--plugins {path}: {type(e).__name__}: {e}") from e
    finally:
        LOADING.pop()
    new = sorted(_registered() - before)
    if not new:
        raise UserError(f"--plugins {path} registers no condition or action (decorate a function with "
                        "@relaff_jax.learn.register_condition(\"NAME\"), or call "
                        "relaff_jax.sim.actions.register_action(ActionSpec(...)))")
    _LOADED[origin] = (sha, new)
    return new



def _origins() -> dict[str, str]:
    """``{"condition NAME" / "action NAME": origin}`` of everything registered now."""
    import importlib

    conditions = importlib.import_module("relaff_jax.learn.conditions")
    registry = importlib.import_module("relaff_jax.sim.actions.registry")
    out = {f"condition {n}": c.origin for n, c in conditions._REGISTRY.items()}
    out.update({f"action {n}": u.origin for n, u in registry._USER.items()})
    return out


def any_executed() -> bool:
    """Whether a plugin file was executed in this process (even one whose registrations were
    undone since: what it ran may have changed any module)."""
    return bool(_LOADED)


def loaded_files() -> tuple[tuple[str, str], ...]:
    """``(path, sha256)`` of the plugin files executed in this process whose registrations all
    still stand (a test may have undone some), for its worker processes (``load_files``)."""
    live = _origins()
    return tuple((origin[len("file "):], sha) for origin, (sha, names) in _LOADED.items()
                 if all(live.get(n) == origin for n in names))


def _forget(origin: str) -> None:
    """Undo what the plugin file ``origin`` registered in this process (what still stands)."""
    import importlib

    conditions = importlib.import_module("relaff_jax.learn.conditions")
    registry = importlib.import_module("relaff_jax.sim.actions.registry")
    live = _origins()
    for n in _LOADED.pop(origin)[1]:
        if live.get(n) != origin:
            continue
        kind, _, name = n.partition(" ")
        if kind == "condition":
            conditions._REGISTRY.pop(name, None)
        else:
            registry.unregister(name)


def load_files(files) -> None:
    """In a worker process: make its plugin files the driver's ``files`` (``loaded_files``):
    what another driver had it execute is forgotten (a reused worker), the files not yet
    executed here are, so that its registries hold the driver's actions and conditions. A file
    whose bytes changed since the driver read them is a ``UserError``."""
    want = {f"file {path}": sha for path, sha in files}
    for origin in [o for o, (sha, _) in _LOADED.items() if want.get(o) != sha]:
        _forget(origin)
    for path, sha in files:
        if _LOADED.get(f"file {path}", (None,))[0] == sha:
            continue
        p = Path(path)
        if not p.is_file() or hashlib.sha256(p.read_bytes()).hexdigest() != sha:
            raise UserError(f"--plugins {path}: the file changed or went away while the run used it")
        load_file(p)
