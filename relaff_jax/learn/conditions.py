"""Conditions as registered functions: how a target's state is augmented from what is already learnt.

A condition is a function ``fn(k: Knowledge)`` of what the agent knows when it starts learning
target affordance ``k.target`` (its state on N scenes, the 0/1 outputs of the other actions'
source predictors and of the categories it may use, their correlations) giving the extra
columns of the state on the same N scenes: an array ``(N, E)`` (one learner, named after the
condition) or ``{variant: (N, E)}`` (one learner per variant, named ``NAME:variant``). Row i
of the output may depend on row i of the inputs only (checked: a condition is applied to a
target pool once, and the sweep takes its training and test rows from it).

The paper's five (NB, DB1, DBn, CB1, CBn) are registered here as built-ins with the same
signature. The sweep runs them through their plan (``protocol.condition_plan``: shared test
columns, the same bits as before conditions were registered; ``tests/learn/test_plugins.py`` checks
that each built-in's columns are the plan's); a user's conditions run after them, one learner
per variant, appended to the condition axis (``user_conditions.py``). A user registers conditions with
``@register_condition("NAME")`` in a Python file (``relaff experiment --plugins FILE.py``) or in an
installed package's entry point group ``relaff_jax.conditions`` (entry point name = condition
name); they run where named in ``experiment.conditions_pca`` / ``conditions_rhf``, and each is
recorded in ``experiment.json`` with a sha256 of its source (``record``).
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from relaff_jax.constants import ACTIONS, FAMILIES, SPACES
from relaff_jax.errors import UserError
from relaff_jax.learn.correlation import categories_above, category_pairs
from relaff_jax.plugins import load_file

ENTRY_POINTS = "relaff_jax.conditions"
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_VARIANT = re.compile(r"^[A-Za-z0-9_.+=-]+$")


@dataclasses.dataclass(frozen=True)
class Knowledge:
    """What is already learnt when target ``target`` is learnt, on N scenes of its pool.

    state: (N, D) float32 the target's state (its own order); sources: ``{action: (N,)}`` 0/1
    outputs of each other action's source predictor (the target's own is left out: it was
    trained on the target's labels); categories: ``{(a, b): (N,)}`` 0/1 outputs of the
    categories the target may use (empty where the space builds none); corr: (A, A) the source
    predictors' correlations (rows and columns in ``actions`` order); repeats: the paper's
    repetition of each bootstrap input in this space (6 PCA, 30 RHF); thresholds: the
    correlation heuristic's thresholds.
    """

    target: str
    actions: tuple[str, ...]
    state: np.ndarray
    sources: Mapping[str, np.ndarray]
    categories: Mapping[tuple[str, str], np.ndarray]
    corr: np.ndarray
    repeats: int
    thresholds: tuple[float, ...] = (0.0, 0.125, 0.5)

    @property
    def n(self) -> int:
        return int(self.state.shape[0])

    def repeated(self, *outputs: np.ndarray) -> np.ndarray:
        """``(N, len(outputs) * repeats)``: each output column repeated ``repeats`` times, in
        order (the paper's bootstrap input, ``states.augment``)."""
        if not outputs:
            return np.zeros((self.n, 0), np.float32)
        return np.repeat(np.stack(outputs, axis=1).astype(np.float32), self.repeats, axis=1)


@dataclasses.dataclass(frozen=True)
class Condition:
    """A registered condition: its function, where it came from and a sha256 of its source."""

    name: str
    fn: Callable[[Knowledge], Any]
    origin: str
    sha256: str
    builtin: bool = False


_REGISTRY: dict[str, Condition] = {}
from relaff_jax.plugins import LOADING as _loading  # noqa: E402 (the plugin file being loaded)
from relaff_jax.plugins import source_hash as _source_hash  # noqa: E402 (one hash for every plugin kind)
_entry_points_loaded = False


def register_condition(name: str, fn: Callable | None = None):
    """Register ``fn`` as condition ``name`` (also usable as ``@register_condition(name)``).
    A name of a built-in or of another registered condition is refused."""
    def add(f: Callable) -> Callable:
        if not isinstance(name, str) or not _NAME.match(name):
            raise UserError(f"condition name {name!r}: expected a letter, then letters, digits or _")
        if not callable(f):
            raise UserError(f"condition {name!r}: {f!r} is not a function")
        origin, sha = _loading[-1] if _loading else (f"module {f.__module__}", _source_hash(f))
        if name in _REGISTRY:
            was = _REGISTRY[name]
            if was.builtin or was.origin != origin:
                raise UserError(f"condition {name!r} from {origin} clashes with the "
                                f"{'built-in' if was.builtin else 'one from ' + was.origin}; choose another name")
        _REGISTRY[name] = Condition(name, f, origin, sha)
        return f

    return add(fn) if fn is not None else add


def load_plugin_file(path: str | Path) -> list[str]:
    """Execute a Python file that registers conditions (and/or actions: one loader for both,
    ``relaff_jax.plugins.load_file``); returns what it registered. A missing file, an error
    while executing it or a file that registers nothing is a ``UserError``."""
    return load_file(path)


def _load_entry_points() -> None:
    """Register the conditions of installed packages' ``relaff_jax.conditions`` entry points, once."""
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        try:
            fn = ep.load()
        except Exception as e:
            raise UserError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINTS}): cannot load it: {e}") from e
        _loading.append((f"entry point {ep.value}", _source_hash(fn)))
        try:
            register_condition(ep.name, fn)
        finally:
            _loading.pop()


def registered() -> dict[str, Condition]:
    """Every registered condition by name: the five built-ins, then plugins (entry points loaded)."""
    _load_entry_points()
    return dict(_REGISTRY)


def custom_names(cfg: Any, space: str) -> list[str]:
    """The user's conditions ``cfg`` runs in ``space`` (its condition list minus the built-ins)."""
    return [c for c in cfg.conditions(space) if c not in FAMILIES]


def check_conditions(cfg: Any) -> None:
    """Every user condition ``cfg`` names is registered and gives valid columns on a small
    synthetic knowledge (shape, finite, row by row): one ``UserError`` before any work."""
    names = dict.fromkeys(n for s in SPACES for n in custom_names(cfg, s))
    if not names:
        return
    reg = registered()
    for name in names:
        if name not in reg:
            raise UserError(f"condition {name!r} (experiment.conditions_*) is not registered: load the file that "
                            f"registers it with --plugins FILE.py, or install its package ({ENTRY_POINTS})")
        k = _probe_knowledge(cfg)
        cols = columns(reg[name], k)
        perm = np.arange(k.n)[::-1]
        flipped = columns(reg[name], dataclasses.replace(
            k, state=k.state[perm], sources={a: v[perm] for a, v in k.sources.items()},
            categories={p: v[perm] for p, v in k.categories.items()}))
        if [v for v, _ in cols] != [v for v, _ in flipped] or not all(
                np.array_equal(c[perm], f) for (_, c), (_, f) in zip(cols, flipped)):
            raise UserError(f"condition {name!r}: row i of its columns must depend on scene i only "
                            "(reordering the scenes changed them)")


def _probe_knowledge(cfg: Any, n: int = 12) -> Knowledge:
    """A synthetic knowledge of n scenes for target ``ACTIONS[0]`` (for ``check_conditions``)."""
    rng = np.random.default_rng(0)
    acts = tuple(ACTIONS)
    t = acts[0]
    return Knowledge(t, acts, rng.normal(size=(n, 18)).astype(np.float32),
                     {a: (rng.random(n) < 0.5).astype(np.float32) for a in acts[1:]},
                     {(acts[i], acts[j]): (rng.random(n) < 0.5).astype(np.float32)
                      for i, j in category_pairs(acts) if 0 not in (i, j)},
                     np.eye(len(acts)), cfg.repeats_pca, tuple(cfg.thresholds))


def columns(cond: Condition, k: Knowledge) -> list[tuple[str, np.ndarray]]:
    """``[(learner name, (N, E) float32 columns)]`` of a condition on ``k``; a ``UserError``
    naming the condition if its output is not an ``(N, E)`` finite array or a mapping of them."""
    try:
        out = cond.fn(k)
    except UserError:
        raise
    except Exception as e:
        raise UserError(f"condition {cond.name!r} ({cond.origin}) failed: {type(e).__name__}: {e}") from e
    items = [(cond.name, out)] if not isinstance(out, Mapping) else [(f"{cond.name}:{v}", c) for v, c in out.items()]
    res = []
    for name, c in items:
        if not isinstance(name, str) or not _VARIANT.match(name.partition(":")[2] or name):
            raise UserError(f"condition {cond.name!r}: variant name {name!r} must be letters, digits or _.+=-")
        c = np.asarray(c)
        if c.ndim != 2 or c.shape[0] != k.n or not np.issubdtype(c.dtype, np.number) and c.dtype != bool:
            raise UserError(f"condition {cond.name!r}: {name} must be an (N, E) numeric array with N = {k.n} scenes, "
                            f"got shape {c.shape} ({c.dtype})")
        c = c.astype(np.float32)
        if not np.all(np.isfinite(c)):
            raise UserError(f"condition {cond.name!r}: {name} has NaN or inf")
        res.append((name, c))
    return res


# --- the paper's five, registered like any other ---------------------------------------------

def _nb(k: Knowledge) -> np.ndarray:
    """No bootstrapping: the state alone."""
    return k.repeated()


def _db1(k: Knowledge) -> dict[str, np.ndarray]:
    """One other action's source predictor, repeated."""
    return {s: k.repeated(v) for s, v in k.sources.items()}


def _dbn(k: Knowledge) -> np.ndarray:
    """Every other action's source predictor, each repeated."""
    return k.repeated(*k.sources.values())


def _cb1(k: Knowledge) -> dict[str, np.ndarray]:
    """One category the target may use, repeated."""
    return {f"{a}+{b}": k.repeated(v) for (a, b), v in k.categories.items()}


def _cbn(k: Knowledge) -> dict[str, np.ndarray]:
    """Per threshold T, every usable category whose two source predictors correlate above T."""
    idx = {a: i for i, a in enumerate(k.actions)}
    pairs = [(idx[a], idx[b]) for a, b in k.categories]
    out = {}
    for t in k.thresholds:
        keep = categories_above(k.corr, pairs, t)
        out[f"T={t:g}"] = k.repeated(*[v for v, on in zip(k.categories.values(), keep) if on])
    return out


for _name, _fn in zip(FAMILIES, (_nb, _db1, _dbn, _cb1, _cbn)):
    _REGISTRY[_name] = Condition(_name, _fn, "built-in", _source_hash(_fn), builtin=True)
