"""Where the generate stage's CPU time goes, per action (issue 47): MuJoCo C's execution of the
motor programs against the rest (C settle, placement, reach screen, plans in JAX, Python).

The native rollout function (``rollouts.make_rollout_fn(action, batch, engine="native")``,
what ``relaff generate --engine native`` runs per chunk) on ``--batches`` batches after one
untimed batch (compiles), with ``rollouts.execute_native`` (the C execution of the feasible
programs, its marshalling included) and ``rollouts.settle_batch`` (the C settle) wrapped by
timers. CPU seconds are the process's (every thread: the C batches run on ``nthread``
threads), wall seconds beside. "rest" = the whole call minus execution and settle.

    python benchmarks/generate_cpu.py [--actions lift take ...] [--batch 64] [--batches 2]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import relaff_jax  # noqa: F401  (XLA flags before JAX work)
from relaff_jax.constants import ACTIONS
from relaff_jax.sim import rollouts


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


def measure(action: str, batch: int, batches: int) -> dict:
    ex, st = Timer(rollouts.execute_native), Timer(rollouts.settle_batch)
    rollouts.execute_native, rollouts.settle_batch = ex, st
    try:
        fn = rollouts.make_rollout_fn(action, batch, engine="native")
        fn(rollouts.bench_batch_key(3, batch, 0), batch)  # compiles
        ex.cpu = ex.wall = st.cpu = st.wall = 0.0
        c0, t0 = time.process_time(), time.perf_counter()
        for i in range(batches):
            fn(rollouts.bench_batch_key(3, batch, 1 + i), batch)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    finally:
        rollouts.execute_native, rollouts.settle_batch = ex.fn, st.fn
    return dict(cpu=cpu, wall=wall, exec_cpu=ex.cpu, exec_wall=ex.wall, settle_cpu=st.cpu, settle_wall=st.wall)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=list(ACTIONS), choices=ACTIONS)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--batches", type=int, default=2)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average before {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; batch {args.batch}, {args.batches} timed batches")
    print("| action | CPU s | C execution | C settle | rest (place, screen, plan, Python) | execution share of CPU "
          "| wall s |\n|---|---:|---:|---:|---:|---:|---:|")
    for a in args.actions:
        d = measure(a, args.batch, args.batches)
        rest = d["cpu"] - d["exec_cpu"] - d["settle_cpu"]
        print(f"| {a} | {d['cpu']:.2f} | {d['exec_cpu']:.2f} | {d['settle_cpu']:.2f} | {rest:.2f} | "
              f"{d['exec_cpu'] / d['cpu']:.1%} | {d['wall']:.2f} |", flush=True)
    print(f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
