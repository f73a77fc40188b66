"""The one path for overriding frozen config dataclasses.

Every node of the tree is a frozen dataclass (defaults are the paper's) in this package;
``relaff_jax.config.tree.RunConfig`` nests them into one tree. ``override(cfg, {"key": value})``
returns a copy with checked overrides: an unknown key is an error that lists the valid ones,
never silently ignored. ``parse_set`` turns the CLI's ``--set dotted.key=value`` into such a
mapping.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any, Iterable, Mapping, TypeVar

from relaff_jax.config.constraints import ConfigError

T = TypeVar("T")


def parse_set(items: Iterable[str]) -> dict[str, Any]:
    """``["a.b=1", "c=[1, 2]", "d=robwork"]`` -> ``{"a.b": 1, "c": (1, 2), "d": "robwork"}``.

    Values are read as JSON where they parse (numbers, booleans, lists, null), else kept as
    strings; lists become tuples (config fields are immutable).
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            v = json.loads(value)
        except json.JSONDecodeError:
            v = value
        out[key.strip()] = _freeze(v)
    return out


def _freeze(v: Any) -> Any:
    return tuple(_freeze(x) for x in v) if isinstance(v, list) else v


def override(cfg: T, updates: Mapping[str, Any] | None = None, **kwargs: Any) -> T:
    """Return ``cfg`` with fields replaced; unknown keys raise ``ConfigError``.

    Nested dataclasses are addressed with dots: ``{"camera.width": 320}``.
    """
    merged = dict(updates or {}, **kwargs)
    return _override(cfg, merged, "") if merged else cfg


def override_under(cfg: T, updates: Mapping[str, Any], prefix: str) -> T:
    """``override`` of the node ``cfg`` found at ``prefix`` (``"dataset."``) of a larger tree:
    the error messages name the keys as they are spelled from the tree's root."""
    return _override(cfg, dict(updates), prefix) if updates else cfg


def _override(cfg: T, merged: Mapping[str, Any], prefix: str) -> T:
    direct: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    names = {f.name for f in dataclasses.fields(cfg)}
    for key, value in merged.items():
        head, _, rest = key.partition(".")
        if head not in names:
            raise ConfigError(f"unknown config key {prefix + key!r}: {type(cfg).__name__} has no {head!r}; "
                              f"valid keys{' under ' + prefix[:-1] if prefix else ''}: {sorted(names)}")
        if rest and not dataclasses.is_dataclass(getattr(cfg, head)):
            raise ConfigError(f"config key {prefix + key!r}: {prefix + head} has no sub-keys")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = _checked(type(cfg).__name__, prefix + key, getattr(cfg, head), value)
    for head, sub in nested.items():
        direct[head] = _override(getattr(cfg, head), sub, f"{prefix}{head}.")
    return dataclasses.replace(cfg, **direct)


def _checked(owner: str, key: str, old: Any, new: Any) -> Any:
    """``new`` if it has the kind of value ``old`` has (ints for ints, numbers for floats,
    booleans for booleans, tuples for tuples); a float field given an int gets a float, so a
    config has one spelling per value. ``None`` fields take anything."""
    where = f"config key {key!r} ({owner})"
    if dataclasses.is_dataclass(old):
        if isinstance(new, type(old)):  # a whole group, e.g. from ``from_dict``
            return new
        raise ConfigError(f"{where} is a group of settings; set one of its keys, e.g. {key}.<name>")
    if old is None or new is None:
        return new
    if isinstance(old, bool):
        if not isinstance(new, bool):
            raise ConfigError(f"{where} expects true or false, got {new!r}")
    elif isinstance(old, int):
        if isinstance(new, bool) or not isinstance(new, int):
            raise ConfigError(f"{where} expects an integer, got {new!r}")
    elif isinstance(old, float):
        if isinstance(new, bool) or not isinstance(new, (int, float)):
            raise ConfigError(f"{where} expects a number, got {new!r}")
        return float(new)
    elif isinstance(old, str):
        if not isinstance(new, str):
            raise ConfigError(f"{where} expects a string, got {new!r}")
    elif isinstance(old, tuple):
        if not isinstance(new, (tuple, list)):
            raise ConfigError(f"{where} expects a list, e.g. [1, 2], got {new!r}")
        return tuple(new)
    return new


def to_dict(cfg: Any) -> dict[str, Any]:
    """Plain-dict view of a (nested) config dataclass, for JSON sidecars."""
    return dataclasses.asdict(cfg)


def from_dict(cls: type[T], data: Mapping[str, Any]) -> T:
    """Rebuild a config from ``to_dict`` output, checking keys (nested dataclasses too)."""
    default = cls()
    flat: dict[str, Any] = {}
    for key, value in data.items():
        field = getattr(default, key, None)
        if dataclasses.is_dataclass(field) and isinstance(value, Mapping):
            flat[key] = from_dict(type(field), value)
        elif isinstance(getattr(default, key, None), tuple) and isinstance(value, list):
            flat[key] = _freeze(value)  # nested lists too: JSON has no tuples
        else:
            flat[key] = value
    return override(default, flat)


def differences(stored: Any, wanted: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    """The dotted keys at which two JSON trees differ, with the stored and the wanted value
    (a key missing on one side shows as ``<absent>``)."""
    if isinstance(stored, dict) and isinstance(wanted, dict):
        out = []
        for k in sorted(set(stored) | set(wanted), key=str):
            key = f"{prefix}.{k}" if prefix else str(k)
            out += differences(stored.get(k, "<absent>"), wanted.get(k, "<absent>"), key)
        return out
    return [] if stored == wanted else [(prefix, stored, wanted)]
