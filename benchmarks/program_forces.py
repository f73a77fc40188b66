"""Contact forces and penetrations of the v1 and v2 motor programs, replayed in MuJoCo C.

Usage: python benchmarks/program_forces.py N [ACTION ...] [--seed S] [--programs v1 v2]
Per action and version: N scenes (native settle, one key for both versions), the feasible
programs replayed scene by scene with ``native.forces.physics``; prints the largest summed
contact force on an object held for 0.1 s (press) and in one step (peak), both also as a
multiple of the heavier object's weight, the deepest penetration, and the programs with a
palm contact on an object (docs/arm.md, "Bounded forces").
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


def measure(action: str, cfg: ActionConfig, n: int, seed: int) -> dict:
    prep = R.make_batch_prepare_fn(action, cfg, settle="native")(jax.random.PRNGKey(seed), n)
    run = np.flatnonzero(prep.plan.feasible)
    plan = {k: np.asarray(getattr(prep.plan, k))[run] for k in ("q_way", "grip_way", "feasible", "direction")}
    return native_forces.physics(action, cfg, prep.pair[run], np.asarray(prep.scenes.qpos)[run],
                                 np.asarray(prep.scenes.qvel)[run], plan)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int)
    ap.add_argument("actions", nargs="*", default=list(ACTIONS))
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--programs", nargs="+", default=["v1", "v2"])
    a = ap.parse_args()
    print("action version feasible | press max N (x weight) | peak max N (x weight) | depth max mm | palm contacts | unsettled")
    for act in a.actions:
        for v in a.programs:
            t = time.time()
            r = measure(act, dataclasses.replace(ActionConfig(), programs=v), a.n, a.seed)
            if not len(r["peak"]):
                print(f"{act:10s} {v} 0 feasible")
                continue
            print(f"{act:10s} {v}  {len(r['peak']):4d} | {r['press'].max():7.1f} ({(r['press'] / r['weight']).max():5.1f}) | "
                  f"{r['peak'].max():7.1f} ({(r['peak'] / r['weight']).max():6.1f}) | {1e3 * r['depth'].max():5.1f} | "
                  f"{int((r['palm'] > 0).sum()):3d} | {int((~r['settled']).sum()):3d}   ({time.time() - t:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
