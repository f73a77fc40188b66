"""A reproduce run's measured time, read from its run log (``DIR/run.json``).

    python benchmarks/run_times.py RUN_DIR [--write-figures ID]

Prints every invocation of the run log: when it started, its wall seconds, each stage's
status and seconds, and the rollouts its generate stage made with their rate. The figure of a run is its last invocation that ran every stage
(``status`` "ran") in one stretch; ``--write-figures ID`` writes that invocation's wall
seconds and stage seconds (a record in labelled rollouts/s: the generate stage's rate) into
record ID of ``docs/figures.json`` (keeping the record's
description, replacing its value, stages, date and machine; a new ID needs a record made by
hand first, which says what the figure rests on).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import figures  # noqa: E402


def invocations(run: Path) -> list[dict]:
    """The run log's invocations, each ``{started, seconds, stages: {stage: (status, s)},
    rollouts}`` (``rollouts``: summed over the actions the generate stage ran)."""
    log = json.loads((run / "run.json").read_text())
    out = []
    for r in log.get("runs", []):
        stages = {k: (v.get("status"), float(v.get("seconds") or 0.0)) for k, v in r.get("stages", {}).items()}
        gen = r.get("stages", {}).get("generate", {}).get("actions") or {}
        rollouts = sum(int(a.get("rollouts") or 0) for a in gen.values() if a.get("status") == "ran")
        out.append({"started": r.get("started"), "seconds": r.get("seconds"), "stages": stages, "rollouts": rollouts,
                    "machine": r.get("machine") or log.get("machine"), "preset": log.get("preset")})
    return out


def machine_text(m: dict | None) -> str:
    """The run log's machine (``provenance.machine``) as one line: architecture, CPU, cores."""
    if not m:
        return "not recorded"
    return f"{m.get('machine')}, {m.get('cpu_model') or 'CPU ?'}, {m.get('cpus')} cores"


def rate(inv: dict) -> float:
    """Labelled rollouts per second of an invocation's generate stage (NaN if none ran)."""
    status, sec = inv["stages"].get("generate", (None, 0.0))
    return inv["rollouts"] / sec if status == "ran" and sec > 0 and inv["rollouts"] else float("nan")


def whole(invs: list[dict]) -> dict | None:
    """The last invocation in which every stage ran (one stretch), or None."""
    full = [i for i in invs if i["stages"] and all(s == "ran" for s, _ in i["stages"].values())
            and i["seconds"] is not None]
    return full[-1] if full else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a relaff reproduce output folder")
    ap.add_argument("--write-figures", metavar="ID", help="update figure ID of docs/figures.json")
    args = ap.parse_args(argv)
    if not (args.run / "run.json").is_file():
        print(f"run_times: error: {args.run}/run.json not found", file=sys.stderr)
        return 2
    invs = invocations(args.run)
    print("| started | wall s | stages (status s) | rollouts generated | labelled rollouts/s |\n|---|---:|---|---:|---:|")
    for i in invs:
        st = ", ".join(f"{k} {s} {v:.0f}" for k, (s, v) in i["stages"].items())
        print(f"| {i['started']} | {i['seconds'] or float('nan'):.0f} | {st} | {i['rollouts']} | {rate(i):.1f} |")
    best = whole(invs)
    if args.write_figures:
        if best is None:
            print("run_times: error: no invocation ran every stage in one stretch", file=sys.stderr)
            return 2
        recs = figures.load()
        if args.write_figures not in recs:
            print(f"run_times: error: no figure {args.write_figures!r} in {figures.FIGURES} "
                  f"(add its record by hand first)", file=sys.stderr)
            return 2
        rec = dict(recs[args.write_figures])
        if rec["unit"] == "labelled rollouts/s":  # the generate stage's rate, not a time
            rec["value"] = round(rate(best))
        else:
            rec.update(value=round(float(best["seconds"])), stages_s={k: round(v) for k, (_, v) in best["stages"].items()})
        rec["rests_on"] = dict(rec["rests_on"], date=str(best["started"])[:10], machine=machine_text(best["machine"]))
        figures.write_records([rec])
    return 0


if __name__ == "__main__":
    sys.exit(main())
