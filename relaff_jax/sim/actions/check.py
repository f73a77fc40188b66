"""The user actions' rules traced once on a dummy scene (``jax.eval_shape``: no compile, no
simulation), so that a rule of the wrong shape is one clear line before any work."""
from __future__ import annotations

from typing import Iterable

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.sim.templates import N_TARGETS, ActionConfig

from .registry import is_builtin, spec
from .rules import Reading, Settled
from .spec import ActionSpec
from relaff_jax.sim.planning import setup

_SCALAR, _VEC = (), (3,)


def _shape_error(s: ActionSpec, field: str, what: str, got) -> UserError:
    return UserError(f"action {s.name!r}: field {field}: {what}, got {got}")


def _check_targets(s: ActionSpec, cfg: ActionConfig, setup) -> None:
    dummy = Settled(setup.arm, cfg, setup.geo, jnp.int32(0), jnp.zeros(14, jnp.float32))
    try:
        out = jax.eval_shape(lambda p, q: s.targets(dummy._replace(pair=p, qpos=q)), dummy.pair, dummy.qpos)
    except Exception as e:
        raise UserError(f"action {s.name!r}: field targets: tracing it on a settled scene failed: "
                        f"{type(e).__name__}: {e}") from e
    fields = ("targets", "opening", "ok", "direction", "grip_closed")
    if not all(hasattr(out, f) for f in fields):
        raise _shape_error(s, "targets", "expected a Program (targets, opening, ok, direction, grip_closed)",
                           type(out).__name__)
    t = out.targets
    need = max(x[1] for x in s.segments) + 1
    pos = getattr(t, "pos", None)
    k = pos.shape[0] if pos is not None and len(pos.shape) == 2 else None
    if k is None or not need <= k <= N_TARGETS:
        raise _shape_error(s, "targets", f"expected targets.pos (K, 3) with {need} <= K <= {N_TARGETS} (the "
                                         "segments' largest target index + 1 .. the compiled budget)",
                           None if pos is None else tuple(pos.shape))
    want = {"pos": (k, 3), "approach": (k, 3), "closing": (k, 3), "closing_weight": (k,), "closing_signed": (k,)}
    for f, shp in want.items():
        got = getattr(t, f, None)
        if got is None or tuple(got.shape) != shp:
            raise _shape_error(s, "targets", f"expected targets.{f} of shape {shp}",
                               None if got is None else tuple(got.shape))
    for f, shp in (("opening", _SCALAR), ("ok", _SCALAR), ("direction", _VEC), ("grip_closed", _SCALAR)):
        got = getattr(out, f)
        if tuple(got.shape) != shp:
            raise _shape_error(s, "targets", f"expected Program.{f} of shape {shp}", tuple(got.shape))


def _check_goal(s: ActionSpec, cfg: ActionConfig) -> None:
    z3, b = jnp.zeros((2, 3), jnp.float32), jnp.bool_(False)
    try:
        out = jax.eval_shape(lambda r: s.goal(cfg, r), Reading(z3, z3, jnp.zeros(3, jnp.float32), b, b))
    except Exception as e:
        raise UserError(f"action {s.name!r}: field goal: tracing it on a reading failed: "
                        f"{type(e).__name__}: {e}") from e
    if not hasattr(out, "shape") or tuple(out.shape) != () or out.dtype != np.bool_:
        raise _shape_error(s, "goal", "expected a () bool", getattr(out, "shape", type(out).__name__) if not hasattr(
            out, "dtype") else f"{tuple(out.shape)} {out.dtype}")


def check_actions(names: Iterable[str], cfg: ActionConfig = ActionConfig()) -> None:
    """Trace the target and goal rules of every user action in ``names`` once (built-ins are the
    package's); one ``UserError`` naming the action and the field. Builds the action world
    (``planning.setup``, cached for the run)."""
    users = [spec(n) for n in names if not is_builtin(n)]
    if not users:
        return

    st = setup(cfg)
    for s in users:
        _check_targets(s, cfg, st)
        _check_goal(s, cfg)
