"""Audited rollouts of a dataset replayed with another programs version, in MuJoCo C.

Usage: python benchmarks/replay_programs.py DATASET:ID[,ID...] [...] [--programs v3] [--json OUT]
       python benchmarks/replay_programs.py DATASET:audited [...] (every rollout of DATASET/audit.json;
       prints only the summary)

For each listed rollout: the dataset's scene (its placement, re-settled in C as ``relaff audit``
does: the settle does not depend on the programs), planned with the dataset's action settings
except ``programs``, replayed with the audit's probe (``data.audit_replay.replay_probed``) and
checked as the audit checks (``data.audit.failures``). Prints per rollout the stored and the
new plan's palm contact from above (steps, N), the held press (N, weights), the held
penetration (mm), the label and which checks fail; a program the new version refuses at plan
time is shown as refused (counted infeasible, as an unreachable target). The audit's code is
used unchanged; only the configuration differs.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import relaff_jax  # noqa: F401 (XLA flags)
import numpy as np

from relaff_jax.constants import action_id
from relaff_jax.data import audit as AU
from relaff_jax.data.audit_replay import replay_probed
from relaff_jax.data.load import load_rollouts
from relaff_jax.data.store import read_sidecar
from relaff_jax.sim.actions.tables import tables

NEED = ("pair", "qpos0", "qpos_settled", "intended", "label", "feasible", "relation", "toy", "other", "rollout")


def replay(path: str, ids: list[int], programs: str) -> list[dict]:
    meta = read_sidecar(Path(path))
    cfg = dataclasses.replace(AU.action_config(meta), programs=programs)
    action = str(meta["action"])
    r = load_rollouts(path)
    idx = np.array([int(np.flatnonzero(np.asarray(r["rollout"]) == i)[0]) for i in ids])
    rr = {k: np.asarray(r[k])[idx] for k in NEED}
    qvel, same = AU.settled_velocities(cfg, meta, rr, None)
    plan = AU._plan(cfg, action, rr["pair"], rr["qpos_settled"], int(meta["batch"]))
    measure = int(tables(cfg).measure[action_id(action)])  # the replayed version's (v3: rake's dwell)
    rep, got = replay_probed(meta, cfg, action, rr["pair"], rr["qpos_settled"], qvel, plan, measure, 1)
    rows = []
    for b, i in enumerate(ids):
        row = {k: (v[b].item() if hasattr(v[b], "item") else v[b]) for k, v in got.items()}
        row.update(rollout=i, toy=str(rr["toy"][b]), other=str(rr["other"][b]), resettled=bool(same[b]),
                   feasible=bool(plan["feasible"][b]), label=bool(rep["label"][b]), stored_label=bool(rr["label"][b]))
        row["fails"] = [k for k, v in AU.failures(row).items() if v] if row["feasible"] else []
        rows.append(row)
    return rows


def summary(name: str, programs: str, rows: list[dict], old: dict) -> None:
    """One line per dataset: refused, failing per check (the audit's), label changes."""
    ran = [r for r in rows if r["feasible"]]
    fails = {k: sum(k in r["fails"] for r in ran) for k in ("palm_contact", "force", "penetration", "moving")}
    was = {k: sum(AU.failures(old[r["rollout"]])[k] for r in rows if r["rollout"] in old) for k in fails}
    flips = sum(r["label"] != r["stored_label"] for r in ran)
    press = max((r["press_n"] / r["weight_n"] for r in ran), default=float("nan"))
    print(f"# {name}: {len(rows)} rollouts, {programs}: {len(rows) - len(ran)} refused at plan time; failing "
          f"(palm above / force / penetration / moving) {' / '.join(str(v) for v in fails.values())} "
          f"(stored: {' / '.join(str(v) for v in was.values())}); press/weight max {press:.1f}; "
          f"labels changed {flips} of {len(ran)} ({sum(r['label'] and not r['stored_label'] for r in ran)} to positive)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="+", help="DATASET:ID[,ID...]")
    ap.add_argument("--programs", default="v3")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    out = []
    print(f"| dataset | rollout | toy / other | stored: palm above steps, N / press N / pen. mm / fails | "
          f"{a.programs}: feasible | palm above steps, N | press N (weights) | held pen. mm | label (stored) | fails |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for spec in a.specs:
        path, ids = spec.rsplit(":", 1)
        audit = json.loads((Path(path) / "audit.json").read_text()) if (Path(path) / "audit.json").exists() else None
        old = {r["rollout"]: r for r in audit["rollouts"]} if audit else {}
        every = ids == "audited"
        ids = sorted(old) if every else [int(x) for x in ids.split(",")]
        rows = replay(path, ids, a.programs)
        summary(Path(path).name, a.programs, rows, old)
        for row in rows:
            out.append(dict(dataset=path, **{k: v for k, v in row.items() if not isinstance(v, np.ndarray)}))
            if every and not row["fails"]:
                continue
            o = old.get(row["rollout"])
            was = "-" if o is None else (f"{o['palm_top_steps']}, {o['palm_top_force_n']:.1f} / {o['press_n']:.1f} / "
                                         f"{1000 * AU._held_depth(o):.1f} / {'+'.join(k for k, v in AU.failures(o).items() if v) or 'none'}")
            if row["feasible"]:
                new = (f"yes | {row['palm_top_steps']}, {row['palm_top_force_n']:.1f} | {row['press_n']:.1f} "
                       f"({row['press_n'] / row['weight_n']:.1f}) | {1000 * AU._held_depth(row):.1f} | "
                       f"{row['label']} ({row['stored_label']}) | {'+'.join(row['fails']) or 'none'}")
            else:
                new = f"refused at plan time | - | - | - | {row['label']} ({row['stored_label']}) | none"
            print(f"| {Path(path).name} | {row['rollout']} | {row['toy']} / {row['other']} | {was} | {new} |", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
