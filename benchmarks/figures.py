"""The measured headline figures, kept once in ``docs/figures.json``.

A record is ``{id, value, unit, shown, what, rests_on: {preset, sizes, machine, date, ...},
source}``: ``value`` in ``unit`` as measured, ``shown`` how prose quotes it (``display``), and
``source`` the command that measures it. The README and the docs pages quote a figure behind
a marker, ``<!-- fig:ID -->`` followed by exactly ``display(record)``;
``tests/docs/test_docs_figures.py`` checks every marker against this file. A benchmark that
measures a figure updates its record with ``--write-figures`` (``write_records``: one atomic
rewrite of the file, other records untouched).

    python benchmarks/figures.py            # the figures as a table
"""
from __future__ import annotations

import re
from pathlib import Path

from relaff_jax import io as rio

FIGURES = Path(__file__).resolve().parent.parent / "docs" / "figures.json"
MARK = re.compile(r"<!-- fig:([a-z0-9_]+) -->")
SHOWN = ("min", "h min", "min s", "s", "plain")


def display(rec: dict) -> str:
    """How prose quotes a record: ``shown`` = ``min`` (seconds as "4.4 minutes"), ``h min``
    ("1 h 32 min"), ``min s`` ("28 min 53 s"), ``s`` ("5,515 s") or ``plain`` (value and unit,
    e.g. "7.0 GB", "579 tests")."""
    v, shown = rec["value"], rec.get("shown", "plain")
    if shown not in SHOWN:
        raise ValueError(f"figure {rec['id']}: shown {shown!r} is not one of {SHOWN}")
    if shown != "plain" and rec["unit"] != "s":
        raise ValueError(f"figure {rec['id']}: shown {shown!r} needs unit 's', not {rec['unit']!r}")
    if shown == "min":
        return f"{v / 60:.1f} minutes"
    if shown == "h min":
        m = int(round(v / 60))
        return f"{m // 60} h {m % 60} min"
    if shown == "min s":
        s = int(round(v))
        return f"{s // 60} min {s % 60} s"
    if shown == "s":
        return f"{v:,.0f} s"
    digits = rec.get("digits")
    num = f"{v:,.{digits}f}" if digits is not None else f"{v:,}"
    return f"{num} {rec['unit']}"


def load(path: Path | None = None) -> dict[str, dict]:
    """The records by id; an id given twice, or a record without its fields, is an error."""
    path = path or FIGURES
    out: dict[str, dict] = {}
    for rec in rio.read_json(path)["figures"]:
        missing = {"id", "value", "unit", "what", "rests_on", "source"} - rec.keys()
        if missing:
            raise ValueError(f"{path}: figure {rec.get('id')!r} lacks {sorted(missing)}")
        if rec["id"] in out:
            raise ValueError(f"{path}: figure {rec['id']!r} given twice")
        display(rec)  # checks `shown`
        out[rec["id"]] = rec
    return out


def write_records(updates: list[dict], path: Path | None = None) -> None:
    """Replace (or add) the records with these ids, keep the others and their order; one
    atomic write (``relaff_jax.io.atomic_write_json``)."""
    path = path or FIGURES
    doc = rio.read_json(path)
    by_id = {r["id"]: r for r in updates}
    for rec in updates:
        display(rec)
    figs = [by_id.pop(r["id"], r) for r in doc["figures"]]
    figs += list(by_id.values())
    doc["figures"] = figs
    rio.atomic_write_json(path, doc)
    for rec in updates:
        print(f"figures: {rec['id']} = {display(rec)} -> {path}")


def machine_line() -> str:
    """The machine as the records state it: architecture, cores, load average now."""
    import os
    import platform

    return f"{platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"


def today() -> str:
    import time

    return time.strftime("%Y-%m-%d", time.gmtime())


def main() -> None:
    for rid, rec in load().items():
        print(f"{rid:<28} {display(rec):<18} {rec['rests_on'].get('date', '-'):<11} {rec['source']}")


if __name__ == "__main__":
    main()
