"""The four experiments of paper VI on synthetic feature sets whose answers are known, the
summaries (bootstrap interval, undefined bootstrap factors) and the report files."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from relaff_jax.errors import UserError
from relaff_jax.real import experiments as ex
from relaff_jax.real import report

from helpers import OSD


def synthetic(n, p_on_top, margin, seed=0):
    """Relation data separable in every PCA column: 0.1 N(0, 1) jitter plus ``margin`` times
    the label; RHF is uniform noise (its 300 columns carry nothing)."""
    rng = np.random.default_rng(seed)
    y = np.zeros(n, int)
    y[: int(round(p_on_top * n))] = 1
    y = rng.permutation(y)
    pca = (0.1 * rng.normal(size=(n, 18)) + margin * y[:, None]).astype(np.float32)
    rhf = rng.random((n, 300)).astype(np.float32)
    return pca, rhf, y


def make(real_n=24, real_p=0.34, sim_n=200, margin=5.0, seed=0):
    p, r, y = synthetic(real_n, real_p, margin, seed=seed)
    real = dict(pca=p, rhf=r, y=y, scene=np.asarray([f"s{i}.pcd" for i in range(real_n)]))  # a scene per pair
    p, r, y = synthetic(sim_n, 0.5, margin, seed=seed + 1)
    rel = np.where(y == 1, 1, 0)
    rel[:10] = 2  # inside scenes are left out of beside vs on top
    return real, dict(pca=p, rhf=r, relation=rel)


def test_split_sizes_and_balanced_accuracy():
    assert ex.split_sizes(np.r_[np.zeros(73), np.ones(14)], 0.625) == dict(pool=14, train=9, test=5)
    assert ex.split_sizes(np.r_[np.zeros(80), np.ones(80)], 0.625) == dict(pool=80, train=50, test=30)
    with pytest.raises(UserError, match="need >= 2 pairs of each relation"):
        ex.split_sizes(np.r_[np.zeros(5), np.ones(1)], 0.625)
    # 3 of 4 beside right, 1 of 2 on top right: (0.75 + 0.5) / 2
    assert ex.balanced_accuracy(np.array([0, 0, 0, 1, 1, 0]), np.array([0, 0, 0, 0, 1, 1])) == 0.625
    with pytest.raises(UserError, match="unknown space"):
        ex.states(dict(pca=np.zeros((1, 18)), rhf=np.zeros((1, 300))), "xyz")


def test_separable_data_give_accuracy_one():
    real, sim = make()
    cfg = ex.RealExperimentConfig(reps=3, n_full=60, trees=20)
    res = ex.run_space(real, sim, "pca", cfg)
    for k in ("sim_fair", "sim_full", "real", "fair_to_real", "full_to_real"):
        np.testing.assert_array_equal(res[k], 1.0)
    assert res["curve_sl"].shape == (len(res["sizes"]), 3)
    assert res["split"].tolist() == [8, 5, 3, 10, 60]
    s = ex.summarise(res, cfg)
    assert s["accuracy"]["real"] == dict(mean=1.0, std=0.0, ci95=(1.0, 1.0))
    assert s["split"]["real_train_per_class"] == 5


def test_sim_only_covers_inside():
    rng = np.random.default_rng(5)
    rel = np.repeat([0, 1, 2], [40, 30, 12])
    sim = {"pca": (0.1 * rng.normal(size=(82, 18)) + 3.0 * rel[:, None]).astype(np.float32),
           "rhf": np.zeros((82, 300), np.float32), "relation": rel}
    res = ex.run_sim_only(sim, "pca", ex.RealExperimentConfig(reps=2, n_full=20, trees=10))
    assert res["beside_vs_inside_n"] == 12
    assert res["beside_vs_on_top_n"] == 20  # min(n_full / 2, half the smaller)
    for pair in ("beside_vs_on_top", "beside_vs_inside", "on_top_vs_inside"):
        np.testing.assert_array_equal(res[pair], 1.0)


@pytest.mark.slow
def test_simulation_prediction_as_input_helps_early():
    """The real states carry the label weakly (0.3 against unit noise) in 17 columns and
    strongly in one, the simulated ones only in that one, so the SIM_full prediction is the
    label: repeated 6 times it is found at more splits than the one strong column, and the
    bootstrapped learner beats the standard one at small n (bf > 1)."""
    rng = np.random.default_rng(3)
    real, sim = make(real_n=40, real_p=0.5, sim_n=300, margin=5.0, seed=3)
    real["pca"][:] = rng.normal(size=(40, 18)) + 0.3 * real["y"][:, None]  # weak in the real states...
    real["pca"][:, 3] = 5.0 * real["y"]  # ...except one column, on which the simulation separates
    sim["pca"][:] = rng.normal(size=(300, 18))
    sim["pca"][:, 3] = 5.0 * (sim["relation"] == 1)
    cfg = ex.RealExperimentConfig(reps=6, n_full=100, trees=30, train_fraction=0.3)
    res = ex.run_space(real, sim, "pca", cfg)
    s = ex.summarise(res, cfg)
    np.testing.assert_array_equal(res["full_to_real"], 1.0)
    assert s["curve_bl"][0] > s["curve_sl"][0]
    assert s["bf_early_mean"] > 1.0


def test_summary_counts_undefined_bootstrap_factors():
    sizes = np.arange(2, 7)
    sl = np.tile(np.array([0.5, 0.4, 0.6, 0.7, 0.8])[:, None], (1, 4))
    bl = np.tile(np.array([0.7, 0.7, 0.8, 0.8, 0.8])[:, None], (1, 4))
    res = dict(sim_fair=np.ones(4), sim_full=np.ones(4), real=np.full(4, 0.8), fair_to_real=np.ones(4),
               full_to_real=np.array([0.6, 0.7, 0.8, 0.9]), curve_sl=sl, curve_bl=bl, sizes=sizes,
               split=np.array([8, 5, 3, 10, 60]))
    s = ex.summarise(res, ex.RealExperimentConfig(n_boot=500))
    assert s["bf_undefined_sizes"] == [2, 3]
    assert s["bf"][:2] == [None, None]
    np.testing.assert_allclose(s["bf"][2:], [3.0, 1.5, 1.0])
    lo, hi = s["accuracy"]["full_to_real"]["ci95"]
    assert 0.6 <= lo < 0.75 < hi <= 0.9
    assert s["accuracy"]["full_to_real"]["std"] == pytest.approx(np.std([0.6, 0.7, 0.8, 0.9], ddof=1))


@pytest.mark.slow
def test_report_files(tmp_path):
    real, sim = make()
    cfg = ex.RealExperimentConfig(reps=3, n_full=60, trees=10)
    raw = {"pca": ex.run_space(real, sim, "pca", cfg)}
    summary = {"pca": ex.summarise(raw["pca"], cfg)}
    paths = report.write_report(tmp_path, raw, summary, {"real pairs": "synthetic"})
    assert {p.name for p in paths} == {"fig14_pca.png", "fig15_pca.png", "results.json", "results.md"}
    doc = json.loads((tmp_path / "results.json").read_text())
    verdicts = {c["claim"][:2]: c["holds"] for c in doc["claims"]}
    assert verdicts["a)"]
    assert verdicts["b)"]
    assert verdicts["c)"]  # everything at accuracy 1
    assert "| REAL | 1.000 |" in (tmp_path / "results.md").read_text()


def test_too_few_simulated_scenes_is_a_user_error():
    real, sim = make(sim_n=40)
    with pytest.raises(UserError, match="SIM_full needs"):
        ex.run_space(real, sim, "pca", ex.RealExperimentConfig(reps=1, n_full=60))


# ---- the simulated sensor and the frames real and simulated scenes share -------------------

def test_sim_camera_sits_where_the_real_one_does():
    from relaff_jax.real import real_data
    from relaff_jax.real import sim_relations as sr
    from relaff_jax.real.scene_source import TARGET

    h, tilt = 0.59, 50.8
    cam = sr.perception_config(sr.SimSensor(h, tilt, 49.1), sr.SimRelationConfig()).camera
    np.testing.assert_allclose(cam.position, (TARGET[0] + h * np.tan(np.radians(tilt)), 0.0, h), atol=1e-9)
    assert cam.target == TARGET
    assert cam.vfov_deg == 49.1
    # a real camera with the same pose: table plane n . p + d = 0 in camera coordinates
    n = np.array([0.0, -np.sin(np.radians(tilt)), -np.cos(np.radians(tilt))])
    fr = real_data.sim_aligned_frame(np.r_[n, h])
    origin_cam = (np.zeros(3) - fr["origin"]) @ fr["rotation"].T  # the real camera, simulation frame
    np.testing.assert_allclose(origin_cam, cam.position, atol=1e-9)
    axis_hit = (np.array([0.0, 0.0, h / np.cos(np.radians(tilt))]) - fr["origin"]) @ fr["rotation"].T
    np.testing.assert_allclose(axis_hit, TARGET, atol=1e-9)


@pytest.mark.slow
def test_real_features_put_the_upper_object_first(tmp_path):
    from relaff_jax.real import labels as lab
    from relaff_jax.real import real_data

    osd = OSD
    rows = [lab.Label("learn17.pcd", 3, 2, "on_top", lab.file_sha256(osd / "learn17.pcd")),
            lab.Label("learn0.pcd", 2, 3, "beside", lab.file_sha256(osd / "learn0.pcd"))]
    path = lab.write_labels(tmp_path / "l.csv", rows)
    data = real_data.real_features(osd, path, progress=False)
    assert data["pca"].shape == (2, 18)
    assert data["rhf"].shape == (2, 300)
    assert data["y"].tolist() == [1, 0]  # scenes in the labels file's first-seen order: learn17 first
    on = data["y"] == 1
    assert data["pca"][on, 2] > data["pca"][on, 11] + 0.03  # centroid of a 3 cm above b's
    np.testing.assert_allclose(data["rhf"].reshape(2, 6, 50).sum(-1), 1.0, atol=1e-5)
    s = real_data.sensor(data)
    assert 0.55 < s.height < 0.65
    assert 30 < s.tilt_deg < 60
    assert abs(s.vfov_deg - 49.13) < 0.1


def test_sim_relations_build_resume_and_guard(tmp_path, monkeypatch):
    """The chunk loop (stop rule, resume, counts, guard) with the settle + perceive step
    replaced by a stand-in: chunk c keeps 2 beside, c on_top and 1 inside scenes and drops 3.
    (The real step costs ~1-2 min of compilation; ``relaff real study`` runs it, docs/real.md.)"""
    from relaff_jax.real import sim_relations as sr

    calls = []

    def fake_chunk_fn(world, sensor, cfg, perception=None):
        def run(c):
            calls.append(c)
            rel = np.array([0, 0] + [1] * c + [2])
            n = len(rel)
            return dict(pca=np.full((n, 18), c, np.float32), rhf=np.zeros((n, 300), np.float32), relation=rel,
                        pair=np.zeros(n, int), scene_id=c * cfg.chunk + np.arange(n), dropped=np.array([0, 2, 1]))
        return run

    monkeypatch.setattr(sr, "_chunk_fn", fake_chunk_fn)
    monkeypatch.setattr("relaff_jax.sim.world.build_world", lambda: None)
    sensor = sr.SimSensor(0.59, 50.8, 49.1)
    cfg = sr.SimRelationConfig(per_relation=3, chunk=8, feature_batch=8)
    s = sr.build_sim_relations(tmp_path / "sim", sensor, cfg, progress=False)
    assert calls == [0, 1, 2]  # on_top 0, 1, 3: stops once beside (6) and on_top (3) reach 3
    assert s["counts"] == {"beside": 6, "on_top": 3, "inside": 3}
    assert s["dropped"] == {"not_at_rest": 0, "unseen": 6, "overflow": 3}
    assert s["scenes"] == 24
    data = sr.load_sim_relations(tmp_path / "sim")
    assert data["pca"].shape == (12, 18)
    assert data["relation"].tolist().count(1) == 3
    again = sr.build_sim_relations(tmp_path / "sim", sensor, dataclasses.replace(cfg, per_relation=4), progress=False)
    assert calls == [0, 1, 2, 3]
    assert again["counts"]["on_top"] == 6
    assert again["chunks_timed"] == 4  # resumed
    with pytest.raises(UserError, match=r"another sensor \(height 0.59 vs 0.8 .*tilt_deg 50.8 vs 40.0"):
        sr.build_sim_relations(tmp_path / "sim", sr.SimSensor(0.8, 40.0), cfg, progress=False)
    with pytest.raises(UserError, match="another config .seed 0 there, 1 asked"):
        sr.build_sim_relations(tmp_path / "sim", sensor, dataclasses.replace(cfg, seed=1), progress=False)
    with pytest.raises(UserError, match="no simulated relation chunks"):
        sr.load_sim_relations(tmp_path / "empty")
    with pytest.raises(UserError, match="must be a multiple of real.sim.feature_batch"):
        sr.build_sim_relations(tmp_path / "sim2", sensor, dataclasses.replace(cfg, feature_batch=3), progress=False)
