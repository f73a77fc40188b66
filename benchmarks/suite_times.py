"""Where the test suite's time goes: the per-test record of ``RELAFF_TEST_TIMES`` as tables.

    RELAFF_TEST_TIMES=/tmp/times.json python -m pytest -q -n 2 --dist loadfile
    python benchmarks/suite_times.py /tmp/times.json [--top 25] [--by folder|file] [--against OLD.json]

The record (tests/helpers/times.py) holds each test's wall seconds, the CPU seconds of its
process (every thread of the pytest process or xdist worker) and of the child processes it
waited for. CPU seconds are what a test costs whatever else runs on the machine; wall seconds
on a loaded machine are inflated by the load. A run still going is read from its part files.

Prints: the session (wall from start to end, the tests' summed wall and CPU, each worker's
busy time, the load average at both ends); one row per folder (or file) with its share; the
slowest tests by CPU seconds; where a record has them, JAX's tracing, lowering and compile (or
cache load) seconds in the test processes, and the functions whose traces cost most. ``--against OLD.json`` puts another run's folders beside these,
CPU and wall, with the ratio new/old.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path


def load(path: Path) -> dict:
    """The merged record, or, while the run goes on, the tests of its part files."""
    if path.exists():
        return json.loads(path.read_text())
    rows = []
    for part in sorted(path.parent.glob(f"{path.name}.*.jsonl")):
        for line in part.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:  # a line being written
                pass
    if not rows:
        raise SystemExit(f"suite_times: error: no record at {path} (nor its part files)")
    return {"tests": rows, "running": True}


def key_of(nodeid: str, by: str) -> str:
    """A test's folder (``tests/sim``) or file."""
    path = nodeid.split("::", 1)[0]
    return path.rsplit("/", 1)[0] if by == "folder" else path


def totals(tests: list[dict], by: str) -> dict[str, dict]:
    """key -> {n, wall, cpu, kids} summed over its tests."""
    out: dict[str, dict] = defaultdict(lambda: {"n": 0, "wall": 0.0, "cpu": 0.0, "kids": 0.0})
    for t in tests:
        row = out[key_of(t["nodeid"], by)]
        row["n"] += 1
        row["wall"] += t["wall_s"]
        row["cpu"] += t["cpu_s"]
        row["kids"] += t["children_cpu_s"]
    return dict(out)


def session_lines(rec: dict) -> list[str]:
    tests = rec["tests"]
    wall, cpu, kids = (sum(t[k] for t in tests) for k in ("wall_s", "cpu_s", "children_cpu_s"))
    lines = [f"tests {len(tests)} ({sum(t['slow'] for t in tests)} slow), failed "
             f"{sum(t['outcome'] == 'failed' for t in tests)}, skipped {sum(t['outcome'] == 'skipped' for t in tests)}"
             + ("; the run is still going" if rec.get("running") else "")]
    if "started" in rec and "finished" in rec:
        span = rec["finished"] - rec["started"]
        lines.append(f"session wall {span:.0f} s, workers {rec.get('workers') or 1}, cpus {rec.get('cpus')}, "
                     f"load average {rec['load_start'][0]:.1f} at start, {rec['load_end'][0]:.1f} at end")
    lines.append(f"summed over the tests: wall {wall:.0f} s, CPU {cpu:.0f} s in the test processes "
                 f"+ {kids:.0f} s in their children = {cpu + kids:.0f} s")
    busy = defaultdict(float)
    for t in tests:
        busy[t["worker"]] += t["wall_s"]
    lines.append("busy wall per worker: " + ", ".join(f"{w} {s:.0f} s" for w, s in sorted(busy.items())))
    return lines


def table_by(tests: list[dict], by: str) -> list[str]:
    rows = totals(tests, by)
    cpu_all = sum(r["cpu"] + r["kids"] for r in rows.values()) or 1.0
    lines = [f"| {by} | tests | wall s | CPU s | children CPU s | share of CPU |", "|---|---:|---:|---:|---:|---:|"]
    for k, r in sorted(rows.items(), key=lambda kv: -(kv[1]["cpu"] + kv[1]["kids"])):
        lines.append(f"| {k} | {r['n']} | {r['wall']:.1f} | {r['cpu']:.1f} | {r['kids']:.1f} | "
                     f"{100 * (r['cpu'] + r['kids']) / cpu_all:.1f} % |")
    return lines


def table_slowest(tests: list[dict], top: int) -> list[str]:
    lines = ["| test | worker | wall s | CPU s | children CPU s | CPU / wall |", "|---|---|---:|---:|---:|---:|"]
    for t in sorted(tests, key=lambda t: -(t["cpu_s"] + t["children_cpu_s"]))[:top]:
        c = t["cpu_s"] + t["children_cpu_s"]
        lines.append(f"| {t['nodeid']} | {t['worker']} | {t['wall_s']:.1f} | {t['cpu_s']:.1f} | "
                     f"{t['children_cpu_s']:.1f} | {c / t['wall_s'] if t['wall_s'] > 0 else 0:.2f} |")
    return lines


def table_against(new: list[dict], old: list[dict], by: str) -> list[str]:
    a, b = totals(new, by), totals(old, by)
    lines = [f"| {by} | CPU s old | CPU s new | new/old | wall s old | wall s new | new/old |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for k in sorted(set(a) | set(b)):
        ra, rb = a.get(k), b.get(k)
        ca, cb = (r["cpu"] + r["kids"] if r else 0.0 for r in (ra, rb))
        wa, wb = (r["wall"] if r else 0.0 for r in (ra, rb))
        lines.append(f"| {k} | {cb:.1f} | {ca:.1f} | {ca / cb if cb else float('nan'):.2f} | "
                     f"{wb:.1f} | {wa:.1f} | {wa / wb if wb else float('nan'):.2f} |")
    return lines


def table_jax(tests: list[dict], top: int) -> list[str]:
    """JAX's seconds in the test processes (absent from records made before they were kept)."""
    if not any("jax_trace_s" in t for t in tests):
        return []
    sums = {k: sum(t.get(k, 0.0) for t in tests) for k in ("jax_trace_s", "jax_lower_s", "jax_compile_s")}
    lines = [f"JAX in the test processes: tracing {sums['jax_trace_s']:.0f} s, lowering {sums['jax_lower_s']:.0f} s, "
             f"compile or cache load {sums['jax_compile_s']:.0f} s (wall)", "",
             "| traced function | traces over 1 s | seconds | tests tracing it most |", "|---|---:|---:|---|"]
    by: dict[str, list] = defaultdict(list)
    for t in tests:
        for name, s in t.get("traced", {}).items():
            by[name].append((s, t["nodeid"]))
    for name, hits in sorted(by.items(), key=lambda kv: -sum(s for s, _ in kv[1]))[:top]:
        most = ", ".join(n.split("::", 1)[-1] for _, n in sorted(hits, reverse=True)[:3])
        lines.append(f"| {name} | {len(hits)} | {sum(s for s, _ in hits):.1f} | {most} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("record", type=Path, help="the RELAFF_TEST_TIMES file")
    p.add_argument("--top", type=int, default=25, help="slowest tests listed (default 25)")
    p.add_argument("--by", choices=("folder", "file"), default="folder")
    p.add_argument("--against", type=Path, help="another run's record, compared by folder/file")
    args = p.parse_args(argv)
    if args.top < 0:
        p.error(f"--top must be >= 0, got {args.top}")
    rec = load(args.record)
    out = session_lines(rec) + [""] + table_by(rec["tests"], args.by) + [""] + table_slowest(rec["tests"], args.top)
    jax_lines = table_jax(rec["tests"], args.top)
    if jax_lines:
        out += [""] + jax_lines
    if args.against is not None:
        out += ["", f"against {args.against}:"] + table_against(rec["tests"], load(args.against)["tests"], args.by)
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
