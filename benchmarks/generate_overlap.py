"""The generate stage's batches on both cores: each chunk prepared while the one before it
executes, against one chunk after another, in the same run, with every output compared.

"before" is the driver as it was: per chunk, ``rollout_fn(key, batch)`` (sample, place, C
settle, reach screen and plans in JAX, then MuJoCo C's execution of the feasible programs,
labels) one after another, with the rest reader of the C execution as it was
(``PerSceneRestReader`` below: ``labels.read_at_rest`` scene by scene, over every collected
step, after every step). "after" is what ``relaff generate`` runs without a cluster now: the
next chunk's first half on a background thread (``data.tasks.PrepareAhead``) while this one
executes, and the step-by-step reader (``native.program.RestReader``). Both run the same keys
(the dataset's chunks 1..N of seed 0; chunk 0 first, untimed, for the compiles); every field of
every chunk must be equal bit for bit, or the script stops.

The first table splits the "before" path (timers around its parts): CPU seconds (the
process's, every thread), wall seconds and cores busy (CPU / wall) of each part. The second
table gives each path's CPU and wall seconds and the ratio. The machine may be shared: the
ratios of two paths in the same run and CPU seconds are what to read.

    python benchmarks/generate_overlap.py [--actions lift take rake] [--batch 1024] [--batches 2]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from relaff_jax import compile_cache  # XLA flags before JAX work

compile_cache.configure()  # as the command does: compiled programs from the cache
import mujoco.batch  # noqa: E402
from relaff_jax.constants import ACTIONS
from relaff_jax.data.tasks import PrepareAhead, chunk_key
from relaff_jax.sim import labels, rollouts
from relaff_jax.sim.native import batch as native_batch
from relaff_jax.sim.native import program as native_program


class PerSceneRestReader(native_program.RestReader):
    """The rest reader as it was: after every step in the window, ``labels.read_at_rest`` of
    each scene on all its collected steps (the reference the step-by-step reader replaces)."""

    def add(self, t, com, qpos):
        if t < self.lo or t > self.lo + self.cfg.rest_window + self.hold:
            return
        self.com.append(np.array(com, np.float64))
        self.q.append(np.array(qpos))
        if len(self.com) > self.cfg.rest_window:
            _, settled = self._read()
            self.done = bool(np.all(settled)) or len(self.com) == self.cfg.rest_window + 1 + self.hold

    def _read(self):
        com = np.stack(self.com, axis=1)  # (B, T, 2, 3)
        out = [labels.read_at_rest(c, self.cfg.rest_window, self.cfg.scene.rest_speed, self.cfg.phys.timestep, np)
               for c in com]
        return np.array([i for i, _ in out]), np.array([s for _, s in out], bool)


PARTS = [  # (module or class, attribute, label) of the "before" path's split
    (rollouts.sc, "sample_pairs", "sample pairs (JAX)"),
    (rollouts, "settle_batch", "settle (MuJoCo C, then relations in Python)"),
    (rollouts, "prepare_screened", "reach screen and plans (JAX)"),
    (rollouts, "execute_native", "execution, all of it"),
    (native_batch, "program_inputs", "- initial states and commands (JAX)"),
    (mujoco.batch.Batch, "step", "- mujoco.batch steps (C; the settle's counted here too)"),
    (mujoco.batch.Batch, "rollout", "- mujoco.batch rollouts (C: the stretches between decision steps)"),
    (native_batch, "_landing", "- landing tests (Python, numpy)"),
    (native_batch, "_touching", "- grasp tests (Python, numpy)"),
    (PerSceneRestReader, "add", "- rest reader (Python, numpy)"),
    (native_batch, "native_labels", "- outcome rules (JAX, numpy)"),
]


class Timers:
    """Wraps each part's function by one that adds its CPU and wall seconds (outermost call)."""

    def __init__(self):
        self.sums: dict[str, list[float]] = {label: [0.0, 0.0] for _, _, label in PARTS}
        self.saved = []

    def install(self):
        for owner, name, label in PARTS:
            fn = getattr(owner, name)
            self.saved.append((owner, name, fn))
            setattr(owner, name, self._timed(fn, label))

    def _timed(self, fn, label):
        sums = self.sums

        def timed(*a, **k):
            c0, t0 = time.process_time(), time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                sums[label][0] += time.process_time() - c0
                sums[label][1] += time.perf_counter() - t0
        return timed

    def remove(self):
        for owner, name, fn in reversed(self.saved):
            setattr(owner, name, fn)
        self.saved.clear()


def before(fn, keys, batch, timers=None):
    native_batch.RestReader = PerSceneRestReader
    if timers:
        timers.install()
    try:
        return [fn(k, batch) for k in keys]
    finally:
        if timers:
            timers.remove()
        native_batch.RestReader = native_program.RestReader


def after(fn, first, n, batch):
    ahead = PrepareAhead(fn, 0, batch, first + n)
    try:
        out = []
        for k in range(first, first + n):
            prepared = ahead.take(k)
            ahead.begin(k + 1)
            out.append(fn.execute(prepared))
        return out
    finally:
        ahead.close()


def clocked(run):
    c0, t0 = time.process_time(), time.perf_counter()
    out = run()
    return out, time.process_time() - c0, time.perf_counter() - t0


def differing(a: list[dict], b: list[dict]) -> list[str]:
    """The fields of the chunks ``a`` and ``b`` whose bits differ (NaN, e.g. a screened
    program's ``ik_error``, equals itself here); [] when all are equal."""
    bits = lambda x: (x.dtype.str, x.shape, x.tobytes())
    return sorted({f for x, y in zip(a, b) for f in x.keys() | y.keys()
                   if f not in x or f not in y or bits(np.asarray(x[f])) != bits(np.asarray(y[f]))})


def reader_rows(scenes: int = 512, steps: int = 211) -> str:
    """The two rest readers alone on the same synthetic motions (``scenes`` scenes that move
    until a random step, then stay still; v2's window and hold): CPU seconds each, and
    whether every scene's read step, state and ``settled`` agree."""
    from types import SimpleNamespace

    from relaff_jax.config.action import ActionConfig

    cfg = ActionConfig()
    inp = SimpleNamespace(measure=cfg.rest_window, v2=True)
    rng = np.random.default_rng(0)
    move = rng.normal(size=(scenes, steps, 2, 3)) * 1e-3
    move[np.arange(steps)[None, :] >= rng.integers(0, steps, scenes)[:, None]] = 0.0
    com, qpos = np.cumsum(move, axis=1), rng.normal(size=(scenes, steps, 14)).astype(np.float32)
    out, cpu = [], []
    for cls in (PerSceneRestReader, native_program.RestReader):
        c0 = time.process_time()
        r = cls(cfg, inp)
        for t in range(steps):
            r.add(t, com[:, t], qpos[:, t])
            if r.done:
                break
        out.append((*r.result(), r.read_steps()))
        cpu.append(time.process_time() - c0)
    agree = all(np.array_equal(x, y) for x, y in zip(*out))
    return (f"| rest reader alone, {scenes} scenes, up to {steps} steps | {cpu[0]:.2f} | {cpu[1]:.3f} | "
            f"{cpu[0] / cpu[1]:.0f} | {'equal' if agree else 'DIFFER'} |")


def table(rows) -> str:
    out = ["| action | executed programs | before: CPU s | wall s | cores busy | after: CPU s | wall s | cores busy "
           "| wall before / after | CPU before / after | outputs |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for a, c0, w0, c1, w1, sim in rows:
        out.append(f"| {a} | {sim} | {c0:.1f} | {w0:.1f} | {c0 / w0:.2f} | {c1:.1f} | {w1:.1f} | {c1 / w1:.2f} | "
                   f"{w0 / w1:.2f} | {c0 / c1:.2f} | equal |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--actions", nargs="+", default=["lift", "take", "rake"], choices=ACTIONS)
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--batches", type=int, default=2)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average before {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; batch {args.batch}, {args.batches} timed "
          f"batches per path, native engine, default programs")
    print("\n| piece | before: CPU s | after: CPU s | ratio | outputs |\n|---|---:|---:|---:|---|\n" + reader_rows(),
          flush=True)
    rows = []
    for a in args.actions:
        fn = rollouts.make_rollout_fn(a, args.batch, engine="native")
        fn(chunk_key(0, 0), args.batch)  # compiles
        keys = [chunk_key(0, k) for k in range(1, 1 + args.batches)]
        timers = Timers()
        # "after" first: a compile a timed chunk still needs (the execution pads its rows to a
        # power of two, a shape chunk 0 may not have had) then falls on it, not on the reference
        new, cpu1, wall1 = clocked(lambda: after(fn, 1, args.batches, args.batch))
        ref, cpu0, wall0 = clocked(lambda: before(fn, keys, args.batch, timers))
        print(f"\n{a}: where the 'before' path's {cpu0:.1f} CPU s ({wall0:.1f} s wall, "
              f"{cpu0 / wall0:.2f} cores busy) go\n\n| part | CPU s | share of CPU | wall s | cores busy |\n"
              f"|---|---:|---:|---:|---:|")
        for label, (c, w) in timers.sums.items():
            print(f"| {label} | {c:.2f} | {c / cpu0:.1%} | {w:.2f} | {c / w if w else 0:.2f} |")
        outside = cpu0 - sum(timers.sums[label][0] for _, _, label in PARTS if not label.startswith("-"))
        print(f"| the rest (placement, ids, Python) | {outside:.2f} | {outside / cpu0:.1%} | | |", flush=True)
        if differing(ref, new):
            raise SystemExit(f"{a}: the two paths' rollouts differ in {differing(ref, new)}")
        rows.append((a, cpu0, wall0, cpu1, wall1, sum(int(r["simulated"].sum()) for r in ref)))
        print(f"\n{a}, before against after:\n" + table(rows[-1:]), flush=True)
    print("\nAll actions:\n" + table(rows))
    print(f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
