"""MJX against MuJoCo C (the native engine) on today's programs: label agreement per action.

    python benchmarks/engine_agreement.py N [ACTION ...] [--seed S] [--batch B] [--json OUT]
        [--set action.programs=v2 ...] [--no-compile-cache]

Per action, prepared batches of B scenes (``rollouts.make_batch_prepare_fn``, settled in C so
that no MJX settle is compiled; keys ``rollouts.bench_batch_key(seed, B, i)``) until at least
N programs are feasible; every feasible program is executed by both engines with the
``ActionConfig`` of the defaults plus ``--set`` (e.g. ``action.programs=v1``): MJX
(``simulate.make_simulate_fn``, calls of 16, one compile for all actions) and the native
engine (``native.batch.execute_native``, the C reference bit for bit). Both engines run the
same settled scenes and the same plans (the shared JAX planner). Prints the agreement on the
feasible programs and, for every scene whose labels differ, the pair, the settled relation,
both labels and the quantities the outcome rule reads in each engine
(``disagreements.quantities``, cm: toy, other) with the first-guess class of
``disagreements.classify``. ``--json`` keeps finished actions (a rerun with the same setting
skips them).

The JAX programs (the plan in calls of ``reach_screen.PLAN_CHUNK``, the placement, MJX's
simulate at 16 scenes) go through the persistent compilation cache as the ``relaff`` command
does (``compile_cache.configure``; ``RELAFF_COMPILE_CACHE``): a planner the command compiled
with the same config is loaded, not compiled again (a compile takes minutes on a loaded
machine). Each action's line ends with the seconds of its stages (first calls include their
compiles): where the time goes, not a speed claim.
"""
from __future__ import annotations

import argparse
import os
import time

if __name__ == "__main__":  # before jaxlib loads: a cached program's loader lines are noise (compile_cache.py)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

from relaff_jax import compile_cache  # noqa: E402,I001 (first: sets the XLA flags)

import numpy as np  # noqa: E402

from relaff_jax.config.override import override_under, parse_set  # noqa: E402
from relaff_jax.constants import ACTIONS  # noqa: E402
from relaff_jax.io import atomic_write_json, read_json  # noqa: E402
from relaff_jax.sim import rollouts, templates  # noqa: E402
from relaff_jax.sim.scenes import RELATIONS  # noqa: E402

from disagreements import classify, outcomes, quantities  # noqa: E402

ENGINES = ("mjx", "native")


def action_config(sets: list[str]) -> templates.ActionConfig:
    """The default ``ActionConfig`` with ``--set action.KEY=VALUE`` overrides (only ``action.``
    keys: this compares executions of one action config); errors raise ``ConfigError`` /
    ``ValueError`` with one line."""
    updates = parse_set(sets)
    bad = [k for k in updates if not k.startswith("action.")]
    if bad:
        raise ValueError(f"--set takes action.* keys only, got {', '.join(bad)}")
    return override_under(templates.ActionConfig(), {k[len("action."):]: v for k, v in updates.items()}, "action.")


def compare(prep, out: dict[str, dict], action: str, cfg: templates.ActionConfig, batch_index: int):
    """Labels of both engines on ``prep``'s feasible rows and a record of each row where they
    differ: ``(labels {engine: [bool]}, differ [dict])``. ``out[engine]`` is ``outcomes(...)``."""
    run = np.flatnonzero(prep.plan.feasible)
    labels = {e: [bool(out[e]["label"][j]) for j in run] for e in ENGINES}
    differ = []
    for j, lm, ln in zip(run, labels["mjx"], labels["native"]):
        if lm != ln:
            d = np.asarray(prep.plan.direction[j])
            qm, qn = quantities(out["mjx"], j, d), quantities(out["native"], j, d)
            differ.append(dict(batch=batch_index, row=int(j), toy=str(prep.names[j][0]), other=str(prep.names[j][1]),
                               relation=RELATIONS[int(prep.scenes.relation[j])], mjx=lm, native=ln,
                               kind=classify(action, cfg, qm, qn),
                               mjx_q={k: [float(x) for x in v] for k, v in qm.items()},
                               native_q={k: [float(x) for x in v] for k, v in qn.items()}))
    return labels, differ


def summary(labels: dict[str, list], differ: list, scenes: int) -> dict:
    """The action's row of the table (and of ``--json``)."""
    lm, ln = np.asarray(labels["mjx"], bool), np.asarray(labels["native"], bool)
    return dict(scenes=int(scenes), feasible=len(lm), agree=int((lm == ln).sum()),
                positives={"mjx": int(lm.sum()), "native": int(ln.sum())}, differ=differ)


def action_row(action: str, n: int, batch: int, seed: int, cfg: templates.ActionConfig) -> dict:
    """Both engines on the feasible programs of prepared batches until ``n`` are feasible."""
    prepare = rollouts.make_batch_prepare_fn(action, cfg, settle="native")
    labels = {e: [] for e in ENGINES}
    differ, c, secs = [], 0, {"prepare": 0.0, **{e: 0.0 for e in ENGINES}}
    while len(labels["mjx"]) < n and c < 32:
        t = time.time()
        prep = prepare(rollouts.bench_batch_key(seed, batch, c), batch)
        secs["prepare"] += time.time() - t
        out = {}
        for e in ENGINES:
            t = time.time()
            out[e] = outcomes(prep, cfg, e)
            secs[e] += time.time() - t
        lab, dif = compare(prep, out, action, cfg, c)
        for e in ENGINES:
            labels[e] += lab[e]
        differ += dif
        c += 1
    return dict(summary(labels, differ, c * batch), seconds={k: round(v, 1) for k, v in secs.items()})


def print_row(action: str, r: dict) -> None:
    print(f"{action:10s} scenes {r['scenes']:4d} feasible {r['feasible']:4d} agree {r['agree']:4d} "
          f"({r['agree'] / max(r['feasible'], 1):.3f}) positives mjx {r['positives']['mjx']} "
          f"native {r['positives']['native']}  [s: " + ", ".join(f"{k} {v:.0f}" for k, v in r["seconds"].items())
          + "]", flush=True)
    for d in r["differ"]:
        print(f"    batch {d['batch']} row {d['row']} {d['toy']} / {d['other']} ({d['relation']}): mjx {d['mjx']}, "
              f"native {d['native']} -> {d['kind']}", flush=True)
        for e in ENGINES:
            q = d[f"{e}_q"]
            print(f"      {e:7s} " + "  ".join(f"{k} {v[0]:6.1f} {v[1]:6.1f}" for k, v in q.items()
                                              if k not in ("moved", "apart"))
                  + f"  toy moved {q['moved'][0]:5.1f}  apart {q['apart'][0]:5.1f}", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("n", type=int, help="feasible programs per action (at least)")
    ap.add_argument("actions", nargs="*", default=list(ACTIONS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--json")
    ap.add_argument("--set", action="append", default=[], metavar="action.KEY=VALUE")
    ap.add_argument("--no-compile-cache", action="store_true")
    a = ap.parse_args(argv)
    bad = [x for x in a.actions if x not in ACTIONS]
    if bad:
        ap.error(f"unknown action {', '.join(bad)}; valid: {', '.join(ACTIONS)}")
    if a.n < 1 or a.batch < 1:
        ap.error("N and --batch must be at least 1")
    try:
        cfg = action_config(a.set)
    except ValueError as e:  # ConfigError is a ValueError
        ap.error(str(e))
    compile_cache.configure(disable=a.no_compile_cache)
    setting = dict(n=a.n, seed=a.seed, batch=a.batch, programs=cfg.programs, set=sorted(a.set))
    done = {}
    if a.json and os.path.exists(a.json):
        prev = read_json(a.json)
        done = prev.get("actions", {}) if prev.get("setting") == setting else {}
    print(f"programs {cfg.programs}, seed {a.seed}, batch {a.batch}, >= {a.n} feasible programs per action"
          + (f", --set {' '.join(a.set)}" if a.set else ""), flush=True)
    for action in a.actions:
        if action not in done:
            done[action] = action_row(action, a.n, a.batch, a.seed, cfg)
            if a.json:
                atomic_write_json(a.json, {"setting": setting, "actions": done})
        print_row(action, done[action])


if __name__ == "__main__":
    main()
