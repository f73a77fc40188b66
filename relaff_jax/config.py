"""Frozen config dataclasses and the one path for overriding them.

Every stage owns a frozen dataclass of its static settings (defaults are the paper's).
``override(cfg, {"key": value})`` returns a copy with checked overrides: an unknown key
is an error that lists the valid ones, never silently ignored.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A config key or value that the stage does not know."""


def override(cfg: T, updates: Mapping[str, Any] | None = None, **kwargs: Any) -> T:
    """Return ``cfg`` with fields replaced; unknown keys raise ``ConfigError``.

    Nested dataclasses are addressed with dots: ``{"camera.width": 320}``.
    """
    merged = dict(updates or {}, **kwargs)
    if not merged:
        return cfg
    direct: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    names = {f.name for f in dataclasses.fields(cfg)}
    for key, value in merged.items():
        head, _, rest = key.partition(".")
        if head not in names:
            raise ConfigError(
                f"unknown config key {key!r} for {type(cfg).__name__}; valid keys: {sorted(names)}"
            )
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in nested.items():
        direct[head] = override(getattr(cfg, head), sub)
    return dataclasses.replace(cfg, **direct)


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
            flat[key] = tuple(value)
        else:
            flat[key] = value
    return override(default, flat)
