"""Labels of the v1 and v2 motor programs on the same placements (issue 43), native engine.

Usage: python benchmarks/programs_v2.py N [ACTION ...] [--seed S] [--json OUT] [--save NPZ]
       [--before NPZ] [--v2-only]
       [--guard-depth M]
Per action: N scenes prepared from one key with each version (the placements and the C
settle do not depend on the programs, checked), executed by the native engine; prints the
feasible programs, positives, labels that differ, and unsettled reads per version, per
relation (beside / on_top / inside). docs/actions.md, "Programs v1 and v2".

``--save NPZ`` stores every scene's v2 outcome (settled state, feasible, label, settled,
relation) per action; ``--before NPZ`` compares with such a file made by another checkout of
the code (v2 before a change against v2 after it) instead of v1 against v2: the same
placements (asserted), "v1" in the table then stands for the stored run.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import relaff_jax  # noqa: F401 (XLA flags)
import jax
import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.sim import rollouts as R
from relaff_jax.config.action import ActionConfig
from relaff_jax.sim.scenes import RELATIONS

KEYS = ("qpos_settled", "feasible", "label", "settled", "relation")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int)
    ap.add_argument("actions", nargs="*", default=list(ACTIONS))
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json")
    ap.add_argument("--save")
    ap.add_argument("--before")
    ap.add_argument("--guard-depth", type=float, default=None, help="v2's ActionConfig.guard_depth (default: its default)")
    ap.add_argument("--v2-only", action="store_true", help="run v2 alone (with --save: a file for --before)")
    a = ap.parse_args()
    before = dict(np.load(a.before)) if a.before else None
    saved = {}
    v2 = ActionConfig() if a.guard_depth is None else ActionConfig(guard_depth=a.guard_depth)
    v1 = dataclasses.replace(v2, programs="v1")
    rows = {}
    print("action relation scenes | feasible v1 v2 | positives v1 v2 | differ (v1+ v2-, v1- v2+) | unsettled v1 v2")
    for act in a.actions:
        t = time.time()
        key = jax.random.PRNGKey(a.seed)
        out = {}
        for name, cfg in (("v1", v1), ("v2", v2)):
            if name == "v1" and before is not None:  # the stored run in place of v1
                out[name] = {k: before[f"{act}/{k}"] for k in KEYS}
                continue
            if name == "v1" and a.v2_only:
                continue
            out[name] = R.execute_batch(R.make_batch_prepare_fn(act, cfg, settle="native")(key, a.n), cfg, "native")
        saved.update({f"{act}/{k}": np.asarray(out["v2"][k]) for k in KEYS})
        if "v1" not in out:
            print(f"{act:10s} v2 only: {int(out['v2']['feasible'].sum())} feasible, {int(out['v2']['label'].sum())} positives"
                  f"  ({time.time() - t:.0f} s)", flush=True)
            continue
        o1, o2 = out["v1"], out["v2"]
        assert np.array_equal(o1["qpos_settled"], o2["qpos_settled"]), "placements differ"
        rel = o1["relation"]
        for r, rname in [(-1, "all")] + list(enumerate(RELATIONS)):
            m = np.ones(len(rel), bool) if r < 0 else rel == r
            if not m.any():
                continue
            row = dict(scenes=int(m.sum()), feasible=[int(o1["feasible"][m].sum()), int(o2["feasible"][m].sum())],
                       positives=[int(o1["label"][m].sum()), int(o2["label"][m].sum())],
                       lost=int((o1["label"] & ~o2["label"])[m].sum()), gained=int((~o1["label"] & o2["label"])[m].sum()),
                       unsettled=[int((~o1["settled"])[m].sum()), int((~o2["settled"])[m].sum())])
            rows[f"{act}/{rname}"] = row
            print(f"{act:10s} {rname:7s} {row['scenes']:4d} | {row['feasible'][0]:4d} {row['feasible'][1]:4d} | "
                  f"{row['positives'][0]:4d} {row['positives'][1]:4d} | {row['lost'] + row['gained']:3d} "
                  f"({row['lost']}, {row['gained']}) | {row['unsettled'][0]:3d} {row['unsettled'][1]:3d}", flush=True)
        print(f"  ({time.time() - t:.0f} s)", flush=True)
    if a.save:
        np.savez_compressed(a.save, **saved)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(n=a.n, seed=a.seed, rows=rows), f, indent=1)


if __name__ == "__main__":
    main()
