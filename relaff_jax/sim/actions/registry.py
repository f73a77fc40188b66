"""One registry of actions: the nine built-ins (``builtin.py``) in ``constants.ACTIONS`` order,
then the user's (``register_action`` in a ``--plugins`` file, or the entry point group
``relaff_jax.actions``: entry point name = action name, value = an ``ActionSpec``).

A run's action list is ``names()``; an action's id (what the compiled programs index) is its
place in it, so the built-ins keep their ids. ``record`` gives what a folder stores of a user
action (origin, the sha256 of the plugin and of the spec: name, fields, the source of the
modules defining its rules), so a dataset never silently changes meaning. No JAX at import.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
from typing import Any, Callable

from relaff_jax import plugins
from relaff_jax.constants import ACTIONS, TOY_MANIPULATED
from relaff_jax.errors import UserError

from .spec import ActionSpec, check_fields

ENTRY_POINTS = "relaff_jax.actions"


@dataclasses.dataclass(frozen=True)
class UserAction:
    """A registered user action: its spec, where it came from and the sha256 of that source."""

    spec: ActionSpec
    origin: str
    sha256: str


_USER: dict[str, UserAction] = {}
_entry_points_loaded = False


def action_list_key() -> tuple[tuple[str, int], ...]:
    """The registered user actions, each by name and the identity of its spec: what a program
    built from ``registry()`` depends on beyond its arguments (the built-ins never change)."""
    return tuple((name, id(u.spec)) for name, u in _USER.items())


def per_action_list(maxsize: int) -> Callable[[Callable], Callable]:
    """``functools.lru_cache(maxsize)`` keyed also by ``action_list_key()``: a cache of programs
    built for one action list is not reused under another, and the nine's are found again once
    a user action is removed (a test registering one and removing it does not make the next
    test trace the planner again). A cached program keeps the specs it was built from, so
    their identities are not reused while its entry lives. ``.cache_clear()`` empties it."""
    def wrap(fn: Callable) -> Callable:
        cached = functools.lru_cache(maxsize=maxsize)(lambda key, *args, **kwargs: fn(*args, **kwargs))

        @functools.wraps(fn)
        def keyed(*args, **kwargs):
            _load_entry_points()
            return cached(action_list_key(), *args, **kwargs)

        keyed.cache_clear = cached.cache_clear
        return keyed

    return wrap


def register_action(spec: ActionSpec) -> ActionSpec:
    """Register a user action (checked: fields, a name not of a built-in or of another plugin's
    action; its rules are traced once by ``check.check_action`` before a run uses it)."""
    check_fields(spec)
    if spec.name in ACTIONS:
        raise UserError(f"action {spec.name!r}: field name: clashes with the built-in action {spec.name!r}; "
                        "choose another name")
    origin, sha = plugins.LOADING[-1] if plugins.LOADING else (f"module {spec.targets.__module__}",
                                                               plugins.source_hash(spec.targets))
    was = _USER.get(spec.name)
    if was is not None and was.origin != origin:
        raise UserError(f"action {spec.name!r} from {origin}: field name: clashes with the one from {was.origin}; "
                        "choose another name")
    _USER[spec.name] = UserAction(spec, origin, sha)
    return spec


def unregister(name: str) -> None:
    """Forget user action ``name`` (tests; a built-in cannot be removed)."""
    _USER.pop(name, None)


def _load_entry_points() -> None:
    """Register the actions of installed packages' ``relaff_jax.actions`` entry points, once."""
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        try:
            spec = ep.load()
        except Exception as e:
            raise UserError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINTS}): cannot load it: {e}") from e
        if not isinstance(spec, ActionSpec) or spec.name != ep.name:
            raise UserError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINTS}): expected an ActionSpec "
                            f"named {ep.name!r}")
        plugins.LOADING.append((f"entry point {ep.value}", plugins.source_hash(spec.targets)))
        try:
            register_action(spec)
        finally:
            plugins.LOADING.pop()


def user_names() -> tuple[str, ...]:
    """The user actions registered so far (without loading entry points)."""
    return tuple(_USER)


def names() -> tuple[str, ...]:
    """The run's action list: the nine built-ins, then the user's in registration order."""
    _load_entry_points()
    return ACTIONS + tuple(_USER)


def registry() -> tuple[ActionSpec, ...]:
    """The ordered specs of ``names()`` (ids = positions; the built-ins first)."""
    # the built-ins' rules import JAX: the command line's checks read this module
    from .builtin import BUILTINS

    _load_entry_points()
    return tuple(BUILTINS) + tuple(u.spec for u in _USER.values())


def action_id(name: str) -> int:
    """Index of action ``name`` in the run's list; an unknown name is a ``UserError`` listing them."""
    known = names()
    if name not in known:
        extra = "" if len(known) > len(ACTIONS) else " (a user action needs --plugins FILE.py)"
        raise UserError(f"unknown action {name!r}; valid actions: {', '.join(known)}{extra}")
    return known.index(name)


def spec(name: str) -> ActionSpec:
    """The spec of action ``name`` (a ``UserError`` if unknown)."""
    return registry()[action_id(name)]


def is_builtin(name: str) -> bool:
    return name in ACTIONS


def manipulated(name: str) -> str:
    """``"toy"`` or ``"other"``: the object action ``name``'s program manipulates (the spec's
    ``manipulated``; the nine's from ``constants.TOY_MANIPULATED``, which their specs declare,
    so that the learning stage reads it without JAX)."""
    action_id(name)
    if is_builtin(name):
        return "toy" if name in TOY_MANIPULATED else "other"
    return _USER[name].spec.manipulated


def spec_hash(s: ActionSpec) -> str:
    """sha256 of the spec: its name and fields and the source of the modules defining its rules
    (``manipulates`` only where declared: a spec written before the field keeps its hash)."""
    fields = {f.name: getattr(s, f.name) for f in dataclasses.fields(s) if f.name not in ("targets", "goal")}
    if s.manipulates is None:
        del fields["manipulates"]
    fields["segments"] = [list(x) for x in s.segments]
    fields["targets"] = plugins.source_hash(s.targets)
    fields["goal"] = plugins.source_hash(s.goal)
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()


def record(name: str) -> dict[str, Any] | None:
    """What a folder stores of action ``name``: None for a built-in (its meaning is the
    package's), else ``{"origin", "sha256" (of the plugin), "spec_sha256"}``."""
    if is_builtin(name):
        return None
    action_id(name)
    u = _USER[name]
    return {"origin": u.origin, "sha256": u.sha256, "spec_sha256": spec_hash(u.spec)}


def check_recorded(name: str, recorded: dict[str, Any] | None) -> None:
    """A folder made with action ``name`` (``recorded``: its ``record``, None for a built-in) is
    read with the same spec: the action registered (``--plugins``) and its spec's hash equal."""
    if recorded is None and is_builtin(name):
        return
    if name not in names():
        raise UserError(f"action {name!r} is a user action ({(recorded or {}).get('origin', 'origin not recorded')}); "
                        "give its plugin with --plugins FILE.py")
    now = record(name)
    if recorded is None or now is None or recorded.get("spec_sha256") != now["spec_sha256"]:
        raise UserError(f"action {name!r}: the registered spec ({now and now['origin']}) is not the one that made "
                        f"this folder ({(recorded or {}).get('origin')}; spec sha256 "
                        f"{(recorded or {}).get('spec_sha256', '?')[:12]} vs {(now or {}).get('spec_sha256', '?')[:12]})")


def key() -> tuple:
    """What the compiled programs depend on: the run's actions and their specs' identities
    (the caches of compiled functions are keyed on it with the config)."""
    _load_entry_points()
    return tuple((n, id(u.spec)) for n, u in _USER.items())
