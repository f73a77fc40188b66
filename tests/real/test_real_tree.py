"""The real stages read the one config tree: ``--set perception.voxel.size`` reaches the real
features, bad real settings are refused before any work."""
from __future__ import annotations

import argparse

import jax
import numpy as np
import pytest

from relaff_jax.cli import real as cli_real
from relaff_jax.errors import UserError
from relaff_jax.real.cloud_features import cloud_normals, pair_features
from relaff_jax.real.segment import fit_table_plane, hand_segmentation
from relaff_jax.real.readers import read_cloud
from relaff_jax.real.frame import table_frame, to_table, vectors_to_table
from relaff_jax.config.real import REAL_MAX_OBJECT_PIXELS, RealConfig, pipeline_config

from helpers import OSD

DATA = OSD


def _tree(*sets):
    return cli_real.real_config(argparse.Namespace(set=list(sets)))


def test_default_tree_gives_the_old_real_config():
    assert pipeline_config(_tree()) == RealConfig()
    assert RealConfig().perception.voxel.max_object_pixels == REAL_MAX_OBJECT_PIXELS


def test_voxel_size_set_on_the_tree_reaches_the_real_features():
    size = 0.03
    cfg = pipeline_config(_tree(f"perception.voxel.size={size}"))
    assert cfg.perception.voxel.size == size
    c = read_cloud(DATA / "learn17.pcd")
    hand = hand_segmentation(c.label)
    frame = table_frame(fit_table_plane(c.xyz[c.valid], jax.random.key(0))["plane"])
    pts = [to_table(c.xyz[(hand == i) & c.valid].astype(np.float64), frame) for i in (2, 3)]
    nrm = [vectors_to_table(cloud_normals(c.xyz[(hand == i) & c.valid].astype(np.float64), 20), frame) for i in (2, 3)]
    f = pair_features(pts[0], nrm[0], pts[1], nrm[1], cfg)
    for o, p in enumerate(pts):
        # Open3D's grid: origin at the min bound - size / 2, voxel floor((p - origin) / size)
        idx = np.floor((p - (p.min(0) - size / 2)) / size).astype(np.int64)
        assert int(f["n_points"][o]) == len(np.unique(idx, axis=0))
    default = pair_features(pts[0], nrm[0], pts[1], nrm[1], pipeline_config(_tree()))
    assert int(default["n_points"][0]) > int(f["n_points"][0])


@pytest.mark.parametrize("setting, words", [
    ("perception.voxel.size=-1", "voxel"),
    ("real.pipeline.kmeans.k=1", "kmeans.k"),
    ("real.experiment.split=halves", "real.experiment.split"),
    ("real.pipeline.max_object_pixels=0", "real.pipeline.max_object_pixels"),
])
def test_bad_real_setting_refused_before_any_work(setting, words, tmp_path, monkeypatch):
    import relaff_jax.real.stages as stages

    def fail(*a, **k):
        raise AssertionError("the study started")

    monkeypatch.setattr(stages, "run_study", fail)
    args = argparse.Namespace(set=[setting], scenes=DATA, labels=tmp_path / "missing.csv", out=tmp_path / "o",
                              per_relation=1000, chunk=256, seed=0, sim_normals="ray", reps=50, trees=100,
                              n_full=1000, split="scene", real_normals="knn", test=None, test_labels=None)
    with pytest.raises(UserError, match=words.replace(".", r"\.")):
        cli_real.cmd_study(args)
    assert not (tmp_path / "o").exists()


def test_unknown_real_key_lists_the_valid_ones():
    from relaff_jax.config import ConfigError

    with pytest.raises((UserError, ConfigError), match="valid"):
        _tree("real.pipeline.kmeans.kk=3")


def test_simulated_relations_see_the_tree_perception_and_guard_it(tmp_path):
    from relaff_jax.config.perception import (CameraConfig, CullConfig, NoiseConfig, NormalsConfig, PerceptionConfig, VoxelConfig)
    from relaff_jax.real import frame as rframe
    from relaff_jax.real import sim_relations as sr
    from relaff_jax.real.scene_source import TARGET

    sensor, cfg = sr.SimSensor(0.6, 50.0), sr.SimRelationConfig()
    # the default tree gives the config the study was built with before the tree reached it
    cam = rframe.sim_camera(sensor.height, sensor.tilt_deg, TARGET, CameraConfig(vfov_deg=sensor.vfov_deg))
    before = PerceptionConfig(camera=cam, noise=NoiseConfig(cfg.noise), normals=NormalsConfig(source=cfg.normals),
                              voxel=VoxelConfig(max_object_pixels=cfg.max_object_pixels),
                              cull=CullConfig(max_tiles=cfg.max_tiles))
    assert sr.perception_config(sensor, cfg, _tree().perception) == before
    tree = _tree("perception.voxel.size=0.03")
    assert sr.perception_config(sensor, cfg, tree.perception).voxel.size == 0.03
    sr.guard(tmp_path / "sim", sensor, cfg, perception=_tree().perception)
    with pytest.raises(UserError, match="voxel_size"):
        sr.guard(tmp_path / "sim", sensor, cfg, perception=tree.perception)
    assert sr.guard(tmp_path / "sim", sensor, cfg) == sensor  # the default perception: the same folder
