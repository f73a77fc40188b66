"""MJX against MuJoCo C (the native engine) on today's programs: label agreement per action.

    python benchmarks/engines_v2.py N [ACTION ...] [--seed S] [--batch B] [--json OUT]

Per action, prepared batches of B scenes (``rollouts.make_batch_prepare_fn``, settled in C so
that no MJX settle is compiled; keys ``rollouts.bench_batch_key(seed, B, i)``) until at least
N programs are feasible; every feasible program is executed by both engines with the default
``ActionConfig`` (programs v2, tuned arm world): MJX (``simulate.make_simulate_fn``, calls of
16, one compile for all actions) and the native engine (``native.batch.execute_native``, the C
reference bit for bit). Prints the agreement on the feasible programs and, for every scene
whose labels differ, the pair, the settled relation, both labels and the quantities the
outcome rule reads in each engine (``disagreements.quantities``, cm: toy, other) with the
first-guess class of ``disagreements.classify``. ``--json`` keeps finished actions (a rerun
with the same setting skips them). No timing: this measures agreement, not speed.
"""
from __future__ import annotations

import argparse
import os
import time

import relaff_jax  # noqa: F401 (XLA flags)
import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.io import atomic_write_json, read_json
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim.scenes import RELATIONS

from disagreements import classify, outcomes, quantities


def action_row(action: str, n: int, batch: int, seed: int, cfg: templates.ActionConfig) -> dict:
    """Both engines on the feasible programs of prepared batches until ``n`` are feasible."""
    prepare = rollouts.make_batch_prepare_fn(action, cfg, settle="native")
    labels = {"mjx": [], "native": []}
    differ, feasible, scenes, c = [], 0, 0, 0
    while feasible < n and c < 32:
        prep = prepare(rollouts.bench_batch_key(seed, batch, c), batch)
        run = np.flatnonzero(prep.plan.feasible)
        out = {e: outcomes(prep, cfg, e) for e in ("mjx", "native")}
        for j in run:
            lm, ln = bool(out["mjx"]["label"][j]), bool(out["native"]["label"][j])
            labels["mjx"].append(lm)
            labels["native"].append(ln)
            if lm != ln:
                d = np.asarray(prep.plan.direction[j])
                qm, qn = quantities(out["mjx"], j, d), quantities(out["native"], j, d)
                differ.append(dict(batch=c, row=int(j), toy=str(prep.names[j][0]), other=str(prep.names[j][1]),
                                   relation=RELATIONS[int(prep.scenes.relation[j])], mjx=lm, native=ln,
                                   kind=classify(action, cfg, qm, qn),
                                   mjx_q={k: [float(x) for x in v] for k, v in qm.items()},
                                   native_q={k: [float(x) for x in v] for k, v in qn.items()}))
        feasible += len(run)
        scenes += batch
        c += 1
    lm, ln = np.asarray(labels["mjx"]), np.asarray(labels["native"])
    return dict(scenes=scenes, feasible=int(feasible), agree=int((lm == ln).sum()),
                positives={"mjx": int(lm.sum()), "native": int(ln.sum())}, differ=differ)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("n", type=int, help="feasible programs per action (at least)")
    ap.add_argument("actions", nargs="*", default=list(ACTIONS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--json")
    a = ap.parse_args()
    cfg = templates.ActionConfig()
    setting = dict(n=a.n, seed=a.seed, batch=a.batch, programs=cfg.programs)
    done = {}
    if a.json and os.path.exists(a.json):
        prev = read_json(a.json)
        done = prev.get("actions", {}) if prev.get("setting") == setting else {}
    print(f"programs {cfg.programs}, seed {a.seed}, batch {a.batch}, >= {a.n} feasible programs per action", flush=True)
    for action in a.actions:
        if action not in done:
            t = time.time()
            done[action] = action_row(action, a.n, a.batch, a.seed, cfg)
            print(f"  ({action}: {time.time() - t:.0f} s)", flush=True)
            if a.json:
                atomic_write_json(a.json, {"setting": setting, "actions": done})
        r = done[action]
        print(f"{action:10s} scenes {r['scenes']:4d} feasible {r['feasible']:4d} agree {r['agree']:4d} "
              f"({r['agree'] / max(r['feasible'], 1):.3f}) positives mjx {r['positives']['mjx']} "
              f"native {r['positives']['native']}", flush=True)
        for d in r["differ"]:
            print(f"    batch {d['batch']} row {d['row']} {d['toy']} / {d['other']} ({d['relation']}): mjx {d['mjx']}, "
                  f"native {d['native']} -> {d['kind']}", flush=True)
            for e in ("mjx", "native"):
                q = d[f"{e}_q"]
                print(f"      {e:7s} " + "  ".join(f"{k} {v[0]:6.1f} {v[1]:6.1f}" for k, v in q.items()
                                                  if k not in ("moved", "apart"))
                      + f"  toy moved {q['moved'][0]:5.1f}  apart {q['apart'][0]:5.1f}", flush=True)


if __name__ == "__main__":
    main()
