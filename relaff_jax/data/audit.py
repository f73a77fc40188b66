"""The physics audit of a dataset (``relaff audit``): a MuJoCo C replay of a sample of its rollouts.

Takes a dataset folder; gives ``audit_dataset(path, sample, seed)``, a JSON-serialisable dict
(schema ``AUDIT_VERSION``), ``stored_audit`` / ``ensure_audit`` (``DIR/audit.json``, written
atomically, reused when its sample, seed and selection match) and ``summarise`` (the checks).

How a stored rollout is re-simulated: the dataset's sidecar records its ``ActionConfig``
(``config.action_config``), engine and settle; every rollout records its pair, placement
(``qpos0``) and settled state (``qpos_settled``). The audit plans the sampled scenes with the
same jitted planner and batch shape as generation (``rollouts.make_batch_prepare_fn``), and
replays the programs one ``MjData`` per scene (``native.reference.replay_native``, the reference
the native engine equals bit for bit) with ``native.probe_arrays.ArrayProbe`` (``native.probe.Probe``'s
readings from the contact arrays) reading every step, in ``jobs`` processes
(``audit_replay``: the same audit at any count). A native
dataset's scenes are re-settled in MuJoCo C from ``qpos0`` (``native.settle.settle_batch``,
what generation ran) for the settled velocities, which are not stored; the settled positions
are checked against the stored ones. An MJX dataset is replayed in C from its stored settled
positions at rest: C and MJX agree on about 98 % of labels (docs/actions.md), so its label
agreement is measured, not exact.

Population: the selected samples whose program ran (``feasible``; an infeasible program
leaves the arm at home and has no physics); ``sample`` of them (all if fewer), drawn with
``seed``.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.constants import RELATIONS
from relaff_jax.data.errors import DatasetError
from relaff_jax.data.load import load_rollouts
from relaff_jax.data.store import read_sidecar
from relaff_jax.sim import physics_bounds as bounds
from relaff_jax.config import from_dict
from relaff_jax.sim.object_library import use_recorded
from relaff_jax.sim.actions.registry import action_id, check_recorded, names
from relaff_jax.data.layout import SIDECAR
from relaff_jax.config.action import ActionConfig

AUDIT_FILE = "audit.json"
# 7: a palm contact from above fails only above PALM_FORCE_N (a 0 N touch is not a press);
# 6: the palm check fails on palm contacts from above only (a push from the side is reported);
# 5: a press under PRESS_FLOOR_N newtons passes; 4: penetration held 0.1 s (was one step's);
# 3: force = the press held 0.1 s, penetration 3 mm
AUDIT_VERSION = 7
DEFAULT_SAMPLE = 64
# The checks' bounds are the programs' (sim/physics_bounds.py; reasoning: docs/arm.md,
# "Bounded forces"): a rollout fails a check when it has more steps with a hand-object contact
# from above (the normal within PALM_ABOVE_DEG of vertical: a press) carrying more than PALM_FORCE_N
# newtons than PALM_CONTACTS (contacts
# from the side, the palm pushing an object aside, are reported), its press exceeds FORCE_WEIGHTS
# weights of the heavier object and FORCE_FLOOR_N newtons, a contact with an object stays deeper
# than PENETRATION_M for 0.1 s (an impact's one-step depth is reported), or an object not held by
# the hand moves faster than MOVING_M_S at the measuring step
PALM_CONTACTS = bounds.PALM_CONTACT_STEPS
PALM_FORCE_N = bounds.PALM_FORCE_N
FORCE_WEIGHTS = bounds.PRESS_WEIGHTS
FORCE_FLOOR_N = bounds.PRESS_FLOOR_N
PENETRATION_M = bounds.PENETRATION_M
MOVING_M_S = bounds.MOVING_M_S
PALM_ABOVE_DEG = bounds.PALM_ABOVE_DEG
THRESHOLDS = {"palm_contact_steps": PALM_CONTACTS, "palm_force_n": PALM_FORCE_N, "palm_above_deg": PALM_ABOVE_DEG, "press_weights": FORCE_WEIGHTS, "press_floor_n": FORCE_FLOOR_N,
              "press_steps": bounds.SUSTAIN_STEPS,
              "penetration_m": PENETRATION_M, "moving_m_s": MOVING_M_S}


def action_config(meta: Mapping[str, Any]):
    record = meta.get("config")
    if not isinstance(record, dict) or not isinstance(record.get("action_config"), dict):
        raise DatasetError(f"{meta.get('action')}: the sidecar records no action_config; cannot replay")

    use_recorded(meta)  # the objects its pair indices refer to (the built-ins if it records none)

    check_recorded(str(meta.get("action")), record.get("action_spec"))  # a user action: the spec that made it
    return from_dict(ActionConfig, {**record["action_config"], "programs": recorded_programs(meta)})


def recorded_programs(meta: Mapping[str, Any]) -> str:
    """The programs' version a dataset was made with: v1 is recorded by the absence of ``programs``
    (``templates.stored_config``, as before v2), so a missing one is v1, not the default (v2)."""
    record = meta.get("config")
    stored = record.get("action_config") if isinstance(record, dict) else None
    return str(stored.get("programs", "v1")) if isinstance(stored, dict) else "v1"


def _plan(cfg: Any, action: str, pair: np.ndarray, qpos: np.ndarray, batch: int) -> dict[str, np.ndarray]:
    """The plans of the scenes, by generation's jitted planner in calls of the dataset's batch
    (the last padded with repeats: a plan does not depend on the other rows of its call)."""
    # the simulation (JAX, MuJoCo) loads when a replay runs: reproduce --status reads this module
    from relaff_jax.sim.reach_screen import prepare_screened
    from relaff_jax.sim.rollouts import jitted_stage_fns

    import jax

    aid = action_id(action)
    prepare_fn, _ = jitted_stage_fns(cfg)
    parts = []
    for lo in range(0, len(pair), batch):
        rows = np.resize(np.arange(lo, min(lo + batch, len(pair))), batch)
        if cfg.arm.reach_screen:
            plan, _ = prepare_screened(cfg, aid, pair[rows], qpos[rows])
        else:
            plan, _ = jax.device_get(prepare_fn(aid, pair[rows], qpos[rows]))
        k = min(batch, len(pair) - lo)
        parts.append({f: np.asarray(getattr(plan, f))[:k] for f in ("q_way", "grip_way", "feasible", "direction")})
    return {f: np.concatenate([p[f] for p in parts]) for f in parts[0]}


def settled_velocities(cfg: Any, meta: Mapping[str, Any], r: Mapping[str, np.ndarray], nthread: int | None
             ) -> tuple[np.ndarray, np.ndarray]:
    """(qvel (n, 12) float32, reproduced (n,) bool): the settled velocities and whether the
    re-settle gave the stored settled positions bit for bit (native datasets only)."""
    n = len(r["pair"])
    if meta.get("engine") != "native":
        return np.zeros((n, 12), np.float32), np.zeros(n, bool)
    # the simulation (JAX, MuJoCo) loads when a replay runs: reproduce --status reads this module
    from relaff_jax.sim import world as wd
    from relaff_jax.sim.native.batch import default_threads
    from relaff_jax.sim.native.settle import settle_batch

    s = settle_batch(wd.build_world(cfg.phys), r["pair"], r["qpos0"], r["intended"], cfg.scene,
                     default_threads() if nthread is None else nthread)
    same = np.all(s.qpos == r["qpos_settled"], axis=1)
    return np.where(same[:, None], s.qvel, 0.0).astype(np.float32), same


def _sample(rollouts: Mapping[str, Any], sample: int, seed: int) -> np.ndarray:
    pop = rollouts["selected"] & rollouts["feasible"] if rollouts["selected"].any() else rollouts["feasible"].copy()
    idx = np.flatnonzero(pop)
    if len(idx) > sample:
        idx = np.sort(np.random.default_rng(seed).choice(idx, sample, replace=False))
    return idx


def audit_dataset(path: str | os.PathLike, sample: int = DEFAULT_SAMPLE, seed: int = 0,
                  nthread: int | None = None, jobs: int | None = None) -> dict[str, Any]:
    """Replay ``sample`` rollouts of the dataset ``path`` in MuJoCo C with the physics probe
    (in ``jobs`` processes, default the cores: ``audit_replay``); the per-rollout readings and
    their summary (``summarise``)."""
    # the simulation (JAX, MuJoCo) loads when a replay runs: reproduce --status reads this module
    from relaff_jax.data.audit_replay import default_jobs, replay_probed
    from relaff_jax.sim.actions.tables import tables

    t0 = time.perf_counter()
    path = Path(path)
    meta = read_sidecar(path)
    if meta["status"] != "complete":
        raise DatasetError(f"{path}: generation not finished; audit a finished dataset")
    action = str(meta["action"])
    cfg = action_config(meta)
    rollouts = load_rollouts(path)
    need = ("pair", "qpos0", "qpos_settled", "intended", "label", "feasible", "relation", "toy", "other", "rollout")
    lack = [k for k in need if k not in rollouts]
    if lack:
        raise DatasetError(f"{path}: its rollouts lack {', '.join(lack)}; not the simulation's rollouts, cannot replay")
    idx = _sample(rollouts, int(sample), int(seed))
    r = {k: np.asarray(rollouts[k])[idx] for k in need}
    out: dict[str, Any] = dict(version=AUDIT_VERSION, dataset=str(path), action=action, engine=meta.get("engine"),
                               settle=meta.get("settle"), programs=cfg.programs, sample=int(sample), seed=int(seed),
                               selection_sha256=meta.get("selection", {}).get("sha256"),
                               population=int((rollouts["selected"] & rollouts["feasible"]).sum()),
                               n_audited=len(idx), thresholds=dict(THRESHOLDS))
    rows: list[dict[str, Any]] = []
    if len(idx):
        qvel, resettled = settled_velocities(cfg, meta, r, nthread)
        plan = _plan(cfg, action, r["pair"], r["qpos_settled"], int(meta["batch"]))
        rep, got = replay_probed(meta, cfg, action, r["pair"], r["qpos_settled"], qvel, plan,
                                 int(tables(cfg).measure[action_id(action)]), default_jobs() if jobs is None else jobs)
        for i in range(len(idx)):
            rel = r["relation"][i]
            rows.append(dict(
                rollout=int(r["rollout"][i]), toy=str(r["toy"][i]), other=str(r["other"][i]),
                relation=str(RELATIONS[int(rel)] if np.issubdtype(np.asarray(rel).dtype, np.integer) else rel),
                label=bool(r["label"][i]), replay_label=bool(rep["label"][i]),
                plan_feasible=bool(plan["feasible"][i]), resettled=bool(resettled[i]),
                **{k: _jsonable(v[i]) for k, v in got.items()}))
    out["rollouts"] = rows
    out.update(summarise(rows, meta.get("engine")))
    out["seconds"] = round(time.perf_counter() - t0, 2)
    return out


def _jsonable(v: Any) -> Any:
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        return None if not np.isfinite(v) else round(float(v), 6)
    return str(v)


def _dist(x: np.ndarray) -> dict[str, float | None]:
    if not len(x):
        return {"median": None, "p95": None, "max": None}
    return {"median": round(float(np.median(x)), 6), "p95": round(float(np.quantile(x, 0.95)), 6),
            "max": round(float(np.max(x)), 6)}


def failures(row: Mapping[str, Any]) -> dict[str, bool]:
    """Which checks one audited rollout fails."""
    speeds = [s for s, held in ((row["speed_toy"], row.get("held_toy")), (row["speed_other"], row.get("held_other")))
              if s is not None and not held]  # a held object moves with the arm
    return {"palm_contact": row["palm_top_steps"] > PALM_CONTACTS and row["palm_top_force_n"] > PALM_FORCE_N,
            "force": not bool(bounds.press_ok(row["press_n"], row["weight_n"])),
            "penetration": _held_depth(row) > PENETRATION_M,
            "moving": bool(speeds) and max(speeds) > MOVING_M_S}


def _held_depth(row: Mapping[str, Any]) -> float:
    """The deepest contact held over 0.1 s (rows made before that reading: the one-step depth)."""
    held = row.get("held_penetration_m")
    return row["max_penetration_m"] if held is None else held


def summarise(rows: list[Mapping[str, Any]], engine: str | None = None) -> dict[str, Any]:
    """The checks over audited rollouts ``rows``: per check its statistic, bound, the count and
    share of failing rollouts and pass (no rollout fails); the shares by label and by relation;
    the replay's agreement with the stored labels."""
    n = len(rows)
    fails = [failures(r) for r in rows]
    count = {k: sum(f[k] for f in fails) for k in ("palm_contact", "force", "penetration", "moving")}
    share = lambda k: (count[k] / n) if n else None
    arr = lambda k: np.asarray([r[k] for r in rows if r[k] is not None], float)
    # the palm's forces from above / the side over the rollouts with such a (nonzero) force
    _pos = lambda k: np.asarray([r[k] for r in rows if r[k]], float)
    side = sum(bool(r["palm_side_steps"]) for r in rows)
    checks = {
        "palm_contact": dict(count=count["palm_contact"], share=share("palm_contact"),
                             bound=f"no contact from above (normal within {PALM_ABOVE_DEG:g} deg of vertical) between "
                                   f"the hand body (palm) and an object carrying more than {PALM_FORCE_N:g} N; contacts "
                                   "from the side are reported",
                             above_deg=PALM_ABOVE_DEG,
                             palm_seconds=_dist(arr("palm_seconds")), palm_force_n=_dist(arr("palm_force_n")),
                             top_force_n=_dist(_pos("palm_top_force_n")),
                             side_count=side, side_share=(side / n) if n else None,
                             side_force_n=_dist(_pos("palm_side_force_n"))),
        "force": dict(count=count["force"], share=share("force"), bound_weights=FORCE_WEIGHTS,
                      bound_floor_n=FORCE_FLOOR_N,
                      held_steps=bounds.SUSTAIN_STEPS,
                      weights=_dist(arr("press_weights")), newtons=_dist(arr("press_n")),
                      peak_weights=_dist(arr("peak_force_weights")), peak_newtons=_dist(arr("peak_force_n"))),
        "penetration": dict(count=count["penetration"], share=share("penetration"), bound_m=PENETRATION_M,
                            held_steps=bounds.SUSTAIN_STEPS,
                            metres=_dist(np.asarray([_held_depth(r) for r in rows], float)),
                            peak_metres=_dist(arr("max_penetration_m"))),
        "moving": dict(count=count["moving"], share=share("moving"), bound_m_s=MOVING_M_S,
                       speed_toy=_dist(arr("speed_toy")), speed_other=_dist(arr("speed_other"))),
    }
    for c in checks.values():
        c["pass"] = c["count"] == 0
    groups: dict[str, dict[str, Any]] = {}
    for key, name in (("label", lambda r: "positive" if r["label"] else "negative"), ("relation", lambda r: r["relation"])):
        g: dict[str, dict[str, Any]] = {}
        for r, f in zip(rows, fails):
            cell = g.setdefault(name(r), {"n": 0, **{k: 0 for k in count}})
            cell["n"] += 1
            for k in count:
                cell[k] += int(f[k])
        groups[f"by_{key}"] = g
    agree = sum(r["label"] == r["replay_label"] for r in rows)
    why = ("exact: the replay is the native engine's reference from the same settled state and plan"
           if engine == "native" else
           "the dataset was simulated by MJX; the C replay starts from its settled positions at rest "
           "(MJX and C agree on ~98 % of labels, docs/actions.md)")
    replay = dict(label_agreement=(agree / n) if n else None, agree=agree, n=n, why=why,
                  disagreements=[r["rollout"] for r in rows if r["label"] != r["replay_label"]],
                  resettled=sum(bool(r["resettled"]) for r in rows),
                  plan_feasible=sum(bool(r["plan_feasible"]) for r in rows))
    return {"checks": checks, **groups, "replay": replay}


def stored_audit(path: str | os.PathLike, sample: int, seed: int) -> dict[str, Any] | None:
    """``path/audit.json`` if made with this sample, seed, selection and the dataset's programs, else None."""
    path = Path(path)
    try:
        d = rio.read_json(path / AUDIT_FILE)
    except (OSError, ValueError):
        return None
    meta = read_sidecar(path)
    sel = meta.get("selection", {}).get("sha256")
    # no ``programs``: made before it was recorded, when every replay ran v2 (a v1 dataset's too)
    ok = isinstance(d, dict) and (d.get("version"), d.get("sample"), d.get("seed"), d.get("selection_sha256"),
                                  d.get("programs", "v2")) == (AUDIT_VERSION, int(sample), int(seed), sel,
                                                               recorded_programs(meta))
    return d if ok else None


def ensure_audit(path: str | os.PathLike, sample: int = DEFAULT_SAMPLE, seed: int = 0,
                 nthread: int | None = None, jobs: int | None = None) -> dict[str, Any]:
    """The stored audit of ``path`` if it matches (``stored_audit``), else a new one written
    atomically to ``path/audit.json``: resumable, a killed run leaves no partial file."""
    d = stored_audit(path, sample, seed)
    if d is None:
        d = audit_dataset(path, sample, seed, nthread, jobs)
        rio.atomic_write_json(Path(path) / AUDIT_FILE, d)
    return d


def dataset_folders(path: str | os.PathLike) -> list[Path]:
    """The dataset folders of ``path``: itself if it is a dataset (has a sidecar), else the
    ``data/<action>/`` datasets of a run folder, in ``ACTIONS`` order. One-line errors for a
    missing folder, a file, or a folder that is neither."""
    p = Path(path)
    if not p.exists():
        raise DatasetError(f"{p}: no such dataset or run folder")
    if not p.is_dir():
        raise DatasetError(f"{p}: not a folder")
    if (p / SIDECAR).is_file():
        return [p]
    found = [p / "data" / a for a in names() if (p / "data" / a / SIDECAR).is_file()]
    if not found:
        raise DatasetError(f"{p}: not a relaff dataset (no {SIDECAR}) nor a run folder with data/<action>/ datasets")
    return found


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def format_audit(audits: list[Mapping[str, Any]]) -> str:
    """The table ``relaff audit`` prints: one row per dataset, the bounds below."""
    head = (f"{'action':<11}{'engine':<7}{'audited':>9}  {'palm above/side':>15}  {'press/weight med p95 max':>25}  "
            f"{'pen. max':>8}  {'moving':>6}  {'label agr.':>10}  checks")
    lines = [head, "-" * len(head)]
    for a in audits:
        c = a["checks"]
        w = c["force"]["weights"]
        fmt = lambda v: "-" if v is None else f"{v:.0f}" if v >= 10 else f"{v:.1f}"
        force = f"{fmt(w['median'])} {fmt(w['p95'])} {fmt(w['max'])}"
        pen = c["penetration"]["metres"]["max"]
        failed = [k for k in ("palm_contact", "force", "penetration", "moving") if not c[k]["pass"]]
        lines.append(
            f"{a['action']:<11}{str(a['engine']):<7}{a['n_audited']:>4}/{a['population']:<4}  "
            f"{_pct(c['palm_contact']['share']) + '/' + _pct(c['palm_contact']['side_share']):>15}  {force:>25}  "
            f"{'-' if pen is None else f'{1000 * pen:.1f} mm':>8}  {_pct(c['moving']['share']):>6}  "
            f"{_pct(a['replay']['label_agreement']):>10}  {'FAIL ' + ','.join(failed) if failed else 'pass'}")
    lines.append("")
    lines.append(f"audited: sampled selected samples whose program ran / all of them. palm above/side: the share "
                 f"of rollouts with a contact between the hand body and an object from above (its normal within "
                 f"{PALM_ABOVE_DEG:g} deg of vertical: the palm pressing on an object) / from the side (the palm pushing "
                 f"it). A rollout fails: palm = a contact from above carrying more than {PALM_FORCE_N:g} N (lighter touches and side contacts are reported, not checked); force = the summed normal force on an object held "
                 f"over {bounds.SUSTAIN_STEPS} steps (a press, not an impact) > {FORCE_WEIGHTS:g} weights of the "
                 f"heavier object and > {FORCE_FLOOR_N:g} N; pen. = a contact with an object deeper than "
                 f"{1000 * PENETRATION_M:g} mm held over {bounds.SUSTAIN_STEPS} steps; moving = an object not held by "
                 f"the hand faster than {MOVING_M_S:g} m/s "
                 f"at the measuring step. A check passes when no audited rollout fails it. label agr.: the C replay's labels "
                 f"equal to the stored ones.")
    return "\n".join(lines)
