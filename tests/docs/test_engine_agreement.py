"""``benchmarks/engine_agreement.py`` without MJX: its config, its comparison of two engines'
outcomes on a hand-made batch, its resume through ``--json`` and its refusals."""
from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import engine_agreement as E  # noqa: E402
from relaff_jax.config.constraints import ConfigError  # noqa: E402
from relaff_jax.io import atomic_write_json, read_json  # noqa: E402
from relaff_jax.sim.scenes import RELATIONS  # noqa: E402


def test_action_config_takes_action_keys_only():
    assert E.action_config([]).programs == "v4"
    assert E.action_config(["action.programs=v1"]).programs == "v1"
    with pytest.raises(ValueError, match="action.\\* keys only"):
        E.action_config(["programs=v1"])
    with pytest.raises(ConfigError, match="action.nope"):
        E.action_config(["action.nope=1"])


def _batch():
    """Four scenes, the second infeasible; the engines' labels differ on the third (a lift:
    MJX lifts the toy 6 cm, C 1 cm)."""
    com0 = np.zeros((4, 2, 3))
    com_m = {"mjx": com0.copy(), "native": com0.copy()}
    com_m["mjx"][2, 0, 2], com_m["native"][2, 0, 2] = 0.06, 0.01
    out = {e: {"label": np.array(lab), "com0": com0, "com_m": com_m[e], "com_end": com0}
           for e, lab in (("mjx", [True, False, True, False]), ("native", [True, True, False, False]))}
    prep = SimpleNamespace(plan=SimpleNamespace(feasible=np.array([True, False, True, True]),
                                                direction=np.tile([1.0, 0, 0], (4, 1))),
                           scenes=SimpleNamespace(relation=np.array([0, 1, 2, 0])),
                           names=np.array([["toy", "cup"]] * 4))
    return prep, out


def test_compare_counts_feasible_rows_and_records_each_difference():
    prep, out = _batch()
    labels, differ = E.compare(prep, out, "lift", E.action_config([]), batch_index=3)
    # the infeasible row 1 is not counted although the labels differ there
    assert labels == {"mjx": [True, True, False], "native": [True, False, False]}
    assert len(differ) == 1
    d = differ[0]
    assert (d["batch"], d["row"], d["relation"], d["mjx"], d["native"]) == (3, 2, RELATIONS[2], True, False)
    assert d["mjx_q"]["rise"] == pytest.approx([6.0, 0.0]) and d["native_q"]["rise"] == pytest.approx([1.0, 0.0])
    assert d["kind"] == "grasp"  # the lift threshold (5 cm) lies between the two rises
    row = E.summary(labels, differ, scenes=64)
    assert row["feasible"] == 3 and row["agree"] == 2 and row["positives"] == {"mjx": 2, "native": 1}


def test_json_resumes_finished_actions_only_for_the_same_setting(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(E.compile_cache, "configure", lambda disable=False: None)
    row = dict(E.summary({"mjx": [True, False], "native": [True, True]}, [], 64),
               seconds={"prepare": 1.0, "mjx": 2.0, "native": 0.5})
    calls = []
    monkeypatch.setattr(E, "action_row", lambda action, n, batch, seed, cfg: calls.append((action, cfg.programs)) or row)
    js = tmp_path / "a.json"
    setting = dict(n=8, seed=0, batch=64, programs="v4", set=[])
    atomic_write_json(js, {"setting": setting, "actions": {"lift": row}})
    E.main(["8", "lift", "take", "--json", str(js)])
    assert calls == [("take", "v4")]  # lift kept
    assert set(read_json(js)["actions"]) == {"lift", "take"}
    assert "lift       scenes   64 feasible    2 agree    1 (0.500)" in capsys.readouterr().out
    E.main(["8", "lift", "--json", str(js), "--set", "action.programs=v1"])  # another setting: redone
    assert calls[-1] == ("lift", "v1") and read_json(js)["setting"]["programs"] == "v1"


@pytest.mark.parametrize("argv, msg", [(["8", "lift", "jump"], "unknown action jump"),
                                       (["0", "lift"], "at least 1"),
                                       (["8", "--set", "seed=1"], "action.\\* keys only")])
def test_bad_input_exits_2_before_any_work(argv, msg, monkeypatch, capsys):
    monkeypatch.setattr(E.compile_cache, "configure", lambda disable=False: pytest.fail("work started"))
    with pytest.raises(SystemExit) as e:
        E.main(argv)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert e.value.code == 2 and "error:" in err
    assert __import__("re").search(msg, err)
