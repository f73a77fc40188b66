"""Examine the label disagreements of an engine table, scene by scene.

    python benchmarks/disagreements.py ENGINES.json [--pairs mjx~mjx_today native~mjx]
        [--actions ...] [--per-action 5] [--seed 0]

``ENGINES.json`` is what ``benchmarks/actions.py --engines B --agree N --json ENGINES.json``
wrote: per action and batch size the rows where two executors' labels differ. For a sample of
them (the first ``--per-action`` of each action and pair, in row order) this rebuilds the
row's batch from its key (the same keys as ``actions.py``), runs both executors on it again,
checks that the labels are reproduced, and prints the quantities the action's outcome rule
reads (``labels.goals``) in both executors: rise at the measuring step, displacement along
the action, change of the horizontal distance to the robot, and the drop of each centre of
mass at the end (a toppled object). Each row gets a first-guess class:

- ``threshold``: both executors put the rule's quantity within 25 % of its threshold;
- ``grasp``: a lift-type action where one executor lifts a body and the other does not;
- ``tips``: else, an object's centre ends >= 2 cm lower (than before the action) in one
  executor than in the other;
- ``other``: none of these (read the numbers).
"""
from __future__ import annotations

import argparse

import jax
import numpy as np

from relaff_jax.constants import action_id
from relaff_jax.io import read_json
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim.native.batch import execute_native
from relaff_jax.sim.planning import Plan

# executor name -> (engine, tuned?): the names of benchmarks/actions.py's EXECUTORS
EXECUTORS = {"mjx_today": ("mjx", False), "mjx": ("mjx", True), "native": ("native", True),
             "native_today": ("native", False)}
LIFT_TYPE = ("lift", "take", "pour", "slide")


def outcomes(prep: rollouts.Prepared, cfg: templates.ActionConfig, engine: str) -> dict[str, np.ndarray]:
    """Labels and centres of mass of every feasible scene of ``prep`` (NaN where infeasible),
    grouped as ``rollouts.execute_batch`` groups them (MJX calls of 16, padded)."""
    aid = action_id(prep.action)
    s, plan, p = prep.scenes, prep.plan, prep.pair
    n = len(p)
    out = {"label": np.zeros(n, bool), **{k: np.full((n, 2, 3), np.nan) for k in ("com0", "com_m", "com_end")},
           "reach_after": prep.before.copy()}
    run = np.flatnonzero(plan.feasible)
    qpos, qvel = np.asarray(s.qpos, np.float32), np.asarray(s.qvel)
    sub = lambda idx: Plan(plan.q_way[idx], plan.grip_way[idx], plan.seg_steps, plan.feasible[idx],  # noqa: E731
                           plan.direction[idx], plan.ik_error[idx])
    if engine == "native" and len(run):
        r = execute_native(prep.action, cfg, p[run], qpos[run], qvel[run], sub(run), prep.before[run])
        for k in out:
            out[k][run] = r[k]
    if engine == "mjx":
        _, simulate_fn = rollouts.jitted_stage_fns(cfg)
        for lo in range(0, len(run), 16):
            rows = run[lo:lo + 16]
            idx = np.resize(rows, 16)
            r = jax.device_get(simulate_fn(aid, p[idx], qpos[idx], qvel[idx], sub(idx), prep.before[idx]))
            for k in out:
                out[k][rows] = np.asarray(r[k])[:len(rows)]
    return out


def quantities(o: dict, i: int, direction: np.ndarray) -> dict[str, np.ndarray]:
    """The outcome rule's inputs of row ``i``, (toy, other) each, in cm; ``moved`` (the toy's
    displacement, slide) and ``apart`` (toy minus base along the sweep, move) twice."""
    c0, cm, ce = o["com0"][i], o["com_m"][i], o["com_end"][i]
    r0, r1 = np.linalg.norm(c0[:, :2], axis=-1), np.linalg.norm(ce[:, :2], axis=-1)
    return {"rise": 100 * (cm[:, 2] - c0[:, 2]), "along": 100 * ((ce - c0) @ direction),
            "dr": 100 * (r1 - r0), "drop": 100 * (c0[:, 2] - ce[:, 2]),
            "moved": 100 * np.linalg.norm(cm[0] - c0[0]) * np.ones(2),
            "apart": 100 * ((ce[0] - c0[0]) - (ce[1] - c0[1])) @ direction * np.ones(2)}


def classify(action: str, cfg: templates.ActionConfig, qa: dict, qb: dict) -> str:
    """First-guess class of one disagreement (module docstring)."""
    rule = {"lift": ("rise", cfg.lifted), "take": ("rise", cfg.lifted), "pour": ("rise", cfg.lifted),
            "slide": ("moved", cfg.moved), "pull": ("dr", -cfg.closer), "push": ("dr", cfg.farther),
            "rake": ("dr", -cfg.closer),
            "move": ("apart" if cfg.move_rule == "apart" else "along", cfg.aside)}.get(action)
    if action in LIFT_TYPE and ((qa["rise"] >= 100 * cfg.lifted) != (qb["rise"] >= 100 * cfg.lifted)).any():
        return "grasp"
    fell = lambda q: np.maximum(q["drop"], 0.0)  # noqa: E731  (a lifted body's drop is negative)
    if np.abs(fell(qa) - fell(qb)).max() >= 2.0:
        return "tips"
    if rule:
        key, thr = rule
        near = lambda q: np.any(np.abs(q[key] - 100 * thr) <= 0.25 * abs(100 * thr))  # noqa: E731
        if near(qa) and near(qb):
            return "threshold"
    return "other"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("engines_json")
    ap.add_argument("--pairs", nargs="+", default=["mjx~mjx_today", "native~mjx"])
    ap.add_argument("--actions", nargs="+", default=None)
    ap.add_argument("--per-action", type=int, default=5)
    args = ap.parse_args()
    doc = read_json(args.engines_json)
    seed = int(doc["setting"]["seed"])
    tuned = templates.ActionConfig()
    cfgs = {True: tuned, False: templates.untuned(tuned)}
    names = lambda prep, j: f"{prep.names[j][0]} / {prep.names[j][1]}"  # noqa: E731
    counts: dict[str, dict[str, int]] = {}
    for action, by_batch in doc["actions"].items():
        if args.actions and action not in args.actions:
            continue
        prepare = rollouts.make_batch_prepare_fn(action, tuned)
        for b, row in by_batch.items():
            b = int(b)
            preps, runs = {}, {}
            for pair_name in args.pairs:
                xa, xb = pair_name.split("~")
                rows = row["differ_rows"].get(pair_name, [])[:args.per_action]
                print(f"\n{action}, batch {b}, {pair_name}: {len(row['differ_rows'].get(pair_name, []))} "
                      f"disagreements, examining {len(rows)}", flush=True)
                for i, _, la, lb in rows:
                    c, j = divmod(int(i), b)
                    if c not in preps:
                        preps[c] = prepare(rollouts.bench_batch_key(seed, b, c), b)
                    prep = preps[c]
                    for x in (xa, xb):  # each batch and executor runs once
                        if (c, x) not in runs:
                            runs[c, x] = outcomes(prep, cfgs[EXECUTORS[x][1]], EXECUTORS[x][0])
                    oa, ob = runs[c, xa], runs[c, xb]
                    same = (bool(oa["label"][j]) == bool(la)) and (bool(ob["label"][j]) == bool(lb))
                    d = np.asarray(prep.plan.direction[j])
                    qa, qb = quantities(oa, j, d), quantities(ob, j, d)
                    kind = classify(action, tuned, qa, qb)
                    counts.setdefault(action, {}).setdefault(kind, 0)
                    counts[action][kind] += 1
                    print(f"  row {i} ({names(prep, j)}): {xa} {bool(oa['label'][j])}, {xb} {bool(ob['label'][j])}"
                          f"{'' if same else '  [NOT REPRODUCED]'} -> {kind}")
                    for x, q, o in ((xa, qa, oa), (xb, qb, ob)):
                        print(f"    {x:12s} " + "  ".join(f"{k} {v[0]:6.1f} {v[1]:6.1f}" for k, v in q.items()
                                                        if k not in ("moved", "apart"))
                              + f"  toy moved {q['moved'][0]:5.1f}  apart {q['apart'][0]:5.1f}"
                              + (f"  reach {bool(prep.before[j])}->{bool(o['reach_after'][j])}"
                                 if action == "unobstruct" else ""), flush=True)
    print("\nclasses (cm; toy, other): " + "; ".join(f"{a}: " + ", ".join(f"{k} {v}" for k, v in c.items())
                                                    for a, c in counts.items()))


if __name__ == "__main__":
    main()
