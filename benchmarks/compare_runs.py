"""Two ``relaff reproduce`` run folders compared array by array, stage by stage: where the bits
part, if they do.

    python benchmarks/compare_runs.py OLD NEW [--keys] [--json OUT.json]

Beyond ``fingerprint.py`` (one hash per key), this reads both folders and compares every
key with ``np.array_equal`` (NaN equal to NaN; strings as text), so it names how many
elements differ and by how much, and it orders the stages:

* generate/ACTION: every stored rollout (``relaff_jax.data.load_rollouts``: labels, poses,
  relations, IK errors, ``selected``) and ``selection.json``;
* features/ACTION: the attached features (``load_dataset``'s arrays that are not rollout
  fields: ``pca``, ``rhf``, ``unseen``, ...);
* experiment/SPACE: ``experiment.json``'s data fingerprints and pools, ``prep.npz`` (source
  predictors' outputs, correlations) and ``results.npz`` (accuracies per target, condition,
  size and repetition, leave-one-out, the per-scene outcomes ``correct``), not the wall times
  nor the fits counter ``new_fits``;
* report: every leaf of ``findings.json``'s findings (by id), ``summary.json`` and
  ``reach.json``, every cell of ``table2.csv``, ``table2_rhf.csv`` and ``affordances.csv``.

Prints one row per stage and item (keys compared, equal, differing, only in one folder) and
the first stage where a compared key differs. Keys only in one folder (a field added later)
are listed, not counted as differences. Reads only the public loaders and the stored files,
so a folder made by an older version compares too. Exit status 1 when a compared key
differs or an item exists on one side only, else 0.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path
from typing import Any, Iterator

import numpy as np

STAGES = ("generate", "features", "experiment", "report")
# wall times, work counters and where the run happened: not results
SKIP_NPZ = ("new_fits",)
REPORT_CSV = ("table2.csv", "table2_rhf.csv", "affordances.csv")


def same(a: Any, b: Any) -> tuple[bool, str]:
    """Whether two arrays hold the same values (NaN = NaN, strings as text); a short reason if not."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False, f"shape {a.shape} vs {b.shape}"
    if a.dtype.kind in "USO" or b.dtype.kind in "USO":
        sa, sb = a.astype(str), b.astype(str)
        n = int(np.sum(sa != sb))
        return n == 0, f"{n} of {a.size} differ"
    if a.dtype != b.dtype:
        return False, f"dtype {a.dtype} vs {b.dtype}"
    nan = a.dtype.kind in "fc"
    if np.array_equal(a, b, equal_nan=nan):
        return True, ""
    bad = ~((a == b) | (np.isnan(a) & np.isnan(b))) if nan else a != b
    why = f"{int(bad.sum())} of {a.size} differ"
    if a.dtype.kind in "fiu" and bad.any():
        d = np.abs(a.astype(np.float64) - b.astype(np.float64))[bad]
        why += f", max |diff| {np.nanmax(d) if np.isfinite(d).any() else np.nan:.3g}"
    return False, why


def compare_maps(old: dict, new: dict) -> dict:
    """``{equal: [...], differ: [(key, why)], only_old: [...], only_new: [...]}`` of two key -> array maps."""
    out = {"equal": [], "differ": [], "only_old": sorted(set(old) - set(new)), "only_new": sorted(set(new) - set(old))}
    for k in sorted(set(old) & set(new)):
        ok, why = same(old[k], new[k])
        if ok:
            out["equal"].append(k)
        else:
            out["differ"].append((k, why))
    return out


def _leaves(x: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(x, dict):
        for k in sorted(x):
            yield from _leaves(x[k], f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{prefix}[{i}]")
    elif isinstance(x, (int, float)) and not isinstance(x, bool):
        yield prefix, float(x)  # 1 and 1.0 are one number in JSON
    else:
        yield prefix, np.nan if x is None else x  # the report writes NaN as null


def json_leaves(x: Any) -> dict[str, Any]:
    """Every leaf of a JSON value as ``{dotted.path[i]: value}``."""
    return dict(_leaves(x))


def csv_cells(path: Path) -> dict[str, str]:
    rows = list(csv.reader(io.StringIO(path.read_text())))
    return {f"r{i}c{j}": v for i, row in enumerate(rows) for j, v in enumerate(row)}


def npz_arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files if not k.startswith("seconds") and k not in SKIP_NPZ}


def _datasets(run: Path) -> list[str]:
    d = run / "data"
    return sorted(p.name for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")) if d.is_dir() else []


def _dataset_items(run: Path, action: str) -> dict[str, dict[str, Any] | None]:
    """``{generate: arrays, features: arrays}`` of one dataset (None where not finished); a
    damaged or foreign folder raises the loaders' ``DatasetError``."""
    from relaff_jax.data import load_dataset, load_rollouts
    from relaff_jax.data.store import read_sidecar

    path = run / "data" / action
    if read_sidecar(path)["status"] != "complete":  # still generating: a prefix, not a dataset
        return {"generate": None, "features": None}
    rolls = dict(load_rollouts(path))
    rolls["selection.json"] = np.asarray(json.loads((path / "selection.json").read_text())["selected"])
    feats = {k: v for k, v in load_dataset(path).items() if k not in rolls and isinstance(v, np.ndarray)}
    return {"generate": rolls, "features": feats or None}


def _experiment_items(run: Path) -> dict[str, dict[str, Any] | None]:
    res = run / "results"
    items: dict[str, dict[str, Any] | None] = {}
    meta = res / "experiment.json"
    if meta.exists():
        m = json.loads(meta.read_text())
        items["experiment.json"] = json_leaves({k: m.get(k) for k in ("actions", "seed", "spaces", "fingerprint",
                                                                     "pool_sizes")})
    for space in sorted(p.name for p in res.iterdir() if p.is_dir()) if res.is_dir() else []:
        for name in ("prep", "results"):
            f = res / space / f"{name}.npz"
            items[f"{space}/{name}.npz"] = npz_arrays(f) if f.exists() else None
    return items


def _report_items(run: Path) -> dict[str, dict[str, Any] | None]:
    rep = run / "report"
    items: dict[str, dict[str, Any] | None] = {}
    if not rep.is_dir():
        return items
    f = rep / "findings.json"
    # keyed by the finding's id, so a finding added or dropped does not shift the others
    items["findings.json"] = (json_leaves({x.get("id", str(i)): x for i, x in enumerate(
        json.loads(f.read_text())["findings"])}) if f.exists() else None)
    for name in ("summary.json", "reach.json"):
        f = rep / name
        items[name] = json_leaves(json.loads(f.read_text())) if f.exists() else None
    for name in REPORT_CSV:
        f = rep / name
        items[name] = csv_cells(f) if f.exists() else None
    return items


def items_of(run: Path) -> dict[tuple[str, str], dict[str, Any] | None]:
    """``{(stage, item): {key: value} or None}`` of a run folder."""
    out: dict[tuple[str, str], dict[str, Any] | None] = {}
    for a in _datasets(run):
        for stage, arrays in _dataset_items(run, a).items():
            out[(stage, a)] = arrays
    out.update({("experiment", k): v for k, v in _experiment_items(run).items()})
    out.update({("report", k): v for k, v in _report_items(run).items()})
    return out


def compare_runs(old: Path, new: Path) -> list[dict]:
    """One row per (stage, item) present in either folder, in stage order."""
    a, b = items_of(old), items_of(new)
    rows = []
    for stage, item in sorted(set(a) | set(b), key=lambda si: (STAGES.index(si[0]), si[1])):
        x, y = a.get((stage, item)), b.get((stage, item))
        row = {"stage": stage, "item": item}
        if x is None and y is None:
            row["unfinished"] = True  # neither run has finished it: nothing to compare
        elif x is None or y is None:
            row["missing"] = "old" if x is None else "new"
        else:
            row.update(compare_maps(x, y))
        rows.append(row)
    return rows


def first_difference(rows: list[dict]) -> dict | None:
    return next((r for r in rows if r.get("differ") or "missing" in r), None)


def _few(keys: list[str], most: int = 3) -> str:
    """Up to ``most`` key names, then how many more."""
    if not keys:
        return "-"
    return ", ".join(keys[:most]) + (f" and {len(keys) - most} more" if len(keys) > most else "")


def table(rows: list[dict], keys: bool = False) -> str:
    head = f"| {'stage':<10} | {'item':<18} | {'compared':>8} | {'equal':>6} | {'differ':>6} | only old | only new |"
    lines = [head, "|" + "|".join("-" * (len(c)) for c in head.split("|")[1:-1]) + "|"]
    for r in rows:
        if r.get("unfinished"):
            lines.append(f"| {r['stage']:<10} | {r['item']:<18} | {'-':>8} | {'-':>6} | {'-':>6} | "
                         "unfinished in both | |")
            continue
        if "missing" in r:
            lines.append(f"| {r['stage']:<10} | {r['item']:<18} | {'-':>8} | {'-':>6} | {'-':>6} | "
                         f"missing in {r['missing']} | |")
            continue
        n = len(r["equal"]) + len(r["differ"])
        lines.append(f"| {r['stage']:<10} | {r['item']:<18} | {n:>8} | {len(r['equal']):>6} | {len(r['differ']):>6} | "
                     f"{_few(r['only_old'])} | {_few(r['only_new'])} |")
    out = "\n".join(lines)
    details = [f"  {r['stage']}/{r['item']}: {k}: {why}" for r in rows for k, why in r.get("differ", ())]
    if keys:
        details += [f"  {r['stage']}/{r['item']}: {k}: equal" for r in rows for k in r.get("equal", ())]
        details += [f"  {r['stage']}/{r['item']}: {k}: only in {side}" for r in rows for side in ("old", "new")
                    for k in r.get(f"only_{side}", ())]
    if details:
        out += "\n\nkeys:\n" + "\n".join(details)
    first = first_difference(rows)
    out += "\n\n" + ("every compared key is equal" if first is None else
                     f"first difference: {first['stage']} ({first['item']})")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--keys", action="store_true", help="list the equal keys and those only in one folder too")
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args(argv)
    for p in (args.old, args.new):
        if not (p / "data").is_dir() and not (p / "results").is_dir():
            print(f"compare_runs: error: {p} is not a run folder (no data/ nor results/)", file=sys.stderr)
            return 2
    from relaff_jax.errors import UserError

    try:
        rows = compare_runs(args.old, args.new)
    except (UserError, OSError, ValueError, KeyError) as e:  # a damaged folder: one line, no table
        print(f"compare_runs: error: {e}", file=sys.stderr)
        return 2
    print(f"old: {args.old}\nnew: {args.new}\n")
    print(table(rows, args.keys))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str) + "\n")
    return 1 if first_difference(rows) else 0


if __name__ == "__main__":
    sys.exit(main())
