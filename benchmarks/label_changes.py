"""How two runs' datasets differ, rollout by rollout: what a change of the motor programs does
to the labels on the same placements.

Takes two run folders (``relaff reproduce --out``, each with ``data/<action>/``) made with the
same seeds and batch, so that rollout ``i`` of an action is the same placement and settle in
both; prints two markdown tables: per action the rollouts, executed programs, the positive
rate among them, the borrowed share and the refused unsettled rollouts of each run; and, over
the rollouts both runs hold, the programs each executed, the labels that changed among those
both executed (to positive / to negative) and by relation. ``--json FILE`` writes the numbers.

    python benchmarks/label_changes.py /work/runs/paper_v3 /work/runs/paper_v4
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from relaff_jax.constants import ACTIONS, RELATIONS  # noqa: E402
from relaff_jax.data.load import load_rollouts  # noqa: E402
from relaff_jax.data.store import read_sidecar  # noqa: E402


def compare_action(a: dict, b: dict) -> dict:
    """Numbers of one action from two ``load_rollouts`` dicts (the same rollout ids first)."""
    n = min(len(a["label"]), len(b["label"]))
    if not np.array_equal(np.asarray(a["rollout"][:n]), np.asarray(b["rollout"][:n])):
        raise SystemExit("the two datasets' rollout ids differ: not the same seeds and batch")
    fa, fb = (np.asarray(r.get("feasible", np.ones(len(r["label"]), bool))[:n], bool) for r in (a, b))
    la, lb = (np.asarray(r["label"][:n], bool) for r in (a, b))
    rel = np.asarray(b["relation"][:n]).astype(str)
    both = fa & fb
    up, down = both & ~la & lb, both & la & ~lb
    return {"common": n, "executed": [int(fa.sum()), int(fb.sum())], "both": int(both.sum()),
            "to_positive": int(up.sum()), "to_negative": int(down.sum()),
            "by_relation": {k: int(((up | down) & (rel == k)).sum()) for k in RELATIONS}}


def summary(r: dict, meta: dict) -> dict:
    f = np.asarray(r.get("feasible", np.ones(len(r["label"]), bool)), bool)
    lab = np.asarray(r["label"], bool)
    sel = meta.get("selection", {})
    return {"rollouts": len(lab), "executed": int(f.sum()),
            "positive_rate_executed": float(lab[f].mean()) if f.any() else None,
            "borrowed_share": sel.get("borrowed_share"), "unsettled_refused": sel.get("unsettled_refused")}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_a", type=Path)
    p.add_argument("run_b", type=Path)
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    acts = [x for x in ACTIONS if (args.run_a / "data" / x).is_dir() and (args.run_b / "data" / x).is_dir()]
    if not acts:
        raise SystemExit(f"no action has a dataset in both {args.run_a}/data and {args.run_b}/data")
    out = {}
    for x in acts:
        ra, rb = (load_rollouts(r / "data" / x) for r in (args.run_a, args.run_b))
        ma, mb = (read_sidecar(r / "data" / x) for r in (args.run_a, args.run_b))
        out[x] = {"a": summary(ra, ma), "b": summary(rb, mb), "same_placements": compare_action(ra, rb)}
    pct = lambda v: "-" if v is None else f"{v:.1%}"
    cnt = lambda v: "-" if v is None else str(v)  # "-": not recorded (made before the setting) or not known
    print(f"a = {args.run_a}, b = {args.run_b}\n")
    print("| action | rollouts a -> b | executed a -> b | positives among executed a -> b | borrowed a -> b "
          "| refused unsettled a / b |")
    print("|---|---|---|---|---|---|")
    for x, d in out.items():
        a, b = d["a"], d["b"]
        print(f"| {x} | {a['rollouts']:,} -> {b['rollouts']:,} | {a['executed']:,} -> {b['executed']:,} | "
              f"{pct(a['positive_rate_executed'])} -> {pct(b['positive_rate_executed'])} | "
              f"{pct(a['borrowed_share'])} -> {pct(b['borrowed_share'])} | {cnt(a['unsettled_refused'])} / {cnt(b['unsettled_refused'])} |")
    print("\nOn the rollouts both hold (the same placements):\n")
    print("| action | rollouts | executed a -> b | executed by both | labels changed (to positive / to negative) "
          "| by relation: " + " / ".join(RELATIONS) + " |")
    print("|---|---:|---|---:|---|---|")
    for x, d in out.items():
        s = d["same_placements"]
        print(f"| {x} | {s['common']:,} | {s['executed'][0]:,} -> {s['executed'][1]:,} | {s['both']:,} | "
              f"{s['to_positive'] + s['to_negative']} ({s['to_positive']} / {s['to_negative']}) | "
              + " / ".join(str(s["by_relation"][k]) for k in RELATIONS) + " |")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
