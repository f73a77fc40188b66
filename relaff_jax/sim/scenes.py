"""Scene sampling and settling: object pairs placed by the paper's distribution, then
simulated in MJX until they are at rest, then labelled with their spatial relation.

Takes a ``World`` (``world.py``) and a PRNG key; gives ``Scenes``, a pytree of per-scene
arrays with a leading (B,) axis. The pieces are pure functions of (world, config, key,
arrays); ``place`` samples placements and ``make_settle_fn`` closes the settling over the static
world and config; the caller jits them once per batch shape (``run_scenes`` does, chunk by
chunk, through ``jitted_scene_fns``).

Placement (paper IV-C, IV-D): the other object lies in the half-disc x > 0 of radius
``workspace_radius`` around the robot at the origin, no closer than ``min_radius``. For
toy+base pairs a fraction ``p_stacked`` of scenes drops the toy onto / into the base
(anywhere over the top surface or inside the walls, so some fall off or land on a rim);
the rest put the toy beside it on the table, either near (a gap of ``near_gap``) or
anywhere in the workspace. For toy+obstacle pairs the obstacle stands between the robot
and the toy with probability ``p_between``. Rakes are held by the gripper: the rake sits
at ``PhysicsConfig.held_rake_pos`` and the toy alone is on the table.

The relation is computed from the settled state, not from the sampler's intent:
``on_top`` or ``inside`` when the toy touches the other object and not the table
(``inside`` when its centre is within the container's inner walls, below the rim), else
``beside``.
"""
from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any

import chex
import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from . import objects as lib
from . import world as wd
from .contacts import contacts

from relaff_jax.constants import BESIDE, INSIDE, ON_TOP, RELATIONS  # noqa: F401 (re-exported)
from relaff_jax.errors import UserError
from relaff_jax.config.action import SceneConfig


@chex.dataclass
class Scenes:
    """A batch of scenes. Leading axis (B,) on every field.

    pair: (B,) int pair index into ``world.pairs``.
    qpos0: (B, nq) initial placement.
    qpos: (B, nq) settled state.
    qvel: (B, nv) velocities at the end of settling.
    relation: (B,) int, index into RELATIONS.
    intended: (B,) int, the relation the sampler aimed for (for diagnostics only).
    cog_distance: (B,) distance between the two objects' centres of mass (m), settled.
    at_rest: (B,) bool, both objects slower than ``rest_speed``.
    """

    pair: jax.Array
    qpos0: jax.Array
    qpos: jax.Array
    qvel: jax.Array
    relation: jax.Array
    intended: jax.Array
    cog_distance: jax.Array
    at_rest: jax.Array


@dataclasses.dataclass(frozen=True, eq=False)
class PairTable:
    """Per-pair geometry needed by the sampler, as (P,) / (P, k) numpy arrays."""

    pairing: np.ndarray  # 0 toy+base, 1 toy+obstacle, 2 toy+rake
    toy_radius: np.ndarray  # footprint radius of the toy
    toy_half: np.ndarray  # (P, 2) half extents of the toy footprint
    other_radius: np.ndarray
    top_half: np.ndarray  # (P, 2) half extents of the other's top surface
    top_z: np.ndarray  # height of the support surface of a flat base / floor of a container
    container: np.ndarray  # bool
    inner: np.ndarray  # (P, 3) container inner half extents x, y and rim height


@functools.lru_cache(maxsize=8)
def pair_table(world: wd.World) -> PairTable:
    rows = []
    for toy, other, pairing in world.pairs:
        t, o = world.objects.get(toy), world.objects.get(other)
        base = dict(o.parts)["base"]
        inner = o.inner if o.inner is not None else (0.0, 0.0, 0.0)
        rows.append((
            lib.PAIRINGS.index(pairing), t.footprint_radius, (t.extent[0] / 2, t.extent[1] / 2),
            o.footprint_radius, o.top_extent, base.centre[2] + base.size[2] / 2,
            o.inner is not None, inner,
        ))
    cols = list(zip(*rows))
    return PairTable(*(np.asarray(c, np.int32 if i == 0 else np.float32) if i != 6
                       else np.asarray(c, bool) for i, c in enumerate(cols)))


def _yaw_quat(yaw: jax.Array) -> jax.Array:
    return jnp.stack([jnp.cos(yaw / 2), 0.0 * yaw, 0.0 * yaw, jnp.sin(yaw / 2)])


def _rot2(yaw: jax.Array, v: jax.Array) -> jax.Array:
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _in_workspace(xy: jax.Array, radius: jax.Array, cfg: SceneConfig) -> jax.Array:
    r = jnp.linalg.norm(xy)
    return (r >= cfg.min_radius + radius) & (r <= cfg.workspace_radius - radius) & (xy[0] >= radius)


def _uniform_workspace(key: jax.Array, radius: jax.Array, cfg: SceneConfig, k: int) -> jax.Array:
    """(k, 2) area-uniform points of the half-disc annulus shrunk by ``radius``."""
    k1, k2 = jax.random.split(key)
    rmin, rmax = cfg.min_radius + radius, cfg.workspace_radius - radius
    r = jnp.sqrt(jax.random.uniform(k1, (k,)) * (rmax**2 - rmin**2) + rmin**2)
    th = jax.random.uniform(k2, (k,), minval=-jnp.pi / 2, maxval=jnp.pi / 2)
    return jnp.stack([r * jnp.cos(th), r * jnp.sin(th)], -1)


def _first_valid(cands: jax.Array, valid: jax.Array, fallback: jax.Array) -> tuple[jax.Array, jax.Array]:
    """First candidate row with ``valid``; ``fallback`` if none is."""
    i = jnp.argmax(valid)
    ok = valid[i]
    return jnp.where(ok, cands[i], fallback), ok


def sample_placement(key: jax.Array, pair: jax.Array, table: PairTable, cfg: SceneConfig,
                     phys: wd.PhysicsConfig) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Place one scene's two objects.

    Args:
      key: PRNG key.
      pair: () int pair index.
    Returns:
      toy7: (7,) toy free-joint qpos, obj7: (7,) other free-joint qpos,
      intended: () int relation the sampler aimed for.
    """
    tb = jax.tree_util.tree_map(lambda a: jnp.asarray(a)[pair], dataclasses.asdict(table))
    ks = jax.random.split(key, 12)
    k = cfg.candidates
    pairing = tb["pairing"]
    r_t, r_o = tb["toy_radius"], tb["other_radius"]
    sep = r_t + r_o + 0.01

    # The other object: anywhere in the workspace.
    obj_xy = _uniform_workspace(ks[0], r_o, cfg, 1)[0]
    obj_yaw = jax.random.uniform(ks[1], minval=-jnp.pi, maxval=jnp.pi)
    toy_yaw = jax.random.uniform(ks[2], minval=-jnp.pi, maxval=jnp.pi)

    # Toy+base, stacked: over the top surface, or inside the walls of a container.
    fit = tb["inner"][:2] - tb["toy_half"].max()
    fits = tb["container"] & jnp.all(fit > 0.0)
    reach = jnp.where(fits, fit, jnp.where(tb["container"], tb["inner"][:2], tb["top_half"]))
    u = jax.random.uniform(ks[3], (2,), minval=-1.0, maxval=1.0)
    stack_xy = obj_xy + _rot2(obj_yaw, u * reach)
    # Inside a container it starts on the floor plate; one that does not fit lands on the rim.
    stack_z = jnp.where(tb["container"] & ~fits, tb["inner"][2], tb["top_z"]) + cfg.drop_height

    # Beside: near the other object, else anywhere; never overlapping it.
    ang = jax.random.uniform(ks[4], (k,), minval=-jnp.pi, maxval=jnp.pi)
    gap = jax.random.uniform(ks[5], (k,), minval=cfg.near_gap[0], maxval=cfg.near_gap[1])
    near = obj_xy + (r_o + r_t + gap)[:, None] * jnp.stack([jnp.cos(ang), jnp.sin(ang)], -1)
    anywhere = _uniform_workspace(ks[6], r_t, cfg, k)
    use_near = jax.random.uniform(ks[7]) < cfg.p_near
    cands = jnp.concatenate([near, anywhere])
    in_ws = jax.vmap(lambda p: _in_workspace(p, r_t, cfg))(cands)
    apart = jnp.linalg.norm(cands - obj_xy, axis=-1) >= sep
    valid = in_ws & apart & jnp.concatenate([jnp.full(k, use_near), jnp.ones(k, bool)])
    beside_xy, _ = _first_valid(cands, valid, obj_xy + jnp.array([0.0, sep]))

    # Toy+obstacle: the toy anywhere; the obstacle often between the robot and the toy.
    toy_free = _uniform_workspace(ks[8], r_t, cfg, 1)[0]
    towards = toy_free / jnp.maximum(jnp.linalg.norm(toy_free), 1e-6)
    bgap = jax.random.uniform(ks[9], minval=cfg.between_gap[0], maxval=cfg.between_gap[1])
    between_xy = toy_free - towards * (r_t + r_o + bgap)
    between_ok = _in_workspace(between_xy, r_o, cfg) & (jax.random.uniform(ks[11]) < cfg.p_between)
    far_cands = _uniform_workspace(jax.random.fold_in(ks[11], 1), r_o, cfg, k)
    far_ok = jnp.linalg.norm(far_cands - toy_free, axis=-1) >= sep
    far_xy, _ = _first_valid(far_cands, far_ok, obj_xy)
    obst_xy = jnp.where(between_ok, between_xy, far_xy)
    # An obstacle in the way faces the robot (its wide side across the line of sight).
    obst_yaw = jnp.where(between_ok, jnp.arctan2(towards[1], towards[0]) + 0.3 * jnp.tanh(obj_yaw),
                         obj_yaw)

    stacked = (pairing == 0) & (jax.random.uniform(ks[10], ()) < cfg.p_stacked)
    is_base, is_obst, is_rake = pairing == 0, pairing == 1, pairing == 2

    toy_xy = jnp.where(is_base, jnp.where(stacked, stack_xy, beside_xy), toy_free)
    toy_z = jnp.where(stacked, stack_z, 0.0) + 0.001
    o_xy = jnp.where(is_obst, obst_xy, obj_xy)
    o_yaw = jnp.where(is_obst, obst_yaw, obj_yaw)
    held = jnp.asarray(phys.held_rake_pos)
    obj_pos = jnp.where(is_rake, held, jnp.concatenate([o_xy, jnp.array([0.001])]))
    o_yaw = jnp.where(is_rake, 0.0, o_yaw)

    toy7 = jnp.concatenate([toy_xy, toy_z[None], _yaw_quat(toy_yaw)])
    obj7 = jnp.concatenate([obj_pos, _yaw_quat(o_yaw)])
    intended = jnp.where(stacked, jnp.where(tb["container"] & fits, INSIDE, ON_TOP), BESIDE)
    return toy7, obj7, intended


def sample_pairs(key: jax.Array, allowed: np.ndarray, world: wd.World, n: int) -> jax.Array:
    """(n,) pair indices: a pairing uniformly among those present in ``allowed``, then a
    pair uniformly within it (so every group pairing is equally represented)."""
    table = pair_table(world)
    allowed = np.asarray(allowed)
    pg = table.pairing[allowed]
    counts = np.bincount(pg, minlength=3)
    w = 1.0 / (counts[pg] * (counts > 0).sum())
    return jnp.asarray(allowed)[jax.random.choice(key, len(allowed), (n,), p=jnp.asarray(w))]


@functools.lru_cache(maxsize=8)
def contact_masks(world: wd.World) -> tuple[np.ndarray, np.ndarray]:
    """Which MJX contact slots are toy-other and toy-table contacts.

    MJX has a fixed, static list of candidate geom pairs (one slot per potential contact)
    whose geom ids the collision pass fills in; read it once per world from one forward pass,
    run now even inside a trace (``ensure_compile_time_eval``), so the MJX settle can ask for
    it when it is traced and a run that settles in MuJoCo C never pays for it (a trace and a
    compile of ``mjx.forward``, ~5 s).
    Returns two (ncon,) bool arrays.
    """
    with jax.ensure_compile_time_eval():
        m = mjx.put_model(world.mj_model)
        con = jax.device_get(contacts(jax.jit(mjx.forward)(m, mjx.make_data(world.mj_model))))
    g = np.asarray(world.mj_model.geom_bodyid)
    b1, b2 = g[np.asarray(con.geom1)], g[np.asarray(con.geom2)]
    toy, obj = world.toy_body, world.obj_body
    toy_obj = ((b1 == toy) & (b2 == obj)) | ((b1 == obj) & (b2 == toy))
    toy_tab = ((b1 == toy) & (b2 == 0)) | ((b1 == 0) & (b2 == toy))
    return toy_obj, toy_tab


def relation_of(world: wd.World, table: PairTable, cfg: SceneConfig, pair: jax.Array,
                d: Any, masks: tuple[np.ndarray, np.ndarray]) -> jax.Array:
    """Spatial relation of one settled scene from its contacts and geometry.

    Args:
      pair: () pair index; d: one scene's mjx.Data (no batch axis);
      masks: ``contact_masks(world)``.
    Returns:
      () int in {BESIDE, ON_TOP, INSIDE}.
    """
    touching = contacts(d).dist < cfg.contact_dist
    on_obj = jnp.any(touching & masks[0])
    on_table = jnp.any(touching & masks[1])
    supported = on_obj & ~on_table
    toy, obj = world.toy_body, world.obj_body

    # Toy centre of mass in the other object's frame.
    p = d.xipos[toy] - d.xpos[obj]
    local = d.xmat[obj].T @ p
    inner = jnp.asarray(table.inner)[pair]
    within = (jnp.abs(local[0]) < inner[0]) & (jnp.abs(local[1]) < inner[1]) & (local[2] < inner[2])
    inside = supported & jnp.asarray(table.container)[pair] & within
    return jnp.where(inside, INSIDE, jnp.where(supported, ON_TOP, BESIDE))


def step_held(world: wd.World, table, step, models, pair: jax.Array, data, steps: int):
    """``steps`` MJX steps (``lax.scan`` over time of the vmapped ``step``) of the batch ``data``
    of ``pair`` (B,), a held rake pinned at its pose after each step: it stays in the gripper (no
    gravity, no drift). The settle's and ``still.make_still_fn``'s time loop."""
    oq, od = world.obj_qpos, world.obj_dof
    held = jnp.asarray(table.pairing)[pair] == 2
    obj7 = data.qpos[:, oq:oq + 7]

    def body(d, _):
        d = step(models, d)
        q = jnp.where(held[:, None], d.qpos.at[:, oq:oq + 7].set(obj7), d.qpos)
        v = jnp.where(held[:, None], d.qvel.at[:, od:od + 6].set(0.0), d.qvel)
        return d.replace(qpos=q, qvel=v), None

    return jax.lax.scan(body, data, None, length=steps)[0]


def make_settle_fn(world: wd.World, cfg: SceneConfig = SceneConfig()):
    """Build ``settle_fn(pair, qpos0, intended) -> Scenes`` (pure; the caller jits it).

    Args (of the returned function):
      pair: (B,) int pair indices.
      qpos0: (B, nq) placements (e.g. from ``sample_placement`` or built by hand).
      intended: (B,) int relation the placement aimed for (kept for diagnostics).
    Simulates ``cfg.settle_steps`` MJX steps (``lax.scan`` over time of the vmapped step),
    holding a rake at its start pose, then labels the settled relation.
    """
    table = pair_table(world)
    d0 = mjx.make_data(world.mj_model)
    od = world.obj_dof
    td = world.toy_dof

    def settle_fn(pair: jax.Array, qpos0: jax.Array, intended: jax.Array) -> Scenes:
        # here, when traced, not above: only a run that settles in MJX needs the contact masks
        # and the MJX model stack (``World.model``)
        masks = contact_masks(world)
        step = wd.batched_step(world)
        models = wd.scene_models(world, pair)
        data = jax.vmap(lambda q: d0.replace(qpos=q))(qpos0)
        data = step_held(world, table, step, models, pair, data, cfg.settle_steps)
        data = jax.vmap(mjx.forward, in_axes=(world.model_axes, 0))(models, data)
        rel = jax.vmap(lambda p, d: relation_of(world, table, cfg, p, d, masks))(pair, data)
        cog = jnp.linalg.norm(data.xipos[:, world.toy_body] - data.xipos[:, world.obj_body], axis=-1)
        speed = jnp.maximum(jnp.linalg.norm(data.qvel[:, td:td + 3], axis=-1),
                            jnp.linalg.norm(data.qvel[:, od:od + 3], axis=-1))
        return Scenes(pair=pair, qpos0=qpos0, qpos=data.qpos, qvel=data.qvel, relation=rel,
                      intended=intended, cog_distance=cog, at_rest=speed < cfg.rest_speed)

    return settle_fn


def place(world: wd.World, cfg: SceneConfig, key: jax.Array, pair: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Sample placements for a batch of pairs.

    Args:
      key: PRNG key; pair: (B,) pair indices.
    Returns:
      qpos0: (B, nq) placements; intended: (B,) relation the sampler aimed for.
    """
    table = pair_table(world)
    keys = jax.random.split(key, pair.shape[0])
    toy7, obj7, intended = jax.vmap(
        lambda k, p: sample_placement(k, p, table, cfg, world.phys))(keys, pair)
    qpos0 = jnp.tile(jnp.asarray(world.mj_model.qpos0, jnp.float32), (pair.shape[0], 1))
    tq, oq = world.toy_qpos, world.obj_qpos
    return qpos0.at[:, tq:tq + 7].set(toy7).at[:, oq:oq + 7].set(obj7), intended


def run_scenes(n: int, seed: int = 0, batch: int = 1024, allowed: np.ndarray | None = None,
               world: wd.World | None = None, cfg: SceneConfig = SceneConfig(),
               progress: bool = True) -> tuple[Scenes, dict]:
    """Sample and settle ``n`` scenes in chunks of ``batch`` (memory stays bounded).

    Chunk ``c`` uses ``fold_in(PRNGKey(seed), c)``, so the scenes depend on the seed and the
    batch size only, bit for bit. The last chunk is padded to ``batch`` so one compiled
    program serves every chunk.
    Returns (scenes as numpy arrays with leading (n,) axis, stats dict).
    """
    if n < 1:
        raise UserError(f"n must be >= 1, got {n}")
    if batch < 1:
        raise UserError(f"batch must be >= 1, got {batch}")
    world = world or wd.build_world()
    allowed = np.arange(world.n_pairs) if allowed is None else np.asarray(allowed)
    place_fn, settle_fn, traces = jitted_scene_fns(world, cfg)
    traces_before = traces[0]
    root = jax.random.PRNGKey(seed)
    chunks = []
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    bar = tqdm(total=n, unit="scene", desc="settle", disable=not progress)
    for c in range(-(-n // batch)):
        kp, ks = jax.random.split(jax.random.fold_in(root, c))
        pair = sample_pairs(kp, allowed, world, batch)
        qpos0, intended = place_fn(ks, pair)
        out = jax.device_get(settle_fn(pair, qpos0, intended))
        chunks.append(out)
        bar.update(min(batch, n - c * batch))
    bar.close()
    seconds = time.perf_counter() - t0
    scenes = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs)[:n], *chunks)
    return scenes, {"compilations": traces[0] - traces_before, "seconds": seconds}


@functools.lru_cache(maxsize=8)
def jitted_scene_fns(world: wd.World, cfg: SceneConfig = SceneConfig()):
    """Jitted ``place`` and ``make_settle_fn`` for one world and config, reused across calls,
    and a one-element list counting their traces, i.e. their compilations."""
    traces = [0]

    def counted(fn):
        def wrapper(*args):
            traces[0] += 1  # runs only while tracing
            return fn(*args)
        return jax.jit(wrapper)

    settle = make_settle_fn(world, cfg)
    return (counted(lambda key, pair: place(world, cfg, key, pair)),
            counted(settle), traces)


def summary(world: wd.World, scenes: Scenes, stats: dict) -> dict:
    """The ``relaff scenes`` summary: counts per relation and per pairing."""
    n = int(scenes.pair.shape[0])
    pairing = np.asarray([world.pairs[p][2] for p in np.asarray(scenes.pair)])
    rel = np.asarray(RELATIONS)[np.asarray(scenes.relation)]
    by_pairing = {}
    for pg in lib.PAIRINGS:
        m = pairing == pg
        by_pairing[pg] = {"n": int(m.sum()), **{r: int((rel[m] == r).sum()) for r in RELATIONS}}
    return {
        "n": n,
        "relations": {r: int((rel == r).sum()) for r in RELATIONS},
        "pairings": by_pairing,
        "at_rest": int(np.asarray(scenes.at_rest).sum()),
        "intended_agrees": float(np.mean(np.asarray(scenes.intended) == np.asarray(scenes.relation))),
        "compilations": stats["compilations"],
        "seconds": round(stats["seconds"], 3),
        "scenes_per_second": round(n / max(stats["seconds"], 1e-9), 2),
    }
