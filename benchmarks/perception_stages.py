"""Where the features stage's time goes, stage by stage, at the capacities it runs.

Scenes: ``--scenes`` settled scenes per action (``settled_scenes.load_scenes``), sorted
by active tiles and cut into calls of ``from_sim.SUB_BATCH`` (4) as ``make_culled_features``
does; each call is cast at its ``tile_capacity`` and runs the stages after the cast at its
``pixel_capacity``. Every stage of the chain is jitted on its own (vmapped over the call's
scenes, inputs computed by the stage before, untimed) and timed over all calls after one
untimed pass: tile count, ray cast (``render_objects``), compaction, ray-hit normals, noise,
voxel grid, PCA, RHF, and the RHF as it was (``rhf_histograms_fused``, the reference); then
the whole chain (``make_culled_features``) as it runs and the reference chain (the pixel
buffer at the tile capacity, ``pixel_buckets=()``, and the fused RHF), in the same run, rounds
alternating. Asserts that both chains give the same bits. Prints ms per scene of each stage (process CPU seconds: the machine is shared), its
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
from relaff_jax.perception.render import BUFFER_FIELDS
from relaff_jax.perception.scene import scene_layout
from relaff_jax.perception.voxels import voxel_downsample


def stage_fns(geom_type, geom_seg, cfg):
    """name -> (jitted vmapped fn, fn(previous outputs) -> its args)."""
    sc = scene_layout(geom_type, geom_seg)
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


def run_stages(fns, s, x, m, k, pixels):
    """Each stage once on one call's inputs, the stages after the compaction on its first
    ``pixels`` slots; returns {name: seconds} (blocking after each)."""
    t = {}

    def go(name, *args):
        t0 = time.process_time()
        r = jax.block_until_ready(fns[name](*args))
        t[name] = time.process_time() - t0
        return r

    go("tile count", s, x, m)
    ro = go("ray cast", s, x, m)
    pix = go("compaction", ro)
    pix = {name: v[:, :pixels] if name in BUFFER_FIELDS else v for name, v in pix.items()}
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
    groups = np.split(order, len(order) // sb)
    chains = {"now": pc.make_culled_features(gt, gs, cfg, sub_batch=sb),
              "before": pc.make_culled_features(gt, gs, cfg, sub_batch=sb, pixel_buckets=())}

    def stages_pass():
        tot = {}
        for grp, k, m in calls:
            for name, dt in run_stages(fns[k], size[grp], xpos[grp], xmat[grp], keys[grp], m).items():
                tot[name] = tot.get(name, 0.0) + dt
        return tot

    def chain_pass(name):
        outs = []
        with fused_rhf() if name == "before" else contextlib.nullcontext():  # traced on first use
            t0, c0 = time.perf_counter(), time.process_time()
            for lo in range(0, n, 32):
                outs.append(chains[name](size[lo:lo + 32], xpos[lo:lo + 32], xmat[lo:lo + 32], keys[lo:lo + 32]))
            return (time.perf_counter() - t0, time.process_time() - c0), outs

    first = {name: chain_pass(name) for name in chains}  # compiles
    for a, b in zip(first["now"][1], first["before"][1]):
        for k in a:
            if not np.array_equal(a[k], b[k]):
                raise AssertionError(f"the chain of now changed {k}")
    pixels = np.concatenate([o["n_pixels"] for o in first["now"][1]]).sum(1)
    calls = []
    for grp in groups:
        k = pc.tile_capacity(int(tiles[grp].max()), cfg)
        calls.append((grp, k, pc.pixel_capacity(int(pixels[grp].max()), pc.capacity_config(cfg, k).voxel.max_object_pixels)))
    fns = {k: stage_fns(gt, gs, pc.capacity_config(cfg, k)) for k in {c[1] for c in calls}}
    stages_pass()  # compiles
    best, best_chain = {}, {name: (np.inf, np.inf) for name in chains}
    for r in range(args.rounds):
        for name, dt in stages_pass().items():
            best[name] = min(best.get(name, np.inf), dt)
        for name in (("now", "before") if r % 2 == 0 else ("before", "now")):
            wall, cpu = chain_pass(name)[0]
            best_chain[name] = (min(best_chain[name][0], wall), min(best_chain[name][1], cpu))
    total = sum(dt for name, dt in best.items() if name != "RHF before (reference)")
    print(f"\n{n} settled scenes ({', '.join(args.actions)}), calls of {sb} at capacities "
          f"{sorted({c[1] for c in calls})} tiles and {sorted({c[2] for c in calls})} pixels; active tiles median "
          f"{np.median(tiles):.0f}, max {tiles.max()}; object pixels median {np.median(pixels):.0f}, max "
          f"{pixels.max()}; best of {args.rounds} passes")
    print("\n| stage | CPU ms / scene | share |\n|---|---:|---:|")
    for name, dt in best.items():
        print(f"| {name} | {1e3 * dt / n:.2f} | {'' if 'before' in name else f'{dt / total:.0%}'} |")
    print(f"| sum of stages (now) | {1e3 * total / n:.2f} | |")
    print("\n| whole chain (make_culled_features, chunks of 32) | scenes/s (wall) | wall ms / scene "
          "| CPU ms / scene |\n|---|---:|---:|---:|")
    labels = {"before": "reference (buffer at the tile capacity, fused RHF)", "now": "as it runs"}
    for name in ("before", "now"):
        wall, cpu = best_chain[name]
        print(f"| {labels[name]} | {n / wall:.1f} | {1e3 * wall / n:.2f} | {1e3 * cpu / n:.2f} |")
    (wb, cb), (wn, cn) = best_chain["before"], best_chain["now"]
    print(f"\nnow / before: {wb / wn:.2f} (wall), {cb / cn:.2f} (CPU); outputs equal bit for bit; "
          f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
