"""The nine actions end to end: action functions for any batch, and dataset rollouts.

Takes an ``ActionConfig`` (and, for rollouts, an action name and batch size); gives
``make_action_fn`` / ``jitted_action_fn`` (plan, simulate and label settled scenes; two compiled
programs per batch shape, plan and simulate, shared by all nine actions: the action index is
traced) and ``make_rollout_fn(action, batch, config, engine=...)``, the sampler of
``dataset.generate_dataset``: sample pairs of the action's pairing (``allowed_pairs``), place
and settle them (``scenes.py`` on the arm-less world), plan, simulate the feasible programs,
label (``make_batch_prepare_fn`` then ``execute_batch``, also usable apart: the benchmark
executes one prepared batch with several engines; the ``RolloutFn`` it returns keeps the two
halves, which the dataset driver runs one chunk apart, ``data.tasks.PrepareAhead``). Two engines execute the programs (``ENGINES``): ``"mjx"`` (default; it also runs on an
accelerator) and ``"native"`` (MuJoCo C on a thread pool, ``native.batch.execute_native``);
sampling and planning are the same JAX code for both; the native engine also settles the
scenes in MuJoCo C (``native.settle``), so its scenes are C's (docs/scenes.md, "Native settle").

Pipeline of one batch: ``planning.make_plan_fn`` (tcp waypoints from the settled poses, batched
IK; infeasible programs keep the arm home), ``simulate.make_simulate_fn`` (MJX, ``lax.scan``
over time), ``labels.goals`` (outcome rules of Table I on the objects' centres of mass).
Motor programs: docs/actions.md.
"""
from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import scenes as sc
from . import world as wd
from .actions.registry import action_id, per_action_list, spec
from .actions.tables import tables
from .bodies import geometry
from .native.batch import default_threads, execute_native
from .native.settle import settle_batch, still_batch
from .planning import Plan
from .reach_screen import jitted_parts, jitted_screen_fn, prepare_screened
from .simulate import make_prepare_fn, make_simulate_fn
from .still import make_still_fn
from .templates import ActionConfig, is_v4, stored_config  # noqa: F401 (stored_config: for reproduce)

from relaff_jax.constants import SIM_ENGINES
from relaff_jax.errors import UserError
from .object_library import use_scene

ENGINES = SIM_ENGINES  # executors of the planned programs in make_rollout_fn


def make_action_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``action_fn(action_id (), pair (B,), qpos (B, 14), qvel (B, 12)) -> dict`` of per-scene
    results for any of the nine actions (pure; the caller jits; one compile per batch shape
    for all actions). ``qpos``/``qvel``: settled object states in the arm-less layout
    (``scenes.Scenes.qpos``/``qvel``). Composes ``make_prepare_fn`` and ``make_simulate_fn``.

    Returns ``label`` (B,) bool, ``feasible``, ``ik_error``, ``com0``/``com_m``/``com_end``
    (B, 2, 3) centres of mass of (toy, other), ``reach_before``/``reach_after`` (unobstruct),
    ``qpos_final`` (B, 14) and the plan (``q_way``, ``grip_way``, ``seg_steps``).
    """
    prepare_fn, simulate_fn = make_prepare_fn(cfg), make_simulate_fn(cfg)

    def action_fn(action_id, pair, qpos, qvel):
        plan, before = prepare_fn(action_id, pair, qpos)
        return simulate_fn(action_id, pair, qpos, qvel, plan, before)

    return action_fn


@per_action_list(maxsize=4)  # built for the run's action list
def jitted_stage_fns(cfg: ActionConfig = ActionConfig()) -> tuple[Callable, Callable]:
    """``make_prepare_fn(cfg)``'s results from compiled programs, and the jitted
    ``make_simulate_fn(cfg)``, cached: each program compiles once per batch shape and serves
    all nine actions (the action index is traced).

    The prepare function calls the programs the screened generation calls, on every scene
    (``reach_screen.jitted_screen_fn`` for the scenes' programs, then ``jitted_parts``: their
    plan, and unobstruct's toy reach only for the actions that read it) instead of compiling
    ``make_prepare_fn`` as one program: a run traces and compiles the actions' target rules
    once and the planner once (docs/arm.md, "The reach screen"). Its ``action_id`` must be
    concrete (a Python or numpy integer). ``tests/sim/test_reach_screen.py`` compares its
    results with ``make_prepare_fn`` compiled as one program, bit for bit."""
    screen_fn = jitted_screen_fn(cfg)
    plan_of, reach_fn = jitted_parts(cfg)
    reads = tables(cfg).reach

    def prepare_fn(action_id, pair, qpos):
        """``(Plan, reach_before (B,) bool)`` of ``make_prepare_fn``."""
        before = reach_fn(pair, qpos) if reads[int(action_id)] else jnp.zeros(np.shape(pair), bool)
        return plan_of(action_id, *screen_fn(action_id, pair, qpos)[3]), before

    return prepare_fn, jax.jit(make_simulate_fn(cfg))


def jitted_action_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``action_fn`` built from the two cached jitted stages (``jitted_stage_fns``), so that
    it shares its compiled programs with ``make_rollout_fn``: two programs per batch shape
    (plan, simulate), for all actions."""
    prepare_fn, simulate_fn = jitted_stage_fns(cfg)

    def action_fn(action_id, pair, qpos, qvel):
        plan, before = prepare_fn(action_id, pair, qpos)
        return simulate_fn(action_id, pair, qpos, qvel, plan, before)

    return action_fn


# ----------------------------------------------------------------- dataset rollouts


def allowed_pairs(world: wd.World, action: str) -> np.ndarray:
    """Pair indices whose pairing the action uses (toy+base, toy+obstacle or toy+rake)."""
    return np.nonzero(geometry(world).pairing == spec(action).pairing_id)[0]


def default_sim_batch(batch: int) -> int:
    """Scenes per simulation call in ``make_rollout_fn``: 16 (or ``batch`` if smaller).

    MJX on the CPU simulates about the same number of scenes per second at 16 and 32 (2.6
    scenes/s, docs/actions.md) and fewer at 8, so 16 keeps the padding of a chunk's last call
    small (about 40 % of a chunk is feasible: a chunk of 32 needs one call)."""
    return min(int(batch), 16)


def bench_batch_key(seed: int, batch_size: int, index: int) -> jax.Array:
    """PRNG key of prepared batch ``index`` in the engine benchmarks (``benchmarks/actions.py
    --engines``, ``disagreements.py``, ``chaos.py``): the same key gives the same scenes."""
    return jax.random.fold_in(jax.random.PRNGKey(seed + 1000 * batch_size), index)


def make_rollout_fn(action: str, batch: int, config: ActionConfig | None = None,
                    sim_batch: int | None = None, engine: str = "mjx",
                    nthread: int | None = None) -> Callable:
    """``rollout_fn(key, batch_size) -> dict`` of numpy arrays per sample, for
    ``dataset.generate_dataset``: samples pairs of the action's pairing, places and settles
    the scenes (``scenes.jitted_scene_fns`` on the arm-less world), plans the action, runs the
    feasible programs, labels.

    Only feasible programs are simulated, in calls of ``sim_batch`` scenes (default
    ``default_sim_batch(batch)`` = 16; the last call is padded with repeats of its scenes). An
    infeasible program is not executed (the arm stays home, ``make_plan_fn``) and its label is
    False by definition, so skipping its simulation changes no label; its ``qpos_final`` is
    the settled state and ``reach_after`` equals ``reach_before``. About 60 % of the sampled
    scenes are infeasible (out of the arm's 1.2 m reach in the 1.8 m workspace), so this
    simulates ~2.5x fewer scenes. ``tests/sim/test_actions.py`` checks the labels against running
    every scene.

    Fields: ``label``, ``relation`` (int codes into ``scenes.RELATIONS``), ``cog_distance``,
    ``toy``, ``other`` (names), ``pair`` (int32), ``qpos0`` / ``qpos_settled`` (float32 (14,),
    arm-less layout), ``qpos_final``, ``rollout_id`` (int64), ``intended``, ``at_rest``,
    ``feasible``, ``ik_error``, ``reach_before``/``reach_after``, ``simulated`` (bool: the
    program was executed, by either engine), ``settled`` (bool: both objects were at rest
    where the goal was read, ``labels.read_at_rest``; True where nothing was executed).
    ``batch`` is the batch size the caller will use (compiled on the first call).

    ``engine``: ``"mjx"`` runs the programs in MJX in calls of ``sim_batch`` scenes;
    ``"native"`` settles the scenes and runs all feasible programs of the batch in
    ``mujoco.batch`` on ``nthread`` C threads (default: every CPU of the process; ``sim_batch``
    unused). The same placements, planner and outcome rules (``docs/actions.md``, "Engines");
    the settled scenes are C's (``docs/scenes.md``, "Native settle").
    """
    action_id(action)  # an unknown action raises here, before any compile
    if int(batch) < 1:
        raise UserError(f"batch must be >= 1, got {batch}")
    sim_batch = default_sim_batch(batch) if sim_batch is None else int(sim_batch)
    if sim_batch < 1:
        raise UserError(f"sim_batch must be >= 1, got {sim_batch}")
    if engine not in ENGINES:
        raise UserError(f"unknown engine {engine!r}; valid: {', '.join(ENGINES)}")
    if nthread is not None and int(nthread) < 1:
        raise UserError(f"nthread must be >= 1, got {nthread}")
    cfg = config or ActionConfig()
    # the native engine settles in C too (native.settle); MJX's settle stays MJX's, bit for bit
    prepare = make_batch_prepare_fn(action, cfg, settle="native" if engine == "native" else "mjx", nthread=nthread)

    return RolloutFn(prepare, functools.partial(execute_batch, cfg=cfg, engine=engine, sim_batch=sim_batch,
                                                nthread=nthread))


class RolloutFn:
    """``rollout_fn(key, batch_size) = execute(prepare(key, batch_size))``, with its two halves
    apart: ``prepare`` (sample, place, settle, screen and plan: ``make_batch_prepare_fn``) and
    ``execute`` (run the feasible programs and label: ``execute_batch``). The dataset driver
    prepares the next chunk while this one executes (``data.tasks.PrepareAhead``); a chunk's
    result does not depend on when its halves ran."""

    def __init__(self, prepare: Callable, execute: Callable):
        self.prepare, self.execute = prepare, execute

    def __call__(self, key, batch_size: int) -> dict[str, np.ndarray]:
        return self.execute(self.prepare(key, batch_size))


class Prepared(NamedTuple):
    """One rollout batch before execution (host arrays): ``action``, ``pair`` (B,), the
    settled ``scenes`` (``scenes.Scenes``), the ``plan`` (``planning.Plan``), ``before`` (B,)
    unobstruct's reachability, ``ids`` (B,) int64 rollout ids, ``names`` (B, 2) object names."""

    action: str
    pair: np.ndarray
    scenes: Any
    plan: Plan
    before: np.ndarray
    ids: np.ndarray
    names: np.ndarray


def make_batch_prepare_fn(action: str, cfg: ActionConfig, settle: str = "mjx",
                          nthread: int | None = None) -> Callable:
    """``prepare(key, batch_size) -> Prepared``: the half of a rollout batch before execution
    (sample pairs of the action's pairing, place, settle, plan in JAX). Its results do not
    depend on the arm world's tuning (``PhysicsConfig.arm_*``), only on the settle world and
    the arm's kinematics.

    ``settle``: ``"mjx"`` (the jitted ``scenes.make_settle_fn``) or ``"native"`` (MuJoCo C,
    ``native.settle.settle_batch`` on ``nthread`` threads, default every CPU): the same
    placements, settled by another simulator (agreement: docs/scenes.md, "Native settle")."""
    if settle not in ENGINES:
        raise UserError(f"unknown settle {settle!r}; valid: {', '.join(ENGINES)}")
    aid = action_id(action)

    use_scene(cfg.scene, cfg.grip_margin)  # the objects cfg selects (a Dask worker's first call reads them here)
    scene_world = wd.build_world(cfg.phys)
    place_fn, settle_fn, _ = sc.jitted_scene_fns(scene_world, cfg.scene)
    prepare_fn, _ = jitted_stage_fns(cfg)
    allowed = allowed_pairs(scene_world, action)
    names = np.asarray([(t, o) for t, o, _ in scene_world.pairs])
    threads = default_threads() if nthread is None else int(nthread)
    # v4: no program on a scene that does not stay still after settling (sim/still.py)
    still_fn = jitted_still_fn(scene_world) if is_v4(cfg) and settle == "mjx" else None

    def prepare(key, batch_size: int) -> Prepared:
        kp, ks, kid = jax.random.split(key, 3)
        pair = sc.sample_pairs(kp, allowed, scene_world, int(batch_size))
        qpos0, intended = place_fn(ks, pair)
        if settle == "native":
            scenes = settle_batch(scene_world, *jax.device_get((pair, qpos0, intended)), cfg.scene, threads)
        else:
            scenes = settle_fn(pair, qpos0, intended)
        if cfg.arm.reach_screen:  # the IK only where the arm might reach (reach_screen.py)
            s = jax.device_get(scenes)
            plan, before = prepare_screened(cfg, aid, np.asarray(pair), s.qpos)
        else:
            plan, before = prepare_fn(aid, pair, jnp.asarray(scenes.qpos))
            s, plan, before = jax.device_get((scenes, plan, before))
        p = np.asarray(pair)
        if is_v4(cfg):
            feasible = np.asarray(plan.feasible, bool).copy()
            if still_fn is not None:  # MJX: every scene, one compiled shape
                feasible &= np.asarray(jax.device_get(still_fn(pair, jnp.asarray(s.qpos), jnp.asarray(s.qvel))))
            elif feasible.any():  # MuJoCo C: only where a program would run
                run = np.flatnonzero(feasible)
                feasible[run] = still_batch(scene_world, p[run], np.asarray(s.qpos)[run], np.asarray(s.qvel)[run],
                                            nthread=threads)
            plan = plan._replace(feasible=feasible)
        base = int(jax.random.bits(kid, (), jnp.uint32))
        ids = np.int64(base) * int(batch_size) + np.arange(int(batch_size), dtype=np.int64)
        return Prepared(action, p, s, plan, np.asarray(before, bool), ids, names[p])

    return prepare


@functools.lru_cache(maxsize=4)
def jitted_still_fn(world: wd.World):
    """The jitted MJX stillness check (``still.make_still_fn``) of one scene world."""
    return jax.jit(make_still_fn(world))


def execute_batch(prep: Prepared, cfg: ActionConfig, engine: str = "mjx", sim_batch: int = 16,
                  nthread: int | None = None) -> dict[str, np.ndarray]:
    """Execute the feasible programs of ``prep`` with ``engine`` and label every scene: the
    fields of ``make_rollout_fn``. An infeasible program is not executed: label False, the
    objects where they settled, ``reach_after`` = ``reach_before``."""
    if engine not in ENGINES:
        raise UserError(f"unknown engine {engine!r}; valid: {', '.join(ENGINES)}")
    aid = action_id(prep.action)
    s, plan, before, p = prep.scenes, prep.plan, prep.before, prep.pair
    qpos = np.asarray(s.qpos, np.float32)
    label = np.zeros(len(p), bool)
    qpos_final = qpos.copy()
    after = before.copy()
    settled = np.ones(len(p), bool)  # a program not executed leaves the settled scene as it was
    run = np.flatnonzero(plan.feasible)
    if engine == "native" and len(run):
        sub = Plan(plan.q_way[run], plan.grip_way[run], plan.seg_steps, plan.feasible[run],
                   plan.direction[run], plan.ik_error[run])
        out = execute_native(prep.action, cfg, p[run], qpos[run], np.asarray(s.qvel)[run], sub,
                             before[run], nthread=nthread)
        label[run], qpos_final[run], after[run] = out["label"], out["qpos_final"], out["reach_after"]
        settled[run] = out["settled"]
    if engine == "mjx":
        _, simulate_fn = jitted_stage_fns(cfg)
        for lo in range(0, len(run), sim_batch):
            rows = run[lo:lo + sim_batch]
            idx = np.resize(rows, sim_batch)  # pad with repeats: one compiled shape
            sub = Plan(plan.q_way[idx], plan.grip_way[idx], plan.seg_steps, plan.feasible[idx],
                       plan.direction[idx], plan.ik_error[idx])
            out = jax.device_get(simulate_fn(aid, p[idx], qpos[idx], np.asarray(s.qvel)[idx], sub, before[idx]))
            k = len(rows)
            label[rows] = out["label"][:k]
            qpos_final[rows] = out["qpos_final"][:k]
            after[rows] = out["reach_after"][:k]
            settled[rows] = out["settled"][:k]
    simulated = np.zeros(len(p), bool)
    simulated[run] = True
    return dict(
        label=label,
        relation=np.asarray(s.relation, np.int32),
        cog_distance=np.asarray(s.cog_distance, np.float32),
        toy=prep.names[:, 0], other=prep.names[:, 1], pair=p.astype(np.int32),
        qpos0=np.asarray(s.qpos0, np.float32), qpos_settled=qpos,
        qpos_final=np.asarray(qpos_final, np.float32), rollout_id=prep.ids,
        intended=np.asarray(s.intended, np.int32), at_rest=np.asarray(s.at_rest, bool),
        feasible=np.asarray(plan.feasible, bool), ik_error=np.asarray(plan.ik_error, np.float32),
        reach_before=before, reach_after=after, simulated=simulated, settled=settled,
    )
