"""The two IK solvers (``ArmConfig.ik_solver``: "lbfgs", the default, and "lm") on the same
scenes: N placements per action settled in MuJoCo C, planned by both (the jitted prepare stage),
both plans executed in MuJoCo C; feasibility, waypoint differences, label agreement and plan
time per action (docs/arm.md, "IK solvers").

    python benchmarks/ik_solvers.py N BATCH [ACTION ...] [--json OUT]

e.g. ``python benchmarks/ik_solvers.py 2000 250`` (all nine actions, ~40 min on 2 shared cores).
"""
import time, sys, dataclasses, json
import jax, jax.numpy as jnp, numpy as np
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim.native import settle as native_settle
from relaff_jax.sim.native.batch import execute_native
from relaff_jax.sim.planning import Plan
from relaff_jax.sim import scenes as sc, world as wd
from relaff_jax.constants import ACTIONS, action_id
argv = sys.argv[1:]
out_json = argv.pop(argv.index("--json") + 1) if "--json" in argv else None
argv = [a for a in argv if a != "--json"]
N, B = int(argv[0]), int(argv[1])
acts = argv[2:] or ACTIONS
cfg = templates.ActionConfig()
lm = dataclasses.replace(cfg, arm=dataclasses.replace(cfg.arm, ik_solver="lm"))
sw = wd.build_world(cfg.phys)
place_fn, _, _ = sc.jitted_scene_fns(sw, cfg.scene)
res = {}
for ai, action in enumerate(acts):
    allowed = rollouts.allowed_pairs(sw, action)
    out = {"lbfgs": [], "lm": []}; tm = {"lbfgs": 0.0, "lm": 0.0}; lab = {"lbfgs": [], "lm": []}
    for c in range(N // B):
        pair = np.asarray(sc.sample_pairs(jax.random.PRNGKey(1000 * ai + c), allowed, sw, B))
        q0, it = jax.device_get(place_fn(jax.random.PRNGKey(500000 + 1000 * ai + c), jnp.asarray(pair)))
        s = native_settle.settle_batch(sw, pair, q0, it, cfg.scene, 2)
        for name, cc in (("lbfgs", cfg), ("lm", lm)):
            f = rollouts.jitted_stage_fns(cc)[0]
            if c == 0:
                jax.block_until_ready(f(action_id(action), jnp.asarray(pair), jnp.asarray(s.qpos)))
            t0 = time.perf_counter()
            plan, before = jax.device_get(f(action_id(action), jnp.asarray(pair), jnp.asarray(s.qpos)))
            tm[name] += time.perf_counter() - t0
            out[name].append(plan)
            run = np.flatnonzero(plan.feasible)
            label = np.zeros(B, bool)
            if len(run):
                sub = Plan(plan.q_way[run], plan.grip_way[run], plan.seg_steps, plan.feasible[run], plan.direction[run], plan.ik_error[run])
                label[run] = execute_native(action, cfg, pair[run], np.asarray(s.qpos)[run], np.asarray(s.qvel)[run], sub, np.asarray(before)[run], nthread=2)["label"]
            lab[name].append(label)
    cat = lambda name, k: np.concatenate([getattr(p, k) for p in out[name]])
    fa, fb = cat("lbfgs", "feasible"), cat("lm", "feasible")
    both = fa & fb
    d = np.abs(cat("lbfgs", "q_way") - cat("lm", "q_way")).max(axis=(1, 2))[both]
    la, lb = np.concatenate(lab["lbfgs"]), np.concatenate(lab["lm"])
    r = dict(n=int(len(fa)), feasible_lbfgs=int(fa.sum()), feasible_lm=int(fb.sum()), feasible_differ=int((fa != fb).sum()),
             dq_median=float(np.median(d)), dq_p95=float(np.percentile(d, 95)), dq_p99=float(np.percentile(d, 99)), dq_max=float(d.max()),
             labels_differ=int((la != lb).sum()), positives_lbfgs=int(la.sum()), positives_lm=int(lb.sum()),
             plan_s_lbfgs=round(tm["lbfgs"], 2), plan_s_lm=round(tm["lm"], 2), speedup=round(tm["lbfgs"] / tm["lm"], 1))
    res[action] = r
    print(action, json.dumps(r), flush=True)
if out_json:
    with open(out_json, "w") as f:
        json.dump(res, f, indent=1)
