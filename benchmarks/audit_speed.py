"""The audit's replay speed: the former path (``physics_probe.Probe``, contacts read one
``d.contact[i]`` at a time) against ``audit_replay.replay_probed`` (``probe_arrays.ArrayProbe``,
contact arrays) in one process and in ``--jobs`` processes, on the same scenes of a dataset.

    python benchmarks/audit_speed.py DATASET_DIR [--sample 24] [--jobs 2] [--cache prep.npz]

Prepares the audit's scenes as ``data/audit.py`` does (re-settle, plan; ``--cache`` keeps them
in a file, the plan's compile takes minutes), then times each path once, checks that every
reading and replay output is equal to the reference's, and prints a table: seconds,
rollouts/s and the ratio to the reference. The reference runs first, after one warm-up scene
(the replay's jitted helpers compile once per process; JAX's compilation cache is on, as
for the ``relaff`` command, so a worker loads them).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import relaff_jax  # noqa: F401  (XLA flags before JAX)
from relaff_jax import compile_cache

compile_cache.configure()  # as the command does, before JAX: the workers load the replay's programs from the cache
from relaff_jax.data import audit as A
from relaff_jax.data import audit_replay as AR
from relaff_jax.data.load import load_rollouts
from relaff_jax.data.store import read_sidecar
from relaff_jax.sim.native import reference as native
from relaff_jax.sim.native.reference import replay_native
from relaff_jax.sim.native.probe import Probe
from relaff_jax.sim.planning import setup

NEED = ("pair", "qpos0", "qpos_settled", "intended", "label", "feasible")


def former_pad_contacts(d, pad, geoms):
    """The replay's pad contacts as read before ``native._pad_contacts`` used the arrays."""
    cons = [c for c in d.contact[:d.ncon]
            if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms)]
    return np.array([c.dist for c in cons]), np.array([np.asarray(c.frame[:3], np.float64) for c in cons]).reshape(-1, 3)


def prepare(path: Path, sample: int, cache: str | None) -> dict[str, np.ndarray]:
    if cache and Path(cache).is_file():
        return dict(np.load(cache))
    meta, cfg = read_sidecar(path), None
    cfg = A.action_config(meta)
    ro = load_rollouts(path)
    r = {k: np.asarray(ro[k])[A._sample(ro, sample, 0)] for k in NEED}
    qvel, _ = A.settled_velocities(cfg, meta, r, None)
    plan = A._plan(cfg, str(meta["action"]), r["pair"], r["qpos_settled"], int(meta["batch"]))
    out = dict(pair=r["pair"], qpos=r["qpos_settled"], qvel=qvel, **{"plan_" + k: v for k, v in plan.items()})
    if cache:
        np.savez(cache, **out)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--sample", type=int, default=24)
    ap.add_argument("--jobs", type=int, default=AR.default_jobs())
    ap.add_argument("--cache", default=None, help="npz file keeping the prepared scenes")
    a = ap.parse_args()
    meta = read_sidecar(a.dir)
    cfg, action = A.action_config(meta), str(meta["action"])
    z = prepare(a.dir, a.sample, a.cache)
    n = min(a.sample, len(z["pair"]))
    pair, qpos, qvel = z["pair"][:n], z["qpos"][:n], z["qvel"][:n]
    plan = {k[5:]: z[k][:n] for k in z if k.startswith("plan_")}
    from relaff_jax.sim.actions.registry import action_id
    from relaff_jax.sim.actions.tables import tables

    measure = int(tables(cfg).measure[action_id(action)])  # the dataset's programs' (v3: rake's dwell), as the audit
    AR._replay(cfg, action, pair[:1], qpos[:1], qvel[:1], {k: v[:1] for k, v in plan.items()}, measure)  # warm-up
    world = setup(cfg).world
    new_pad, native._pad_contacts = native._pad_contacts, former_pad_contacts
    probe = Probe(n, world.toy_body, world.obj_body, cfg.phys.timestep)
    t0 = time.perf_counter()
    ref_rep = replay_native(action, cfg, pair, qpos, qvel, dict(plan), observe=probe)
    ref_got = probe.result(ref_rep["read_step"])
    times = {"reference: Probe, per-contact reads": time.perf_counter() - t0}
    native._pad_contacts = new_pad
    rows = [("ArrayProbe, 1 process", 1)] + ([(f"ArrayProbe, {a.jobs} processes", a.jobs)] if a.jobs > 1 else [])
    saved = AR.MIN_PER_JOB
    AR.MIN_PER_JOB = 1  # time the workers even for a small sample
    for name, jobs in rows:
        t0 = time.perf_counter()
        rep, got = AR.replay_probed(meta, cfg, action, pair, qpos, qvel, plan, measure, jobs)
        times[name] = time.perf_counter() - t0
        same = all(np.array_equal(ref_rep[k], rep[k]) for k in ref_rep) and all(
            ref_got[k].dtype == got[k].dtype and np.array_equal(ref_got[k], got[k], equal_nan=got[k].dtype.kind == "f")
            for k in ref_got)
        assert same, f"{name}: readings differ from the reference"
    AR.MIN_PER_JOB = saved
    ref = times["reference: Probe, per-contact reads"]
    print(f"audit replay of {n} rollouts of {a.dir} ({action}); every output equal to the reference's")
    print(f"{'path':<40}{'seconds':>9}{'rollouts/s':>12}{'speed-up':>10}")
    for name, s in times.items():
        print(f"{name:<40}{s:>9.2f}{n / s:>12.2f}{ref / s:>10.2f}")


if __name__ == "__main__":
    main()
