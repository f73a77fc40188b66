"""Contact forces and penetrations of the v1 and v2 motor programs, replayed in MuJoCo C.

Usage: python benchmarks/program_forces.py N [ACTION ...] [--seed S] [--programs v1 v2 ...]
Each ``--programs`` entry is a version, optionally with ActionConfig fields after a colon:
``v2:tilt_lean=robot,guard_depth=0.001``.
Per action and version: N scenes (native settle, one key for every version), the feasible
programs replayed scene by scene with ``native.forces.physics``; prints the largest summed
contact force on an object held for 0.1 s (press) and in one step (peak), both also as a
multiple of the heavier object's weight, the deepest penetration, and the programs with a
palm contact on an object, in all and per relation (beside / on top / inside), and the
positives (docs/arm.md, "Bounded forces").
"""
from __future__ import annotations

import argparse
import dataclasses
import time

import relaff_jax  # noqa: F401 (XLA flags)
import jax
import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.sim.native import forces as native_forces
from relaff_jax.sim import rollouts as R
from relaff_jax.config.action import ActionConfig
from relaff_jax.sim.scenes import RELATIONS


def variant(entry: str) -> ActionConfig:
    """``v2`` or ``v2:key=value,...`` -> the ActionConfig (values cast to the field's type)."""
    version, _, rest = entry.partition(":")
    cfg = dataclasses.replace(ActionConfig(), programs=version)
    for item in filter(None, rest.split(",")):
        k, v = item.split("=", 1)
        kind = type(getattr(cfg, k))
        value = v.lower() in ("1", "true", "yes") if kind is bool else kind(v)
        cfg = dataclasses.replace(cfg, **{k: value})
    return cfg


def measure(action: str, cfg: ActionConfig, n: int, seed: int) -> dict:
    prep = R.make_batch_prepare_fn(action, cfg, settle="native")(jax.random.PRNGKey(seed), n)
    run = np.flatnonzero(prep.plan.feasible)
    plan = {k: np.asarray(getattr(prep.plan, k))[run] for k in ("q_way", "grip_way", "feasible", "direction")}
    r = native_forces.physics(action, cfg, prep.pair[run], np.asarray(prep.scenes.qpos)[run],
                              np.asarray(prep.scenes.qvel)[run], plan)
    r["relation"] = np.asarray(prep.scenes.relation)[run]
    r["names"] = np.asarray(prep.names)[run]
    return r


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int)
    ap.add_argument("actions", nargs="*", default=list(ACTIONS))
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--programs", nargs="+", default=["v1", "v2"])
    ap.add_argument("--worst", type=int, default=0, help="also list the K programs with the largest press (x weight) "
                    "and every one with a palm contact")
    a = ap.parse_args()
    rel = "/".join(RELATIONS)
    print(f"action version feasible | press max N (x weight) | peak max N (x weight) | depth max mm | held mm | "
          f"palm contacts ({rel}) | positives ({rel}) | unsettled")
    for act in a.actions:
        for v in a.programs:
            t = time.time()
            r = measure(act, variant(v), a.n, a.seed)
            by = lambda m: "/".join(str(int((m & (r["relation"] == i)).sum())) for i in range(len(RELATIONS)))
            if not len(r["peak"]):
                print(f"{act:10s} {v} 0 feasible")
                continue
            print(f"{act:10s} {v}  {len(r['peak']):4d} | {r['press'].max():7.1f} ({(r['press'] / r['weight']).max():5.1f}) | "
                  f"{r['peak'].max():7.1f} ({(r['peak'] / r['weight']).max():6.1f}) | {1e3 * r['depth'].max():5.1f} | "
                  f"{1e3 * r['held_depth'].max():5.1f} | {int((r['palm'] > 0).sum()):3d} ({by(r['palm'] > 0)}) | "
                  f"{int(r['label'].sum()):3d} ({by(r['label'])}) | {int((~r['settled']).sum()):3d}   ({time.time() - t:.0f} s)",
                  flush=True)
            if a.worst:
                xw = r["press"] / r["weight"]
                for i in sorted(set(np.argsort(-xw)[:a.worst]) | set(np.flatnonzero(r["palm"] > 0))):
                    print(f"    {'/'.join(map(str, r['names'][i]))} {RELATIONS[int(r['relation'][i])]}: press "
                          f"{xw[i]:.1f} x weight, palm {r['palm'][i]:.1f} N over {int(r['palm_steps'][i])} steps, "
                          f"held depth {1e3 * r['held_depth'][i]:.1f} mm, label {bool(r['label'][i])}", flush=True)


if __name__ == "__main__":
    main()
