"""Perception benchmark: scenes/s through the JAX chain vs native MuJoCo rays + Open3D + numpy.

Scenes: random (toy, other) pairs of the object library (``world.pair_xml`` models, so the
geom layout is the real one: table plane, toy sphere + box, five boxes of the other object),
placed at random positions/yaws in the workspace, the toy beside the other object or above
it, through ``mj_forward`` (perception does not need settled physics to be timed).

Per stage, 640x480, the whole set of scenes once (one run, after a warm-up/compile pass):
  JAX:    ``make_batched_features`` and each stage jitted + vmapped over a batch;
  native: ``mj_multiRay`` over all 307200 pixels, numpy noise, Open3D ``voxel_down_sample``,
          numpy ``eigh`` PCA, numpy RHF (vectorised, chunked pairs, ``np.bincount``), one scene
          at a time (single thread).
Each side runs in its own subprocess, so each reports its own peak RSS. A noise-free pass of
both chains on the same scenes gives the agreement of the final features.

    PYTHONPATH=. python benchmarks/perception.py --scenes 32 --batch 8 [--write-docs]
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import resource
import sys
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from relaff_jax.sim import objects as lib
from relaff_jax import perception as P
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.sim import world as wd


def make_scenes(n: int, seed: int = 0):
    """n random scenes: (geom_type (G,), geom_seg (G,), size (n, G, 3), xpos (n, G, 3),
    xmat (n, G, 3, 3), [(MjModel, MjData)] for the native path)."""
    rng = np.random.default_rng(seed)
    pairs = lib.pairs()
    native, sizes, xpos, xmat = [], [], [], []
    cache = {}
    for i in range(n):
        toy, other, _ = pairs[rng.integers(len(pairs))]
        if (toy, other) not in cache:
            cache[(toy, other)] = mujoco.MjModel.from_xml_string(wd.pair_xml(toy, other))
        m = cache[(toy, other)]
        d = mujoco.MjData(m)
        # Toy and other object apart, or the toy above the other object (on top / inside).
        r, th = rng.uniform(0.5, 1.3), rng.uniform(-1.0, 1.0)
        obj_xy = np.array([r * np.cos(th), r * np.sin(th)])
        if rng.random() < 0.5:
            toy_xy, toy_z = obj_xy + rng.uniform(-0.05, 0.05, 2), lib.get(other).height + 0.002
        else:
            ang = rng.uniform(0, 2 * np.pi)
            toy_xy, toy_z = obj_xy + 0.35 * np.array([np.cos(ang), np.sin(ang)]), 0.0
        for adr, xy, z in ((m.jnt_qposadr[0], toy_xy, toy_z), (m.jnt_qposadr[1], obj_xy, 0.0)):
            yaw = rng.uniform(-np.pi, np.pi)
            d.qpos[adr:adr + 7] = [xy[0], xy[1], z, np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        mujoco.mj_forward(m, d)
        native.append((m, d))
        sizes.append(m.geom_size.copy())
        xpos.append(d.geom_xpos.copy())
        xmat.append(d.geom_xmat.reshape(-1, 3, 3).copy())
    m0 = native[0][0]
    seg = np.full(m0.ngeom, wd.SEG_BACKGROUND, np.int32)
    seg[m0.geom_bodyid == 1] = wd.SEG_TOY
    seg[m0.geom_bodyid == 2] = wd.SEG_OTHER
    return m0.geom_type.copy(), seg, np.stack(sizes), np.stack(xpos), np.stack(xmat), native


# ----------------------------------------------------------------------------- native chain

NUMPY_SIGMA = {  # the docs/facts.md "Sensor" formulas again, in numpy (metres)
    "robwork": lambda z, r: np.maximum(
        2.344 - 1.202e-2 * r - 1.734e-3 * (z * 1e3) + 1.818e-5 * r * r + 6.516e-6 * r * (z * 1e3)
        + 1.233e-6 * (z * 1e3) ** 2, 0.0) / 1e3,
    "khoshelham": lambda z, r: 1.425e-3 * z * z,
    "nguyen": lambda z, r: 0.0012 + 0.0019 * (z - 0.4) ** 2,
}


def native_features(m, d, seg, cfg: PerceptionConfig, rng, timers: dict | None = None):
    """The same stages with native tools: mj_multiRay, numpy, Open3D, numpy."""
    import open3d as o3d

    def tick(name, t0):
        if timers is not None:
            timers[name] = timers.get(name, 0.0) + time.perf_counter() - t0
        return time.perf_counter()

    cam = cfg.camera
    t0 = time.perf_counter()
    origin, dirs = P.camera_rays(cam)
    n = dirs.shape[0]
    geom = np.zeros(n, np.int32)
    dist = np.zeros(n)
    normal = np.zeros(3 * n)
    mujoco.mj_multiRay(m, d, origin, dirs.ravel(), None, 1, -1, geom, dist, normal, n, 1e6)
    t0 = tick("render", t0)
    valid = (geom >= 0) & (dist >= cam.near) & (dist <= cam.far)
    pix_seg = np.where(valid, seg[np.maximum(geom, 0)], -1)
    obj = np.flatnonzero((pix_seg == 1) | (pix_seg == 2))
    depth = dist[obj]
    if cfg.noise.model != "none":
        fx, fy, cx, cy = P.intrinsics(cam)
        u = obj % cam.width + 0.5 - cx
        v = obj // cam.width + 0.5 - cy
        r = np.hypot(u, v) * (640.0 / cam.width)
        sigma = NUMPY_SIGMA[cfg.noise.model](depth, r)
        depth = depth + sigma * rng.standard_normal(len(obj))
    fwd = P.camera_frame(cam)[1][:, 2]
    pts = origin + dist[obj, None] * dirs[obj] + (depth - dist[obj])[:, None] * fwd
    nrm = normal.reshape(n, 3)[obj]
    oseg = pix_seg[obj]
    t0 = tick("noise", t0)
    clouds = []
    for s in (1, 2):
        pc = o3d.geometry.PointCloud()
        pc.points = o3d.utility.Vector3dVector(pts[oseg == s])
        pc.normals = o3d.utility.Vector3dVector(nrm[oseg == s])
        dn = pc.voxel_down_sample(cfg.voxel.size)
        q, qn = np.asarray(dn.points), np.asarray(dn.normals)
        ln = np.linalg.norm(qn, axis=1, keepdims=True)
        qn = np.where(ln > 1e-6, qn / np.maximum(ln, 1e-6), [0.0, 0.0, 1.0])
        clouds.append((q, qn))
    t0 = tick("voxel", t0)
    pca, unseen = [], []
    for q, _ in clouds:
        if len(q) < cfg.min_points:
            pca.append(np.zeros(9))
            unseen.append(True)
            continue
        mu = q.mean(0)
        w, vec = np.linalg.eigh((q - mu).T @ (q - mu) / len(q))

        def fix(x, order):
            for i in order:
                if abs(x[i]) > 1e-6:
                    return x * np.sign(x[i])
            return x

        ax, az = fix(vec[:, 2], (0, 1, 2)), fix(vec[:, 0], (2, 0, 1))
        rot = np.stack([ax, np.cross(az, ax), az], 1)
        rpy = [np.arctan2(rot[2, 1], rot[2, 2]), np.arctan2(-rot[2, 0], np.hypot(rot[0, 0], rot[1, 0])),
               np.arctan2(rot[1, 0], rot[0, 0])]
        pca.append(np.concatenate([mu, rpy, w[::-1]]))
        unseen.append(False)
    t0 = tick("pca", t0)
    rhf = np.zeros(6 * cfg.rhf.bins)
    if not any(unseen):
        (pa, na), (pb, nb) = clouds
        counts = np.zeros(6 * cfg.rhf.bins)
        nbin = cfg.rhf.bins
        for i in range(0, len(pa), 256):  # chunked so memory stays bounded
            a, an = pa[i:i + 256, None, :], na[i:i + 256, None, :]
            dd = pb[None] - a
            dist_ = np.linalg.norm(dd, axis=-1)
            cos_nn = np.clip(np.sum(an * nb[None], -1), -1, 1)
            cos_nd = np.where(dist_ > 0, np.sum(an * dd, -1) / np.where(dist_ > 0, dist_, 1), 1)
            vals = (dd[..., 0], dd[..., 1], dd[..., 2], dist_, np.arccos(cos_nn), np.arccos(np.clip(cos_nd, -1, 1)))
            for f, val in enumerate(vals):
                lo, hi = cfg.rhf.ranges[f]
                b = np.clip(np.floor((val - lo) / (hi - lo) * nbin), 0, nbin - 1).astype(np.int64)
                counts[f * nbin:(f + 1) * nbin] += np.bincount(b.ravel(), minlength=nbin)
        rhf = counts / (len(pa) * len(pb))
    tick("rhf", t0)
    return dict(pca=np.concatenate(pca), rhf=rhf, unseen=np.array(unseen),
                n_points=np.array([len(c[0]) for c in clouds]))


# ----------------------------------------------------------------------------- runners


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_jax(n: int, batch: int, seed: int) -> dict:
    gt, gs, size, xpos, xmat, _ = make_scenes(n, seed)
    cfg = PerceptionConfig()
    nb = n // batch
    keys = jax.random.split(jax.random.key(seed), n)
    res = {"stages": {}, "compile": {}}
    scene = P.make_scene(gt, gs, size[:batch], xpos[:batch], xmat[:batch])

    def batches():
        for i in range(nb):
            sl = slice(i * batch, (i + 1) * batch)
            yield P.SceneGeoms(scene.geom_type, scene.geom_seg, jnp.asarray(size[sl], jnp.float32),
                               jnp.asarray(xpos[sl], jnp.float32), jnp.asarray(xmat[sl], jnp.float32)), keys[sl]

    def timed(name, fn, inputs):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*inputs[0]))
        res["compile"][name] = time.perf_counter() - t0
        outs = []
        t0 = time.perf_counter()
        for inp in inputs:
            outs.append(fn(*inp))
        jax.block_until_ready(outs)
        res["stages"][name] = time.perf_counter() - t0
        return outs

    f = P.make_batched_features(gt, gs, cfg)
    timed("chain", lambda s, k: f.jitted(s.size, s.xpos, s.xmat, k), list(batches()))
    full = jax.jit(jax.vmap(lambda s: P.render(s, cfg)))
    timed("render_full", lambda s, k: full(s), list(batches()))

    def stage_render(s, k):
        ro = P.render_objects(s, cfg)
        pix = P.compact_objects(ro, cfg)
        pix["normal"] = P.surface_normals(s, pix["points"], pix["geom"])
        return pix

    r = timed("render", jax.jit(jax.vmap(stage_render)), list(batches()))
    ks = [k for _, k in batches()]
    nz = timed("noise", jax.jit(jax.vmap(lambda p, k: P.add_depth_noise(p, k, cfg))), list(zip(r, ks)))
    vx = timed("voxel", jax.jit(jax.vmap(lambda p: P.voxel_downsample(p["points"], p["normal"], p["seg"], cfg))),
               [(p,) for p in nz])
    timed("pca", jax.jit(jax.vmap(lambda v: jax.vmap(P.pca_object, (0, 0, None))(v["points"], v["mask"], cfg.min_points))),
          [(v,) for v in vx])
    timed("rhf", jax.jit(jax.vmap(lambda v: P.rhf_histograms(v["points"][0], v["normals"][0], v["count"][0],
                                                             v["points"][1], v["normals"][1], v["count"][1], cfg.rhf))),
          [(v,) for v in vx])
    # Noise-free features for the agreement check with the native chain.
    clean = override_noise(cfg)
    g = P.make_batched_features(gt, gs, clean)
    out = [g.jitted(s.size, s.xpos, s.xmat, k) for s, k in batches()]
    res["clean"] = {k: np.concatenate([np.asarray(o[k]) for o in out]).tolist() for k in ("pca", "rhf", "unseen", "n_points")}
    res["n_points"] = np.concatenate([np.asarray(v["count"]) for v in vx]).tolist()
    res["peak_rss_mb"] = _peak_rss_mb()
    res["scenes"] = nb * batch
    return res


def override_noise(cfg):
    from relaff_jax.config import override

    return override(cfg, {"noise.model": "none"})


def run_native(n: int, batch: int, seed: int) -> dict:
    gt, gs, size, xpos, xmat, native = make_scenes(n, seed)
    n = (n // batch) * batch
    cfg = PerceptionConfig()
    rng = np.random.default_rng(seed)
    native_features(*native[0], gs, cfg, rng)  # warm-up (imports, allocations)
    timers: dict = {}
    t0 = time.perf_counter()
    for m, d in native[:n]:
        native_features(m, d, gs, cfg, rng, timers)
    chain = time.perf_counter() - t0
    clean = override_noise(cfg)
    outs = [native_features(m, d, gs, clean, rng) for m, d in native[:n]]
    return dict(stages=dict(timers, chain=chain), peak_rss_mb=_peak_rss_mb(), scenes=n,
                clean={k: np.stack([o[k] for o in outs]).tolist() for k in ("pca", "rhf", "unseen", "n_points")})


# ----------------------------------------------------------------------------- report


STAGES = (
    ("render", "1. camera: ray cast (JAX: object tiles + compaction + normals; native: all pixels)"),
    ("noise", "2. depth noise (RobWork)"),
    ("voxel", "3. voxel grid 0.0125 m (JAX sort; native Open3D)"),
    ("pca", "4. PCA (eigh)"),
    ("rhf", "5. RHF (all pairs, 6 x 50 bins)"),
    ("chain", "whole chain (JAX: one jitted program)"),
)


def table(jx: dict, nt: dict) -> str:
    n = jx["scenes"]
    lines = ["| stage | JAX scenes/s | native scenes/s | JAX / native |", "|---|---:|---:|---:|"]
    for key, label in STAGES:
        a, b = n / jx["stages"][key], nt["scenes"] / nt["stages"][key]
        lines.append(f"| {label} | {a:,.1f} | {b:,.1f} | {a / b:.2f} |")
    a = n / jx["stages"]["render_full"]
    b = nt["scenes"] / nt["stages"]["render"]
    lines.append(f"| (JAX full 640x480 render, for the depth image) | {a:,.1f} | {b:,.1f} | {a / b:.2f} |")
    lines.append(f"| peak RSS (MB) | {jx['peak_rss_mb']:,.0f} | {nt['peak_rss_mb']:,.0f} | |")
    return "\n".join(lines)


def agreement(jx: dict, nt: dict) -> str:
    a, b = jx["clean"], nt["clean"]
    pa, pb = np.asarray(a["pca"]), np.asarray(b["pca"])
    ra, rb = np.asarray(a["rhf"]), np.asarray(b["rhf"])
    na, nb_ = np.asarray(a["n_points"]), np.asarray(b["n_points"])
    same_unseen = np.array_equal(np.asarray(a["unseen"]), np.asarray(b["unseen"]))
    l1 = np.abs(ra - rb).reshape(len(ra), 6, -1).sum(-1).max()
    return (f"noise off, {len(pa)} scenes: voxel counts equal in {np.mean(na == nb_) * 100:.1f} % of objects "
            f"(max |diff| {np.abs(na - nb_).max()}); unseen flags equal: {same_unseen}; "
            f"PCA max |diff| {np.abs(pa - pb).max():.2e}; RHF max L1 per histogram {l1:.2e}")


def write_docs(text: str, path: str | None = None) -> None:
    """Put this run's section into today's journal (``docs/journal/YYYY-MM-DD.md``), replacing
    a section of the same heading written earlier that day."""
    import time

    day = time.strftime("%Y-%m-%d", time.gmtime())
    path = path or f"docs/journal/{day}.md"
    head = "## Perception"
    old = open(path).read() if os.path.exists(path) else f"# Journal, {day}\n"
    lines = old.split("\n")
    try:
        start = lines.index(head)
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        lines = lines[:start] + text.rstrip("\n").split("\n") + [""] + lines[end:]
    except ValueError:
        lines = lines + ([""] if lines[-1] else []) + text.rstrip("\n").split("\n") + [""]
    from relaff_jax.io import atomic_write_text

    atomic_write_text(path, "\n".join(lines).rstrip("\n") + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", type=int, default=32)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--part", choices=("jax", "native"), help=argparse.SUPPRESS)
    ap.add_argument("--write-docs", action="store_true", help="write the run's section into today's journal, docs/journal/YYYY-MM-DD.md")
    args = ap.parse_args(argv)
    if args.part:
        res = (run_jax if args.part == "jax" else run_native)(args.scenes, args.batch, args.seed)
        print("RESULT " + __import__("json").dumps(res))
        return 0
    import json
    import subprocess

    out = {}
    for part in ("jax", "native"):
        cmd = [sys.executable, __file__, "--part", part, "--scenes", str(args.scenes),
               "--batch", str(args.batch), "--seed", str(args.seed)]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ))
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if proc.returncode or not line:
            sys.stderr.write(proc.stderr[-3000:])
            raise SystemExit(f"{part} part failed")
        out[part] = json.loads(line[0][7:])
    jx, nt = out["jax"], out["native"]
    load = os.getloadavg()
    text = "\n".join([
        "## Perception",
        "",
        f"Date: {datetime.date.today().isoformat()}. Command: "
        f"`PYTHONPATH=. python benchmarks/perception.py --scenes {args.scenes} --batch {args.batch}`.",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, jax {jax.__version__}, mujoco {mujoco.__version__}; "
        f"load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}.",
        "",
        f"{jx['scenes']} random library scenes at 640x480, JAX in batches of {args.batch} (vmap, "
        "XLA CPU may use both cores), native one scene at a time on one thread; one timed run "
        "after a compile/warm-up pass.",
        "",
        table(jx, nt),
        "",
        "JAX compile times (s): " + ", ".join(f"{k} {v:.1f}" for k, v in jx["compile"].items()) + ".",
        "",
        "Agreement of the two chains: " + agreement(jx, nt) + ".",
        "",
    ])
    print(text)
    if args.write_docs:
        write_docs(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
