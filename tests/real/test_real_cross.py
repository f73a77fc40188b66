"""Sim-to-real across folders: grouped splits, cross-folder figures on a hand-worked
case, the simulated-data guard on a killed build, and a train/test study through the CLI on
the shipped scenes split in two (settle + perceive replaced by a stand-in)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from relaff_jax import cli
from relaff_jax.errors import UserError
from relaff_jax.real import splits
from relaff_jax.config.real import RealExperimentConfig, SensorTolerance, SimRelationConfig, SimSensor

from helpers import OSD, ROOT



def test_scene_splits_never_put_a_scene_on_both_sides():
    rng = np.random.default_rng(0)
    scene = np.repeat([f"s{i}" for i in range(30)], rng.integers(1, 4, 30))  # 1-3 pairs per scene
    y = (rng.random(len(scene)) < 0.3).astype(int)
    sz = splits.split_sizes(y, 0.625)
    out, n_train = splits.scene_splits(y, scene, sz, seed=3, reps=40)
    assert 1 <= n_train <= sz["train"]
    assert len(out) == 40
    for tr, te in out:
        assert not set(scene[tr]) & set(scene[te])
        assert len(tr) == 2 * n_train
        assert len(te) == 2 * sz["test"]
        assert y[tr].tolist() == [1, 0] * n_train  # interleaved: its first n are balanced
        assert y[te].sum() == sz["test"]
    # a new grouping per repetition, the same ones for the same seed
    assert len({tuple(sorted(set(scene[te]))) for _, te in out}) > 10
    again, _ = splits.scene_splits(y, scene, sz, seed=3, reps=40)
    assert all((a[0] == b[0]).all() for a, b in zip(out, again))
    assert all((a[1] == b[1]).all() for a, b in zip(out, again))
    # every on_top pair in one scene: no split by scene can test on them and train on them too
    y2, sc2 = np.array([1, 1, 1, 0, 0, 0, 0]), np.array(["a", "a", "a", "b", "c", "d", "e"])
    with pytest.raises(UserError, match="split by scene needs whole scenes.*1 with on_top"):
        splits.scene_splits(y2, sc2, splits.split_sizes(y2, 0.625), 0, 5)


def _states(x):
    """PCA states carrying the relation in one column (x) and nothing elsewhere."""
    pca = np.zeros((len(x), 18), np.float32)
    pca[:, 0] = x
    return pca


def test_cross_folder_figures_by_hand():
    """Training folder, simulation: on_top at x = 10, beside at x = 0. Test folder: 3 beside at
    x = 0, 2 on_top, one at x = 10 and one at x = 0 (looks beside). Every classifier then calls
    the test pairs by x: beside 3 of 3 right, on_top 1 of 2, balanced accuracy (1 + 1/2) / 2 =
    0.75 at every repetition (the bootstrap input, SIM_full's prediction, says the same), so
    bf = (0.75 - 0.5) / (0.75 - 0.5) = 1; REAL trains on all 3 on_top + 3 of 4 beside."""
    y_tr = np.array([0, 1, 0, 1, 0, 1, 0])
    real = dict(pca=_states(10.0 * y_tr), rhf=np.zeros((7, 300), np.float32), y=y_tr,
                scene=np.array([f"t{i}" for i in range(7)]))
    y_te = np.array([0, 0, 0, 1, 1])
    test = dict(pca=_states([0, 0, 0, 10, 0]), rhf=np.zeros((5, 300), np.float32), y=y_te,
                scene=np.array(["u0", "u0", "u1", "u2", "u3"]))
    rel = np.r_[np.zeros(12, int), np.ones(12, int), np.full(3, 2)]
    sim = dict(pca=_states(10.0 * (rel == 1)), rhf=np.zeros((27, 300), np.float32), relation=rel)
    from relaff_jax.real import experiments as ex

    cfg = RealExperimentConfig(reps=3, trees=10, n_full=8, n_boot=100)
    res = ex.run_space(real, sim, "pca", cfg, test=test)
    for k in ("real", "fair_to_real", "full_to_real"):
        np.testing.assert_allclose(res[k], 0.75)
    np.testing.assert_allclose(res["sim_fair"], 1.0)
    np.testing.assert_allclose(res["sim_full"], 1.0)
    assert res["sizes"].tolist() == [2, 3, 4, 5, 6]
    assert str(res["kind"]) == "cross"
    np.testing.assert_allclose(res["curve_sl"][2:], 0.75)  # n >= 4: both classes twice
    np.testing.assert_allclose(res["curve_bl"][2:], 0.75)
    assert res["split"].tolist() == [3, 3, 5, 6, 8]
    assert res["test_counts"].tolist() == [3, 2]
    s = ex.summarise(res, cfg)
    assert s["accuracy"]["real"]["ci95"] == pytest.approx((0.75, 0.75))
    np.testing.assert_allclose([b for b in s["bf"][2:]], 1.0)
    assert s["split"]["kind"] == "cross"
    assert s["split"]["real_test_counts"] == [3, 2]
    # test scenes resampled: beside always right, on_top right in 0, 1/2 or all of a resample's
    # on_top pairs, so the balanced accuracy lies in [0.5, 1]; both ends are reachable
    assert s["accuracy"]["real"]["ci95_scenes"] == pytest.approx((0.5, 1.0))
    # the curves' hits at n >= 4 are those of REAL, so bf = 1 in every resample that defines it
    assert res["hits_curve_sl"].shape == (5, 3, 5)
    np.testing.assert_array_equal(res["hits_curve_bl"][2:], res["hits_real"][None].repeat(3, 0))
    with pytest.raises(UserError, match="test folder needs >= 1 pair of each relation"):
        ex.run_space(real, sim, "pca", cfg, test=dict(test, y=np.zeros(5, int)))


def _fake_chunks(calls, stop_after=None):
    """Stand-in for settle + perceive: chunk c keeps 2 beside, 2 on_top, 1 inside scene whose
    PCA x is 10 on top; ``stop_after``: the build is killed once that many chunks are written."""
    def fake_chunk_fn(world, sensor, cfg, perception=None):
        def run(c):
            if stop_after is not None and c >= stop_after:
                raise KeyboardInterrupt
            calls.append((c, sensor))
            rel = np.array([0, 0, 1, 1, 2])
            return dict(pca=_states(10.0 * (rel == 1)), rhf=np.zeros((5, 300), np.float32), relation=rel,
                        pair=np.zeros(5, int), scene_id=c * cfg.chunk + np.arange(5), dropped=np.array([0, 3, 0]))
        return run
    return fake_chunk_fn


def test_guard_on_a_killed_build(tmp_path, monkeypatch):
    from relaff_jax.real import sim_relations as sr

    monkeypatch.setattr("relaff_jax.sim.world.build_world", lambda: None)
    cfg = SimRelationConfig(per_relation=6, chunk=8, feature_batch=8)
    a, b = SimSensor(0.59, 50.8, 49.1), SimSensor(0.59, 44.0, 49.1)
    calls = []
    monkeypatch.setattr(sr, "_chunk_fn", _fake_chunks(calls, stop_after=1))
    with pytest.raises(KeyboardInterrupt):  # killed after its first chunk
        sr.build_sim_relations(tmp_path / "sim", a, cfg, progress=False)
    assert [p.name for p in sorted((tmp_path / "sim").iterdir())] == ["chunk_00000.npz", "sim_relations.json"]
    monkeypatch.setattr(sr, "_chunk_fn", _fake_chunks(calls))
    with pytest.raises(UserError, match=r"another sensor \(tilt_deg 50.8 vs 44.0 \(\|diff\| 6.8 > tolerance 2.5\)"):
        sr.build_sim_relations(tmp_path / "sim", b, cfg, progress=False)
    # within the tolerance (2 mm, 2 deg: an unseen folder): resumed with the folder's own sensor
    near = SimSensor(0.588, 48.8, 49.1)
    s = sr.build_sim_relations(tmp_path / "sim", near, cfg, progress=False)
    assert [c for c, _ in calls] == [0, 1, 2]
    assert {x for _, x in calls} == {a}
    assert s["sensor"]["tilt_deg"] == 50.8
    assert s["status"] == "complete"
    assert s["counts"]["on_top"] == 6
    with pytest.raises(UserError, match="another sensor"):  # tolerance 0 asks for the exact sensor
        sr.guard(tmp_path / "sim", near, cfg, SensorTolerance(0.0, 0.0, 0.0))
    # chunks without a guard (a build from before the guard): which sensor made them is unknown
    (tmp_path / "old").mkdir()
    shutil.copy(tmp_path / "sim" / "chunk_00000.npz", tmp_path / "old")
    with pytest.raises(UserError, match="no sim_relations.json, so which sensor made them is unknown"):
        sr.build_sim_relations(tmp_path / "old", a, cfg, progress=False)


def _label_files(tmp_path):
    """The three shipped scenes cut in two folders. The relations are made up where the hand
    labels would not give both relations on each side (the check is of the plumbing):
    A = learn0 (2-3 beside), learn34 (2-3 on_top, 2-4 beside, 3-4 on_top);
    B = learn17 (3-2 on_top, the hand label) and a copy of learn0 (2-3 beside)."""
    from relaff_jax.real import labels as lab

    a, b = tmp_path / "A", tmp_path / "B"
    a.mkdir(), b.mkdir()
    for src, dst in (("learn0", a / "learn0.pcd"), ("learn34", a / "learn34.pcd"), ("learn17", b / "learn17.pcd"),
                     ("learn0", b / "copy_learn0.pcd")):
        shutil.copy(OSD / f"{src}.pcd", dst)
    sha = {p.name: lab.file_sha256(p) for p in (a / "learn0.pcd", a / "learn34.pcd", b / "learn17.pcd")}
    rows = [lab.Label("learn0.pcd", 2, 3, "beside", sha["learn0.pcd"]),
            lab.Label("learn34.pcd", 2, 3, "on_top", sha["learn34.pcd"]),
            lab.Label("learn34.pcd", 2, 4, "beside", sha["learn34.pcd"]),
            lab.Label("learn34.pcd", 3, 4, "on_top", sha["learn34.pcd"]),
            lab.Label("learn17.pcd", 3, 2, "on_top", sha["learn17.pcd"]),
            lab.Label("copy_learn0.pcd", 2, 3, "beside", sha["learn0.pcd"])]
    both = lab.write_labels(tmp_path / "both.csv", rows)  # one file for both folders: --only-present
    return a, b, both


def test_train_test_study_through_the_cli(tmp_path, monkeypatch, capsys):
    from relaff_jax.real import sim_relations as sr

    a, b, labels = _label_files(tmp_path)
    calls = []
    monkeypatch.setattr(sr, "_chunk_fn", _fake_chunks(calls))
    monkeypatch.setattr("relaff_jax.sim.world.build_world", lambda: None)
    out = tmp_path / "study"
    base = ["real", "study", str(a), "--labels", str(labels), "--test", str(b), "--test-labels", str(labels),
            "--out", str(out), "--spaces", "pca", "--reps", "2", "--trees", "5", "--n-full", "4",
            "--per-relation", "4", "--chunk", "8", "--set", "real.sim.feature_batch=8"]
    assert cli.main(base + ["--split", "pair"]) == 2  # the labels name scenes the folders lack
    assert "unknown scene" in capsys.readouterr().err
    assert cli.main(base + ["--split", "pair", "--only-present"]) == 0
    printed = capsys.readouterr().out
    assert "pca claim d)" in printed and "(CI " in printed  # intervals and verdicts in the terminal
    res = json.loads((out / "results.json").read_text())
    # the per-pair error table: every listed pair is a test folder pair, wrong in some repetition
    for row in res["cross"]["pca"]["pair_errors"]:
        assert row["relation"] in ("beside", "on_top") and max(v or 0 for v in row["wrong"].values()) > 0
        assert row["tested"]["real"] == 2
    assert res["claims_decided_on"] == "cross"
    assert res["summary"]["pca"]["split"]["kind"] == "pair"
    cross = res["cross"]["pca"]
    assert cross["split"]["kind"] == "cross"
    assert cross["split"]["real_test_counts"] == [1, 1]
    assert cross["split"]["real_train_per_class"] == 2
    assert cross["sizes"] == [2, 3, 4]
    # by hand: one beside and one on_top test pair, so each balanced accuracy is 0, 0.5 or 1
    raw = np.load(out / "raw_pca_cross.npz")
    for k in ("real", "fair_to_real", "full_to_real"):
        assert set(np.round(raw[k] * 2).tolist()) <= {0.0, 1.0, 2.0}
        assert cross["accuracy"][k]["mean"] == pytest.approx(raw[k].mean())
    sensor = json.loads((out / "sensor.json").read_text())
    assert sensor["source"].startswith("the training folder")
    assert sensor["scenes"] == 2
    assert sensor["test"]["scenes"] == 2
    assert sensor["simulated"]["height"] == sensor["height"]
    md = (out / "results.md").read_text()
    assert "| PCA | REAL |" in md
    assert "across folders (test folder)" in md
    assert "4 labelled scenes" not in md
    assert "2 labelled scenes not in the folder skipped" in md
    assert {p.name for p in out.glob("fig1*_pca*.png")} == {"fig14_pca.png", "fig15_pca.png", "fig14_pca_cross.png",
                                                          "fig15_pca_cross.png"}
    assert len(calls) == 2  # 4 on_top scenes at 2 a chunk
    # the real features of both folders are kept; a rerun skips every step
    assert np.load(out / "real_features_test.npz")["y"].tolist() == [1, 0]
    capsys.readouterr()
    assert cli.main(base + ["--split", "pair", "--only-present"]) == 0
    assert len(calls) == 2


def test_config_and_inputs_are_checked_first(tmp_path, monkeypatch, capsys):
    from relaff_jax.real import real_data

    monkeypatch.setattr(real_data, "scene_poses", lambda *a, **k: (_ for _ in ()).throw(AssertionError("work")))
    a, b, labels = _label_files(tmp_path)
    argv = ["real", "study", str(a), "--labels", str(labels), "--out", str(tmp_path / "s"), "--only-present"]
    assert cli.main(argv + ["--set", "real.experiment.splt=pair"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("relaff real study: error: unknown config key 'real.experiment.splt'")
    assert "split" in err
    assert cli.main(argv + ["--set", "real.experiment.split=scenes"]) == 2
    assert "config key 'real.experiment.split' must be one of scene, pair, got 'scenes'" in capsys.readouterr().err
    # a flag is an alias of its tree key: a --set of the same key that disagrees is refused
    assert cli.main(argv + ["--reps", "5", "--set", "real.experiment.reps=7"]) == 2
    assert "--reps 5 and --set real.experiment.reps=7 disagree" in capsys.readouterr().err
    assert cli.main(argv + ["--seed", "1", "--set", "real.sim.seed=2"]) == 2
    assert "--seed 1 and --set real.sim.seed=2 disagree" in capsys.readouterr().err
    assert cli.main(argv + ["--test", str(b)]) == 2
    assert "--test needs --test-labels" in capsys.readouterr().err
    # A's scenes cannot be cut by scene with both relations on both sides (the within-folder figures)
    assert cli.main(argv + ["--test", str(b), "--test-labels", str(labels)]) == 2
    assert "split by scene needs whole scenes" in capsys.readouterr().err
    only_beside = tmp_path / "beside.csv"
    only_beside.write_text("\n".join(x for x in labels.read_text().splitlines() if "on_top" not in x) + "\n")
    assert cli.main(argv + ["--split", "pair", "--test", str(b), "--test-labels", str(only_beside)]) == 2
    assert "the test folder needs >= 1 pair of each relation, have 1 beside and 0 on_top" in capsys.readouterr().err
    assert cli.main(["real", "segment", str(a), "--set", "real.pipeline.kmeans.k=true"]) == 2
    assert "expects an integer" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_check_only_present(capsys):
    shipped = ROOT / "scenes" / "osd_learn_relations.csv"
    assert cli.main(["real", "check", str(OSD), "--labels", str(shipped)]) == 2
    assert "unknown scene 'learn1.pcd'" in capsys.readouterr().err
    assert cli.main(["real", "check", str(OSD), "--labels", str(shipped), "--only-present"]) == 0
    assert "valid; 4 beside, 1 on_top in 3 scenes; 42 labelled scenes not in" in capsys.readouterr().out


def test_claim_d_is_undefined_when_bf_mostly_is():
    """The real learner at chance (P_sl <= 0.5) at most early sizes: bf is undefined there, and a
    mean over the one size left is not a verdict (C -> D of docs/real.md section 9)."""
    from relaff_jax.real import experiments as ex
    from relaff_jax.real import report

    sizes = np.arange(2, 8)  # early: n = 2..4
    sl = np.tile(np.array([0.5, 0.45, 0.6, 0.7, 0.8, 0.8])[:, None], (1, 4))
    bl = np.tile(np.array([0.7, 0.7, 0.9, 0.8, 0.8, 0.8])[:, None], (1, 4))
    res = dict(sim_fair=np.ones(4), sim_full=np.ones(4), real=np.full(4, 0.5), fair_to_real=np.ones(4),
               full_to_real=np.full(4, 0.6), curve_sl=sl, curve_bl=bl, sizes=sizes, split=np.array([8, 5, 3, 10, 60]))
    s = ex.summarise(res, RealExperimentConfig(n_boot=50, bf_sizes=(2, 4)))
    assert s["bf_early_sizes"] == [2, 3, 4]
    assert s["bf_undefined_sizes"] == [2, 3]
    assert s["bf_early_mean"] == pytest.approx(4.0)
    d = [c for c in report.claims({"pca": s}) if c["claim"].startswith("d)")][0]
    assert d["holds"] is None and d["verdict"] == "not measurable"
    assert "defined at 1 of 3" in d["numbers"]
    assert "| undefined |" in report.markdown({"pca": s}, {})
    # the default window is the paper's early range in training sizes, whatever the folder's size
    assert ex.summarise(res, RealExperimentConfig(n_boot=50))["bf_early_sizes"] == [4, 5, 6, 7]
    res2 = dict(res, curve_sl=np.tile(np.linspace(0.6, 0.9, 40)[:, None], (1, 4)),
                curve_bl=np.tile(np.linspace(0.8, 0.95, 40)[:, None], (1, 4)), sizes=np.arange(2, 42))
    assert ex.summarise(res2, RealExperimentConfig(n_boot=50))["bf_early_sizes"] == list(range(4, 26))


def test_real_claims_decided_by_intervals():
    """Every claim is decided by an interval: claim d holds when the window's bf interval is
    above 1, is undecided when it straddles 1, in either space."""
    from relaff_jax.real import experiments as ex
    from relaff_jax.real import report

    assert report.decide((1.02, 1.3), 1.0, True) == "holds"
    assert report.decide((0.9, 1.3), 1.0, True) == "undecided"
    assert report.decide((0.5, 0.9), 1.0, True) == "does not hold"
    assert report.decide(None, 1.0, True) == "not measurable"
    rng = np.random.default_rng(0)
    sizes = np.arange(2, 12)
    sl = 0.6 + 0.02 * np.arange(10)[:, None] + 0.01 * rng.standard_normal((10, 8))
    res = dict(sim_fair=np.full(8, 0.9) + 0.01 * rng.standard_normal(8), sim_full=np.ones(8),
               real=np.full(8, 0.85) + 0.02 * rng.standard_normal(8), fair_to_real=np.ones(8),
               full_to_real=np.full(8, 0.9), curve_sl=sl, curve_bl=sl + 0.1, sizes=sizes,
               split=np.array([8, 5, 3, 10, 60]))
    cfg = RealExperimentConfig(n_boot=200)
    s = ex.summarise(res, cfg)
    for space in ("pca", "rhf"):
        by = {c["claim"][:2]: c["verdict"] for c in report.claims({space: s}, space)}
        assert by["d)"] == "holds" and by["a)"] == "holds" and by["b)"] == "holds"
    flat = dict(res, curve_bl=sl + 0.02 * rng.standard_normal(sl.shape))  # bf around 1
    s2 = ex.summarise(flat, cfg)
    d = [c for c in report.claims({"pca": s2}) if c["claim"].startswith("d)")][0]
    assert d["verdict"] in ("undecided", "does not hold")
    lines = report.terminal_lines({"pca": s})
    assert any("REAL 0.8" in x and "(CI " in x and "bf n = 4..25" in x for x in lines)
    assert any(x.startswith("pca claim d)") and "holds" in x for x in lines)


def test_voxel_size_set_reaches_a_real_study(tmp_path, monkeypatch):
    """``--set perception.voxel.size`` reaches the real features, the simulated chunks and the record."""
    import argparse

    from relaff_jax.cli.real import real_config
    from relaff_jax.real import labels as lab
    from relaff_jax.real import real_data
    from relaff_jax.real import sim_relations as sr
    from relaff_jax.config.real import pipeline_config

    a, _, labels = _label_files(tmp_path)
    calls, seen = [], []
    fake = _fake_chunks(calls)

    def chunk_fn(world, sensor, cfg, perception=None):
        seen.append(perception.voxel.size)
        return fake(world, sensor, cfg, perception)

    monkeypatch.setattr(sr, "_chunk_fn", chunk_fn)
    monkeypatch.setattr("relaff_jax.sim.world.build_world", lambda: None)
    out = tmp_path / "study"
    assert cli.main(["real", "study", str(a), "--labels", str(labels), "--out", str(out), "--spaces", "pca",
                     "--reps", "2", "--trees", "5", "--n-full", "4", "--per-relation", "4", "--chunk", "8",
                     "--split", "pair", "--only-present", "--set", "real.sim.feature_batch=8",
                     "--set", "perception.voxel.size=0.03"]) == 0
    assert seen == [0.03]
    rows, _ = lab.present(lab.read_labels(labels), a)
    tree = real_config(argparse.Namespace(set=["perception.voxel.size=0.03"]))
    stored = np.load(out / "real_features.npz")["pca"]
    np.testing.assert_array_equal(stored, real_data.real_features(a, rows, pipeline_config(tree), False)["pca"])
    default = real_data.real_features(a, rows, pipeline_config(real_config(argparse.Namespace(set=[]))), False)
    assert not np.array_equal(stored, default["pca"])
    assert json.loads((out / "relaff_config.json").read_text())["config"]["perception"]["voxel"]["size"] == 0.03
    assert json.loads((out / "sim" / "sim_relations.json").read_text())["perception"]["voxel_size"] == 0.03


def test_pair_error_table_hand_made():
    """Per pair: the share of the repetitions that tested it in which a classifier was wrong."""
    from relaff_jax.real import experiments as ex
    from relaff_jax.real import report

    nan = np.nan
    res = dict(sim_fair=np.ones(4), sim_full=np.ones(4), real=np.full(4, 0.8), fair_to_real=np.ones(4),
               full_to_real=np.full(4, 0.9), curve_sl=np.full((3, 4), 0.7), curve_bl=np.full((3, 4), 0.8),
               sizes=np.arange(2, 5), split=np.array([8, 5, 3, 10, 60]),
               pairs_scene=np.array(["s1", "s1", "s2"]), pairs_ab=np.array(["1,2", "2,3", "1,2"]),
               pairs_y=np.array([True, False, False]),
               pairs_real=np.array([[1, nan, 1], [0, nan, 1], [nan, 1, 1], [nan, 1, 1]], float),
               pairs_fair_to_real=np.ones((4, 3)),
               pairs_full_to_real=np.array([[1, 0, 1], [1, 0, 1], [1, 1, 1], [1, 0, 1]], float))
    rows = ex.summarise(res, RealExperimentConfig(n_boot=20))["pair_errors"]
    assert [(r["scene"], r["pair"], r["relation"]) for r in rows] == [("s1", "2,3", "beside"), ("s1", "1,2", "on_top")]
    assert rows[0]["wrong"] == {"real": 0.0, "fair_to_real": 0.0, "full_to_real": 0.75}
    assert rows[1]["wrong"]["real"] == 0.5 and rows[1]["tested"]["real"] == 2
    md = "\n".join(report.pair_error_lines({"pair_errors": rows}))
    assert "| s1 | 2,3 | beside | 0.00 (2) | 0.00 (4) | 0.75 (4) |" in md
