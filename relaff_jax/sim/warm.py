"""The planner's programs compiled ahead of the generation that needs them, on another thread.

Takes an ``ActionConfig``, the rollout batch and the actions a run generates; gives
``planner_warmups(cfg, batch, actions)``: functions of no argument, each tracing (or reading
from the traced store, ``traced_cache``) and compiling one of the planner's two programs
(``reach_screen.jitted_parts``: every action's plan of the programs the reach screen
draws, and unobstruct's toy reach when unobstruct is generated) at the shape the generation
calls it with, on placeholder programs and scenes, and returning nothing.

The generate stage runs them on its background thread (``stages/audits.py``) from its start.
The first action settles its first chunk in MuJoCo C and traces and compiles the reach screen
meanwhile, so the plan's trace and compile (~30 CPU s on a new install) overlap them: XLA's
compiles leave the GIL free; the traces take turns. A generation that reaches a program being
warmed waits for it (``traced_cache._Stored``'s lock) instead of tracing it again. A compiled
program depends on its arguments' shapes and dtypes, not their values, so the generation runs
the programs it would have compiled itself: the same bits.

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
from relaff_jax.sim.kinematics import IKTarget
from relaff_jax.sim.programs import Program
from relaff_jax.sim.reach_screen import PLAN_CHUNK, jitted_parts
from relaff_jax.sim.templates import N_TARGETS, ActionConfig


def placeholder_scenes(cfg: ActionConfig, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """``(pair (rows,) int32, qpos (rows, 14) float32)``: every row the first pair at its
    model's initial pose: the dtypes and shapes of the generation's settled scenes."""
    m = wd.build_world(cfg.phys).mj_models[0]
    return np.zeros(rows, np.int32), np.tile(np.asarray(m.qpos0, np.float32), (rows, 1))


def placeholder_programs(rows: int) -> list[np.ndarray]:
    """The leaves of ``rows`` scenes' ``programs.Program`` (``planning.PROGRAM_TREE``'s order),
    zeros: the shapes and dtypes the reach screen returns (``reach_screen.make_screen_fn``)."""
    f = lambda *shape: np.zeros((rows,) + shape, np.float32)
    target = IKTarget(f(N_TARGETS, 3), f(N_TARGETS, 3), f(N_TARGETS, 3), f(N_TARGETS), f(N_TARGETS))
    return jax.tree_util.tree_leaves(Program(target, f(), np.zeros(rows, bool), f(3), f()))


def planner_warmups(cfg: ActionConfig, batch: int, actions: Sequence[str]) -> list[Callable[[], None]]:
    """The warm-ups of the planner's programs for a generation of ``actions`` in batches of
    ``batch`` (module doc): the plan, then unobstruct's toy reach if unobstruct is among
    ``actions``; none when no action is generated."""
    if not actions:
        return []
    use_scene(cfg.scene, cfg.grip_margin)  # the run's objects, as the generation's factory selects them
    # screened, the halves run in calls of min(batch, PLAN_CHUNK) rows (reach_screen.prepare_screened);
    # unscreened, in calls of the whole batch (rollouts.jitted_stage_fns)
    rows = min(int(batch), PLAN_CHUNK) if cfg.arm.reach_screen else int(batch)
    pair, qpos = placeholder_scenes(cfg, rows)
    plan_of, reach_fn = jitted_parts(cfg)
    out = [functools.partial(_call, plan_of, action_id(actions[0]), *placeholder_programs(rows))]
    if "unobstruct" in actions:
        out.append(functools.partial(_call, reach_fn, pair, qpos))
    return out


def _call(fn: Callable, *args) -> None:
    jax.block_until_ready(fn(*args))
