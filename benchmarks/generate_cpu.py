"""Where the generate stage's CPU time goes, per action (issue 47): MuJoCo C's execution of the
motor programs against the rest (C settle, placement, reach screen, plans in JAX, Python).

The native rollout function (``rollouts.make_rollout_fn(action, batch, engine="native")``,
what ``relaff generate --engine native`` runs per chunk) on ``--batches`` batches after one
untimed batch (compiles), with ``rollouts.execute_native`` (the C execution of the feasible
programs, its marshalling included), ``rollouts.settle_batch`` (the C settle) and
``rollouts.still_batch`` (the C stillness check of a settled scene) wrapped by timers. CPU seconds are the process's (every thread: the C batches run on ``nthread``
threads), wall seconds beside. "rest" = the whole call minus the three MuJoCo C parts; the
last row sums the actions. ``--parts`` adds a second table: the CPU seconds of the planner's
stored programs inside "rest" (the reach screen, the plan of its programs, unobstruct's toy
reach; each call waited for, so the time of its asynchronous run is its own) and the rest
outside them (placement, the stage's Python).

    python benchmarks/generate_cpu.py [--actions lift take ...] [--batch 64] [--batches 2] [--parts]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import relaff_jax  # noqa: F401  (XLA flags before JAX work)
import jax
from relaff_jax.constants import ACTIONS
from relaff_jax.sim import rollouts, traced_cache

PARTS = ("screen", "plan_of", "toy_reach")  # the planner's stored programs (sim/reach_screen.py)


class Timer:
    """Wraps ``fn``; sums the CPU (``time.process_time``) and wall seconds spent in it."""

    def __init__(self, fn):
        self.fn, self.cpu, self.wall = fn, 0.0, 0.0

    def __call__(self, *a, **k):
        c0, t0 = time.process_time(), time.perf_counter()
        try:
            return self.fn(*a, **k)
        finally:
            self.cpu += time.process_time() - c0
            self.wall += time.perf_counter() - t0


class Parts:
    """Sums the CPU seconds of each stored program's calls (by name), each call waited for."""

    def __init__(self):
        self.cpu = dict.fromkeys(PARTS, 0.0)
        self.call = traced_cache._Stored.__call__
        parts = self

        def timed(stored, *args):
            if stored.name not in parts.cpu:
                return parts.call(stored, *args)
            c0 = time.process_time()
            out = jax.block_until_ready(parts.call(stored, *args))
            parts.cpu[stored.name] += time.process_time() - c0
            return out

        traced_cache._Stored.__call__ = timed

    def close(self):
        traced_cache._Stored.__call__ = self.call


def measure(action: str, batch: int, batches: int) -> dict:
    ex, st, sl = Timer(rollouts.execute_native), Timer(rollouts.settle_batch), Timer(rollouts.still_batch)
    rollouts.execute_native, rollouts.settle_batch, rollouts.still_batch = ex, st, sl
    parts = Parts()
    try:
        fn = rollouts.make_rollout_fn(action, batch, engine="native")
        fn(rollouts.bench_batch_key(3, batch, 0), batch)  # compiles
        ex.cpu = ex.wall = st.cpu = st.wall = sl.cpu = sl.wall = 0.0
        parts.cpu = dict.fromkeys(PARTS, 0.0)
        c0, t0 = time.process_time(), time.perf_counter()
        for i in range(batches):
            fn(rollouts.bench_batch_key(3, batch, 1 + i), batch)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    finally:
        rollouts.execute_native, rollouts.settle_batch, rollouts.still_batch = ex.fn, st.fn, sl.fn
        parts.close()
    return dict(cpu=cpu, wall=wall, exec_cpu=ex.cpu, exec_wall=ex.wall, settle_cpu=st.cpu, settle_wall=st.wall,
                still_cpu=sl.cpu, parts=parts.cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS), choices=ACTIONS)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--batches", type=int, default=2)
    ap.add_argument("--parts", action="store_true", help="the planner's programs' CPU inside the rest, per action")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average before {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; batch {args.batch}, {args.batches} timed batches")
    print("| action | CPU s | C execution | C settle | C stillness check | rest (place, screen, plan, Python) "
          "| execution share of CPU | MuJoCo C share | wall s |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    tot = dict(cpu=0.0, c=0.0, ex=0.0)
    rows = []
    for a in args.actions:
        d = measure(a, args.batch, args.batches)
        rows.append((a, d))
        c = d["exec_cpu"] + d["settle_cpu"] + d["still_cpu"]
        tot["cpu"] += d["cpu"]
        tot["c"] += c
        tot["ex"] += d["exec_cpu"]
        print(f"| {a} | {d['cpu']:.2f} | {d['exec_cpu']:.2f} | {d['settle_cpu']:.2f} | {d['still_cpu']:.2f} | "
              f"{d['cpu'] - c:.2f} | {d['exec_cpu'] / d['cpu']:.1%} | {c / d['cpu']:.1%} | {d['wall']:.2f} |", flush=True)
    print(f"| all | {tot['cpu']:.2f} | | | | {tot['cpu'] - tot['c']:.2f} | {tot['ex'] / tot['cpu']:.1%} | "
          f"{tot['c'] / tot['cpu']:.1%} | |")
    if args.parts:
        print("\n| action | rest CPU s | " + " | ".join(PARTS) + " | rest outside them |\n|---|---:|"
              + "---:|" * (len(PARTS) + 1))
        for a, d in rows:
            rest = d["cpu"] - d["exec_cpu"] - d["settle_cpu"] - d["still_cpu"]
            p = d["parts"]
            print(f"| {a} | {rest:.2f} | " + " | ".join(f"{p[k]:.2f}" for k in PARTS)
                  + f" | {rest - sum(p.values()):.2f} |")
    print(f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
