"""The compiled engine's fit kernel (``build_forests``) alone, reference code against this
checkout in the same run, interleaved, with the kernel outputs checked bit for bit.

The forests of ``forest_engines.py`` (the sweep's DB1 learners: PCA 18 + 6, RHF 318 + 30
columns; synthetic labels) at sizes ``--sizes``, ``--forests`` per kernel call. Each round
runs every version in its own subprocess (``PYTHONPATH``), the versions' order alternating
from round to round; a subprocess times ``--reps`` kernel calls per cell (after one warm
call) and keeps the fastest by CPU time (``time.process_time``) and by wall time. The table
gives the median over rounds of CPU ms per forest and of the new / reference ratio (the
ratio's spread: min-max over rounds); the outputs' digests must be equal in every round.

    PYTHONPATH=. python benchmarks/forest_fit.py --ref /path/to/reference/checkout [--rounds 5]
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def worker(cells: list[tuple[str, int]], k: int, reps: int) -> None:
    sys.path.insert(0, str(HERE))
    from forest_engines import inputs

    from relaff_jax.config.experiment import ForestConfig
    from relaff_jax.learn.forest.compiled import forest as cf

    kern = cf.kernels()
    build = kern["build_forests"]
    rec: dict = {}

    def timed(*a):
        c, t = time.process_time(), time.perf_counter()
        r = build(*a)
        rec["cpu"], rec["wall"] = time.process_time() - c, time.perf_counter() - t
        rec["digest"] = hashlib.sha256(b"".join(np.ascontiguousarray(x).tobytes() for x in r)).hexdigest()
        return r

    kern["build_forests"] = timed
    cfg = ForestConfig(engine="compiled")
    out = {}
    for space, n in cells:
        fits, _, _ = inputs(space, n, k)
        args = ([f[0] for f in fits], [f[1] for f in fits], [f[2] for f in fits], cfg)
        cf.fit_many(*args)  # warm (kernels loaded or compiled)
        cpu, wall = [], []
        for _ in range(reps):
            cf.fit_many(*args)
            cpu.append(rec["cpu"])
            wall.append(rec["wall"])
        out[f"{space}:{n}"] = {"cpu": min(cpu) / k, "wall": min(wall) / k, "digest": rec["digest"]}
    print("RESULT " + json.dumps(out))


def run(code: Path, cells, k, reps) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--forests", str(k), "--reps", str(reps),
           "--cells", *[f"{s}:{n}" for s, n in cells]]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=str(code))
    if p.returncode:
        sys.exit(f"{code}: worker failed\n{p.stderr[-4000:]}")
    return json.loads([x for x in p.stdout.splitlines() if x.startswith("RESULT ")][-1][len("RESULT "):])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ref", type=Path, help="a checkout of the reference code")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--reps", type=int, default=3, help="kernel calls per cell and subprocess")
    ap.add_argument("--forests", type=int, default=128, help="forests per kernel call")
    ap.add_argument("--sizes", type=int, nargs="+", default=[25, 100])
    ap.add_argument("--spaces", nargs="+", default=["pca", "rhf"])
    ap.add_argument("--worker", action="store_true")
    ap.add_argument("--cells", nargs="+", default=None)
    args = ap.parse_args()
    if args.worker:
        worker([(c.split(":")[0], int(c.split(":")[1])) for c in args.cells], args.forests, args.reps)
        return
    cells = [(s, n) for s in args.spaces for n in args.sizes]
    versions = {"new": HERE.parent} | ({"ref": args.ref.resolve()} if args.ref else {})
    print(f"# fit kernel, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average before "
          f"{os.getloadavg()[0]:.2f}; {args.rounds} rounds x {args.reps} calls of {args.forests} forests per cell")
    res: dict = {v: [] for v in versions}
    for r in range(args.rounds):
        order = list(versions) if r % 2 == 0 else list(versions)[::-1]
        for v in order:
            res[v].append(run(versions[v], cells, args.forests, args.reps))
        if "ref" in res:
            for c in res["new"][-1]:
                if res["new"][-1][c]["digest"] != res["ref"][-1][c]["digest"]:
                    sys.exit(f"round {r}: {c}: the kernels' outputs differ")
        print(f"# round {r + 1} done, load average {os.getloadavg()[0]:.2f}", flush=True)
    print()
    print("| space | n | ref CPU ms | new CPU ms | new / ref CPU (min-max) | ref wall ms | new wall ms | new / ref wall |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for s, n in cells:
        c = f"{s}:{n}"
        med = {v: {q: 1e3 * float(np.median([x[c][q] for x in res[v]])) for q in ("cpu", "wall")} for v in versions}
        if "ref" not in res:
            print(f"| {s.upper()} | {n} | | {med['new']['cpu']:.3f} | | | {med['new']['wall']:.3f} | |")
            continue
        rc = [a[c]["cpu"] / b[c]["cpu"] for a, b in zip(res["new"], res["ref"])]
        rw = [a[c]["wall"] / b[c]["wall"] for a, b in zip(res["new"], res["ref"])]
        print(f"| {s.upper()} | {n} | {med['ref']['cpu']:.3f} | {med['new']['cpu']:.3f} | {np.median(rc):.3f} "
              f"({min(rc):.3f}-{max(rc):.3f}) | {med['ref']['wall']:.3f} | {med['new']['wall']:.3f} | {np.median(rw):.3f} |")
    print()
    print(f"load average after {os.getloadavg()[0]:.2f}; outputs bit-identical in every round" if "ref" in res else "")


if __name__ == "__main__":
    main()
