"""A small declarative vocabulary for config values (like scikit-learn's ``_parameter_constraints``).

A node declares ``_constraints``, a class attribute mapping a field name to a constraint
(``Interval``, ``Options``, ``Boolean``, ``Seq``, ``AnyOf``, ``Check``), or a tuple of field
names to a ``Rule`` over the whole node (a cross-field rule, reported under its first field).
``check_node`` is the one checker: every node's ``__post_init__`` calls it, so a node is checked
once, when it is built. Numbers are finite everywhere (NaN and +-inf refused) unless an
``Interval`` says ``inf=True``; integers are capped (``INT_MAX`` unless a tighter bound is
declared) so that a huge value is refused here, not after minutes of work.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any, Callable, Iterable

from relaff_jax.errors import UserError

INT_MAX = 2**31 - 1  # int32: the arrays the stages size from these counts


class ConfigError(UserError):
    """A config key or value that the tree does not take (exit 2, one line)."""


class RuleError(ConfigError):
    """A cross-field rule a node's values break together (``Rule``)."""


def _num(v: Any) -> str:
    return repr(v) if not isinstance(v, float) or v != int(v) or abs(v) > 1e15 else str(v)


class Constraint:
    def problem(self, v: Any) -> str | None:  # what is wrong with ``v`` (None: fine)
        raise NotImplementedError

    def describe(self) -> str:
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class Interval(Constraint):
    """A number of ``type`` (``int``: an integer, not a bool; ``float``: any real) in
    [lo, hi] (``closed``: "both", "left", "right" or "neither"; ``None``: unbounded; an ``int``
    interval is capped at ``INT_MAX``). NaN is always refused, +-inf unless ``inf``."""

    type: type
    lo: float | None = None
    hi: float | None = None
    closed: str = "both"
    inf: bool = False

    def _hi(self):
        return INT_MAX if self.type is int and self.hi is None else self.hi

    def describe(self) -> str:
        what = "an integer" if self.type is int else "a finite number" if not self.inf else "a number"
        lo, hi = self.lo, self.hi  # the implicit INT_MAX cap is not shown
        left = "[" if self.closed in ("both", "left") else "("
        right = "]" if self.closed in ("both", "right") else ")"
        if lo is None and hi is None:
            return what
        if hi is None:
            return f"{what} {'>=' if left == '[' else '>'} {_num(lo)}"
        if lo is None:
            return f"{what} {'<=' if right == ']' else '<'} {_num(hi)}"
        return f"{what} in {left}{_num(lo)}, {_num(hi)}{right}"

    def problem(self, v: Any) -> str | None:
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            return self.describe()
        if self.type is int and not isinstance(v, numbers.Integral):
            return self.describe()
        if math.isnan(v) or (math.isinf(v) and not self.inf):
            return self.describe()
        lo, hi = self.lo, self._hi()
        if lo is not None and (v < lo or (v == lo and self.closed in ("right", "neither"))):
            return self.describe()
        if hi is not None and (v > hi or (v == hi and self.closed in ("left", "neither"))):
            return self.describe()
        return None


@dataclasses.dataclass(frozen=True)
class Options(Constraint):
    """One of ``values`` (strings, or ``None``)."""

    values: tuple

    def __init__(self, values: Iterable):
        object.__setattr__(self, "values", tuple(values))

    def describe(self) -> str:
        return "one of " + ", ".join("null" if v is None else str(v) for v in self.values)

    def problem(self, v: Any) -> str | None:
        ok = any(v is w if w is None else (isinstance(v, str) and v == w) for w in self.values)
        return None if ok else self.describe()


@dataclasses.dataclass(frozen=True)
class Boolean(Constraint):
    def describe(self) -> str:
        return "true or false"

    def problem(self, v: Any) -> str | None:
        return None if isinstance(v, bool) else self.describe()


@dataclasses.dataclass(frozen=True)
class Seq(Constraint):
    """A list of items each meeting ``item``: ``length`` items exactly, or at least
    ``min_len``; ``distinct`` / ``increasing`` (strictly) if asked."""

    item: Constraint
    length: int | None = None
    min_len: int = 1
    distinct: bool = False
    increasing: bool = False

    def describe(self) -> str:
        n = f"{self.length} " if self.length is not None else f"at least {self.min_len} " if self.min_len else ""
        extra = ", distinct" * self.distinct + ", strictly increasing" * self.increasing
        return f"a list of {n}values{extra}, each {self.item.describe()}"

    def problem(self, v: Any) -> str | None:
        if not isinstance(v, (tuple, list)):
            return self.describe()
        if (self.length is not None and len(v) != self.length) or len(v) < self.min_len:
            return self.describe()
        if any(self.item.problem(x) for x in v):
            return self.describe()
        if self.distinct and len(set(v)) != len(v):
            return self.describe()
        if self.increasing and any(b <= a for a, b in zip(v, v[1:])):
            return self.describe()
        return None


@dataclasses.dataclass(frozen=True)
class AnyOf(Constraint):
    """Any one of ``options`` (e.g. ``null`` or an integer)."""

    options: tuple

    def __init__(self, *options: Constraint):
        object.__setattr__(self, "options", options)

    def describe(self) -> str:
        return " or ".join(o.describe() for o in self.options)

    def problem(self, v: Any) -> str | None:
        return None if any(o.problem(v) is None for o in self.options) else self.describe()


@dataclasses.dataclass(frozen=True)
class Check(Constraint):
    """A value checked by ``ok(value) -> bool``; ``must`` says what it must be."""

    ok: Callable[[Any], bool]
    must: str

    def describe(self) -> str:
        return self.must

    def problem(self, v: Any) -> str | None:
        try:
            good = bool(self.ok(v))
        except (TypeError, ValueError, AttributeError, IndexError):
            good = False
        return None if good else self.must


@dataclasses.dataclass(frozen=True)
class Rule:
    """A cross-field rule: ``ok(node) -> bool`` over the whole node, checked after every
    field's own constraint; ``must(node) -> str`` says what is wrong."""

    ok: Callable[[Any], bool]
    must: Callable[[Any], str]


NULL = Options((None,))
FRACTION = Interval(float, 0.0, 1.0)
POS = Interval(float, 0.0, None, closed="neither")
NONNEG = Interval(float, 0.0, None)


def length(hi: float = 10.0) -> Interval:
    """A length in metres, in [0, hi] (the workspace is a few metres across)."""
    return Interval(float, 0.0, hi)


def count(lo: int = 1, hi: int | None = None) -> Interval:
    return Interval(int, lo, hi)


def _shown(v: Any) -> str:
    return "[" + ", ".join(_shown(x) for x in v) + "]" if isinstance(v, (tuple, list)) else \
        ("null" if v is None else repr(v) if isinstance(v, str) else str(v))


def check_node(node: Any) -> None:
    """The one checker: each field of ``node`` against its ``_constraints`` entry, then the
    node's cross-field ``Rule``s; the first problem is a ``ConfigError`` naming the key from
    the tree's root (``node._path``). Fields without an entry must be nested nodes."""
    path = getattr(type(node), "_path", type(node).__name__)
    cons = type(node)._constraints
    for key, c in cons.items():
        if isinstance(key, str):
            v = getattr(node, key)
            p = c.problem(v)
            if p is not None:
                raise ConfigError(f"config key '{path + '.' if path else ''}{key}' must be {p}, got {_shown(v)}")
    for key, c in cons.items():
        if not isinstance(key, str):
            try:
                good = bool(c.ok(node))
            except (TypeError, ValueError, ArithmeticError):
                good = False
            if not good:
                at = path + "." if path else ""
                also = "".join(f" (with '{at}{k}')" for k in key[1:])
                raise RuleError(f"config key '{at}{key[0]}'{also} {c.must(node)}")


def unchecked_fields(cls: type) -> list[str]:
    """Fields of a node class with neither a constraint nor a nested node (for tests)."""
    named = {k for k in cls._constraints if isinstance(k, str)}
    return [f.name for f in dataclasses.fields(cls) if f.name not in named
            and not dataclasses.is_dataclass(f.default) and f.default_factory is dataclasses.MISSING]
