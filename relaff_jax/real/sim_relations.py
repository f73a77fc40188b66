"""Simulated relation data seen by a simulated sensor that matches the real one.

Takes a ``SimSensor`` (camera height, tilt and vertical field of view, from the real scenes:
``sensor_from_scenes``) and a ``SimRelationConfig``; gives, per settled simulated toy+base
scene, ``pca (N, 18)`` (toy first: the upper object of an ``on_top`` pair, as in the real
labels), ``rhf (N, 300)`` (normals from the ray hits, or with ``normals="cloud"`` from the
noisy points by the image-window rule real clouds can use), ``relation (N,)`` index into
``constants.RELATIONS`` (beside, on_top, inside), ``pair (N,)``, ``scene_id (N,)``.

Scenes: ``sim.scenes.run_scenes`` on the toy+base pairs (the only pairing that stacks) with
the workspace radius of the config, settled by MJX; the camera is ``frame.sim_camera(height,
tilt, TARGET)`` with the sensor's field of view and the project's depth noise (``robwork``);
features by the project's jitted batched perception chain, compiled once per chunk shape.
Kept: scenes at rest with both objects seen (>= ``min_points`` voxels) and no capacity
overflow; dropped scenes are counted, never silently. ``build_sim_relations(folder, ...)``
works chunk by chunk, each chunk an atomic ``chunk_XXXXX.npz`` in ``folder``, so a killed run
resumes; it stops once every relation of ``need`` has enough scenes. ``load_sim_relations``
concatenates the chunks.

The guard ``sim_relations.json`` (sensor + config) is written *before* the first chunk, so a
killed build cannot take chunks of another sensor: ``guard`` refuses a folder whose config
differs in a ``GUARD_KEYS`` setting or whose sensor lies outside ``SensorTolerance`` of the one
asked for (naming what differs), and reuses it, with its own sensor, otherwise.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax import io as rio
from relaff_jax.constants import RELATIONS
from relaff_jax.errors import UserError
from relaff_jax.provenance import derive_seed

from relaff_jax.data.progress import progress_bar

from . import folder as layout
from . import frame as rframe
from relaff_jax.config.real import SensorTolerance, SimRelationConfig, SimSensor, sensor_mismatch
from .scene_source import TARGET
from relaff_jax.config import streams
from relaff_jax.config.perception import CameraConfig, NoiseConfig, NormalsConfig, PerceptionConfig
from relaff_jax.perception import make_batched_features
from relaff_jax.perception.from_sim import jitted_geoms, rollout_keys
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd

# Settings that change what a chunk holds: a folder's chunks must share them (the others, e.g.
# per_relation or feature_batch, only say how many chunks or how they are computed).
GUARD_KEYS = ("seed", "chunk", "workspace_radius", "normals", "noise", "max_tiles", "max_object_pixels")
GUARD = layout.GUARD


def perception_config(sensor: SimSensor, cfg: SimRelationConfig, perception=None):
    """The tree's ``perception`` settings (default: the default tree's; voxel grid, RHF,
    ``min_points``) seen by the simulated sensor: its camera pose and fov, and the simulated
    relation data's noise model, normals source and capacities (``real.sim.*``)."""
    p = PerceptionConfig() if perception is None else perception
    cam = rframe.sim_camera(sensor.height, sensor.tilt_deg, TARGET, CameraConfig(vfov_deg=sensor.vfov_deg))
    return dataclasses.replace(p, camera=cam, noise=NoiseConfig(cfg.noise),
                               normals=dataclasses.replace(p.normals, source=cfg.normals),
                               voxel=dataclasses.replace(p.voxel, max_object_pixels=cfg.max_object_pixels),
                               cull=dataclasses.replace(p.cull, max_tiles=cfg.max_tiles))


def features_record(perception) -> dict:
    """What of the tree's perception decides a chunk's features (voxel grid, RHF): the guard holds it."""
    p = PerceptionConfig() if perception is None else perception
    return rio.jsonable(dict(voxel_size=p.voxel.size, max_voxels=p.voxel.max_voxels, rhf=dataclasses.asdict(p.rhf)))


def _chunk_fn(world, sensor: SimSensor, cfg: SimRelationConfig, perception=None):
    """``run(c) -> dict of arrays`` for chunk ``c``: settle, perceive, filter."""
    pcfg = perception_config(sensor, cfg, perception)
    feats = make_batched_features(world.mj_model.geom_type, world.geom_seg, pcfg)
    geoms = jitted_geoms(world)
    scfg = sc.SceneConfig(workspace_radius=cfg.workspace_radius)
    allowed = np.asarray([i for i, p in enumerate(world.pairs) if p[2] == "toy+base"])
    root = jax.random.PRNGKey(derive_seed(cfg.seed, streams.SIM_RELATIONS, 1))

    def run(c: int) -> dict:
        scenes, _ = sc.run_scenes(cfg.chunk, seed=derive_seed(cfg.seed, streams.SIM_RELATIONS, 0, c), batch=cfg.chunk,
                                  allowed=allowed, world=world, cfg=scfg, progress=False)
        ids = c * cfg.chunk + np.arange(cfg.chunk, dtype=np.int64)
        size, xpos, xmat = geoms(jnp.asarray(scenes.pair, jnp.int32), jnp.asarray(scenes.qpos, jnp.float32))
        keys = rollout_keys(root, ids)
        fb = cfg.feature_batch
        parts = [jax.device_get(feats(size[i:i + fb], xpos[i:i + fb], xmat[i:i + fb], keys[i:i + fb]))
                 for i in range(0, cfg.chunk, fb)]
        out = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in ("pca", "rhf", "unseen", "overflow")}
        ok_rest = np.asarray(scenes.at_rest)
        seen = ~np.asarray(out["unseen"]).any(-1)
        ok_cap = ~np.asarray(out["overflow"])
        keep = ok_rest & seen & ok_cap
        return dict(pca=np.asarray(out["pca"])[keep], rhf=np.asarray(out["rhf"])[keep],
                    relation=np.asarray(scenes.relation)[keep], pair=np.asarray(scenes.pair)[keep],
                    scene_id=ids[keep], dropped=np.array([(~ok_rest).sum(), (~seen).sum(), (~ok_cap).sum()]))

    return run


def _counts(folder: Path) -> tuple[list[Path], np.ndarray]:
    files = sorted(folder.glob(layout.CHUNK_GLOB))
    counts = np.zeros(len(RELATIONS), np.int64)
    for f in files:
        with np.load(f) as z:
            counts += np.bincount(z["relation"], minlength=len(RELATIONS))
    return files, counts


def guard(folder: str | Path, sensor: SimSensor, cfg: SimRelationConfig = SimRelationConfig(),
          tol: SensorTolerance = SensorTolerance(), write: bool = True, perception=None) -> SimSensor:
    """The sensor whose data ``folder`` holds (or will hold): the stored one when the folder's
    guard matches ``cfg`` and lies within ``tol`` of ``sensor``, else ``UserError`` with the
    reason. A new folder gets its guard now (``write``), before any chunk."""
    folder = Path(folder)
    meta_path = folder / GUARD
    if meta_path.exists():
        try:
            old = rio.read_json(meta_path)
            stored = SimSensor(**old["sensor"])
            conf = old["config"]
        except (ValueError, KeyError, TypeError) as e:
            raise UserError(f"{meta_path} is not a simulated relation guard ({e}); delete the folder") from None
        ask, dflt = dataclasses.asdict(cfg), dataclasses.asdict(SimRelationConfig())
        differs = [f"{k} {conf.get(k, dflt[k])!r} there, {ask[k]!r} asked" for k in GUARD_KEYS
                   if rio.jsonable(conf.get(k, dflt[k])) != rio.jsonable(ask[k])]  # older folders: defaults
        feats = features_record(perception)
        there = old.get("perception", features_record(None))  # older folders: the default perception
        if there != feats:
            differs.append(f"perception (voxel grid, RHF) {there} there, {feats} asked")
        if differs:
            raise UserError(f"{folder} holds simulated relation data of another config ({'; '.join(differs)}); "
                            "use another folder or delete it")
        why = sensor_mismatch(stored, sensor, tol)
        if why:
            raise UserError(f"{folder} holds simulated relation data of another sensor ({why}); use another "
                            "folder, delete it, or widen --set real.tolerance.<key>")
        return stored
    chunks = sorted(folder.glob(layout.CHUNK_GLOB))
    if chunks:
        raise UserError(f"{folder} holds {len(chunks)} simulated chunks but no {GUARD}, so which sensor made them "
                        "is unknown (a build killed before the guard was written first); delete them")
    if write:
        folder.mkdir(parents=True, exist_ok=True)
        rio.atomic_write_json(meta_path, dict(sensor=dataclasses.asdict(sensor), config=dataclasses.asdict(cfg),
                                              perception=features_record(perception), status="building"))
    return sensor


def build_sim_relations(folder: str | Path, sensor: SimSensor, cfg: SimRelationConfig = SimRelationConfig(),
                        progress: bool = True, tol: SensorTolerance = SensorTolerance(), perception=None) -> dict:
    """Fill ``folder`` with chunks until each relation of ``cfg.need`` has ``cfg.per_relation``
    kept scenes (resumable; ``guard`` first: the same config, a sensor within ``tol``; chunks
    are made with the folder's own sensor). Returns a summary dict, ``sensor`` the one simulated."""
    folder = Path(folder)
    sensor = guard(folder, sensor, cfg, tol, perception=perception)
    meta_path = folder / GUARD
    meta = dict(sensor=dataclasses.asdict(sensor), config=dataclasses.asdict(cfg),
                perception=features_record(perception))
    need = np.asarray([RELATIONS.index(r) for r in cfg.need])
    files, counts = _counts(folder)
    # the bar counts kept scenes of the relations still needed (a chunk's worth at a time)
    held = lambda: int(np.minimum(counts[need], cfg.per_relation).sum())  # noqa: E731
    bar = progress_bar(progress, cfg.per_relation * len(need), "sim relations", unit="scene")
    bar.update(held())
    run, seconds, done_now = None, 0.0, 0
    while (counts[need] < cfg.per_relation).any():
        c = len(files)
        if c >= cfg.max_chunks:
            bar.close()
            raise UserError(f"{c} chunks ({c * cfg.chunk} scenes) gave only {dict(zip(RELATIONS, counts.tolist()))}; "
                            "raise max_chunks or lower per_relation")
        if run is None:
            bar.set_description("sim relations: compiling, first chunk")
            run = _chunk_fn(wd.build_world(), sensor, cfg, perception)
        t0 = time.perf_counter()
        out = run(c)
        seconds += time.perf_counter() - t0
        done_now += 1
        rio.atomic_save_npz(folder / layout.chunk(c), **out)
        files, counts = _counts(folder)
        bar.set_description("sim relations")
        bar.update(held() - bar.n)
        bar.set_postfix(chunk=c, s_per_chunk=f"{seconds / done_now:.1f}", **dict(zip(RELATIONS, counts.tolist())))
    bar.close()
    prev = rio.read_json(meta_path) if meta_path.exists() else {}
    timed_s = prev.get("seconds_timed", 0.0) + seconds  # over every run that built chunks
    timed_c = prev.get("chunks_timed", 0) + done_now
    summary = dict(meta, status="complete", counts=dict(zip(RELATIONS, counts.tolist())), chunks=len(files),
                   scenes=len(files) * cfg.chunk, dropped=_dropped(files),
                   seconds_timed=round(timed_s, 2), chunks_timed=timed_c,
                   seconds_per_scene=round(timed_s / max(timed_c * cfg.chunk, 1), 4))
    rio.atomic_write_json(meta_path, summary)
    return summary


def normals_note(cfg: SimRelationConfig, real_cfg) -> str:
    """Which RHF normals each side of a study used (one line for ``results.md``)."""
    w = NormalsConfig()
    sim = ("the renderer's ray-hit normals" if cfg.normals == "ray" else
           f"from the noisy cloud (PCA over a {w.window} x {w.window} pixel window within {w.radius} m)")
    n = real_cfg.normals
    real = (f"from the cloud ({n.knn} nearest points)" if n.method == "knn" else
            f"from the cloud (PCA over a {n.window} x {n.window} pixel window within {n.radius} m)")
    return f"simulation: {sim}; real: {real}"


def _dropped(files) -> dict:
    d = np.zeros(3, np.int64)
    for f in files:
        with np.load(f) as z:
            d += z["dropped"]
    return dict(not_at_rest=int(d[0]), unseen=int(d[1]), overflow=int(d[2]))


def load_sim_relations(folder: str | Path) -> dict:
    """All kept scenes of ``folder``: pca (N, 18), rhf (N, 300), relation, pair, scene_id (N,)."""
    files = sorted(Path(folder).glob(layout.CHUNK_GLOB))
    if not files:
        raise UserError(f"{folder} holds no simulated relation chunks; run `relaff real sim` first")
    parts = []
    for f in files:
        with np.load(f) as z:
            parts.append({k: z[k] for k in ("pca", "rhf", "relation", "pair", "scene_id")})
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def describe(folder: str | Path) -> dict:
    """The summary JSON ``build_sim_relations`` wrote."""
    path = Path(folder) / layout.GUARD
    if not path.exists():
        raise UserError(f"{path} missing: not a simulated relation folder")
    return json.loads(path.read_text())
