"""Where the features stage's time goes, stage by stage, at the capacities it runs.

Scenes: ``--scenes`` settled scenes per action (``settled_scenes.load_scenes``), sorted
by active tiles and cut into calls of ``from_sim.SUB_BATCH`` (4) as ``make_culled_features``
does; each call runs at its ``tile_capacity``. Every stage of the chain is jitted on its own
(vmapped over the call's scenes, inputs computed by the stage before, untimed) and timed
over all calls after one untimed pass: tile count, ray cast (``render_objects``), compaction,
ray-hit normals, noise, voxel grid, PCA, RHF, and the RHF as it was (``rhf_histograms_fused``,
the reference); then the whole chain (``make_culled_features``) with the RHF of now and with
the one before, in the same run, rounds alternating. Asserts that both chains give the same
bits. Prints ms per scene of each stage (process CPU seconds: the machine is shared), its
share, and both chains' scenes/s (wall clock), CPU ms per scene and the ratios (on a shared
machine the CPU figure is the steadier one).

    python benchmarks/perception_stages.py [--actions lift take pour] [--scenes 64] [--rounds 3]
"""
from __future__ import annotations

import argparse
import contextlib
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from settled_scenes import add_scene_args, load_scenes, machine_line  # first: XLA flags before JAX work
from relaff_jax import perception as pc
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.perception import from_sim
from relaff_jax.perception import pipeline
from relaff_jax.perception.descriptors import pca_object, rhf_histograms, rhf_histograms_fused
from relaff_jax.perception.noise import add_depth_noise
from relaff_jax.perception.raycast import surface_normals
from relaff_jax.perception.render import active_tiles, compact_objects, render_objects
from relaff_jax.perception.scene import SceneGeoms, make_scene
from relaff_jax.perception.voxels import voxel_downsample


def stage_fns(geom_type, geom_seg, cfg):
    """name -> (jitted vmapped fn, fn(previous outputs) -> its args)."""
    g = len(geom_type)
    st = make_scene(geom_type, geom_seg, np.zeros((g, 3)), np.zeros((g, 3)), np.tile(np.eye(3), (g, 1, 1)))
    sc = lambda s, x, m: SceneGeoms(st.geom_type, st.geom_seg, s, x, m)
    v = lambda f: jax.jit(jax.vmap(f))

    def pca2(vox):
        return [pca_object(vox["points"][o], vox["mask"][o], cfg.min_points) for o in range(2)]

    def rhf(fn):
        def f(vox):
            cnt = jnp.minimum(vox["count"], cfg.voxel.max_voxels)
            return fn(vox["points"][0], vox["normals"][0], cnt[0], vox["points"][1], vox["normals"][1], cnt[1], cfg.rhf)
        return f

    return {
        "tile count": v(lambda s, x, m: jnp.sum(active_tiles(sc(s, x, m), cfg))),
        "ray cast": v(lambda s, x, m: render_objects(sc(s, x, m), cfg)),
        "compaction": v(lambda ro: compact_objects(ro, cfg)),
        "hit normals": v(lambda s, x, m, pix: surface_normals(sc(s, x, m), pix["points"], pix["geom"])),
        "noise": v(lambda pix, k: add_depth_noise(pix, k, cfg)),
        "voxel grid": v(lambda pix: voxel_downsample(pix["points"], pix["normal"], pix["seg"], cfg)),
        "PCA": v(pca2),
        "RHF": v(rhf(rhf_histograms)),
        "RHF before (reference)": v(rhf(rhf_histograms_fused)),
    }


@contextlib.contextmanager
def fused_rhf():
    """The chain traced with ``rhf_histograms_fused`` (the RHF before) while inside."""
    pipeline.rhf_histograms = rhf_histograms_fused
    try:
        yield
    finally:
        pipeline.rhf_histograms = rhf_histograms


def run_stages(fns, s, x, m, k):
    """Each stage once on one call's inputs; returns {name: seconds} (blocking after each)."""
    t = {}

    def go(name, *args):
        t0 = time.process_time()
        r = jax.block_until_ready(fns[name](*args))
        t[name] = time.process_time() - t0
        return r

    go("tile count", s, x, m)
    ro = go("ray cast", s, x, m)
    pix = go("compaction", ro)
    pix = dict(pix, normal=go("hit normals", s, x, m, pix))
    pix = go("noise", pix, k)
    vox = go("voxel grid", pix)
    go("PCA", vox)
    go("RHF", vox)
    go("RHF before (reference)", vox)
    return t


def main() -> None:
    ap = add_scene_args(argparse.ArgumentParser(description=__doc__.split("\n\n")[0]), scenes=64)
    ap.add_argument("--rounds", type=int, default=3, help="timed passes (the best per stage is kept)")
    args = ap.parse_args()
    print(machine_line(), flush=True)
    sw, chunks = load_scenes(args)
    geoms, root = from_sim.jitted_geoms(sw), jax.random.PRNGKey(args.seed)
    parts = [jax.device_get(geoms(jnp.asarray(c["pair"], jnp.int32), jnp.asarray(c["qpos_settled"], jnp.float32)))
             for c in chunks]
    size, xpos, xmat = (jnp.asarray(np.concatenate(p)) for p in zip(*parts))
    keys = from_sim.rollout_keys(root, np.concatenate([c["rollout_id"] for c in chunks]))
    n = size.shape[0]
    cfg = PerceptionConfig()
    gt, gs = tuple(int(v) for v in sw.mj_model.geom_type), tuple(int(v) for v in sw.geom_seg)
    tiles = np.asarray(pc.make_tile_counter(gt, gs, cfg)(size, xpos, xmat))
    sb = from_sim.SUB_BATCH
    order = np.argsort(tiles, kind="stable")
    order = np.concatenate([order, np.full(-n % sb, order[-1])])
    calls = [(grp, pc.tile_capacity(int(tiles[grp].max()), cfg)) for grp in np.split(order, len(order) // sb)]
    fns = {k: stage_fns(gt, gs, pc.capacity_config(cfg, k)) for k in {c for _, c in calls}}
    chains = {"now": pc.make_culled_features(gt, gs, cfg, sub_batch=sb),
              "before": pc.make_culled_features(gt, gs, cfg, sub_batch=sb)}

    def stages_pass():
        tot = {}
        for grp, k in calls:
            for name, dt in run_stages(fns[k], size[grp], xpos[grp], xmat[grp], keys[grp]).items():
                tot[name] = tot.get(name, 0.0) + dt
        return tot

    def chain_pass(name):
        outs = []
        with fused_rhf() if name == "before" else contextlib.nullcontext():  # traced on first use
            t0, c0 = time.perf_counter(), time.process_time()
            for lo in range(0, n, 32):
                outs.append(chains[name](size[lo:lo + 32], xpos[lo:lo + 32], xmat[lo:lo + 32], keys[lo:lo + 32]))
            return (time.perf_counter() - t0, time.process_time() - c0), outs

    stages_pass()  # compiles
    first = {name: chain_pass(name) for name in chains}
    for a, b in zip(first["now"][1], first["before"][1]):
        for k in a:
            if not np.array_equal(a[k], b[k]):
                raise AssertionError(f"the RHF of now changed {k}")
    best, best_chain = {}, {name: (np.inf, np.inf) for name in chains}
    for r in range(args.rounds):
        for name, dt in stages_pass().items():
            best[name] = min(best.get(name, np.inf), dt)
        for name in (("now", "before") if r % 2 == 0 else ("before", "now")):
            wall, cpu = chain_pass(name)[0]
            best_chain[name] = (min(best_chain[name][0], wall), min(best_chain[name][1], cpu))
    total = sum(dt for name, dt in best.items() if name != "RHF before (reference)")
    print(f"\n{n} settled scenes ({', '.join(args.actions)}), calls of {sb} at capacities "
          f"{sorted({k for _, k in calls})} tiles; active tiles median {np.median(tiles):.0f}, max {tiles.max()}; "
          f"best of {args.rounds} passes")
    print("\n| stage | CPU ms / scene | share |\n|---|---:|---:|")
    for name, dt in best.items():
        print(f"| {name} | {1e3 * dt / n:.2f} | {'' if 'before' in name else f'{dt / total:.0%}'} |")
    print(f"| sum of stages (now) | {1e3 * total / n:.2f} | |")
    print("\n| whole chain (make_culled_features, chunks of 32) | scenes/s (wall) | wall ms / scene "
          "| CPU ms / scene |\n|---|---:|---:|---:|")
    for name in ("before", "now"):
        wall, cpu = best_chain[name]
        print(f"| RHF {name} | {n / wall:.1f} | {1e3 * wall / n:.2f} | {1e3 * cpu / n:.2f} |")
    (wb, cb), (wn, cn) = best_chain["before"], best_chain["now"]
    print(f"\nnow / before: {wb / wn:.2f} (wall), {cb / cn:.2f} (CPU); outputs equal bit for bit; "
          f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
