"""Features at the cost of what they read (issue 47): the features stage's function with
capacities sized per call (``perception.culled``, the default) against every call at the
config's capacities (``make_feature_fn(..., culled=False)``: 65,536 rays, 32,768 pixel slots,
RHF tiles of 256 per scene, the stage before), on the same scenes in the same run.

Scenes: ``--scenes`` per action of ``--actions`` (``settled_scenes.load_scenes``: sampled and
settled as the generate stage does, in chunks of 32, the paper preset's ``feature_batch``,
with rollout ids as in a dataset). One untimed pass of each function over
every chunk (compiles: the sized path compiles one program per capacity it meets), then a
timed pass, chunk by chunk, the two functions alternating first. Asserts that every output
(PCA, RHF, unseen, voxel counts, overflow) is equal, bit for bit, and prints scenes/s of both
and the ratio, the active tiles per scene and the capacities used.

    python benchmarks/perception_culled.py [--actions lift take pour] [--scenes 256]
"""
from __future__ import annotations

import argparse
import os
import time

import jax.numpy as jnp
import numpy as np

from settled_scenes import add_scene_args, load_scenes, machine_line  # first: XLA flags before JAX work
from relaff_jax import perception as pc
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.perception import from_sim


def main() -> None:
    args = add_scene_args(argparse.ArgumentParser(description=__doc__.split("\n\n")[0]), scenes=256).parse_args()
    print(machine_line(), flush=True)
    sw, chunks = load_scenes(args)
    n = sum(len(c["pair"]) for c in chunks)
    cfg = PerceptionConfig()
    fns = {"full": from_sim.make_feature_fn(sw, cfg, args.seed, culled=False),
           "sized": from_sim.make_feature_fn(sw, cfg, args.seed)}
    first = {}
    for name, f in fns.items():
        t0 = time.perf_counter()
        for c in chunks:
            f(c)
        first[name] = time.perf_counter() - t0
    t = {name: 0.0 for name in fns}
    outs = {name: [] for name in fns}
    for i, c in enumerate(chunks):
        for name in (("full", "sized") if i % 2 == 0 else ("sized", "full")):
            t0 = time.perf_counter()
            outs[name].append(fns[name](c))
            t[name] += time.perf_counter() - t0
    for a, b in zip(outs["full"], outs["sized"]):
        for k in a:
            if not np.array_equal(a[k], b[k]):
                raise AssertionError(f"the sized path changed {k}")
    geoms = from_sim.jitted_geoms(sw)
    count = pc.make_tile_counter(sw.mj_model.geom_type, sw.geom_seg, cfg)
    tiles = np.concatenate([np.asarray(count(*geoms(jnp.asarray(c["pair"], jnp.int32),
                                                     jnp.asarray(c["qpos_settled"], jnp.float32)))) for c in chunks])
    caps = {k: int(np.sum([pc.tile_capacity(int(m), cfg) == k for m in tiles])) for k in (*pc.TILE_BUCKETS, cfg.cull.max_tiles)}
    unseen = np.concatenate([o["unseen"] for o in outs["full"]]).any(1).mean()
    print(f"\n{n} settled scenes ({', '.join(args.actions)}, {args.scenes} each, chunks of 32), seed {args.seed}; "
          f"outputs equal bit for bit (pca, rhf, unseen, n_points, overflow); {unseen:.1%} with an unseen object")
    print(f"active 16 x 16 tiles per scene (of 1,200; capacity {cfg.cull.max_tiles}): median {np.median(tiles):.0f}, "
          f"90 % {np.percentile(tiles, 90):.0f}, max {tiles.max()}; scenes by capacity (alone): {caps}")
    print("\n| path | scenes/s | first pass s (compiles) |\n|---|---:|---:|")
    for name, label in (("full", "config's capacities (before)"), ("sized", "capacities sized per call (now)")):
        print(f"| {label} | {n / t[name]:.1f} | {first[name]:.1f} |")
    print(f"\nsized / full: {t['full'] / t['sized']:.2f}; load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
