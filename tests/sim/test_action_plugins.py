"""Actions as declared specs: the registry's built-ins are today's tables and goals bit for bit,
a user's action (examples/tenth_action.py) generates a dataset from outside the package with
labels from its own rule, bad specs are one line before any simulation, and docs/extending.md
shows the example as it is."""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import relaff_jax  # noqa: F401 (XLA flags before JAX)
from relaff_jax.constants import ACTIONS, PAIRING, PAIRINGS

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "tenth_action.py"


def _relaff(args, cwd):
    return subprocess.run([sys.executable, "-m", "relaff_jax.cli", *args], cwd=cwd, capture_output=True, text=True,
                          env=dict(os.environ))


def test_builtin_specs_give_the_hard_wired_tables():
    from relaff_jax.sim import templates as T
    from relaff_jax.sim.actions import names, registry
    from relaff_jax.sim.actions.tables import tables

    assert names()[:9] == ACTIONS and tuple(s.name for s in registry()[:9]) == ACTIONS
    assert [s.pairing for s in registry()[:9]] == [PAIRINGS[PAIRING[a]] for a in ACTIONS]
    for programs in ("v1", "v2"):
        cfg = T.ActionConfig(programs=programs)
        tb = tables(cfg)
        assert tb.steps.shape[0] >= 9
        ref = T.TPL_STEPS.copy()
        if programs == "v2":
            ref[:, -1] += cfg.rest_hold
        np.testing.assert_array_equal(tb.steps[:9], ref)
        np.testing.assert_array_equal(tb.target[:9], T.TPL_TARGET)
        np.testing.assert_array_equal(tb.closed[:9], T.TPL_CLOSED)
        np.testing.assert_array_equal(tb.measure[:9], T.TPL_MEASURE)
        np.testing.assert_array_equal(tb.grasp[:9], T.GRASPS)
        np.testing.assert_array_equal(tb.held[:9], np.asarray(ACTIONS) == "rake")
        np.testing.assert_array_equal(tb.reach[:9], np.asarray(ACTIONS) == "unobstruct")


def test_builtin_goal_rules_are_labels_goals():
    """On random outcomes (both after states different) every built-in's goal equals its entry of
    labels.goals: each reads the one after state its spec declares."""
    import jax
    import jax.numpy as jnp

    from relaff_jax.sim.actions import registry
    from relaff_jax.sim.actions.rules import goal_row
    from relaff_jax.sim.labels import Outcome, goals
    from relaff_jax.sim.templates import ActionConfig

    rng = np.random.default_rng(0)
    n = 4000
    com0 = rng.uniform(-0.6, 0.6, (n, 2, 3)).astype(np.float32)
    com0[..., 2] = rng.uniform(0, 0.1, (n, 2))
    step = lambda: (com0 + rng.normal(0, 0.12, (n, 2, 3))).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:, 2] = 0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = Outcome(jnp.asarray(com0), jnp.asarray(step()), jnp.asarray(step()), jnp.asarray(d),
                jnp.asarray(rng.random(n) < 0.5), jnp.asarray(rng.random(n) < 0.5))
    cfg = ActionConfig()
    specs = registry()[:9]
    ref = np.asarray(jax.vmap(lambda x: goals(cfg, x))(o))
    got = np.asarray(jax.vmap(lambda x: goal_row(specs, cfg, x))(o))
    np.testing.assert_array_equal(got, ref)
    assert 0.02 < ref.mean() < 0.98  # both outcomes occur


BAD = {
    "missing field": ("ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS, targets=drag_targets)",
                      "action 'drag2': field goal: missing"),
    "name clash": ("ActionSpec(name='pull', pairing='toy+base', segments=SEGMENTS, targets=drag_targets, "
                   "goal=toy_rode_along)", "action 'pull': field name: clashes with the built-in"),
    "unknown pairing": ("ActionSpec(name='drag2', pairing='toy+table', segments=SEGMENTS, targets=drag_targets, "
                        "goal=toy_rode_along)", "action 'drag2': field pairing: unknown pairing 'toy+table'"),
    "template too long": ("ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS[:-1] + ((500, 5, False),), "
                          "targets=drag_targets, goal=toy_rode_along)",
                          "action 'drag2': field segments: the template needs 1205 control steps, longer than the "
                          "compiled step budget of 815"),
    "unknown manipulated object": ("ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS, "
                                   "targets=drag_targets, goal=toy_rode_along, manipulates='base')",
                                   "action 'drag2': field manipulates: 'base'; valid: toy, other"),
    "manipulated object not the one held": (
        "ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS, targets=drag_targets, "
        "goal=toy_rode_along, manipulates='toy')",
        "action 'drag2': field manipulates: 'toy', but the closed gripper holds the other object (grasp 'other')"),
    "target rule of the wrong shape": (
        "ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS, "
        "targets=lambda s: drag_targets(s)._replace(direction=jnp.zeros(2)), goal=toy_rode_along)",
        "action 'drag2': field targets: expected Program.direction of shape (3,), got (2,)"),
    "goal of the wrong shape": (
        "ActionSpec(name='drag2', pairing='toy+base', segments=SEGMENTS, targets=drag_targets, "
        "goal=lambda cfg, r: r.after[:, 0] > 0)", "action 'drag2': field goal: expected a () bool, got (2,) bool"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_spec_is_one_line_before_any_simulation(case, tmp_path):
    spec, message = BAD[case]
    src = EXAMPLE.read_text().replace("DRAG = register_action(", "_ = (") + f"\nregister_action({spec})\n"
    bad = tmp_path / "bad_action.py"
    bad.write_text(src)
    run = _relaff(["generate", "drag2", "--plugins", str(bad), "--samples", "8", "--engine", "native",
                   "--out", str(tmp_path / "out")], tmp_path)
    assert run.returncode == 2, run.stderr
    # XLA's own log lines (a compile cache's notes) aside, one line
    lines = [x for x in run.stderr.strip().splitlines() if not re.match(r"^[WEI]\d{4} ", x)]
    assert len(lines) == 1 and lines[0].startswith("relaff generate: error: "), run.stderr
    assert message in lines[0], lines[0]
    assert not (tmp_path / "out" / "chunks").exists()  # nothing simulated


def test_an_unknown_action_names_the_plugins_option(tmp_path):
    run = _relaff(["generate", "drag", "--samples", "8", "--out", str(tmp_path / "out")], tmp_path)
    assert run.returncode == 2 and "unknown action 'drag'" in run.stderr and "--plugins" in run.stderr


def test_the_page_shows_the_action_example_as_it_is():
    text = (ROOT / "docs" / "extending.md").read_text()
    assert EXAMPLE.read_text() in re.findall(r"```python\n(.*?)```", text, flags=re.S)


def _com(world, pair, qpos):
    """(R, 2, 3) centres of mass of (toy, other) from free-joint qpos (R, 14), in float64."""
    out = np.zeros((len(pair), 2, 3))
    for r, (p, q) in enumerate(zip(pair, np.asarray(qpos, np.float64))):
        m = world.mj_models[int(p)]
        for j, body in enumerate((world.toy_body, world.obj_body)):
            w, x, y, z = q[7 * j + 3:7 * j + 7] / np.linalg.norm(q[7 * j + 3:7 * j + 7])
            rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            out[r, j] = q[7 * j:7 * j + 3] + rot @ m.body_ipos[body]
    return out


@pytest.mark.slow
def test_the_tenth_action_generates_labels_from_its_rule(tmp_path):
    out = tmp_path / "drag"
    run = _relaff(["generate", "drag", "--plugins", str(EXAMPLE), "--samples", "8", "--engine", "native",
                   "--batch", "32", "--out", str(out)], tmp_path)  # from outside the package
    assert run.returncode == 0, run.stderr
    meta = json.loads((out / "relaff_dataset.json").read_text())
    assert meta["action"] == "drag"
    rec = meta["config"]["action_spec"]
    assert rec["origin"] == f"file {EXAMPLE.resolve()}" and len(rec["spec_sha256"]) == 64

    from relaff_jax.data import load_rollouts
    from relaff_jax.sim.world import build_world
    from relaff_jax.config.action import ActionConfig

    r = load_rollouts(out)
    assert r["selected"].sum() == 8 and r["label"][r["selected"]].sum() == 4
    world = build_world(ActionConfig().phys, arm=True)
    before, after = _com(world, r["pair"], r["qpos_settled"]), _com(world, r["pair"], r["qpos_final"])
    # the example's rule by hand: base moved >= 10 cm, the toy's offset from it changed < 2 cm
    moved = np.linalg.norm(after[:, 1, :2] - before[:, 1, :2], axis=1)
    change = np.linalg.norm((after[:, 0] - after[:, 1]) - (before[:, 0] - before[:, 1]), axis=1)
    hand = (moved >= 0.10) & (change < 0.02) & r["feasible"]
    # float32 stored states against the engine's float64 centres: a case on a threshold may differ
    edge = (np.abs(moved - 0.10) < 1e-5) | (np.abs(change - 0.02) < 1e-5)
    np.testing.assert_array_equal(r["label"][~edge], hand[~edge])
    assert r["label"].sum() >= 4 and (~r["label"] & r["feasible"]).sum() >= 1  # both outcomes of executed drags

    # a changed spec is refused where the dataset is read again
    changed = tmp_path / "tenth_action.py"
    changed.write_text(EXAMPLE.read_text().replace("distance=0.20", "distance=0.25"))
    audit = _relaff(["audit", str(out), "--sample", "2", "--plugins", str(changed)], tmp_path)
    assert audit.returncode == 2 and "is not the one that made this folder" in audit.stderr, audit.stderr
