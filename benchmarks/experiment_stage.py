"""Where the experiment stage's time goes (issue 26): compiled fit, compiled evaluation and
everything else, on a paper-shaped slice, projected to the paper preset; reference code
against this checkout in the same run, with the results checked bit for bit.

The slice: 9 synthetic actions of 10,000 samples (``learn.synthetic_datasets``), the paper
preset (4,000 test scenes, 2,000 source scenes, 52 conditions, outcomes kept, leave-one-out
forests at n = 10) with the compiled engine, one repetition and two of the preset's four
blocks of sizes (n = 2..26 and 77..100, mean n 50.5 against the preset's 51), ``jobs=1`` so
that one process does everything. Each code version runs in its own subprocess
(``PYTHONPATH``): the numba kernels are wrapped by timers (``build_forests`` = fit,
``block_sums`` = evaluation: on the 4,000 test rows, or the leave-one-out forests' 10
rows), ``prepare`` (source predictors, categories, correlation) is timed apart, "other" is
the sweep's time minus the kernels. Times are the worker's CPU seconds (``time.process_time``:
the kernels are single-threaded, so a loaded machine stretches their wall time but hardly
their CPU time); ``--wall`` times wall seconds, for an idle machine.

Projection to the preset (9 actions, sizes 2..100, 50 PCA / 25 RHF repetitions): the sweep
forests' fit time per forest is interpolated in n (measured at 2..26 and 77..100) and
summed over the preset's forests (``protocol.condition_plan`` on the run's correlations);
evaluation per forest times the preset's forests, leave-one-out parts per leave-one-out
forest, "other" per forest; prep as measured (it is the preset's own size). The preset's
wall time with 2 workers is the CPU sum / 2.

    PYTHONPATH=. python benchmarks/experiment_stage.py --ref /path/to/reference/checkout [--spaces pca rhf]

``--ref``: a checkout of the reference code (``git worktree add`` or ``git archive main``);
without it only this checkout runs. Each version's folder is kept in ``--out``. With ``--ref`` the
script exits non-zero when any result array differs between the two.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
SIZES = tuple(range(2, 27)) + tuple(range(77, 101))
SKIP = {"seconds", "seconds_prep"}  # timings, not results


def worker(out: str, spaces: list[str], samples: int, reps: int, wall: bool = False) -> None:
    """Run the slice in this process; print one JSON line of timings (this process's CPU
    seconds, or wall seconds with ``wall``)."""
    clock = time.perf_counter if wall else time.process_time
    from relaff_jax.config import override
    from relaff_jax.learn import blocks, sweep
    from relaff_jax.learn.forest.compiled import forest as cf
    from relaff_jax.config.experiment import experiment_preset
    from relaff_jax.learn.synthetic import synthetic_datasets

    cfg = override(experiment_preset("paper"), {"sizes": SIZES, "reps_pca": reps, "reps_rhf": reps,
                                                "forest.engine": "compiled"})
    ds = synthetic_datasets(samples, seed=0)
    k = cf.kernels()
    rec = {"on": True, "pending": [], "fit": [], "eval": [], "prep": 0.0}
    build, sums = k["build_forests"], k["block_sums"]

    def build_t(*a):
        t = clock()
        r = build(*a)
        if rec["on"]:
            rec["pending"].append((int(a[2][0]), len(a[2]), clock() - t))  # (n, forests, s)
        return r

    def sums_t(*a):
        t = clock()
        r = sums(*a)
        if rec["on"]:
            rows = int(a[-1].shape[1])
            kind = "sweep" if rows == cfg.test_size else "loo"
            rec["eval"].append((kind, len(a[6]) - 1, clock() - t))
            rec["fit"] += [(kind,) + p for p in rec["pending"]]
            rec["pending"].clear()
        return r

    k["build_forests"], k["block_sums"] = build_t, sums_t
    prepare = sweep.prepare

    def prepare_t(*a, **kw):
        rec["on"] = False
        t = clock()
        try:
            return prepare(*a, **kw)
        finally:
            rec["prep"] += clock() - t
            rec["on"] = True

    sweep.prepare = prepare_t
    assert blocks.FLUSH  # the blocks module is the one timed
    res = {}
    for space in spaces:
        rec.update(fit=[], eval=[], prep=0.0)
        t = clock()
        sweep.run_experiment(ds, out, cfg, [space], seed=0, jobs=1, progress=False)
        wall = clock() - t
        with np.load(Path(out) / space / "results.npz") as z:
            corr = z["corr"]
        res[space] = {"wall": wall, "prep": rec["prep"], "fit": rec["fit"], "eval": rec["eval"], "corr": corr.tolist()}
    print("RESULT " + json.dumps(res))


def run_version(code: Path, out: Path, spaces, samples, reps, wall=False) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--out", str(out), "--spaces", *spaces,
           "--samples", str(samples), "--reps", str(reps)] + (["--wall"] if wall else [])
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=str(code))
    if p.returncode:
        sys.exit(f"{code}: worker failed\n{p.stderr[-4000:]}")
    line = [x for x in p.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def parts(r: dict) -> dict:
    """Seconds of one space's slice: prep, fit / eval of sweep and leave-one-out forests, other."""
    fit_s = sum(s for kind, _, _, s in r["fit"] if kind == "sweep")
    fit_l = sum(s for kind, _, _, s in r["fit"] if kind == "loo")
    ev_s = sum(s for kind, _, s in r["eval"] if kind == "sweep")
    ev_l = sum(s for kind, _, s in r["eval"] if kind == "loo")
    n_s = sum(f for kind, f, _ in r["eval"] if kind == "sweep")
    n_l = sum(f for kind, f, _ in r["eval"] if kind == "loo")
    sweep = r["wall"] - r["prep"]
    return {"prep": r["prep"], "fit": fit_s, "fit_loo": fit_l, "eval": ev_s, "eval_loo": ev_l,
            "other": sweep - fit_s - fit_l - ev_s - ev_l, "sweep": sweep, "forests": n_s, "forests_loo": n_l}


def project(r: dict, space: str) -> dict:
    """The paper preset's CPU seconds of one space from the slice (module docstring)."""
    from relaff_jax import learn as L
    from relaff_jax.config.experiment import experiment_preset

    p = parts(r)
    cfg = experiment_preset("paper")
    plans = [L.condition_plan(list(L.ACTIONS), t, np.asarray(r["corr"]), cfg, space) for t in range(len(L.ACTIONS))]
    per_size = sum(len({rows for _, rows in pl}) for pl in plans) * cfg.reps(space)  # sweep forests per n
    full_s = per_size * len(cfg.sizes)
    from relaff_jax.learn.protocol import loo_conditions

    cands = loo_conditions(len(L.ACTIONS), len(cfg.thresholds))
    full_l = sum(len({rows for c, rows in pl if c in cands}) for pl in plans) * cfg.select_size * cfg.reps(space)
    by_n: dict[int, list] = {}
    for kind, n, f, s in r["fit"]:
        if kind == "sweep":
            by_n.setdefault(n, [0, 0.0])
            by_n[n][0] += f
            by_n[n][1] += s
    ns = np.asarray(sorted(by_n))
    per = np.asarray([by_n[n][1] / by_n[n][0] for n in ns])
    fit_full = float(np.interp(np.asarray(cfg.sizes), ns, per).sum() * per_size)
    scale_s, scale_l = full_s / p["forests"], full_l / max(p["forests_loo"], 1)
    scale_all = (full_s + full_l) / (p["forests"] + p["forests_loo"])
    return {"prep": p["prep"], "fit": fit_full, "fit_loo": p["fit_loo"] * scale_l, "eval": p["eval"] * scale_s,
            "eval_loo": p["eval_loo"] * scale_l, "other": p["other"] * scale_all, "forests": full_s + full_l}


def main_process(reps: int = 5, rounds: int = 1) -> dict:
    """Seconds of the sweep's main process for the paper's PCA array shape at ``reps`` of its
    50 repetitions (9 targets x 4 blocks per repetition, 52 conditions, 4,000 scenes):
    receiving each block from a worker (pickle round trip), storing it, and packing the
    whole at the end: the reference route (bool outcomes) against the new (packed bits)."""
    import pickle

    rng = np.random.default_rng(0)
    a, c, s, t, chunk = 9, 52, 99, 4000, 25
    blk = rng.random((c, chunk, t)) < 0.7
    bits = np.packbits(blk, axis=-1)
    out = {}
    for name in ("reference", "new"):
        t0 = time.perf_counter()
        if name == "reference":
            whole = np.zeros((a, c, s, reps, t), bool)
        else:
            whole = np.zeros((a, c, s, reps, (t + 7) // 8), np.uint8)
        for ti in range(a):
            for r in range(reps):
                for s0 in range(0, s, chunk):
                    n = min(chunk, s - s0)
                    got = pickle.loads(pickle.dumps(blk if name == "reference" else bits, protocol=5))
                    whole[ti, :, s0:s0 + n, r, :got.shape[-1]] = got[:, :n]
        if name == "reference":
            whole = np.packbits(whole, axis=-1)
        out[name] = time.perf_counter() - t0
        del whole
    return out


def compare(a: Path, b: Path, spaces) -> tuple[int, int]:
    """(equal arrays, arrays) of the two folders' results.npz, prep.npz and block files."""
    same = total = 0
    for s in spaces:
        files = [Path(s) / "results.npz", Path(s) / "prep.npz"] + sorted(p.relative_to(a) for p in (a / s / "blocks").glob("*.npz"))
        for f in files:
            with np.load(a / f) as x, np.load(b / f) as y:
                for k in x.files:
                    if k in SKIP:
                        continue
                    total += 1
                    same += k in y.files and x[k].shape == y[k].shape and np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f")
    return same, total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ref", type=Path, help="checkout of the reference code (run first)")
    ap.add_argument("--new", type=Path, default=HERE, help="checkout of the new code (default: this one)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/relaff_experiment_stage"))
    ap.add_argument("--spaces", nargs="+", default=["pca", "rhf"])
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--main-reps", type=int, default=5, help="repetitions of the main-process emulation (0: skip)")
    ap.add_argument("--render", action="store_true", help="print the tables of the runs saved in --out")
    ap.add_argument("--wall", action="store_true", help="time wall seconds, not the worker's CPU seconds (an idle machine)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        worker(str(a.out), a.spaces, a.samples, a.reps, a.wall)
        return
    import shutil

    versions = ([("reference", a.ref)] if a.ref else []) + [("new", a.new)]
    got = {}
    for name, code in versions:
        out = a.out / name
        saved = a.out / f"{name}.json"
        if a.render:
            got[name] = json.loads(saved.read_text())
            continue
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        got[name] = run_version(code, out, a.spaces, a.samples, a.reps, a.wall)
        saved.write_text(json.dumps(got[name]))
        print(f"{name}: {code}, {time.perf_counter() - t:.0f} s", flush=True)
    cols = ("prep", "fit", "fit_loo", "eval", "eval_loo", "other")
    print(f"\nslice, {'wall' if a.wall else 'CPU'} seconds (one process; load average now {os.getloadavg()[0]:.1f}):")
    print("| version | space | forests | " + " | ".join(cols) + " | sweep | other ms/forest |")
    print("|---|---|---:|" + "---:|" * (len(cols) + 2))
    for name in got:
        for s in a.spaces:
            p = parts(got[name][s])
            n = p["forests"] + p["forests_loo"]
            print(f"| {name} | {s} | {n:.0f} | " + " | ".join(f"{p[c]:.2f}" for c in cols)
                  + f" | {p['sweep']:.2f} | {1e3 * p['other'] / n:.3f} |")
    print("\npaper preset projected, CPU seconds (wall with 2 workers = total / 2):")
    print("| version | space | forests | " + " | ".join(cols) + " | total | wall, 2 workers |")
    print("|---|---|---:|" + "---:|" * (len(cols) + 2))
    totals = {}
    for name in got:
        tot = {c: 0.0 for c in cols}
        for s in a.spaces:
            p = project(got[name][s], s)
            for c in cols:
                tot[c] += p[c]
            t = sum(p[c] for c in cols)
            print(f"| {name} | {s} | {p['forests']:.0f} | " + " | ".join(f"{p[c]:.0f}" for c in cols) + f" | {t:.0f} | {t / 2:.0f} |")
        totals[name] = tot
        t = sum(tot.values())
        print(f"| {name} | all | | " + " | ".join(f"{tot[c]:.0f} ({100 * tot[c] / t:.1f} %)" for c in cols)
              + f" | {t:.0f} | {t / 2:.0f} |")
    if a.ref:
        same, total = compare(a.out / "reference", a.out / "new", a.spaces)
        r, n = totals["reference"], totals["new"]
        print(f"\narrays equal (results.npz, prep.npz, every block file): {same} of {total}")
        print(f"other: new / reference {n['other'] / r['other']:.2f}; whole projection new / reference "
              f"{sum(n.values()) / sum(r.values()):.3f}")
        print(f"identical={same == total}")
        if same != total:
            sys.exit("the new code's results differ from the reference's")
    if a.main_reps and not a.render:
        m = main_process(a.main_reps)
        k = 50 / a.main_reps * 1.5  # to the PCA preset's 50 repetitions, and RHF's half of that
        print(f"\nmain process, the preset's PCA outcome array at {a.main_reps} of 50 repetitions (receive, store, pack): "
              f"reference {m['reference']:.2f} s, new {m['new']:.2f} s ({m['new'] / m['reference']:.2f}); "
              f"both spaces of the preset x{k:g}: reference {m['reference'] * k:.0f} s, new {m['new'] * k:.0f} s of CPU")


if __name__ == "__main__":
    main()
