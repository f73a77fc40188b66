"""Fingerprint of a ``relaff reproduce`` run folder: a sha256 per stored array, to check that
two runs (two code versions, two machines, a resumed and an uninterrupted run) gave the same
bits.

    python benchmarks/fingerprint.py RUN_DIR [--json OUT.json] [--compare OTHER.json]

Hashes every array of every dataset (``relaff_jax.load_dataset``: rollout ids, labels,
states, PCA and RHF features, ...), every array of ``results/<space>/results.npz`` (accuracy
arrays, correlations; not the wall times nor the fits counter ``new_fits``) and
``report/findings.json``. Reads only the public loader and the
stored files, so the same script fingerprints a folder made by an older version. Prints a
table (key, sha256 prefix, and with --compare: same / DIFFERENT / missing).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np


# Counters of the work a run did, not of its results: ``new_fits`` counts the forests fitted by
# the invocation that finished the sweep, so a resumed run (fewer new fits) is not a difference.
RUN_COUNTERS = ("new_fits",)


def _sha(a) -> str:
    a = np.asarray(a)
    if a.dtype.kind in "OU":
        a = np.asarray([str(x) for x in a.ravel()])
        return hashlib.sha256("\x00".join(a.tolist()).encode()).hexdigest()
    return hashlib.sha256(np.ascontiguousarray(a).tobytes() + str(a.dtype).encode() + str(a.shape).encode()).hexdigest()


def fingerprint(run: Path) -> dict[str, str]:
    import relaff_jax

    out: dict[str, str] = {}
    for d in sorted((run / "data").iterdir()):
        if not d.is_dir() or d.name.startswith("."):
            continue
        ds = relaff_jax.load_dataset(d)
        for k in sorted(ds):
            v = ds[k]
            if isinstance(v, np.ndarray):
                out[f"data/{d.name}/{k}"] = _sha(v)
    for npz in sorted((run / "results").glob("*/results.npz")):
        with np.load(npz) as z:
            for k in sorted(z.files):
                if k.startswith("seconds") or k in RUN_COUNTERS:  # wall times and work counters, not results
                    continue
                out[f"results/{npz.parent.name}/{k}"] = _sha(z[k])
    f = run / "report" / "findings.json"
    if f.exists():
        out["report/findings.json"] = hashlib.sha256(
            json.dumps(json.loads(f.read_text())["findings"], sort_keys=True).encode()).hexdigest()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--json", type=Path, help="write the fingerprint (with the machine) here")
    ap.add_argument("--compare", type=Path, help="a fingerprint JSON to compare with")
    args = ap.parse_args(argv)
    fp = fingerprint(args.run)
    other = json.loads(args.compare.read_text())["hashes"] if args.compare else None
    diff = 0
    print(f"{'key':<48} {'sha256':<16} {'vs ' + args.compare.name if other else ''}")
    for k in sorted(set(fp) | set(other or {})):
        mine = fp.get(k)
        verdict = ""
        if other is not None:
            verdict = "same" if other.get(k) == mine else ("missing here" if mine is None else
                                                          "missing there" if k not in other else "DIFFERENT")
            diff += verdict != "same"
        print(f"{k:<48} {(mine or '-')[:16]:<16} {verdict}")
    if other is not None:
        print(f"\n{len(fp)} keys here, {len(other)} there, {diff} differ or are missing")
    if args.json:
        # the CPU model and vector extensions too: XLA's code, and so the bits, depend on them
        from relaff_jax.provenance import machine

        args.json.write_text(json.dumps({"run": str(args.run), "machine": machine(), "hashes": fp},
                                        indent=1) + "\n")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
