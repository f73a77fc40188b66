"""How many labels flip when the settled scene moves by a micrometre: the chaos floor of label
agreement between any two executors.

    python benchmarks/chaos.py [--actions ...] [--n 1000] [--batch 64] [--engine native]
        [--shift 1e-6] [--seed 0] [--json OUT]

Per action, the same prepared batches as ``benchmarks/actions.py --engines`` (same keys), each
executed twice by one executor: as prepared, and with the toy's settled position moved by
``--shift`` metres along x (float32 resolves ~6e-8 m at 0.5 m, so the shift is real but far
below anything a sensor or a planner could tell apart). The programs are the same (the plan is
not redone). Prints, per action, the feasible programs, the labels that differ and the
agreement with its 95 % Wilson interval. Two executors that compute the same physics with
different rounding (tuned and today's MJX, MJX and MuJoCo C) cannot be expected to agree
better than an executor agrees with itself under such a shift. ``--engine native`` (MuJoCo C,
deterministic) is cheap; ``--engine mjx`` runs the tuned MJX. Resumable with ``--json``.
"""
from __future__ import annotations

import argparse
import math
import os

import jax
import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.io import atomic_write_json, read_json
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim import world as wd


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k / n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (c - h, c + h)


def shifted(prep: rollouts.Prepared, toy_x: int, shift: float) -> rollouts.Prepared:
    """``prep`` with the toy's settled x (qpos address ``toy_x``) moved by ``shift`` m."""
    qpos = np.array(prep.scenes.qpos, copy=True)
    qpos[:, toy_x] += np.float32(shift)
    return prep._replace(scenes=prep.scenes.replace(qpos=qpos))


def chaos_row(action: str, n: int, batch: int, engine: str, shift: float, seed: int) -> dict:
    """One action: labels as prepared and shifted over ``ceil(n / batch)`` batches."""
    cfg = templates.ActionConfig()
    toy_x = wd.build_world(cfg.phys).toy_qpos
    prepare = rollouts.make_batch_prepare_fn(action, cfg)
    sim_batch = rollouts.default_sim_batch(batch)
    base, moved, feas, apart = [], [], [], []
    for c in range(-(-n // batch)):
        prep = prepare(rollouts.bench_batch_key(seed, batch, c), batch)
        out = rollouts.execute_batch(prep, cfg, engine, sim_batch)
        out_s = rollouts.execute_batch(shifted(prep, toy_x, shift), cfg, engine, sim_batch)
        base.append(out["label"])
        moved.append(out_s["label"])
        feas.append(np.asarray(prep.plan.feasible, bool))
        # the shift is real: how far the final states end apart (max over coordinates)
        apart.append(np.abs(out["qpos_final"] - out_s["qpos_final"]).max(axis=1))
    f = np.concatenate(feas)
    a, b = np.concatenate(base)[f], np.concatenate(moved)[f]
    k = int((a != b).sum())
    d = np.concatenate(apart)[f]
    nf = int(f.sum())
    return {"n": int(len(f)), "n_feasible": nf, "differ": k, "positives": [int(a.sum()), int(b.sum())],
            "agree": 1 - k / max(nf, 1), "agree_95": wilson(nf - k, nf),
            "final_apart_m": {"median": float(np.median(d)), "max": float(d.max())} if nf else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS))
    ap.add_argument("--n", type=int, default=1000, help="scenes per action")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--engine", default="native", choices=rollouts.ENGINES)
    ap.add_argument("--shift", type=float, default=1e-6, help="metres along x, the toy's settled position")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    bad = [a for a in args.actions if a not in ACTIONS]
    if bad:
        ap.error(f"unknown action(s) {bad}; valid: {', '.join(ACTIONS)}")
    if args.shift == 0:
        ap.error("--shift 0 measures nothing")
    setting = {k: getattr(args, k) for k in ("n", "batch", "engine", "shift", "seed")}
    done = {}
    if args.json and os.path.exists(args.json):
        prev = read_json(args.json)
        done = prev.get("actions", {}) if prev.get("setting") == setting else {}
    print(f"jax {jax.__version__}; {setting}", flush=True)
    print(f"{'action':10s} {'feasible':>8s} {'differ':>6s} {'agree':>6s} {'95 % interval':>15s}  positives (as is, shifted); final states apart (median, max)",
          flush=True)
    for action in args.actions:
        r = done.get(action) or chaos_row(action, args.n, args.batch, args.engine, args.shift, args.seed)
        done[action] = r
        if args.json:
            atomic_write_json(args.json, {"setting": setting, "actions": done})
        lo, hi = r["agree_95"]
        fa = r["final_apart_m"] or {"median": float("nan"), "max": float("nan")}  # None: no feasible program
        print(f"{action:10s} {r['n_feasible']:8d} {r['differ']:6d} {r['agree']:6.3f} {lo:7.3f}-{hi:.3f}  {r['positives']}; "
              f"{fa['median']:.2g}, {fa['max']:.2g}", flush=True)


if __name__ == "__main__":
    main()
