"""From stored scenes to the paper's state spaces: the glue between datasets and perception.

Takes a dataset's per-sample ``pair`` (int) and ``qpos_settled`` ((nq,) settled object state
in the arm-less world layout) and gives ``pca`` (18,), ``rhf`` (300,), ``unseen`` (2,) and the
overflow flag per sample: the scene's geoms are placed by ``mjx.kinematics`` on the pair's
model (batched model fields, as in ``world.py``), then ``perception.features`` sees them.
The depth-noise key of a sample is ``fold_in(PRNGKey(seed), rollout_id)``, so features do
not depend on the batch size or on resuming.

``relaff features DIR`` attaches them to a dataset (resumable, progress bar);
``relaff show DIR --index I --out scene.png`` draws what the robot saw.
"""
from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from relaff_jax import config as rconfig
from . import core as pc
from relaff_jax.sim import world as wd


def scene_geoms(world: wd.World, pair: jax.Array, qpos: jax.Array):
    """Geom sizes and poses of a batch of settled scenes.

    Args:
      pair: (B,) pair indices; qpos: (B, nq) settled states (arm-less layout).
    Returns:
      size (B, G, 3), xpos (B, G, 3), xmat (B, G, 3, 3), robot frame.
    """
    models = wd.scene_models(world, pair)
    d0 = mjx.make_data(world.mj_model)

    def one(m, q):
        d = mjx.kinematics(m, d0.replace(qpos=q))
        return m.geom_size, d.geom_xpos, d.geom_xmat

    return jax.vmap(one, in_axes=(world.model_axes, 0))(models, qpos)


@functools.lru_cache(maxsize=4)
def _jitted_geoms(world: wd.World):
    return jax.jit(lambda pair, qpos: scene_geoms(world, pair, qpos))


def make_feature_fn(world: wd.World, cfg: pc.PerceptionConfig = pc.PerceptionConfig(), seed: int = 0):
    """``compute(samples) -> dict of numpy arrays`` for ``dataset.add_features``.

    ``samples`` needs ``pair`` (B,), ``qpos_settled`` (B, nq) and ``rollout_id`` (B,).
    """
    feats = pc.make_batched_features(world.mj_model.geom_type, world.geom_seg, cfg)
    geoms = _jitted_geoms(world)
    root = jax.random.PRNGKey(seed)

    def compute(samples: dict) -> dict:
        missing = {"pair", "qpos_settled", "rollout_id"} - set(samples)
        if missing:
            raise ValueError(f"samples lack {sorted(missing)}: not a scene dataset of this version")
        size, xpos, xmat = geoms(jnp.asarray(samples["pair"], jnp.int32),
                                 jnp.asarray(samples["qpos_settled"], jnp.float32))
        ids = np.asarray(samples["rollout_id"]).astype(np.uint32)
        keys = jax.vmap(lambda i: jax.random.fold_in(root, i))(jnp.asarray(ids))
        out = jax.device_get(feats(size, xpos, xmat, keys))
        if out["overflow"].any():
            bad = np.flatnonzero(out["overflow"])
            flags = {k: np.asarray(out[k])[bad].tolist() for k in
                     ("tile_overflow", "pixel_overflow", "voxel_overflow", "range_overflow")}
            raise ValueError(
                f"perception capacity exceeded for rollout_id {ids[bad].tolist()} ({flags}); "
                "raise the matching capacity in PerceptionConfig (docs/perception.md) rather than "
                "truncate the point clouds")
        return {"pca": out["pca"], "rhf": out["rhf"], "unseen": out["unseen"],
                "n_points": out["n_points"], "overflow": out["overflow"]}

    return compute


def add_features(path, batch: int = 32, seed: int = 0, overrides: dict | None = None,
                 progress: bool = True, overwrite: bool = False) -> dict:
    """Attach PCA and RHF features to the dataset at ``path`` (resumable)."""
    from relaff_jax.data import dataset

    cfg = rconfig.override(pc.PerceptionConfig(), overrides or {})
    world = wd.build_world()
    fn = make_feature_fn(world, cfg, seed)
    return dataset.add_features(path, fn, batch, progress,
                                {"perception": rconfig.to_dict(cfg), "seed": seed}, overwrite=overwrite)


def register_cli(sub) -> None:
    p = sub.add_parser("features", help="add PCA and RHF features to a dataset (resumable)")
    p.add_argument("dir", type=Path)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--seed", type=int, default=0, help="depth-noise seed")
    p.add_argument("--overwrite", action="store_true", help="recompute features of another config")
    p.set_defaults(func=_cmd_features)
    _register_show(sub)


def _cmd_features(args) -> int:
    out = add_features(args.dir, args.batch, args.seed, overwrite=args.overwrite)
    print(f"{args.dir}: features for {out['n']} samples: "
          + ", ".join(f"{k} {tuple(v)}" for k, v in out["features"].items()))
    return 0


def show_scene(world: wd.World, pair: int, qpos: np.ndarray, out: str | Path, key=None,
               cfg: pc.PerceptionConfig = pc.PerceptionConfig(), title: str = "") -> Path:
    """Draw what the robot saw in one settled scene (``perception.render_scene_png``: noisy
    depth image, segmentation, voxel clouds with PCA frames); writes ``out`` atomically."""
    key = jax.random.PRNGKey(0) if key is None else key
    size, xpos, xmat = jax.device_get(_jitted_geoms(world)(
        jnp.asarray([pair], jnp.int32), jnp.asarray(qpos, jnp.float32)[None]))
    scene = pc.make_scene(world.mj_model.geom_type, world.geom_seg, size[0], xpos[0], xmat[0])
    toy, other = world.pairs[pair][:2]
    pc.render_scene_png(scene, key, out, cfg, title=title or f"{toy} + {other}")
    return Path(out)


def _register_show(sub) -> None:
    p = sub.add_parser("show", help="draw what the robot saw in one sample of a dataset")
    p.add_argument("dir", type=Path)
    p.add_argument("--index", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("scene.png"))
    p.set_defaults(func=_cmd_show)


def _cmd_show(args) -> int:
    from relaff_jax.data import dataset

    ds = dataset.load_dataset(args.dir, features=False)
    n = len(ds["label"])
    if not 0 <= args.index < n:
        raise ValueError(f"--index {args.index} out of range: the dataset has {n} samples")
    i = args.index
    title = (f"{ds['action']} sample {i}: {ds['toy'][i]} + {ds['other'][i]}, {ds['relation'][i]}, "
             f"label {bool(ds['label'][i])}")
    out = show_scene(wd.build_world(), int(ds["pair"][i]), ds["qpos_settled"][i], args.out,
                     jax.random.PRNGKey(int(ds["rollout_id"][i])), title=title)
    print(f"wrote {out}")
    return 0
