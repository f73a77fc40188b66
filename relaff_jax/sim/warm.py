"""The planner's programs compiled ahead of the generation that needs them, on another thread.

Takes an ``ActionConfig``, the rollout batch and the actions a run generates; gives
``unobstruct_warmups(cfg, batch, actions)``: functions of no argument, each tracing (or reading
from the traced store, ``traced_cache``) and compiling one of the planner's programs at the
shape the generation calls it with, on placeholder scenes, and returning nothing: unobstruct's
two halves screened apart (``reach_screen.jitted_parts``, its program's plan and its toy's
reach), which only unobstruct needs, and it is generated last.

The generate stage runs them on its background thread (``stages/audits.py``) from its start,
while the first action compiles its own programs (XLA's compiles leave the GIL free): on a
new install they are about 45 s of trace and compile that unobstruct no longer waits for (``docs/reproduce.md``, "The quick preset's defaults"). The
planner shared by every action (``rollouts.jitted_stage_fns``) is not warmed: the first action
needs it seconds after the stage starts, and tracing it beside that action's own traces only
made them take turns (lift 103 s against 94 on a new install); the unobstruct warm-ups started
after the first action instead slowed the next two (docs/journal/2026-12-07.md). A generation that reaches a program
being warmed waits for it (``traced_cache._Stored``'s lock) instead of tracing it again. A compiled program depends on
its arguments' shapes and dtypes, not their values, so the generation runs the programs it
would have compiled itself: the same bits.

The cached program objects are built here, in the caller's thread, with the run's object set
active, before any function is returned: the threads then share them.
"""
from __future__ import annotations

import functools
from typing import Callable, Sequence

import jax
import numpy as np

from relaff_jax.sim import world as wd
from relaff_jax.sim.actions.registry import action_id
from relaff_jax.sim.object_library import use_scene
from relaff_jax.sim.reach_screen import PLAN_CHUNK, jitted_parts
from relaff_jax.sim.templates import ActionConfig


def placeholder_scenes(cfg: ActionConfig, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """``(pair (rows,) int32, qpos (rows, 14) float32)``: every row the first pair at its
    model's initial pose: the dtypes and shapes of the generation's settled scenes."""
    m = wd.build_world(cfg.phys).mj_models[0]
    return np.zeros(rows, np.int32), np.tile(np.asarray(m.qpos0, np.float32), (rows, 1))


def unobstruct_warmups(cfg: ActionConfig, batch: int, actions: Sequence[str]) -> list[Callable[[], None]]:
    """The warm-ups of unobstruct's screened halves for a generation of ``actions`` (in that
    order) in batches of ``batch`` (module doc): none when unobstruct is not generated or is
    generated first, or the reach screen is off (its plan is then the planner's)."""
    if not cfg.arm.reach_screen or "unobstruct" not in actions[1:]:  # unscreened, absent or first: nothing ahead
        return []
    use_scene(cfg.scene, cfg.grip_margin)  # the run's objects, as the generation's factory selects them
    # the screened halves run in calls of min(batch, PLAN_CHUNK) rows (reach_screen.prepare_screened)
    pair, qpos = placeholder_scenes(cfg, min(int(batch), PLAN_CHUNK))
    plan_fn, reach_fn = jitted_parts(cfg)
    return [functools.partial(_call, plan_fn, action_id("unobstruct"), pair, qpos),
            functools.partial(_call, reach_fn, pair, qpos)]


def _call(fn: Callable, *args) -> None:
    jax.block_until_ready(fn(*args))
