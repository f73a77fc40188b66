"""The physics audit (``relaff audit``, ``data/audit.py``, ``sim/native/probe.py``): the probe's
readings on hand-built MuJoCo C scenes with known answers, the checks and their JSON, the
command's one-line errors, and (slow) the replay of a generated native dataset."""
import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from relaff_jax.data import audit as A
from relaff_jax.sim import objects as lib
from relaff_jax.sim import physics_bounds as bounds
from relaff_jax.sim.native.probe import Probe, held_peak

# A 1 kg box on the table; above it a "hand" body (the probe's arm_hand) on a vertical slide,
# weightless (gravcomp), pushed down by a motor with a known force.
PRESS = """
<mujoco>
  <option timestep="0.004" cone="pyramidal"/>
  <worldbody>
    <geom name="table" type="plane" size="2 2 0.1"/>
    <body name="toy" pos="0.5 0.5 0.05"><freejoint/>
      <geom type="sphere" size="0.05" mass="0.2"/></body>
    <body name="obj" pos="0 0 {z}"><freejoint/>
      <geom type="box" size="0.05 0.05 0.05" mass="1.0"/></body>
    <body name="arm_hand" pos="0 0 {hz}" gravcomp="1">
      <joint name="slide" type="slide" axis="0 0 1" damping="50"/>
      <geom name="arm_palm" type="box" size="0.03 0.03 0.015" mass="0.5"/>
    </body>
  </worldbody>
  <actuator><motor joint="slide" gear="1"/></actuator>
</mujoco>
"""
G = 9.81


def _run(xml: str, steps: int, force: float = 0.0):
    m = mujoco.MjModel.from_xml_string(xml)
    m.opt.gravity[:] = (0.0, 0.0, -G)
    d = mujoco.MjData(m)
    toy = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "toy")
    obj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "obj")
    probe = Probe(1, toy, obj, m.opt.timestep)
    for t in range(steps):
        d.ctrl[:] = -force * min(1.0, t / 500)  # ramped: quasi-static, no impact overshoot
        mujoco.mj_step(m, d)
        probe(0, t, m, d)
    return probe, m, d


def test_probe_reads_a_known_palm_press():
    """A weightless palm pushed down with a force ramped to 98.1 N (10 weights of the 1 kg box)
    onto the box: at rest the palm-box pair carries 98.1 N and the box-table pair 107.9 N (11 weights), the
    peak; the palm touches the box from its first contact on."""
    probe, m, d = _run(PRESS.format(z=0.05, hz=0.1149), 1500, force=10 * G)  # touching
    r = probe.result(1499)
    assert r["palm_contact"][0]
    assert r["peak_pair"][0] == "world|obj"
    assert r["peak_force_weights"][0] == pytest.approx(11.0, rel=0.02)
    assert r["peak_force_n"][0] == pytest.approx(11 * G, rel=0.02)
    assert r["palm_force_n"][0] == pytest.approx(10 * G, rel=0.02)
    assert r["palm_steps"][0] > 1000
    # the palm on the box's top: every contact from above (the normal vertical), none from the side
    assert r["palm_top_steps"][0] == r["palm_steps"][0] and r["palm_side_steps"][0] == 0
    assert r["palm_top_force_n"][0] == pytest.approx(10 * G, rel=0.02) and r["palm_side_force_n"][0] == 0.0
    # the press sums every contact on the box (palm 98.1 N + table 107.9 N = 21 weights), held
    # at the end of the ramp; the ball (0.2 kg) is lighter: the weight is the box's
    assert r["weight_n"][0] == pytest.approx(G)
    assert r["press_weights"][0] == pytest.approx(21.0, rel=0.02)
    assert r["press_n"][0] == pytest.approx(21 * G, rel=0.02) and r["object_peak_n"][0] >= r["press_n"][0]
    # both objects rest at the end: the ball on the table, the box pressed
    assert r["speed_toy"][0] < 1e-3 and r["speed_other"][0] < 1e-3


def test_probe_without_a_press_reads_one_weight_and_no_palm():
    probe, _, _ = _run(PRESS.format(z=0.05, hz=0.2), 300, force=-5.0)  # the palm held up, away
    r = probe.result(299)
    assert not r["palm_contact"][0] and r["palm_steps"][0] == 0
    # the box placed on the soft table sinks in and rebounds (1.4 weights at the first steps),
    # then rests at one weight
    assert r["peak_pair"][0] == "world|obj" and r["peak_step"][0] < 20
    assert 1.0 < r["peak_force_weights"][0] < 1.5
    # the rebound's impact is brief: the force held over SUSTAIN_STEPS is the box's weight
    assert r["object_peak_n"][0] > 1.3 * G
    assert r["press_weights"][0] == pytest.approx(1.0, rel=0.01)


def test_held_peak_by_hand():
    assert held_peak([0, 5, 5, 5, 1], 3) == 5.0 and held_peak([0, 5, 5, 5, 1], 4) == 1.0
    assert held_peak([3, 1, 3, 2], 2) == 2.0 and held_peak([9, 9], 3) == 0.0
    assert bounds.SUSTAIN_STEPS == 25 and A.FORCE_WEIGHTS == bounds.PRESS_WEIGHTS  # the audit's bounds are the programs'


def test_probe_reads_a_known_penetration_and_a_known_speed():
    """The box starts 3 mm into the table: the first step's contacts read that depth (the
    deepest of the run, as the solver pushes it out). The ball, lifted off the table, falls
    freely: at step t its velocity in the step's forward pass is g * dt * t (semi-implicit Euler)."""
    xml = PRESS.format(z=0.047, hz=0.2).replace('pos="0.5 0.5 0.05"', 'pos="0.5 0.5 1.0"')
    probe, m, _ = _run(xml, 40, force=-5.0)
    r = probe.result(30)
    assert r["max_penetration_m"][0] == pytest.approx(0.003, abs=1e-9)
    assert r["penetration_pair"][0] == "world|obj"
    assert r["speed_toy"][0] == pytest.approx(G * m.opt.timestep * 30, rel=1e-9)
    assert np.isnan(probe.result(40)["speed_toy"][0])  # a step not simulated


def _row(**kw):
    row = dict(rollout=0, toy="ball", other="tray", relation="on_top", label=True, replay_label=True,
               plan_feasible=True, resettled=True, palm_contact=False, palm_steps=0, palm_seconds=0.0,
               palm_force_n=0.0, palm_top_steps=0, palm_top_force_n=0.0, palm_side_steps=0,
               palm_side_force_n=0.0, peak_force_n=5.0, peak_force_weights=1.0, peak_pair="world|obj", peak_step=3,
               object_peak_n=5.0, press_n=5.0, weight_n=5.0, press_weights=1.0,
               max_penetration_m=0.001, penetration_pair="world|obj", speed_toy=0.0, speed_other=0.0, held_toy=False,
               held_other=False, speed_end=0.0)
    row.update(kw)
    return row


def test_checks_count_failures_against_the_stated_bounds():
    rows = [_row(), _row(rollout=1, palm_contact=True, palm_steps=5, palm_top_steps=2, palm_top_force_n=30.0,
                         palm_side_steps=4, palm_side_force_n=3.0, label=False, replay_label=False, relation="beside"),
            _row(rollout=2, press_weights=A.FORCE_WEIGHTS + 1, press_n=5.0 * (A.FORCE_WEIGHTS + 1),
                 max_penetration_m=A.PENETRATION_M * 2, speed_toy=A.MOVING_M_S * 1.5, replay_label=False),
            _row(rollout=3, press_weights=A.FORCE_WEIGHTS, press_n=5.0 * A.FORCE_WEIGHTS, max_penetration_m=A.PENETRATION_M,
                 speed_other=A.MOVING_M_S, peak_force_weights=50.0),  # on the bounds: not failures; an impact
            # (a one-step peak) above the bound is not a press
            _row(rollout=4, speed_other=1.0, held_other=True),  # a held object moves with the arm: no failure
            # 11 weights of a 100 g pair, under the floor (the least squeeze): not a failure
            _row(rollout=5, press_weights=11.0, press_n=11 * 0.981, weight_n=0.981),
            # the palm pushing an object from the side (move's sweep against a tall base): reported, not a failure
            _row(rollout=6, palm_contact=True, palm_steps=318, palm_side_steps=318, palm_side_force_n=41.6)]
    s = A.summarise(rows, "native")
    c = s["checks"]
    assert (c["palm_contact"]["count"], c["force"]["count"], c["penetration"]["count"], c["moving"]["count"]) == (1, 1, 1, 1)
    assert c["palm_contact"]["share"] == pytest.approx(1 / 7) and not c["palm_contact"]["pass"]
    assert c["palm_contact"]["side_count"] == 2 and c["palm_contact"]["side_share"] == pytest.approx(2 / 7)
    assert c["palm_contact"]["side_force_n"] == {"median": pytest.approx(22.3), "p95": pytest.approx(3.0 + 0.95 * 38.6),
                                                  "max": 41.6}
    assert c["palm_contact"]["top_force_n"]["max"] == 30.0 and c["palm_contact"]["palm_force_n"]["max"] == 0.0
    assert c["force"]["weights"] == {"median": 1.0, "p95": pytest.approx(np.quantile([1, 1, 11, 10, 1, 11, 1], 0.95)),
                                     "max": 11.0}
    assert s["by_label"]["negative"] == {"n": 1, "palm_contact": 1, "force": 0, "penetration": 0, "moving": 0}
    assert s["by_relation"]["on_top"]["n"] == 6
    assert s["replay"]["agree"] == 6 and s["replay"]["disagreements"] == [2]
    assert A.summarise([_row()], "native")["checks"]["force"]["pass"]
    # side only passes the palm check; one step from above fails it
    assert A.summarise([rows[6]], "native")["checks"]["palm_contact"]["pass"]
    assert not A.summarise([_row(palm_steps=1, palm_top_steps=1, palm_top_force_n=1.0)], "native")["checks"]["palm_contact"]["pass"]
    # a touch from above that carries no more than PALM_FORCE_N (a rim grazing the palm at 0 N) presses nothing
    for f in (0.0, A.PALM_FORCE_N):
        assert not A.failures(_row(palm_contact=True, palm_steps=1, palm_top_steps=1, palm_top_force_n=f))["palm_contact"]
    assert A.failures(_row(palm_contact=True, palm_steps=1, palm_top_steps=1, palm_top_force_n=0.6))["palm_contact"]
    assert A.PALM_FORCE_N < 9.81 * min(o.mass for o in lib.OBJECTS.values())  # under the lightest object's weight
    assert not A.failures(_row(palm_steps=3, palm_side_steps=3))["palm_contact"]
    json.dumps(s)  # serialisable as it is


def test_cli_one_line_errors(tmp_path):
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "x.txt").write_text("x")
    (tmp_path / "f.txt").write_text("x")
    for target, msg in ((tmp_path / "missing", "no such dataset or run folder"),
                        (tmp_path / "foreign", "not a relaff dataset"), (tmp_path / "f.txt", "not a folder")):
        p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "audit", str(target)], capture_output=True, text=True)
        assert p.returncode == 2, p.stderr
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("relaff audit: error: ") and msg in lines[0], p.stderr
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "audit", str(tmp_path), "--sample", "0"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.strip() == "relaff audit: error: --sample must be >= 1, got 0"
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "audit", str(tmp_path), "--jobs", "0"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.strip() == "relaff audit: error: --jobs must be >= 1, got 0"


ROLLOUT_KEYS = {"rollout", "toy", "other", "relation", "label", "replay_label", "plan_feasible", "resettled",
                "palm_contact", "palm_steps", "palm_seconds", "palm_force_n", "palm_top_steps", "palm_top_force_n",
                "palm_side_steps", "palm_side_force_n", "peak_force_n", "peak_force_weights",
                "peak_pair", "peak_step", "max_penetration_m", "held_penetration_m", "penetration_pair", "speed_toy", "speed_other",
                "held_toy", "held_other", "speed_end", "object_peak_n", "press_n", "weight_n", "press_weights"}
TOP_KEYS = {"version", "dataset", "action", "engine", "settle", "programs", "sample", "seed", "selection_sha256", "population",
            "n_audited", "thresholds", "rollouts", "checks", "by_label", "by_relation", "replay", "seconds"}


@pytest.mark.slow  # generates a small native dataset (plan compile) and replays it in C
def test_audit_of_a_native_dataset_reproduces_its_labels(tmp_path):
    """The replay of a native dataset reproduces every stored label and settled state exactly;
    the JSON has its schema; audit.json is written and reused; a run folder lists its datasets."""
    run = tmp_path / "run"
    d = run / "data" / "lift"
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "generate", "lift", "--samples", "6", "--out", str(d),
                        "--engine", "native", "--batch", "8", "--seed", "3"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "audit", str(run), "--json", "--sample", "5"],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    a = json.loads(p.stdout)
    assert set(a) == TOP_KEYS and a["version"] == A.AUDIT_VERSION and a["engine"] == "native"
    assert set(a["checks"]) == {"palm_contact", "force", "penetration", "moving"}
    assert all({"count", "share", "pass"} <= set(c) for c in a["checks"].values())
    assert 1 <= a["n_audited"] == len(a["rollouts"]) <= 5 and all(set(r) == ROLLOUT_KEYS for r in a["rollouts"])
    assert a["replay"]["label_agreement"] == 1.0 and a["replay"]["resettled"] == a["n_audited"]
    assert a["replay"]["plan_feasible"] == a["n_audited"]
    assert all(r["peak_force_weights"] >= 0.9 for r in a["rollouts"])  # everything rests on something
    assert all(r["press_weights"] >= 0.9 and r["object_peak_n"] >= r["press_n"] for r in a["rollouts"])
    stored = json.loads((d / A.AUDIT_FILE).read_text())
    assert stored == a and A.stored_audit(d, 5, 0) == a and A.stored_audit(d, 6, 0) is None
    p = subprocess.run([sys.executable, "-m", "relaff_jax.cli", "audit", str(d), "--sample", "5"],
                       capture_output=True, text=True)  # the stored audit, as a table
    rows = [x for x in p.stdout.splitlines() if x.startswith("lift ")]
    assert p.returncode == 0 and len(rows) == 1 and "100%" in rows[0], p.stdout


def test_report_section_plots_the_press_against_the_bound(tmp_path):
    from relaff_jax.report import audit as RA

    rows = [_row(), _row(rollout=1, press_weights=A.FORCE_WEIGHTS * 2, press_n=5.0 * A.FORCE_WEIGHTS * 2)]
    a = dict(action="lift", engine="native", n_audited=2, population=2, rollouts=rows, **A.summarise(rows, "native"))
    blocks = RA.audit_blocks({"lift": a}, {}, tmp_path)
    assert (tmp_path / RA.F.FIG_AUDIT).is_file()
    text = " ".join(str(b[1]) for b in blocks if b[0] == "p")
    assert "held over 0.1 s" in text and f"{1000 * A.PENETRATION_M:g} mm" in text
    assert "FAIL force" in A.format_audit([a])
    # the palm: above / side, the bound on the first; a side push alone does not fail
    rows.append(_row(rollout=2, palm_contact=True, palm_steps=45, palm_side_steps=45, palm_side_force_n=4.7))
    a = dict(action="lift", engine="native", n_audited=3, population=3, rollouts=rows, **A.summarise(rows, "native"))
    table = A.format_audit([a])
    assert "palm above/side" in table and " 0%/33% " in table and "FAIL force" in table and "palm_contact" not in table
    assert "side contacts are reported, not checked" in table and f"more than {A.PALM_FORCE_N:g} N" in table
    blocks = RA.audit_blocks({"lift": a}, {}, tmp_path)
    (_, header, body), = [b for b in blocks if b[0] == "table"]
    assert body[0][header.index("palm above")] == "0 %" and body[0][header.index("palm side (max N)")] == "33 % (4.7)"
    text = " ".join(str(b[1]) for b in blocks if b[0] == "p")
    assert f"within {A.PALM_ABOVE_DEG:g} degrees of vertical" in text


@pytest.mark.parametrize("programs", ["v1", "v2"])
def test_audit_rebuilds_the_recorded_programs(programs):
    """A dataset records v1 by the absence of ``programs`` (``templates.stored_config``); the
    audit's replay config is the one that made the labels, not the default (v2)."""
    import dataclasses

    from relaff_jax.config.action import ActionConfig
    from relaff_jax.sim.templates import stored_config

    cfg = dataclasses.replace(ActionConfig(), programs=programs)
    record = json.loads(json.dumps(stored_config(cfg)))  # as the sidecar stores it
    assert ("programs" in record) == (programs == "v2")
    assert A.action_config({"action": "lift", "config": {"action_config": record}}) == cfg
