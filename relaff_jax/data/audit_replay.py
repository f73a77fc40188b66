"""The audit's replay with its probe, in this process or in ``jobs`` worker processes.

Takes a dataset's sidecar, its ``ActionConfig``, the audited scenes (pair, settled qpos and qvel)
and their plans; gives ``replay_probed``: ``native.reference.replay_native``'s outputs and
``native.probe_arrays.ArrayProbe``'s readings for every scene, in scene order.

Each scene's replay is independent (one ``MjData``; the JAX parts, program inputs and labels,
are computed row by row on padded batches), so the scenes are split into contiguous chunks,
replayed by spawned workers (never forked: JAX deadlocks in a child forked after it started)
and the chunks' outputs concatenated in order: the same values as one process
(``tests/data/test_audit_jobs.py``). A worker rebuilds what the parent set up from the sidecar
(the recorded object set, the action's spec) and loads the parent's ``--plugins`` files.
"""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import Any, Mapping

import numpy as np

# A worker starts a Python with JAX, builds the planner's setup (``planning.setup``: the world's
# models, an IK solve) and compiles the replay's small jitted functions: ~30 s at load 12 on two
# cores (docs/journal/2026-12-05.md), the time of ~250 rollouts replayed here. Fewer scenes
# than this per worker are replayed in this process.
MIN_PER_JOB = 250


def default_jobs() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def n_workers(n: int, jobs: int) -> int:
    """Processes for ``n`` scenes with ``jobs`` allowed: 1 (this process) for few scenes."""
    return max(1, min(int(jobs), n // MIN_PER_JOB))


def replay_probed(meta: Mapping[str, Any], cfg: Any, action: str, pair: np.ndarray, qpos: np.ndarray,
                  qvel: np.ndarray, plan: Mapping[str, np.ndarray], measure: int, jobs: int = 1
                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(replay outputs, probe readings), each a dict of (B, ...) arrays in scene order.

    pair (B,), qpos (B, 14), qvel (B, 12): the settled scenes; plan: (B, ...) ``q_way``,
    ``grip_way``, ``feasible``, ``direction``; measure: the template's measuring step (v1
    programs; v2 read each scene at its ``read_step``); jobs: processes allowed."""
    k = n_workers(len(pair), jobs)
    if k == 1:
        return _replay(cfg, action, pair, qpos, qvel, plan, measure)
    from relaff_jax.plugins import loaded_files

    # the plugin files whose registrations still stand here (not every file this process ever ran)
    plugins = loaded_files()
    parts = np.array_split(np.arange(len(pair)), k)
    jobs_args = [(dict(meta), plugins, cfg, action, pair[i], qpos[i], qvel[i], {f: v[i] for f, v in plan.items()}, measure)
                 for i in parts]
    with ProcessPoolExecutor(k, mp_context=get_context("spawn")) as pool:
        outs = list(pool.map(_worker, jobs_args))
    rep = {f: np.concatenate([o[0][f] for o in outs]) for f in outs[0][0]}
    got = {f: np.concatenate([o[1][f] for o in outs]) for f in outs[0][1]}
    return rep, got


def _replay(cfg: Any, action: str, pair: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
            plan: Mapping[str, np.ndarray], measure: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    from relaff_jax.sim.native.reference import replay_native
    from relaff_jax.sim.planning import setup
    from relaff_jax.sim.native.probe_arrays import ArrayProbe

    world = setup(cfg).world
    probe = ArrayProbe(len(pair), world.toy_body, world.obj_body, cfg.phys.timestep)
    rep = replay_native(action, cfg, pair, qpos, qvel, dict(plan), observe=probe)
    # the step each goal was read at: the template's (v1) or the first at rest after it (v2)
    return rep, probe.result(rep.get("read_step", measure))


def _worker(args: tuple) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """One chunk in a spawned process: the parent's plugins, the sidecar's object set and action
    spec (as ``audit.action_config`` sets them up), then ``_replay``."""
    meta, plugins, cfg, action, pair, qpos, qvel, plan, measure = args
    from relaff_jax.plugins import load_files
    from relaff_jax.sim.actions.registry import check_recorded
    from relaff_jax.sim.object_library import use_recorded

    load_files(plugins)  # (path, sha256) pairs: a file changed since the parent read it is refused
    use_recorded(meta)
    check_recorded(action, meta["config"].get("action_spec"))
    return _replay(cfg, action, pair, qpos, qvel, plan, measure)
