"""The report stage's two resampling functions, reference path against the fast one in the same run.

    python benchmarks/report_resampling.py [--sizes 99] [--quick] [--resamples 1000]

On one target of paper-shaped synthetic outcomes (``learn.synthetic.synthetic_outcomes``:
nine actions, 50 conditions + the 2 online learners, 4,000 balanced test scenes, outcomes
bit-packed as the results store them, ``--sizes`` training sizes), for R = 50 (PCA: every
family) and R = 25 (RHF: NB and DB1 only), times ``analysis.half_curves`` and
``intervals.resampled_means`` (``cfg.ci_resamples`` = 1,000 resamples) with
``reference=True`` and the default (fast) path, checks both give the same bits
(``np.array_equal``) and prints seconds and ratios. Projection: the paper preset's report
runs both functions for 9 targets in each space (the time scales with the targets). ``--quick``:
10 sizes and 200 resamples (about a minute). The last line is ``speedup_pca=<x> speedup_rhf=<x>
projected_s=<reference> -> <fast>``.
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from relaff_jax.learn.analysis import half_curves
from relaff_jax.learn.intervals import resampled_means, scene_halves
from relaff_jax.learn.online import extend
from relaff_jax.learn.results import PackedBits
from relaff_jax.learn.synthetic import synthetic_outcomes

N_TEST = 4000
TARGETS = 9
RHF_NOT_RUN = ("DBn", "CB1", "CBn")  # the paper's RHF runs NB and DB1 only


def one_target(reps: int, sizes: int, not_run: tuple[str, ...], seed: int = 0):
    """``acc_x``, the ``Outcomes`` over packed bits, ``n_test`` and ``halves`` of target 0."""
    d = synthetic_outcomes(TARGETS, sizes, reps, np.full(TARGETS, N_TEST), seed=seed, not_run=not_run, targets=[0])
    corr = PackedBits(np.packbits(d.pop("correct"), axis=-1), N_TEST)
    acc_x, out, _ = extend(d["acc"], corr, d["loo"], d["lay"])
    n_test = np.array([N_TEST])
    return acc_x, out, n_test, scene_halves(n_test, n_test // 2, N_TEST)


def timed(f):
    t = time.perf_counter()
    out = f()
    return time.perf_counter() - t, out


def measure(reps: int, sizes: int, resamples: int, not_run: tuple[str, ...]) -> dict:
    acc_x, out, n_test, halves = one_target(reps, sizes, not_run)
    row = {}
    for name, f in (("half_curves", lambda ref: half_curves(acc_x, out, halves, reference=ref)),
                    ("resampled_means",
                     lambda ref: resampled_means(acc_x, out, n_test, resamples, 7, halves, reference=ref))):
        t_ref, a = timed(lambda: f(True))
        t_new, b = timed(lambda: f(False))
        row[name] = (t_ref, t_new, bool(np.array_equal(a, b, equal_nan=True)))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, default=99)
    ap.add_argument("--resamples", type=int, default=1000)
    ap.add_argument("--quick", action="store_true", help="10 sizes, 200 resamples")
    args = ap.parse_args()
    sizes, resamples = (10, 200) if args.quick else (args.sizes, args.resamples)
    print(f"{platform.machine()} {os.cpu_count()} cores, load average {os.getloadavg()}, numpy {np.__version__}")
    print(f"one target: {sizes} sizes, {N_TEST} test scenes, 52 conditions (50 + 2 online), {resamples} resamples")
    print(f"{'space':5} {'function':16} {'reference s':>12} {'fast s':>8} {'ratio':>6} same bits")
    total = {}
    for space, reps, not_run in (("pca", 50, ()), ("rhf", 25, RHF_NOT_RUN)):
        row = measure(reps, sizes, resamples, not_run)
        for name, (t_ref, t_new, same) in row.items():
            print(f"{space:5} {name:16} {t_ref:12.2f} {t_new:8.2f} {t_ref / t_new:6.2f} {same}")
        t_ref, t_new = (sum(v[i] for v in row.values()) for i in (0, 1))
        print(f"{space:5} {'both':16} {t_ref:12.2f} {t_new:8.2f} {t_ref / t_new:6.2f}")
        total[space] = (t_ref, t_new)
    scale = TARGETS * 99 / sizes * (1000 / resamples if resamples != 1000 else 1)
    proj_ref, proj_new = (scale * sum(v[i] for v in total.values()) for i in (0, 1))
    note = "" if (sizes, resamples) == (99, 1000) else " (scaled linearly from the measured sizes/resamples)"
    print(f"paper preset report, both functions, 9 targets x 2 spaces: {proj_ref:.0f} s -> {proj_new:.0f} s{note}")
    print(f"speedup_pca={total['pca'][0] / total['pca'][1]:.2f} speedup_rhf={total['rhf'][0] / total['rhf'][1]:.2f} "
          f"projected_s={proj_ref:.0f} -> {proj_new:.0f}")


if __name__ == "__main__":
    main()
