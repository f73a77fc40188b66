"""``relaff reproduce --status`` from metadata against the reference that reads every chunk.

Usage: python benchmarks/status.py RUN_DIR [--repeats 3] [--keep]

RUN_DIR is copied to a temporary folder (the original is not written); the copy's datasets
get their status manifests (``stages.features.record_fingerprint``, what a run writes when a
dataset's features finish), then ``reproduce.run.status(copy, reference=True)`` (every chunk
read and verified, the path before manifests) and ``status(copy)`` (metadata) are timed in
this process, each after one untimed call (imports and file cache warm), and their states
and reasons compared. Prints one table: best of ``--repeats`` per path and the ratio.
A separate ``python -X importtime`` of each path is the cold-start share (not measured here).
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--keep", action="store_true", help="keep the temporary copy")
    a = ap.parse_args(argv)
    if not (a.run_dir / "run.json").is_file():
        print(f"benchmarks/status.py: error: {a.run_dir} is not a relaff reproduce folder (no run.json)", file=sys.stderr)
        return 2
    import relaff_jax  # noqa: F401 (XLA flags first)
    from relaff_jax.reproduce.run import status
    from relaff_jax.stages.features import record_fingerprint

    tmp = Path(tempfile.mkdtemp(prefix="relaff_status_bench_"))
    try:
        run = tmp / "run"
        shutil.copytree(a.run_dir, run)
        t0 = time.perf_counter()
        data = sorted(p for p in (run / "data").iterdir() if p.is_dir()) if (run / "data").is_dir() else []
        for d in data:
            record_fingerprint(d)
        t_record = time.perf_counter() - t0
        times = {}
        states = {}
        for name, ref in (("reference (every chunk)", True), ("metadata (manifests)", False)):
            states[name] = status(run, reference=ref)  # warm: imports, file cache
            best = float("inf")
            for _ in range(a.repeats):
                t0 = time.perf_counter()
                status(run, reference=ref)
                best = min(best, time.perf_counter() - t0)
            times[name] = best
        (ref_name, ref_t), (new_name, new_t) = times.items()
        same = states[ref_name] == states[new_name]
        print(f"run folder {a.run_dir} ({len(data)} datasets); manifests recorded in {t_record:.2f} s")
        print(f"{'path':26s} {'seconds (best of ' + str(a.repeats) + ')':>24s}")
        print(f"{ref_name:26s} {ref_t:24.3f}")
        print(f"{new_name:26s} {new_t:24.3f}")
        print(f"{'ratio reference/metadata':26s} {ref_t / new_t:24.1f}")
        print("same states and reasons: " + ("yes" if same else "NO"))
        for stage, st in states[new_name].items():
            print(f"  {stage:10s} {st.state:9s} {st.why}")
        return 0 if same else 1
    finally:
        if a.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
